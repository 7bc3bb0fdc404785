"""One role's vector file as it is being written (:class:`RoleFile`), and the pieces every
vector is made of: the generator's sample rate and frame, conditions on ports, inputs given as a
schedule.
"""
from __future__ import annotations

import io
import json
import zipfile
from pathlib import Path
from typing import Dict, List, Optional

import numpy as np

from fmus.signalling import aspects as sig
from fmus.sizes import DEFAULT_SAMPLE_RATE_HZ
from orchestrator.conformance.vectors import FORMAT

FS_HZ = DEFAULT_SAMPLE_RATE_HZ
FRAME = 40                  # the generator's own frame; the runner steps with the target's
GENERATOR = "python -m orchestrator.conformance.generate"


class RoleFile:
    """One role's vectors and arrays as they are being written."""

    def __init__(self, role: str, required_ports: List[str]):
        self.role, self.required_ports = role, required_ports
        self.vectors: List[dict] = []
        self.arrays: Dict[str, np.ndarray] = {}
        self.data_files: Dict[str, object] = {}        # file name → JSON document written beside

    def samples(self, vector: str, port: str, values: np.ndarray) -> dict:
        """An input stream stored as int16 counts × scale (the scale keeps 15 bits of its peak)."""
        peak = float(np.max(np.abs(values))) or 1.0
        scale = peak / 32000.0
        key = f"{vector}.{port}"
        self.arrays[key] = np.round(values / scale).astype(np.int16)
        return {"array": key, "scale": scale}

    def write(self, directory: Path) -> List[Path]:
        directory.mkdir(parents=True, exist_ok=True)
        data = {"format": FORMAT, "role": self.role, "generator": GENERATOR,
                "required_ports": self.required_ports,
                "arrays": f"{self.role}.npz" if self.arrays else None, "vectors": self.vectors}
        path = directory / f"{self.role}.json"
        path.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
        written = [path]
        for file_name, document in sorted(self.data_files.items()):
            data_path = directory / file_name
            data_path.write_text(json.dumps(document, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
            written.append(data_path)
        if self.arrays:
            npz = directory / f"{self.role}.npz"
            # fixed member timestamps: the same vectors give the same bytes
            _save_npz(npz, self.arrays)
            written.append(npz)
        return written



def _save_npz(path: Path, arrays: Dict[str, np.ndarray]) -> None:
    """The arrays as an .npz whose members carry a fixed timestamp: the same vectors give the
    same bytes."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        for key in sorted(arrays):
            buffer = io.BytesIO()
            np.lib.format.write_array(buffer, arrays[key], allow_pickle=False)
            info = zipfile.ZipInfo(f"{key}.npy", date_time=(2020, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            archive.writestr(info, buffer.getvalue())


def cond(port: str, values) -> dict:
    """A condition: ``port`` takes one of ``values``."""
    return {"port": port, "in": [int(v) for v in values]}


def in_range(port: str, lo: Optional[float], hi: Optional[float]) -> dict:
    """A condition: ``port`` within [lo, hi] (None: unbounded)."""
    return {"port": port, "range": [lo, hi]}


def schedule_input(times: List[float], values: List) -> dict:
    """An input that takes ``values[k]`` from ``times[k]`` on."""
    return {"times_s": times, "values": values}


def not_more_permissive(code: int) -> List[int]:
    """Aspects a receiver may show while ``code`` is sent: the code or anything more restrictive."""
    return [a for a in (sig.WHITE, sig.RED, sig.RED_YELLOW, sig.YELLOW, sig.GREEN)
            if sig.restrictiveness(a) <= sig.restrictiveness(code)]
