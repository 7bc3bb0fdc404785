"""The receiver coils' pickup: code current in the rails → coil EMF per train (no FMI here;
docs/rail_line.md).

Coils ``coil_offset`` (1.5 m) ahead of the first wheelset, EMF = M·d/dt of the loop current
they see, which is

* over their own section, between the wheelset and the feed leads: the rail current arriving
  from the feed at the train's first axle (what the axles of any train ahead in the section leave);
* between the feed leads and the exit joint: nothing (the ≈ 1 m null zone);
* over the next section, before the wheelset has crossed: that section's entry-end current,
  weak because it is not shunted yet (the ≈ 1.5 m weak zone);

averaged over the coil's sensitivity length, plus the traction interference under the coil
(traction_interference.py). The time derivative is taken on the sampled current, so the motion
term v·∂i/∂x is included. Positions outside the line are reported, not errors.
"""
from __future__ import annotations

import bisect
import math
from typing import List, Optional, Sequence

import numpy as np

from fmus.rail_line.circuit_bank import FrameCurrents, TrackCircuitBank
from fmus.rail_line.traction_interference import TractionInterference

_COIL_POINTS = 5


class CoilPickup:
    def __init__(self, line_length_m: float, settings, trains: int, bank: TrackCircuitBank,
                 interference: TractionInterference):
        s = settings
        self.settings, self.trains, self.interference = s, trains, interference
        self.amplitudes = bank.amplitudes
        self.geometry = geometry = bank.geometry
        self.line_length_m = line_length_m
        self._coil_spread = (np.linspace(0.0, 1.0, _COIL_POINTS) - 0.5) * s.coil_length_m
        self._emf_gain = s.fs_hz * s.coil_gain_h
        self._last_current = [0.0] * trains
        self._sensing = [False] * trains
        # where the coil needs the sample-by-sample treatment: around the joints' bond-lead zones,
        # over the separation zones and from each feed to its section's end, widened by the coil length
        margin = s.coil_length_m
        reach = interference.reach_m
        bands = sorted([(min(lo, joint - reach) - margin, max(hi, joint + reach) + margin)
                        for lo, joint, hi in geometry.joint_zones] +
                       [(lo - margin, hi + margin) for lo, _, hi in geometry.separation_zones] +
                       [(c.feed_m - margin, c.end_m + margin) for c in geometry.circuits])
        merged: List[List[float]] = []
        for lo, hi in bands:                    # touching or overlapping bands merged: disjoint, sorted
            if merged and lo <= merged[-1][1]:
                merged[-1][1] = max(merged[-1][1], hi)
            else:
                merged.append([lo, hi])
        self._band_lo = [lo for lo, _ in merged]
        self._band_hi = [hi for _, hi in merged]

    def sense(self, first: int, times: np.ndarray, heads: np.ndarray, currents: FrameCurrents, out,
              standing_at: Sequence[Optional[float]]) -> None:
        """Every train's coil EMF, code current under its first wheelset, coil section and
        off-line flag for the frame of sample index ``first`` (``times`` its sample times,
        ``heads`` the trains' first-wheelset positions per sample, ``standing_at`` the position
        of each train that stands over the whole frame, else None); written into ``out``."""
        s, amplitudes, geometry, interference = self.settings, self.amplitudes, self.geometry, self.interference
        n = times.size
        ends, feeds = geometry.ends_list, geometry.feed_list
        for j in range(self.trains):
            head = heads[j]
            head_first, head_last = float(head[0]), float(head[-1])
            out.coil_section[j] = geometry.section_at(head_last + s.coil_offset_m) + 1
            if head_last + s.coil_offset_m + s.coil_length_m < 0.0 or head_first > self.line_length_m:
                out.off_line[j] = True                   # no coil over the line: nothing to sense
                if self._sensing[j]:
                    out.e_coil[j, :n] = 0.0
                    out.i_axle[j] = 0.0
                    self._sensing[j] = False
                continue
            out.off_line[j] = head_last < 0 or head_last > self.line_length_m
            k = geometry.section_at(head_first)
            first_coil = head_first + s.coil_offset_m + self._coil_spread[0]
            last_coil = head_last + s.coil_offset_m + self._coil_spread[-1]
            if (k >= 0 and head_last < ends[k] and last_coil <= feeds[k]
                    and not self._near_joint(first_coil, last_coil)):
                # the usual frame: wheelset and whole coil over the same section, clear of joints
                if n == 1:
                    self._usual_sample(out, j, k, first, times, head, currents, standing_at[j])
                    continue
                shunt_current = currents.ahead(k, j) * amplitudes.scale(k, head, j, times, standing_at[j])
                current = shunt_current + interference.asymmetry[k] * interference.wave(j, first, times)
                i_axle = shunt_current
            else:
                current, i_axle = self._coil_general(j, first, times, head, currents)
            self._emf(out.e_coil[j], j, current, n)
            out.i_axle[j] = math.sqrt(float(np.dot(i_axle, i_axle)) / n)

    def _usual_sample(self, out, j: int, k: int, first: int, times: np.ndarray, head: np.ndarray,
                      currents: FrameCurrents, standing_at: Optional[float]) -> None:
        """The usual frame of a build with one sample per frame (the hardware-in-the-loop case):
        the frame path's quantities, the EMF and the rms in Python floats instead of numpy
        calls on one-element arrays."""
        interference = self.interference
        scale = self.amplitudes.scale(k, head, j, times, standing_at)
        shunt_current = currents.ahead(k, j).item(0) * (scale if isinstance(scale, float) else scale.item(0))
        current = shunt_current + interference.asymmetry.item(k) * interference.wave_sample(j, first, times)
        previous = self._last_current[j] if self._sensing[j] else current      # no step at the first sample
        out.e_coil[j, 0] = (current - previous) * self._emf_gain
        self._last_current[j] = current
        self._sensing[j] = True
        out.i_axle[j] = abs(shunt_current)            # the rms of one sample

    def _emf(self, emf: np.ndarray, j: int, current: np.ndarray, n: int) -> None:
        """EMF = M·di/dt on the sampled current, continuing from the previous frame's last sample."""
        previous = self._last_current[j] if self._sensing[j] else current[0]   # no step at the first sample
        emf[0] = current[0] - previous
        np.subtract(current[1:], current[:-1], out=emf[1:n])
        emf[:n] *= self._emf_gain
        self._last_current[j] = float(current[-1])
        self._sensing[j] = True

    def _near_joint(self, lo: float, hi: float) -> bool:
        """Does [lo, hi] touch a joint band (bands merged, sorted, disjoint)?"""
        i = bisect.bisect_right(self._band_hi, lo)         # first band ending after lo
        return i < len(self._band_lo) and self._band_lo[i] <= hi

    def _coil_general(self, j: int, first: int, times: np.ndarray, head: np.ndarray, currents: FrameCurrents):
        """Sample by sample, the share of the coil's sensitivity window over each stretch of
        rail: its own section up to the feed leads (shunt current), the dead end from the leads to
        the joint (nothing), the next section's entry end (its unshunted current)."""
        s, amplitudes, geometry = self.settings, self.amplitudes, self.geometry
        n = times.size
        axle_section = geometry.section_of(head)
        centre = head + s.coil_offset_m
        lo, hi = centre - 0.5 * s.coil_length_m, centre + 0.5 * s.coil_length_m
        width = max(s.coil_length_m, 1e-9)

        def share(a, b):
            return np.clip(np.minimum(hi, b) - np.maximum(lo, a), 0.0, None) / width if s.coil_length_m > 0 \
                else ((centre >= a) & (centre < b)).astype(float)
        seen = np.zeros(n)
        i_axle = np.zeros(n)
        for k in set(int(k) for k in np.unique(axle_section) if k >= 0):
            own = axle_section == k
            shunt_current = currents.ahead(k, j) * amplitudes.scale(k, head, j, times)
            i_axle = np.where(own, shunt_current, i_axle)
            view = share(-np.inf, geometry.circuits[k].feed_m) * shunt_current
            if k + 1 < geometry.count:
                beyond = share(geometry.ends[k], np.inf)
                if beyond.any():
                    view = view + beyond * currents.entry(k + 1)
            seen = np.where(own, view, seen)
        coil = centre[None, :] + self._coil_spread[:, None]
        return seen + self.interference.under_coil(j, first, times, coil), i_axle
