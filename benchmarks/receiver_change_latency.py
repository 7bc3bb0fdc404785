"""How long the ALSN receiver takes to show a restrictive change (З → Ж, Ж → КЖ), over cam
phases × noise seeds (docs/loco_receiver.md, "Latency of a change"), on the cores without FMI
(harness/latency.py):

* **within a circuit** — the code of the circuit under the coils turns more restrictive (the
  block ahead becomes occupied), KPT-5 and KPT-7: the coder core into the receiver core at
  0.4 V; ``phase`` is where the cam stands in its cycle at the change;
* **at a joint** — the coils cross from one circuit into the next, whose code is more
  restrictive (a train stands two circuits ahead of the one past the joint: З → Ж; one: Ж → КЖ),
  KPT-7 → KPT-5 and KPT-5 → KPT-7: coder → rail line → receiver cores, 80 km/h, 1000 A of traction current;
  the receiver is overloaded by the strong feed end before the joint and recovers after it;
  ``phase`` / ``old phase``: where the cams of the circuit past / behind the joint stand when
  the coils cross it.

Each seed draws the white noise (10 dB over the whole band against the weak code, 0.28 V at a
joint, 0.4 V within a circuit) and, at a joint, the rails' asymmetry. Prints one Markdown row per
case: min, median, p90, max and the worst point, against the stated latency. The latency falls
as the phase grows and jumps up by about one cycle where a cycle is lost: the greatest value
lies up to one phase step before the grid's worst point, so that step is searched again at
``--refine`` phases (every seed and old phase): "max refined".

    python benchmarks/receiver_change_latency.py [--phases 24] [--old-phases 3] [--seeds 6] [--refine 12]
                                                 [--jobs 1] [--cases TEXT]
"""
import argparse
import itertools
import sys
import time
from contextlib import nullcontext
from multiprocessing import Pool

import numpy as np

from harness import latency as lat
from harness.channel import white_noise_and_hum
from fmus.signalling import aspects as sig
from fmus.signalling.alsn import STATED_LATENCY_S

WITHIN = ("KPT-5", "KPT-7")
CHANGES = ((sig.GREEN, sig.YELLOW), (sig.YELLOW, sig.RED_YELLOW))
CODE_NAMES = {sig.GREEN: "З", sig.YELLOW: "Ж", sig.RED_YELLOW: "КЖ"}


def _within(point):
    (kpt, change), phase, _, seed = point
    noise = white_noise_and_hum(lat.NOISE_SNR_DB, 4.0 * lat.BENCH_COIL_COUPLING, {}, seed)
    return lat.change_s(kpt, *change, phase, disturb=noise)


def _joint(point):
    (case, change), phase, old_phase, seed = point
    return lat.joint_change_s(case, phase, old_phase, seed, change=change)


def grid(phases: int, old_phases: int, seeds: int):
    """(case name, function, points) per case; a point is ((where, change), phase, old phase, seed)."""
    phase_grid = np.arange(phases) / phases
    old_grid = np.arange(old_phases) / old_phases
    seed_grid = range(1, seeds + 1)
    cases = []
    for change in CHANGES:
        what = " → ".join(CODE_NAMES[code] for code in change)
        cases += [(f"{what} within a circuit, {kpt}", _within,
                   [((kpt, change), p, 0.0, s) for p, s in itertools.product(phase_grid, seed_grid)]) for kpt in WITHIN]
        cases += [(f"{what} at a joint, {case}", _joint,
                   [((case, change), p, q, s) for p, q, s in itertools.product(phase_grid, old_grid, seed_grid)])
                  for case in lat.JOINT_CASES]
    return cases


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--phases", type=int, default=24, help="cam phases over one cycle (default 24)")
    parser.add_argument("--old-phases", type=int, default=3, help="phases of the cam behind a joint (default 3)")
    parser.add_argument("--seeds", type=int, default=6, help="noise seeds 1..N (default 6)")
    parser.add_argument("--refine", type=int, default=12, help="phases searched again before the worst point (default 12)")
    parser.add_argument("--jobs", type=int, default=1, help="worker processes (default 1)")
    parser.add_argument("--cases", default="", help="only the cases whose name contains TEXT (e.g. 'З → Ж at a joint')")
    args = parser.parse_args()
    print(f"stated latency {STATED_LATENCY_S:.2f} s; {args.phases} phases × {args.seeds} seeds "
          f"(× {args.old_phases} phases of the cam behind a joint)\n")
    print("| change | runs | min s | median s | p90 s | max s | above the stated latency | worst at (phase, old phase, seed) | max refined s |")
    print("|---|---|---|---|---|---|---|---|---|")
    with (Pool(args.jobs) if args.jobs > 1 else nullcontext()) as pool:
        measure = (lambda f, points: np.array(pool.map(f, points, chunksize=4))) if pool else \
            (lambda f, points: np.array(list(map(f, points))))
        for name, function, points in grid(args.phases, args.old_phases, args.seeds):
            if args.cases not in name:
                continue
            started = time.perf_counter()
            took = measure(function, points)
            worst = points[int(np.argmax(took))]
            step = 1.0 / args.phases
            old_phases = sorted({point[2] for point in points})
            before = [(worst[0], (worst[1] - step * k / args.refine) % 1.0, old_phase, seed)
                      for k in range(1, args.refine) for old_phase in old_phases for seed in range(1, args.seeds + 1)]
            refined = max(took.max(), measure(function, before).max()) if before else took.max()
            print(f"| {name} | {took.size} | {took.min():.2f} | {np.median(took):.2f} | {np.percentile(took, 90):.2f} "
                  f"| {took.max():.2f} | {int(np.sum(took > STATED_LATENCY_S))} | ({worst[1]:.3f}, {worst[2]:.3f}, {worst[3]}) "
                  f"| {refined:.2f} |", flush=True)
            print(f"{name}: {time.perf_counter() - started:.0f} s", file=sys.stderr, flush=True)


if __name__ == "__main__":
    main()
