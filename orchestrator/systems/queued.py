"""Systems of N identical trains following at an interval, made from a single-train system: the
headway trials (orchestrator/headway/) and the shipped systems of many trains
(orchestrator/systems/shipped.py; docs/capacity.md#co-simulated-headway).

What a trial holds, built from the base system's own line, rolling stock, timetable and cab
signalling (its SSD's parameters, read by :func:`read_base`):

* **the trains waiting** where the cab system lets a train start from its own track circuit
  (every system but TVM-430): the leader stands where the base train stands; the others wait
  on **holding tracks** laid before the line's first track circuit, one short coded track
  circuit each (its own signal at its exit, ``pitch = train length + QUEUE_GAP_M`` long, the
  base line's first circuit copied), nearest the line the second train. Each follower draws up
  to the origin at ``HOLDING_KMH`` in time to call there ``ORIGIN_DWELL_S`` before its
  departure, train j's (j − 1)·h after the leader's, and every later time of its timetable is
  the base timetable's shifted the same. No two trains ever share a track circuit: a train
  standing behind another in one circuit may pick up the code meant for the one ahead once
  that one's last wheelsets near the feed end (docs/scenarios.md#systems-of-many-trains), which
  a real line forbids and the verdicts rightly call unsafe. The trial's line is the base line
  shifted by the holding tracks' length (``offset_m``); everything judged and reported is in
  the base line's positions (trajectories are read back shifted);
* **the trains queued** on TVM-430 lines, where a train without a word may not move (step 0),
  so no holding track can be left: the last train stands where the base train stands, each
  train ahead of it ``QUEUE_GAP_M`` clear of the next, at a stopping point added to the line
  ("queue 1" is the leader's); train j departs (j − 1)·h after the leader;
* **a run-off** where the cab system allows it: at its last stop each train dwells
  ``FINAL_DWELL_S`` and runs on to sidings beyond the last track circuit (track without track
  circuits, ``SIDINGS_KMH``: the no-code ceiling), each to its own place, so that no train stands
  in a coded section at the end (the following systems' sidings, docs/scenarios.md). TVM-430
  has no such track: a train without a word is at step 0 and may not move, so on a TVM line
  the trains stay at their last stop and are judged only up to the approach of its block
  (``judge_end_m``, set from the blocking times: docs/capacity.md#the-end-of-the-line);
* the signal chain of the base system (coder, rail line, one receiver per train) built for N
  trains (a sized build, docs/architecture.md#build-sizes).

How the trials are judged: orchestrator/headway/trials.py.
"""
from __future__ import annotations

import json
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np

from fmus.data.loader import DATA, DEFAULT_LINE, DEFAULT_ROLLING_STOCK, DEFAULT_TIMETABLE, load_line, load_rolling_stock
from fmus.signalling import cab_systems
from fmus.sizes import BuildConfig, DEFAULT_SAMPLE_RATE_HZ, sizes_of_source
from orchestrator.systems.chain import (ATO_FMU, CODER_FMU, RAIL_FMU, RECEIVER_FMU, TRAIN_FMU, signal_chain,
                                        train_and_ato, write_ssd)
from orchestrator.verdicts.verdict import ATO_MODEL, TRAIN_MODEL
from orchestrator.errors import UserError

#: clear space between the tail of one queued train and the head of the next (m) [U]
QUEUE_GAP_M = 50.0
#: the holding tracks' speed limit, and the speed a follower is timed to draw up at (km/h) [U]
HOLDING_KMH = 40.0
#: a follower calls at the origin this long before its departure (s) [U]
ORIGIN_DWELL_S = 30.0
#: a follower's draw-up is timed this much slower than the ATO's fastest (s) [U]
DRAW_UP_MARGIN_S = 30.0
#: dwell at the last stop before running on to the sidings (s) [U]
FINAL_DWELL_S = 30.0
#: the sidings' speed limit: the cab's no-code ceiling (ALSN white, 40 km/h) [U]
SIDINGS_KMH = 40.0
#: a trial runs on this long after the last train, alone, would reach the end of judging (s)
JUDGED_MARGIN_S = 30.0
#: between the last track circuit and the last train's tail in the sidings (m)
SIDINGS_CLEARANCE_M = 20.0
#: trains a trial may hold (the build sizes of the rail line, docs/architecture.md#build-sizes)
MAX_TRAINS = 16
#: the unit of each railcosim FMU, by its file name
UNIT_OF_FMU = {CODER_FMU: "coder", RAIL_FMU: "rail", RECEIVER_FMU: "receiver", TRAIN_FMU: "train", ATO_FMU: "ato"}
#: per-train parameters of the rail line (set for each train of a trial)
_PER_TRAIN = ("train_length[", "rolling_stock_file[")


@dataclass
class BaseSystem:
    """A single-train system's parts, as its SSD binds them (file parameters resolved)."""

    name: str
    folder: Path
    cab_system: str                     # the coder's `system` (ALSN unless set)
    block_aspects: int
    line_file: Path
    stock_file: Path
    timetable_file: Path
    x0_m: float
    sections: int
    frame: int
    fs_hz: float
    steps_s: Dict[str, float]           # unit → step size
    parameters: Dict[str, Dict[str, object]] = field(default_factory=dict)   # unit → name → value
    fmu_folder: str = "resources"

    @property
    def line(self):
        return load_line(self.line_file)

    @property
    def stock(self):
        return load_rolling_stock(self.stock_file)


def resolved_file(value, folder: Path, default: Path) -> Path:
    from orchestrator.graph import resolve_data_file

    if not value:
        return Path(default)
    found = Path(resolve_data_file(value, folder))
    if found.is_file():
        return found.resolve()
    if (DATA / str(value)).is_file():
        return (DATA / str(value)).resolve()
    raise UserError(f"{folder}: {value}: file not found (looked for in its resources/ and the bundled data)")


def parameter_values(component) -> Dict[str, object]:
    """A component's bound parameters by the FMU's own names (a binding may name them
    ``component.var``; an array element's ``var[j]`` keeps its index)."""
    return {p.name.split(".")[-1] if "." in p.name and "[" not in p.name.split(".")[0] else p.name: p.value
            for p in component.parameters}


def read_base(system_path: Path) -> BaseSystem:
    """The parts of a single-train system with a signal chain; a UserError naming what is
    missing otherwise (no chain: no line to block; several trains: no single train to copy)."""
    from orchestrator.ssp import open_system

    system_path = Path(system_path)
    description = open_system(system_path)
    folder = description.folder
    units: Dict[str, list] = {}
    for component in description.components.values():
        unit = UNIT_OF_FMU.get(Path(component.source).name)
        if unit:
            units.setdefault(unit, []).append(component)
    name = description.name
    for unit in ("train", "ato"):
        if len(units.get(unit, [])) != 1:
            count = len(units.get(unit, []))
            raise UserError(f"system {name!r}: headway needs a system of one train to copy; it has {count} "
                            f"{TRAIN_MODEL if unit == 'train' else ATO_MODEL} components"
                            + (" (a system of several trains: give its single-train counterpart)" if count > 1 else ""))
    for unit in ("coder", "rail", "receiver"):
        if not units.get(unit):
            raise UserError(f"system {name!r}: no signal chain (no {unit}); headway needs a line with block "
                            "sections and a cab system (e.g. free_run, alsu, als_en, fire_dqpsk, tvm430)")
    parameters = {unit: parameter_values(components[0]) for unit, components in units.items()}
    rail = units["rail"][0]
    sizes = sizes_of_source(rail.source) or BuildConfig()
    ato, train = parameters["ato"], parameters["train"]
    line_file = resolved_file(ato.get("line_file") or parameters["rail"].get("line_file"), folder, DEFAULT_LINE)
    stock_file = resolved_file(ato.get("rolling_stock_file") or train.get("rolling_stock_file"), folder, DEFAULT_ROLLING_STOCK)
    timetable_file = resolved_file(ato.get("timetable_file"), folder, DEFAULT_TIMETABLE)
    coder = parameters["coder"]
    return BaseSystem(
        name=name, folder=folder, cab_system=str(coder.get("system") or cab_systems.DEFAULT.name),
        block_aspects=int(coder.get("block_aspects") or 3), line_file=line_file, stock_file=stock_file,
        timetable_file=timetable_file, x0_m=float(train.get("x0", 400.0)),
        sections=sizes.sections, frame=sizes.frame, fs_hz=float(coder.get("fs") or DEFAULT_SAMPLE_RATE_HZ),
        steps_s={unit: float(components[0].step_size_s) for unit, components in units.items()},
        parameters=parameters, fmu_folder=str(Path(rail.source).parent.parent if sizes_of_source(rail.source)
                                              else Path(rail.source).parent))


@dataclass(frozen=True)
class TrainSlot:
    """One train of a trial: its name, where it stands, its timetable (before any shift)."""

    index: int                  # 1: the leader
    name: str                   # the Traction component ("train1" …)
    start_m: float
    start_station: str
    sidings_station: str
    sidings_m: float


class TrialPlan:
    """The line, the trains' places and the timetables of N trains of a base system (module
    docstring). Positions: ``slots``, ``line_doc`` and the timetables are the trial's line
    (the base line shifted by ``offset_m``); ``judge_end_m``, ``last_stop_m`` and
    :meth:`timing_points_m` are the base line's."""

    def __init__(self, base: BaseSystem, trains: int):
        if not 2 <= trains <= MAX_TRAINS:
            raise UserError(f"--trains {trains}: a headway trial needs 2 to {MAX_TRAINS} trains (a leader and "
                            "at least one follower)")
        self.base, self.count = base, trains
        self.length_m = float(base.stock.length_m)
        line_doc = json.loads(Path(base.line_file).read_text())
        timetable = json.loads(Path(base.timetable_file).read_text())
        self.base_timetable = timetable
        stops = timetable["stops"]
        self.origin = stops[0]["station"]
        stations = {s["name"]: float(s["stop_m"]) for s in line_doc["stations"]}
        self.pitch_m = pitch = self.length_m + QUEUE_GAP_M
        #: sidings beyond the line for the trains to clear it, holding tracks before it (module docstring)
        self.run_off = cab_systems.lookup(base.cab_system).transmitter != cab_systems.UM71
        self.offset_m = (trains - 1) * pitch if self.holding else 0.0
        line_end = float(line_doc["length_m"]) + self.offset_m
        last_circuit_m = max(float(s["end_m"]) for s in line_doc["block_sections"]) + self.offset_m
        self.slots: List[TrainSlot] = []
        for j in range(1, trains + 1):
            if self.holding:
                # the leader at the origin; train j ≥ 2 in holding circuit j, its head half the
                # gap short of that circuit's signal
                start = base.x0_m + self.offset_m if j == 1 else self.offset_m - (j - 2) * pitch - QUEUE_GAP_M / 2
                station = self.origin if j == 1 else f"holding {j}"
            else:
                start = base.x0_m + (trains - j) * pitch
                station = self.origin if j == trains else f"queue {j}"
            sidings = max(line_end, last_circuit_m) + SIDINGS_CLEARANCE_M + self.length_m + (trains - j) * pitch
            self.slots.append(TrainSlot(j, f"train{j}", start, station, f"sidings {j}", sidings))
        # the queue must stand before the train's first stop after the origin
        if not self.holding and len(stops) > 1 \
                and self.slots[0].start_m >= stations[stops[1]["station"]] - 1.0:
            raise UserError(f"--trains {trains}: the queue of {trains} trains ({pitch:g} m each) reaches "
                            f"{self.slots[0].start_m:g} m, past {stops[1]['station']!r} "
                            f"({stations[stops[1]['station']]:g} m); fewer trains")
        self.last_stop_m = stations[stops[-1]["station"]]
        self.line_doc = self._line(line_doc)
        self._trial_line = None            # loaded when first needed (:meth:`_fastest_s`)
        #: every timetable's times later by this (s), so that no train's draw-up starts before 0
        self.lead_s = max([0.0] + [self._draw_up_s(slot) - float(stops[0]["departure_s"])
                                   for slot in self.slots[1:] if self.holding])
        self.sections = len(self.line_doc["block_sections"])
        #: where judging ends: the last stop with a run-off, else set by the caller (the approach
        #: point of the last stop's block: a train standing there holds its followers)
        self.judge_end_m = self.last_stop_m

    @property
    def holding(self) -> bool:
        """Followers wait on holding tracks: where a train may move without a code, as for the
        sidings (``run_off``: every cab system but TVM-430)."""
        return self.run_off

    @property
    def origin_slot(self) -> TrainSlot:
        """The train standing where the base train stands (its run is the base train's)."""
        return self.slots[0] if self.holding else self.slots[-1]

    def _draw_up_s(self, slot: TrainSlot) -> float:
        """From a follower's holding place to its departure from the origin (s): the ATO's
        fastest run there, a margin and the dwell."""
        return self._fastest_s(slot.start_m, self.base.x0_m + self.offset_m) + DRAW_UP_MARGIN_S + ORIGIN_DWELL_S

    def _line(self, doc: dict) -> dict:
        line = json.loads(json.dumps(doc))
        if self.holding:
            line = self._with_holding_tracks(line)
            line["name"] = f"{doc['name']} (headway trial: {self.count} trains, holding tracks"
        else:
            line["name"] = f"{doc['name']} (headway trial: {self.count} trains queued"
        line["name"] += ", sidings)" if self.run_off else ")"
        extra = [{"name": s.start_station, "stop_m": s.start_m, "platform_length_m": self.length_m}
                 for s in self.slots if s.start_station != self.origin]
        if not self.run_off:
            line["stations"] = sorted(line["stations"] + extra, key=lambda s: s["stop_m"])
            return line
        extra += [{"name": s.sidings_station, "stop_m": s.sidings_m, "platform_length_m": self.length_m}
                  for s in self.slots]
        line["stations"] = sorted(line["stations"] + extra, key=lambda s: s["stop_m"])
        line["length_m"] = max(s.sidings_m for s in self.slots) + 100.0
        kmh = SIDINGS_KMH
        limit = {key: kmh for key in ("passenger_kmh", "freight_kmh")}
        if any("high_speed_kmh" in item for item in line["speed_limits"]):
            limit["high_speed_kmh"] = kmh
        # the sidings' limit from the last stop on, so a train leaving it enters them within it
        last_stop_m = self.last_stop_m + self.offset_m
        line["speed_limits"] = [item for item in line["speed_limits"] if item["start_m"] < last_stop_m] \
            + [{"start_m": last_stop_m, **limit}]
        return line

    def _with_holding_tracks(self, line: dict) -> dict:
        """The base line shifted by ``offset_m``, the holding circuits laid before it (straight,
        on the line's first grade, ``HOLDING_KMH``), each a copy of the base line's first circuit."""
        offset = self.offset_m
        for key, fields in _POSITIONS.items():
            for item in line.get(key, []):
                for name in fields:
                    if name in item:
                        item[name] = item[name] + offset
        line["length_m"] = float(line["length_m"]) + offset
        first = min(line["block_sections"], key=lambda s: s["start_m"])
        holding = [{**first, "name": f"H{j}", "signal": f"H{j}",
                    "start_m": offset - (j - 1) * self.pitch_m, "end_m": offset - (j - 2) * self.pitch_m}
                   for j in range(self.count, 1, -1)]
        line["block_sections"] = holding + line["block_sections"]
        joints = line.get("insulated_joints", [])
        if joints:
            model = {k: v for k, v in min(joints, key=lambda j: j["position_m"]).items() if k != "position_m"}
            line["insulated_joints"] = [{"position_m": s["start_m"], **model} for s in holding] + joints
        limit = {key: HOLDING_KMH for key in ("passenger_kmh", "freight_kmh")}
        if any("high_speed_kmh" in item for item in line["speed_limits"]):
            limit["high_speed_kmh"] = HOLDING_KMH
        line["speed_limits"] = [{"start_m": 0, **limit}] + line["speed_limits"]
        # the holding tracks lie on the grade the line starts with (one entry: no repeated grade)
        min(line["gradients"], key=lambda g: g["start_m"])["start_m"] = 0
        return line

    def timetable(self, slot: TrainSlot, shift_s: float) -> dict:
        """Train ``slot``'s timetable with every time shifted by ``shift_s`` (and ``lead_s``)."""
        stops = [dict(s) for s in self.base_timetable["stops"]]
        if not self.holding:
            stops[0]["station"] = slot.start_station
        elif slot is not self.origin_slot:
            departure = float(stops[0]["departure_s"])
            stops[0] = {"station": self.origin, "arrival_s": departure - ORIGIN_DWELL_S, "departure_s": departure}
            stops.insert(0, {"station": slot.start_station, "departure_s": departure - self._draw_up_s(slot)})
        last = stops[-1]
        if not self.run_off:
            return self._shifted(stops, slot, shift_s)
        last.setdefault("departure_s", float(last["arrival_s"]) + FINAL_DWELL_S)
        # timed at the ATO's own minimum running time, so that every train clears the last block
        # as fast as the sidings allow (with slack the ATO would creep out, and the last block's
        # blocking time would be its choice of speed, not the line's)
        stops.append({"station": slot.sidings_station,
                      "arrival_s": float(last["departure_s"])
                      + self._fastest_s(self.last_stop_m + self.offset_m, slot.sidings_m)})
        return self._shifted(stops, slot, shift_s)

    def _fastest_s(self, from_m: float, to_m: float) -> float:
        """The ATO's minimum running time between two stops of the trial line (s), rounded up
        to 0.1 s: its own planner, with the base ATO's braking and speed margin."""
        from fmus.ato_controller.core import AtoSettings, default_plan_decel_mps2
        from fmus.ato_controller.planner import InfeasibleStage, StagePlanner
        from fmus.ato_controller.train_model import NominalTrain

        if self._trial_line is None:
            with tempfile.TemporaryDirectory() as scratch:
                path = Path(scratch) / "trial_line.json"
                path.write_text(json.dumps(self.line_doc))
                self._trial_line = load_line(path)
        ato, stock = self.base.parameters["ato"], self.base.stock
        defaults = AtoSettings()
        decel = float(ato.get("braking_decel") or 0.0) or default_plan_decel_mps2(stock, str(ato.get("cab_signal", cab_systems.AtoMode.ALSN)))
        margin = float(ato.get("speed_margin", defaults.speed_margin_mps))
        category = str(ato.get("train_category") or stock.category)
        planner = StagePlanner(NominalTrain(stock, self._trial_line), self._trial_line, category, decel, margin)
        try:
            planner.plan(from_m, to_m, 0.0)
        except InfeasibleStage as fastest:
            return math.ceil(fastest.minimum_time_s * 10.0) / 10.0
        raise AssertionError("a zero running time cannot be feasible")

    def _shifted(self, stops: List[dict], slot: TrainSlot, shift_s: float) -> dict:
        for stop in stops:
            for key in ("arrival_s", "departure_s"):
                if key in stop:
                    stop[key] = round(float(stop[key]) + shift_s + self.lead_s, 3)
        return {"train": f"{self.base_timetable.get('train', 'train')} ({slot.name})", "stops": stops}

    def stop_time_s(self, headway_s: float, judge_end_s: Optional[float] = None) -> float:
        """Long enough for the last train to pass the end of judging (``judge_end_s``: when it,
        alone, reaches it), or else to reach its sidings (or its last stop, without a run-off)."""
        shift = (self.count - 1) * headway_s
        if judge_end_s is None:
            last = self.timetable(self.slots[-1], shift)["stops"][-1]["arrival_s"]
            return math.ceil(last + 120.0)
        return math.ceil(judge_end_s + shift + JUDGED_MARGIN_S)

    def timing_points_m(self) -> np.ndarray:
        """Block signals and stops of the base line from the queue on, up to the last stop."""
        line = self.base.line
        signals = [start for start, _ in line.block_bounds] + [line.block_bounds[-1][1]]
        stops = [s.stop_m for s in line.stations]
        points = np.unique(np.array(signals + stops, dtype=float))
        return points[points <= self.judge_end_m]


#: the position fields of a line file (docs/interfaces.md#line-file), shifted with the line
_POSITIONS = {"block_sections": ("start_m", "end_m"), "insulated_joints": ("position_m",),
              "separation_zones": ("position_m",), "stations": ("stop_m",), "gradients": ("start_m",),
              "curves": ("start_m", "end_m"), "temporary_restrictions": ("start_m", "end_m"),
              "speed_limits": ("start_m",)}


# ---- writing the systems ---------------------------------------------------------------------
def _chain_parameters(base: BaseSystem, trains: int, files: Dict[str, str]):
    """coder, rail, receiver parameters for ``trains`` trains (per-train rail entries anew)."""
    p = base.parameters
    coder = {k: v for k, v in p["coder"].items() if k not in ("line_file",)}
    rail = {k: v for k, v in p["rail"].items() if not k.startswith(_PER_TRAIN) and k != "line_file"}
    receiver = dict(p["receiver"])
    for part in (coder, rail, receiver):
        part.pop("fs", None)
    return {**coder, **files}, {**rail, **files}, receiver


def write_system(folder: Path, plan: TrialPlan, slots: Sequence[TrainSlot], name: str,
                 timetables: Dict[int, str], stop_time_s: float) -> Path:
    """A system of the trains ``slots`` (their timetable files ``timetables[index]``, in
    resources/) on the plan's line: the base system's chain sized for them."""

    base = plan.base
    folder = Path(folder)
    resources = folder / "resources"
    resources.mkdir(parents=True, exist_ok=True)
    (resources / "trial_line.json").write_text(json.dumps(plan.line_doc, indent=1, ensure_ascii=False) + "\n")
    stock_name = Path(base.stock_file).name
    (resources / stock_name).write_text(Path(base.stock_file).read_text())
    files = {"line_file": "trial_line.json"}
    size = BuildConfig(max(base.sections, plan.sections), max(len(slots), BuildConfig().trains), base.frame)
    fmu_folder = f"resources/{size.folder_name}" if size.folder_name else "resources"
    coder, rail, receiver = _chain_parameters(base, len(slots), files)
    pairs = [(slot.name, f"{slot.name}_ato") for slot in slots] if len(slots) > 1 else [("train", "ato")]
    chain, links = signal_chain(pairs, sections=size.sections, frame=base.frame, fmu_folder=fmu_folder,
                                coder=coder, rail=rail, receiver=receiver, stocks=[stock_name] * len(slots),
                                fs_hz=base.fs_hz)
    components, connections = list(chain), list(links)
    ato_base = {k: v for k, v in base.parameters["ato"].items()
                if k not in ("line_file", "rolling_stock_file", "timetable_file")}
    train_base = {k: v for k, v in base.parameters["train"].items()
                  if k not in ("line_file", "rolling_stock_file", "x0")}
    stock = {"rolling_stock_file": stock_name}
    for slot, (train, ato) in zip(slots, pairs):
        parts, wires = train_and_ato(
            train, ato, train_parameters={**train_base, **files, **stock, "x0": slot.start_m},
            ato_parameters={**ato_base, **files, **stock, "timetable_file": timetables[slot.index]},
            step_s=(base.steps_s["train"], base.steps_s["ato"]))
        components += parts
        connections += wires
    return write_ssd(folder, name, components, connections, stop_time=float(stop_time_s))


def write_timetable(folder: Path, plan: TrialPlan, slot: TrainSlot, shift_s: float, label: str) -> str:
    """Train ``slot``'s timetable shifted by ``shift_s`` into the system's resources/; its name."""
    name = f"timetable_{label}_{slot.name}.json"
    path = Path(folder) / "resources" / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(plan.timetable(slot, shift_s), indent=1, ensure_ascii=False) + "\n")
    return name


