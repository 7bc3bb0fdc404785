"""A section's track circuit with every wheelset at its axle position, solved at one frequency as
a chain of two-ports (no FMI here; docs/rail_line.md, wheelsets at their axles).

The track circuit is a ladder along the rails: the relay end, the rail loop (a uniform line: its
series impedance per km at the frequency and the ballast's conductance distributed along it),
a 0.06 Ω wheelset wherever an axle stands, the feed end; beyond the feed leads a short overhang of
rails up to the exit joint (open there: the insulated joint), on which an axle still shunts the
feed. Solving it as a chain of 2×2 transmission (ABCD) matrices from the relay end to the feed
is exact for that ladder (the rails are not cut into π sections), and costs a few complex
operations per piece of rail: a train's wheelsets are a fixed pattern, so the product of the
matrices between its axles is tabulated once per (train, ballast, frequency) in powers of two
(a sparse table), and any run of its axles costs log₂(axles) matrix-vector products.

What it gives per unit code input (u_tx = 1 V, × the transformer ratio at the rails): the
current arriving from the feed at any probe position (a train's first axle), the entry-end
current (what the next section's coils see before they cross the joint) and the relay-end
voltage. The network model (network_models.py) lumps a train into one shunt per node; the
bank scales what that model's currents give to these amplitudes (circuit_bank.py).
"""
from __future__ import annotations

import cmath
import math
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from fmus.rail_line.track_circuit import (OPEN_OHM, CircuitParameters, Faults, TrackCircuit, end_admittance,
                                         rail_impedance)

# a 2×2 complex matrix as a tuple (a, b, c, d): [[a, b], [c, d]] acting on (V, I), I the rail-loop
# current flowing toward the relay end
Matrix = Tuple[complex, complex, complex, complex]


class RailLine:
    """The rail loop of one section at one frequency and ballast: uniform-line two-ports."""

    def __init__(self, params: CircuitParameters, ballast_ohm_km: float, frequency_hz: float):
        omega = 2.0 * math.pi * frequency_hz
        r, l = rail_impedance(params, frequency_hz)
        z, y = complex(r, omega * l), 1.0 / ballast_ohm_km          # per km
        self.gamma = cmath.sqrt(z * y)                                # per km
        self.impedance = cmath.sqrt(z / y)                            # characteristic, Ω
        self.z_per_km = z

    def matrix(self, length_m: float) -> Matrix:
        """(V, I) at the far end (toward the feed) from (V, I) at the near end, over ``length_m``."""
        x = self.gamma * (length_m / 1000.0)
        ch, sh = cmath.cosh(x), cmath.sinh(x)
        return ch, self.impedance * sh, sh / self.impedance, ch


def _times(m: Matrix, n: Matrix) -> Matrix:
    """m · n."""
    a, b, c, d = m
    e, f, g, h = n
    return a * e + b * g, a * f + b * h, c * e + d * g, c * f + d * h


def _apply(m: Matrix, v: complex, i: complex) -> Tuple[complex, complex]:
    a, b, c, d = m
    return a * v + b * i, c * v + d * i


class AxleTable:
    """A train's wheelsets on one section's rails: the matrices from each axle to the next (the
    axle's shunt, then the rails to the next axle toward the feed), tabulated in powers of two,
    so the product over any run of consecutive axles is log₂(axles) products."""

    def __init__(self, positions_m: np.ndarray, line: RailLine, g_shunt: float):
        # positions ascending (the tail's axle first, toward the feed): the cells between them
        self.count = len(positions_m)
        self.offsets = np.asarray(positions_m, dtype=float)
        shunt = (1.0 + 0j, 0j, complex(g_shunt), 1.0 + 0j)
        cells = [_times(line.matrix(float(b - a)), shunt) for a, b in zip(positions_m[:-1], positions_m[1:])]
        self.levels: List[List[Matrix]] = [cells]
        width = 1
        while 2 * width <= len(cells):
            below = self.levels[-1]
            self.levels.append([_times(below[i + width], below[i]) for i in range(len(cells) - 2 * width + 1)])
            width *= 2
        self.shunt = shunt

    def through(self, first: int, last: int, v: complex, i: complex) -> Tuple[complex, complex]:
        """(V, I) just beyond axle ``last`` (toward the feed, its shunt included) from (V, I) just
        before axle ``first`` (toward the relay), first ≤ last (indices in ascending position)."""
        while first < last:
            level = (last - first).bit_length() - 1
            v, i = _apply(self.levels[level][first], v, i)
            first += 1 << level
        return _apply(self.shunt, v, i)


class SectionChain:
    """One section's track circuit at one frequency, ballast and faults, as a chain from the
    relay end (entry joint) to the feed leads, with the overhang of rails beyond them up to the exit
    joint."""

    def __init__(self, circuit: TrackCircuit, faults: Faults, frequency_hz: float, transformer_ratio: float):
        p = circuit.params
        self.circuit, self.faults = circuit, faults
        self.start_m, self.feed_m, self.end_m = float(circuit.start_m), float(circuit.feed_m), float(circuit.end_m)
        self.line = RailLine(p, circuit.ballast(faults), frequency_hz)
        # each end's bond winding, or its tuned separation zone (a TVM circuit)
        termination = end_admittance(p, circuit.ballast(faults), frequency_hz)
        self.relay_admittance = 1.0 / p.relay_r_ohm + termination
        self.feed_bond_admittance = termination
        self.feed_r_ohm, self.ratio = p.feed_r_ohm, transformer_ratio
        self.g_shunt = 1.0 / p.shunt_r_ohm
        self.feed_open = faults.feed_open
        # a broken rail inside the section: its position (the model opens the segment holding it)
        broken = faults.broken_rail_m
        self.broken_m = broken if self.start_m <= broken < self.feed_m else None
        self._tables: Dict[int, AxleTable] = {}

    def table(self, key: int, positions_m: np.ndarray) -> AxleTable:
        """The axle table of a wheelset pattern (``key`` names it: one per train), positions
        relative to any origin, ascending."""
        table = self._tables.get(key)
        if table is None:
            table = self._tables[key] = AxleTable(positions_m, self.line, self.g_shunt)
        return table

    def shunts_at(self, positions_m: Sequence[float]) -> List[tuple]:
        """Single wheelsets at these absolute positions as runs for ``solve`` (the design
        regimes' normative shunt)."""
        table = self.table(-1, np.zeros(1))
        return [(float(x), float(x), table, 0, 0) for x in sorted(positions_m)]

    def solve(self, runs: Sequence[tuple], probes: Sequence[float] = ()):
        """The section with these wheelsets, per unit code input: (currents arriving from the feed
        at each probe position, A; the entry-end current, A; the relay-end voltage, V).

        ``runs``: the wheelsets as runs of one train's consecutive axles, sorted along the
        section, each (start_m, end_m, table, first, last): axles ``first``…``last`` of ``table``
        (ascending), the first of them at ``start_m`` and the last at ``end_m`` (absolute). A
        probe is taken just on the feed side of a wheelset at the same position (the current
        arriving at that axle); a probe beyond the feed leads is the current into the overhang."""
        v, i, entry, found, into_overhang = self._walk(runs, probes)
        # the feed: u·ratio behind the feed resistance, the bond winding (or zone) across the rails
        source = v + self.feed_r_ohm * (i + into_overhang + self.feed_bond_admittance * v)
        if self.feed_open or abs(source) == 0.0:
            return [0.0] * len(probes), 0.0, 0.0
        per_unit = self.ratio / source
        currents = [abs(into_overhang * per_unit) if point is None else abs(point[1] * per_unit) for point in found]
        return currents, abs(entry * per_unit), abs(per_unit)

    def seen_from_feed(self, runs: Sequence[tuple], probes: Sequence[float] = ()):
        """The rails with these wheelsets as the feed node sees them, without the feed's own
        equipment: (their admittance at the feed node (rails toward the relay end with the relay
        end's termination, and the overhang), S; the current arriving at each probe per volt at
        the feed node, A/V, complex). What a voltage applied at the feed node from outside (a
        neighbour's carrier through the separation zone) drives into the rails."""
        v, i, _, found, into_overhang = self._walk(runs, probes)
        return (i + into_overhang) / v, [into_overhang / v if point is None else point[1] / v for point in found]

    def _walk(self, runs: Sequence[tuple], probes: Sequence[float]):
        """From the relay end (V = 1) through the rails and wheelsets to the feed node: (V, I
        there, the entry-end current, (V, I) at each probe (None: beyond the feed leads), the
        overhang's current at the feed)."""
        broken = self.broken_m
        v, i = 1.0 + 0j, self.relay_admittance           # at the relay end, V = 1 (scaled at the end)
        entry = i
        x = self.start_m
        wanted = sorted((position, index) for index, position in enumerate(probes))
        # per probe (V, I) where it is read; None: beyond the feed leads (the current into the overhang)
        found: List[Optional[Tuple[complex, complex]]] = [None] * len(probes)
        next_probe = 0
        overhang = []
        for start, end, table, first, last in runs:
            if start > self.feed_m:                        # on the overhang beyond the feed leads
                overhang.append((start, end, table, first, last))
                continue
            while next_probe < len(wanted) and wanted[next_probe][0] < start:
                v, i, x = self._rails(v, i, x, wanted[next_probe][0])
                found[wanted[next_probe][1]] = (v, i)
                next_probe += 1
            v, i, x = self._rails(v, i, x, start)
            if broken is not None and start <= broken < end:
                v, i = self._axles_one_by_one(table, first, last, start, v, i)   # a break under a train
            else:
                v, i = table.through(first, last, v, i)
            x = end
            while next_probe < len(wanted) and wanted[next_probe][0] <= end:
                # at the run's last axle: just beyond it; a probe between a train's axles reads
                # what passes its last axle there (probes are the trains' first axles)
                found[wanted[next_probe][1]] = (v, i)
                next_probe += 1
        while next_probe < len(wanted) and wanted[next_probe][0] <= self.feed_m:
            v, i, x = self._rails(v, i, x, wanted[next_probe][0])
            found[wanted[next_probe][1]] = (v, i)
            next_probe += 1
        v, i, x = self._rails(v, i, x, self.feed_m)
        return v, i, entry, found, self._overhang_admittance(overhang) * v

    def _rails(self, v: complex, i: complex, x: float, to: float) -> Tuple[complex, complex, float]:
        """Along the rails from x to ``to`` (≥ x), through a broken rail if one lies between."""
        if to <= x:
            return v, i, x
        broken = self.broken_m
        if broken is not None and x <= broken < to:
            v, i = _apply(self.line.matrix(broken - x), v, i)
            v = v + OPEN_OHM * i                          # the break: the rail's series resistance opens
            x = broken
        v, i = _apply(self.line.matrix(to - x), v, i)
        return v, i, to

    def _axles_one_by_one(self, table: AxleTable, first: int, last: int, start: float, v: complex, i: complex):
        """A run of axles with a broken rail between two of them: axle by axle."""
        positions = table_positions(table, first, last, start)
        x = positions[0]
        for position in positions:
            v, i, x = self._rails(v, i, x, position)
            i = i + self.g_shunt * v
        return v, i

    def _overhang_admittance(self, overhang) -> complex:
        """The overhang from the feed leads to the exit joint (open: the insulated joint) with the
        wheelsets on it, as an admittance at the feed."""
        if not overhang:
            return 0j
        positions = sorted(p for start, end, table, first, last in overhang
                           for p in table_positions(table, first, last, start))
        # from the joint (open: no current) toward the feed, mirrored: the same uniform line
        v, i, x = 1.0 + 0j, 0j, self.end_m
        for position in reversed(positions):
            v, i = _apply(self.line.matrix(x - position), v, i)
            i = i + self.g_shunt * v
            x = position
        v, i = _apply(self.line.matrix(x - self.feed_m), v, i)
        return i / v


def table_positions(table: AxleTable, first: int, last: int, start: float) -> List[float]:
    """Absolute positions of axles first…last of a table whose axle ``first`` is at ``start``."""
    offsets = table.offsets
    return [start + float(offsets[k] - offsets[first]) for k in range(first, last + 1)]
