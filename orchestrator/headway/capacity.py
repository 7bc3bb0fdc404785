"""Capacity consumption by compression, after UIC Code 406 (docs/capacity.md#compression-and-consumption).

The input is a system of several trains, each a Traction driven by its own AtoController with
its own timetable. Each train runs **alone** on the system's line with its ATO and no signal
chain (cab signal "off": the ATP supervises the line's limits only, as ``ato_only``) — its
unhindered run — and its blocking times over the line form its stairway
(:func:`orchestrator.headway.blocking.stairway`, with the approach points of the system's cab
system). The timetable is then **compressed**:

* the trains keep their timetable's running order (by departure from the first station they all
  depart from, else from their first stop);
* the first train keeps its times; each following train's stairway is moved, earlier or later,
  to the least shift at which none of its blocking times begins before the end of the same
  section's blocking time of any train placed before it (:func:`blocking.minimum_headway_s`
  against each of them): the buffer times become zero where the stairways touch;
* the set is closed as if it repeated: the first train of the next period is compressed behind
  the last train the same way. A timetable of N trains without a period has no time window of
  its own; taking the next period's first train is how the occupancy of the end of the window
  is counted (the compressed stairways of a repeated pattern).

The figures (UIC 406's capacity consumption = occupancy time / time window):

* ``compressed_s`` — the **occupancy time**: from the first train's blocking start to the same
  start of the next period's first train, in the compressed timetable (the sum of the minimum
  headways round the cycle);
* ``window_s`` — the **time window** of the original timetable: N times its mean interval
  between departures (the period the N trains would repeat at), unless given;
* ``consumption_line`` = ``compressed_s`` / ``window_s``;
* per block section, ``occupied_s`` = the sum of the trains' blocking times on it (a shift moves
  a blocking time, it does not change its length) and its ``consumption`` = ``occupied_s`` /
  ``window_s``. For identical trains the critical section's consumption equals the line's (its
  blocking times touch end to start round the cycle); for a mix of trains the line's is higher,
  since different pairs touch on different sections;
* the **critical section**: the section of the highest consumption;
* ``headways``: the minimum headway of each compressed pair (leader, follower, the section on
  which their stairways touch).

What is left out, as the docs page says: UIC 406's buffer times and supplements (the figure is
the compressed occupancy alone), and blocks a train never clears in its run (a train standing
at its last stop occupies its block to the end: that section is left out for it).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Dict, List, Optional, Sequence

import numpy as np

from fmus.signalling import cab_systems
from orchestrator.errors import UserError
from orchestrator.folders import replace_file
from orchestrator.systems import queued
from orchestrator.headway import blocking, trials
from orchestrator.headway.blocking import BlockingTime, Trajectory


# ---- compression (no simulation) ------------------------------------------------------------------
def shifted(steps: Sequence[BlockingTime], shift_s: float) -> List[BlockingTime]:
    """The stairway ``steps`` with every blocking time moved by ``shift_s``."""
    return [replace(b, start_s=b.start_s + shift_s, end_s=b.end_s + shift_s) for b in steps]


@dataclass(frozen=True)
class Compression:
    """The compressed timetable of trains in their running order (module docstring)."""

    shifts_s: List[float]                 # each train's shift from its timetable (the first: 0)
    headways: List[dict]                  # per compressed pair: leader, follower, headway_s, section
    closing_shift_s: float                # the next period's first train's shift
    stairways: List[List[BlockingTime]]   # the compressed stairways, in running order

    @property
    def occupancy_s(self) -> float:
        """From the first train's blocking start to that of the next period's first train (the
        sum of the pairs' headways round the cycle)."""
        return self.closing_shift_s - self.shifts_s[0]


def _least_shift(placed: Sequence[Sequence[BlockingTime]], steps: Sequence[BlockingTime]):
    """The least shift of ``steps`` clear of every stairway in ``placed``, the index of the
    train that binds it and the section where they touch (None, None, None: no shared section)."""
    best, binding, section = None, None, None
    for i, other in enumerate(placed):
        need, where = blocking.minimum_headway_s(other, steps)
        if where is not None and (best is None or need > best):
            best, binding, section = need, i, where
    return best, binding, section


def compress(stairways: Sequence[Sequence[BlockingTime]], names: Sequence[str],
             departures_s: Sequence[float]) -> Compression:
    """Compress stairways given in running order, at their timetable times, of trains departing
    at ``departures_s`` (module docstring); a pair's headway is between their compressed
    departures. A train that shares no section with any train before it keeps its interval to
    the train before (nothing binds it)."""
    if len(stairways) < 2:
        raise ValueError("compression needs at least two trains")
    placed = [list(stairways[0])]
    shifts = [0.0]
    headways = []
    for j in range(1, len(stairways)):
        need, binding, section = _least_shift(placed, stairways[j])
        shift = shifts[-1] if need is None else need
        shifts.append(float(shift))
        placed.append(shifted(stairways[j], shift))
        headways.append({"leader": names[j - 1], "follower": names[j],
                         "binding": None if binding is None else names[binding], "section": section,
                         "headway_s": departures_s[j] + shift - departures_s[j - 1] - shifts[-2]})
    need, binding, section = _least_shift(placed, stairways[0])
    closing = (shifts[-1] + (shifts[-1] - shifts[-2]) if need is None else need)
    headways.append({"leader": names[-1], "follower": f"{names[0]} (next period)",
                     "binding": None if binding is None else names[binding], "section": section,
                     "headway_s": departures_s[0] + closing - departures_s[-1] - shifts[-1]})
    return Compression(shifts, headways, float(closing), placed)


def consumption(stairways: Sequence[Sequence[BlockingTime]], names: Sequence[str], departures_s: Sequence[float],
                window_s: Optional[float] = None) -> dict:
    """The figures of the module docstring for stairways at their timetable times, in running
    order, with their trains' scheduled departures (s)."""
    departures = np.asarray(departures_s, dtype=float)
    if window_s is None:
        span = float(departures[-1] - departures[0])
        if span <= 0.0:
            raise UserError("capacity: the trains' departures span no time; the time window cannot be "
                            "taken from the timetable")
        window_s = span * len(departures) / (len(departures) - 1)
    result = compress(stairways, names, departures)
    sections: Dict[int, dict] = {}
    for steps in result.stairways:
        for b in steps:
            entry = sections.setdefault(b.section, {"section": b.section, "name": b.name, "entry_m": b.entry_m,
                                                     "exit_m": b.exit_m, "occupied_s": 0.0})
            entry["occupied_s"] += b.duration_s
    rows = [dict(s, occupied_s=round(s["occupied_s"], 2), consumption=round(s["occupied_s"] / window_s, 4))
            for _, s in sorted(sections.items())]
    critical = max(rows, key=lambda r: r["consumption"]) if rows else None
    return {"trains": list(names), "window_s": round(float(window_s), 2),
            "compressed_s": round(result.occupancy_s, 2),
            "consumption_line": round(result.occupancy_s / float(window_s), 4),
            "sections": rows, "critical_section": critical,
            "departures_s": [round(float(d), 2) for d in departures],
            "compressed_departures_s": [round(float(d + s), 2) for d, s in zip(departures, result.shifts_s)],
            "headways": [dict(h, headway_s=round(h["headway_s"], 2)) for h in result.headways]}


# ---- the trains of a system -----------------------------------------------------------------------
@dataclass
class TrainOfSystem:
    """One train of a multi-train system: its Traction, its ATO and what they are given."""

    train: str
    ato: str
    base: trials.BaseSystem             # the system's parts as they bind this train
    departure_s: float


def read_trains(system_path: Path) -> List[TrainOfSystem]:
    """Each train of a system with a signal chain, paired with the ATO whose ``x`` input its
    position feeds, in running order (by departure from the first station all trains depart
    from); a UserError naming what is missing otherwise."""
    from fmus.data.loader import DEFAULT_LINE, DEFAULT_ROLLING_STOCK, DEFAULT_TIMETABLE
    from fmus.sizes import BuildConfig, DEFAULT_SAMPLE_RATE_HZ, sizes_of_source
    from orchestrator.ssp import open_system

    description = open_system(Path(system_path))
    name, folder = description.name, description.folder
    by_unit: Dict[str, list] = {}
    for component in description.components.values():
        unit = queued.UNIT_OF_FMU.get(Path(component.source).name)
        if unit:
            by_unit.setdefault(unit, []).append(component)
    for unit in ("coder", "rail", "receiver"):
        if not by_unit.get(unit):
            raise UserError(f"system {name!r}: no signal chain (no {unit}); capacity needs a line with block "
                            "sections and a cab system")
    atos = {c.name for c in by_unit.get("ato", [])}
    pairs = []
    for train in by_unit.get("train", []):
        driver = next((c.end_element for c in description.connections
                       if c.start_element == train.name and c.start_connector == "x" and c.end_element in atos), None)
        if driver is None:
            raise UserError(f"system {name!r}: train {train.name!r} has no AtoController reading its position; "
                            "capacity needs every train driven by its ATO to a timetable")
        pairs.append((train, description.components[driver]))
    if len(pairs) < 2:
        raise UserError(f"system {name!r}: capacity needs at least two trains; it has {len(pairs)} "
                        "(for one train's headway: railcosim headway)")
    chain = {unit: queued.parameter_values(by_unit[unit][0]) for unit in ("coder", "rail", "receiver")}
    rail = by_unit["rail"][0]
    sizes = sizes_of_source(rail.source) or BuildConfig()
    out = []
    for train, ato in pairs:
        values = {**chain, "train": queued.parameter_values(train), "ato": queued.parameter_values(ato)}
        a, t = values["ato"], values["train"]
        timetable = queued.resolved_file(a.get("timetable_file"), folder, DEFAULT_TIMETABLE)
        base = trials.BaseSystem(
            name=name, folder=folder, cab_system=str(chain["coder"].get("system") or cab_systems.DEFAULT.name),
            block_aspects=int(chain["coder"].get("block_aspects") or 3),
            line_file=queued.resolved_file(a.get("line_file") or chain["rail"].get("line_file"), folder, DEFAULT_LINE),
            stock_file=queued.resolved_file(a.get("rolling_stock_file") or t.get("rolling_stock_file"), folder,
                                        DEFAULT_ROLLING_STOCK),
            timetable_file=timetable, x0_m=float(t.get("x0", 400.0)), sections=sizes.sections, frame=sizes.frame,
            fs_hz=float(chain["coder"].get("fs") or DEFAULT_SAMPLE_RATE_HZ),
            steps_s={"train": float(train.step_size_s), "ato": float(ato.step_size_s)}, parameters=values)
        stops = json.loads(Path(timetable).read_text())["stops"]
        if "departure_s" not in stops[0]:
            raise UserError(f"{timetable}: the first stop of {train.name!r}'s timetable has no departure_s")
        out.append((TrainOfSystem(train.name, ato.name, base, float(stops[0]["departure_s"])), stops))
    # the departures that order the trains and span the window: from the first station every
    # train departs from (the origin of trains that draw up to it from holding tracks,
    # docs/capacity.md#co-simulated-headway), else each train's first stop
    departing = [{s["station"]: float(s["departure_s"]) for s in stops if "departure_s" in s} for _, stops in out]
    common = next((s["station"] for s in out[0][1] if all(s["station"] in d for d in departing)), None)
    trains = [TrainOfSystem(t.train, t.ato, t.base, d[common]) if common is not None else t
              for (t, _), d in zip(out, departing)]
    return sorted(trains, key=lambda t: (t.departure_s, t.train))


def unhindered_run(train: TrainOfSystem, folder: Path, fmu_dirs: Sequence[Path]) -> Trajectory:
    """The train alone on the system's line with its own ATO and timetable, cab signal "off"
    (orchestrator/headway/search.py ``run_alone``): its trajectory, at the timetable's own
    times. The run ends 120 s after the timetable's last time."""
    from orchestrator.headway.search import run_alone

    base = train.base
    timetable = json.loads(Path(base.timetable_file).read_text())
    stop_time = max(float(s.get(k, 0.0)) for s in timetable["stops"] for k in ("arrival_s", "departure_s")) + 120.0
    return run_alone(base, folder, fmu_dirs, Path(base.line_file).read_text(), timetable, base.x0_m, stop_time)


def train_stairway(train: TrainOfSystem, run: Trajectory) -> List[BlockingTime]:
    """The train's blocking times on its unhindered run (its timetable's times)."""
    from orchestrator.headway import search

    base = train.base
    line = base.line
    names = [line.sections[line.block_of_section.index(k)].signal or str(k + 1) for k in range(len(line.block_bounds))]
    length_m = float(base.stock.length_m)
    return blocking.stairway(run, line.block_bounds, names, search.approach_points(base, None, run)[0], length_m,
                             search.latency_s(base), search.release_s(base))


def capacity(system_path: Path, fmu_dirs: Sequence[Path], output_dir: Path, window_s: Optional[float] = None) -> dict:
    """UIC 406 capacity consumption of a multi-train system (module docstring): each train's
    unhindered run into ``output_dir/<train>/``, the result also written as capacity.json."""
    trains = read_trains(system_path)
    output_dir = Path(output_dir)
    output_dir.mkdir(parents=True, exist_ok=True)
    fmu_dirs = [Path(d) for d in fmu_dirs]
    stairways = []
    for train in trains:
        run = unhindered_run(train, output_dir / train.train, fmu_dirs)
        steps = train_stairway(train, run)
        if not steps:
            raise UserError(f"system {trains[0].base.name!r}: train {train.train!r} clears no block section "
                            "in its timetable's run; capacity has nothing to compress")
        stairways.append(steps)
    out = {"system": trains[0].base.name, "cab_signal": trains[0].base.cab_system}
    out.update(consumption(stairways, [t.train for t in trains], [t.departure_s for t in trains], window_s))
    out["stairways"] = {t.train: [b.as_dict() for b in steps] for t, steps in zip(trains, stairways)}
    replace_file(output_dir / "capacity.json", json.dumps(out, indent=1, ensure_ascii=False) + "\n")
    return out


def text_lines(result: dict) -> List[str]:
    """What `railcosim capacity` prints: the line's consumption, then each section's."""
    critical = result["critical_section"]
    lines = [f"capacity of {result['system']} ({result['cab_signal']}), {len(result['trains'])} trains: "
             f"{100 * result['consumption_line']:.1f} % of {result['window_s']:.0f} s "
             f"({result['compressed_s']:.0f} s compressed); critical section {critical['name']}"]
    lines += [f"  {section['name']:>6} {section['entry_m']:8.0f}-{section['exit_m']:<8.0f} m "
              f"{section['occupied_s']:7.1f} s  {100 * section['consumption']:5.1f} %"
              for section in result["sections"]]
    return lines
