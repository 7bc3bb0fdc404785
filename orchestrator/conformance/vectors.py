"""A role's vector file (data/<role>.json, arrays in data/<role>.npz), read and checked: any
defect is one UserError naming the file and the field."""
from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional

import numpy as np

from orchestrator.conformance.judges import JUDGES
from orchestrator.errors import UserError
from orchestrator.ports import base_of

DATA_DIR = Path(__file__).resolve().parent / "data"
FORMAT = 1

#: fields every check kind needs (beyond kind and label)
_CHECK_FIELDS = {
    "latency": ("from_s", "until", "bound_s"), "holds": ("conditions", "bound_s"),
    "table": ("port", "at_s", "expected"), "near": ("port", "expected", "tolerance"),
    "extreme": ("port", "extreme"), "when": ("trigger", "port", "expected", "tolerance"),
    "code_timing": ("port", "pattern_s", "tolerance", "fs_hz", "carrier_hz", "cycle_s"),
    "frame_peak": ("port",),
    "tones": ("port", "fs_hz", "frequencies_hz", "present", "at_least", "at_most"),
    "fm_tones": ("port", "fs_hz", "carrier_hz", "frequencies_hz", "present", "at_least", "at_most"),
    "frequency_excursion": ("port", "fs_hz", "carrier_hz", "at_most"),
}


@dataclass
class RoleVectors:
    role: str
    path: Path
    required_ports: List[str]
    vectors: List[Dict[str, Any]]
    arrays_path: Optional[Path] = None
    _arrays: Dict[str, np.ndarray] = field(default_factory=dict)

    def array(self, spec: Mapping) -> np.ndarray:
        """An input's samples: the stored array × its ``scale`` (1)."""
        key = spec["array"]
        if key not in self._arrays:
            self._arrays[key] = self._load(key) * float(spec.get("scale", 1.0))
        return self._arrays[key]

    def _load(self, key: str) -> np.ndarray:
        try:
            with np.load(self.arrays_path) as archive:
                return np.asarray(archive[key], dtype=float)
        except KeyError:
            raise UserError(f"{self.arrays_path}: array {key!r} is missing (regenerate: "
                            "python -m orchestrator.conformance.generate)") from None
        except (OSError, ValueError, zipfile.BadZipFile, EOFError) as error:
            raise UserError(f"{self.arrays_path}: not a readable .npz archive ({error})") from None


def load_role(role: str, directory: Optional[Path] = None) -> RoleVectors:
    path = Path(directory or DATA_DIR) / f"{role}.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise UserError(f"{path}: vector file missing (python -m orchestrator.conformance.generate)") from None
    except (OSError, UnicodeDecodeError, ValueError) as error:
        raise UserError(f"{path}: not a valid JSON vector file ({' '.join(str(error).split())})") from None
    _require(isinstance(data, dict), path, "(top level)", "must be an object")
    _require(data.get("format") == FORMAT, path, "format", f"must be {FORMAT}")
    _require(data.get("role") == role, path, "role", f"must be {role!r}")
    ports = data.get("required_ports")
    _require(isinstance(ports, list) and all(isinstance(p, str) for p in ports), path, "required_ports",
             "must be a list of port names")
    vectors = data.get("vectors")
    _require(isinstance(vectors, list) and vectors, path, "vectors", "must be a non-empty list")
    arrays_path = None
    if data.get("arrays") is not None:
        arrays_path = path.parent / str(data["arrays"])
        _require(arrays_path.is_file(), path, "arrays", f"{arrays_path.name} not found beside it")
    for i, vector in enumerate(vectors):
        _check_vector(path, f"vectors[{i}]", vector, arrays_path is not None)
        _check_ports(path, f"vectors[{i}]", vector, ports)
    return RoleVectors(role, path, ports, vectors, arrays_path)


def _check_vector(path: Path, where: str, vector: Any, have_arrays: bool) -> None:
    _require(isinstance(vector, dict), path, where, "must be an object")
    for key in ("name", "duration_s", "step", "checks"):
        _require(key in vector, path, f"{where}.{key}", "missing")
    _require(isinstance(vector["name"], str), path, f"{where}.name", "must be a string")
    _require(_positive(vector["duration_s"]), path, f"{where}.duration_s", "must be a positive number")
    step = vector["step"]
    _require(isinstance(step, dict) and (_positive(step.get("fs_hz")) or _positive(step.get("step_s"))),
             path, f"{where}.step", "must give a positive fs_hz (frame-stepped) or step_s")
    for port, spec in vector.get("inputs", {}).items():
        at = f"{where}.inputs.{port}"
        _require(isinstance(spec, dict), path, at, "must be an object")
        if "array" in spec:
            _require(have_arrays, path, at, "names an array but the file names no arrays archive")
        else:
            times, values = spec.get("times_s"), spec.get("values")
            _require(isinstance(times, list) and isinstance(values, list) and len(times) == len(values) > 0,
                     path, at, "needs times_s and values of the same non-zero length")
    checks = vector["checks"]
    _require(isinstance(checks, list) and checks, path, f"{where}.checks", "must be a non-empty list")
    for j, check in enumerate(checks):
        at = f"{where}.checks[{j}]"
        _require(isinstance(check, dict) and check.get("kind") in JUDGES, path, f"{at}.kind",
                 f"must be one of {', '.join(JUDGES)}")
        for key in ("label", *_CHECK_FIELDS[check["kind"]]):
            _require(key in check, path, f"{at}.{key}", "missing")


def _check_ports(path: Path, where: str, vector: Mapping, required: List[str]) -> None:
    """Every port a vector uses is one of the role's required ports, so that a target lacking
    it is refused before anything runs."""
    from orchestrator.conformance.judges import FRAME_KINDS, ports_of

    used = [*vector.get("parameters", {}), *vector.get("inputs", {}), *vector.get("record_frames", [])]
    used += [p for check in vector["checks"] for p in ports_of(check) if not p.startswith("plant.")]
    used += [check["port"] for check in vector["checks"] if check["kind"] in FRAME_KINDS]
    missing = sorted({base_of(p) for p in used} - set(required))
    _require(not missing, path, f"{where}", f"uses ports not in required_ports: {', '.join(missing)}")


def _positive(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and value > 0


def _require(ok: bool, path: Path, field_name: str, problem: str) -> None:
    if not ok:
        raise UserError(f"{path}: field {field_name}: {problem}")
