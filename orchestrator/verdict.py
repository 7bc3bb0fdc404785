"""The per-train part of summary.json (DESIGN §8), gathered while the run goes.

A train is a Traction component. When an AtoController drives it (its ``command`` output is
connected to the train's ``command`` input), the train's entry also carries the ATP/ATO
verdict: overspeed, interventions, signals passed at danger, every timetable stop reached
(arrival time and deviation, stop error) and every change of the aspect the ATP acted upon.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Optional

from .graph import TICKS_PER_SECOND, SystemGraph

TRAIN_MODEL = "Traction"
ATO_MODEL = "AtoController"
J_PER_KWH = 3.6e6
TRAIN_OUTPUTS = ("energy", "x")
ATO_OUTPUTS = ("stop_index", "arrival_time", "stop_error", "atp_aspect", "max_overspeed", "atp_interventions",
               "emergency_brakings", "signals_passed_at_danger")


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
    from fmus.common.data import DEFAULT_LINE, DEFAULT_TIMETABLE, load_line, load_timetable
    from fmus.common.slave import FmuInputError

    params = graph.nodes[ato].parameters
    try:
        line = load_line(params.get("line_file") or DEFAULT_LINE)
        return load_timetable(params.get("timetable_file") or DEFAULT_TIMETABLE, line)
    except FmuInputError:
        return []     # the FMU itself reports the bad file at initialisation


class TrainVerdict:
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

    def started(self, master, tick: int) -> None:
        self._slots = {}
        for train in self.trains:
            for var in TRAIN_OUTPUTS:
                self._slots[(train.name, var)] = master.output_slot(train.name, var)
            if train.ato:
                for var in ATO_OUTPUTS:
                    self._slots[(train.ato, var)] = master.output_slot(train.ato, var)
        self.after_tick(master, tick, ())

    def _value(self, component: str, var: str):
        buffer, index = self._slots[(component, var)]
        return buffer.values[index]

    def after_tick(self, master, tick: int, due) -> None:
        for train in self.trains:
            if not train.ato:
                continue
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
        from fmus.common.signalling import ASPECT_NAMES

        train.aspects.append({"t": tick / TICKS_PER_SECOND, "x": float(self._value(train.name, "x")),
                              "aspect": ASPECT_NAMES.get(aspect, str(aspect))})

    def summary(self) -> List[dict]:
        if not hasattr(self, "_slots"):      # the run failed before it started
            return [{"name": train.name} for train in self.trains]
        entries = []
        for train in self.trains:
            entry = {"name": train.name, "energy_kwh": float(self._value(train.name, "energy")) / J_PER_KWH}
            if train.ato:
                entry.update(
                    ato=train.ato,
                    max_overspeed_kmh=float(self._value(train.ato, "max_overspeed")) * 3.6,
                    atp_interventions=int(self._value(train.ato, "atp_interventions")),
                    emergency_brakings=int(self._value(train.ato, "emergency_brakings")),
                    signals_passed_at_danger=int(self._value(train.ato, "signals_passed_at_danger")),
                    stops=train.stops, aspects=train.aspects)
            entries.append(entry)
        return entries
