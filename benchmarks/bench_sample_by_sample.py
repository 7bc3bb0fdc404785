"""The signal chain sample by sample (the hardware-in-the-loop case, target ≥ 2× real time in
process): free_run built with N = 1, so coder, rail line and receiver step every 0.25 ms
sample (4000 steps per simulated second each) and the train and ATO every 0.5 s.

    python benchmarks/bench_sample_by_sample.py [--stop-time 20] [--repeats 3] [--fmi]

Builds the five FMUs with frame 1 into build/fmus_n1 (once; later runs find them up to
date), writes a free_run system for them into a temporary folder (the shipped free_run's
components and connections with one sample per frame) and runs it in process (with --fmi also
through FMI, alternating). Prints each run's real-time factor and the medians: the run's own
(summary.json's, initialisation included: about 1 s of model generation and the ATO's
planning) and the stepping's alone (the master's run from the start to the stop time: the
rate a hardware-in-the-loop set-up must sustain tick after tick).
"""
import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

from fmus.signalling import cab_systems
from fmus.sizes import BuildConfig
from orchestrator.systems.chain import cab_settings, signal_chain, train_and_ato
from orchestrator import master
from orchestrator.packaging.builder import build_all
from orchestrator.sspgen import write_ssd

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # `python benchmarks/X.py` from anywhere
from benchmarks._runs import scratch_run  # noqa: E402

REPO = Path(__file__).resolve().parent.parent


def sample_by_sample_system(folder: Path, fmus: Path) -> Path:
    coder, rail, receiver, ato = cab_settings(cab_systems.ALSN.name)
    components, connections = train_and_ato(ato_parameters=ato)
    chain, links = signal_chain(frame=1, fmu_folder=str(fmus), coder=coder, rail=rail, receiver=receiver)
    return write_ssd(folder / "free_run_n1", "free_run_n1", chain + components, connections + links,
                     stop_time=1100.0).parent


def _timed_stepping(times: list):
    """Master.run_until wrapped to append its wall time to ``times``."""
    run_until = master.Master.run_until

    def timed(self, stop_ticks):
        began = time.perf_counter()
        try:
            run_until(self, stop_ticks)
        finally:
            times.append(time.perf_counter() - began)
    return timed


def run_once(system: Path, stop_time: float, in_process: bool, fmus: Path):
    """(the run's real-time factor, the stepping's alone)."""
    stepping: list = []
    original, master.Master.run_until = master.Master.run_until, _timed_stepping(stepping)
    try:
        summary = scratch_run(system, in_process, [fmus], stop_time).summary
    finally:
        master.Master.run_until = original
    steady = stop_time / sum(stepping)
    print(f"free_run, N = 1, {'in process' if in_process else 'through FMI'}: {stop_time:g} s simulated, "
          f"{summary['wall_time_s']:.1f} s with initialisation, {summary['realtime_factor']:.2f}x real time; "
          f"stepping alone {sum(stepping):.1f} s, {steady:.2f}x", flush=True)
    return summary["realtime_factor"], steady


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--stop-time", type=float, default=20.0)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--fmi", action="store_true", help="also through FMI, alternating")
    args = parser.parse_args()
    fmus = REPO / "build" / "fmus_n1"
    build_all(fmus, BuildConfig(frame=1))
    modes = (True, False) if args.fmi else (True,)
    factors = {mode: [] for mode in modes}
    with tempfile.TemporaryDirectory() as folder:
        system = sample_by_sample_system(Path(folder), fmus)
        for _ in range(args.repeats):
            for in_process in modes:
                factors[in_process].append(run_once(system, args.stop_time, in_process, fmus))
    for in_process, pairs in factors.items():
        where = "in process" if in_process else "through FMI"
        for label, values in (("the run's", [p[0] for p in pairs]), ("stepping alone", [p[1] for p in pairs])):
            print(f"median real-time factor over {args.repeats} runs {where}, {label}: "
                  f"{statistics.median(values):.2f}x (min {min(values):.2f}, max {max(values):.2f})")


if __name__ == "__main__":
    main()
