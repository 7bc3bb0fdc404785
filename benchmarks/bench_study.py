"""Throughput of `railcosim study` and what its machinery costs per run (docs/studies.md,
docs/performance.md).

1. One fixed study (ato_only, 60 s of simulated time, through FMI as `railcosim run` runs it,
   --runs runs) on a LocalCluster of 1 worker, then of 2 workers, back to back: runs per minute
   over the study's whole wall time (cluster start included) and from the moment the cluster is
   up (the study's first progress line) to its end, and over the last three quarters of the
   runs (from the moment a quarter of them are done: every worker past its one-off
   preparation, the rate a long study keeps), and the speed-ups.
2. Per-run cost: a run inside the study (the task on the worker: fork, run, record) against
   the run's own wall time (summary.json wall_time_s: instantiation, initialisation and
   stepping), median of the per-run ratios over the 1-worker study's runs (the first run,
   which also plans the ATO's stages, included), and against the
   median of plain `railcosim run` commands of the same run (a fresh process each, as a user
   starts them).
3. The simulations' own time (summary.json) on 1 and on 2 workers, median over the last three
   quarters: a run's simulation takes longer while the other core is busy too, and twice one
   worker's rate scaled by that is the most two workers could reach (the ceiling printed).

    PYTHONPATH=. python benchmarks/bench_study.py [--runs 32] [--plain 4] [--stop-time 60] [--runs-per-task N]
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from orchestrator.packaging.builder import build_all, default_build_dir  # noqa: E402
from orchestrator.study.runner import run_study  # noqa: E402
from orchestrator.study.spec import check_against_system, load_study  # noqa: E402

SYSTEM = REPO / "ssp" / "ato_only"


def study_file(folder: Path, runs: int, stop_s: float) -> Path:
    # one point per run: initial speeds 4, 5, ... m/s, closer together past 32 runs so every
    # start stays within the line's limit
    step_mps = 1.0 if runs <= 32 else 31.0 / runs
    values = ", ".join(f"{4.0 + k * step_mps:.4f}" for k in range(runs))
    path = folder / "bench.toml"
    path.write_text(f'name = "bench"\nsystem = "ato_only"\nstop_time = {stop_s}\n'
                    f'collect = ["final.train.x", "verdict"]\n[options]\noutput_interval = 1.0\n'
                    f'[grid]\n"train.v0" = [{values}]\n')
    return path


class _Times:
    """A progress stream that notes when the study writes its first line (the cluster is up and
    the runs are being submitted) and then each run's line (as to a terminal: one per run done),
    and shows nothing."""

    def __init__(self):
        self.at = None
        self.done = []

    def write(self, text: str) -> None:
        now = time.perf_counter()
        if self.at is None:
            self.at = now
        else:
            self.done.append(now)

    def flush(self) -> None:
        pass

    def isatty(self) -> bool:
        return True


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=32)
    parser.add_argument("--plain", type=int, default=4, help="plain `railcosim run` commands for the overhead")
    parser.add_argument("--stop-time", type=float, default=60.0)
    parser.add_argument("--runs-per-task", type=int, default=None,
                        help="runs a Dask task takes (default: the study's own choice)")
    args = parser.parse_args(argv)
    fmus = default_build_dir(REPO)
    build_all(fmus)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        spec = load_study(study_file(folder, args.runs, args.stop_time))
        check_against_system(spec, SYSTEM, [fmus])
        throughput, steady, kept, inside, own, simulated = {}, {}, {}, [], [], {}
        for workers in (1, 2):
            up = _Times()
            began = time.perf_counter()
            result = run_study(spec, folder / f"w{workers}", SYSTEM, [fmus], workers=workers, progress=up,
                               runs_per_task=args.runs_per_task)
            ended = time.perf_counter()
            assert result.counts["ok"] == args.runs, result.counts
            throughput[workers] = args.runs / (ended - began) * 60.0
            steady[workers] = args.runs / (ended - up.at) * 60.0
            quarter = args.runs // 4
            kept[workers] = (args.runs - quarter) / (up.done[-1] - up.done[quarter - 1]) * 60.0
            print(f"{workers} worker(s): {args.runs} runs in {ended - began:.1f} s = {throughput[workers]:.1f} runs/min; "
                  f"cluster up after {up.at - began:.1f} s, then {steady[workers]:.1f} runs/min; "
                  f"the last {args.runs - quarter} runs {kept[workers]:.1f} runs/min", flush=True)
            simulations = [json.loads((folder / f"w{workers}" / "runs" / r["id"] / "summary.json").read_text())
                           ["wall_time_s"] for r in result.records]
            simulated[workers] = statistics.median(simulations[quarter:])
            if workers == 1:
                inside = [r["wall_time_s"] for r in result.records]
                own = simulations
        print(f"speed-up 2 workers / 1 worker: {throughput[2] / throughput[1]:.2f}x "
              f"(cluster up: {steady[2] / steady[1]:.2f}x; the last three quarters: {kept[2] / kept[1]:.2f}x)")
        # the simulations alone slow down when both cores are busy (caches, memory, the host):
        # twice one worker's rate scaled by that is as far as two workers could go
        print(f"the simulation of a run (median of the last three quarters): {1e3 * simulated[1]:.1f} ms on 1 worker, "
              f"{1e3 * simulated[2]:.1f} ms on 2: two workers' ceiling {2 * simulated[1] / simulated[2]:.2f}x")
        plain = []
        env = {**os.environ, "PYTHONPATH": str(REPO)}
        for k in range(args.plain):
            began = time.perf_counter()
            subprocess.run([sys.executable, "-m", "orchestrator", "run", "ato_only", "--no-build",
                            "--stop-time", str(args.stop_time), "--output-interval", "1.0",
                            "--set", f"train.v0={4.0 + k:.1f}", "--output", str(folder / f"plain{k}")],
                           env=env, check=True, capture_output=True)
            plain.append(time.perf_counter() - began)
        med_inside, med_own = statistics.median(inside), statistics.median(own)
        print(f"median per run: in the study {med_inside:.3f} s, the simulation alone {med_own:.3f} s"
              + (f", plain `railcosim run` {statistics.median(plain):.2f} s "
                 f"(study machinery over a plain run: {100 * (med_inside / statistics.median(plain) - 1):+.1f} %)"
                 if plain else ""))
        ratio = statistics.median(a / b for a, b in zip(inside, own))
        per_run_kept = 60.0 / kept[1]
        print(f"a run in the study / the simulation alone: {ratio:.2f}x (median over {len(own)} runs); "
              f"the 1-worker study's wall time per run over its last three quarters {per_run_kept:.3f} s "
              f"= {per_run_kept / med_own:.2f}x the median simulation; load average {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
