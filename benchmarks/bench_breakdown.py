"""Where a shipped system's frame goes: timers around every slave call (write inputs, step,
read outputs) per component, in process and through FMI, for one run of each.

    python benchmarks/bench_breakdown.py [--system free_run] [--stop-time 200] [--mode both|in-process|fmi]

Prints µs per 10 ms frame for each (component, call) and the master's total. The timers
themselves add about 1 µs per call, so the totals are a little above bench_free_run's; the
difference between the two modes is what the FMI layer (fmpy + pythonfmu's C wrapper) costs
per call (docs/performance.md).
"""
import argparse
import collections
import tempfile
import time
from pathlib import Path

from orchestrator import fmu, master
from orchestrator.cli import SSP_ROOT, _build_dir
from orchestrator.verdicts.verdict import railway_verdicts
from orchestrator.run import RunOptions, run_system

FRAME_S = 0.01
CALLS = ("write_inputs", "do_step", "read_outputs")


def _timed(spent, counts, cls, method):
    original = getattr(cls, method)

    def wrapper(self, *args):
        began = time.perf_counter()
        try:
            return original(self, *args)
        finally:
            spent[(self.name, method)] += time.perf_counter() - began
            counts[(self.name, method)] += 1
    setattr(cls, method, wrapper)
    return original


def breakdown(system: str, stop_time: float, in_process: bool):
    spent, counts = collections.defaultdict(float), collections.Counter()
    originals = [(cls, m, _timed(spent, counts, cls, m)) for cls in (fmu.InProcessSlave, fmu.FmuSlave) for m in CALLS]
    original_run = master.Master.run_until

    def run_until(self, stop_ticks):
        began = time.perf_counter()
        original_run(self, stop_ticks)
        spent[("master", "run_until (all)")] += time.perf_counter() - began
    master.Master.run_until = run_until
    try:
        with tempfile.TemporaryDirectory() as folder:
            options = RunOptions(summaries=railway_verdicts, stop_time=stop_time, output_dir=Path(folder), in_process=in_process,
                                 fmu_dirs=[_build_dir()], record=["train.x"])
            run_system(SSP_ROOT / system, options)
    finally:
        master.Master.run_until = original_run
        for cls, method, original in originals:
            setattr(cls, method, original)
    frames = stop_time / FRAME_S
    return {key: value / frames * 1e6 for key, value in spent.items()}, counts


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--system", default="free_run")
    parser.add_argument("--stop-time", type=float, default=200.0)
    parser.add_argument("--mode", choices=("both", "in-process", "fmi"), default="both")
    args = parser.parse_args()
    modes = {"both": (True, False), "in-process": (True,), "fmi": (False,)}[args.mode]
    results = {mode: breakdown(args.system, args.stop_time, mode) for mode in modes}
    keys = sorted({key for per_frame, _ in results.values() for key in per_frame})
    header = " | ".join("in process µs/frame" if mode else "FMI µs/frame" for mode in modes)
    print(f"{args.system}, {args.stop_time:g} s: component call | {header} | calls")
    for key in keys:
        cells = " | ".join(f"{results[mode][0].get(key, 0.0):8.1f}" for mode in modes)
        print(f"{key[0]:>8} {key[1]:<16} | {cells} | {results[modes[0]][1].get(key, '')}")


if __name__ == "__main__":
    main()
