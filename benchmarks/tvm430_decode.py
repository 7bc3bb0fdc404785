"""TVM-430 receiver: decode time and cost (harness/tvm430_receiver.py: carriers synthesised from
fmus/signalling/tvm430.py's modulation, white noise; no rail line); the figures of
docs/loco_receiver.md#tvm-430 and docs/performance.md#tvm-430-receiver.

    python benchmarks/tvm430_decode.py [--seeds 16] [--quick]

1. decode time: a word change at the coils (green 300/300 → 230/170 restrictive, then back,
   permissive) → the new word on the display, over ``--seeds`` tone-phase seeds (the coder's
   tone phases at the change instant; tvm430's tones repeat every 12.5 s) at 12 and 8 kHz, with no
   noise and with 0.1 V rms white noise on a 0.3 V carrier (6.5 dB per sample, 24 dB in the
   100 Hz baseband), a neighbour's carrier 20 dB down; also a cold start (nothing shown → the
   word) and a lost carrier (→ the restrictive display);
2. margins against white noise: a 0.3 V carrier with 0.05 … 0.3 V rms noise at 12 kHz, 30 s:
   the share of decisions that read the word, valid words other than the one sent (must be 0),
   the smallest fitted amplitude of a present tone and the largest of an absent one (units of
   the deviation per tone; decided above 0.65, below 0.35);
3. every used field value, coder core → the high-speed line's rail line at 12 kHz → receiver
   (each of the speed pairs, 29 distance codes and 16 gradients once, 2.5 s each, on one
   running receiver),
   a train standing 10 m into a 1700 Hz and a 2300 Hz section (where its code is weakest), the
   neighbour sections sending a more permissive word, at the line's ballast (its minimum, 1 and
   1.5 Ω·km there) and at 50 Ω·km (the line's maximum): each word shown by the end of its slot,
   nothing else ever shown, and the slowest decode;
4. cost: the receiver core's CPU time per simulated second at 8 and 12 kHz, frames of 40
   samples (the build's default) and at 12 kHz frames of 120 (the TVM chain's 10 ms), the
   signal synthesised beforehand (best of 3 runs of 20 s).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fmus.loco_receiver import tvm430 as rx  # noqa: E402
from fmus.loco_receiver.tvm430 import Tvm430ReceiverCore, Tvm430ReceiverSettings  # noqa: E402
from fmus.signalling import tvm430  # noqa: E402
from harness.tvm430_receiver import TONE_PERIOD_S, fm_carrier, run, word  # noqa: E402

GREEN = word(300, 300)
YELLOW = word(230, 170, 2750.0, -6.0)
EMF_V, LEAK = 0.3, 0.1
NOISE_V = (0.0, 0.1)


def decode_times(seeds: int, noise_v: float, fs_hz: float = 12000.0):
    """Per seed: (cold start, restrictive change, permissive change, lost carrier) in s."""
    plan = [(0.0, {1700.0: (GREEN, EMF_V), 2300.0: (YELLOW, LEAK * EMF_V)}),
            (5.0, {1700.0: (YELLOW, EMF_V), 2300.0: (GREEN, LEAK * EMF_V)}),
            (10.0, {1700.0: (GREEN, EMF_V), 2300.0: (YELLOW, LEAK * EMF_V)}),
            (15.0, {2300.0: (YELLOW, LEAK * EMF_V)})]
    rows = []
    for seed in range(seeds):
        offset = seed * TONE_PERIOD_S / seeds
        record, _ = run(plan, 20.0, fs_hz=fs_hz, noise_v=noise_v, seed=seed, tone_offset_s=offset)
        wrong = set(record.code.tolist()) - {0, GREEN, YELLOW}
        if wrong or (record.word_carrier_hz == 2300.0).any():
            raise SystemExit(f"seed {seed}, noise {noise_v} V: a word not sent, or the neighbour's, was shown")
        rows.append((record.first(0.0, record.code == GREEN), record.first(5.0, record.code == YELLOW),
                     record.first(10.0, record.code == GREEN), record.first(15.0, ~record.valid)))
    return np.array(rows, dtype=float)


def noise_margins(noise_v: float, seconds: float = 30.0, fs_hz: float = 12000.0, frame: int = 600):
    """(share of decisions reading the word, other valid words read, smallest present tone,
    largest absent tone) for YELLOW at EMF_V in white noise."""
    core = Tvm430ReceiverCore(frame, Tvm430ReceiverSettings(fs_hz=fs_hz))
    rng = np.random.default_rng(1)
    bits = tvm430.bits_of(YELLOW).astype(bool)
    seen, right, other, present, absent = None, 0, 0, np.inf, 0.0
    decisions = 0
    for first in range(0, int(seconds * fs_hz), frame):
        t = (first + np.arange(frame)) / fs_hz
        core.step(first / fs_hz, fm_carrier(YELLOW, t, 1700.0, EMF_V) + rng.normal(0.0, noise_v, frame))
        decision = core.last_decision
        if decision is None or decision is seen:
            continue
        seen, decisions = decision, decisions + 1
        right += decision.word == YELLOW
        other += decision.word not in (0, YELLOW)
        if decision.amplitudes is not None:
            present = min(present, float(decision.amplitudes[bits].min()))
            absent = max(absent, float(decision.amplitudes[~bits].max()))
    return right / decisions, other, present, absent


def every_field_value(section: int, ballast_ohm_km: float = 0.0, slot_s: float = 2.5):
    """(words sent, shown by the end of their slot, words shown that were not sent, slowest
    decode s, the coil EMF's peak V) for every used field value on ``section`` of the line, at
    the line's ballast (0: its sections' own, their minimum) or ``ballast_ohm_km``."""
    from fmus.data.loader import load_line
    from harness.tvm_line import HSL_LINE
    from harness.tvm430_receiver import rail_line_emf

    tvm = tvm430.system()
    table = tvm.table
    address = table.addresses[0]
    middle_gradient = table.gradient_code(0.0)
    sent = [tvm430.assemble(address, code, table.distance_codes - 1 if pair == (300.0, 300.0) else 8, middle_gradient)
            for code, pair in table.speed_codes.items()]
    sent += [tvm430.assemble(address, table.speed_code(230.0, 170.0), d, middle_gradient) for d in range(table.distance_codes)]
    sent += [tvm430.assemble(address, table.speed_code(230.0, 170.0), 8, g) for g in range(16)]
    line = load_line(HSL_LINE)
    schedule = []
    for k, w in enumerate(sent):
        words = [GREEN] * len(line.sections)
        words[section] = w
        schedule.append((k * slot_s, words))
    seconds = len(sent) * slot_s
    emf = rail_line_emf(schedule, line.sections[section].start_m + 10.0, seconds, ballast_ohm_km=ballast_ohm_km)
    core = Tvm430ReceiverCore(120, Tvm430ReceiverSettings(fs_hz=12000.0))
    shown = []
    for first in range(0, emf.size, 120):
        shown.append(core.step(first / 12000.0, emf[first:first + 120]).code)
    shown = np.array(shown)
    frames_per_slot = int(round(slot_s / 0.01))
    at_end = [shown[(k + 1) * frames_per_slot - 1] == w for k, w in enumerate(sent)]
    slowest = max(float(np.flatnonzero(shown[k * frames_per_slot:(k + 1) * frames_per_slot] == w)[0] + 1) * 0.01
                  if (shown[k * frames_per_slot:(k + 1) * frames_per_slot] == w).any() else np.inf
                  for k, w in enumerate(sent))
    strangers = set(shown.tolist()) - set(sent) - {0}
    return len(sent), sum(at_end), len(strangers), slowest, float(np.abs(emf).max())


def cost_per_simulated_second(fs_hz: float, seconds: float = 20.0, frame: int = 40) -> float:
    """CPU seconds of the core per simulated second (best of 3)."""
    t = np.arange(int(seconds * fs_hz)) / fs_hz
    e = fm_carrier(YELLOW, t, 1700.0, EMF_V) + fm_carrier(GREEN, t, 2300.0, LEAK * EMF_V) \
        + np.random.default_rng(0).normal(0.0, 0.05, t.size)
    best = np.inf
    for _ in range(3):
        core = Tvm430ReceiverCore(frame, Tvm430ReceiverSettings(fs_hz=fs_hz))
        start = time.process_time()
        for first in range(0, t.size - frame + 1, frame):
            core.step(first / fs_hz, e[first:first + frame])
        best = min(best, time.process_time() - start)
        assert core.out.code == YELLOW
    return best / seconds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=16)
    parser.add_argument("--quick", action="store_true", help="4 seeds, 5 s cost runs")
    args = parser.parse_args()
    seeds = 4 if args.quick else args.seeds
    print(f"window {rx.WINDOW_S:.4f} s, hop {rx.HOP_S} s, hold {rx.HOLD_S} s, "
          f"stated latency {rx.STATED_LATENCY_S:.3f} s")
    print(f"decode time, {seeds} tone-phase seeds (min / median / max, s):")
    print("| fs | noise V rms | cold start | restrictive change | permissive change | lost carrier → restrictive |")
    print("|---|---|---|---|---|---|")
    for fs in (12000.0, 8000.0):
        for noise in NOISE_V:
            times = decode_times(seeds, noise, fs)
            cells = [f"{np.min(c):.2f} / {np.median(c):.2f} / {np.max(c):.2f}" for c in times.T]
            print(f"| {fs / 1000:g} kHz | {noise:g} | " + " | ".join(cells) + " |")
    print("margins against white noise, 0.3 V carrier, 12 kHz:")
    print("| noise V rms | SNR per sample | decisions reading the word | other words read | smallest present | "
          "largest absent |")
    print("|---|---|---|---|---|---|")
    for noise in (0.05, 0.1, 0.2, 0.3):
        share, other, present, absent = noise_margins(noise, seconds=10.0 if args.quick else 30.0)
        snr_db = 10 * np.log10(EMF_V ** 2 / 2 / noise ** 2)
        print(f"| {noise:g} | {snr_db:.1f} dB | {100 * share:.0f} % | {other} | {present:.2f} | {absent:.2f} |")
    print("every used field value, coder → rail line → receiver, 12 kHz, 10 m into the section:")
    for ballast in (0.0, 50.0):
        for section, name in ((0, "1700 Hz"), (1, "2300 Hz")):
            count, shown, strangers, slowest, peak = every_field_value(section, ballast)
            where = f"{ballast:g} Ω·km" if ballast else "the line's ballast (1-1.5 Ω·km)"
            print(f"  {name}, {where}: {shown}/{count} words shown, {strangers} words shown that were not "
                  f"sent, slowest {slowest:.2f} s, EMF peak {peak:.3f} V")
    print("receiver core cost:")
    for fs, frame in ((8000.0, 40), (12000.0, 40), (12000.0, 120)):
        cost = cost_per_simulated_second(fs, seconds=5.0 if args.quick else 20.0, frame=frame)
        print(f"  {fs / 1000:g} kHz, frames of {frame}: {cost * 1000:.1f} ms CPU per simulated second "
              f"({1 / cost:.0f}× real time), {cost / (fs / frame) * 1e6:.1f} µs per frame")


if __name__ == "__main__":
    main()
