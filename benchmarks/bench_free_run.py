"""The default system in full (issue 8 names ≥ 50× real time for it; measured here, not yet met):
free_run = wayside coder → rail line → locomotive receiver (4 kHz, 10 ms frames) → ATP/ATO →
train (0.5 s), 1100 s of the default timetable, through FMI and in process.

    python benchmarks/bench_free_run.py [--stop-time 1100]

Prints the wall time, the real-time factor and the verdict (arrivals, stop errors, ATP
counters) of each run.
"""
import argparse
import json
import tempfile
import time
from pathlib import Path

from orchestrator.cli import SSP_ROOT, _build_dir
from orchestrator.run import RunOptions, run_system


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--stop-time", type=float, default=1100.0)
    args = parser.parse_args()
    for in_process in (False, True):
        with tempfile.TemporaryDirectory() as folder:
            options = RunOptions(stop_time=args.stop_time, output_dir=Path(folder), in_process=in_process,
                                 fmu_dirs=[_build_dir()], record=["train.x", "train.v", "rx.aspect"])
            began = time.perf_counter()
            result = run_system(SSP_ROOT / "free_run", options)
            wall = time.perf_counter() - began
            summary = result.summary
            train = summary["trains"][0]
            stops = ", ".join(f"{s['station']} {s['arrival_deviation_s']:+.1f} s / {s['stop_error_m']:+.2f} m"
                              for s in train.get("stops", []))
            print(f"free_run {'in process' if in_process else 'through FMI'}: {args.stop_time:g} s simulated in "
                  f"{wall:.1f} s ({summary['realtime_factor']:.1f}x real time); {train['energy_kwh']:.1f} kWh; "
                  f"arrivals {stops}; ATP interventions {train['atp_interventions']}, "
                  f"SPAD {train['signals_passed_at_danger']}, max overspeed {train['max_overspeed_kmh']:.2f} km/h")
            print("  aspects:", json.dumps([(round(a["t"], 1), round(a["x"]), a["aspect"]) for a in train["aspects"]]))


if __name__ == "__main__":
    main()
