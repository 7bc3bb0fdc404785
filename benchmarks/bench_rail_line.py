"""Rail line core (target: K = 8 sections, M = 2 trains, one 10 ms frame at 4 kHz in ≤ 300 µs
median).

Two trains on the default line, both moving (160 and 80 km/h, 600 A and 300 A traction), each
shunting at every network node it covers, a keyed 50 Hz code in every section; the first train crosses joints during the run. Reports the
median per-frame time over repeats (each: 2000 frames = 20 s after a 2 s warm-up that fills the
model caches), and the per-frame time of the first, cold pass (model generation included).

    python benchmarks/bench_rail_line.py [--frames 2000] [--repeats 5]
"""
import argparse
import statistics
import time

import numpy as np

from fmus.data.loader import load_line
from fmus.rail_line.core import RailLineCore, RailSettings

FS, N = 4000.0, 40


def run(core, frames, t0, record):
    speeds = np.array([160 / 3.6, 80 / 3.6])
    start = np.array([1500.0, 6000.0])
    traction = np.array([600.0, 300.0])
    samples = np.arange(N) / FS
    for k in range(frames):
        t = t0 + k * N / FS
        times = t + samples
        key = (np.sin(2 * np.pi * times / 1.6) > 0.3).astype(float)
        u = np.outer(np.full(8, 4.0), key * np.sin(2 * np.pi * 50 * times))
        x = start + speeds * np.floor(t / 0.5) * 0.5
        began = time.perf_counter()
        core.step(t, u, x, speeds, traction)
        record.append(time.perf_counter() - began)


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    medians = []
    cold = []
    for _ in range(args.repeats):
        core = RailLineCore(load_line(), 8, 2, N, RailSettings())
        warm = []
        run(core, 200, 0.0, warm)
        cold.append(float(np.mean(warm)) * 1e6)
        timed = []
        run(core, args.frames, 2.0, timed)
        medians.append(float(np.median(timed)) * 1e6)
    print(f"rail line K=8 M=2, 10 ms frame: median {statistics.median(medians):.1f} µs "
          f"(min {min(medians):.1f}, max {max(medians):.1f}; {args.repeats} × {args.frames} frames); "
          f"first 2 s incl. model generation: mean {statistics.median(cold):.0f} µs per frame")


if __name__ == "__main__":
    main()
