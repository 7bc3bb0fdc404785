"""Wayside coder for ALSU: block logic → an ALSU code per track circuit → two continuous tones
of six into each section (no FMI here; docs/wayside_coder.md#alsu).

* **Codes.** The block rules of fmus/signalling/block_rules.py (3- or 4-aspect block, no code
  behind an occupied circuit of the same block, `coding` always or on occupation) and the
  line's diverging routes and limits give every circuit its ALSU code
  (fmus/signalling/alsu.py ``BlockCoding``): 1 / 4 / 6 / 9 from the exit signal, 3 / 5 / 7
  for a diverging route, 10 / 11 before a permanent restriction, 12 / 13 on a line cleared for
  180 / 200 km/h.
* **Tones.** Each section has its own six tone generators running continuously, each at its
  own random phase (`seed`: the generators of different sections are not synchronised); a code
  switches two of them onto the section's output. A code change only switches generators, so
  a tone the new code keeps goes on without a break in phase, and a new one starts at its
  generator's running phase. u_tx[k, n] = amplitude · Σ over the code's two tones of
  sin(2π·f·t_n + φ_k,f): `amplitude` is each tone's peak.
* **Faults** as ALSN's: main transmitter failed → the reserve takes over (status 1, same
  codes); both → no tones anywhere (status 2).

Sample times come from the integer sample index; the tones are odd multiples of 25 Hz, so at
4 kHz they repeat every 160 samples, and a frame is read from one period of each generator's
sine and cosine: frames of any length give the same samples.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from fmus.data.loader import Line
from fmus.dsp.periodic import period_samples
from fmus.errors import FmuInputError
from fmus.signalling import alsu
from fmus.signalling.block_rules import SIGNAL_DARK, block_codes
from fmus.wayside_coder.core import (STATUS_FAILED, STATUS_OK, STATUS_PARTIAL, CoderOutputs, CoderSettings,
                                     CodingSwitch, check_settings)

MIN_SAMPLES_PER_TONE_PERIOD = 8
_TABLE_MAX_SAMPLES = 1 << 16


def check_tone_rate(table: alsu.CodeTable, fs_hz: float) -> None:
    top = max(table.tones_hz)
    if fs_hz < MIN_SAMPLES_PER_TONE_PERIOD * top:
        raise FmuInputError(f"parameter fs: {fs_hz:g} Hz is below {MIN_SAMPLES_PER_TONE_PERIOD}× the highest "
                            f"ALSU tone {top:g} Hz")


class AlsuCoderCore:
    def __init__(self, line: Line, sections: int, frame: int, settings: CoderSettings,
                 table: Optional[alsu.CodeTable] = None):
        s = settings
        check_settings(line, sections, s)
        if s.carrier_hz:
            raise FmuInputError(f"parameter carrier: {s.carrier_hz:g} Hz, but ALSU sends its own six tones "
                                f"(leave carrier 0)")
        self.alsu = alsu.AlsuSystem(table) if table is not None else alsu.system()
        check_tone_rate(self.alsu.table, s.fs_hz)
        self.settings = s
        self.count, self.sections, self.frame = len(line.sections), sections, frame
        k = self.count
        self.coding = alsu.BlockCoding(line, s.block_aspects, self.alsu)
        self.block_of = np.array(line.block_of_section)
        self.has_signal = np.array(line.has_signal)
        self.switch = CodingSwitch(k, s)
        self.tones_hz = np.array(self.alsu.table.tones_hz)
        # per code number (0: none) the two tones it switches on
        self.tone_mask = np.zeros((alsu.CODE_COUNT + 1, alsu.TONE_COUNT), dtype=bool)
        for number, code in self.alsu.table.codes.items():
            self.tone_mask[number, list(code.tones)] = True
        rng = np.random.default_rng(s.seed)
        phase = rng.uniform(0.0, 2.0 * np.pi, (k, alsu.TONE_COUNT))
        # sin(ωt + φ) = sin ωt·cos φ + cos ωt·sin φ: per section and tone two weights
        self._cos_phase, self._sin_phase = np.cos(phase) * s.amplitude_v, np.sin(phase) * s.amplitude_v
        self._weight_sin = np.zeros((k, alsu.TONE_COUNT))     # cos φ where the tone is on
        self._weight_cos = np.zeros((k, alsu.TONE_COUNT))
        self.codes = np.zeros(k, dtype=np.int64)
        self._index = np.arange(frame)
        self._period = period_samples([1.0 / f for f in self.tones_hz], s.fs_hz, _TABLE_MAX_SAMPLES)
        if self._period is not None:
            # one period of every generator's sine and cosine, and a frame's continuation
            n = np.arange(self._period + frame) % self._period
            angle = 2.0 * np.pi * self.tones_hz[:, None] * (n / s.fs_hz)[None, :]
            self._sin_table, self._cos_table = np.sin(angle), np.cos(angle)
        self._logic_state = None
        self._forced: Optional[np.ndarray] = None      # a bench's tones (send), instead of the block's
        self.out = CoderOutputs(np.zeros((sections, frame)), np.zeros(sections, dtype=np.int64),
                                np.zeros(sections, dtype=np.int64))

    def send(self, tones: Optional[np.ndarray], codes: Optional[np.ndarray] = None) -> None:
        """A bench's test generator: from the next frame on, section k sends the tones
        ``tones[k]`` (bool, K × 6: any set, a code's pair or not) and reports ``codes[k]`` as
        its code_tx, instead of what the block rules give; None: the block rules again. The
        generators keep running, so a change is phase-continuous as in service."""
        self._forced = None if tones is None else np.asarray(tones, dtype=bool).reshape(self.count, alsu.TONE_COUNT)
        self._forced_codes = np.zeros(self.count, dtype=np.int64) if codes is None else np.asarray(codes)
        self._logic_state = None

    def tones_of(self, code: int) -> np.ndarray:
        """The six on/off flags of a code number (0: none)."""
        return self.tone_mask[int(code)].copy()

    def step(self, t: float, occupied: np.ndarray, fault_main: bool = False, fault_reserve: bool = False,
             wrong_command_main: int = 0, wrong_command_reserve: int = 0) -> CoderOutputs:
        """One frame (the wrong-command faults are the digital coders': ignored here)."""
        s, k, out = self.settings, self.count, self.out
        state = (occupied[:k].tobytes(), fault_main, fault_reserve)
        if state != self._logic_state or self.switch.waiting:
            self._logic_state = state
            self._block_logic(t, np.asarray(occupied[:k], dtype=bool), fault_main, fault_reserve)
        first = round(t * s.fs_hz)
        n = out.u_tx.shape[1]
        if self._period is not None:
            start = first % self._period
            sines, cosines = self._sin_table[:, start:start + n], self._cos_table[:, start:start + n]
        else:
            angle = 2.0 * np.pi * self.tones_hz[:, None] * ((first + self._index[:n]) / s.fs_hz)[None, :]
            sines, cosines = np.sin(angle), np.cos(angle)
        u = out.u_tx[:k]
        u.fill(0.0)
        # tone by tone in a fixed order: the same operations whatever the frame length
        for tone in range(alsu.TONE_COUNT):
            u += self._weight_sin[:, tone, None] * sines[tone]
            u += self._weight_cos[:, tone, None] * cosines[tone]
        return out

    def _block_logic(self, t: float, occupied: np.ndarray, fault_main: bool, fault_reserve: bool) -> None:
        k, out = self.count, self.out
        rules = block_codes(occupied, self.block_of, self.settings.block_aspects)
        codes = np.where(self.switch.coded(t, occupied), self.coding.codes(rules), alsu.NO_CODE)
        out.status = STATUS_FAILED if (fault_main and fault_reserve) else (
            STATUS_PARTIAL if fault_main or fault_reserve else STATUS_OK)
        if out.status == STATUS_FAILED:
            codes = np.zeros(k, dtype=np.int64)
        self.codes = codes
        on = self.tone_mask[codes]
        if self._forced is not None:
            on, self.codes = self._forced, self._forced_codes
            codes = self.codes
        self._weight_sin = np.where(on, self._cos_phase, 0.0)
        self._weight_cos = np.where(on, self._sin_phase, 0.0)
        out.code_tx[:k] = codes
        out.signal[:k] = np.where(self.has_signal, rules.signal, SIGNAL_DARK)
