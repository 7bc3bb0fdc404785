"""The coder cores' output the vectors of several roles are made of: the ALSN coder's sections
and code cycles, the occupancy that makes it send a code, its transmitter output as a coil EMF
(the receiver's input, the rail line's), and the TVM-430 test line and its sample rate (the
coder's vectors and the receiver's).
"""
from __future__ import annotations

import json
import tempfile
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from fmus.data.loader import DEFAULT_LINE, load_line
from fmus.signalling import alsn, cab_systems
from fmus.signalling import aspects as sig
from fmus.signalling.alsn import BENCH_COIL_COUPLING
from fmus.wayside_coder.core import CoderSettings, WaysideCoderCore
from fmus.wayside_coder.digital_generator import DigitalCoderCore
from orchestrator.conformance.generate.role_file import FRAME, FS_HZ

SECTION = {"KPT-5": 0, "KPT-7": 1}      # the bundled line's sections 1 and 2
#: cam cycle per transmitter type, from the code tables (docs/wayside_coder.md)
CYCLE_S = {kpt: table["cycle_s"] for kpt, table in
           json.loads(alsn.CODES_FILE.read_text(encoding="utf-8"))["transmitters"].items()}
CODE_TAG = {sig.GREEN: "Z", sig.YELLOW: "Zh", sig.RED_YELLOW: "KZh"}      # in vector names
CODE_NAME = {sig.GREEN: "З", sig.YELLOW: "Ж", sig.RED_YELLOW: "КЖ"}


def occupancy(code: int, section: int, sections: int = 8) -> np.ndarray:
    """Occupied sections that make the coder send ``code`` into ``section`` (3-aspect block)."""
    occupied = np.zeros(sections, dtype=bool)
    if code == sig.YELLOW:
        occupied[section + 2] = True
    elif code == sig.RED_YELLOW:
        occupied[section + 1] = True
    return occupied


def coder_emf(section: int, seconds: float, schedule: Callable[[float], np.ndarray], phase: float,
              level: float = BENCH_COIL_COUPLING) -> np.ndarray:
    """The coil EMF of one section's transmitter output × ``level``, frame by frame, every cam
    starting at ``phase`` of its cycle."""
    line = load_line(str(DEFAULT_LINE))
    coder = WaysideCoderCore(line, len(line.sections), FRAME, CoderSettings(fs_hz=FS_HZ, seed=1))
    coder.cam_offset_s[:] = phase * coder.cycle_s
    frames = []
    for k in range(int(round(seconds * FS_HZ / FRAME))):
        t = k * FRAME / FS_HZ
        frames.append(coder.step(t, schedule(t)).u_tx[section] * level)
    return np.concatenate(frames)


def coder_core(block_aspects: int = 3, system: Optional[str] = None):
    """The coder core of the bundled line (8 sections): ALSN, or the digital ``system``."""
    line = load_line(str(DEFAULT_LINE))
    settings = CoderSettings(fs_hz=FS_HZ, block_aspects=block_aspects, seed=1)
    if system is None:
        return WaysideCoderCore(line, 8, FRAME, settings)
    return DigitalCoderCore(cab_systems.digital_system(system), line, 8, FRAME, settings)


TVM_LINE_FILE = "wayside_coder_tvm430_line.json"
#: the 4 kHz of the other vectors cannot hold a 2300 Hz carrier. 8 kHz, not the TVM chain's 12
#: kHz: a sample is 125 µs, so a target's step N/fs is a whole number of nanoseconds for any
#: frame N (at 12 kHz only for N a multiple of 3, and the default N is 40); the receiver works
#: at any fs ≥ 5.1 kHz on track 1 (docs/loco_receiver.md#tvm-430)
TVM_FS_HZ = 8000.0


def tvm_line() -> dict:
    """8 blocks of 1500 m on track 1 (UM71 circuits, carriers 1700 / 2300 Hz alternating, a
    separation zone at every boundary), a 10 ‰ fall from 4 km, the station stop near the end:
    every TVM-430 speed pair within 8 sections."""
    blocks = [{"name": f"B{b + 1}", "start_m": 1500.0 * b, "end_m": 1500.0 * (b + 1), "signal": f"M{b + 1}",
               "transmitter": "UM71", "carrier_hz": (1700, 2300)[b % 2], "ballast_ohm_km": 2.0} for b in range(8)]
    return {"name": "TVM-430 coder vectors", "length_m": 12000.0, "electrification": {"system": "AC25000"},
            "block_sections": blocks, "separation_zones": [{"position_m": 1500.0 * b} for b in range(1, 8)],
            "stations": [{"name": "end", "stop_m": 11800.0}],
            "gradients": [{"start_m": 0, "permille": 0.0}, {"start_m": 4000, "permille": -10.0}], "curves": [],
            "speed_limits": [{"start_m": 0, "passenger_kmh": 160, "freight_kmh": 90, "high_speed_kmh": 300}]}


def tvm_line_loaded():
    """tvm_line() as the loader reads it."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / TVM_LINE_FILE
        path.write_text(json.dumps(tvm_line()), encoding="utf-8")
        return load_line(str(path))

