"""The track relays' calibration (no FMI here; docs/rail_line.md, relay calibration): each track
circuit's reference voltage from the three design regimes of the standard (normal, shunt and
control mode, docs/sources.md#track-circuits-and-rail-impedance, row 8) at the track circuit's own
frequency, a line refused when a circuit cannot meet them, and the relay-end level of any set of
wheelset shunts relative to that reference (what the relays read).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, Sequence, Tuple

import numpy as np

from fmus.data.loader import Line
from fmus.errors import FmuInputError
from fmus.rail_line.geometry import LineGeometry
from fmus.rail_line.axle_chain import SectionChain
from fmus.rail_line.track_circuit import Faults, TrackCircuit


@dataclass(frozen=True)
class Calibration:
    """A track circuit's design levels (relay-end voltage / calibrated reference, docs/rail_line.md)."""
    length_m: float
    ballast_min_ohm_km: float
    ballast_max_ohm_km: float
    normal_level: float      # free circuit, minimum ballast, minimum supply (= pick-up by construction)
    shunt_level: float       # worst 0.06 Ω shunt over all nodes, maximum ballast, maximum supply
    shunt_node: int          # where that worst shunt is (0 relay end … S feed end)
    control_level: float     # worst broken rail over all segments, either ballast, maximum supply
    shunt_margin: float      # drop-out / shunt_level − 1 (required ≥ settings.shunt_margin)


class RelayCalibration:
    """Every circuit's calibration (``table``) and reference voltage per unit feed
    (``reference``); the line refused at construction when a circuit cannot be calibrated."""

    def __init__(self, line: Line, geometry: LineGeometry, settings):
        self.settings, self.geometry = settings, geometry
        self.g_shunt = 1.0 / settings.circuit.shunt_r_ohm
        self.ballast_max_ohm_km = float(line.max_ballast_ohm_km)      # the loader gives its default
        self.table = self._calibrate(line)

    def _design_levels(self, circuit: TrackCircuit, frequency_hz: float, ballast_min: float, ballast_max: float):
        """Relay-end voltages per unit feed at the track circuit's frequency, from the wheelset
        chain (axle_chain.py): (free circuit at the minimum ballast; the worst 0.06 Ω shunt over
        all nodes at the maximum ballast and its node; the worst broken rail over all segments
        (at each segment's middle) at either ballast)."""
        worst_control = 0.0
        middles = 0.5 * (circuit.nodes_m[:-1] + circuit.nodes_m[1:])
        for ballast in sorted({ballast_min, ballast_max}):     # one, when a circuit's minimum is the line's maximum
            for broken in middles:
                chain = SectionChain(circuit, Faults(ballast, float(broken)), frequency_hz, 1.0)
                worst_control = max(worst_control, chain.solve(())[2])
        normal = SectionChain(circuit, Faults(ballast_min), frequency_hz, 1.0).solve(())[2]
        chain = SectionChain(circuit, Faults(ballast_max), frequency_hz, 1.0)
        shunted = [chain.solve(chain.shunts_at((float(x),)))[2] for x in circuit.nodes_m]
        worst_node = int(np.argmax(shunted))
        return normal, float(shunted[worst_node]), worst_node, worst_control

    def _levels(self, circuit: TrackCircuit, carrier_hz: float) -> Tuple[Calibration, float]:
        """Calibrate one circuit (docs/rail_line.md, relay calibration): the reference is set so that
        the free circuit at the minimum ballast and minimum supply reads exactly the pick-up
        level; the shunt and control modes are then read at the maximum supply."""
        s = self.settings
        tol = s.supply_tolerance
        ballast_min = circuit.params.ballast_ohm_km
        normal, shunt, node, control = self._design_levels(circuit, carrier_hz, ballast_min, self.ballast_max_ohm_km)
        reference = (1.0 - tol) * normal / s.relay_pick_up * (1.0 - 1e-9)   # 1e-9: picks up despite rounding
        shunt_level = (1.0 + tol) * shunt / reference
        control_level = (1.0 + tol) * control / reference
        return Calibration(float(circuit.feed_m - circuit.start_m), ballast_min, self.ballast_max_ohm_km,
                           float((1.0 - tol) * normal / reference), float(shunt_level), node, float(control_level),
                           float(s.relay_drop_out / max(shunt_level, control_level) - 1.0)), float(reference)

    def _calibrates(self, calibration: Calibration) -> bool:
        return calibration.shunt_margin >= self.settings.shunt_margin - 1e-12

    def _calibrate(self, line: Line) -> List[Calibration]:
        """Each circuit's reference voltage (self.reference) from the three design regimes
        (docs/sources.md#track-circuits-and-rail-impedance, row 8), or the line refused naming the
        circuit and the longest circuit that would calibrate."""
        s, geometry = self.settings, self.geometry
        table, references, known = [], [], {}
        for k, (circuit, section) in enumerate(zip(geometry.circuits, line.sections)):
            if circuit.params.ballast_ohm_km > self.ballast_max_ohm_km:
                raise FmuInputError(f"{line.path}: field block_sections[{k}].ballast_ohm_km: "
                                    f"{circuit.params.ballast_ohm_km:g} Ω·km is above the line's max_ballast_ohm_km "
                                    f"{self.ballast_max_ohm_km:g}")
            key = (circuit.feed_m - circuit.start_m, circuit.params, float(geometry.track_frequencies[k]))
            if key not in known:                 # sections of one design share their calibration
                known[key] = self._levels(circuit, geometry.track_frequencies[k])
            calibration, reference = known[key]
            if not self._calibrates(calibration):
                longest = self.longest_calibratable_m(k)
                raise FmuInputError(
                    f"{line.path}: field block_sections[{k}]: track circuit '{section.name}' "
                    f"({calibration.length_m:.0f} m feed to relay) cannot be calibrated for ballast "
                    f"{calibration.ballast_min_ohm_km:g}–{calibration.ballast_max_ohm_km:g} Ω·km and "
                    f"±{100 * s.supply_tolerance:g} % supply: a 0.06 Ω shunt leaves the relay at "
                    f"{calibration.shunt_level:.3f} of its reference, drop-out {s.relay_drop_out:g} needs a margin of "
                    f"{100 * s.shunt_margin:g} %; the longest circuit that calibrates is {longest:.0f} m")
            table.append(calibration)
            references.append(reference)
        self.reference = np.array(references)
        return table

    def longest_calibratable_m(self, k: int) -> float:
        """The longest circuit (feed leads to relay end) with section k's equipment and ballast
        range that meets the normal and shunt modes with the required margin (bisection, 1 m)."""
        circuit = self.geometry.circuits[k]
        offset = circuit.end_m - circuit.feed_m

        def ok(length_m):
            trial = TrackCircuit(0.0, length_m + offset, offset, circuit.params)
            return self._calibrates(self._levels(trial, self.geometry.track_frequencies[k])[0])
        lo, hi = 1.0, max(circuit.feed_m - circuit.start_m, 1.0)
        if ok(hi):
            while ok(2 * hi) and hi < 1e5:
                lo, hi = 2 * hi, 2 * hi
            hi = 2 * hi
        elif not ok(lo):
            return 0.0
        while hi - lo > 1.0:
            middle = 0.5 * (lo + hi)
            lo, hi = (middle, hi) if ok(middle) else (lo, middle)
        return lo

    def relay_level(self, k: int, shunts: Sequence[int], faults: Faults, supply: float = 1.0) -> float:
        """Relay-end voltage of section k with a 0.06 Ω shunt at each node in ``shunts`` under
        ``faults``, at ``supply`` × the nominal feed, relative to the circuit's calibrated
        reference (pick-up and drop-out are levels of this)."""
        circuit = self.geometry.circuits[k]
        chain = SectionChain(circuit, faults, self.geometry.track_frequencies[k], 1.0)
        positions = tuple(float(circuit.nodes_m[node]) for node in sorted(shunts))
        return supply * chain.solve(chain.shunts_at(positions))[2] / self.reference[k]
