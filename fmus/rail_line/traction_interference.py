"""Traction interference at the receiver coils: the asymmetric part of the traction return
current, a(x)·i_traction(t) (no FMI here).

* a(x): a per-section asymmetry (seeded, 1–5 %), falling linearly to zero between the bond
  leads and the joint where the centre-tap jumper balances the rails, so each joint gives two
  pulses of opposite polarity, each (lead offset + coil length)/v wide (1.3 m, 0.059 s at
  80 km/h; docs/rail_line.md), amplitude ∝ v.
* i_traction(t): the train's traction current through a first-order lag (the traction
  circuit's inductance), times the rectifier ripple of a DC line (300/600 Hz) or the 50 Hz
  wave with odd harmonics of an AC line. A line without electrification has none.
"""
from __future__ import annotations

import numpy as np

from fmus.data.loader import Line
from fmus.dsp.periodic import period_samples

_RIPPLE_MAX_SAMPLES = 1 << 14    # traction ripple kept as a table when it repeats within this


class TractionInterference:
    def __init__(self, line: Line, settings, trains: int, frame: int, bank):
        s = settings
        self.settings, self.trains, self.bank = s, trains, bank
        count = bank.count
        self.ac = line.electrification == "AC25000"
        self.dc = line.electrification == "DC3000"
        lo, hi = s.asymmetry_range
        rng = np.random.default_rng(s.seed)
        self.asymmetry = rng.uniform(lo, hi, count) * rng.choice([-1.0, 1.0], count)
        dt = 1.0 / s.fs_hz
        lag = np.exp(-dt / s.traction_time_constant_s)
        self._lag_powers = lag ** np.arange(1, frame + 1)
        self._traction_last = [0.0] * trains                   # smoothed current at the last sample
        self._traction_on = [False] * trains
        self._i_traction = np.zeros((trains, frame))
        self._index = np.arange(frame)
        self._ripple_first = None                              # the frame's ripple waveform, once computed
        self._ripple = np.zeros(frame)
        ripple_hz = (300.0, 600.0) if self.dc else (50.0, 150.0, 250.0)
        self._ripple_period = period_samples([1.0 / f for f in ripple_hz], s.fs_hz, _RIPPLE_MAX_SAMPLES)
        if self._ripple_period is not None and (self.dc or self.ac):
            self._ripple_table = self._ripple_wave(np.arange(self._ripple_period) * dt)

    def new_frame(self, i_traction: np.ndarray, n: int) -> None:
        """The traction current reaches the rails through the traction circuit's inductance
        (smoothing reactor, motors): a first-order lag of ``traction_time_constant``. It also
        turns the steps of a slowly sampled traction FMU into ramps, which the coils would
        otherwise see as EMF spikes of tens of volts. The input is held over the frame, so the
        lag's response is closed-form: y[i] = c + (y[−1] − c)·λ^(i+1)."""
        for j in range(self.trains):
            held, last = float(i_traction[j]), self._traction_last[j]
            row = self._i_traction[j, :n]
            if held == last == 0.0:
                if self._traction_on[j]:
                    row[:] = 0.0
                    self._traction_on[j] = False
                continue
            np.multiply(self._lag_powers[:n], last - held, out=row)
            row += held
            self._traction_last[j] = float(row[-1])
            self._traction_on[j] = True
        self._ripple_first = None

    def wave(self, j: int, first: int, times: np.ndarray) -> np.ndarray:
        """Traction return current i_tr(t) of train j (DC with rectifier ripple, or AC 50 Hz);
        ``first`` is the frame's first sample index, ``times`` its sample times."""
        if not (self.ac or self.dc) or not self._traction_on[j]:
            return np.zeros(times.size)
        if self._ripple_first != first:       # the waveform is the same for every train: once a frame
            if self._ripple_period is not None:
                self._ripple = self._ripple_table.take((first + self._index[:times.size]) % self._ripple_period)
            else:
                self._ripple = self._ripple_wave(times)
            self._ripple_first = first
        return self._i_traction[j, :times.size] * self._ripple     # smoothed per sample (new_frame)

    def _ripple_wave(self, times: np.ndarray) -> np.ndarray:
        """Waveform of a unit traction current: DC with 300/600 Hz rectifier ripple, AC 50 Hz
        with odd harmonics (rms 1)."""
        s = self.settings
        if self.dc:
            r300, r600 = s.dc_ripple
            return 1.0 + r300 * np.sin(2 * np.pi * 300 * times) + r600 * np.sin(2 * np.pi * 600 * times)
        h3, h5 = s.ac_harmonics
        w = 2 * np.pi * 50 * times
        return np.sqrt(2.0) * (np.sin(w) + h3 * np.sin(3 * w) + h5 * np.sin(5 * w))

    def under_coil(self, j: int, first: int, times: np.ndarray, coil: np.ndarray) -> np.ndarray:
        """Asymmetric part of train j's traction return current averaged over its coil, a(x)·i_tr(t);
        ``coil`` holds the positions of the coil's sensitivity points (points × samples)."""
        section = self.bank.section_of(coil)
        a = np.where(section >= 0, self.asymmetry[np.clip(section, 0, self.bank.count - 1)], 0.0)
        for lo, joint, hi in self.bank.joint_zones:
            # between the bond leads the centre-tap jumper evens the rails out: the asymmetric
            # part falls linearly to zero at the joint and rises again beyond it
            a = np.where((coil >= lo) & (coil < hi), a * np.abs(coil - joint) / (joint - lo), a)
        return a.mean(axis=0) * self.wave(j, first, times)
