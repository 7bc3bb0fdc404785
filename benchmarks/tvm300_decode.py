"""TVM-300 receiver: decode time per code and the outcomes of none / two / an unused
sub-frequency; the figures of docs/loco_receiver.md#tvm-300 and docs/performance.md#tvm-300-receiver.

    python benchmarks/tvm300_decode.py [--quick]

1. every used code, coder core → the high-speed line's rail line at 12 kHz → receiver, a train
   standing 10 m into the 1700 Hz and the 2300 Hz section (where its code is weakest), every
   other section sending 300/300, at the line's ballast (its minimum, 1 and 1.5 Ω·km there) and
   at 50 Ω·km: each code for 2 s after a slot of the stop code (so every code is a change to a
   more permissive one, the slower case), on one running receiver: its decode time, and
   whether anything but the two codes was ever shown;
2. from the stop code shown, at 0.3 V with 0.05 V rms noise (synthesised, harness/tvm300_receiver.py):
   a bare carrier, two sub-frequencies at once (each at Δ, each at Δ/2), every unused one, one
   at Δ/2 — over ``--seeds`` phase seeds: any code other than the stop code shown (must be
   none), and the time to the restrictive display (stated latency: tvm300.STATED_LATENCY_S);
3. cold start, restrictive and permissive change, lost carrier (synthesised, 12 and 8 kHz);
4. cost: the receiver core's CPU time per simulated second, 12 kHz, frames of 40 and 120.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fmus.loco_receiver import tvm300 as rx  # noqa: E402
from fmus.loco_receiver.tvm300 import Tvm300ReceiverCore, Tvm300ReceiverSettings  # noqa: E402
from fmus.signalling import tvm300  # noqa: E402
from harness.tvm300_receiver import code, fm_carrier, rail_line_emf, run  # noqa: E402

TVM = tvm300.system()
GREEN, YELLOW, STOP = code(300, 300), code(220, 160), code(0, 0)
USED = sorted(tvm300.code_of_index(k) for k in TVM.table.pairs)
UNUSED = sorted(set(range(1, tvm300.SUB_FREQUENCY_COUNT + 1)) - set(USED))
EMF_V = 0.3


def every_code(section: int, ballast_ohm_km: float, slot_s: float = 2.0):
    """(decode time per code s, codes shown that were not the slot's or the one before, EMF peak V)."""
    from fmus.data.loader import load_line
    from harness.tvm_line import HSL_LINE

    line = load_line(HSL_LINE)
    sent = [c for used in USED if used != STOP for c in (STOP, used)]
    schedule = [(slot_s * k, [GREEN] * section + [c] + [GREEN] * (len(line.sections) - section - 1))
                for k, c in enumerate(sent)]
    emf = rail_line_emf(schedule, line.sections[section].start_m + 10.0, slot_s * len(sent), ballast_ohm_km=ballast_ohm_km)
    core = Tvm300ReceiverCore(120, Tvm300ReceiverSettings(fs_hz=12000.0))
    shown = np.array([core.step(first / 12000.0, emf[first:first + 120]).code for first in range(0, emf.size, 120)])
    frames = int(round(slot_s / 0.01))
    times, strangers = {}, 0
    for k, c in enumerate(sent):
        piece = shown[k * frames:(k + 1) * frames]
        allowed = {c, sent[k - 1]} if k else {c, 0}
        strangers += int(np.count_nonzero(~np.isin(piece, list(allowed))))
        if c != STOP:
            hits = np.flatnonzero(piece == c)
            times[c] = (hits[0] + 1) * 0.01 if hits.size else np.inf
    return times, strangers, float(np.abs(emf).max())


def no_code_outcomes(seeds: int):
    """Per case: (codes other than the stop code shown, worst time to no code s)."""
    cases = {"bare carrier": [(0, 1.0)], "two at Δ": [((GREEN, YELLOW), 1.0), ((STOP, code(80, 0)), 1.0)],
             "two at Δ/2": [((GREEN, YELLOW), 0.5)], "unused": [(u, 1.0) for u in UNUSED], "one at Δ/2": [(GREEN, 0.5)]}
    rows = {}
    for name, sent in cases.items():
        wrong, worst = 0, 0.0
        for codes, share in sent:
            for seed in range(seeds):
                plan = [(0.0, {1700.0: (STOP, EMF_V)}), (2.0, {1700.0: (codes, EMF_V, share)})]
                record, _ = run(plan, 2.0 + rx.STATED_LATENCY_S + 0.3, noise_v=0.05, seed=seed, phase_seed=seed)
                wrong += int(np.count_nonzero(~np.isin(record.code, [0, STOP])))
                lost = record.first(2.0, ~record.valid)
                worst = max(worst, np.inf if lost is None else lost)
        rows[name] = (wrong, worst)
    return rows


def decode_times(seeds: int, fs_hz: float):
    plan = [(0.0, {1700.0: (GREEN, EMF_V), 2300.0: (YELLOW, 0.1 * EMF_V)}), (3.0, {1700.0: (YELLOW, EMF_V)}),
            (6.0, {1700.0: (GREEN, EMF_V)}), (9.0, {})]
    rows = []
    for seed in range(seeds):
        record, _ = run(plan, 9.0 + rx.STATED_LATENCY_S + 0.3, fs_hz=fs_hz, noise_v=0.05, seed=seed, phase_seed=seed)
        rows.append((record.first(0.0, record.code == GREEN), record.first(3.0, record.code == YELLOW),
                     record.first(6.0, record.code == GREEN), record.first(9.0, ~record.valid)))
    return np.array(rows, dtype=float)


def cost(frame: int, seconds: float, fs_hz: float = 12000.0) -> float:
    t = np.arange(int(seconds * fs_hz)) / fs_hz
    e = fm_carrier(YELLOW, t, 1700.0, EMF_V) + np.random.default_rng(0).normal(0.0, 0.05, t.size)
    best = np.inf
    for _ in range(3):
        core = Tvm300ReceiverCore(frame, Tvm300ReceiverSettings(fs_hz=fs_hz))
        start = time.process_time()
        for first in range(0, t.size - frame + 1, frame):
            core.step(first / fs_hz, e[first:first + frame])
        best = min(best, time.process_time() - start)
    return best / seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--quick", action="store_true", help="2 seeds, 5 s cost runs")
    args = parser.parse_args()
    seeds = 2 if args.quick else args.seeds
    print(f"window {rx.WINDOW_S:.4f} s, hop {rx.HOP_S} s, hold {rx.HOLD_S:.3f} s, stated decode "
          f"{rx.STATED_DECODE_S:.3f} s, stated latency {rx.STATED_LATENCY_S:.3f} s")
    print("1. every used code after the stop code, coder → rail line → receiver, 12 kHz, 10 m into the section:")
    names = {c: "{:g}/{:g}".format(*TVM.table.pairs[tvm300.index_of_code(c)]) for c in USED}
    header = [names[c] for c in USED if c != STOP]
    print("| section, ballast | " + " | ".join(header) + " | other codes shown | EMF peak |")
    print("|---" * (len(header) + 3) + "|")
    for ballast in (0.0, 50.0):
        for section, name in ((0, "1700 Hz"), (1, "2300 Hz")):
            times, strangers, peak = every_code(section, ballast)
            where = f"{ballast:g} Ω·km" if ballast else "line minimum"
            print(f"| {name}, {where} | " + " | ".join(f"{times[c]:.2f}" for c in USED if c != STOP)
                  + f" | {strangers} | {peak:.3f} V |")
    print(f"2. from the stop code shown, 0.3 V, 0.05 V rms noise, {seeds} seeds:")
    print("| sent | frames showing a code other than the stop code | worst time to no code |")
    print("|---|---|---|")
    for name, (wrong, worst) in no_code_outcomes(seeds).items():
        print(f"| {name} | {wrong} | {worst:.2f} s |")
    print(f"3. synthesised, 0.3 V, 0.05 V rms noise, {seeds} seeds (min / max, s):")
    print("| fs | cold start | restrictive change | permissive change | lost carrier → restrictive |")
    print("|---|---|---|---|---|")
    for fs in (12000.0, 8000.0):
        times = decode_times(seeds, fs)
        print(f"| {fs / 1000:g} kHz | " + " | ".join(f"{np.min(c):.2f} / {np.max(c):.2f}" for c in times.T) + " |")
    print("4. receiver core cost, 12 kHz:")
    for frame in (40, 120):
        c = cost(frame, 5.0 if args.quick else 20.0)
        print(f"  frames of {frame}: {c * 1000:.1f} ms CPU per simulated second ({1 / c:.0f}× real time), "
              f"{c / (12000.0 / frame) * 1e6:.1f} µs per frame")


if __name__ == "__main__":
    main()
