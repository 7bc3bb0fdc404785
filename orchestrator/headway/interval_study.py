"""The ``capacity_ato`` study: the book's statistical capacity method on co-simulated trains
(docs/capacity.md#the-capacity_ato-study).

One run (:func:`interval_trial`) is a headway trial of the base system (its line, train, ATO
and signal chain; orchestrator/headway/trials.py): ``trains`` identical trains queued at its
origin, scheduled ``interval_factor`` times its blocking-time headway apart, each train's whole
timetable shifted by a deviation drawn for it from a normal distribution of standard deviation
``DEPARTURE_SIGMA_S[driving]``: the train leaves late or early and keeps that deviation, as a
driver keeping his own time would. A follower scheduled too close behind a late leader gets
the leader's restrictive codes through the whole signal chain and is held; its actual interval
is measured at the timing point, the departure from ``timing_station`` (the head
``TIMING_BEYOND_STOP_M`` past its stopping point), from the run's results.csv.

The deviations (per train; an interval differs from its schedule by the difference of two
successive deviations, so independent deviations of standard deviation σ make intervals of
RMS deviation σ·√2):

* ``manual``: the book's pooled RMS of suburban intervals under manual driving, 77.6 s
  (docs/sources.md#headway-and-capacity, row 8), as per-train σ = 77.6 / √2 = 54.9 s;
* ``ato``: our ATO's own spread, the RMS of its arrival deviations at B and C in the shipped
  ``ato_robustness`` study with its default strategy (programme): 5.7 s over its 7 plant
  variants (mass ±10 %, resistance ±20 %, voltage ±5 %; docs/capacity.md#the-capacity_ato-study
  gives the command and the figures).

:func:`summarise` pools a study's intervals per driving and applies the book's formulas
(orchestrator/headway/statistical.py): RMS, under-use, exact interval, the achievable interval
and the capacity gain of ATO driving (its measured interval RMS) over manual driving.
"""
from __future__ import annotations

import json
import math
import shutil
import tempfile
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np

from orchestrator.errors import UserError
from orchestrator.headway import statistical, trials

#: the book's pooled RMS of interval deviations under manual driving (s) [S]
BOOK_MANUAL_INTERVAL_RMS_S = 77.6
#: the ATO RMS the book assumes (s) [S]
BOOK_ATO_RMS_S = 15.0
#: our ATO's RMS arrival deviation (s): ato_robustness, strategy programme, B and C, 14 values [D]
OUR_ATO_DEVIATION_RMS_S = 5.7
#: each driving's per-train deviation σ (s)
DEPARTURE_SIGMA_S = {"manual": BOOK_MANUAL_INTERVAL_RMS_S / math.sqrt(2.0), "ato": OUR_ATO_DEVIATION_RMS_S}
#: the timing point: this far past the timing station's stopping point (its departure) (m)
TIMING_BEYOND_STOP_M = 20.0
#: the run goes on this long after the last train's scheduled departure from the timing station
#: plus its drawn deviation (s): room for a held follower
RUN_MARGIN_S = 150.0


def _system_path(system: str) -> Path:
    """A system folder, or a shipped system's name in a checkout of the repository (ssp/NAME)."""
    path = Path(system)
    if path.exists():
        return path
    shipped = Path(__file__).resolve().parents[2] / "ssp" / system
    if shipped.is_dir():
        return shipped
    raise UserError(f"system {system!r}: no such folder, and no ssp/{system} of a checkout of the repository "
                    "(the capacity_ato study needs a checkout)")


def interval_trial(driving: str, seed: int, system: str = "free_run", trains: int = 4,
                   interval_factor: float = 1.3, timing_station: str = "B", build_dir: Optional[str] = None,
                   fmu_dirs: Optional[Sequence[str]] = None,
                   keep_in: Optional[str] = None, deviations_s: Optional[Sequence[float]] = None) -> dict:
    """One run of the study (module docstring): the measured intervals at the timing point and
    what they come from. ``keep_in``: a folder to keep the run's systems and results in (by
    default a temporary one, removed); ``deviations_s``: the trains' deviations given, not drawn."""
    from orchestrator.headway import search

    if driving not in DEPARTURE_SIGMA_S:
        raise UserError(f"driving {driving!r}: choose one of {', '.join(DEPARTURE_SIGMA_S)}")
    base = trials.read_base(_system_path(system))
    plan = trials.TrialPlan(base, int(trains))
    stations = {s.name: s.stop_m for s in base.line.stations}
    stops = plan.base_timetable["stops"]
    timed = next((s for s in stops if s["station"] == timing_station and "departure_s" in s), None)
    if timed is None:
        raise UserError(f"timing_station {timing_station!r}: not a stop with a departure in {base.timetable_file} "
                        f"(its stops: {', '.join(s['station'] for s in stops)})")
    if not build_dir and not fmu_dirs:
        raise UserError("interval_trial: give build_dir, or run it as a study (which passes its fmu_dirs)")
    build = Path(build_dir) if build_dir else Path(fmu_dirs[0])
    folder = Path(keep_in) if keep_in else Path(tempfile.mkdtemp(prefix="railcosim_capacity_"))
    try:
        unhindered = search.unhindered_run(plan, folder / "unhindered", [build])
        headway_s = blocking_headway_s(plan, unhindered)
        scheduled_s = round(interval_factor * headway_s, 1)
        if deviations_s is None:
            drawn = np.random.default_rng(int(seed)).normal(0.0, DEPARTURE_SIGMA_S[driving], plan.count)
        elif len(deviations_s) != plan.count:
            raise UserError(f"deviations_s: {len(deviations_s)} value(s) for {plan.count} trains")
        else:
            drawn = np.asarray(deviations_s, dtype=float)
        # the earliest train keeps its timetable: no time before the base timetable's own
        shifts = np.arange(plan.count) * scheduled_s + drawn - drawn.min()
        system_dir = folder / "trial"
        timetables = {slot.index: trials.write_timetable(system_dir, plan, slot, float(shifts[slot.index - 1]), "t")
                      for slot in plan.slots}
        stop_s = math.ceil(float(timed["departure_s"]) + plan.lead_s + float(shifts.max()) + RUN_MARGIN_S)
        trials.write_system(system_dir, plan, plan.slots, "interval_trial", timetables, stop_s)
        run_dir = folder / "run"
        summary = _run_judged(system_dir, run_dir, stop_s, [build])
        names = [slot.name for slot in plan.slots]
        runs = trials.read_trajectories(run_dir, names, plan.offset_m)
        point_m = stations[timing_station] + TIMING_BEYOND_STOP_M
        passed = np.array([float(runs[n].time_at(point_m)) for n in names])
        # when each train would pass unhindered: the train alone, shifted as its timetable
        scheduled_pass = float(unhindered.time_at(point_m)) + shifts
        intervals = np.diff(passed)
        out = {"driving": driving, "sigma_s": round(DEPARTURE_SIGMA_S[driving], 2), "seed": int(seed),
               "system": base.name, "trains": plan.count, "headway_blocking_s": round(headway_s, 1),
               "scheduled_interval_s": scheduled_s, "timing_point_m": point_m,
               "drawn_deviations_s": [round(float(d), 2) for d in drawn],
               "scheduled_passing_s": [round(float(t), 2) for t in scheduled_pass],
               "passing_s": [None if math.isnan(t) else round(float(t), 2) for t in passed],
               "delays_s": [None if math.isnan(t) else round(float(t - s), 2) for t, s in zip(passed, scheduled_pass)],
               "intervals_s": [None if math.isnan(i) else round(float(i), 2) for i in intervals],
               "held": [bool(i - (s1 - s0) > trials.LATE_TOLERANCE_S) for i, s0, s1 in
                        zip(intervals, scheduled_pass[:-1], scheduled_pass[1:])],
               **summary}
        for k, interval in enumerate(out["intervals_s"], start=1):
            out[f"interval_{k}_s"] = interval
        valid = intervals[~np.isnan(intervals)]
        out["rms_s"] = round(statistical.rms_deviation_s(valid, scheduled_s), 2) if valid.size else None
        return out
    finally:
        if not keep_in:
            shutil.rmtree(folder, ignore_errors=True)


def blocking_headway_s(plan: trials.TrialPlan, unhindered) -> float:
    """The blocking-time headway of the plan's train (its critical section's blocking time)."""
    from orchestrator.headway import blocking, search

    return float(blocking.critical_section(search.blocking_stairway(plan, unhindered)).duration_s)


def _run_judged(system: Path, run_dir: Path, stop_s: float, fmu_dirs: Sequence[Path]) -> dict:
    """The run with the railway verdicts in its summary.json (as ``railcosim run``)."""
    from functools import partial

    from orchestrator.verdicts.labels import railway_labels
    from orchestrator.verdicts.verdict import railway_verdicts
    from orchestrator.run import RunOptions, run_system
    from orchestrator.study.collect import DERIVED
    from orchestrator.headway.search import OUTPUT_INTERVAL_S

    def silent(line: str) -> None:          # a trial run's warnings are not the user's
        pass

    options = RunOptions(stop_time=stop_s, output_dir=run_dir, output_interval=OUTPUT_INTERVAL_S, in_process=True,
                         fmu_dirs=list(fmu_dirs), default_scenario=False, progress=False, warn=silent,
                         summaries=partial(railway_verdicts, warn=silent), labels=railway_labels)
    run_system(system, options)
    summary = json.loads((run_dir / "summary.json").read_text())
    return {key: derive(summary) for key, derive in DERIVED.items()
            if key in ("verdict", "signals_passed_at_danger", "wrong_side_failures", "unsafe_indications")}


# ---- the study's figures -------------------------------------------------------------------------
def summarise(study_folder: Path) -> dict:
    """A ``capacity_ato`` study's runs pooled per driving, and the book's method applied:
    for each driving its intervals' mean, RMS against the schedule, under-use and exact
    interval; the capacity gain of ATO driving over manual driving with the RMS the ATO runs
    held (and, beside it, with the book's assumed 15 s)."""
    runs_folder = Path(study_folder) / "runs"
    if not runs_folder.is_dir():
        raise UserError(f"{study_folder}: no runs/ folder (give the output folder of railcosim study capacity_ato)")
    pooled: Dict[str, Dict[str, list]] = {}
    for summary_path in sorted(runs_folder.glob("*/summary.json")):
        run = json.loads(summary_path.read_text())
        if "intervals_s" not in run:
            continue
        entry = pooled.setdefault(run["driving"], {"actual": [], "scheduled": [], "held": 0, "runs": 0, "spads": 0})
        entry["runs"] += 1
        entry["spads"] += int(run.get("signals_passed_at_danger") or 0)
        for interval, held in zip(run["intervals_s"], run["held"]):
            if interval is not None:
                entry["actual"].append(interval)
                entry["scheduled"].append(run["scheduled_interval_s"])
                entry["held"] += int(held)
    if not pooled:
        raise UserError(f"{study_folder}: no run of the capacity_ato study there")
    out: Dict[str, object] = {}
    for driving, entry in sorted(pooled.items()):
        actual, scheduled = np.array(entry["actual"]), np.array(entry["scheduled"])
        rms = statistical.rms_deviation_s(actual, scheduled)
        out[driving] = {"runs": entry["runs"], "intervals": int(actual.size), "held_intervals": entry["held"],
                        "signals_passed_at_danger": entry["spads"],
                        "scheduled_interval_s": round(float(scheduled.mean()), 1),
                        "mean_interval_s": round(float(actual.mean()), 1), "rms_s": round(rms, 1),
                        "under_use": round(statistical.under_use(float(actual.mean()), rms), 3),
                        "exact_interval_s": round(statistical.exact_interval_s(float(actual.mean()), rms), 1)}
    if "manual" in pooled and "ato" in pooled:
        manual = np.array(pooled["manual"]["actual"])
        held = out["ato"]["rms_s"]
        for label, r in (("gain_with_our_ato", held), ("gain_with_book_ato", BOOK_ATO_RMS_S)):
            assessed = statistical.assess(manual, np.array(pooled["manual"]["scheduled"]), r)
            out[label] = {"held_rms_s": r, "achievable_interval_s": round(assessed.achievable_interval_s, 1),
                          "capacity_gain": round(assessed.capacity_gain, 3)}
    return out


def main(argv: Optional[List[str]] = None) -> int:
    """``python -m orchestrator.headway.interval_study DIR``: the figures of a study's output."""
    import sys

    args = sys.argv[1:] if argv is None else argv
    if len(args) != 1:
        print("usage: python -m orchestrator.headway.interval_study STUDY_OUTPUT_DIR", file=sys.stderr)
        return 2
    try:
        print(json.dumps(summarise(Path(args[0])), indent=1))
    except UserError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
