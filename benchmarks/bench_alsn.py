"""ALSN cores (target: each core processes a 10 ms frame at 4 kHz in ≤ 50 µs median for one
section / receiver, vectorised over the frame).

* coder: WaysideCoderCore stepping one 40-sample frame, for a one-section line and for the
  default 8-section line (per-section cost = the 8-section time / 8);
* receiver: LocoReceiverCore on 40-sample frames of a З code at 0.4 V;
* both: median over repeats of the mean time per frame over 2000 frames (20 s of signal).

    python benchmarks/bench_alsn.py [--frames 2000] [--repeats 5]
"""
import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from fmus.data.loader import DATA, load_line
from fmus.loco_receiver.core import LocoReceiverCore, ReceiverSettings
from fmus.wayside_coder.core import CoderSettings, WaysideCoderCore

FS, N = 4000.0, 40


def one_section_line() -> Path:
    doc = json.loads((DATA / "default_line.json").read_text())
    doc["block_sections"] = doc["block_sections"][:1]
    path = Path(tempfile.mkdtemp()) / "one_section.json"
    path.write_text(json.dumps(doc))
    return path


def coder_frame_us(line, frames: int) -> float:
    coder = WaysideCoderCore(line, len(line.sections), N, CoderSettings())
    occupied = np.zeros(len(line.sections), dtype=bool)
    began = time.perf_counter()
    for k in range(frames):
        coder.step(k * N / FS, occupied)
    return (time.perf_counter() - began) / frames * 1e6


def receiver_frame_us(frames: int) -> float:
    coder = WaysideCoderCore(load_line(), 8, N, CoderSettings())
    signal = np.concatenate([coder.step(k * N / FS, np.zeros(8, bool)).u_tx[0] * 0.1 for k in range(frames)])
    receiver = LocoReceiverCore(N, ReceiverSettings())
    began = time.perf_counter()
    for k in range(frames):
        receiver.step(k * N / FS, signal[k * N:(k + 1) * N])
    elapsed = (time.perf_counter() - began) / frames * 1e6
    assert receiver.out.aspect == 4, "the benchmark signal was not decoded"
    return elapsed


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--frames", type=int, default=2000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    single, full = load_line(one_section_line()), load_line()
    results = {
        "coder, 1 section": [coder_frame_us(single, args.frames) for _ in range(args.repeats)],
        "coder, 8 sections": [coder_frame_us(full, args.frames) for _ in range(args.repeats)],
        "receiver": [receiver_frame_us(args.frames) for _ in range(args.repeats)],
    }
    for name, samples in results.items():
        print(f"{name:18s}: median {statistics.median(samples):6.1f} µs per 10 ms frame "
              f"(min {min(samples):.1f}, max {max(samples):.1f}; {args.repeats} × {args.frames} frames)")


if __name__ == "__main__":
    main()
