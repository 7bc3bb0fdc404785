"""Digital cores (target: each digital core processes a 10 ms frame at 4 kHz in ≤ 100 µs
median).

* coder: DigitalCoderCore stepping one 40-sample frame, for a one-section line and for the
  default 8-section line, with the whole line free (the usual case: commands change rarely);
* receiver: DigitalReceiverCore on 40-sample frames of that coder's section-1 output at
  0.2 V, after acquisition (the benchmark checks the code was decoded);
* each: median over repeats of the mean time per frame over ``--frames`` frames.

    python benchmarks/bench_digital.py [--frames 2000] [--repeats 5]
"""
import argparse
import statistics
import time

import numpy as np

from bench_alsn import one_section_line
from fmus.signalling import cab_systems
from fmus.data.loader import load_line
from fmus.loco_receiver.digital_receiver import DigitalReceiverCore, DigitalReceiverSettings
from fmus.wayside_coder.core import CoderSettings
from fmus.wayside_coder.digital_generator import DigitalCoderCore

FS, N = 4000.0, 40


def coder_frame_us(system, line, frames: int) -> float:
    coder = DigitalCoderCore(system, line, len(line.sections), N, CoderSettings(fs_hz=FS))
    occupied = np.zeros(len(line.sections), dtype=bool)
    began = time.perf_counter()
    for k in range(frames):
        coder.step(k * N / FS, occupied)
    return (time.perf_counter() - began) / frames * 1e6


def receiver_frame_us(system, frames: int) -> float:
    coder = DigitalCoderCore(system, load_line(), 8, N, CoderSettings(fs_hz=FS, amplitude_v=1.0))
    warm_up = int(8 * system.message_s(system.carrier_hz) * FS / N)
    total = warm_up + frames
    signal = np.concatenate([coder.step(k * N / FS, np.zeros(8, bool)).u_tx[0] * 0.2 for k in range(total)])
    receiver = DigitalReceiverCore(system, N, DigitalReceiverSettings(fs_hz=FS))
    for k in range(warm_up):
        receiver.step(k * N / FS, signal[k * N:(k + 1) * N])
    began = time.perf_counter()
    for k in range(warm_up, total):
        receiver.step(k * N / FS, signal[k * N:(k + 1) * N])
    elapsed = (time.perf_counter() - began) / frames * 1e6
    assert receiver.out.code_valid, "the benchmark signal was not decoded"
    return elapsed


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    single, full = load_line(one_section_line()), load_line()
    for name, system in cab_systems.DIGITAL.items():
        results = {
            "coder, 1 section": [coder_frame_us(system, single, args.frames) for _ in range(args.repeats)],
            "coder, 8 sections": [coder_frame_us(system, full, args.frames) for _ in range(args.repeats)],
            "receiver": [receiver_frame_us(system, args.frames) for _ in range(args.repeats)],
        }
        for part, samples in results.items():
            print(f"{name:10s} {part:18s}: median {statistics.median(samples):6.1f} µs per 10 ms frame "
                  f"(min {min(samples):.1f}, max {max(samples):.1f}; {args.repeats} × {args.frames} frames)")


if __name__ == "__main__":
    main()
