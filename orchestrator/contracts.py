"""Interface contracts of an FMU: its manifest (``railcosim contract snapshot``) and the classified
differences between an FMU and a manifest (``railcosim contract check``); docs/contracts.md.

A manifest is the FMU-level interface (model identifier, default communication step, whether the
step may vary, frame size) plus every port as :func:`orchestrator.ports.manifest_of` reads it
(causality, variability, type, unit, min, max, start, description; an array collapsed with its
shape). The five roles' reference manifests are the shipped ``fmus/<role>/contract.json``
(orchestrator/conformance/roles.py finds them by role name; this module knows no railway).

A difference is *breaking* when a host or a system built against the manifest may stop working or
silently behave otherwise with the FMU; *compatible* when everything that worked still does.
"""
from __future__ import annotations

import json
import math
import zipfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Dict, List, Optional, Tuple

from orchestrator.errors import UserError
from orchestrator.ports import ports_of_description

MANIFEST_VERSION = 1
#: FMU-level fields of a manifest, and the fields of each port (``shape`` only for an array)
MODEL_FIELDS = ("model_identifier", "step_size_s", "variable_step", "frame", "ports")
PORT_FIELDS = ("causality", "variability", "type", "unit", "min", "max", "start", "description")
BREAKING, COMPATIBLE = "breaking", "compatible"


# ---- snapshot ---------------------------------------------------------------------------------
def snapshot(fmu_path: Path) -> dict:
    """The manifest of the FMU at ``fmu_path`` (an unreadable FMU: one UserError)."""
    from lxml import etree

    from orchestrator.fmu import read_interface

    fmu_path = Path(fmu_path)
    read_interface(fmu_path)           # not an FMU / invalid: one clear line
    with zipfile.ZipFile(fmu_path) as archive:
        return manifest_of_description(etree.fromstring(archive.read("modelDescription.xml")))


def manifest_of_description(root) -> dict:
    """The manifest of a modelDescription (its lxml root element): of a built FMU, or of the one
    a facade writes in process (orchestrator/packaging/declarations.py)."""
    from orchestrator.fmu import frame_ports_of

    co_simulation = root.find("CoSimulation")
    variable_step = co_simulation.get("canHandleVariableCommunicationStepSize", "false") in ("true", "1")
    experiment = root.find("DefaultExperiment")
    step = experiment.get("stepSize") if experiment is not None else None
    ports = ports_of_description(root)
    # a frame port's last index runs over the samples of one communication step
    frames = {ports[name]["shape"][-1] for name in frame_ports_of(root)
              if name in ports and ports[name].get("shape")}
    return {"manifest_version": MANIFEST_VERSION, "model_identifier": co_simulation.get("modelIdentifier"),
            "step_size_s": float(step) if step else None, "variable_step": variable_step,
            "frame": frames.pop() if len(frames) == 1 else None, "ports": ports}


def manifest_text(manifest: dict) -> str:
    """A manifest as its file holds it (the committed fmus/<unit>/contract.json are this text)."""
    return json.dumps(manifest, indent=1, sort_keys=True) + "\n"


def write_snapshot(fmu_path: Path, manifest_path: Path) -> dict:
    manifest = snapshot(fmu_path)
    try:
        Path(manifest_path).write_text(manifest_text(manifest))
    except OSError as error:
        raise UserError(f"{manifest_path}: cannot write the manifest: {error.strerror or error}") from None
    return manifest


# ---- reading a manifest -----------------------------------------------------------------------
def load_manifest(path: Path) -> dict:
    """A manifest file, checked for every field :func:`compare` reads; a defect is one UserError
    naming the file and the field."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise UserError(f"manifest {path}: cannot read it: {getattr(error, 'strerror', None) or error}") from None
    try:
        manifest = json.loads(text)
    except ValueError as error:
        raise UserError(f"manifest {path}: not JSON ({error})") from None
    if not isinstance(manifest, dict):
        raise UserError(f"manifest {path}: expected a JSON object with the fields {', '.join(MODEL_FIELDS)}")
    version = manifest.get("manifest_version", MANIFEST_VERSION)
    if version != MANIFEST_VERSION:
        raise UserError(f"manifest {path}: manifest_version {version!r}; this railcosim reads version {MANIFEST_VERSION}")
    missing = [key for key in MODEL_FIELDS if key not in manifest]
    if missing:
        raise UserError(f"manifest {path}: lacks the field(s) {', '.join(missing)} "
                        "(write one with `railcosim contract snapshot FMU -o FILE`)")
    if not isinstance(manifest["ports"], dict) or not manifest["ports"]:
        raise UserError(f"manifest {path}: field ports: expected an object of ports by name")
    for name, port in manifest["ports"].items():
        if not isinstance(port, dict):
            raise UserError(f"manifest {path}: ports.{name}: expected an object")
        lacking = [key for key in PORT_FIELDS if key not in port]
        if lacking:
            raise UserError(f"manifest {path}: ports.{name} lacks the field(s) {', '.join(lacking)}")
    return manifest


# ---- comparison -------------------------------------------------------------------------------
@dataclass(frozen=True)
class Difference:
    kind: str                   # breaking | compatible
    port: Optional[str]         # None: an FMU-level field
    field: Optional[str]        # None: the port as a whole (removed, added, renamed)
    manifest: object
    fmu: object
    message: str

    def line(self) -> str:
        return f"{self.kind.upper():10s} {self.message}"


def _number(text) -> Optional[float]:
    try:
        return None if text is None else float(text)
    except (TypeError, ValueError):
        return None


def _range_kind(causality: str, bound: str, old, new) -> str:
    """A port's min or max changed: breaking when a value the manifest allowed is refused now (a
    parameter or an input narrowed) or a value it ruled out may come now (an output widened)."""
    low, high = (-math.inf, math.inf)
    old_v, new_v = _number(old), _number(new)
    old_v = old_v if old_v is not None else (low if bound == "min" else high)
    new_v = new_v if new_v is not None else (low if bound == "min" else high)
    narrowed = new_v > old_v if bound == "min" else new_v < old_v
    if causality in ("parameter", "input"):
        return BREAKING if narrowed else COMPATIBLE
    return COMPATIBLE if narrowed else BREAKING


def _show(value) -> str:
    return "none" if value is None else json.dumps(value, ensure_ascii=False)


def _port_differences(name: str, old: dict, new: dict) -> List[Difference]:
    found = []
    causality = old.get("causality")
    for key in PORT_FIELDS + ("shape",):          # other keys of a hand-edited manifest: not compared
        a, b = old.get(key), new.get(key)
        if a == b or (key in ("min", "max", "start") and _number(a) is not None and _number(a) == _number(b)):
            continue                    # "10" and "10.0" are one value
        if key == "description":
            kind = COMPATIBLE
        elif key in ("min", "max"):
            kind = _range_kind(causality, key, a, b)
        elif key == "start":
            # what the model uses when the host does not set it; an output's start is only the
            # value before the first step
            kind = BREAKING if causality in ("parameter", "input") else COMPATIBLE
        elif key == "variability":
            # a fixed parameter that became tunable still takes every value set before the run
            kind = COMPATIBLE if (a, b) == ("fixed", "tunable") else BREAKING
        else:                   # causality, type, unit, shape (an array's elements are ports)
            kind = BREAKING
        found.append(Difference(kind, name, key, a, b, f"{name}: {key} {_show(a)} in the manifest, {_show(b)} in the FMU"))
    return found


def _signature(port: dict) -> tuple:
    return tuple(json.dumps(port.get(key)) for key in ("causality", "variability", "type", "unit", "shape"))


def compare(manifest: dict, current: dict) -> List[Difference]:
    """Every difference between a manifest and an FMU's snapshot, each classified."""
    found: List[Difference] = []
    old_id, new_id = manifest.get("model_identifier"), current.get("model_identifier")
    if old_id != new_id:
        # the interface a host couples is the ports; the identifier names the FMU's binary
        found.append(Difference(COMPATIBLE, None, "model_identifier", old_id, new_id,
                                f"model identifier {_show(old_id)} in the manifest, {_show(new_id)} in the FMU"))
    fixed_step = manifest.get("variable_step") is False or current.get("variable_step") is False
    old_var, new_var = manifest.get("variable_step"), current.get("variable_step")
    if old_var != new_var:
        kind = BREAKING if old_var and not new_var else COMPATIBLE
        found.append(Difference(kind, None, "variable_step", old_var, new_var,
                                f"variable communication step: {'allowed' if old_var else 'not allowed'} in the "
                                f"manifest, {'allowed' if new_var else 'not allowed'} in the FMU"))
    old_step, new_step = manifest.get("step_size_s"), current.get("step_size_s")
    if not _same_number(old_step, new_step):
        # a fixed-step FMU must be stepped at exactly its step; otherwise it is a default only
        kind = BREAKING if fixed_step else COMPATIBLE
        found.append(Difference(kind, None, "step_size_s", old_step, new_step,
                                f"default step {_show(old_step)} s in the manifest, {_show(new_step)} s in the FMU"
                                + (" (a fixed step: a host must use it)" if fixed_step else "")))
    old_frame, new_frame = manifest.get("frame"), current.get("frame")
    if old_frame != new_frame:
        found.append(Difference(BREAKING, None, "frame", old_frame, new_frame,
                                f"frame {_show(old_frame)} samples in the manifest, {_show(new_frame)} in the FMU"))

    old_ports, new_ports = manifest["ports"], current["ports"]
    removed = sorted(set(old_ports) - set(new_ports))
    added = sorted(set(new_ports) - set(old_ports))
    renamed: Dict[str, str] = {}
    for name in removed:        # a removed port with exactly one added look-alike: renamed
        alike = [other for other in added if _signature(new_ports[other]) == _signature(old_ports[name])]
        if len(alike) == 1 and sum(_signature(old_ports[r]) == _signature(old_ports[name]) for r in removed) == 1:
            renamed[name] = alike[0]
    for name in sorted(set(old_ports) | set(new_ports)):
        if name in renamed:
            found.append(Difference(BREAKING, name, None, name, renamed[name],
                                    f"{name}: renamed {renamed[name]} in the FMU (same causality, type, unit)"))
        elif name in removed:
            found.append(Difference(BREAKING, name, None, old_ports[name].get("causality"), None,
                                    f"{name}: removed ({old_ports[name].get('causality')} in the manifest, "
                                    "not in the FMU)"))
        elif name in added:
            if name in renamed.values():
                continue
            found.append(Difference(COMPATIBLE, name, None, None, new_ports[name].get("causality"),
                                    f"{name}: added ({new_ports[name].get('causality')} in the FMU, "
                                    "not in the manifest)"))
        else:
            found.extend(_port_differences(name, old_ports[name], new_ports[name]))
    return found


def _same_number(a, b) -> bool:
    if a is None or b is None:
        return a is b
    return math.isclose(float(a), float(b), rel_tol=1e-12, abs_tol=0.0)


@dataclass(frozen=True)
class CheckResult:
    fmu: str
    manifest: str
    differences: Tuple[Difference, ...]
    strict: bool

    @property
    def breaking(self) -> int:
        return sum(d.kind == BREAKING for d in self.differences)

    @property
    def compatible(self) -> int:
        return sum(d.kind == COMPATIBLE for d in self.differences)

    @property
    def passed(self) -> bool:
        return not self.differences if self.strict else self.breaking == 0

    def as_json(self) -> dict:
        return {"fmu": self.fmu, "manifest": self.manifest, "strict": self.strict, "passed": self.passed,
                "breaking": self.breaking, "compatible": self.compatible,
                "differences": [asdict(d) for d in self.differences]}

    def text(self) -> str:
        lines = [d.line() for d in self.differences]
        verdict = "passed" if self.passed else "FAILED"
        lines.append(f"{self.fmu} against {self.manifest}: {self.breaking} breaking, {self.compatible} compatible "
                     f"difference(s){' (--strict: any difference fails)' if self.strict else ''}: {verdict}")
        return "\n".join(lines)


def check(fmu_path: Path, manifest_path: Path, strict: bool = False, shown: Optional[str] = None) -> CheckResult:
    """The FMU against the manifest file; ``shown`` names the manifest in the report (a role)."""
    current = snapshot(Path(fmu_path))
    manifest = load_manifest(Path(manifest_path))
    return CheckResult(str(fmu_path), shown or str(manifest_path), tuple(compare(manifest, current)), strict)
