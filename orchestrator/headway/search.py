"""``railcosim headway``: a system's minimum headway by blocking-time theory and by co-simulation
of N trains through the whole signal chain, side by side (docs/capacity.md).

The pieces: :mod:`orchestrator.headway.trials` makes the systems (N trains queued, each train
alone as its reference), :mod:`orchestrator.headway.blocking` the stairway, and
:mod:`orchestrator.headway.approach` the approach points from each cab system's own rules. The
runs go through the study machinery (orchestrator/study/), each round of trials one study whose
run folders are kept under ``DIR/trials/``.

The search: the trials' headways bracket the blocking-time figure, then each round splits the
bracket between the last unhindered and the last hindered headway into as many parts as there
are workers (plus one), until it is ``RESOLUTION_S`` wide: the least unhindered headway found
is the co-simulated headway (assuming, as every headway computation does, that a longer
interval never hinders where a shorter one does not).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, TextIO

import numpy as np

from orchestrator.errors import UserError
from orchestrator.headway import blocking, trials
from orchestrator.headway.blocking import Trajectory

METHODS = ("blocking", "cosim", "both")
DEFAULT_TRAINS = 3
#: the search stops when the bracket is this narrow (s)
RESOLUTION_S = 1.0
#: the first bracket around the blocking-time figure, as factors of it
FIRST_BRACKET = (0.85, 1.2)
#: rounds after which a search that has not closed its bracket gives up (reported)
MAX_ROUNDS = 12
#: the results' sampling (s): the trajectories' resolution in time
OUTPUT_INTERVAL_S = 0.5


@dataclass
class HeadwayResult:
    system: str
    cab_signal: str
    trains: int
    method: str
    headway_blocking_s: Optional[float] = None
    headway_cosim_s: Optional[float] = None
    critical_section: Optional[dict] = None
    parts_s: Dict[str, float] = field(default_factory=dict)
    stairway: List[dict] = field(default_factory=list)
    trials: List[dict] = field(default_factory=list)
    breakdown_s: Dict[str, float] = field(default_factory=dict)
    notes: List[str] = field(default_factory=list)
    output: Optional[str] = None
    #: the trials' line is the base line shifted by this (m): their results.csv positions less it
    trial_offset_m: float = 0.0

    def as_dict(self) -> dict:
        return {"system": self.system, "cab_signal": self.cab_signal, "trains": self.trains,
                "method": self.method, "headway_blocking_s": self.headway_blocking_s,
                "headway_cosim_s": self.headway_cosim_s, "critical_section": self.critical_section,
                "parts_s": self.parts_s, "trials": self.trials, "breakdown_s": self.breakdown_s,
                "stairway": self.stairway, "notes": self.notes, "output": self.output,
                "trial_offset_m": self.trial_offset_m}


# ---- running systems ---------------------------------------------------------------------------
def run_in_process(system: Path, output: Path, stop_time_s: float, fmu_dirs: Sequence[Path], overrides=None):
    from orchestrator.run import RunOptions, run_system

    options = RunOptions(stop_time=stop_time_s, output_dir=output, overrides=dict(overrides or {}),
                         output_interval=OUTPUT_INTERVAL_S, in_process=True, fmu_dirs=list(fmu_dirs),
                         default_scenario=False, progress=False, warn=lambda line: None)
    return run_system(system, options)


def _study(folder: Path, name: str, system: Path, cases: List[dict], stop_time_s: float,
           fmu_dirs: Sequence[Path], workers: Optional[int], progress: Optional[TextIO], resume: bool = False):
    """Run ``cases`` of ``system`` as one study into ``folder``; its records by run id, in order."""
    from orchestrator.study.runner import run_study
    from orchestrator.study.spec import load_study

    folder.mkdir(parents=True, exist_ok=True)
    spec_path = folder / f"{name}.json"
    spec_path.write_text(json.dumps({
        "name": name, "description": f"headway trials: {name}", "system": str(system),
        "stop_time": float(stop_time_s), "timeout_s": 7200,
        "options": {"output_interval": OUTPUT_INTERVAL_S, "no_scenario": True, "in_process": True},
        "collect": ["verdict", "signals_passed_at_danger", "wrong_side_failures", "unsafe_indications"],
        "cases": cases}, indent=1) + "\n")
    spec = load_study(spec_path)
    result = run_study(spec, folder / "study", system, list(fmu_dirs), workers=workers, progress=progress,
                       resume=resume)
    failed = [r for r in result.records if r["status"] != "ok"]
    if failed:
        raise UserError(f"headway: {len(failed)} run(s) of {name} failed, first {failed[0]['id']}: "
                        f"{failed[0]['error']} (runs in {folder / 'study' / 'runs'})")
    return [(record, folder / "study" / "runs" / record["id"]) for record in sorted(result.records, key=lambda r: r["id"])]


# ---- the blocking-time method -----------------------------------------------------------------
def release_s(base: trials.BaseSystem) -> float:
    """Track relay pick-up (the section shows free) and the coder's switch-on delay."""
    from fmus.rail_line.core import RailSettings
    from fmus.wayside_coder.core import CoderSettings

    rail = base.parameters["rail"]
    coder = base.parameters["coder"]
    pick_up = float(rail.get("relay_pick_up_delay", RailSettings().relay_pick_up_delay_s))
    switch_on = float(coder.get("switch_on_delay", CoderSettings().switch_on_delay_s))
    return pick_up + switch_on


def latency_s(base: trials.BaseSystem) -> float:
    from fmus.ato_controller.core import AtoSettings

    return float(base.parameters["ato"].get("decoding_latency", AtoSettings().decoding_latency_s))


def run_alone(base: trials.BaseSystem, folder: Path, fmu_dirs: Sequence[Path], line_text: str,
              timetable: dict, x0_m: float, stop_time_s: float, offset_m: float = 0.0) -> Trajectory:
    """The base system's train alone with its ATO and no signal chain (the ATP on line limits,
    as ``ato_only``) on the line ``line_text`` (a line file's text) to ``timetable``: its
    trajectory. The ATO keeps the base's planned deceleration (its default depends on the cab
    mode: TVM-430's is harder), so that it drives as it does in the chain. Positions read back
    less ``offset_m`` (a trial's line against its base line)."""
    from orchestrator.systems.chain import train_and_ato, write_ssd

    system = Path(folder) / "system"
    resources = system / "resources"
    resources.mkdir(parents=True, exist_ok=True)
    (resources / "line.json").write_text(line_text)
    stock = Path(base.stock_file).name
    (resources / stock).write_text(Path(base.stock_file).read_text())
    (resources / "timetable.json").write_text(json.dumps(timetable, indent=1, ensure_ascii=False) + "\n")
    ato = {k: v for k, v in base.parameters["ato"].items() if k not in ("line_file", "rolling_stock_file", "timetable_file")}
    if not float(ato.get("braking_decel", 0.0) or 0.0) > 0.0:
        from fmus.ato_controller.core import AtoSettings, default_plan_decel_mps2

        mode = str(ato.get("cab_signal") or AtoSettings().cab_signal)
        ato["braking_decel"] = round(default_plan_decel_mps2(base.stock, mode), 6)
    files = {"line_file": "line.json", "rolling_stock_file": stock}
    plant = {k: v for k, v in base.parameters["train"].items() if k not in ("line_file", "rolling_stock_file", "x0")}
    components, connections = train_and_ato(
        train_parameters={**plant, **files, "x0": float(x0_m)},
        ato_parameters={**ato, **files, "cab_signal": "off", "timetable_file": "timetable.json"},
        step_s=(base.steps_s["train"], base.steps_s["ato"]))
    write_ssd(system, "unhindered", components, connections, stop_time=float(stop_time_s))
    run_in_process(system, Path(folder) / "run", float(stop_time_s), fmu_dirs)
    return trials.read_trajectories(Path(folder) / "run", ["train"], offset_m)["train"]


def unhindered_run(plan: trials.TrialPlan, folder: Path, fmu_dirs: Sequence[Path]) -> Trajectory:
    """The train of the plan standing where the base train stands, alone: :func:`run_alone`."""
    slot = plan.origin_slot
    timetable = plan.timetable(slot, 0.0)
    stop = plan.stop_time_s(0.0) if plan.run_off else timetable["stops"][-1]["arrival_s"] + 120.0
    return run_alone(plan.base, folder, fmu_dirs, json.dumps(plan.line_doc, indent=1, ensure_ascii=False) + "\n",
                     timetable, slot.start_m, stop, plan.offset_m)


def approach_points(base: trials.BaseSystem, plan: trials.TrialPlan, run: Trajectory):
    """Each block's approach points on the unhindered run, were that block occupied
    (orchestrator/headway/approach.py; docs/capacity.md#approach): by **indication**, the entry
    of the first block behind it whose indication's permitted speed lies anywhere below the
    unhindered run (the ATO must find the free-line indication there, or it is slowed); by
    **braking curve**, the first head position where the unhindered speed exceeds the ATP's
    permitted speed (the latest the ATP itself would intervene). None: nothing restricts."""
    from orchestrator.headway import approach

    line = base.line
    setup = approach.cab_setup(base.cab_system, base.block_aspects, base.line_file, base.stock_file,
                               base.parameters["ato"], base.parameters["receiver"])
    grid = np.arange(max(run.start_m, 0.0), run.furthest_m, 5.0)
    speeds = run.speed_at(grid)
    starts = np.array([entry for entry, _ in line.block_bounds])
    by_indication: List[Optional[float]] = []
    by_curve: List[Optional[float]] = []
    for k, (entry, _) in enumerate(line.block_bounds):
        ahead = grid < entry
        if not ahead.any():
            by_indication.append(None)
            by_curve.append(None)
            continue
        permitted = approach.permitted_speed_mps(setup, k, grid[ahead], speeds[ahead])
        over = np.flatnonzero(np.nan_to_num(speeds[ahead] - permitted, nan=-1.0) > 0.0)
        if not over.size:
            by_indication.append(None)
            by_curve.append(None)
            continue
        by_curve.append(float(grid[ahead][over[0]]))
        block = int(np.searchsorted(starts, grid[ahead][over[0]], side="right") - 1)
        by_indication.append(float(max(starts[block], run.start_m)))
    return by_indication, by_curve


def blocking_stairway(plan: trials.TrialPlan, run: Trajectory, by: str = "indication",
                      points=None) -> List[blocking.BlockingTime]:
    """The run's stairway with the approach points ``by`` indication (the headline) or by the
    ATP's braking curve (:func:`approach_points`; ``points``: as it gave them for this run)."""
    base = plan.base
    line = base.line
    names = [line.sections[line.block_of_section.index(k)].signal or str(k + 1) for k in range(len(line.block_bounds))]
    by_indication, by_curve = points if points is not None else approach_points(base, plan, run)
    return blocking.stairway(run, line.block_bounds, names, by_indication if by == "indication" else by_curve,
                             plan.length_m, latency_s(base), release_s(base))


# ---- the co-simulation method -----------------------------------------------------------------
class Search:
    """The trials of one system (module docstring)."""

    def __init__(self, plan: trials.TrialPlan, folder: Path, fmu_dirs: Sequence[Path], workers: Optional[int],
                 progress: Optional[TextIO], build: Optional[Callable[[Sequence[Path]], None]], resume: bool = False):
        self.plan, self.folder, self.fmu_dirs = plan, folder, list(fmu_dirs)
        self.resume = resume
        self.workers, self.progress, self.build = workers, progress, build
        self.references: Dict[str, Trajectory] = {}
        self.outcomes: Dict[float, dict] = {}
        #: each block's approach point by indication on the unhindered run (set by headway())
        self.approach_m: List[Optional[float]] = []
        #: the unhindered run and its approach points (for the breakdown; set by headway())
        self.unhindered: Optional[Trajectory] = None
        self.unhindered_points = None
        self.rounds = 0

    def _say(self, text: str) -> None:
        if self.progress is not None:
            print(f"headway: {text}", file=self.progress, flush=True)

    def prepare(self) -> None:
        """Write the reference and trial systems and build the FMU sizes they need, before any
        run in this process (a build after runs in the same process is what the builder's
        shadowing rules guard against; doing it first keeps it simple)."""
        plan = self.plan
        system = self.folder / "systems" / "reference"
        self.reference_timetables = {slot.index: trials.write_timetable(system, plan, slot, 0.0, "reference")
                                     for slot in plan.slots}
        first = plan.origin_slot
        trials.write_system(system, plan, [first], "reference", {first.index: self.reference_timetables[first.index]},
                            plan.stop_time_s(0.0))
        if self.build is not None:
            self.build([system, self.trial_system()])

    def run_references(self) -> None:
        plan = self.plan
        system = self.folder / "systems" / "reference"
        timetables = self.reference_timetables
        cases = [{"train.x0": slot.start_m, "ato.timetable_file": timetables[slot.index]} for slot in plan.slots]
        stop = max(plan.timetable(slot, 0.0)["stops"][-1]["arrival_s"] for slot in plan.slots) + 120.0
        if plan.run_off:
            stop = plan.stop_time_s(0.0)
        self._say(f"{len(cases)} reference run(s): each train alone on the line")
        for slot, (_, run_dir) in zip(plan.slots, _study(self.folder / "references", "references", system, cases,
                                                         stop, self.fmu_dirs, self.workers, self.progress, self.resume)):
            self.references[slot.name] = trials.read_trajectories(run_dir, ["train"], plan.offset_m)["train"]

    def trial_system(self) -> Path:
        plan = self.plan
        system = self.folder / "systems" / "trial"
        if not (system / "SystemStructure.ssd").is_file():
            timetables = {slot.index: trials.write_timetable(system, plan, slot, 0.0, "h0") for slot in plan.slots}
            trials.write_system(system, plan, plan.slots, "trial", timetables, plan.stop_time_s(0.0))
        return system

    def evaluate(self, headways: Sequence[float]) -> None:
        """One round: the trials at ``headways`` (s) as one study, and each follower's reference
        at its trial's shift as another (orchestrator/headway/trials.py: why the same shift)."""
        plan = self.plan
        system = self.trial_system()
        headways = [h for h in dict.fromkeys(float(h) for h in headways) if h not in self.outcomes]
        if not headways:
            return
        self.rounds += 1
        cases = []
        for h in headways:
            label = f"h{h:g}"
            cases.append({f"{slot.name}_ato.timetable_file":
                          trials.write_timetable(system, plan, slot, (slot.index - 1) * h, label) for slot in plan.slots})
        reference_last = self.references[plan.slots[-1].name]
        stop = max(plan.stop_time_s(h, float(reference_last.time_at(plan.judge_end_m))) for h in headways)
        self._say(f"round {self.rounds}: trains at {', '.join(f'{h:g}' for h in headways)} s")
        runs = _study(self.folder / "trials" / f"round{self.rounds}", f"round{self.rounds}", system, cases, stop,
                      self.fmu_dirs, self.workers, self.progress, self.resume)
        shifted = self.shifted_references(headways, stop)
        points = plan.timing_points_m()
        names = [slot.name for slot in plan.slots]
        for h, (record, run_dir) in zip(headways, runs):
            runs_of = trials.read_trajectories(run_dir, names, plan.offset_m)
            judged = [trials.judge(slot.name, runs_of[slot.name], shifted[h, slot.name], 0.0,
                                   points, self.judge_end_m(runs_of[ahead.name]))
                      for ahead, slot in zip(plan.slots, plan.slots[1:])]
            # the leader has nobody ahead: it must match its reference (the check of the method)
            leader = trials.judge(plan.slots[0].name, runs_of[plan.slots[0].name],
                                  self.references[plan.slots[0].name], 0.0, points, plan.judge_end_m)
            worst = max(judged, key=lambda j: (j.hindered, j.late_s))
            self.outcomes[h] = {
                "headway_s": h, "hindered": any(j.hindered for j in judged), "run_dir": str(run_dir),
                "worst_follower": worst.train, "late_s": round(worst.late_s, 2), "late_at_m": worst.late_at_m,
                "speed_deficit_kmh": round(max(j.speed_deficit_kmh for j in judged), 2),
                "leader_late_s": round(leader.late_s, 2), "verdict": record["collected"].get("verdict"),
                "signals_passed_at_danger": record["collected"].get("signals_passed_at_danger"),
                "wrong_side_failures": record["collected"].get("wrong_side_failures"),
                "unsafe_indications": record["collected"].get("unsafe_indications")}
            self._say(f"  {h:g} s: {'hindered' if self.outcomes[h]['hindered'] else 'unhindered'} "
                      f"(worst {worst.train}: {worst.late_s:+.1f} s at {worst.late_at_m:g} m, "
                      f"{self.outcomes[h]['speed_deficit_kmh']:.1f} km/h slower)")

    def shifted_references(self, headways: Sequence[float], stop_s: float) -> Dict[tuple, Trajectory]:
        """Each follower alone at its trial's shift, as one study: (headway, train) → its run."""
        plan = self.plan
        system = self.folder / "systems" / "reference"
        keys = [(h, slot) for h in headways for slot in plan.slots[1:]]
        cases = [{"train.x0": slot.start_m,
                  "ato.timetable_file": trials.write_timetable(system, plan, slot, (slot.index - 1) * h, f"h{h:g}")}
                 for h, slot in keys]
        runs = _study(self.folder / "references" / f"round{self.rounds}", f"references{self.rounds}", system,
                      cases, stop_s, self.fmu_dirs, self.workers, self.progress, self.resume)
        return {(h, slot.name): trials.read_trajectories(run_dir, ["train"], plan.offset_m)["train"]
                for (h, slot), (_, run_dir) in zip(keys, runs)}

    def judge_end_m(self, ahead: Trajectory) -> float:
        """Where judging a follower ends: the plan's end (the last stop, or without a run-off the
        approach point of its block), or, without a run-off, the approach point of the block in
        which the train ahead stands at the end — trains held behind a full terminus stand
        further back on the line, and what they restrict is the terminus, not the headway."""
        end = self.plan.judge_end_m
        if self.plan.run_off or abs(float(ahead.speed_mps[-1])) > 1e-3:
            return end
        bounds = self.plan.base.line.block_bounds
        standing = float(ahead.head_m[-1])
        block = next((k for k, (a, b) in enumerate(bounds) if a <= standing < b), None)
        if block is None:
            return end
        point = self.approach_m[block] if self.approach_m[block] is not None else bounds[block][0]
        return min(end, float(point))

    def bracket(self) -> tuple:
        free = [h for h, o in self.outcomes.items() if not o["hindered"]]
        held = [h for h, o in self.outcomes.items() if o["hindered"] and (not free or h < min(free))]
        return (max(held) if held else None), (min(free) if free else None)

    def run(self, guess_s: float) -> Optional[float]:
        """The least unhindered headway, to RESOLUTION_S (None: not found within MAX_ROUNDS)."""
        parts = max(int(self.workers or 2), 1)
        self.evaluate([max(round(guess_s * f), 30.0) for f in FIRST_BRACKET])
        while self.rounds < MAX_ROUNDS:
            low, high = self.bracket()
            if high is None:
                self.evaluate([round(max(self.outcomes) * 1.5)])
                continue
            if low is None:
                self.evaluate([max(round(min(self.outcomes) / 1.5), 1.0)])
                continue
            if high - low <= RESOLUTION_S:
                return high
            step = (high - low) / (parts + 1)
            points = sorted({min(max(round(low + step * i), low + 1), high - 1) for i in range(1, parts + 1)})
            self.evaluate(points)
        low, high = self.bracket()
        return high if low is not None and high is not None and high - low <= RESOLUTION_S else None


# ---- the command ------------------------------------------------------------------------------
def headway(system_path: Path, method: str = "both", trains: int = DEFAULT_TRAINS, output: Optional[Path] = None,
            fmu_dirs: Sequence[Path] = (), build: Optional[Callable[[Sequence[Path]], None]] = None,
            workers: Optional[int] = None, progress: Optional[TextIO] = None, resume: bool = False) -> HeadwayResult:
    """The system's headway by ``method`` (module docstring) into ``output``; ``build`` makes
    the FMU sizes the trial systems name (the CLI passes the builder; None: already built);
    ``resume``: the runs an earlier call into the same folder finished for the same study are
    kept (the study machinery's --resume)."""
    if method not in METHODS:
        raise UserError(f"--method {method}: choose one of {', '.join(METHODS)}")
    base = trials.read_base(system_path)
    plan = trials.TrialPlan(base, trains)
    folder = Path(output) if output else Path("results") / f"headway_{base.name}"
    folder.mkdir(parents=True, exist_ok=True)
    fmu_dirs = list(fmu_dirs)
    result = HeadwayResult(base.name, base.cab_system, trains, method, output=str(folder),
                           trial_offset_m=plan.offset_m)
    search = Search(plan, folder, fmu_dirs, workers, progress, build, resume)
    if method in ("cosim", "both"):
        search.prepare()
    run = unhindered_run(plan, folder / "unhindered", fmu_dirs)
    points = approach_points(base, plan, run)
    steps = blocking_stairway(plan, run, points=points)
    search.approach_m = points[0]
    if not plan.run_off:
        # the trains stay at their last stop: its block is never cleared; judging ends where a
        # train standing there would first restrict its follower
        last_block = next(k for k, (a, b) in enumerate(base.line.block_bounds) if a <= plan.last_stop_m < b)
        end = points[0][last_block] if points[0][last_block] is not None else base.line.block_bounds[last_block][0]
        plan.judge_end_m = float(end)
        steps = [s for s in steps if s.exit_m <= plan.judge_end_m]
        result.notes.append(f"the trains stay at their last stop ({plan.last_stop_m:g} m); headway judged up "
                            f"to {plan.judge_end_m:g} m, the approach point of its block, and each follower "
                            "only up to the approach point of the block where the train ahead of it ends up")
    result.stairway = [s.as_dict() for s in steps]
    critical = blocking.critical_section(steps)
    result.headway_blocking_s = round(critical.duration_s, 1)
    result.critical_section = {"section": critical.section, "name": critical.name, "entry_m": critical.entry_m,
                               "exit_m": critical.exit_m, "approach_m": critical.approach_m}
    result.parts_s = {k: round(v, 2) for k, v in critical.parts_s.items()}
    if method in ("cosim", "both"):
        search.unhindered, search.unhindered_points = run, points
        search.run_references()
        found = search.run(critical.duration_s)
        result.headway_cosim_s = found
        result.trials = [search.outcomes[h] for h in sorted(search.outcomes)]
        if found is None:
            result.notes.append(f"the co-simulated search did not close its bracket in {MAX_ROUNDS} rounds")
        else:
            result.breakdown_s = breakdown(plan, steps, critical, search, found)
    if method == "cosim":
        result.method = "cosim"
    return result


def breakdown(plan, steps, critical, search, found_s: float) -> Dict[str, float]:
    """The difference between the two methods, part by part (docs/capacity.md#the-difference):
    ``cosim_minus_blocking`` = ``chain_running`` + ``chain_reaction``, where

    * ``chain_running``: the critical blocking time on the train's run alone through the whole
      chain (its reference) less that on its run with line limits only (``ato_only``): what the
      cab's ceilings and the ATP's own assumptions do to the train's running;
    * ``chain_reaction``: the co-simulated headway less that blocking time: what the stated
      latency, relay and coder times and the ATO's driving under restrictive indications
      (its margins below the ATP's curves) differ from as simulated;

    and, apart, ``approach_by_braking_curve``: the critical blocking time with the approach point
    where the ATP's curve would first bind instead of at the first restrictive block's entry
    (what the shape of the braking curves leaves of the approach)."""
    run = search.references[plan.origin_slot.name]
    chain_steps = {s.section: s for s in blocking_stairway(plan, run)}
    curve_steps = {s.section: s for s in blocking_stairway(plan, search.unhindered, by="curve",
                                                           points=search.unhindered_points)}
    out = {"cosim_minus_blocking": round(found_s - critical.duration_s, 1)}
    same = chain_steps.get(critical.section)
    if same is not None:
        out["chain_running"] = round(same.duration_s - critical.duration_s, 1)
        out["chain_reaction"] = round(found_s - same.duration_s, 1)
    if critical.section in curve_steps:
        out["approach_by_braking_curve"] = round(curve_steps[critical.section].duration_s - critical.duration_s, 1)
    return out
