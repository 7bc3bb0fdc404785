"""TVM-430 wayside coder core: the cost of one 10 ms frame at the sample rates the TVM chain may
run at (8, 12, 16 kHz), for 8 sections and for 27 (a 40 km line of 1500 m blocks), the line
clear with one train in it (the word of every section fixed, as between block changes).

* Tvm430CoderCore stepping frames of fs/100 samples; median over repeats of the mean time per
  frame over ``--frames`` frames; the cost per section is the K-section time / K.

    python benchmarks/bench_tvm430_coder.py [--frames 1000] [--repeats 5]
"""
import argparse
import json
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np

from fmus.data.loader import load_line
from fmus.wayside_coder.core import CoderSettings
from fmus.wayside_coder.tvm430 import Tvm430CoderCore

FRAME_S = 0.01


def tvm_line(blocks: int) -> Path:
    sections = [{"name": f"B{b}", "start_m": 1500.0 * b, "end_m": 1500.0 * (b + 1), "signal": f"M{b}",
                 "transmitter": "UM71", "carrier_hz": (1700, 2300)[b % 2], "ballast_ohm_km": 2.0}
                for b in range(blocks)]
    doc = {"name": f"{blocks} TVM blocks", "length_m": 1500.0 * blocks, "electrification": {"system": "AC25000"},
           "block_sections": sections, "separation_zones": [{"position_m": 1500.0 * b} for b in range(1, blocks)], "stations": [{"name": "end", "stop_m": 1500.0 * blocks - 200.0}],
           "gradients": [{"start_m": 0, "permille": 0}], "curves": [],
           "speed_limits": [{"start_m": 0, "passenger_kmh": 160, "freight_kmh": 90, "high_speed_kmh": 300}]}
    path = Path(tempfile.mkdtemp()) / "tvm_line.json"
    path.write_text(json.dumps(doc))
    return path


def frame_us(line, fs_hz: float, frames: int) -> float:
    frame = round(fs_hz * FRAME_S)
    count = len(line.sections)
    coder = Tvm430CoderCore(line, count, frame, CoderSettings(fs_hz=fs_hz))
    occupied = np.zeros(count, dtype=bool)
    occupied[count // 2] = True
    coder.step(0.0, occupied)
    began = time.perf_counter()
    for k in range(1, frames + 1):
        coder.step(k * FRAME_S, occupied)
    return (time.perf_counter() - began) / frames * 1e6


def main():
    parser = argparse.ArgumentParser()
    parser.add_argument("--frames", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    results = {}
    for blocks in (8, 27):
        line = load_line(tvm_line(blocks))
        for fs_hz in (8000.0, 12000.0, 16000.0):
            median = statistics.median(frame_us(line, fs_hz, args.frames) for _ in range(args.repeats))
            results[f"{blocks}_sections_{fs_hz / 1000:g}kHz"] = {
                "frame_us": round(median, 1), "per_section_us": round(median / blocks, 2),
                "realtime_share": round(median * 1e-6 / FRAME_S, 4)}
    print(json.dumps({"benchmark": "tvm430_coder", "frame_s": FRAME_S, "frames": args.frames,
                      "repeats": args.repeats, "results": results}, indent=1))


if __name__ == "__main__":
    main()
