"""Traction interference at the receiver coils: the loop-equivalent current the traction
return current makes under the coils, c(x)·i_traction(t), whose time derivative the coils turn
into EMF (no FMI here; docs/rail_line.md, traction interference at the joints).

* c(x) = a(x) + (joint_coupling + mismatch_coupling·m)·b(x):
  - a(x): the rails' asymmetry, one value per section (seeded, 1–5 %), passing from one
    section's to the next across the joint's bond-lead zone;
  - b(x): the coils' coupling to the traction current in the impedance bonds' leads and the
    jumper between their centre taps, a trapezoid around each joint (1.31 m ramps, 0.58 m top,
    fitted to the joints paper's 0.059 s half-amplitude width and 5 Hz spectral maximum at
    80 km/h); its peak coupling gives the paper's 0.925 V at 80 km/h and the reference current,
    and a coil-pair mismatch m adds the common-mode part (5 % → the paper's 5 V).
  Under DC traction the coils' motion over b(x) gives two pulses of opposite polarity per
  joint (∝ v, each 1.31 m / v wide); under AC traction a 50 Hz burst whose amplitude does not
  depend on speed and whose duration is the zone's length over v.
* i_traction(t): the train's traction current through a first-order lag (the traction
  circuit's inductance), times the rectifier ripple of a DC line (300/600 Hz, and 100/200 Hz
  from an unbalanced supply) or the 50 Hz wave with odd harmonics (150/250/350 Hz) of an AC
  line. A line without electrification has none.
"""
from __future__ import annotations

import bisect

import numpy as np

from fmus.data.loader import Line
from fmus.dsp.periodic import period_samples
from fmus.rail_line.geometry import LineGeometry

_RIPPLE_MAX_SAMPLES = 1 << 14    # traction ripple kept as a table when it repeats within this

# the joints paper's DC pulse pair at 22.2 m/s (80 km/h) (docs/sources.md#interference-at-insulated-joints)
PAPER_SPEED_MPS = 80.0 / 3.6
PAPER_HALF_WIDTH_S = 0.059           # each pulse, at half amplitude
PAPER_SPECTRUM_PEAK_HZ = 5.0         # the envelope of the pair's spectrum
PAPER_EMF_V = 0.925                  # the largest EMF, coils matched
PAPER_MISMATCH = 0.05                # coil-pair asymmetry of the paper's second figure ...
PAPER_MISMATCH_EMF_V = 5.0           # ... and its EMF
REFERENCE_TRACTION_A = 1000.0        # the traction current of the paper's figures [U] (not given)
JOINT_RAMP_M = PAPER_HALF_WIDTH_S * PAPER_SPEED_MPS    # 1.31 m: a pulse's half width × v
JOINT_TOP_M = 0.575                  # fitted: puts the pair's spectral maximum at 5 Hz [D]


def joint_couplings(coil_gain_h: float) -> tuple:
    """(joint_coupling, mismatch_coupling): the peak of b(x) in loop-equivalent amperes per
    ampere of traction current with matched coils, and its growth per unit coil mismatch, from
    the paper's 0.925 V and 5 V at 22.2 m/s and the reference current. The DC EMF's peak is
    coil_gain · I · v · coupling / ramp (the slope of b times the speed)."""
    per_coupling = coil_gain_h * REFERENCE_TRACTION_A * PAPER_SPEED_MPS / JOINT_RAMP_M
    joint = PAPER_EMF_V / per_coupling
    return joint, (PAPER_MISMATCH_EMF_V - PAPER_EMF_V) / per_coupling / PAPER_MISMATCH


class TractionInterference:
    def __init__(self, line: Line, settings, trains: int, frame: int, geometry: LineGeometry):
        s = settings
        self.settings, self.trains, self.geometry = s, trains, geometry
        count = geometry.count
        self.ac = line.electrification == "AC25000"
        self.dc = line.electrification == "DC3000"
        lo, hi = s.asymmetry_range
        rng = np.random.default_rng(s.seed)
        self.asymmetry = rng.uniform(lo, hi, count) * rng.choice([-1.0, 1.0], count)
        joint, per_mismatch = joint_couplings(s.coil_gain_h)
        self.joint_peak = joint + per_mismatch * s.coil_mismatch     # peak of the coupling b(x)
        # sorted: the nearest joint is found by binary search whatever order the line file lists them in
        self.joints = np.sort(np.array([joint for _, joint, _ in geometry.joint_zones], dtype=float))
        # each bond-lead zone with the sections on either side (−1: off the line); indices, not
        # values, because a study may overwrite the asymmetries after construction
        # (a separation zone between TVM sections likewise, over its length, without a joint's trapezoid)
        self.lead_zones = sorted((lo_m, hi_m, geometry.section_at(lo_m - 1e-9), geometry.section_at(hi_m))
                                 for lo_m, _, hi_m in geometry.joint_zones + geometry.separation_zones)
        self._lead_starts = [zone[0] for zone in self.lead_zones]
        self._lead_ends = [zone[1] for zone in self.lead_zones]
        self.reach_m = JOINT_RAMP_M + 0.5 * JOINT_TOP_M     # b(x) is zero farther than this from a joint
        dt = 1.0 / s.fs_hz
        lag = np.exp(-dt / s.traction_time_constant_s)
        self._lag_powers = lag ** np.arange(1, frame + 1)
        self._lag = float(self._lag_powers[0])
        self._traction_last = [0.0] * trains                   # smoothed current at the last sample
        self._traction_on = [False] * trains
        self._traction_settled = [False] * trains             # the row is the held value at every sample
        self._i_traction = np.zeros((trains, frame))
        self._index = np.arange(frame)
        self._ripple_first = None                              # the frame's ripple waveform, once computed
        self._ripple = np.zeros(frame)
        ripple_hz = (100.0, 200.0, 300.0, 600.0) if self.dc else (50.0, 150.0, 250.0, 350.0)
        self._ripple_period = period_samples([1.0 / f for f in ripple_hz], s.fs_hz, _RIPPLE_MAX_SAMPLES)
        if self._ripple_period is not None and (self.dc or self.ac):
            # one period and a frame's length of its continuation: a frame is a slice from
            # (first sample mod period), no index array (the same values as a look-up per sample)
            table = self._ripple_wave(np.arange(self._ripple_period) * dt)
            self._ripple_table = table[np.arange(self._ripple_period + frame) % self._ripple_period]

    def new_frame(self, i_traction: np.ndarray, n: int) -> None:
        """The traction current reaches the rails through the traction circuit's inductance
        (smoothing reactor, motors): a first-order lag of ``traction_time_constant``. It also
        turns the steps of a slowly sampled traction FMU into ramps, which the coils would
        otherwise see as EMF spikes of tens of volts. The input is held over the frame, so the
        lag's response is closed-form: y[i] = c + (y[−1] − c)·λ^(i+1)."""
        for j, held in zip(range(self.trains), i_traction.tolist()):
            last = self._traction_last[j]
            if held == last == 0.0:
                if self._traction_on[j]:
                    self._i_traction[j, :n] = 0.0
                    self._traction_on[j] = False
                    self._traction_settled[j] = False
                continue
            if held == last and self._traction_settled[j]:
                continue                   # the lag has reached the held value: the row is all held
            if n == 1:                     # one sample a frame: the same operations in floats
                self._traction_last[j] = self._i_traction[j, 0] = self._lag * (last - held) + held
            else:
                row = self._i_traction[j, :n]
                np.multiply(self._lag_powers[:n], last - held, out=row)
                row += held
                self._traction_last[j] = float(row[-1])
            self._traction_on[j] = True
            self._traction_settled[j] = held == last and n == self._i_traction.shape[1]
        self._ripple_first = None

    def wave(self, j: int, first: int, times: np.ndarray) -> np.ndarray:
        """Traction return current i_tr(t) of train j (DC with rectifier ripple, or AC 50 Hz);
        ``first`` is the frame's first sample index, ``times`` its sample times."""
        if not (self.ac or self.dc) or not self._traction_on[j]:
            return np.zeros(times.size)
        if self._ripple_first != first:       # the waveform is the same for every train: once a frame
            if self._ripple_period is not None:
                start = first % self._ripple_period
                self._ripple = self._ripple_table[start:start + times.size]    # a view: only read
            else:
                self._ripple = self._ripple_wave(times)
            self._ripple_first = first
        return self._i_traction[j, :times.size] * self._ripple     # smoothed per sample (new_frame)

    def wave_sample(self, j: int, first: int, times: np.ndarray) -> float:
        """``wave`` for a frame of one sample, as a float (a look-up, not a view and a product)."""
        if not (self.ac or self.dc) or not self._traction_on[j]:
            return 0.0
        ripple = self._ripple_table.item(first % self._ripple_period) if self._ripple_period is not None \
            else self._ripple_wave(times).item(0)
        return self._i_traction.item(j, 0) * ripple

    def _ripple_wave(self, times: np.ndarray) -> np.ndarray:
        """Waveform of a unit traction current: DC with the 300/600 Hz rectifier ripple and the
        100/200 Hz even harmonics of an unbalanced supply, AC 50 Hz with its 3rd, 5th and 7th
        harmonics (rms 1 of the fundamental). The even harmonics on DC and the odd on AC are
        what ALSU's tones sit between (docs/sources.md#traction-current-interference)."""
        s = self.settings
        if self.dc:
            r300, r600 = s.dc_ripple
            r100, r200 = s.dc_even_harmonics
            return (1.0 + r300 * np.sin(2 * np.pi * 300 * times) + r600 * np.sin(2 * np.pi * 600 * times)
                    + r100 * np.sin(2 * np.pi * 100 * times) + r200 * np.sin(2 * np.pi * 200 * times))
        h3, h5, h7 = s.ac_harmonics
        w = 2 * np.pi * 50 * times
        return np.sqrt(2.0) * (np.sin(w) + h3 * np.sin(3 * w) + h5 * np.sin(5 * w) + h7 * np.sin(7 * w))

    def coupling(self, coil: np.ndarray) -> np.ndarray:
        """c(x) at the positions ``coil`` (any shape): the rails' asymmetry, passing linearly from
        one section's to the next between the bond leads, plus the bond leads' and jumper's
        trapezoid around each joint."""
        geometry = self.geometry
        section = geometry.section_of(coil)
        c = np.where(section >= 0, self.asymmetry[np.clip(section, 0, geometry.count - 1)], 0.0)
        first, last = float(coil.min()), float(coil.max())
        for lo, hi, before, beyond in self.lead_zones[bisect.bisect_left(self._lead_ends, first):
                                                      bisect.bisect_right(self._lead_starts, last)]:
            inside = (coil >= lo) & (coil < hi)
            if inside.any():
                a0 = self.asymmetry[before] if before >= 0 else 0.0
                a1 = self.asymmetry[beyond] if beyond >= 0 else 0.0
                c = np.where(inside, a0 + (a1 - a0) * (coil - lo) / (hi - lo), c)
        joints = self.joints
        if joints.size:
            # the nearest joint's trapezoid (joints are metres apart at the least)
            if joints.size > 1:
                i = np.clip(np.searchsorted(joints, coil), 1, joints.size - 1)
                nearest = joints[np.where(np.abs(coil - joints[i - 1]) < np.abs(coil - joints[i]), i - 1, i)]
            else:
                nearest = joints[0]
            distance = np.abs(coil - nearest)
            c = c + self.joint_peak * np.clip((self.reach_m - distance) / JOINT_RAMP_M, 0.0, 1.0)
        return c

    def under_coil(self, j: int, first: int, times: np.ndarray, coil: np.ndarray) -> np.ndarray:
        """Train j's loop-equivalent traction current averaged over its coil, c(x)·i_tr(t);
        ``coil`` holds the positions of the coil's sensitivity points (points × samples); zero
        without traction current (an unelectrified line, or the train's current off and settled)."""
        if not (self.ac or self.dc) or not self._traction_on[j]:
            return np.zeros(times.size)
        return self.coupling(coil).mean(axis=0) * self.wave(j, first, times)
