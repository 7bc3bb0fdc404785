"""Wayside coder for TVM-300: block states → the speed code of every track circuit → its one
low sub-frequency frequency-modulating the circuit's UM71 carrier (no FMI here;
docs/wayside_coder.md#tvm-300; the sub-frequencies, table and block rules:
fmus/signalling/tvm300.py).

* **Codes.** The block rules of fmus/signalling/block_rules.py give every circuit the free
  blocks ahead of its block before the first occupied one; tvm300.BlockCoding turns them, with
  the line file (limits, the last station), into the code (the sub-frequency index + 1). A
  circuit whose code is cut sends the stop code 0/0: the carrier of a TVM track circuit never
  stops, it is also the circuit's detection signal.
* **Carrier.** Section k sends on its line-file ``carrier_hz`` (1700 / 2000 / 2300 / 2600 Hz):
  u_tx[k, n] = amplitude · sin(φ_k,n), φ_k,n = 2π f_c,k t_n + (Δ / f_k)·sin θ_k,n + offset_k,
  θ_k,n = 2π f_k t_n + ψ_k: the instantaneous frequency is f_c,k + Δ·cos θ_k,n (Δ = 11 Hz).
* **Code change, phase-continuous.** A new sub-frequency f' from sample n₀ on sets ψ_k so that
  θ continues from its value at n₀ (the modulating oscillator's phase does not jump, so neither
  does the frequency) and changes offset_k by (Δ/f − Δ/f')·sin θ_k,n₀, so that the carrier's
  phase at n₀ is what the old code would have given. Each section starts at its own random
  carrier and modulation phase (``seed``).
* **Faults** as ALSN's: main transmitter failed → the reserve takes over (status 1, same
  codes); both → no carrier anywhere (status 2, code 0).

Sample times come from the integer sample index (the carrier's and the sub-frequency's phase
from (f·n mod fs)/fs, so long runs keep full precision), computed for all sections at once
per frame (fmus/wayside_coder/um71.py): frames of any length give the same samples to rounding.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from fmus.data.loader import Line
from fmus.signalling import tvm300
from fmus.signalling.block_rules import SIGNAL_DARK, block_codes
from fmus.wayside_coder import um71
from fmus.wayside_coder.core import STATUS_FAILED, CoderOutputs, CoderSettings
from fmus.wayside_coder.um71 import SampleClock, check_um71_settings, fault_status

SYSTEM_LABEL = "TVM-300"
#: the largest frequency deviation a code makes
PEAK_DEVIATION_HZ = tvm300.DEVIATION_HZ


def check_carriers_and_rate(line: Line, fs_hz: float) -> np.ndarray:
    """Each section's carrier (Hz) from the line file; a carrier not of UM71 or a sample rate
    that cannot hold the highest one is an input error."""
    return um71.check_carriers_and_rate(line, fs_hz, PEAK_DEVIATION_HZ, SYSTEM_LABEL)


def sub_frequencies_of(codes: np.ndarray) -> np.ndarray:
    """(K,) the sub-frequency (Hz) of each code, 0 for code 0 (a bare carrier)."""
    codes = np.asarray(codes, dtype=np.int64)
    return np.where(codes > 0, tvm300.SUB_FREQUENCIES_HZ[np.clip(codes - 1, 0, tvm300.SUB_FREQUENCY_COUNT - 1)], 0.0)


class Tvm300CoderCore:
    def __init__(self, line: Line, sections: int, frame: int, settings: CoderSettings,
                 table: Optional[tvm300.CodeTable] = None):
        s = settings
        check_um71_settings(line, sections, s, SYSTEM_LABEL)
        self.tvm = tvm300.Tvm300System(table) if table is not None else tvm300.system()
        self.settings = s
        self.carriers_hz = check_carriers_and_rate(line, s.fs_hz)
        self.codes_of = tvm300.BlockCoding(line, self.tvm)
        self.count, self.sections, self.frame = len(line.sections), sections, frame
        k = self.count
        self.block_of = np.array(line.block_of_section)
        self.has_signal = np.array(line.has_signal)
        self.codes = np.zeros(k, dtype=np.int64)
        self._sub_hz = np.zeros(k)                                  # f_k (0: a bare carrier)
        self._depth = np.zeros(k)                                   # Δ / f_k (rad), 0 for a bare carrier
        rng = np.random.default_rng(s.seed)
        self._offset = rng.uniform(0.0, 2.0 * np.pi, k)             # offset_k (rad)
        self._psi = rng.uniform(0.0, 2.0 * np.pi, k)                # ψ_k (rad)
        self.clock = SampleClock(self.carriers_hz, frame, s.fs_hz)
        # per-frame work buffers: the sub-frequencies' phase, the total phase of every section
        self._theta = np.empty((k, frame))
        self._logic_state = None
        self._forced: Optional[np.ndarray] = None      # a bench's codes (send), instead of the block's
        self.out = CoderOutputs(np.zeros((sections, frame)), np.zeros(sections, dtype=np.int64),
                                np.zeros(sections, dtype=np.int64))

    def send(self, codes: Optional[np.ndarray]) -> None:
        """A bench's test generator: from the next frame on, section k sends ``codes[k]`` (0: the
        bare carrier, 1…18: sub-frequency code − 1, used in the table or not) instead of the
        block rules' code; None: the block rules again. A change is phase-continuous as in
        service."""
        self._forced = None if codes is None else np.asarray(codes, dtype=np.int64).reshape(self.count)
        self._logic_state = None

    def _theta_at(self, sub_hz: np.ndarray, psi: np.ndarray, index: np.ndarray, out: np.ndarray) -> np.ndarray:
        """(K, n) θ = 2π·((f·n) mod fs)/fs + ψ at the sample indices ``index``."""
        fs = self.settings.fs_hz
        theta = np.multiply.outer(sub_hz, index, out=out)
        np.fmod(theta, fs, out=theta)
        theta *= 2.0 * np.pi / fs
        theta += psi[:, None]
        return theta

    def step(self, t: float, occupied: np.ndarray, fault_main: bool = False, fault_reserve: bool = False,
             wrong_command_main: int = 0, wrong_command_reserve: int = 0) -> CoderOutputs:
        """One frame (the wrong-command faults are the digital coders': ignored here)."""
        k, out = self.count, self.out
        n = out.u_tx.shape[1]
        index, _ = self.clock.samples(t, n)
        state = (occupied[:k].tobytes(), fault_main, fault_reserve)
        if state != self._logic_state:
            self._logic_state = state
            self._block_logic(np.asarray(occupied[:k], dtype=bool), fault_main, fault_reserve, index[:1])
        u = out.u_tx[:k]
        if out.status == STATUS_FAILED:
            u.fill(0.0)
            return out
        phase = self._theta_at(self._sub_hz, self._psi, index, self._theta[:, :n])
        np.sin(phase, out=phase)
        phase *= self._depth[:, None]
        phase += self.clock.carrier_phase(index)
        phase += self._offset[:, None]
        np.sin(phase, out=u)
        u *= self.settings.amplitude_v
        return out

    def _block_logic(self, occupied: np.ndarray, fault_main: bool, fault_reserve: bool, first: np.ndarray) -> None:
        k, out = self.count, self.out
        rules = block_codes(occupied, self.block_of, self.settings.block_aspects)
        out.status = fault_status(fault_main, fault_reserve)
        if self._forced is not None:
            codes = self._forced
        elif out.status == STATUS_FAILED:
            codes = np.zeros(k, dtype=np.int64)
        else:
            codes = self.codes_of.codes(rules)
        sub_hz = sub_frequencies_of(codes)
        depth = np.divide(tvm300.DEVIATION_HZ, sub_hz, out=np.zeros(k), where=sub_hz > 0)
        # phase-continuous: θ and the carrier's phase at this frame's first sample stay what they were
        theta_now = self._theta_at(self._sub_hz, self._psi, first, np.empty((k, 1)))[:, 0]
        self._offset += (self._depth - depth) * np.sin(theta_now)
        np.mod(self._offset, 2.0 * np.pi, out=self._offset)
        self._psi = np.mod(theta_now - self._theta_at(sub_hz, np.zeros(k), first, np.empty((k, 1)))[:, 0], 2.0 * np.pi)
        self._sub_hz, self._depth, self.codes = sub_hz, depth, codes
        out.code_tx[:k] = codes
        out.signal[:k] = np.where(self.has_signal, rules.signal, SIGNAL_DARK)
