"""Wayside ALSN coder: automatic-block aspect logic and KPT-5/KPT-7 code transmitters keying the
carrier into each block section (no FMI here).

Per block section k (line data: transmitter type and carrier per section):

* **Block logic** — the code fed into section k (from its exit end) follows the aspect of the
  signal at its exit, which depends on the occupancy of the sections ahead. 3-aspect block:
  next section occupied → red → КЖ; the one after occupied → yellow → Ж; else green → З.
  4-aspect block adds yellow-green (three sections ahead occupied), sent as З [U]. Beyond the
  last modelled section the line is taken as free. A track circuit behind an occupied one of
  the same block (throats: circuits without their own signal) gets no code. The rules are
  fmus/signalling/block_rules.py, shared with the digital coder and the run verdict. Coding is
  either always on or switched on when the section is occupied, after a switch-on delay.
* **Transmitter** — the cam turns continuously with the transmitter's cycle (KPT-5 1.6 s,
  KPT-7 1.86 s, scaled by ``timing_scale`` to model drift); a code change selects another cam
  contact at the current cam phase (no resynchronisation). Each section starts at a random cam
  phase (seeded): transmitters are not synchronised.
* **Output** — u_tx[k, n] = amplitude · key[k, n] · sin(2π·f_k·t_n), t_n = t + n/fs; the key
  is ideal or, with ``relay_time_constant`` > 0, smoothed by a first-order transmitter-relay
  transient (scipy.signal.lfilter with carried state).

Faults: main transmitter failed → reserve takes over (status 1, same codes); main and reserve
failed → no code anywhere (status 2).

Everything is a pure function of the sample index and the carried filter state, so frames of
any length N give the same samples (docs/wayside_coder.md#model-corepy).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np
from scipy.signal import lfilter

from fmus.signalling import alsn
from fmus.signalling.block_rules import (SIGNAL_DARK, SIGNAL_GREEN, SIGNAL_RED, SIGNAL_YELLOW,  # noqa: F401 (re-exported)
                                         SIGNAL_YELLOW_GREEN, BlockCodes, block_codes)
from fmus.data.loader import Line
from fmus.dsp.periodic import period_samples
from fmus.errors import FmuInputError
from fmus.sizes import DEFAULT_SAMPLE_RATE_HZ

STATUS_OK, STATUS_PARTIAL, STATUS_FAILED = 0, 1, 2
STATUS_NAMES = {STATUS_OK: "ok", STATUS_PARTIAL: "one transmitter/controller failed", STATUS_FAILED: "both failed"}
_WAVE_MAX_SAMPLES = 1 << 16     # longest repeating output kept as a table, per section and code


@dataclass
class CoderSettings:
    fs_hz: float = DEFAULT_SAMPLE_RATE_HZ
    carrier_hz: float = 0.0             # 0: each section's carrier from the line file
    amplitude_v: float = 4.0            # peak transmitter voltage while a pulse is on
    block_aspects: int = 3
    coding: str = "always"              # always | on_occupation
    switch_on_delay_s: float = 0.0
    timing_scale: float = 1.0           # all code timings × this (transmitter drift)
    relay_time_constant_s: float = 0.0  # 0: ideal keying
    seed: int = 1
    # digital systems only
    track_parity: int = 1               # 1 odd track, 0 even (adjacent-track protection)
    generator_bandwidth_hz: float = 0.0  # 0: 10/3 × the symbol rate
    generator_ripple_db: float = 0.5


@dataclass
class CoderOutputs:
    u_tx: np.ndarray          # (K, N) V
    code_tx: np.ndarray       # (K,) aspect code sent, 0 none
    signal: np.ndarray        # (K,) wayside signal at each section's exit
    status: int = STATUS_OK


def bind_outputs(core, u_tx: np.ndarray, code_tx: np.ndarray, signal: np.ndarray) -> None:
    """Let a coder core (ALSN or digital) write its array outputs straight into these arrays
    (a host's port buffers, of the shapes of ``core.out``'s): no copy per frame."""
    out = core.out
    for name, theirs in (("u_tx", u_tx), ("code_tx", code_tx), ("signal", signal)):
        mine = getattr(out, name)
        if theirs.shape != mine.shape:
            raise ValueError(f"bind_outputs: {name} has shape {theirs.shape}, the core's {mine.shape}")
        theirs[...] = mine
        setattr(out, name, theirs)


def check_settings(line: Line, sections: int, s: CoderSettings) -> None:
    """What every coder (ALSN or digital) checks of its line and parameters."""
    if len(line.sections) > sections:
        raise FmuInputError(f"{line.path}: field block_sections: {len(line.sections)} sections, but this "
                            f"build models {sections}; rebuild with `railcosim build --sections "
                            f"{len(line.sections)}`")
    if s.block_aspects not in (3, 4):
        raise FmuInputError(f"parameter block_aspects: {s.block_aspects} (3 or 4)")
    if s.coding not in ("always", "on_occupation"):
        raise FmuInputError(f"parameter coding: {s.coding!r} is not always or on_occupation")
    for name, value in (("fs", s.fs_hz), ("amplitude", s.amplitude_v), ("timing_scale", s.timing_scale)):
        if not value > 0:
            raise FmuInputError(f"parameter {name}: must be positive, got {value}")
    for name, value in (("switch_on_delay", s.switch_on_delay_s), ("relay_time_constant", s.relay_time_constant_s)):
        if value < 0:
            raise FmuInputError(f"parameter {name}: must not be negative, got {value}")
    if s.track_parity not in (0, 1):
        raise FmuInputError(f"parameter track_parity: {s.track_parity} (0 even track, 1 odd track)")


def keyed(phase_s: np.ndarray, pulses: np.ndarray) -> np.ndarray:
    """Whether each cam phase lies inside one of the pulses (``pulses``: … × P × 2, on / off in
    seconds of the cam cycle, broadcast against ``phase_s``)."""
    phase = phase_s[..., None]
    return ((phase >= pulses[..., 0]) & (phase < pulses[..., 1])).any(-1)


class CodingSwitch:
    """`coding = on_occupation`: a section is coded once occupied for the switch-on delay."""

    def __init__(self, count: int, settings: CoderSettings):
        self.settings = settings
        self.occupied_since = np.full(count, np.inf)
        self.always = settings.coding == "always"
        self._all = np.ones(count, dtype=bool)
        self.waiting = False        # a section is occupied but not yet switched on: time alone changes it

    def coded(self, t: float, occupied: np.ndarray) -> np.ndarray:
        if self.always:
            return self._all
        self.occupied_since = np.where(occupied, np.minimum(self.occupied_since, t), np.inf)
        coded = t - self.occupied_since >= self.settings.switch_on_delay_s - 1e-12
        self.waiting = bool((occupied & ~coded).any())
        return coded


class WaysideCoderCore:
    def __init__(self, line: Line, sections: int, frame: int, settings: CoderSettings,
                 transmitters: Optional[dict] = None):
        s = settings
        check_settings(line, sections, s)
        transmitters = transmitters or alsn.load_transmitters()
        self.settings = s
        self.count = len(line.sections)           # modelled sections; ports beyond stay silent
        self.sections, self.frame = sections, frame
        k = self.count
        carriers = np.array([sec.carrier_hz for sec in line.sections], dtype=float)
        if s.carrier_hz > 0:
            carriers[:] = s.carrier_hz
        for index, carrier in enumerate(carriers):
            where = "parameter " if s.carrier_hz > 0 else f"{line.path}: field block_sections[{index}]."
            alsn.check_carrier_and_rate(float(carrier), s.fs_hz, where)
        types = []
        for index, sec in enumerate(line.sections):
            if sec.transmitter not in transmitters:
                raise FmuInputError(f"{line.path}: field block_sections[{index}].transmitter: "
                                    f"{sec.transmitter!r} is not one of {', '.join(transmitters)}")
            types.append(transmitters[sec.transmitter])
        self.cycle_s = np.array([tx.cycle_s for tx in types]) * s.timing_scale
        # pulse table (K, code, P, 2) padded with empty pulses; code axis indexed by aspect code 0..4
        width = max(p.shape[0] for tx in types for p in tx.pulses.values())
        self.pulses = np.zeros((k, 5, width, 2))
        for index, tx in enumerate(types):
            for code, pulses in tx.pulses.items():
                self.pulses[index, code, :pulses.shape[0]] = pulses * s.timing_scale
        rng = np.random.default_rng(s.seed)
        self.cam_offset_s = rng.uniform(0.0, 1.0, k) * self.cycle_s
        self.omega = 2.0 * np.pi * carriers
        self.codes = np.zeros(k, dtype=np.int64)
        self.signals = np.zeros(k, dtype=np.int64)
        self.switch = CodingSwitch(k, s)
        self.block_of = np.array(line.block_of_section)
        self.has_signal = np.array(line.has_signal)
        if s.relay_time_constant_s > 0:
            a = np.exp(-1.0 / (s.fs_hz * s.relay_time_constant_s))
            self._relay = (np.array([1.0 - a]), np.array([1.0, -a]))
        else:
            self._relay = None
        self._relay_state = np.zeros((k, 1))
        self._index = np.arange(frame)
        self._omega_column = self.omega[:, None]
        self._logic_state = None
        self._period = self._wave_periods() if self._relay is None else None
        self._waves = {}              # (section, code) → one period of u_tx and the next frame's N samples
        if self._period is not None:
            # each section's row: one period followed by the frame's length of its continuation,
            # so a frame is the N entries from (first sample mod period) on: no modulo per sample
            width = int(self._period.max()) + frame
            self._frame_index = np.arange(k)[:, None] * width + self._index
            self._wave_rows = np.zeros(k * width)
        # one sample per frame: each section's sample read from its row by (row start, period),
        # look-ups in Python instead of three numpy calls on one-sample arrays
        self._sample_rows = list(zip(range(0, k * width, width), self._period.tolist())) \
            if self._period is not None and frame == 1 else None
        self.out = CoderOutputs(np.zeros((sections, frame)), np.zeros(sections, dtype=np.int64),
                                np.zeros(sections, dtype=np.int64))

    # ---- block logic --------------------------------------------------------------------------
    def block_codes(self, occupied: np.ndarray) -> BlockCodes:
        """The block rules for this line (fmus/signalling/block_rules.py)."""
        return block_codes(np.asarray(occupied[:self.count], dtype=bool), self.block_of, self.settings.block_aspects)

    def block_signals(self, occupied: np.ndarray) -> np.ndarray:
        """Aspect of the signal closing each section's block."""
        return self.block_codes(occupied).signal

    def step(self, t: float, occupied: np.ndarray, fault_main: bool = False, fault_reserve: bool = False,
             wrong_command_main: int = 0, wrong_command_reserve: int = 0) -> CoderOutputs:
        """One frame. The wrong-command faults are the digital coders' (digital_generator.py): an ALSN
        coder has no controllers computing commands, so it ignores them."""
        s = self.settings
        k, out = self.count, self.out
        state = (occupied[:k].tobytes(), fault_main, fault_reserve)
        if state != self._logic_state or self.switch.waiting:     # block logic only when its inputs change
            self._logic_state = state
            self._block_logic(t, np.asarray(occupied[:k], dtype=bool), fault_main, fault_reserve)
        # sample times from the integer sample index: no drift over long runs
        first = round(t * s.fs_hz)
        if self._sample_rows is not None:
            rows = self._wave_rows
            out.u_tx[:k, 0] = [rows.item(start + first % period) for start, period in self._sample_rows]
            return out
        if self._period is not None:          # the periodic waveform of each section, from its table
            self._wave_rows.take(self._frame_index + (first % self._period)[:, None], out=out.u_tx[:k])
            return out
        times = (first + self._index) / s.fs_hz
        key = keyed(np.mod(times + self.cam_offset_s[:, None], self.cycle_s[:, None]), self._pulses)
        if self._relay is not None:
            key, self._relay_state = lfilter(*self._relay, key.astype(float), axis=1, zi=self._relay_state)
        np.multiply(key, np.sin(self._omega_column * times) * s.amplitude_v, out=out.u_tx[:k])
        return out

    def _block_logic(self, t: float, occupied: np.ndarray, fault_main: bool, fault_reserve: bool) -> None:
        """Signals, codes, transmitter status and the cam contacts the codes select."""
        k, out = self.count, self.out
        rules = self.block_codes(occupied)
        signals = rules.signal
        # the block rules' code: none behind an occupied circuit of the same block
        codes = np.where(self.switch.coded(t, occupied), rules.alsn_code, alsn.NO_CODE)
        out.status = STATUS_FAILED if (fault_main and fault_reserve) else (STATUS_PARTIAL if fault_main or fault_reserve else STATUS_OK)
        if out.status == STATUS_FAILED:
            codes = np.zeros(k, dtype=np.int64)
        self.codes, self.signals = codes, signals
        self._pulses = self.pulses[np.arange(k), codes][:, None]       # (K, 1, P, 2): against (K, N) phases
        out.code_tx[:k] = codes
        out.signal[:k] = np.where(self.has_signal, signals, SIGNAL_DARK)
        if self._period is not None:
            width = int(self._period.max()) + self.frame
            for section, code in enumerate(codes.tolist()):
                wave = self._wave(section, code)
                self._wave_rows[section * width:section * width + wave.size] = wave

    def _wave_periods(self) -> Optional[np.ndarray]:
        """Samples after which each section's output repeats (its cam cycle and carrier period
        together), or None when a section's does not within _WAVE_MAX_SAMPLES: then the output
        is computed from the sample times every frame."""
        periods = [period_samples((cycle_s, 2 * np.pi / omega), self.settings.fs_hz, _WAVE_MAX_SAMPLES)
                   for cycle_s, omega in zip(self.cycle_s, self.omega)]
        return None if None in periods else np.array(periods, dtype=np.int64)

    def _wave(self, section: int, code: int) -> np.ndarray:
        """One period of section ``section``'s output for ``code`` and the frame's length of its
        continuation (the output at sample n is entry n mod period)."""
        key = (section, code)
        if key not in self._waves:
            s = self.settings
            times = np.arange(self._period[section]) / s.fs_hz
            key_on = keyed(np.mod(times + self.cam_offset_s[section], self.cycle_s[section]), self.pulses[section, code])
            wave = key_on * (np.sin(self.omega[section] * times) * s.amplitude_v)
            self._waves[key] = wave[np.arange(wave.size + self.frame) % wave.size]   # + the frame's continuation
        return self._waves[key]
