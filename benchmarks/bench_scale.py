"""How the rail line core's cost grows with the line (docs/performance.md#cost-against-the-size-of-the-line).

    python benchmarks/bench_scale.py [--frames 300] [--warm 200] [--repeats 3] [--tvm] [--fmi]

Synthetic lines of 20, 40 and 80 km cut into block sections of 1.25 km (16, 32 and 64
sections, the most a build allows: the default line's first section's circuit, carrier and
ballast repeated), with 1, 4, 8 and 16 trains (the bundled passenger train, 388 m and its
wheelsets) spread evenly along the line, all moving (60 to
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

``--fmi``: also the RailLine FMU of a build of each grid point's own sizes (`railcosim build
--sections S --trains T`, into build/bench_scale), driven through FMI as `railcosim run`
drives it (orchestrator/fmu.py's FmuSlave: the frame's inputs written, fmi2DoStep, the
outputs read), the same synthetic lines and trains: the cost per simulated second with the
FMI calls and the copies of the u_tx and e_coil frames, and its own fit.

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

from fmus.data.loader import DEFAULT_LINE, DEFAULT_ROLLING_STOCK, load_line, load_rolling_stock  # noqa: E402
from fmus.rail_line.core import RailLineCore, RailSettings  # noqa: E402

REPO = Path(__file__).resolve().parent.parent

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


def train_length_m() -> float:
    """The bundled default train's length (its wheelsets, in process and in the FMU alike)."""
    return load_rolling_stock(DEFAULT_ROLLING_STOCK).length_m


def train_starts_m(trains: int, length_m: float) -> np.ndarray:
    return (np.arange(trains) + 0.5) * length_m / trains * 0.9


def drive(core: RailLineCore, frames: int, t0: float, length_m: float, record=None) -> None:
    drive_step(core.step, core.trains, core.count, core.settings.fs_hz, core.frame,
               [section.carrier_hz for section in core.line.sections], frames, t0, length_m, record)


def drive_step(step, trains: int, count: int, fs: float, n: int, carriers_hz, frames: int, t0: float,
               length_m: float, record=None) -> None:
    """``frames`` frames of ``step(t, u, x, v, i_traction)`` from t0: the trains moving, each
    section's code; each call's wall time appended to ``record``."""
    speeds = np.linspace(60.0, 100.0, trains) / 3.6
    start = train_starts_m(trains, length_m)
    traction = np.full(trains, 600.0)
    samples = np.arange(n) / fs
    carriers = np.array(carriers_hz, dtype=float)
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
        step(t, u, x, speeds, traction)
        if record is not None:
            record.append(time.perf_counter() - began)


def measure(line_path: Path, trains: int, frames: int, warm: int, repeats: int, tvm: bool = False):
    line = load_line(line_path)
    fs, n = (TVM_FS, TVM_N) if tvm else (FS, N)
    settings = RailSettings(fs_hz=fs, train_length_m=(train_length_m(),) * trains)
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


class FmiRailLine:
    """The RailLine FMU of a build of (sections, trains), stepped frame by frame through FMI as
    `railcosim run` steps it (its ports bound by name as `railcosim conform` binds them)."""

    PORTS_IN, PORTS_OUT = ("u_tx", "x_head", "v", "i_traction"), ("e_coil", "occupied")

    def __init__(self, fmus: Path, line_path: Path, length_m: float, trains: int, fs: float, n: int):
        from orchestrator.conformance.port_io import PortIO
        from orchestrator.conformance.target import open_target

        self.target = open_target(str(fmus / "RailLine.fmu"), "rail line", list(self.PORTS_IN + self.PORTS_OUT))
        self.slave = self.target.make_slave("rail")
        self.slave.instantiate()
        self.elements = {port: self.target.elements(port) for port in self.PORTS_IN + self.PORTS_OUT}
        self.io = PortIO(self.target, self.slave, [n for p in self.PORTS_IN for n in self.elements[p]],
                         [n for p in self.PORTS_OUT for n in self.elements[p]])
        self.slave.setup_experiment(0.0, None)
        values = {"line_file": str(line_path), "fs": fs}
        values.update({f"train_length[{j + 1}]": train_length_m() for j in range(trains)})
        values.update({f"x_head[{j + 1}]": x for j, x in enumerate(train_starts_m(trains, length_m))})
        self.slave.set_values(values)
        self.slave.enter_initialization()
        self.slave.exit_initialization()
        self.step_s = n / fs                 # one frame of n samples, the build's

    def step(self, t, u, x, v, i_traction) -> None:
        for port, values in zip(self.PORTS_IN, (u, x, v, i_traction)):
            self.io.set(self.elements[port], values)
        self.slave.write_inputs()
        self.slave.do_step(t, self.step_s)
        self.slave.read_outputs()

    def close(self) -> None:
        self.slave.terminate()
        self.slave.free()
        self.target.close()


def measure_fmi(line_path: Path, sections: int, trains: int, frames: int, warm: int, repeats: int,
                tvm: bool = False) -> float:
    """The median cost per simulated second through FMI, in a build of these very sizes."""
    from fmus.sizes import BuildConfig
    from orchestrator.packaging.builder import build_all

    fs, n = (TVM_FS, TVM_N) if tvm else (FS, N)
    fmus = REPO / "build" / "bench_scale" / BuildConfig(sections, trains, n).folder_name
    build_all(fmus, BuildConfig(sections, trains, n))
    line = load_line(line_path)
    carriers = [section.carrier_hz for section in line.sections]
    per_second = []
    for _ in range(repeats):
        rail = FmiRailLine(fmus, line_path, line.length_m, trains, fs, n)
        try:
            drive_step(rail.step, trains, sections, fs, n, carriers, warm, 0.0, line.length_m)
            timed: list = []
            drive_step(rail.step, trains, sections, fs, n, carriers, frames, warm * n / fs, line.length_m, timed)
        finally:
            rail.close()
        per_second.append(statistics.median(timed) * fs / n)
    return statistics.median(per_second)


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
    parser.add_argument("--fmi", action="store_true", help="also the RailLine FMU through FMI, a build per size")
    args = parser.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for length_km in LENGTHS_KM:
            path = synthetic_line(Path(folder), length_km, args.tvm)
            sections = round(length_km * 1000 / SECTION_M)
            for trains in TRAINS:
                cost, memory = measure(path, trains, args.frames, args.warm, args.repeats, args.tvm)
                fmi = measure_fmi(path, sections, trains, args.frames, args.warm, args.repeats, args.tvm) \
                    if args.fmi else float("nan")
                rows.append((sections, trains, cost, memory, fmi))
                print(f"{length_km} km, {sections} sections, {trains} trains: {cost * 1e3:.1f} ms per simulated "
                      f"second ({cost * 1e6 / 100:.0f} us per 10 ms frame), {memory / 1e6:.1f} MB"
                      + (f"; through FMI {fmi * 1e3:.1f} ms per simulated second" if args.fmi else ""), flush=True)
    sections, trains, costs, memories, fmis = (np.array(c, dtype=float) for c in zip(*rows))
    fits = [("cost per simulated second", costs), ("memory", memories)]
    if args.fmi:
        fits.append(("cost per simulated second through FMI", fmis))
    for what, values in fits:
        _, alpha, beta = fit(sections, trains, values)
        print(f"{what}: exponent {alpha:.2f} in sections, {beta:.2f} in trains (log-log least squares)")


if __name__ == "__main__":
    main()
