"""The per-train part of summary.json (docs/interfaces.md, "Results"), gathered while the run goes.

A train is a Traction component. When an AtoController drives it (its ``command`` output is
connected to the train's ``command`` input), the train's entry also carries the ATP/ATO
verdict: overspeed, interventions, signals passed at danger, every timetabled stop after the
origin (reached: arrival time and deviation, stop error; or ``reached: false`` with its
scheduled arrival) and every change of the aspect the ATP acted upon.
"""
from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from fmus.data.loader import (DATA, DEFAULT_LINE, DEFAULT_ROLLING_STOCK, DEFAULT_TIMETABLE, load_line,
                              load_rolling_stock, load_timetable)
from fmus import ato_controller, loco_receiver, traction
from fmus.errors import FmuInputError
from fmus.loco_receiver.parameters import display_hold_s
from fmus.signalling import alsn, cab_systems
from fmus.signalling import aspects as sig
from fmus.signalling.aspects import ASPECT_NAMES
from fmus.signalling.block_rules import NO_CODE_FREE_BLOCKS, block_codes
from fmus.signalling.digital_messages import FREE_BLOCKS_OPEN

from fmus.units import J_PER_KWH, KMH_PER_MPS
from orchestrator.errors import print_warning
from orchestrator.graph import TICKS_PER_SECOND, SystemGraph
from orchestrator.ports import element_name, split_element
from orchestrator.protocols import MasterView, StepRecord, SummaryObserver

TRAIN_MODEL = traction.MODEL_IDENTIFIER
ATO_MODEL = ato_controller.MODEL_IDENTIFIER
TRAIN_OUTPUTS = ("energy", "x")
ATO_OUTPUTS = ("stop_index", "arrival_time", "stop_error", "atp_aspect", "max_overspeed", "atp_interventions",
               "emergency_brakings", "vigilance_brakings", "signals_passed_at_danger", "departure_hold")


@dataclass
class _Train:
    name: str
    ato: Optional[str]
    timetable: list = field(default_factory=list)
    stops: List[dict] = field(default_factory=list)
    aspects: List[dict] = field(default_factory=list)
    last_stop_index: int = 1
    last_aspect: Optional[int] = None
    min_headway_m: Optional[float] = None     # to the tail of the train ahead on its line


def trains_of(graph: SystemGraph) -> List[_Train]:
    trains = []
    for name in graph.order:
        if graph.nodes[name].interface.model_identifier != TRAIN_MODEL:
            continue
        ato = next((e.source for e in graph.edges if e.target == name and e.target_var.name == "command"
                    and graph.nodes[e.source].interface.model_identifier == ATO_MODEL), None)
        trains.append(_Train(name, ato, _timetable(graph, ato) if ato else []))
    return trains


def _timetable(graph: SystemGraph, ato: str) -> list:
    """The ATO's timetable as it will read it (same files, same defaults)."""

    params = graph.nodes[ato].parameters
    try:
        line = load_line(params.get("line_file") or DEFAULT_LINE)
        return load_timetable(params.get("timetable_file") or DEFAULT_TIMETABLE, line)
    except FmuInputError:
        return []     # the FMU itself reports the bad file at initialisation


class _OutputJudge(SummaryObserver):
    """A verdict reading the outputs it names in ``outputs_needed`` through slots bound once
    when the run starts (``_slots`` stays None when the run failed before that)."""

    _slots: Optional[Dict[tuple, tuple]] = None

    def _bind_slots(self, master: MasterView) -> None:
        self._slots = {}
        for component, variables in self.outputs_needed().items():
            for var in variables:
                self._slots[(component, var)] = master.output_slot(component, var)

    def _value(self, component: str, var: str):
        buffer, index = self._slots[(component, var)]
        return buffer.values[index]


class TrainVerdict(_OutputJudge):
    """Observer: records stops and aspect changes of every ATO-driven train."""

    def __init__(self, graph: SystemGraph):
        self.trains = trains_of(graph)
        self._headways = _Headways(graph, self.trains)

    def outputs_needed(self) -> Dict[str, List[str]]:
        needed: Dict[str, List[str]] = {}
        for train in self.trains:
            needed.setdefault(train.name, []).extend(TRAIN_OUTPUTS)
            if train.ato:
                needed.setdefault(train.ato, []).extend(ATO_OUTPUTS)
        return needed

    def started(self, master: MasterView, step: StepRecord) -> None:
        self._bind_slots(master)
        for train in self.trains:
            if train.ato:
                self._check(master, train, step.tick)
        self._headways.check(master, step.tick, self._value)

    def after_tick(self, master: MasterView, step: StepRecord) -> None:
        self._headways.check(master, step.tick, self._value)
        for train in self.trains:
            if train.ato and train.ato in step.stepped:     # its outputs change only when it steps
                self._check(master, train, step.tick)

    def _check(self, master: MasterView, train: _Train, tick: int) -> None:
        master.fresh(train.ato)
        master.fresh(train.name)
        stop_index = int(self._value(train.ato, "stop_index"))
        if stop_index != train.last_stop_index:
            train.last_stop_index = stop_index
            self._record_stop(train, stop_index)
        aspect = int(self._value(train.ato, "atp_aspect"))
        if aspect != train.last_aspect:
            train.last_aspect = aspect
            self._record_aspect(train, tick, aspect)

    def _record_stop(self, train: _Train, stop_index: int) -> None:
        arrival = float(self._value(train.ato, "arrival_time"))
        entry = {"station": None, "reached": True, "scheduled_arrival_s": None, "arrival_s": arrival,
                 "arrival_deviation_s": None, "stop_error_m": float(self._value(train.ato, "stop_error")),
                 "stop_index": stop_index}
        if 0 < stop_index <= len(train.timetable):
            stop = train.timetable[stop_index - 1]
            entry.update(station=stop.station, scheduled_arrival_s=stop.arrival_s,
                         arrival_deviation_s=arrival - stop.arrival_s if stop.arrival_s is not None else None)
        train.stops.append(entry)

    @staticmethod
    def stops_of(train: _Train) -> List[dict]:
        """Every timetabled stop after the origin, in timetable order: the arrival recorded when
        the train reached it, else ``reached: false`` with its scheduled arrival (the stop was
        missed, or the run ended first); then any arrival beyond the timetable."""
        reached = {entry["stop_index"]: entry for entry in train.stops}
        stops = []
        for index, stop in enumerate(train.timetable[1:], start=2):
            entry = reached.pop(index, None)
            if entry is None:
                entry = {"station": stop.station, "reached": False, "scheduled_arrival_s": stop.arrival_s,
                         "arrival_s": None, "arrival_deviation_s": None, "stop_error_m": None}
            stops.append({k: v for k, v in entry.items() if k != "stop_index"})
        stops += [{k: v for k, v in entry.items() if k != "stop_index"} for _, entry in sorted(reached.items())]
        return stops

    def _record_aspect(self, train: _Train, tick: int, aspect: int) -> None:

        train.aspects.append({"t": tick / TICKS_PER_SECOND, "x": float(self._value(train.name, "x")),
                              "aspect": ASPECT_NAMES.get(aspect, str(aspect))})

    def summary_section(self) -> Dict[str, list]:
        return {"trains": self.summary()}

    def summary(self) -> List[dict]:
        if self._slots is None:              # the run failed before it started
            return [{"name": train.name} for train in self.trains]
        entries = []
        for train in self.trains:
            entry = {"name": train.name, "energy_kwh": float(self._value(train.name, "energy")) / J_PER_KWH}
            if self._headways.shares_line(train.name):
                entry["min_headway_m"] = train.min_headway_m
            if train.ato:
                entry.update(
                    ato=train.ato,
                    max_overspeed_kmh=float(self._value(train.ato, "max_overspeed")) * KMH_PER_MPS,
                    atp_interventions=int(self._value(train.ato, "atp_interventions")),
                    emergency_brakings=int(self._value(train.ato, "emergency_brakings")),
                    # of those, the ones for an unanswered vigilance check (docs/ato.md#vigilance-device)
                    vigilance_brakings=int(self._value(train.ato, "vigilance_brakings")),
                    signals_passed_at_danger=int(self._value(train.ato, "signals_passed_at_danger")),
                    # standing past a departure time without a permissive cab code (docs/ato.md)
                    departure_hold_s=float(self._value(train.ato, "departure_hold")),
                    stops=self.stops_of(train), aspects=train.aspects)
            entries.append(entry)
        return entries


class _Headways:
    """Per train, the least distance from its head to the tail of the train ahead on the same
    line (trains whose ``line_file`` is the same file), checked every CHECK_INTERVAL_S."""

    def __init__(self, graph: SystemGraph, trains: List[_Train]):

        lengths = train_lengths(graph)
        groups: Dict[str, List[_Train]] = {}
        for train in trains:
            line = str(data_file(_parameter(graph, train.name, "line_file"), DEFAULT_LINE))
            groups.setdefault(line, []).append(train)
        self.groups = [(group, [lengths[t.name] for t in group]) for group in groups.values() if len(group) > 1]
        self._shared = {t.name for group, _ in self.groups for t in group}
        self._interval_ticks = max(1, graph.base_ticks * -(-round(CHECK_INTERVAL_S * TICKS_PER_SECOND) // graph.base_ticks))

    def shares_line(self, name: str) -> bool:
        return name in self._shared

    def check(self, master: MasterView, tick: int, value) -> None:
        if not self.groups or tick % self._interval_ticks:
            return
        for group, lengths in self.groups:
            heads = []
            for train in group:
                master.fresh(train.name)
                heads.append(float(value(train.name, "x")))
            for train, head in zip(group, heads):
                gaps = [other - length - head for other, length in zip(heads, lengths) if other > head]
                if gaps and (train.min_headway_m is None or min(gaps) < train.min_headway_m):
                    train.min_headway_m = min(gaps)


# ---- the track as the orchestrator knows it (docs/scenarios.md, "Results: summary.json") ----
def _parameter(graph: SystemGraph, component: str, name: str, default=None):
    """A parameter (or an input's start value) as the component will read it."""
    node = graph.nodes[component]
    if name in node.parameters:
        return node.parameters[name]
    var = node.interface.variables.get(name)
    return default if var is None or var.start is None else var.start


def system_object(cab: cab_systems.CabSystem, parameters: Mapping[str, object]):
    """The cab system's object as a component with these parameters reads it: its
    ``codes_file`` where one is set (resolved as the FMU opens it), else the bundled table."""
    table = parameters.get("codes_file")
    return cab.system(str(data_file(table, cab.codes_file)) if table and cab.codes_file else None)


def data_file(value, default):
    """A ``*_file`` parameter as the FMU opens it: resolved by the graph, else a bundled file."""
    from pathlib import Path


    if not value:
        return default
    path = Path(str(value))
    return path if path.is_absolute() or path.exists() else DATA / path


def train_lengths(graph: SystemGraph) -> Dict[str, float]:
    """Length of every train (Traction component): the longer of the rail line's
    ``train_length[j]`` of the slot its ``x`` feeds and its rolling-stock file's length. The
    verdict judges against the real train: a rail line given a shorter train (its 400 m default
    under a 944 m freight train) would miss the rear of it, and taking the rail line's figure
    alone would make the verdict agree with that mistake instead of catching it."""

    lengths = {}
    for edge in graph.edges:
        if edge.source_var.name != "x":
            continue
        port, slot = split_element(edge.target_var.name) or ("", ())
        if port == "x_head" and slot:
            lengths[edge.source] = float(_parameter(graph, edge.target, element_name("train_length", slot), 0.0))
    for name in graph.order:
        if graph.nodes[name].interface.model_identifier == TRAIN_MODEL:
            try:
                stock = data_file(_parameter(graph, name, "rolling_stock_file"), DEFAULT_ROLLING_STOCK)
                lengths[name] = max(lengths.get(name, 0.0), load_rolling_stock(stock).length_m)
            except FmuInputError:
                lengths.setdefault(name, 0.0)   # the FMU itself reports the bad file at initialisation
    return lengths


class _Track:
    """One rail line: its track circuits and blocks (the line file it reads), the trains on it
    (the Traction components feeding its ``x_head[j]``, with their lengths) and the broken rail
    the scenario sets (its ``broken_rail_at`` input). :meth:`rules` reads the real occupancy,
    not the rail line's relays: a circuit is occupied when a train overlaps it or its rail is
    broken."""

    def __init__(self, graph: SystemGraph, rail: str, line, lengths: Dict[str, float], block_aspects: int):

        self.rail, self.line, self.block_aspects = rail, line, block_aspects
        self.block_of = np.array(line.block_of_section)
        self.trains = [e.source for e in graph.edges if e.target == rail and e.target_var.name.startswith("x_head[")
                       and graph.nodes[e.source].interface.model_identifier == TRAIN_MODEL]
        # plain lists: the checks run every 0.1 s between thousands of signal ticks, where
        # numpy's calls on a few elements cost 5-20 us each, cold, against 1-2 us for the same
        # comparisons in Python (docs/performance.md#one-sample-per-frame-as-a-deadline)
        self._starts = [float(s.start_m) for s in line.sections]
        self._ends = [float(s.end_m) for s in line.sections]
        self._lengths = [float(lengths.get(t, 0.0)) for t in self.trains]
        self._block_end = [float(line.block_bounds[b][1]) for b in line.block_of_section]
        self.coil_offset_m = float(_parameter(graph, rail, "coil_offset", 0.0))
        # the time the track takes to detect a change: the relay's drop-out delay
        self.detection_s = float(_parameter(graph, rail, "relay_drop_out_delay", 0.0))
        self.broken_rail_start_m = float(_parameter(graph, rail, "broken_rail_at", -1.0))
        self._broken_rail = None
        self._cache = (None, None)
        self._codes = (None, None)          # (the circuits the trains overlap, their block rules)

    def bind(self, master: MasterView, slots: Dict[tuple, tuple]) -> None:

        self._x = [slots[(t, "x")] for t in self.trains]
        var = master.graph.nodes[self.rail].interface.variables.get("broken_rail_at")
        buffer = master.slaves[self.rail].inputs.get(var.type) if var is not None else None
        if buffer is not None and np.any(buffer.vr_array == var.vr):       # bound: a scenario drives it
            self._broken_rail = (buffer, int(np.flatnonzero(buffer.vr_array == var.vr)[0]))

    def heads_m(self, master: MasterView) -> List[float]:

        for train in self.trains:
            master.fresh(train)
        return [float(buffer.values[index]) for buffer, index in self._x]

    def broken_rail_m(self) -> float:
        if self._broken_rail is None:
            return self.broken_rail_start_m
        buffer, index = self._broken_rail
        return float(buffer.values[index])

    def _circuits_over(self, tail_m: float, head_m: float) -> Tuple[int, int]:
        """(first, last + 1) of the circuits with start <= head and tail < end (the line file's
        sections are in order and do not overlap: fmus/data/loader.py)."""
        return bisect.bisect_right(self._ends, tail_m), bisect.bisect_right(self._starts, head_m)

    def _spans(self, heads_m: Sequence[float]) -> tuple:
        """The circuits each train overlaps and the broken rail's circuit, as (first, last + 1)."""
        spans = [self._circuits_over(head - length, head) for head, length in zip(heads_m, self._lengths)]
        broken = self.broken_rail_m()
        if broken >= 0:                 # a broken rail drops its circuit's relay (control mode)
            spans.append(self._circuits_over(broken, broken))
        return tuple(spans)

    def _occupancy(self, spans: tuple) -> np.ndarray:
        occupied = np.zeros(len(self._starts), dtype=bool)
        for first, end in spans:
            occupied[first:end] = True
        return occupied

    def rules(self, master: MasterView, tick: int):
        """(trains' heads, block rules of the real occupancy), once per tick."""

        if self._cache[0] != tick:
            heads = self.heads_m(master)
            spans = self._spans(heads)
            if spans != self._codes[0]:        # the rules change only with the occupancy
                self._codes = (spans, block_codes(self._occupancy(spans), self.block_of, self.block_aspects))
            self._cache = (tick, (heads, self._codes[1]))
        return self._cache[1]

    def occupied_ahead_in_block(self, heads_m: Sequence[float], train: int, coil_m: float, circuit: int) -> bool:
        """Whether another train or the broken rail lies between the coil of train ``train`` and
        the exit signal of its block: the block rules applied to the track ahead of the coil
        inside its own circuit too (a train ahead in the same circuit)."""

        end_m = self._block_end[circuit]
        for other, (head, length) in enumerate(zip(heads_m, self._lengths)):
            if other != train and head > coil_m and head - length < end_m:
                return True
        return coil_m < self.broken_rail_m() < end_m

    def circuit_at(self, x_m: float) -> int:
        """0-based track circuit containing ``x_m``, -1 outside every circuit."""

        k = bisect.bisect_right(self._starts, x_m) - 1
        return k if k >= 0 and x_m < self._ends[k] else -1


def tracks_of(graph: SystemGraph, rails) -> Dict[str, _Track]:
    """The tracks of the rail lines ``rails`` (name → coder feeding it); a rail line whose line
    file does not load is not judged (the FMU reports the file)."""

    lengths = train_lengths(graph)
    tracks = {}
    for rail, coder in rails.items():
        try:
            line = load_line(data_file(_parameter(graph, rail, "line_file"), DEFAULT_LINE))
        except FmuInputError:
            continue
        aspects = int(_parameter(graph, coder, "block_aspects", 3))
        tracks[rail] = _Track(graph, rail, line, lengths, aspects)
    return tracks


# ---- receivers: decoded codes, errors, wrong-side failures (docs/interfaces.md, "Results") ---
RECEIVER_MODEL = loco_receiver.MODEL_IDENTIFIER
RECEIVER_OUTPUTS = ("aspect", "code_valid", "free_blocks", "v_target", "v_permitted", "decoded_codes", "errors")
SPEED_TOLERANCE_KMH = 0.5
HOLD_DECAY_S = 0.2


@dataclass
class _Episodes:
    """Episodes of a receiver showing more than it may, counted once each when longer than the
    allowed latency (latency_s)."""

    latency_s: float
    start_s: Optional[float] = None
    counted: bool = False
    count: int = 0
    seconds: float = 0.0
    last_check_s: Optional[float] = None
    events: List[dict] = field(default_factory=list)

    def check(self, now: float, too_permissive: Optional[bool], event: dict,
              latency_s: Optional[float] = None) -> None:
        """``too_permissive`` None: not judged now (the coil outside every section);
        ``latency_s``: the latency allowed now, when not ``self.latency_s`` (a loss of code)."""
        latency_s = self.latency_s if latency_s is None else latency_s
        if too_permissive:
            if self.start_s is None:
                self.start_s, self.counted = now, False
            elif now - self.start_s > latency_s:
                if not self.counted:
                    self.count += 1
                    self.counted = True
                    self.events.append({"t": self.start_s, **event})
                self.seconds += now - max(self.last_check_s or now, self.start_s + latency_s)
        else:
            self.start_s = None
        self.last_check_s = now


@dataclass
class _Receiver:
    name: str
    train: str
    rail: str
    coder: str
    slot: int                      # the train's index j on the rail line (1-based)
    cab: cab_systems.CabSystem
    system: object                 # the descriptor's system object (None for ALSN: its codes are aspects)
    category: str
    latency_s: float
    hold_s: float                                # a code that disappears may be shown this long (display hold)
    wrong_side: Optional[_Episodes] = None       # against the code the coder sent
    unsafe: Optional[_Episodes] = None           # against the real occupancy by the block rules
    coding: Optional[object] = None              # TABLE systems: the code the block rules give each circuit

    def __post_init__(self):
        self.wrong_side = self.wrong_side or _Episodes(self.latency_s)


def receivers_of(graph: SystemGraph) -> List[_Receiver]:
    """Receivers fed by a rail line whose train and coder are known; others are not judged."""

    found = []
    for name in graph.order:
        node = graph.nodes[name]
        if node.interface.model_identifier != RECEIVER_MODEL:
            continue
        feed = next((e for e in graph.edges if e.target == name and e.target_var.name.startswith("e_coil[")), None)
        if feed is None:
            continue
        rail = feed.source
        slot = split_element(feed.source_var.name)[1][0]
        train = next((e.source for e in graph.edges if e.target == rail and e.target_var.name == f"x_head[{slot}]"), None)
        coder = next((e.source for e in graph.edges if e.target == rail and e.target_var.name.startswith("u_tx[")), None)
        if train is None or coder is None:
            continue
        params = node.parameters
        try:
            cab = cab_systems.of_parameters(params)
            system = system_object(cab, params)
        except FmuInputError:
            continue                  # the receiver itself reports it at initialisation
        category = str(params.get("train_category", "passenger"))
        latency = cab.latency_s(params)
        try:
            # + the receiver's filters' decay before its relay or squelch lets go of the code
            hold = max(display_hold_s(cab.name, params) + HOLD_DECAY_S, latency)
        except (TypeError, ValueError):
            continue                  # a bad parameter value: the receiver reports it at initialisation
        found.append(_Receiver(name, train, rail, coder, slot, cab, system, category, latency, hold))
    return found


CHECK_INTERVAL_S = 0.1


class ReceiverVerdict(_OutputJudge):
    """Observer: judges every receiver twice, each time counting episodes longer than the
    system's stated latency once:

    * **wrong-side failures** — against the code transmitted into the section under its
      train's coils (the rail line's ``coil_section``, the coder's ``code_tx``): more permissive
      (aspect, free blocks or speed) than sent;
    * **unsafe indications** — against the track: more permissive than the block rules
      (fmus/signalling/block_rules.py) allow for the track circuit under the coils from the
      real occupancy (every train's extent from its ``x`` and length, the broken rail), and no
      code at all when another train or the broken rail lies between the coils and the
      block's exit signal (a train ahead in the same circuit), which
      the orchestrator computes itself; the latency then also holds the track's detection time
      (the rail line's relay drop-out delay). This catches a coder or a track detection that is
      wrong, which the first check cannot see."""

    def __init__(self, graph: SystemGraph):
        self.graph = graph
        self.receivers = receivers_of(graph)
        self.tracks = tracks_of(graph, {r.rail: r.coder for r in self.receivers})
        for r in self.receivers:
            track = self.tracks.get(r.rail)
            if track is not None:
                r.unsafe = _Episodes(r.latency_s + track.detection_s)
                try:
                    if r.cab.family == cab_systems.TABLE:
                        r.coding = r.system.block_coding(track.line, track.block_aspects)
                except FmuInputError:
                    r.unsafe = None    # a route or limit the code table cannot send: the coder reports it

    def outputs_needed(self) -> Dict[str, List[str]]:
        needed: Dict[str, List[str]] = {}
        for r in self.receivers:
            needed.setdefault(r.name, []).extend(RECEIVER_OUTPUTS)
            needed[r.name].extend(r.cab.judged_outputs)
            needed.setdefault(r.rail, []).append(f"coil_section[{r.slot}]")
            codes = [v for v in self.graph.nodes[r.coder].interface.variables if v.startswith("code_tx[")]
            needed.setdefault(r.coder, []).extend(codes)
        for track in self.tracks.values():
            for train in track.trains:
                needed.setdefault(train, []).append("x")
        return needed

    def started(self, master: MasterView, step: StepRecord) -> None:
        self._bind_slots(master)
        for track in self.tracks.values():
            track.bind(master, self._slots)
        # checked at the first multiple of the receiver's step from CHECK_INTERVAL_S on: an
        # episode is timed to that, against stated latencies of 1.1 s (FIRE) to 4.5 s (ALSN)
        self._check_ticks = {}
        for r in self.receivers:
            step = master.graph.nodes[r.name].step_ticks
            self._check_ticks[r.name] = step * max(1, -(-round(CHECK_INTERVAL_S * TICKS_PER_SECOND) // step))
        # looked up once: the checks run often
        self._coil_section = {r.name: self._slots[(r.rail, f"coil_section[{r.slot}]")] for r in self.receivers}
        self._code_tx = {}
        for r in self.receivers:
            count = sum(1 for v in self.graph.nodes[r.coder].interface.variables if v.startswith("code_tx["))
            self._code_tx[r.name] = [self._slots[(r.coder, f"code_tx[{k}]")] for k in range(1, count + 1)]

    def after_tick(self, master: MasterView, step: StepRecord) -> None:
        now, tick = step.time_s, step.tick
        for r in self.receivers:
            if r.name not in step.stepped or tick % self._check_ticks[r.name]:
                continue
            for component in (r.name, r.rail, r.coder):
                master.fresh(component)
            if r.unsafe is not None:
                self._check_track(master, r, tick, now)
            buffer, index = self._coil_section[r.name]
            section = int(buffer.values[index])
            if section <= 0:
                r.wrong_side.check(now, None, {})
                continue
            buffer, index = self._code_tx[r.name][section - 1]
            sent = int(buffer.values[index])
            meant = sent if r.cab.family == cab_systems.NUMERIC else transmitted_indication(r.system, sent, r.category)
            nothing_sent = not meant if r.cab.family == cab_systems.NUMERIC else meant is None
            r.wrong_side.check(now, self._more_permissive(r, meant), {"section": section, "code_sent": sent},
                               r.hold_s if nothing_sent else None)

    def _check_track(self, master: MasterView, r: _Receiver, tick: int, now: float) -> None:

        track = self.tracks[r.rail]
        heads, rules = track.rules(master, tick)
        train = track.trains.index(r.train)
        coil_m = float(heads[train]) + track.coil_offset_m
        circuit = track.circuit_at(coil_m)
        if circuit < 0:
            r.unsafe.check(now, None, {})
            return
        free = int(rules.free_blocks[circuit])
        if free != NO_CODE_FREE_BLOCKS and track.occupied_ahead_in_block(heads, train, coil_m, circuit):
            free = NO_CODE_FREE_BLOCKS          # occupied between the coil and the block's exit signal
        if r.cab.family == cab_systems.NUMERIC:
            allowed = alsn.NO_CODE if free == NO_CODE_FREE_BLOCKS else int(rules.alsn_code[circuit])
        elif free == NO_CODE_FREE_BLOCKS:
            allowed = None
        elif r.coding is not None:
            code = int(r.coding.codes(rules)[circuit])
            allowed = r.system.indication(code, r.category) if code else None
        else:
            allowed = r.system.indication(r.system.command_for(min(free, FREE_BLOCKS_OPEN)), r.category)
        nothing_allowed = free == NO_CODE_FREE_BLOCKS
        r.unsafe.check(now, self._more_permissive(r, allowed),
                       {"section": circuit + 1, "free_blocks_allowed": None if free < 0 else min(free, FREE_BLOCKS_OPEN),
                        "aspect_shown": int(self._value(r.name, "aspect"))},
                       r.hold_s + self.tracks[r.rail].detection_s if nothing_allowed else None)

    def _more_permissive(self, r: _Receiver, meant) -> bool:
        """Whether the receiver shows more than ``meant``: an ALSN code (aspect enumeration, 0
        none) or a digital Indication (None: no code)."""
        aspect = int(self._value(r.name, "aspect"))
        if r.cab.family == cab_systems.NUMERIC:                       # ALSN: code_tx is in the aspect enumeration
            return sig.restrictiveness(aspect) > sig.restrictiveness(meant if meant else sig.WHITE)
        shown = (sig.restrictiveness(aspect), int(self._value(r.name, "free_blocks")),
                 float(self._value(r.name, "v_target")) * KMH_PER_MPS, float(self._value(r.name, "v_permitted")) * KMH_PER_MPS)
        if not bool(self._value(r.name, "code_valid")):
            return False                           # white / red: the no-code rules, never permissive
        if meant is None:                          # nothing sent: any valid code is more than that
            return True
        if (shown[0] > sig.restrictiveness(meant.aspect) or shown[1] > meant.free_blocks
                or shown[2] > meant.target_kmh + SPEED_TOLERANCE_KMH
                or shown[3] > meant.permitted_kmh + SPEED_TOLERANCE_KMH):
            return True
        if r.cab.judged_outputs:        # the system's own fields (TVM-430: a target farther, a gradient less falling)
            return r.system.shows_beyond(meant.code, {port: self._value(r.name, port) for port in r.cab.judged_outputs})
        return False

    def summary_section(self) -> Dict[str, list]:
        judged = {r.name for r in self.receivers}
        unjudged = [name for name in self.graph.order
                    if self.graph.nodes[name].interface.model_identifier == RECEIVER_MODEL and name not in judged]
        section = {"receivers": self.summary()}
        if unjudged:            # no coder, rail line or train position known for them: said, never "safe"
            section["receivers_not_judged"] = unjudged
        return section

    def summary(self) -> List[dict]:
        entries = []
        for r in self.receivers:
            entry = {"receiver": r.name, "train": r.train, "system": r.cab.name, "rail": r.rail, "coder": r.coder,
                     "slot": r.slot, "latency_s": r.latency_s, "wrong_side_failures": r.wrong_side.count,
                     "wrong_side_s": round(r.wrong_side.seconds, 3), "wrong_side_events": r.wrong_side.events}
            if r.unsafe is not None:
                entry.update(unsafe_indications=r.unsafe.count, unsafe_s=round(r.unsafe.seconds, 3),
                             unsafe_latency_s=r.unsafe.latency_s, unsafe_events=r.unsafe.events)
            if self._slots is not None:
                entry.update(decoded_codes=int(self._value(r.name, "decoded_codes")),
                             code_errors=int(self._value(r.name, "errors")))
            entries.append(entry)
        return entries


def transmitted_indication(system, code: int, category: str):
    """What a coder's raw ``code_tx`` means; None for no code (the system's reading)."""
    command = system.command_of_code(code)
    return None if command is None else system.indication(command, category)


def stop_cells(stop: dict) -> Tuple[str, str, str, str, str, bool]:
    """One stop of a train's summary entry as the CLI and the report show its figures:
    (station, scheduled arrival ``1015``, arrival ``1014.9``, deviation ``+0.0`` s, stop error
    ``-0.16`` m, reached); a figure not known, or of a stop not reached, is ``""``."""
    reached = bool(stop.get("reached", True))

    def shown(key: str, form: str) -> str:
        value = stop.get(key)
        return "" if value is None or not reached else format(value, form)

    scheduled = stop.get("scheduled_arrival_s")
    return (str(stop.get("station")), "" if scheduled is None else f"{scheduled:.0f}", shown("arrival_s", ".1f"),
            shown("arrival_deviation_s", "+.1f"), shown("stop_error_m", "+.2f"), reached)


def stop_text(stop: dict) -> str:
    """One stop in a few words: ``B +0.0 s / -0.16 m``, or ``C not reached (due 1015 s)``."""
    station, due, arrival, deviation, error, reached = stop_cells(stop)
    if not reached:
        return f"{station} not reached" + (f" (due {due} s)" if due else "")
    return f"{station} {f'{deviation} s' if deviation else f'at {arrival} s'} / {error} m"


def missed_stops(summary: dict) -> List[Tuple[str, str]]:
    """(train, station) of every timetabled stop a run did not reach."""
    return [(train["name"], stop.get("station")) for train in summary.get("trains", [])
            for stop in train.get("stops", []) if not stop.get("reached", True)]


def safety_parts(summary: dict) -> Tuple[bool, str]:
    """The run's safety verdict from summary.json: safe when no train passed a signal at danger
    and no receiver had a wrong-side failure or an unsafe indication (docs/scenarios.md); the
    text is the verdict and its counts (``safe (signals passed at danger 0, …)``)."""
    spad = sum(t.get("signals_passed_at_danger", 0) for t in summary.get("trains", []))
    wrong = sum(r.get("wrong_side_failures", 0) for r in summary.get("receivers", []))
    unsafe = sum(r.get("unsafe_indications", 0) for r in summary.get("receivers", []))
    unjudged = summary.get("receivers_not_judged", [])
    safe = spad == 0 and wrong == 0 and unsafe == 0 and not unjudged
    word = "UNSAFE" if spad or wrong or unsafe else ("not judged" if unjudged else "safe")
    # a run that stopped early was judged over what it simulated, no further
    held = "" if summary.get("completed", True) else \
        f" over 0–{float(summary.get('sim_time_s') or 0.0):.1f} s only (the run did not complete)"
    return safe, (f"{word} (signals passed at danger {spad}, "
                  f"wrong-side failures {wrong}, unsafe indications {unsafe}"
                  + (f"; receivers not judged: {', '.join(unjudged)}" if unjudged else "") + ")" + held)


def safety_verdict(summary: dict) -> Tuple[bool, str]:
    """:func:`safety_parts` as one line: ``safety: safe (…)``."""
    safe, text = safety_parts(summary)
    return safe, f"safety: {text}"


def verdict_lines(summary: dict) -> List[str]:
    """What `railcosim run` prints after its first line (docs/scenarios.md quotes them): per
    train its energy, arrivals, ATP interventions, emergency brakings, SPADs and, when it stood
    past a departure time for want of a permissive code, how long; then the safety verdict, or
    ``no signal chain`` for a run without a receiver to judge."""
    lines = []
    for train in summary.get("trains", []):
        stops = ", ".join(stop_text(s) for s in train.get("stops", []))
        line = f"{train['name']}: {train.get('energy_kwh', 0.0):.1f} kWh" + (f"; arrivals {stops}" if stops else "")
        if "atp_interventions" in train:
            line += (f"; ATP interventions {train['atp_interventions']}, emergency brakings "
                     f"{train['emergency_brakings']}, SPAD {train['signals_passed_at_danger']}")
        if train.get("departure_hold_s"):
            line += f"; held at departure {train['departure_hold_s']:.1f} s"
        lines.append(line)
    if summary.get("receivers"):
        lines.append(safety_verdict(summary)[1])
    elif summary.get("trains"):
        spad = sum(t.get("signals_passed_at_danger", 0) for t in summary["trains"])
        lines.append(f"safety: no signal chain (no receiver to judge; signals passed at danger {spad})")
    return lines


def railway_verdicts(graph: SystemGraph, warn: Callable[[str], None] = print_warning) -> list:
    """The summary observers of a railway run: per train (arrivals, stops, energy, ATP,
    headway) and per receiver (codes, errors, wrong-side failures, unsafe indications). Pass as
    ``RunOptions.summaries`` (``functools.partial(railway_verdicts, warn=options.warn)`` to send
    its warnings where the run's go). The system's railway data are checked first (a bad one is
    a UserError before the run starts, what is suspicious goes to ``warn``:
    orchestrator/verdicts/system_checks.py)."""
    from orchestrator.verdicts.system_checks import check_railway_data

    check_railway_data(graph, warn)
    return [TrainVerdict(graph), ReceiverVerdict(graph)]
