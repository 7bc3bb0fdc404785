"""Where the line's track circuits lie (no FMI here; docs/rail_line.md): each section's track
circuit (its feed leads, network nodes and segments, its ballast; a TVM section's zones), the
insulated joints' bond-lead zones and the TVM sections' separation zones, each section's code
carrier and track-circuit frequency, and which section and which network node a position falls
on; for a code of several tones (ALSU) the band the rails' impedance follows.
"""
from __future__ import annotations

import bisect
import math
from dataclasses import replace
from typing import Tuple

import numpy as np

from fmus.data.loader import (DEFAULT_ZONE_LENGTH_M, TVM_TRACK_CARRIERS_HZ, TVM_TRANSMITTER, Line,
                              check_carrier_under_traction)
from fmus.rail_line.track_circuit import (UM71_RECEIVER_R_OHM, UM71_TRANSMITTER_R_OHM, SeparationZone,
                                         TrackCircuit)


def _section_parameters(c, line: Line, section):
    """A section's circuit parameters: its ballast, and for a UM71 circuit its zones and equipment."""
    ballast = c.ballast_ohm_km if c.ballast_ohm_km > 0 else float(section.ballast_ohm_km)
    zone = _zone(line, section)
    if zone is None:
        return replace(c, ballast_ohm_km=ballast)
    return replace(c, ballast_ohm_km=ballast, zone=zone, feed_r_ohm=UM71_TRANSMITTER_R_OHM,
                   relay_r_ohm=UM71_RECEIVER_R_OHM)


def _zone(line: Line, section):
    """A UM71 section's separation zones (None: an ALSN circuit between insulated joints)."""
    if section.transmitter != TVM_TRANSMITTER:
        return None
    own = float(section.carrier_hz)
    pair = next(track for track in TVM_TRACK_CARRIERS_HZ if own in track)
    zones = line.separation_zones
    length = zones.get(float(section.end_m), zones.get(float(section.start_m), DEFAULT_ZONE_LENGTH_M))
    return SeparationZone(own, pair[1] if own == pair[0] else pair[0], length)


class LineGeometry:
    """The line's K track circuits along the line, and positions → sections and nodes."""

    def __init__(self, line: Line, settings):
        s, c = settings, settings.circuit
        self.count = len(line.sections)
        leads = [(float(j["position_m"]), float(j.get("bond_lead_offset_m", 1.0))) for j in line.joints]
        offsets = {round(position, 6): offset for position, offset in leads}
        # each circuit's ballast: the line file's per-section minimum unless the `ballast` parameter
        # overrides all; a TVM (UM71) circuit ends in tuned separation zones for its track's pair of
        # carriers (the zone's length: the line file's at the section's exit, else at its entry)
        self.circuits = [TrackCircuit(sec.start_m, sec.end_m, offsets.get(round(sec.end_m, 6), 1.0),
                                      _section_parameters(c, line, sec))
                         for sec in line.sections]
        # (bond lead before, joint, bond lead beyond) of every insulated joint
        self.joint_zones = [(position - offset, position, position + offset) for position, offset in leads]
        # (start, boundary, end) of every tuned separation zone between two TVM sections: the
        # traction current's asymmetry passes from one section's to the next across it
        self.separation_zones = [(position - 0.5 * length, position, position + 0.5 * length)
                                 for position, length in sorted(line.separation_zones.items())]
        self.starts = np.array([sec.start_m for sec in line.sections])
        self.ends = np.array([sec.end_m for sec in line.sections])
        self._ends_ext = np.append(self.ends, -np.inf)
        self.starts_list = self.starts.tolist()
        self.ends_list = self.ends.tolist()
        self.feed_list = [float(circuit.feed_m) for circuit in self.circuits]
        if s.carrier_hz:          # the parameter overrides the line file's carriers: the same rule holds
            check_carrier_under_traction(s.carrier_hz, line.electrification, "parameter carrier")
        # a code of several tones (ALSU, ``tone_band_hz``): the rails follow the √f law across the
        # band (TrackCircuit.network), the phasor tables and the wheelset chain stand at its
        # geometric centre
        self.band_hz = tuple(s.tone_band_hz) if s.tone_band_hz[1] > 0 else None
        centre = float(np.sqrt(s.tone_band_hz[0] * s.tone_band_hz[1])) if self.band_hz else 0.0
        self.carriers = np.array([s.carrier_hz or centre or sec.carrier_hz for sec in line.sections], dtype=float)
        # train detection works at the track circuit's own frequency (the line file's): a digital
        # cab-signal carrier (174.38 / 175 Hz) is superimposed on it and never feeds the relay
        self.track_frequencies = np.array([sec.carrier_hz for sec in line.sections], dtype=float)
        self.spacing_list = [float(circuit.nodes_m[1] - circuit.nodes_m[0]) for circuit in self.circuits]
        self.nodes_m = [np.ascontiguousarray(circuit.nodes_m, dtype=float) for circuit in self.circuits]
        self.segments_list = [circuit.segments for circuit in self.circuits]
        # positions where a train's head or tail changes section or clipping to the feed
        self.edges = sorted(set(self.starts_list + self.ends_list + self.feed_list))

    def section_of(self, x):
        """Section index of every position in the array ``x`` (−1: outside the line)."""
        k = np.searchsorted(self.starts, x, side="right") - 1
        return np.where(x < self._ends_ext[k], k, -1)      # k = −1 reads −inf: outside

    def section_at(self, x: float) -> int:
        """Section index of one position (−1: outside the line)."""
        k = bisect.bisect_right(self.starts_list, x) - 1
        return k if k >= 0 and x < self.ends_list[k] else -1

    def node_at(self, k: int, x: float) -> int:
        """Network node of section k nearest to x (clipped to the circuit: beyond the feed leads
        the rails carry no signal current, so a wheelset there shunts at the feed node)."""
        return min(max(round((min(x, self.feed_list[k]) - self.starts_list[k]) / self.spacing_list[k]), 0),
                   self.segments_list[k])

    def interval(self, x: float) -> Tuple[float, float]:
        """Open interval around a head or tail position x over which its section, its clipping
        to the feed and its nearest node do not change."""
        edges = self.edges
        i = bisect.bisect_right(edges, x)
        lo, hi = (edges[i - 1] if i > 0 else -math.inf), (edges[i] if i < len(edges) else math.inf)
        k = self.section_at(x)
        if 0 <= k and x < self.feed_list[k]:
            start, spacing = self.starts_list[k], self.spacing_list[k]
            middle = round((x - start) / spacing)
            lo, hi = max(lo, start + (middle - 0.5) * spacing), min(hi, start + (middle + 0.5) * spacing)
        return lo, hi
