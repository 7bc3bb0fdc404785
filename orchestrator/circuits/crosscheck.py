"""The rail line's track circuits checked by ngspice (docs/rail_line.md#checked-against-ngspice):
``railcosim crosscheck spice SYSTEM`` and benchmarks/spice_crosscheck.py.

Three comparisons, each against a netlist of orchestrator/circuits/netlist.py run by ngspice:

* **.ac, the network**: the rail line's own network (a shunt per node a train covers) at a
  frequency, our phasor solution (modified nodal analysis, fmus/rail_line/network.py) against
  ngspice's on the same netlist: relay-end voltage, the current arriving at the first axle,
  the entry-end current and the coil EMF (ω·M times that current). Solver precision expected.
* **.tran, the discretised model**: a 1 s window with a code change (the wayside coder core's
  waveform, held sample by sample as a staircase) and a train entering the section, our exact
  zero-order-hold state space stepped at the sample rate against ngspice's transient at the
  same instants: relay-end voltage and the current at the train's first axle.
* **the wheelsets**: trains with every wheelset at its axle (rails in 1 m pieces) in ngspice,
  the reference; against it the network's lumping (one shunt per node) and the wheelset chain
  the rail line takes its amplitudes from (fmus/rail_line/axle_chain.py): the current at the
  leading train's first axle, the current reaching a following train's first axle behind it
  (the code left behind a train), and the relay-end voltage under the train alone.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Dict, Iterable, List, Optional, Sequence, Tuple

import numpy as np

from fmus.data.loader import DATA, Line, load_rolling_stock
from fmus.errors import FmuInputError
from fmus.rail_line.core import RailLineCore, RailSettings
from fmus.rail_line.geometry import LineGeometry
from fmus.rail_line.network import PhasorFamily, ShuntFamily, discretise
from fmus.rail_line.track_circuit import Faults, TrackCircuit
from fmus.wayside_coder.core import CoderSettings, WaysideCoderCore
from orchestrator.circuits import ngspice
from orchestrator.circuits.netlist import (ac_source, axle_netlist, lumped_netlist, switched_shunts,
                                           tran_source)

AC_BOUND = 1e-3            # .ac: the same network, solver precision
TRAN_BOUND = 5e-3          # .tran: of the local amplitude, at every sample instant
WHEELSET_BOUND = 0.05      # the rail line's amplitudes against the per-axle reference
BALLASTS_OHM_KM = (1.0, 50.0, 200.0)
FOLLOWER_GAPS_M = (30.0, 100.0)
AXLE_SEGMENT_M = 1.0       # the reference's rail pieces
# below the reference by less than this is not "the unsafe side": the reference's own resolution
# (its 1 m π pieces read above the continuous rails by ≈ 3·10⁻⁷ under a 388 m train, 10⁻⁶ under
# the 944 m one; 0.5 m pieces a quarter of it: the difference is the reference's, not ours)
UNSAFE_TOLERANCE = 1e-5
# where ours above the reference is the safe side: more code behind a train, a higher relay level
# under it (a weaker shunt) than the real wheelsets give
SAFE_ABOVE = ("behind", "relay voltage")

# a light engine of two bogies: the ЧМЭ3 shunting locomotive, 17.22 m, two three-axle bogies
# with pivots 8.66 m apart and 4.0 m wheelbase (docs/sources.md#rolling-stock-wheelsets)
LIGHT_ENGINE = ("light engine ЧМЭ3", 17.22, np.array([0.0, 2.0, 4.0, 8.66, 10.66, 12.66]))


@dataclass(frozen=True)
class Train:
    name: str
    length_m: float
    wheelsets_m: np.ndarray          # behind the first wheelset, ascending from 0


def shipped_train(file_name: str) -> Train:
    stock = load_rolling_stock(DATA / file_name)
    return Train(stock.name.split(" (")[0], stock.length_m, stock.wheelset_offsets_m)


def documented_trains() -> List[Train]:
    """The shipped rolling stock and the light engine of docs/rail_line.md."""
    return [shipped_train(name) for name in ("passenger_chs7.json", "emu_er2.json", "freight_vl80.json")] + \
        [Train(*LIGHT_ENGINE)]


def relative_error(ours: float, reference: float) -> float:
    return (ours - reference) / reference if reference != 0.0 else (0.0 if ours == 0.0 else math.inf)


# ---- the network's phasor solution --------------------------------------------------------------
def network_phasors(circuit: TrackCircuit, shunt_nodes: Sequence[int], head_nodes: Sequence[int],
                    faults: Faults, frequency_hz: float, transformer_ratio: float) -> Dict[str, complex]:
    """The rail line's network at one frequency, per volt of code input, the quantities of
    lumped_netlist's probes (relay, entry, head<h>), by modified nodal analysis (network.py)."""
    net = circuit.network(None, faults, transformer_ratio, frequency_hz)
    family = PhasorFamily(net, 2.0 * math.pi * frequency_hz, [1.0])
    g = 1.0 / circuit.params.shunt_r_ohm
    v = family.with_shunts([net.node_index[f"n{node}"] for node in shunt_nodes], g)
    volts = np.array([v[net.node_index[f"n{i}"]] for i in range(circuit.segments + 1)])
    segment = (volts[:-1] - volts[1:]) / family.z_branch[:circuit.segments]      # relay → feed
    values = {"relay": complex(volts[0]), "entry": complex(-segment[0])}
    p = circuit.params
    for h, node in enumerate(head_nodes):
        if node < circuit.segments:
            values[f"head{h}"] = complex(-segment[node])
        elif faults.feed_open:
            values[f"head{h}"] = 0j
        else:                     # what the feed delivers: source current less the bond winding's
            bond = complex(p.bond_r_ohm, 2.0 * math.pi * frequency_hz * p.bond_l_h)
            values[f"head{h}"] = complex((transformer_ratio - volts[-1]) / p.feed_r_ohm - volts[-1] / bond)
    return values


@dataclass
class AcRow:
    line: str
    sections: str
    frequency_hz: float
    ballast_ohm_km: float
    worst: Dict[str, float] = field(default_factory=dict)     # quantity → largest |relative error|

    def passed(self) -> bool:
        return all(error <= AC_BOUND for error in self.worst.values())


def _designs(line: Line, settings: RailSettings, only: Optional[int] = None) -> List[Tuple[List[int], TrackCircuit]]:
    """The line's circuits grouped by design (the same circuit relative to its start); ``only``:
    the design of that section (an index) alone."""
    groups: Dict[tuple, Tuple[List[int], TrackCircuit]] = {}
    for k, circuit in enumerate(LineGeometry(line, settings).circuits):
        if circuit.params.zone is not None:       # netlist.py writes bonds, not tuned zones
            raise FmuInputError(f"{line.path}: field block_sections[{k}].transmitter: the ngspice cross-check "
                                f"covers the ALSN circuits; '{line.sections[k].name}' is a UM71 (TVM) circuit")
        key = (circuit.segments, round(circuit.feed_m - circuit.start_m, 6), round(circuit.end_m - circuit.start_m, 6),
               circuit.params)
        groups.setdefault(key, ([], circuit))[0].append(k)
    return [group for group in groups.values() if only is None or only in group[0]]


def _sections_label(ks: List[int]) -> str:
    ks = [k + 1 for k in ks]
    runs, start = [], ks[0]
    for a, b in zip(ks, ks[1:] + [None]):
        if b != a + 1:
            runs.append(f"{start}" if start == a else f"{start}–{a}")
            start = b
    return ", ".join(runs)


def ac_rows(line: Line, name: str, frequencies: Iterable[float], ballasts: Iterable[float] = BALLASTS_OHM_KM,
            settings: RailSettings = RailSettings(), coil_gain_h: float = 4.5e-4,
            only: Optional[int] = None) -> List[AcRow]:
    """The .ac comparison over the line's sections (one per design), frequencies and ballasts:
    the free circuit and a 400 m train (one shunt per node it covers) with its head in the
    middle and 10 m before the feed leads."""
    rows = []
    for ks, circuit in _designs(line, settings, only):
        for frequency in frequencies:
            for ballast in ballasts:
                faults = Faults(ballast)
                row = AcRow(name, _sections_label(ks), frequency, ballast)
                spacing = circuit.nodes_m[1] - circuit.nodes_m[0]
                for head in (None, 0.5 * (circuit.start_m + circuit.feed_m), circuit.feed_m - 10.0):
                    if head is None:
                        shunts, heads = [], []
                    else:
                        front = int(round((head - circuit.start_m) / spacing))
                        tail = int(round((max(head - 400.0, circuit.start_m) - circuit.start_m) / spacing))
                        shunts, heads = list(range(tail, front + 1)), [front]
                    netlist = ac_source(lumped_netlist(circuit, shunts, heads, faults, frequency,
                                                       settings.transformer_ratio, title=f"{name} {row.sections}"),
                                        frequency)
                    raw = ngspice.run(netlist.text())
                    ours = network_phasors(circuit, shunts, heads, faults, frequency, settings.transformer_ratio)
                    for quantity, probe in netlist.probes.items():
                        theirs = complex(raw.value(probe)[0])
                        label = "current at the first axle" if quantity.startswith("head") else \
                            {"relay": "relay voltage", "entry": "entry current"}[quantity]
                        error = abs(ours[quantity] - theirs) / abs(theirs) if theirs != 0 else abs(ours[quantity])
                        row.worst[label] = max(row.worst.get(label, 0.0), error)
                        if quantity.startswith("head"):      # the EMF is jωM times that current
                            omega = 2.0 * math.pi * frequency
                            emf_ours, emf_theirs = omega * coil_gain_h * ours[quantity], omega * coil_gain_h * theirs
                            row.worst["coil EMF"] = max(row.worst.get("coil EMF", 0.0),
                                                        abs(emf_ours - emf_theirs) / abs(emf_theirs))
                rows.append(row)
    return rows


# ---- the discretised model against .tran -----------------------------------------------------------
@dataclass
class TranResult:
    line: str
    section: int
    seconds: float
    worst: Dict[str, float]          # quantity → largest error over the local amplitude
    samples: int

    def passed(self) -> bool:
        return all(error <= TRAN_BOUND for error in self.worst.values())


def coder_waveform(line: Line, section: int, seconds: float, change_s: float, fs_hz: float) -> np.ndarray:
    """The wayside coder core's code voltage into ``section`` over ``seconds``: З, then from
    ``change_s`` on Ж (the section two ahead occupied), sample by sample."""
    frame = 40
    coder = WaysideCoderCore(line, len(line.sections), frame, CoderSettings(fs_hz=fs_hz))
    occupied = np.zeros(len(line.sections), dtype=bool)
    samples = []
    for index in range(int(math.ceil(seconds * fs_hz / frame))):
        t = index * frame / fs_hz
        occupied[:] = False
        if t >= change_s and section + 2 < len(line.sections):
            occupied[section + 2] = True
        samples.append(coder.step(t, occupied).u_tx[section].copy())
    return np.concatenate(samples)[:int(round(seconds * fs_hz))]


def _discrete(circuit: TrackCircuit, shunt_nodes: Sequence[int], faults: Faults, frequency_hz: float,
              ratio: float, step_s: float):
    net = circuit.network(None, faults, ratio, frequency_hz)
    family = ShuntFamily(net, 1.0 / circuit.params.shunt_r_ohm)
    system = family.state_space([net.node_index[f"n{node}"] for node in shunt_nodes])
    phi, gamma = discretise(system, step_s)
    relay = net.node_index["n0"]
    return phi, gamma[:, 0], system.node_from_state[relay], float(system.node_from_input[relay, 0])


def tran_check(line: Line, name: str, section: int, seconds: float = 1.0, change_s: float = 0.3,
               enter_s: float = 0.6, settings: RailSettings = RailSettings()) -> TranResult:
    """A train entering ``section`` at ``enter_s`` (its first wheelsets at the relay end: a shunt
    at node 0) and a code change at ``change_s``: our discretised model against ngspice."""
    geometry = LineGeometry(line, settings)
    circuit = geometry.circuits[section]
    frequency = float(geometry.carriers[section])
    fs, ratio = settings.fs_hz, settings.transformer_ratio
    u = coder_waveform(line, section, seconds, change_s, fs)
    times = np.arange(len(u)) / fs
    entering = int(round(enter_s * fs))
    # ours: x[n+1] = Φ x[n] + Γ u[n]; relay voltage and the current arriving at node 0 at each instant
    ours_relay, ours_axle = np.zeros(len(u)), np.zeros(len(u))
    x = np.zeros(circuit.segments + 2)
    for shunts, lo, hi in (([], 0, entering), ([0], entering, len(u))):
        phi, gamma, relay_row, relay_direct = _discrete(circuit, shunts, Faults(), frequency, ratio, 1.0 / fs)
        for n in range(lo, hi):
            ours_relay[n] = relay_row @ x + relay_direct * u[n]
            ours_axle[n] = -x[0]
            x = phi @ x + gamma * u[n]
    netlist = lumped_netlist(circuit, [], [0], Faults(), frequency, ratio, title=f"{name} section {section + 1}: .tran")
    switched_shunts(netlist, ["n0"], times[entering], circuit.params.shunt_r_ohm)
    tran_source(netlist, times, u, seconds - 1.0 / fs, 1.0 / fs)
    raw = ngspice.run(netlist.text())
    spice_t = raw.vectors["time"]
    count = min(len(spice_t), len(u))
    if not np.allclose(spice_t[:count], times[:count], atol=1e-9):
        raise ValueError("ngspice's output instants are not the sample instants (the .tran's interp option)")
    worst = {}
    period = int(round(fs / frequency))
    for label, ours, probe in (("relay voltage", ours_relay, netlist.probes["relay"]),
                               ("current at the first axle", ours_axle, netlist.probes["head0"])):
        theirs = raw.value(probe)[:count]
        errors = []
        for piece in (slice(0, entering), slice(entering, count)):
            reference, mine = theirs[piece], ours[:count][piece]
            # the local amplitude: the largest value within a carrier period either side
            local = np.array([np.abs(reference[max(0, i - period):i + period + 1]).max() for i in range(len(reference))])
            useful = local > 1e-6 * np.abs(theirs).max()
            if useful.any():
                errors.append(float(np.max(np.abs(mine - reference)[useful] / local[useful])))
        worst[label] = max(errors) if errors else 0.0
    return TranResult(name, section + 1, seconds, worst, count)


# ---- the wheelsets --------------------------------------------------------------------------------
@dataclass
class WheelsetRow:
    line: str
    ballast_ohm_km: float
    train: str
    follower: str
    # quantity → (lumped error min, max; wheelset chain error min, max) over places, relative
    errors: Dict[str, List[float]] = field(default_factory=dict)
    reference: Dict[str, List[float]] = field(default_factory=dict)    # quantity → [min, max] reference, A or V

    def add(self, quantity: str, lumped: float, chain: float, reference: float) -> None:
        values = self.errors.setdefault(quantity, [math.inf, -math.inf, math.inf, -math.inf])
        for slot, ours in ((0, lumped), (2, chain)):
            error = relative_error(ours, reference)
            values[slot], values[slot + 1] = min(values[slot], error), max(values[slot + 1], error)
        span = self.reference.setdefault(quantity, [math.inf, -math.inf])
        span[0], span[1] = min(span[0], reference), max(span[1], reference)

    def chain_passed(self) -> bool:
        """The wheelset chain within WHEELSET_BOUND of the reference, and for the code behind the
        train and the relay voltage under it never below it (beyond UNSAFE_TOLERANCE)."""
        for quantity, (_, _, low, high) in self.errors.items():
            if max(abs(low), abs(high)) > WHEELSET_BOUND:
                return False
            if any(word in quantity for word in SAFE_ABOVE) and low < -UNSAFE_TOLERANCE:
                return False
        return True


def _lumped_values(core: RailLineCore, k: int, heads: List[float], frequency: float, ballast: float,
                   track: bool = False) -> Tuple[Dict[int, float], float]:
    """The network model's amplitudes: each train's current arriving at its head node (the
    bank's rows, per volt of code) and the relay-end voltage."""
    bank = core.bank
    configs, rows = bank.configuration(heads)
    shunts, head_nodes = configs[k]
    circuit = core.circuits[k]
    values = network_phasors(circuit, shunts, head_nodes, Faults(ballast), frequency, core.settings.transformer_ratio)
    currents = {j: abs(values[f"head{h}"]) for j, h in rows[k].items()}
    return currents, abs(values["relay"])


def wheelset_rows(line: Line, name: str, trains: Sequence[Train], follower: Train,
                  ballasts: Iterable[float] = BALLASTS_OHM_KM, frequency_hz: Optional[float] = None,
                  segment_m: float = AXLE_SEGMENT_M, places: int = 3, only: Optional[int] = None) -> List[WheelsetRow]:
    """Per ballast and leading train: over every design of the line's sections and ``places``
    head positions from where a follower ``gap`` behind still fits in the section to 5 m before
    the feed leads: the lumped network and the wheelset chain against ngspice per axle."""
    rows = []
    for ballast in ballasts:
        for train in trains:
            row = WheelsetRow(name, ballast, train.name, follower.name)
            settings = RailSettings(train_length_m=(train.length_m, follower.length_m),
                                    wheelset_offsets_m=(train.wheelsets_m, follower.wheelsets_m))
            alone = RailSettings(train_length_m=(train.length_m,), wheelset_offsets_m=(train.wheelsets_m,))
            with_follower = RailLineCore(line, len(line.sections), 2, 40, settings)
            single = RailLineCore(line, len(line.sections), 1, 40, alone)
            count = len(line.sections)
            for core in (with_follower, single):        # the ballast as every section's (a fault input)
                core.set_faults(-1.0, np.full(count, ballast), np.zeros(count, dtype=bool))
            for ks, circuit in _designs(line, settings, only):
                k = ks[0]
                frequency = float(with_follower.bank.geometry.carriers[k]) if frequency_hz is None else frequency_hz
                track = float(with_follower.bank.geometry.track_frequencies[k])
                span = float(train.wheelsets_m[-1])
                for gap in FOLLOWER_GAPS_M:
                    lowest = circuit.start_m + span + gap + 5.0
                    highest = circuit.feed_m - 5.0
                    if lowest > highest:
                        continue
                    for head in np.linspace(lowest, highest, places):
                        head = float(head)
                        follower_head = head - span - gap
                        heads = [head, follower_head]
                        axles = [head - o for o in train.wheelsets_m] + [follower_head - o for o in follower.wheelsets_m]
                        netlist = ac_source(axle_netlist(circuit, axles, heads, Faults(ballast), frequency,
                                                         settings.transformer_ratio, segment_m,
                                                         title=f"{name} section {k + 1}: {train.name}"), frequency)
                        raw = ngspice.run(netlist.text())
                        reference = [abs(complex(raw.value(netlist.probes[f"head{h}"])[0])) for h in (0, 1)]
                        lumped, _ = _lumped_values(with_follower, k, heads, frequency, ballast)
                        chain, _, _ = with_follower.bank.wheelset_solution(k, heads, frequency)
                        row.add("current at the first axle", lumped[0], chain[0], reference[0])
                        row.add(f"current {gap:g} m behind", lumped[1], chain[1], reference[1])
                        if gap == FOLLOWER_GAPS_M[-1]:
                            # the relay-end voltage under the train alone, at the track circuit's frequency
                            netlist = ac_source(axle_netlist(circuit, [head - o for o in train.wheelsets_m], [head],
                                                             Faults(ballast), track, settings.transformer_ratio,
                                                             segment_m, title=f"{name} section {k + 1}: relay"), track)
                            raw = ngspice.run(netlist.text())
                            reference_relay = abs(complex(raw.value(netlist.probes["relay"])[0]))
                            _, lumped_relay = _lumped_values(single, k, [head], track, ballast)
                            _, _, chain_relay = single.bank.wheelset_solution(k, [head], track)
                            row.add("relay voltage under the train", lumped_relay, chain_relay, reference_relay)
            rows.append(row)
    return rows


# ---- tables ---------------------------------------------------------------------------------------
def _percent(value: float) -> str:
    if math.isinf(value):
        return "∞"
    if abs(value) >= 10.0:
        return f"{value:+.3g}×" if value > 0 else f"{value * 100:+.0f} %"
    return f"{100 * value:+.2g} %" if abs(value) >= 1e-4 else f"{100 * value:+.1e} %"


def ac_table(rows: Sequence[AcRow]) -> List[str]:
    quantities = ["relay voltage", "current at the first axle", "entry current", "coil EMF"]
    lines = ["| line | sections | frequency Hz | ballast Ω·km | " + " | ".join(quantities) + " |",
             "|---|---|---|---|" + "---|" * len(quantities)]
    for row in rows:
        lines.append(f"| {row.line} | {row.sections} | {row.frequency_hz:g} | {row.ballast_ohm_km:g} | "
                     + " | ".join(f"{row.worst.get(q, 0.0):.1e}" for q in quantities) + " |")
    return lines


def tran_table(results: Sequence[TranResult]) -> List[str]:
    lines = ["| line | section | window s | samples | relay voltage | current at the first axle |", "|---|---|---|---|---|---|"]
    for r in results:
        lines.append(f"| {r.line} | {r.section} | {r.seconds:g} | {r.samples} | {r.worst['relay voltage']:.1e} | "
                     f"{r.worst['current at the first axle']:.1e} |")
    return lines


def wheelset_table(rows: Sequence[WheelsetRow]) -> List[str]:
    lines = ["| line | ballast Ω·km | train | quantity | per axle (ngspice), A or V per V | lumped, error | "
             "wheelset chain, error |", "|---|---|---|---|---|---|---|"]
    for row in rows:
        for quantity, (lumped_low, lumped_high, chain_low, chain_high) in row.errors.items():
            low, high = row.reference[quantity]
            lines.append(f"| {row.line} | {row.ballast_ohm_km:g} | {row.train} | {quantity} | {low:.3g}–{high:.3g} | "
                         f"{_percent(lumped_low)} … {_percent(lumped_high)} | "
                         f"{_percent(chain_low)} … {_percent(chain_high)} |")
    return lines


def crosscheck_system(setup, section: Optional[int], out) -> bool:
    """The three comparisons for a system's (or a line file's) rail line and its trains, as
    tables on ``out``; True when every one is within its bound."""
    line, settings = setup.line, setup.settings
    name = line.path.stem
    carriers = sorted({float(settings.carrier_hz or s.carrier_hz) for s in line.sections}
                      | {float(s.carrier_hz) for s in line.sections})
    only = None if section is None else setup.section(section)     # a section the line has
    passed = True
    out.write(f"## .ac: the rail line's network against ngspice ({name}; largest relative difference, bound {AC_BOUND:g})\n\n")
    rows = ac_rows(line, name, carriers, settings=settings, only=only)
    out.write("\n".join(ac_table(rows)) + "\n\n")
    passed &= all(r.passed() for r in rows)
    k = only or 0
    out.write(f"## .tran: the discretised model against ngspice (of the local amplitude, bound {TRAN_BOUND:g})\n\n")
    tran = [tran_check(line, name, k, settings=settings)]
    out.write("\n".join(tran_table(tran)) + "\n\n")
    passed &= all(r.passed() for r in tran)
    trains = [Train(t.stock_file, t.length_m, t.wheelsets_m) for t in setup.trains]
    unique = {t.name: t for t in trains}
    trains = list(unique.values()) or [shipped_train("passenger_chs7.json")]
    follower = trains[0]
    leaders = trains + [Train(*LIGHT_ENGINE)]
    out.write(f"## wheelsets: lumped and the wheelset chain against every axle in ngspice (bound ±{WHEELSET_BOUND:g}; "
              f"following train: {follower.name})\n\n")
    wheelsets = wheelset_rows(line, name, leaders, follower, only=only)
    out.write("\n".join(wheelset_table(wheelsets)) + "\n\n")
    passed &= all(r.chain_passed() for r in wheelsets)
    out.write(("every comparison within its bound" if passed else "a comparison is OUTSIDE its bound") + "\n")
    return passed
