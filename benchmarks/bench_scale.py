"""How the rail line core's cost grows with the line (docs/performance.md#cost-against-the-size-of-the-line).

    python benchmarks/bench_scale.py [--frames 300] [--warm 200] [--repeats 3] [--tvm]

Synthetic lines of 20, 40 and 80 km cut into block sections of 1.25 km (16, 32 and 64
sections, the most a build allows: the default line's first section's circuit, carrier and
ballast repeated), with 1, 4, 8 and 16 trains spread evenly along the line, all moving (60 to
100 km/h, 600 A each) so that their wheelsets cross network nodes and sections during the
measurement, a keyed 50 Hz code in every section. For each (sections, trains): the median wall
time of a 10 ms frame (N = 40 at 4 kHz) over --frames frames after --warm frames that fill the
model caches, as the cost per simulated second (100 frames), the median of --repeats; and the
memory the core holds after the run (tracemalloc, a separate pass). Then the least-squares fit
of log cost = c + α·log sections + β·log trains, and the same for memory: α, β ≤ 1.1 is the
target (no term worse than linear).

``--tvm``: the same grid for TVM-430's chain, at its 12 kHz (10 ms frames of 120 samples):
jointless UM71 circuits of 1.25 km with tuned separation zones, carriers 1700 / 2300 Hz
alternating, a sine at each section's carrier (docs/rail_line.md#tvm-430-track-circuits).

The rail line is the component whose work depends on both; the coder's cost is per section,
the receiver's, traction's and the ATO's per train.
"""
from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))   # `python benchmarks/X.py` from anywhere

from fmus.data.loader import DEFAULT_LINE, load_line  # noqa: E402
from fmus.rail_line.core import RailLineCore, RailSettings  # noqa: E402

FS, N = 4000.0, 40
TVM_FS, TVM_N = 12000.0, 120
SECTION_M = 1250.0
LENGTHS_KM = (20, 40, 80)
TRAINS = (1, 4, 8, 16)


def synthetic_line(folder: Path, length_km: int, tvm: bool = False) -> Path:
    """The default line's data stretched to ``length_km``: sections of SECTION_M, joints at
    each boundary, level and straight, one limit, stations at both ends; ``tvm``: UM71 circuits
    at 1700 / 2300 Hz with a separation zone at each inner boundary instead of the joints."""
    base = json.loads(Path(DEFAULT_LINE).read_text())
    length_m = length_km * 1000.0
    count = round(length_m / SECTION_M)
    first = base["block_sections"][0]
    sections = [{**first, "name": str(k + 1), "signal": str(k + 1), "start_m": k * SECTION_M,
                 "end_m": (k + 1) * SECTION_M} for k in range(count)]
    joint = base["insulated_joints"][0]
    line = {**base, "name": f"synthetic {length_km} km", "length_m": length_m, "block_sections": sections,
            "insulated_joints": [{**joint, "position_m": k * SECTION_M} for k in range(count + 1)],
            "stations": [{"name": "A", "stop_m": 400, "platform_length_m": 400},
                         {"name": "Z", "stop_m": length_m - 400, "platform_length_m": 400}],
            "gradients": [{"start_m": 0, "permille": 0.0}], "curves": [],
            "speed_limits": [{"start_m": 0, "passenger_kmh": 120, "freight_kmh": 90}]}
    for key in ("temporary_restrictions",):
        line.pop(key, None)
    if tvm:
        for k, section in enumerate(sections):
            section.update(transmitter="UM71", carrier_hz=(1700, 2300)[k % 2])
        line.pop("insulated_joints")
        line["separation_zones"] = [{"position_m": k * SECTION_M} for k in range(1, count)]
    path = folder / f"line_{length_km}km{'_tvm' if tvm else ''}.json"
    path.write_text(json.dumps(line))
    return path


def drive(core: RailLineCore, frames: int, t0: float, length_m: float, record=None) -> None:
    trains, count = core.trains, core.count
    fs, n = core.settings.fs_hz, core.frame
    speeds = np.linspace(60.0, 100.0, trains) / 3.6
    start = (np.arange(trains) + 0.5) * length_m / trains * 0.9
    traction = np.full(trains, 600.0)
    samples = np.arange(n) / fs
    carriers = np.array([section.carrier_hz for section in core.line.sections], dtype=float)
    tvm = carriers.min() > 1000.0
    for k in range(frames):
        t = t0 + k * n / fs
        times = t + samples
        if tvm:                # each section's carrier, always on (it detects the trains)
            u = 4.0 * np.sin(2 * np.pi * np.outer(carriers, times))
        else:
            key = (np.sin(2 * np.pi * times / 1.6) > 0.3).astype(float)
            u = np.outer(np.full(count, 4.0), key * np.sin(2 * np.pi * 50 * times))
        x = np.minimum(start + speeds * np.floor(t / 0.5) * 0.5, length_m - 1.0)
        began = time.perf_counter()
        core.step(t, u, x, speeds, traction)
        if record is not None:
            record.append(time.perf_counter() - began)


def measure(line_path: Path, trains: int, frames: int, warm: int, repeats: int, tvm: bool = False):
    line = load_line(line_path)
    fs, n = (TVM_FS, TVM_N) if tvm else (FS, N)
    settings = RailSettings(fs_hz=fs, train_length_m=(120.0,) * trains)
    per_second = []
    for _ in range(repeats):
        core = RailLineCore(line, len(line.sections), trains, n, settings)
        drive(core, warm, 0.0, line.length_m)
        timed: list = []
        drive(core, frames, warm * n / fs, line.length_m, timed)
        per_second.append(statistics.median(timed) * fs / n)
    tracemalloc.start()
    core = RailLineCore(line, len(line.sections), trains, n, settings)
    drive(core, warm, 0.0, line.length_m)
    memory = tracemalloc.get_traced_memory()[0]
    tracemalloc.stop()
    del core
    return statistics.median(per_second), memory


def fit(sections, trains, values):
    """(c, α, β) of log value = c + α log sections + β log trains, least squares."""
    a = np.column_stack([np.ones(len(values)), np.log(sections), np.log(trains)])
    return np.linalg.lstsq(a, np.log(values), rcond=None)[0]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--warm", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--tvm", action="store_true", help="TVM-430's UM71 circuits at 12 kHz")
    args = parser.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for length_km in LENGTHS_KM:
            path = synthetic_line(Path(folder), length_km, args.tvm)
            sections = round(length_km * 1000 / SECTION_M)
            for trains in TRAINS:
                cost, memory = measure(path, trains, args.frames, args.warm, args.repeats, args.tvm)
                rows.append((sections, trains, cost, memory))
                print(f"{length_km} km, {sections} sections, {trains} trains: {cost * 1e3:.1f} ms per simulated "
                      f"second ({cost * 1e6 / 100:.0f} us per 10 ms frame), {memory / 1e6:.1f} MB", flush=True)
    sections, trains, costs, memories = (np.array(c, dtype=float) for c in zip(*rows))
    for what, values in (("cost per simulated second", costs), ("memory", memories)):
        _, alpha, beta = fit(sections, trains, values)
        print(f"{what}: exponent {alpha:.2f} in sections, {beta:.2f} in trains (log-log least squares)")


if __name__ == "__main__":
    main()
