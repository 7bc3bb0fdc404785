"""ATO controller (target: one ATO step ≤ 200 µs; the offline trajectory for the default
line ≤ 2 s).

* planning: constructing the AtoCore for the default line and timetable (both stages:
  minimum-time profile, the family of 24 programmes, the fitted energy-efficient one), median
  over repeats;
* one step: the ATO core driving the default timetable in closed loop with the traction core
  (0.5 s steps, cab signal green, ALSN supervision active); per-step times of the ATO alone,
  median and 99th percentile, for each strategy.

    python benchmarks/bench_ato.py [--repeats 5]
"""
import argparse
from pathlib import Path
import statistics
import time

import numpy as np

from fmus.ato_controller.core import AtoCore, AtoSettings
from fmus.signalling import aspects as sig
from fmus.data.loader import DEFAULT_TIMETABLE, load_line, load_rolling_stock, load_timetable
from fmus.traction.core import TractionCore


def planning_s() -> float:
    line, stock = load_line(), load_rolling_stock()
    timetable = load_timetable(DEFAULT_TIMETABLE, line)
    began = time.perf_counter()
    AtoCore(line, stock, timetable, DEFAULT_TIMETABLE, "passenger", AtoSettings())
    return time.perf_counter() - began


def step_times_us(strategy: str, stop_s: float = 1100.0, step_s: float = 0.5, freight: bool = False) -> np.ndarray:
    if freight:
        line, stock = load_line(FREIGHT["line"]), load_rolling_stock(FREIGHT["stock"])
        timetable_file = FREIGHT["timetable"]
    else:
        line, stock, timetable_file = load_line(), load_rolling_stock(), DEFAULT_TIMETABLE
    timetable = load_timetable(timetable_file, line)
    ato = AtoCore(line, stock, timetable, timetable_file, stock.category, AtoSettings(strategy=strategy))
    train = TractionCore(stock, line, x0_m=timetable[0].stop_m)
    state = train.out
    n = int(stop_s / step_s)
    times = np.empty(n)
    clock = time.perf_counter
    for k in range(n):
        t = k * step_s
        began = clock()
        out = ato.step(t, step_s, state.x_m, state.v_mps, sig.GREEN, True)
        times[k] = clock() - began
        state = train.step(t, step_s, out.command, out.emergency_brake)
    return times * 1e6


# the shipped freight_ac system's train: its slow pneumatic brake makes the ATO predict the
# stopping point on the final approach (docs/ato.md, precise stopping)
_FREIGHT_DIR = Path(__file__).resolve().parent.parent / "ssp" / "freight_ac" / "resources"
FREIGHT = {"line": _FREIGHT_DIR / "default_line_ac.json", "stock": _FREIGHT_DIR / "freight_vl80.json",
           "timetable": _FREIGHT_DIR / "freight_timetable.json"}


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    plans = [planning_s() for _ in range(args.repeats)]
    print(f"offline planning, default line (2 stages): median {statistics.median(plans):.3f} s "
          f"(min {min(plans):.3f}, max {max(plans):.3f}) over {args.repeats} runs")
    for strategy in ("programme", "predictive", "flat_out"):
        runs = [step_times_us(strategy) for _ in range(args.repeats)]
        medians = [float(np.median(r)) for r in runs]
        p99 = [float(np.percentile(r, 99)) for r in runs]
        print(f"ATO step, {strategy:10s}: median {statistics.median(medians):6.1f} µs, "
              f"p99 {statistics.median(p99):6.1f} µs, max {max(float(r.max()) for r in runs):7.1f} µs "
              f"({args.repeats} × {runs[0].size} steps)")
    runs = [step_times_us("programme", stop_s=1900.0, freight=True) for _ in range(args.repeats)]
    approach = [r[r > 200.0] for r in runs]
    print(f"ATO step, freight_ac train (programme, predictive stop): median "
          f"{statistics.median(float(np.median(r)) for r in runs):6.1f} µs, p99 "
          f"{statistics.median(float(np.percentile(r, 99)) for r in runs):6.1f} µs, max "
          f"{max(float(r.max()) for r in runs):7.1f} µs; steps above 200 µs per run: "
          f"{statistics.median(a.size for a in approach):.0f} of {runs[0].size}, their median "
          f"{statistics.median(float(np.median(a)) if a.size else 0.0 for a in approach):6.1f} µs")


if __name__ == "__main__":
    main()
