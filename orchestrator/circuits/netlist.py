"""A track circuit as a SPICE netlist (docs/rail_line.md#checked-against-ngspice): plain text any
SPICE reads (resistors, inductors, a voltage source and a voltage-controlled voltage source; the
cross-check's train entering adds a voltage-controlled switch).

Two ways to put the trains on it:

* ``lumped_netlist``: the rail line's own network, element for element (fmus/rail_line/
  track_circuit.py): the rails as the same π sections of at most 50 m (series R–L, half the
  ballast at each end), the relay end (relay and bond winding), the feed end (the code voltage
  u_tx times the transformer ratio behind the feed resistance, the bond winding), a broken rail
  (its segment's resistance opened), an open feed, and one 0.06 Ω wheelset shunt per network
  node a train covers;
* ``axle_netlist``: every wheelset at its axle position on rails cut into pieces of at most
  ``segment_m`` (and at every axle), with the rails beyond the feed leads up to the exit joint
  (open there) on which an axle still shunts the feed: the reference the lumping is measured
  against.

Node names: the rail nodes ``n0`` (relay end) … ``nS`` (feed) of the lumped network, ``p0`` …
of the per-axle one, ``q1`` … on the overhang beyond the feed leads; ground (0) is the other rail.
``Netlist.probes`` says which vectors of ngspice's output give each quantity (a sum of vectors
times coefficients: a current at a point of the rails is its piece's series current less the
half ballast lumped at that end).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from fmus.rail_line.track_circuit import OPEN_OHM, Faults, TrackCircuit, rail_impedance

# a quantity as a sum of vectors of the output: [(coefficient, vector name), …]
Probe = List[Tuple[float, str]]
#: the most rail pieces an axle netlist cuts a track circuit into (four cards each): the longest
#: circuit in 1 m pieces is about 3000; a shorter segment than this allows would only make a
#: netlist of gigabytes (`--segment 1e-9`: 10¹² pieces)
MAX_AXLE_PIECES = 100_000


def number(value: float) -> str:
    """A value as SPICE reads it, to 12 significant digits."""
    return f"{value:.12g}"


@dataclass
class Netlist:
    title: str
    cards: List[str]
    probes: Dict[str, Probe] = field(default_factory=dict)
    source: List[str] = field(default_factory=list)       # the code input Vu (set by an excitation)
    analysis: List[str] = field(default_factory=list)

    def text(self) -> str:
        lines = [self.title.replace("\n", " "), *self.cards, *self.source, *self.analysis, ".end"]
        return "\n".join(lines) + "\n"


def _rail_piece(cards: List[str], name: str, a: str, b: str, length_m: float, r_ohm_km: float,
                l_h_km: float, ballast_ohm_km: float, series_r: Optional[float] = None) -> None:
    """One π section: series R–L from a to b, half its ballast conductance at each end."""
    length_km = length_m / 1000.0
    resistance = r_ohm_km * length_km if series_r is None else series_r
    half = 2.0 * ballast_ohm_km / length_km            # the resistance of half the ballast conductance
    cards += [f"R{name} {a} m{name} {number(resistance)}",
              f"L{name} m{name} {b} {number(l_h_km * length_km)}",
              f"RG{name}a {a} 0 {number(half)}",
              f"RG{name}b {b} 0 {number(half)}"]


def _ends(cards: List[str], circuit: TrackCircuit, relay: str, feed: str, faults: Faults,
          transformer_ratio: float) -> None:
    p = circuit.params
    cards += ["* relay end: track relay and impedance bond signal winding",
              f"Rrelay {relay} 0 {number(p.relay_r_ohm)}",
              f"Rbondr {relay} br {number(p.bond_r_ohm)}",
              f"Lbondr br 0 {number(p.bond_l_h)}"]
    if faults.feed_open:
        cards += ["* feed end: open (bond disconnected or transmitter failed)",
                  f"Ropen {feed} 0 {number(OPEN_OHM)}"]
    else:
        cards += ["* feed end: code voltage u (node u) times the transformer ratio behind the feed resistance, bond",
                  f"Etx src 0 u 0 {number(transformer_ratio)}",
                  f"Rfeed src {feed} {number(p.feed_r_ohm)}",
                  f"Rbondf {feed} bf {number(p.bond_r_ohm)}",
                  f"Lbondf bf 0 {number(p.bond_l_h)}"]


def _header(circuit: TrackCircuit, faults: Faults, frequency_hz: float, what: str) -> List[str]:
    p = circuit.params
    r, l = rail_impedance(p, frequency_hz)
    return [f"* track circuit {circuit.start_m:g}–{circuit.end_m:g} m, feed leads at {circuit.feed_m:g} m; {what}",
            f"* rails at {frequency_hz:g} Hz: {r:.6g} Ω/km, {l * 1e3:.6g} mH/km; ballast {circuit.ballast(faults):g} Ω·km"
            + (f"; broken rail at {faults.broken_rail_m:g} m" if faults.broken_rail_m >= 0 else "")
            + ("; feed open" if faults.feed_open else "")]


def lumped_netlist(circuit: TrackCircuit, shunt_nodes: Sequence[int], head_nodes: Sequence[int],
                   faults: Faults = Faults(), frequency_hz: float = 50.0, transformer_ratio: float = 2.5,
                   title: str = "track circuit") -> Netlist:
    """The rail line's own network of ``circuit`` with a wheelset shunt at each node of
    ``shunt_nodes``; probes: ``relay`` (relay-end voltage), ``entry`` (the current arriving at
    the relay end) and ``head<h>`` (the current arriving from the feed at each head node, as the
    rail line reads it: the rail segment ahead of the node, at the feed node what the feed
    delivers)."""
    p = circuit.params
    rail_r, rail_l = rail_impedance(p, frequency_hz)
    segments = circuit.segments
    length_m = (circuit.feed_m - circuit.start_m) / segments
    ballast = circuit.ballast(faults)
    cards = _header(circuit, faults, frequency_hz, f"{segments} π sections of {length_m:.6g} m, "
                    f"wheelsets lumped: one shunt per node a train covers")
    cards.append("* rails: π sections n(k) – n(k+1)")
    for k in range(segments):
        broken = 0 <= faults.broken_rail_m and circuit.nodes_m[k] <= faults.broken_rail_m < circuit.nodes_m[k + 1]
        _rail_piece(cards, str(k), f"n{k}", f"n{k + 1}", length_m, rail_r, rail_l, ballast,
                    OPEN_OHM if broken else None)
    _ends(cards, circuit, "n0", f"n{segments}", faults, transformer_ratio)
    if len(shunt_nodes):
        cards.append("* wheelsets: one shunt per covered node")
        cards += [f"Rsh{node} n{node} 0 {number(p.shunt_r_ohm)}" for node in shunt_nodes]
    probes: Dict[str, Probe] = {"relay": [(1.0, "v(n0)")], "entry": [(-1.0, "i(l0)")]}
    for h, node in enumerate(head_nodes):
        probes[f"head{h}"] = [(-1.0, f"i(l{node})")] if node < segments else \
            ([] if faults.feed_open else [(-1.0, "i(etx)"), (-1.0, "i(lbondf)")])
    return Netlist(title, cards, probes)


def axle_netlist(circuit: TrackCircuit, axles_m: Sequence[float], heads_m: Sequence[float],
                 faults: Faults = Faults(), frequency_hz: float = 50.0, transformer_ratio: float = 2.5,
                 segment_m: float = 1.0, title: str = "track circuit") -> Netlist:
    """``circuit`` with a wheelset shunt at every axle position in ``axles_m`` (absolute, m;
    those outside the circuit's joints are left out), the rails cut into pieces of at most
    ``segment_m`` and at every axle; probes ``relay``, ``entry`` and ``head<h>``: the current
    arriving from the feed at each position of ``heads_m`` (a train's first axle: the rail piece
    on its feed side; beyond the feed leads, the current into the overhang)."""
    p = circuit.params
    rail_r, rail_l = rail_impedance(p, frequency_hz)
    ballast = circuit.ballast(faults)
    start, feed, end = float(circuit.start_m), float(circuit.feed_m), float(circuit.end_m)
    if not (end - start) / segment_m <= MAX_AXLE_PIECES:
        raise ValueError(f"segment_m {segment_m:g}: {end - start:g} m of rails in more than {MAX_AXLE_PIECES} pieces")
    axles = sorted(float(a) for a in axles_m if start <= a <= end)
    broken = float(faults.broken_rail_m) if start <= faults.broken_rail_m < feed else None

    def cuts(lo: float, hi: float, extra: List[float]) -> List[float]:
        count = max(int(np.ceil((hi - lo) / segment_m - 1e-9)), 1)
        points = np.concatenate([np.linspace(lo, hi, count + 1), extra])
        points = np.unique(np.round(points, 9))
        keep = [points[0]]
        for x in points[1:]:
            if x - keep[-1] > 1e-6:
                keep.append(float(x))
        return keep

    inside = [a for a in axles if a <= feed]
    overhang = [a for a in axles if a > feed]
    points = cuts(start, feed, inside + ([broken] if broken is not None else []))
    cards = _header(circuit, faults, frequency_hz, f"rails in {len(points) - 1} pieces of at most {segment_m:g} m, "
                    f"{len(axles)} wheelsets at their axles")
    names = {x: f"p{i}" for i, x in enumerate(points)}
    cards.append("* rails: π pieces p(i) – p(i+1)")
    for i, (a, b) in enumerate(zip(points[:-1], points[1:])):
        # a break is a point: the piece starting there takes the open rail's series resistance
        series = OPEN_OHM if broken is not None and abs(a - broken) < 1e-6 else None
        _rail_piece(cards, f"p{i}", names[a], names[b], b - a, rail_r, rail_l, ballast, series)
    feed_node = names[points[-1]]
    overhang_points = cuts(feed, end, overhang)[1:] if overhang else []
    overhang_names = {x: f"q{i + 1}" for i, x in enumerate(overhang_points)}
    if overhang_points:
        cards.append("* rails beyond the feed leads up to the exit joint (open there), with the axles on them")
        previous, previous_name = feed, feed_node
        for i, x in enumerate(overhang_points):
            _rail_piece(cards, f"q{i}", previous_name, overhang_names[x], x - previous, rail_r, rail_l, ballast)
            previous, previous_name = x, overhang_names[x]
    _ends(cards, circuit, "p0", feed_node, faults, transformer_ratio)
    node_of = dict(names)
    node_of.update(overhang_names)
    if axles:
        cards.append("* wheelsets at their axles")
        for i, a in enumerate(axles):
            nearest = min(node_of, key=lambda x: abs(x - a))
            cards.append(f"Rax{i} {node_of[nearest]} 0 {number(p.shunt_r_ohm)}")
    # currents at a point of the rails: a piece's series current less the half of its ballast
    # lumped at that end (it leaks along the piece, not at the point), so the probes read the
    # rails' current where the axle stands, not half a piece along
    def half_ballast(length_m: float) -> float:
        return 0.5 * (length_m / 1000.0) / ballast

    probes: Dict[str, Probe] = {"relay": [(1.0, "v(p0)")],
                                "entry": [(1.0, "i(lbondr)"), (1.0 / p.relay_r_ohm, "v(p0)")]}
    for h, head in enumerate(heads_m):
        head = float(head)
        if head <= feed:
            index = int(np.searchsorted(np.array(points), head - 1e-6))   # the piece on the feed side
            index = min(index, len(points) - 2)
            node = names[points[index]]
            probes[f"head{h}"] = [(-1.0, f"i(lp{index})"),
                                  (-half_ballast(points[index + 1] - points[index]), f"v({node})")]
        elif overhang_points:
            probes[f"head{h}"] = [(1.0, "i(lq0)"), (half_ballast(overhang_points[0] - feed), f"v({feed_node})")]
        else:
            probes[f"head{h}"] = []
    return Netlist(title, cards, probes)


def ac_source(netlist: Netlist, frequency_hz: float) -> Netlist:
    """A sine at ``frequency_hz`` for .ac: u_tx = 1 V (the results are per volt of code)."""
    netlist.source = ["* code input u_tx: 1 V at the carrier (results per volt)", "Vu u 0 DC 0 AC 1"]
    netlist.analysis = [f".ac lin 1 {number(frequency_hz)} {number(frequency_hz)}"]
    return netlist


def staircase_points(times_s: np.ndarray, values: np.ndarray, corner_s: float) -> List[Tuple[float, float]]:
    """The points of a PWL source that holds each value from its sample instant to the next
    (a zero-order hold): each step starts ``corner_s`` before its instant and is complete at it,
    so the value of sample n is the source's from t_n on, as the discretised model holds it."""
    points = [(0.0, float(values[0]))] if times_s[0] > 0 else [(float(times_s[0]), float(values[0]))]
    for n in range(1, len(values)):
        if values[n] != values[n - 1]:
            points.append((float(times_s[n]) - corner_s, float(values[n - 1])))
            points.append((float(times_s[n]), float(values[n])))
    return points


def _pwl(name: str, a: str, points: List[Tuple[float, float]]) -> List[str]:
    lines = [f"{name} {a} 0 PWL("]
    for k in range(0, len(points), 6):
        lines.append("+ " + " ".join(f"{number(t)} {number(v)}" for t, v in points[k:k + 6]))
    lines.append("+ )")
    return lines


def tran_source(netlist: Netlist, times_s: np.ndarray, u_v: np.ndarray, stop_s: float,
                step_s: float, corner_s: float = 1e-8) -> Netlist:
    """The code input u_tx as the staircase of its samples (``times_s``, ``u_v``) and a .tran to
    ``stop_s`` with tight tolerances; the output interpolated at every ``step_s``."""
    netlist.source = ["* code input u_tx: the coder's samples held from each sample instant to the next",
                      *_pwl("Vu", "u", staircase_points(times_s, u_v, corner_s))]
    netlist.analysis = [".options reltol=1e-7 abstol=1e-13 vntol=1e-10 chgtol=1e-16 trtol=1 interp",
                        f".tran {number(step_s)} {number(stop_s)} 0 {number(step_s / 25.0)}"]
    return netlist


def switched_shunts(netlist: Netlist, nodes: Sequence[str], on_s: float, shunt_r_ohm: float,
                    corner_s: float = 1e-8) -> Netlist:
    """Wheelset shunts at ``nodes`` switched in at ``on_s`` (a train entering): ngspice's
    voltage-controlled switch, closed from ``on_s`` on."""
    netlist.cards += ["* a train entering: its wheelsets switched in",
                      f".model wheelset sw(vt=0.5 vh=0 ron={number(shunt_r_ohm)} roff={number(OPEN_OHM)})",
                      *_pwl("Venter", "enter", [(0.0, 0.0), (on_s - corner_s, 0.0), (on_s, 1.0)])]
    netlist.cards += [f"Sen{i} {node} 0 enter 0 wheelset" for i, node in enumerate(nodes)]
    return netlist


def print_probes(netlist: Netlist, meaning: Dict[str, str], tran: bool = False) -> Netlist:
    """Comment lines saying which vectors give which quantity, and a .print of them, so that
    ``ngspice -b FILE`` prints the results (a current at a point is its vectors' sum as written)."""
    vectors: List[str] = []
    notes = ["* results (ngspice -b prints them): " + ("the waveforms" if tran else "magnitude, phase; currents as re, im")]
    for key, probe in netlist.probes.items():
        if not probe:
            continue
        terms = " + ".join(f"{number(c)}·{name}" for c, name in probe)
        notes.append(f"*   {meaning.get(key, key)}: {terms}")
        vectors += [name for _, name in probe if name not in vectors]
    if tran:
        prints = [f".print tran {' '.join(vectors)}"]
    else:
        prints = [f".print ac {' '.join(v.replace('v(', 'vm(', 1) + ' ' + v.replace('v(', 'vp(', 1) if v.startswith('v(') else v for v in vectors)}"]
    netlist.analysis = netlist.analysis + notes + prints
    return netlist
