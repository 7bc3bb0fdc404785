"""The per-train part of summary.json (docs/interfaces.md, "Results"), gathered while the run goes.

A train is a Traction component. When an AtoController drives it (its ``command`` output is
connected to the train's ``command`` input), the train's entry also carries the ATP/ATO
verdict: overspeed, interventions, signals passed at danger, every timetable stop reached
(arrival time and deviation, stop error) and every change of the aspect the ATP acted upon.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional

from fmus.signalling import aspects as sig

from fmus.units import J_PER_KWH, KMH_PER_MPS
from orchestrator.graph import TICKS_PER_SECOND, SystemGraph
from orchestrator.protocols import MasterView, StepRecord, SummaryObserver

TRAIN_MODEL = "Traction"
ATO_MODEL = "AtoController"
TRAIN_OUTPUTS = ("energy", "x")
ATO_OUTPUTS = ("stop_index", "arrival_time", "stop_error", "atp_aspect", "max_overspeed", "atp_interventions",
               "emergency_brakings", "signals_passed_at_danger", "departure_hold")


@dataclass
class _Train:
    name: str
    ato: Optional[str]
    timetable: list = field(default_factory=list)
    stops: List[dict] = field(default_factory=list)
    aspects: List[dict] = field(default_factory=list)
    last_stop_index: int = 1
    last_aspect: Optional[int] = None


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
    from fmus.data.loader import DEFAULT_LINE, DEFAULT_TIMETABLE, load_line, load_timetable
    from fmus.errors import FmuInputError

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

    def after_tick(self, master: MasterView, step: StepRecord) -> None:
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
        entry = {"station": None, "scheduled_arrival_s": None, "arrival_s": arrival,
                 "arrival_deviation_s": None, "stop_error_m": float(self._value(train.ato, "stop_error"))}
        if 0 < stop_index <= len(train.timetable):
            stop = train.timetable[stop_index - 1]
            entry.update(station=stop.station, scheduled_arrival_s=stop.arrival_s,
                         arrival_deviation_s=arrival - stop.arrival_s if stop.arrival_s is not None else None)
        train.stops.append(entry)

    def _record_aspect(self, train: _Train, tick: int, aspect: int) -> None:
        from fmus.signalling.aspects import ASPECT_NAMES

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
            if train.ato:
                entry.update(
                    ato=train.ato,
                    max_overspeed_kmh=float(self._value(train.ato, "max_overspeed")) * KMH_PER_MPS,
                    atp_interventions=int(self._value(train.ato, "atp_interventions")),
                    emergency_brakings=int(self._value(train.ato, "emergency_brakings")),
                    signals_passed_at_danger=int(self._value(train.ato, "signals_passed_at_danger")),
                    # standing past a departure time without a permissive cab code (docs/ato.md)
                    departure_hold_s=float(self._value(train.ato, "departure_hold")),
                    stops=train.stops, aspects=train.aspects)
            entries.append(entry)
        return entries


# ---- receivers: decoded codes, errors, wrong-side failures (docs/interfaces.md, "Results") ---
RECEIVER_MODEL = "LocoReceiver"
RECEIVER_OUTPUTS = ("aspect", "code_valid", "free_blocks", "v_target", "v_permitted", "decoded_codes", "errors")
SPEED_TOLERANCE_KMH = 0.5


@dataclass
class _Receiver:
    name: str
    train: str
    rail: str
    coder: str
    slot: int                      # the train's index j on the rail line (1-based)
    system: object                 # DigitalSystem, or None for ALSN
    category: str
    latency_s: float
    episode_start_s: Optional[float] = None
    counted: bool = False
    failures: int = 0
    wrong_side_s: float = 0.0
    last_check_s: Optional[float] = None
    events: List[dict] = field(default_factory=list)


def receivers_of(graph: SystemGraph) -> List[_Receiver]:
    """Receivers fed by a rail line whose train and coder are known; others are not judged."""
    from fmus.signalling import alsn, cab_systems, digital
    from fmus.errors import FmuInputError

    found = []
    for name in graph.order:
        node = graph.nodes[name]
        if node.interface.model_identifier != RECEIVER_MODEL:
            continue
        feed = next((e for e in graph.edges if e.target == name and e.target_var.name.startswith("e_coil[")), None)
        if feed is None:
            continue
        rail = feed.source
        slot = int(feed.source_var.name.split("[")[1].split(",")[0])
        train = next((e.source for e in graph.edges if e.target == rail and e.target_var.name == f"x_head[{slot}]"), None)
        coder = next((e.source for e in graph.edges if e.target == rail and e.target_var.name.startswith("u_tx[")), None)
        if train is None or coder is None:
            continue
        params = node.parameters
        try:
            system = cab_systems.digital_system(str(params.get("system", "ALSN")))
        except FmuInputError:
            continue                  # the receiver itself reports it at initialisation
        category = str(params.get("train_category", "passenger"))
        if system is None:
            latency = alsn.STATED_LATENCY_S
        else:
            carrier = float(params.get("carrier", 0.0) or system.carrier_hz)
            latency = digital.stated_latency_s(system.message_s(carrier))
        found.append(_Receiver(name, train, rail, coder, slot, system, category, latency))
    return found


CHECK_INTERVAL_S = 0.1


class ReceiverVerdict(_OutputJudge):
    """Observer: judges every receiver against the code transmitted into the section under its
    train's coils (the rail line's ``coil_section``, the coder's ``code_tx``). More permissive
    (aspect, free blocks or speed) for longer than the system's stated latency is a wrong-side
    failure, counted once per episode."""

    def __init__(self, graph: SystemGraph):
        self.graph = graph
        self.receivers = receivers_of(graph)

    def outputs_needed(self) -> Dict[str, List[str]]:
        needed: Dict[str, List[str]] = {}
        for r in self.receivers:
            needed.setdefault(r.name, []).extend(RECEIVER_OUTPUTS)
            needed.setdefault(r.rail, []).append(f"coil_section[{r.slot}]")
            codes = [v for v in self.graph.nodes[r.coder].interface.variables if v.startswith("code_tx[")]
            needed.setdefault(r.coder, []).extend(codes)
        return needed

    def started(self, master: MasterView, step: StepRecord) -> None:
        self._bind_slots(master)
        # checked at the first multiple of the receiver's step from CHECK_INTERVAL_S on: an
        # episode is timed to that, against stated latencies of 1.1 s (FIRE) to 4.2 s (ALSN)
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
            buffer, index = self._coil_section[r.name]
            section = int(buffer.values[index])
            if section <= 0:
                r.episode_start_s = None
                continue
            buffer, index = self._code_tx[r.name][section - 1]
            sent = int(buffer.values[index])
            if self._more_permissive(r, sent):
                if r.episode_start_s is None:
                    r.episode_start_s, r.counted = now, False
                elif now - r.episode_start_s > r.latency_s:
                    if not r.counted:
                        r.failures += 1
                        r.counted = True
                        r.events.append({"t": r.episode_start_s, "section": section, "code_sent": sent})
                    r.wrong_side_s += now - max(r.last_check_s or now, r.episode_start_s + r.latency_s)
            else:
                r.episode_start_s = None
            r.last_check_s = now

    def _more_permissive(self, r: _Receiver, sent: int) -> bool:
        aspect = int(self._value(r.name, "aspect"))
        if r.system is None:                       # ALSN: code_tx is in the aspect enumeration
            return sig.restrictiveness(aspect) > sig.restrictiveness(sent if sent else sig.WHITE)
        shown = (sig.restrictiveness(aspect), int(self._value(r.name, "free_blocks")),
                 float(self._value(r.name, "v_target")) * 3.6, float(self._value(r.name, "v_permitted")) * 3.6)
        if not bool(self._value(r.name, "code_valid")):
            return False                           # white / red: the no-code rules, never permissive
        meant = transmitted_indication(r.system, sent, r.category)
        if meant is None:                          # nothing sent: any valid code is more than that
            return True
        return (shown[0] > sig.restrictiveness(meant.aspect) or shown[1] > meant.free_blocks
                or shown[2] > meant.target_kmh + SPEED_TOLERANCE_KMH
                or shown[3] > meant.permitted_kmh + SPEED_TOLERANCE_KMH)

    def summary_section(self) -> Dict[str, list]:
        return {"receivers": self.summary()}

    def summary(self) -> List[dict]:
        entries = []
        for r in self.receivers:
            entry = {"receiver": r.name, "train": r.train, "system": "ALSN" if r.system is None else r.system.name,
                     "latency_s": r.latency_s, "wrong_side_failures": r.failures,
                     "wrong_side_s": round(r.wrong_side_s, 3), "wrong_side_events": r.events}
            if self._slots is not None:
                entry.update(decoded_codes=int(self._value(r.name, "decoded_codes")),
                             code_errors=int(self._value(r.name, "errors")))
            entries.append(entry)
        return entries


def transmitted_indication(system, code: int, category: str):
    """What a coder's raw ``code_tx`` means; None for no code (the system's reading)."""
    command = system.command_of_code(code)
    return None if command is None else system.indication(command, category)


def railway_verdicts(graph: SystemGraph) -> list:
    """The summary observers of a railway run: per train (arrivals, stops, energy, ATP) and
    per receiver (codes, errors, wrong-side failures). Pass as ``RunOptions.summaries``."""
    return [TrainVerdict(graph), ReceiverVerdict(graph)]
