"""Timed events on any input or output of any component, applied by the master (a
manipulator, in libcosim's sense), read from a scenario file in the manner of the OSP
scenario format (docs/scenarios.md):

    { "description": "main transmitter fails, then the reserve",
      "events": [
        { "time": 60.0, "model": "coder", "variable": "fault_main", "action": "set", "value": true },
        { "time": 90.0, "model": "rail", "variable": "ballast_override[3]", "action": "set", "value": 0.3 },
        { "time": 95.0, "model": "train", "variable": "v", "action": "bias", "value": 1.5 },
        { "time": 120.0, "model": "coder", "variable": "fault_main", "action": "reset" } ] }

* ``set`` (OSP: ``override``, accepted too) — the variable takes ``value`` from ``time`` on,
  whatever its link delivers; on an output, every consumer (and the recorder) sees ``value``;
* ``bias`` — ``value`` is added to what the link (or, unconnected, the start value) delivers;
* ``reset`` — back to the link's value (or the start value);
* ``restrict`` — a temporary speed restriction for an ATO controller: ``start_m``, ``end_m``,
  ``speed_kmh`` and optionally ``until`` (s, when it is lifted); it takes the lowest of the
  component's ``tsr_*`` input slots free at its time (a slot is free again once its
  restriction is lifted).

Parameters are fixed once a run starts (our FMUs' parameters have variability fixed): set them
with ``--set`` or a parameter set instead; an event on one is an error naming it. Events are
applied before the tick at which they fall (time rounded to the base step), so a component due
at that tick already steps with the new value.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Tuple

from orchestrator.errors import UserError, non_finite_number
from orchestrator.graph import MAX_TIME_S, TICKS_PER_SECOND, SystemGraph
from orchestrator.protocols import Manipulator, MasterView

ACTIONS = {"set": "set", "override": "set", "bias": "bias", "reset": "reset"}
# a temporary speed restriction for an ATO controller (expanded into set/reset events on its
# tsr_start/tsr_end/tsr_speed input slots: docs/scenarios.md, docs/ato.md)
RESTRICT = "restrict"
TSR_PORTS = ("tsr_start", "tsr_end", "tsr_speed")
INT32 = (-2 ** 31, 2 ** 31 - 1)      # an FMI 2.0 Integer is a C int (fmi2Integer)


@dataclass(frozen=True)
class Event:
    time_s: float
    component: str
    variable: str
    action: str          # set | bias | reset
    value: object = None
    where: str = field(default="", compare=False)         # the file and field it came from
    restriction: bool = field(default=False, compare=False)   # one of a restrict event's slot events


@dataclass(frozen=True)
class _Restriction:
    time_s: float
    until_s: float            # inf: never lifted
    model: str
    start_m: float
    end_m: float
    speed_mps: float
    where: str


@dataclass
class Scenario:
    path: Path
    description: str
    events: List[Event]
    end_s: Optional[float] = None


def load_scenario(path) -> Scenario:
    path = Path(path)
    if not path.is_file():
        raise UserError(f"{path}: scenario file not found")
    doc = read_json(path)
    bad = non_finite_number(doc)
    if bad is not None:
        raise UserError(f"{path}: field {bad[0]}: {bad[1]} is not a finite number")
    if not isinstance(doc, dict) or not isinstance(doc.get("events"), list):
        raise UserError(f"{path}: field events: a list of events is required")
    defaults = doc.get("defaultOpts", {}) if isinstance(doc.get("defaultOpts", {}), dict) else {}
    events = []
    restrictions: List[_Restriction] = []
    for index, item in enumerate(doc["events"]):
        where = f"{path}: field events[{index}]"
        if not isinstance(item, dict):
            raise UserError(f"{where}: an object is required")
        merged = {"model": defaults.get("model"), "variable": defaults.get("variable"), **item}
        time_s = merged.get("time")
        if not _is_number(time_s) or not 0 <= time_s <= MAX_TIME_S:
            raise UserError(f"{where}.time: a finite time ≥ 0 in seconds is required, got {time_s!r}")
        restrict = str(merged.get("action", "")).lower() == RESTRICT
        for key in ("model",) if restrict else ("model", "variable"):
            if not isinstance(merged.get(key), str) or not merged[key]:
                raise UserError(f"{where}.{key}: a name is required")
        if restrict:
            restrictions.append(_restriction(merged, float(time_s), where))
            continue
        action = ACTIONS.get(str(merged.get("action", "")).lower())
        if action is None:
            raise UserError(f"{where}.action: {merged.get('action')!r} is not one of set, override, bias, reset, "
                            f"{RESTRICT}")
        if action != "reset" and "value" not in merged:
            raise UserError(f"{where}.value: required for {action}")
        events.append(Event(float(time_s), merged["model"], merged["variable"], action, merged.get("value"), where))
    end = doc.get("end")
    if end is not None and (not _is_number(end) or not 0 < end <= MAX_TIME_S):
        raise UserError(f"{path}: field end: a finite positive time in seconds is required, got {end!r}")
    events.extend(_restriction_events(restrictions))
    events.sort(key=lambda e: e.time_s)          # stable: same-time events keep their file order
    return Scenario(path, str(doc.get("description", "")), events, None if end is None else float(end))


def _restriction(item: dict, time_s: float, where: str) -> _Restriction:
    """A ``restrict`` event's fields, checked."""
    values = {}
    for key in ("start_m", "end_m", "speed_kmh"):
        value = item.get(key)
        if not _is_number(value) or value < 0:
            raise UserError(f"{where}.{key}: a finite number ≥ 0 is required, got {value!r}")
        values[key] = float(value)
    if values["end_m"] <= values["start_m"]:
        raise UserError(f"{where}.end_m: {values['end_m']:g} is not after start_m {values['start_m']:g}")
    if values["speed_kmh"] <= 0:
        raise UserError(f"{where}.speed_kmh: must be positive, got {values['speed_kmh']:g}")
    until = item.get("until")
    if until is not None and (not _is_number(until) or not time_s < until <= MAX_TIME_S):
        raise UserError(f"{where}.until: a time after the event's time ({time_s:g} s) is required, got {until!r}")
    return _Restriction(time_s, math.inf if until is None else float(until), item["model"], values["start_m"],
                        values["end_m"], values["speed_kmh"] / 3.6, where)


def _restriction_events(restrictions: List[_Restriction]) -> List[Event]:
    """Each restriction as ``set`` events on the lowest ``tsr_*`` slot of its component that is
    free at its time, and ``reset`` events lifting it at ``until``. Whether the component has
    that many slots is checked against its interface (ScenarioManipulator)."""
    events = []
    lifted_at: Dict[str, List[float]] = {}      # per component, per slot: when it is free again
    for r in sorted(restrictions, key=lambda r: r.time_s):
        slots = lifted_at.setdefault(r.model, [])
        slot = next((k for k, free_s in enumerate(slots) if free_s <= r.time_s), len(slots))
        if slot == len(slots):
            slots.append(r.until_s)
        else:
            slots[slot] = r.until_s
        for name, value in zip(TSR_PORTS, (r.start_m, r.end_m, r.speed_mps)):
            variable = f"{name}[{slot + 1}]"
            events.append(Event(r.time_s, r.model, variable, "set", value, r.where, restriction=True))
            if r.until_s < math.inf:
                events.append(Event(r.until_s, r.model, variable, "reset", None, r.where, restriction=True))
    # a slot lifted and taken again at one time: the reset first
    events.sort(key=lambda e: (e.time_s, e.action != "reset"))
    return events


def read_json(path: Path):
    """A JSON document the orchestrator reads; anything that is not plain JSON (bad syntax, not
    UTF-8, nested too deeply for the parser) is an error naming the file."""
    try:
        return json.loads(Path(path).read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise UserError(f"{path}: not valid JSON ({error})") from None
    except RecursionError:
        raise UserError(f"{path}: not valid JSON (nested too deeply)") from None
    except OSError as error:
        raise UserError(f"{path}: cannot be read ({error.strerror})") from None


def _is_number(value) -> bool:
    """A finite JSON number (Python's json reads NaN, Infinity and -Infinity too)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


class ScenarioManipulator(Manipulator):
    """Applies a scenario's events; the master calls :meth:`before_tick`, and after each gather
    (inputs) or read (outputs) of a component with events, :meth:`adjust_inputs` /
    :meth:`adjust_outputs`."""

    def __init__(self, scenario: Scenario, graph: SystemGraph):
        self.scenario = scenario
        self.graph = graph
        self.pending = list(scenario.events)
        self.active: Dict[Tuple[str, str], Tuple[str, object]] = {}
        self.applied: List[dict] = []
        connected = {(e.target, e.target_var.name) for e in graph.edges}
        self.kinds: Dict[Tuple[str, str], str] = {}
        for event in scenario.events:
            where = event.where
            node = graph.nodes.get(event.component)
            if node is None:
                raise UserError(f"{where}.model: no component {event.component!r} in {graph.name} "
                                f"({', '.join(graph.nodes)})")
            var = node.interface.variables.get(event.variable)
            if var is None and event.restriction:
                slots = sum(name.startswith(f"{TSR_PORTS[0]}[") for name in node.interface.variables)
                if slots == 0:
                    raise UserError(f"{where}.model: {event.component} takes no restrictions (it has no "
                                    f"tsr_* input slots)")
                raise UserError(f"{where}: more restrictions in force at once on {event.component} than its "
                                f"{slots} tsr_* input slots (lift one earlier with until)")
            if var is None:
                raise UserError(f"{where}.variable: {event.component} has no variable {event.variable!r}")
            if var.causality not in ("input", "output"):
                raise UserError(f"{where}.variable: {event.component}.{event.variable} is a {var.causality}; "
                                f"set it with --set or a parameter set")
            if var.type == "String" or (event.action == "bias" and var.type == "Boolean"):
                raise UserError(f"{where}.action: {event.action} is not possible on a {var.type} variable")
            if event.action != "reset":
                _typed(var.type, event.value, f"{where}.value")
            key = (event.component, event.variable)
            self.kinds[key] = "output" if var.causality == "output" else \
                ("linked" if key in connected else "free")
        self.slots: Dict[Tuple[str, str], tuple] = {}

    # ---- what the master must bind ----------------------------------------------------------
    def inputs_needed(self) -> Dict[str, List[str]]:
        """Unconnected inputs the events drive: the master binds them into the input buffers."""
        return self._variables_of_kind("free")

    def outputs_needed(self) -> Dict[str, List[str]]:
        return self._variables_of_kind("output")

    def _variables_of_kind(self, wanted: str) -> Dict[str, List[str]]:
        needed: Dict[str, List[str]] = {}
        for (component, variable), kind in self.kinds.items():
            if kind == wanted:
                needed.setdefault(component, []).append(variable)
        return needed

    def adjusted_components(self) -> Tuple[set, set]:
        """(components whose inputs are adjusted, components whose outputs are adjusted)."""
        inputs = {c for (c, _), k in self.kinds.items() if k != "output"}
        outputs = {c for (c, _), k in self.kinds.items() if k == "output"}
        return inputs, outputs

    def bound(self, master: MasterView) -> None:
        """Resolve buffer slots once the slaves are bound; free inputs start at their start value."""
        for (component, variable), kind in self.kinds.items():
            var = self.graph.nodes[component].interface.variables[variable]
            slave = master.slaves[component]
            buffer = (slave.outputs if kind == "output" else slave.inputs)[var.type]
            index = int((buffer.vr_array == var.vr).nonzero()[0][0])
            start = _typed(var.type, var.start if var.start is not None else 0, "start")
            self.slots[(component, variable)] = (buffer, index, var.type, start)
            if kind == "free":
                buffer.values[index] = start

    # ---- hooks --------------------------------------------------------------------------------
    def before_tick(self, master: MasterView, tick: int) -> None:
        while self.pending and round(self.pending[0].time_s * TICKS_PER_SECOND) <= tick + master.graph.base_ticks // 2:
            event = self.pending.pop(0)
            key = (event.component, event.variable)
            buffer, index, type_name, start = self.slots[key]
            if event.action == "reset":
                self.active.pop(key, None)
            else:
                self.active[key] = (event.action, _typed(type_name, event.value, "value"))
            if self.kinds[key] == "free":
                buffer.values[index] = self._value(key, start)
            self.applied.append({"t": tick / TICKS_PER_SECOND, "model": event.component,
                                 "variable": event.variable, "action": event.action, "value": event.value})

    def adjust_inputs(self, component: str) -> None:
        """After the master gathered ``component``'s linked inputs."""
        self._adjust(component, "linked")

    def adjust_outputs(self, component: str) -> None:
        """After the master read ``component``'s outputs."""
        self._adjust(component, "output")

    def _adjust(self, component: str, kind: str) -> None:
        for key, (action, value) in self.active.items():
            if key[0] != component or self.kinds[key] != kind:
                continue
            buffer, index, _, _ = self.slots[key]
            buffer.values[index] = value if action == "set" else buffer.values[index] + value

    def _value(self, key, base):
        action, value = self.active.get(key, ("reset", None))
        if action == "set":
            return value
        if action == "bias":
            return base + value
        return base


def _typed(type_name: str, value, where: str):
    try:
        if type_name == "Real":
            if isinstance(value, bool) or not math.isfinite(float(value)):
                raise ValueError
            return float(value)
        if type_name == "Integer":
            if isinstance(value, bool) or not math.isfinite(float(value)) or int(value) != float(value):
                raise ValueError
            if not INT32[0] <= int(value) <= INT32[1]:
                raise UserError(f"{where}: {value!r} is outside the FMI Integer range "
                                f"{INT32[0]}..{INT32[1]}")
            return int(value)
        if type_name == "Boolean":
            if isinstance(value, bool) or value in (0, 1):
                return bool(value)
            if isinstance(value, str) and value.lower() in ("true", "false"):
                return value.lower() == "true"
            raise ValueError
    except (TypeError, ValueError, OverflowError):
        raise UserError(f"{where}: {value!r} is not a {type_name} value") from None
    return value
