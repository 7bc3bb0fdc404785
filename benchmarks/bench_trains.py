"""The whole system against the number of trains (docs/performance.md#many-trains).

    python benchmarks/bench_trains.py [--trains 1 2 4 8 12 16] [--stop-time 90] [--repeats 3] [--in-process]

Through FMI (``--in-process``: the facades without FMI): the wayside coder, the rail line and,
per train, a locomotive receiver, an ATO and a traction unit, on the suburban line (31 block
sections of 1.0-1.35 km, 4-aspect ALSN block, a build of 32 sections and M = the trains):
N ЭР2 EMUs queued 2.2 km apart from Glavnaya (400 m) on, each in block sections of its own, so
that every train gets a code (green, yellow or red-yellow, all of which permit a start) and
moves; the foremost departs at 10 s, each one behind it 2 s later (harness/queued_trains.py).
Each run covers --stop-time simulated seconds and records what `railcosim run` records by
default (every scalar output at 0.1 s). Per N, the median of --repeats runs (the sizes
taken in turn within each repetition, so the machine's drift hits all alike) of

* the real-time factor of the whole run (what summary.json reports: initialisation included),
* the wall cost of a simulated second while stepping (initialisation excluded),
* the initialisation (loading the FMUs, the ATOs' planning from cold, the rail line's models),
* how many trains moved (more than 1 m),

then the least-squares fit of log cost = c + β·log N (β ≤ 1.1 is the target: no worse than one
receiver, ATO and traction unit more per train) for the stepping and for the whole run.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # `python benchmarks/X.py` from anywhere

from fmus.ato_controller import planner  # noqa: E402
from harness.queued_trains import Queue, write_queued_trains  # noqa: E402
from harness.suburban import EMU, SUBURBAN_LINE  # noqa: E402
from orchestrator.reports.report import read_results  # noqa: E402
from orchestrator.verdicts.verdict import railway_verdicts  # noqa: E402
from orchestrator.packaging.builder import build_all, build_sized_for, default_build_dir  # noqa: E402
from orchestrator.run import RunOptions, run_system  # noqa: E402

SPACING_M = 2200.0       # > the longest block section + a train: no two trains in one section


class Stopwatch:
    """A judge that only notes when stepping starts and ends."""

    def __init__(self):
        self.started_s = self.closed_s = None

    def outputs_needed(self):
        return {}

    def started(self, master, step):
        self.started_s = time.perf_counter()

    def after_tick(self, master, step):
        return None

    def close(self):
        self.closed_s = time.perf_counter()

    def summary_section(self):
        return {}


def queue_of(trains: int, stop_time_s: float) -> Queue:
    return Queue(trains=trains, line_file=SUBURBAN_LINE, stock_file=EMU, rear_head_m=400.0, spacing_m=SPACING_M,
                 first_departure_s=10.0, departure_interval_s=2.0, block_aspects=4, sections=32,
                 stop_time_s=stop_time_s)


def one_run(system: Path, in_process: bool, fmu_dir: Path) -> dict:
    # each run plans from cold, as a fresh `railcosim run` does: the FMUs run in this interpreter
    # and would find the stages an earlier run planned (the queues of 12 and 16 share origins)
    planner._IN_MEMORY._kept.clear()
    watch = Stopwatch()
    with tempfile.TemporaryDirectory() as out:
        options = RunOptions(summaries=lambda graph: list(railway_verdicts(graph)) + [watch], output_dir=Path(out),
                             in_process=in_process, fmu_dirs=[fmu_dir])
        began = time.perf_counter()
        summary = run_system(system, options).summary
        results = read_results(Path(out))
    moved = sum(1 for t in summary["trains"] if np.ptp(results[f"{t['name']}.x"]) > 1.0)
    sim = summary["sim_time_s"]
    return {"rtf": summary["realtime_factor"], "step_cost": (watch.closed_s - watch.started_s) / sim,
            "init_s": watch.started_s - began, "moved": moved,
            "spad": sum(t.get("signals_passed_at_danger", 0) for t in summary["trains"]),
            "wrong_side": sum(r["wrong_side_failures"] for r in summary["receivers"])}


def fit_exponent(trains, cost) -> float:
    slope, _ = np.polyfit(np.log(np.asarray(trains, float)), np.log(np.asarray(cost, float)), 1)
    return float(slope)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trains", type=int, nargs="+", default=[1, 2, 4, 8, 12, 16])
    parser.add_argument("--stop-time", type=float, default=90.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--in-process", action="store_true")
    args = parser.parse_args()
    fmu_dir = default_build_dir()
    build_all(fmu_dir)
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory() as scratch:
        systems = {}
        for n in args.trains:
            systems[n] = write_queued_trains(Path(scratch) / f"q{n}", queue_of(n, args.stop_time)).parent
        build_sized_for(fmu_dir, systems.values())
        runs = {n: [] for n in args.trains}
        for repeat in range(args.repeats):
            for n in args.trains:
                runs[n].append(one_run(systems[n], args.in_process, fmu_dir))
                r = runs[n][-1]
                print(f"  repeat {repeat + 1} N={n}: {r['rtf']:.2f}x, {1e3 * r['step_cost']:.0f} ms per sim s, "
                      f"init {r['init_s']:.1f} s, moved {r['moved']}", flush=True)
    mode = "in process" if args.in_process else "through FMI"
    print(f"\n{mode}, {args.stop_time:g} s simulated, median of {args.repeats}; load average (1, 5, 15 min) "
          f"before {' '.join(f'{x:.1f}' for x in load_before)}, after {' '.join(f'{x:.1f}' for x in os.getloadavg())}")
    print(f"{'trains':>6} {'real time':>10} {'ms/sim s stepping':>18} {'per train':>10} {'init s':>7} {'moved':>6} "
          f"{'SPAD':>5} {'wrong-side':>10}")
    med = {}
    for n in args.trains:
        rs = runs[n]
        med[n] = {key: statistics.median(r[key] for r in rs) for key in ("rtf", "step_cost", "init_s")}
        print(f"{n:>6} {med[n]['rtf']:>9.2f}x {1e3 * med[n]['step_cost']:>18.1f} "
              f"{1e3 * med[n]['step_cost'] / n:>10.1f} {med[n]['init_s']:>7.1f} {min(r['moved'] for r in rs):>6} "
              f"{max(r['spad'] for r in rs):>5} {max(r['wrong_side'] for r in rs):>10}")
    ns = list(args.trains)
    stepping = fit_exponent(ns, [med[n]["step_cost"] for n in ns])
    whole = fit_exponent(ns, [args.stop_time / med[n]["rtf"] for n in ns])
    print(f"exponent of cost against trains: stepping {stepping:.2f}, whole run (initialisation included) {whole:.2f}")


if __name__ == "__main__":
    main()
