"""Wayside coder for TVM-430: block states → the 27-bit word of every track circuit → the word's
very-low tones frequency-modulating the circuit's audio-frequency carrier (no FMI here;
docs/wayside_coder.md#tvm-430).

* **Words.** The block rules of fmus/signalling/block_rules.py give every circuit the free
  blocks ahead of its block before the first occupied one; fmus/signalling/tvm430.py
  ``BlockWords`` turns them, with the line file (block lengths, limits, gradients, the last
  station), into the word: address, speed pair, distance to target, gradient, check. A circuit
  whose code is cut by an occupied circuit further on in its block sends the stop word: the
  carrier of a TVM track circuit never stops, it is also the circuit's detection signal.
* **Carrier.** Section k sends on its line-file ``carrier_hz`` (1700 / 2000 / 2300 / 2600 Hz).
  u_tx[k, n] = amplitude · sin(φ_k,n), φ_k,n = 2π f_c,k t_n + b_k · M(t_n) + offset_k, with b_k
  the word's 27 bits and M(t) the tones' phase terms (tvm430.modulation_phase_terms): the
  instantaneous frequency is f_c,k + Δ·Σ_{bit set} cos(2π f_j t + φ_j).
* **Word change, phase-continuous.** A new word b' from sample n₀ on changes offset_k by
  (b − b')·M(t_n₀): the phase at n₀ is what the old word would have given, and from there on
  the frequency follows the new word — the carrier never jumps in phase, as an FM transmitter's
  oscillator does not. Each section starts at its own random phase (``seed``).
* **Faults** as ALSN's: main transmitter failed → the reserve takes over (status 1, same
  words); both → no carrier anywhere (status 2, word 0).

Sample times come from the integer sample index (the carrier's phase from (f_c·n mod fs)/fs, so
long runs keep full precision), the 27 tone terms are computed once per frame for all sections
and the phase is one matrix product (K × 27)·(27 × n): frames of any length give the same
samples to rounding.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from fmus.data.loader import Line
from fmus.signalling import tvm430
from fmus.signalling.block_rules import SIGNAL_DARK, block_codes
from fmus.wayside_coder.core import STATUS_FAILED, CoderOutputs, CoderSettings
from fmus.wayside_coder.um71 import MAX_FREQUENCY_PER_FS, SampleClock, check_um71_settings, fault_status  # noqa: F401
from fmus.wayside_coder import um71

SYSTEM_LABEL = "TVM-430"
#: the largest frequency deviation any word can make (every tone at its peak at once)
PEAK_DEVIATION_HZ = tvm430.TONE_COUNT * tvm430.DEVIATION_HZ_PER_TONE


def check_carriers_and_rate(line: Line, fs_hz: float) -> np.ndarray:
    """Each section's carrier (Hz) from the line file; a carrier not of TVM-430 or a sample rate
    that cannot hold the highest one is an input error."""
    return um71.check_carriers_and_rate(line, fs_hz, PEAK_DEVIATION_HZ, SYSTEM_LABEL)


class Tvm430CoderCore:
    def __init__(self, line: Line, sections: int, frame: int, settings: CoderSettings,
                 table: Optional[tvm430.CodeTable] = None, address: Optional[int] = None):
        s = settings
        check_um71_settings(line, sections, s, SYSTEM_LABEL)
        self.tvm = tvm430.Tvm430System(table) if table is not None else tvm430.system()
        self.settings = s
        self.carriers_hz = check_carriers_and_rate(line, s.fs_hz)
        self.words_of = tvm430.BlockWords(line, self.tvm, address)
        self.count, self.sections, self.frame = len(line.sections), sections, frame
        k = self.count
        self.block_of = np.array(line.block_of_section)
        self.has_signal = np.array(line.has_signal)
        self.words = np.zeros(k, dtype=np.int64)
        self._bits = np.zeros((k, tvm430.WORD_BITS))                 # b_k, one row per section
        rng = np.random.default_rng(s.seed)
        self._offset = rng.uniform(0.0, 2.0 * np.pi, k)              # offset_k (rad)
        self.clock = SampleClock(self.carriers_hz, frame, s.fs_hz)
        # per-frame work buffers (tone terms, total phase of every section)
        self._terms = np.empty((tvm430.TONE_COUNT, frame))
        self._phase = np.empty((k, frame))
        self._logic_state = None
        self._forced: Optional[np.ndarray] = None      # a bench's words (send), instead of the block's
        self.out = CoderOutputs(np.zeros((sections, frame)), np.zeros(sections, dtype=np.int64),
                                np.zeros(sections, dtype=np.int64))

    def send(self, words: Optional[np.ndarray]) -> None:
        """A bench's test generator: from the next frame on, section k sends ``words[k]`` (any
        27-bit pattern, a valid word or not; 0: the bare carrier) instead of the block rules'
        word; None: the block rules again. A change is phase-continuous as in service."""
        self._forced = None if words is None else np.asarray(words, dtype=np.int64).reshape(self.count)
        self._logic_state = None

    def step(self, t: float, occupied: np.ndarray, fault_main: bool = False, fault_reserve: bool = False,
             wrong_command_main: int = 0, wrong_command_reserve: int = 0) -> CoderOutputs:
        """One frame (the wrong-command faults are the digital coders': ignored here)."""
        k, out = self.count, self.out
        n = out.u_tx.shape[1]
        index, times = self.clock.samples(t, n)
        terms = tvm430.modulation_phase_terms(times, out=self._terms[:, :n])
        state = (occupied[:k].tobytes(), fault_main, fault_reserve)
        if state != self._logic_state:
            self._logic_state = state
            self._block_logic(np.asarray(occupied[:k], dtype=bool), fault_main, fault_reserve, terms[:, 0])
        u = out.u_tx[:k]
        if out.status == STATUS_FAILED:
            u.fill(0.0)
            return out
        phase = np.matmul(self._bits, terms, out=self._phase[:, :n])
        phase += self.clock.carrier_phase(index)
        phase += self._offset[:, None]
        np.sin(phase, out=u)
        u *= self.settings.amplitude_v
        return out

    def _block_logic(self, occupied: np.ndarray, fault_main: bool, fault_reserve: bool,
                     terms_now: np.ndarray) -> None:
        k, out = self.count, self.out
        rules = block_codes(occupied, self.block_of, self.settings.block_aspects)
        out.status = fault_status(fault_main, fault_reserve)
        if self._forced is not None:
            words = self._forced
        elif out.status == STATUS_FAILED:
            words = np.zeros(k, dtype=np.int64)
        else:
            words = self.words_of.words(rules.free_blocks, rules.coded)
        bits = ((words[:, None] >> np.arange(tvm430.WORD_BITS)) & 1).astype(float)
        # phase-continuous: the modulation phase at this frame's first sample stays what it was
        self._offset += (self._bits - bits) @ terms_now
        np.mod(self._offset, 2.0 * np.pi, out=self._offset)
        self._bits, self.words = bits, words
        out.code_tx[:k] = words
        out.signal[:k] = np.where(self.has_signal, rules.signal, SIGNAL_DARK)
