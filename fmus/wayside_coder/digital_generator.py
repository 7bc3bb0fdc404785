"""Wayside coder for the digital systems (ALS-EN, FIRE_DQPSK): block logic → command per
section → duplicated generators compared 2-out-of-2 → phase-modulated square-wave carrier →
Chebyshev band-pass (docs/sources.md#digital-generator-receiver-and-redundancy; no FMI here).

* **Commands.** Free sections ahead n (the block rules, fmus/signalling/block_rules.py; the
  line beyond the model is free) → the system's plain-line command for n (als_en.py,
  fire_dqpsk.py), with the track parity (`track_parity`) and the section's block parity (its
  index mod 2). A section behind an occupied one of the same block gets no output (its code
  is cut, as ALSN's).
* **2-out-of-2.** Main and reserve controllers compute the commands independently. Equal →
  sent; different (a controller computing a wrong command, `wrong_command_main/reserve`) →
  the more restrictive; one failed (`fault_main`/`fault_reserve`, found by its self-test) →
  the other alone, `status` 1; both → no output, `status` 2 (redundancy.py).
* **Modulation.** Each section's generator repeats its current message cycle without gaps;
  a new command starts at the next cycle boundary (a message is never cut), and `code_tx`
  reports what is being modulated. The symbol clocks of the sections are not synchronised
  (random phase per section, `seed`). The phase of each sample follows from its symbol
  index; the DSP's output is a square wave sign(cos(ω·t + φ)), shaped by a 4th-order
  Chebyshev band-pass (python-control design, filter_design.py) centred on the carrier, 10/3
  of the symbol rate wide (150–200 Hz for the thesis' 175 Hz, 15 Bd), which passes the
  main lobe and takes the square wave's 3rd harmonic down by > 40 dB. The output is scaled
  so that the carrier's amplitude is `amplitude`. Loss of output is immediate (the filter
  rings down).

Sample times come from the integer sample index, so any frame length gives the same samples.
"""
from __future__ import annotations

from typing import List, Optional, Tuple

import numpy as np
from fmus.dsp.filter_design import filter_frame

from fmus.signalling import redundancy
from fmus.data.loader import Line
from fmus.signalling.digital_messages import FREE_BLOCKS_OPEN, DigitalSystem, Message, check_modem_rate
from fmus.dsp.filter_design import chebyshev_band_pass
from fmus.errors import FmuInputError
from fmus.signalling.block_rules import SIGNAL_DARK, block_codes
from fmus.wayside_coder.core import CoderOutputs, CoderSettings, CodingSwitch, check_settings

GENERATOR_PROTOTYPE_ORDER = 2      # 4th-order band-pass (docs/sources.md#digital-generator-receiver-and-redundancy: two biquads)
SQUARE_FUNDAMENTAL = 4.0 / np.pi   # amplitude of a ±1 square wave's fundamental


class DigitalCoderCore:
    def __init__(self, system: DigitalSystem, line: Line, sections: int, frame: int, settings: CoderSettings):
        s = settings
        check_settings(line, sections, s)
        self.system, self.settings = system, s
        self.carrier_hz = s.carrier_hz if s.carrier_hz > 0 else system.carrier_hz
        check_modem_rate(system, self.carrier_hz, s.fs_hz)
        if s.generator_bandwidth_hz < 0:
            raise FmuInputError(f"parameter generator_bandwidth: must not be negative, got {s.generator_bandwidth_hz:g}")
        if s.generator_ripple_db <= 0:       # a setting of the core, not an FMU variable
            raise ValueError(f"CoderSettings.generator_ripple_db: must be positive, got {s.generator_ripple_db:g}")
        self.baud = system.baud(self.carrier_hz)
        bandwidth = s.generator_bandwidth_hz or 10.0 / 3.0 * self.baud
        if bandwidth >= self.carrier_hz:
            raise FmuInputError(f"parameter generator_bandwidth: {bandwidth:g} Hz must be below the carrier")
        self.count, self.sections, self.frame = len(line.sections), sections, frame
        k = self.count
        self.shaping = chebyshev_band_pass(self.carrier_hz, bandwidth, GENERATOR_PROTOTYPE_ORDER,
                                           s.generator_ripple_db, s.fs_hz)
        w = np.exp(-2j * np.pi * self.carrier_hz / s.fs_hz)
        gain = abs(np.polyval(self.shaping.b[::-1], w) / np.polyval(self.shaping.a[::-1], w))
        self.scale = s.amplitude_v / (SQUARE_FUNDAMENTAL * gain)
        self._filter_state = np.zeros((k, self.shaping.a.size - 1))
        self.switch = CodingSwitch(k, s)
        rng = np.random.default_rng(s.seed)
        self.symbol_offset = rng.uniform(0.0, 1.0, k)          # unsynchronised symbol clocks
        self.symbols_per_sample = self.baud / s.fs_hz
        self.omega_per_sample = 2 * np.pi * self.carrier_hz / s.fs_hz
        length = system.message_symbols
        self.block_of = np.array(line.block_of_section)
        self.has_signal = np.array(line.has_signal)
        self.blocks = self.block_of % 2                       # block parity sent in every message
        # modulated message per section: cumulative phase table, start symbol and phase
        initial = [self._message(system.command_for(0), b) for b in self.blocks]
        self.current: List[Message] = initial
        self.pending: List[Message] = list(initial)
        self.cumulative = np.stack([np.cumsum(system.increments(m)) for m in initial])    # (K, L)
        self.start_symbol = np.floor(self.symbol_offset).astype(np.int64)
        self.start_phase = np.zeros(k)
        self.last_symbol = self.start_symbol - 1
        self.live = np.zeros(k, dtype=bool)
        self.length = length
        self._command_of_free = np.array([system.command_for(n) for n in range(FREE_BLOCKS_OPEN + 1)])
        self.codes = np.zeros(k, dtype=np.int64)
        self._started = False
        self._inputs = None
        self._sending = np.zeros(k, dtype=bool)
        self._changing = np.zeros(0, dtype=np.int64)
        self._index = np.arange(frame)
        self._rows = np.arange(k)[:, None]
        self.out = CoderOutputs(np.zeros((sections, frame)), np.zeros(sections, dtype=np.int64),
                                np.zeros(sections, dtype=np.int64))

    def _message(self, command: int, block: int) -> Message:
        return Message(command, self.settings.track_parity, int(block))

    # ---- commands -----------------------------------------------------------------------------
    def _decide(self, free_blocks: np.ndarray, fault_main: bool, fault_reserve: bool,
                wrong_main: int, wrong_reserve: int) -> Tuple[List[Optional[int]], int]:
        """Command per section (None: no output) and the status, through the 2-out-of-2."""
        planned = self._command_of_free[np.minimum(free_blocks, FREE_BLOCKS_OPEN)].tolist()
        if not (fault_main or fault_reserve or wrong_main or wrong_reserve):
            return planned, redundancy.STATUS_OK        # both controllers agree: the usual case
        # a controller with a wrong-command fault computes that command everywhere, a fault
        # only the comparison can see
        main = [wrong_main] * self.count if wrong_main else planned
        reserve = [wrong_reserve] * self.count if wrong_reserve else planned
        status, commands = redundancy.STATUS_OK, []
        for ours, theirs in zip(main, reserve):
            command, section_status = redundancy.wayside_2oo2(ours, theirs, not fault_main, not fault_reserve,
                                                              self.system.rank)
            commands.append(command)
            status = max(status, section_status)
        return commands, status

    def step(self, t: float, occupied: np.ndarray, fault_main: bool = False, fault_reserve: bool = False,
             wrong_command_main: int = 0, wrong_command_reserve: int = 0) -> CoderOutputs:
        s, k, out = self.settings, self.count, self.out
        for name, wrong in (("wrong_command_main", wrong_command_main), ("wrong_command_reserve", wrong_command_reserve)):
            if wrong:
                self.system.check_command(int(wrong), f"input {name}")
        occ = np.asarray(occupied[:k], dtype=bool)
        coded = self.switch.coded(t, occ)
        inputs = (occ.tobytes(), bool(fault_main), bool(fault_reserve), int(wrong_command_main),
                  int(wrong_command_reserve))
        if inputs != self._inputs:         # the decision changes only with its inputs
            self._inputs = inputs
            rules = block_codes(occ, self.block_of, s.block_aspects)
            commands, out.status = self._decide(np.maximum(rules.free_blocks, 0), *inputs[1:])
            # behind an occupied circuit of the same block the code is cut: no output (block rules)
            self._sending = np.array([c is not None for c in commands]) & rules.coded
            for index, command in enumerate(commands):
                if command is not None and command != self.pending[index].command:
                    self.pending[index] = self._message(command, self.blocks[index])
            self._changing = np.flatnonzero([p != c for p, c in zip(self.pending, self.current)])
            out.signal[:k] = np.where(self.has_signal, rules.signal, SIGNAL_DARK)
        self.live = coded & self._sending
        if not self._started:              # nothing modulated yet: start with the commands of now
            self._started = True
            self.current = list(self.pending)
            self._changing = np.zeros(0, dtype=np.int64)
            self.cumulative = np.stack([np.cumsum(self.system.increments(m)) for m in self.current])
            self.codes = np.array([self._code(m.command) for m in self.current])
        out.u_tx[:k] = self._modulate(t)
        out.code_tx[:k] = self.codes * self.live
        return out

    def _code(self, command: int) -> int:
        return self.system.indication(command, "passenger").code

    # ---- modulation ---------------------------------------------------------------------------
    def _modulate(self, t: float) -> np.ndarray:
        s = self.settings
        first = round(t * s.fs_hz)
        samples = first + self._index
        symbol = np.floor(samples[None, :] * self.symbols_per_sample + self.symbol_offset[:, None]).astype(np.int64)
        phase = self._phase(symbol)
        if self._changing.size:
            for index in self._changing.tolist():
                phase[index] = self._switch(index, symbol[index], phase[index])
            self._changing = np.flatnonzero([p != c for p, c in zip(self.pending, self.current)])
        self.last_symbol = symbol[:, -1]
        carrier = self.omega_per_sample * samples
        square = np.where(np.cos(carrier[None, :] + phase) >= 0.0, 1.0, -1.0)
        square *= self.live[:, None]
        shaped, self._filter_state = filter_frame(self.shaping.b, self.shaping.a, square, self._filter_state, axis=1)
        return self.scale * shaped

    def _phase(self, symbol: np.ndarray, rows=None) -> np.ndarray:
        rows = self._rows if rows is None else rows
        relative = symbol - self.start_symbol[rows]
        cycles, position = np.divmod(relative, self.length)
        cumulative = self.cumulative[rows[:, 0]] if rows is not self._rows else self.cumulative
        return (self.start_phase[rows] + cycles * cumulative[:, -1:]
                + np.take_along_axis(cumulative, position, axis=1))

    def _switch(self, index: int, symbol: np.ndarray, phase: np.ndarray) -> np.ndarray:
        """Start the pending message at the section's next cycle boundary if it falls in this
        frame; a cycle already begun is completed first."""
        start, length = self.start_symbol[index], self.length
        boundary = start + length * ((self.last_symbol[index] - start) // length + 1)
        if symbol[-1] < boundary:
            return phase
        cycles = (boundary - start) // length
        self.start_phase[index] = np.mod(self.start_phase[index] + cycles * self.cumulative[index, -1], 2 * np.pi)
        self.start_symbol[index] = boundary
        self.current[index] = self.pending[index]
        self.codes[index] = self._code(self.current[index].command)
        self.cumulative[index] = np.cumsum(self.system.increments(self.current[index]))
        rows = np.array([[index]])
        new_phase = self._phase(symbol[None, :], rows)[0]
        return np.where(symbol >= boundary, new_phase, phase)
