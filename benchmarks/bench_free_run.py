"""The default system in full (target: ≥ 50× real time in one process): free_run = wayside
coder → rail line → locomotive receiver (4 kHz, 10 ms frames) → ATP/ATO → train (0.5 s), 1100 s
of the default timetable, in process (the facades driven directly, the performance reference of docs/architecture.md#master-algorithm-orchestratormasterpy) and
through FMI (fmpy + pythonfmu, the same process).

    python benchmarks/bench_free_run.py [--stop-time 1100] [--repeats 3]

Prints each run's wall time, real-time factor and verdict (arrivals, stop errors, ATP counters,
receiver wrong-side failures), then the median real-time factor per mode and the FMI / in-process
ratio of the medians (the two modes alternate, so they share the machine's load).
"""
import argparse
import statistics
import sys
import time
from pathlib import Path

from orchestrator.cli import SSP_ROOT, _build_dir

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # `python benchmarks/X.py` from anywhere
from benchmarks._runs import scratch_run  # noqa: E402


def run_once(stop_time: float, in_process: bool) -> float:
    began = time.perf_counter()
    result = scratch_run(SSP_ROOT / "free_run", in_process, [_build_dir()], stop_time)
    wall = time.perf_counter() - began
    summary = result.summary
    train = summary["trains"][0]
    receiver = summary["receivers"][0]
    stops = ", ".join(f"{s['station']} {s['arrival_deviation_s']:+.1f} s / {s['stop_error_m']:+.2f} m"
                      if s.get("arrival_deviation_s") is not None else f"{s['station']} not reached"
                      for s in train.get("stops", []))
    print(f"free_run {'in process' if in_process else 'through FMI'}: {stop_time:g} s simulated, "
          f"{summary['wall_time_s']:.1f} s stepping ({wall:.1f} s with loading), "
          f"{summary['realtime_factor']:.1f}x real time; {train['energy_kwh']:.1f} kWh; arrivals {stops}; "
          f"ATP interventions {train['atp_interventions']}, SPAD {train['signals_passed_at_danger']}, "
          f"receiver wrong-side {receiver['wrong_side_failures']}", flush=True)
    return summary["realtime_factor"]


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--stop-time", type=float, default=1100.0)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    factors = {True: [], False: []}
    for _ in range(args.repeats):
        for in_process in (True, False):
            factors[in_process].append(run_once(args.stop_time, in_process))
    in_process, fmi = statistics.median(factors[True]), statistics.median(factors[False])
    print(f"median real-time factor over {args.repeats} runs: in process {in_process:.1f}x "
          f"(min {min(factors[True]):.1f}, max {max(factors[True]):.1f}), through FMI {fmi:.1f}x "
          f"(min {min(factors[False]):.1f}, max {max(factors[False]):.1f}); FMI costs {in_process / fmi:.2f}x")


if __name__ == "__main__":
    main()
