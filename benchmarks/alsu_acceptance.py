"""ALSU acceptance measurements on the bench (coder → rail line → receiver cores,
harness/alsu.py); the figures of docs/loco_receiver.md#alsu.

    python benchmarks/alsu_acceptance.py [--phases 8] [--quick]

1. every one of the 15 codes at the minimum (1 Ω·km) and maximum (50 Ω·km) ballast, the coils
   over the weakest place (10 m into a 2.6 km section): the pair identified, the code shown
   (reserved ones: no code);
2. none, one, three (and six) tones: never a code shown, the display at no code;
3. every change between two codes the wayside sends (12 × 11) over ``--phases`` tone-phase
   seeds and change instants: time to the new code (or anything more restrictive, for a
   restrictive change) on the display, worst case per kind;
4. a loss of every tone: time to the no-code indication;
5. a train running through the joints at 40, 80 and 160 km/h under DC traction (2000 A, coil
   pair 5 % mismatched: the joints paper's 5 V pulses) and AC traction (300 A, its 14 V 50 Hz
   bursts and 150/250/350 Hz harmonics), with no code sent and with code 1 sent: never a code
   other than the one sent.
"""
from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from harness.alsu import AlsuBench, first_time, sendable_codes, tones_after_code  # noqa: E402
from fmus.data.loader import DATA, load_line  # noqa: E402
from fmus.loco_receiver.alsu import DISPLAY_HOLD_S  # noqa: E402
from fmus.signalling import alsu  # noqa: E402


def all_codes(ballast: float):
    """(code, pair identified after s, shown after s, shown at the end) per code."""
    bench = AlsuBench(ballast_ohm_km=ballast)
    rows = []
    for code in range(1, alsu.CODE_COUNT + 1):
        bench.send_code(code)
        start = bench.t
        record = bench.run(2.5).arrays()
        pair = first_time(bench.record, start, record["pair"] == code)
        shown = first_time(bench.record, start, (record["shown"] == code) & record["valid"])
        rows.append((code, pair, shown, int(record["shown"][-1])))
    return rows


def tone_counts():
    """(tones, flags, time to the no-code indication, any other code shown, a code shown again
    after the no-code indication) for sets of 0, 1, 3 and 6 tones, each after code 9 shown."""
    rows = []
    for flags in ([0] * 6, [1, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, 1], [1, 1, 1, 0, 0, 0], [0, 0, 1, 1, 1, 0],
                  [1, 0, 1, 0, 1, 0], [1] * 6):
        outcome = tones_after_code(flags, code=9, settle_s=3.0, watch_s=4.0)
        rows.append((sum(flags), "".join(str(f) for f in flags), outcome.lost_s, outcome.other_code,
                     outcome.shown_again))
    return rows


def latencies(phases: int):
    """Worst time to the new code per kind of change (restrictive: the new code or more
    restrictive shown; permissive: the new code shown), over every change and phase."""
    system = alsu.system()
    codes = sendable_codes()
    worst = {"restrictive": (0.0, None), "permissive": (0.0, None)}
    counted = 0
    for seed in range(1, phases + 1):
        bench = AlsuBench(seed=seed)
        rng = np.random.default_rng(seed)
        for old, new in itertools.permutations(codes, 2):
            bench.send_code(old)
            bench.run(2.0 + float(rng.uniform(0.0, 0.05)), keep=False)     # the change at a random instant
            bench.record = type(bench.record)()
            bench.send_code(new)
            start = bench.t
            record = bench.run(2.5).arrays()
            restrictive = system.rank(new) < system.rank(old)
            if restrictive:
                done = record["valid"] & np.array([system.rank(c) <= system.rank(new) if c else False
                                                   for c in record["shown"]]) | ~record["valid"]
            else:
                done = record["valid"] & (record["shown"] == new)
            took = first_time(bench.record, start, done)
            took = np.inf if took is None else took + 0.0
            kind = "restrictive" if restrictive else "permissive"
            if took > worst[kind][0]:
                worst[kind] = (took, (old, new, seed))
            counted += 1
    return worst, counted


def loss():
    bench = AlsuBench()
    bench.send_code(6)
    bench.run(3.0)
    bench.send_code(0)
    start = bench.t
    record = bench.run(3.0).arrays()
    return first_time(bench.record, start, ~record["valid"])


def joints(code: int):
    """(line, speed km/h, joints crossed, codes shown other than the one sent) per case."""
    rows = []
    for name, traction_a in (("default_line.json", 2000.0), ("default_line_ac.json", 300.0)):
        line = load_line(DATA / name)
        for speed_kmh in (40.0, 80.0, 160.0):
            speed = speed_kmh / 3.6
            # from 60 m before the joint at 5200 m to 70 m past it, and 2 s more
            head = 5200.0 - 60.0
            seconds = 130.0 / speed + 2.0
            bench = AlsuBench(line=line, head_m=head, speed_mps=speed, traction_a=traction_a, coil_mismatch=0.05)
            bench.send_code(code)
            record = bench.run(seconds).arrays()
            crossed = sum(1 for j in line.joints if head + 1.5 < j["position_m"] < bench.head_at(bench.t) + 1.5)
            wrong = sorted(set(int(c) for c, v in zip(record["shown"], record["valid"]) if v and c != code))
            rows.append((name, speed_kmh, crossed, wrong, float(np.max(np.abs(bench.rail.out.e_coil[0])))))
    return rows


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--phases", type=int, default=8, help="tone-phase seeds per code change")
    parser.add_argument("--quick", action="store_true", help="two phases, fewer cases (a smoke run)")
    args = parser.parse_args(argv)
    started = time.time()
    print("1. every code, coils 10 m into a 2.6 km section (pair identified / shown after, s)")
    for ballast in (1.0, 50.0):
        rows = all_codes(ballast)
        cells = [f"{code}: {pair:.2f}/{'-' if shown is None else f'{shown:.2f}'}" for code, pair, shown, _ in rows]
        identified = sum(pair is not None for _, pair, _, _ in rows)
        print(f"  {ballast:g} Ω·km: {identified}/15 identified; " + ", ".join(cells))
    print("2. tones other than two, after code 9 (time to the no-code indication; another code shown)")
    for count, flags, lost, other, again in tone_counts():
        print(f"  {count} tones {flags}: no code after {'-' if lost is None else f'{lost:.2f} s'}; "
              f"another code shown: {'yes' if other or again else 'no'}")
    worst, counted = latencies(2 if args.quick else args.phases)
    print(f"3. code changes: {counted} (12 × 11 × phases); worst time to the display")
    for kind, (took, case) in worst.items():
        print(f"  {kind}: {took:.2f} s ({case[0]} → {case[1]}, phase seed {case[2]})")
    print(f"4. loss of every tone: no code after {loss():.2f} s (hold {DISPLAY_HOLD_S:g} s)")
    for code in (0, 1):
        print(f"5. joints, {'no code' if code == 0 else f'code {code}'} sent, coil pair 5 % mismatched")
        for name, speed, crossed, wrong, emf in joints(code):
            print(f"  {name} {speed:g} km/h: {crossed} joints, other codes shown: {wrong or 'none'}")
    print(f"({time.time() - started:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
