"""One communication step of the traction core (target: ≤ 100 µs at 1 s steps).

Runs the passenger train (ЧС7 + 14 coaches) over the default line under a fixed command
schedule (full traction, coast, service brake to a stop, restart) with 1 s steps, in process,
and reports the median time per step over repeats; also the FMU stepped through fmpy.

    python benchmarks/bench_traction.py [--steps 1500] [--repeats 5]
"""
import argparse
import statistics
import time

from fmus.data.loader import load_line, load_rolling_stock
from fmus.traction.core import TractionCore


def schedule(t: float) -> float:
    phase = t % 500.0
    return 1.0 if phase < 180.0 else (0.0 if phase < 260.0 else (-0.5 if phase < 420.0 else 1.0))


def core_step_us(steps: int) -> float:
    core = TractionCore(load_rolling_stock(), load_line(), x0_m=400.0)
    began = time.perf_counter()
    for k in range(steps):
        core.step(float(k), 1.0, schedule(float(k)))
    return (time.perf_counter() - began) / steps * 1e6


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    samples = [core_step_us(args.steps) for _ in range(args.repeats)]
    print(f"traction core, 1 s communication step (0.5 s RK4 sub-steps): median {statistics.median(samples):.1f} µs "
          f"over {args.repeats} × {args.steps} steps (min {min(samples):.1f}, max {max(samples):.1f})")


if __name__ == "__main__":
    main()
