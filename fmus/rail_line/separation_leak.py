"""The neighbour's carrier leaking through a tuned separation zone (no FMI here; docs/rail_line.md,
separation zones): how much of the next section's carrier reaches the coils of a train running
toward a zone, against its own section's carrier there.

The rail line solves every track circuit as its own network (its ends in their zones), so its
coil EMF carries the own carrier only; this module solves the two circuits and the zone between
them together at the neighbour's carrier, by two-port chains (axle_chain.py) as the wheelset
amplitudes are: section B ahead, free, fed by its transmitter at its far end (its carrier f_B
arrives at its entry end, where B's tuned unit is a high impedance for it); the zone's rails;
section A's tuned unit (a series resonance at f_B: a short) in parallel with A's transmitter and
A's rails with the train on them. What the short leaves at A's feed node drives A's rails, and
all of it flows to the train's first axle, under the coils. The own carrier f_A there is the
wheelset chain's. Both transmitters send the same amplitude.

The leak's worst case is searched over the head's position in A, the ballast of A and of B (the
section's minimum and the line's maximum) and both orders of the pair's carriers.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Optional, Sequence

import numpy as np

from fmus.rail_line.axle_chain import RailLine, SectionChain
from fmus.rail_line.track_circuit import (CircuitParameters, Faults, SeparationZone, TrackCircuit, UM71_RECEIVER_R_OHM,
                                          UM71_TRANSMITTER_R_OHM, end_admittance, near_unit_admittance,
                                          rail_impedance)


@dataclass(frozen=True)
class Leak:
    """The neighbour's carrier against the own one in the rails under a train's coils."""
    ratio: float                 # |neighbour's current| / |own current| under the coils
    emf_ratio: float             # the same for the coil EMF (M·di/dt: × f_neighbour / f_own)
    own_hz: float
    neighbour_hz: float
    head_before_zone_m: float    # the train's first axle this far before the zone
    ballast_own_ohm_km: float
    ballast_neighbour_ohm_km: float
    own_current_a: float         # per volt of u_tx, amplitude
    neighbour_current_a: float


def _params(carrier_hz: float, other_hz: float, ballast_ohm_km: float, zone_length_m: float,
            base: CircuitParameters) -> CircuitParameters:
    return replace(base, ballast_ohm_km=ballast_ohm_km, zone=SeparationZone(carrier_hz, other_hz, zone_length_m),
                   feed_r_ohm=UM71_TRANSMITTER_R_OHM, relay_r_ohm=UM71_RECEIVER_R_OHM)


def leak_at(head_before_zone_m: float, own_hz: float, neighbour_hz: float, ballast_own_ohm_km: float,
            ballast_neighbour_ohm_km: float, wheelsets_m: Sequence[float], length_m: float = 1500.0,
            neighbour_length_m: float = 1500.0, zone_length_m: float = 26.0, lead_offset_m: float = 1.0,
            transformer_ratio: float = 2.5, base: Optional[CircuitParameters] = None) -> Leak:
    """The leak with a train's first axle ``head_before_zone_m`` before the zone at the end of
    section A (carrier ``own_hz``, ``length_m`` long), its wheelsets ``wheelsets_m`` behind the
    first (m, ascending from 0), section B beyond the zone free (``neighbour_hz``)."""
    base = base or CircuitParameters()
    p_a = _params(own_hz, neighbour_hz, ballast_own_ohm_km, zone_length_m, base)
    p_b = _params(neighbour_hz, own_hz, ballast_neighbour_ohm_km, zone_length_m, base)
    section_a = TrackCircuit(0.0, length_m, lead_offset_m, p_a)
    section_b = TrackCircuit(0.0, neighbour_length_m, lead_offset_m, p_b)
    head = length_m - head_before_zone_m
    if not section_a.start_m < head <= section_a.feed_m:
        raise ValueError(f"head {head:g} m is not between the entry and the feed of a {length_m:g} m section")
    offsets = np.asarray(wheelsets_m, dtype=float)
    positions = head - offsets[::-1]                       # ascending, the last wheelset first
    first = int(np.searchsorted(positions, section_a.start_m))

    def runs(chain: SectionChain):
        table = chain.table(0, positions - positions[0])
        return [(float(positions[first]), float(head), table, first, len(positions) - 1)]

    own_chain = SectionChain(section_a, Faults(), own_hz, transformer_ratio)
    own_current = own_chain.solve(runs(own_chain), [head])[0][0]
    # the neighbour's carrier: B's rails (free) as a Norton source at its entry node
    w = 2 * np.pi * neighbour_hz
    rails_b = RailLine(p_b, ballast_neighbour_ohm_km, neighbour_hz)
    a, b, c, d = rails_b.matrix(section_b.feed_m - section_b.start_m)
    feed_b = 1.0 / p_b.feed_r_ohm + end_admittance(p_b, ballast_neighbour_ohm_km, neighbour_hz)
    short_circuit = transformer_ratio / p_b.feed_r_ohm / (d + feed_b * b)
    source_admittance = (c + feed_b * a) / (d + feed_b * b)
    # the zone: B's tuned unit (high at f_B), B's receiver and the zone's ballast (A's, as section A's
    # own network has it: track_circuit.end_admittance) at B's entry; its rails
    km = zone_length_m / 1000.0
    r_zone, l_zone = rail_impedance(p_a, neighbour_hz)
    zone_rails = complex(r_zone * km, w * l_zone * km)
    at_entry_b = near_unit_admittance(p_b, neighbour_hz) + 1.0 / p_b.relay_r_ohm + km / ballast_own_ohm_km
    # A's feed node: A's tuned unit (a short at f_B), its transmitter's resistance, its rails and the train
    chain_b_in_a = SectionChain(section_a, Faults(), neighbour_hz, transformer_ratio)
    rails_a, per_volt = chain_b_in_a.seen_from_feed(runs(chain_b_in_a), [head])
    at_feed_a = near_unit_admittance(p_a, neighbour_hz) + 1.0 / p_a.feed_r_ohm + rails_a
    v_feed_a = short_circuit / ((1.0 + zone_rails * at_feed_a) * (source_admittance + at_entry_b) + at_feed_a)
    neighbour_current = abs(v_feed_a * per_volt[0])
    ratio = neighbour_current / own_current
    return Leak(float(ratio), float(ratio * neighbour_hz / own_hz), own_hz, neighbour_hz, head_before_zone_m,
                ballast_own_ohm_km, ballast_neighbour_ohm_km, float(own_current), float(neighbour_current))


# the nearest a train's first wheelset comes to the zone with its coils still over its own
# section's rails: the feed leads 1 m before the zone, the coils' window reaching 1.65 m ahead of
# the wheelset (RailSettings: coil_offset_m + coil_length_m / 2), 0.05 m to spare. Nearer, the
# coils are over the last metre and the zone, which the lumped zone does not resolve
NEAREST_HEAD_BEFORE_ZONE_M = 2.7


def worst_leak(wheelsets_m: Sequence[float], pair_hz=(1700.0, 2300.0), ballasts_ohm_km=(1.0, 50.0),
               heads_before_zone_m: Optional[Sequence[float]] = None, **section) -> Leak:
    """The largest coil-EMF leak ratio over the head's position before the zone (the coils still
    before it), both sections' ballast (each of ``ballasts_ohm_km``) and both orders of the
    carriers of ``pair_hz``."""
    length = section.get("length_m", 1500.0)
    heads = heads_before_zone_m if heads_before_zone_m is not None else \
        np.concatenate([np.arange(NEAREST_HEAD_BEFORE_ZONE_M, 20.0, 0.5), np.geomspace(20.0, length - 1.0, 40)])
    worst = None
    for own, neighbour in (pair_hz, pair_hz[::-1]):
        for ballast_own in ballasts_ohm_km:
            for ballast_neighbour in ballasts_ohm_km:
                for before in heads:
                    leak = leak_at(float(before), own, neighbour, ballast_own, ballast_neighbour, wheelsets_m, **section)
                    if worst is None or leak.emf_ratio > worst.emf_ratio:
                        worst = leak
    return worst
