"""The conformance runner: a role's vectors against a target, step by step as a host would
(docs/interfaces.md, "Time and frames": a signal unit steps N/fs, sample n of the frame from
doStep(t, h) is the value at t + (n−1)·h/N), each vector on a fresh instance; then the judges
(judges.py) and a table or JSON of the verdicts."""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from fmus.signalling.aspects import GREEN
from orchestrator.conformance import ROLES
from orchestrator.conformance.judges import Trace, Verdict, judge, ports_of
from orchestrator.conformance.target import Target, open_target
from orchestrator.conformance.vectors import RoleVectors, load_role
from orchestrator.errors import SimulationError, UserError

PLANT_PREFIX = "plant."


@dataclass
class RoleReport:
    role: str
    target: str
    model_identifier: str
    verdicts: List[Verdict]

    @property
    def passed(self) -> bool:
        return all(v.passed for v in self.verdicts)

    def failed_vectors(self) -> List[str]:
        return sorted({v.vector for v in self.verdicts if not v.passed})


class _PortIO:
    """Named inputs and outputs of one slave through its preallocated buffers."""

    def __init__(self, target: Target, slave, inputs: Sequence[str], outputs: Sequence[str]):
        variables = target.interface.variables
        self.slave = slave
        tables: Tuple[Dict[str, List[int]], Dict[str, List[int]]] = ({}, {})
        self.slot: Dict[str, Tuple[bool, str, int]] = {}
        self._positions: Dict[tuple, Tuple[str, np.ndarray]] = {}
        for is_input, names in ((True, inputs), (False, outputs)):
            table = tables[0 if is_input else 1]
            for name in dict.fromkeys(names):
                var = variables[name]
                vrs = table.setdefault(var.type, [])
                self.slot[name] = (is_input, var.type, len(vrs))
                vrs.append(var.vr)
        slave.bind(*tables)
        # an element a vector leaves alone keeps its start value (it is written with the rest)
        for name in dict.fromkeys(inputs):
            start = variables[name].start
            if start is not None:
                self.set([name], [_start_value(variables[name].type, start)])

    def set(self, names: Sequence[str], values) -> None:
        buffers = self.slave.inputs
        type_name, positions = self._where(names)
        buffers[type_name].values[positions] = np.ravel(values)

    def get(self, names: Sequence[str]) -> np.ndarray:
        type_name, positions = self._where(names)
        return np.asarray(self.slave.outputs[type_name].values[positions], dtype=float)

    def _where(self, names: Sequence[str]):
        """(FMI type, buffer positions) of a port's elements (all of one type), found once."""
        key = tuple(names)
        found = self._positions.get(key)
        if found is None:
            slots = [self.slot[n] for n in names]
            found = self._positions[key] = (slots[0][1], np.array([slot[2] for slot in slots], dtype=np.intp))
        return found


def _start_value(type_name: str, start) -> float:
    if type_name == "Boolean":
        return float(str(start).lower() in ("true", "1"))
    return float(start)


class _TractionPlant:
    """The reference train an ATO drives in a closed loop: our traction core (fmus/traction)
    with the bundled rolling stock and line, stepped after the ATO with its command
    (Gauss-Seidel, as the shipped systems couple them)."""

    def __init__(self, spec: Mapping):
        from fmus.data.loader import DEFAULT_LINE, DEFAULT_ROLLING_STOCK, load_line, load_rolling_stock
        from fmus.traction.core import TractionCore

        line = load_line(str(DEFAULT_LINE))
        self.core = TractionCore(load_rolling_stock(str(DEFAULT_ROLLING_STOCK)), line, x0_m=spec["x0_m"])
        self.zones = [tuple(z) for z in spec.get("cab_zones", ())]
        self.clear_s = spec.get("cab_clear_s", math.inf)
        self.state = self.core.out

    def cab(self, t: float) -> Tuple[int, bool]:
        if t < self.clear_s:
            for start, end, aspect in self.zones:
                if start <= self.state.x_m < end:
                    return int(aspect), True
        return GREEN, True

    def values(self) -> Dict[str, float]:
        return {"plant.x": self.state.x_m, "plant.v": self.state.v_mps, "plant.a": self.state.a_mps2}


def _schedule_value(spec: Mapping, t: float):
    times = spec["times_s"]
    k = max(0, int(np.searchsorted(np.asarray(times), t + 1e-9, side="right")) - 1)
    return spec["values"][k]


def run_vector(target: Target, role: RoleVectors, vector: Mapping) -> List[Verdict]:
    name = vector["name"]
    frames = vector.get("record_frames", [])
    wanted = sorted({p for check in vector["checks"] for p in ports_of(check)})
    recorded = [p for p in wanted if not p.startswith(PLANT_PREFIX)]
    out_names = {port: target.elements(port) for port in recorded}
    frame_names = {row: target.elements(row) for row in frames}
    plant = _TractionPlant(vector["plant"]) if "plant" in vector else None
    in_names = {port: target.elements(port) for port in vector.get("inputs", {})}
    if plant is not None:
        for port in ("x", "v", "aspect", "code_valid"):
            in_names[port] = target.elements(port)
        for port in ("command", "emergency_brake"):
            out_names.setdefault(port, target.elements(port))
    frame_inputs = {port: spec for port, spec in vector.get("inputs", {}).items() if "array" in spec}
    if "fs_hz" in vector["step"]:
        frame = _frame_size(target, role, [p for p in [vector["step"].get("frame_port")] if p], frame_inputs, frames)
        step_s = frame / vector["step"]["fs_hz"]
    else:
        frame, step_s = 0, vector["step"]["step_s"]
    steps = int(math.floor(vector["duration_s"] / step_s + 1e-9))

    slave = target.make_slave(name)
    rows: Dict[str, list] = {port: [] for port in [*out_names, *(plant.values() if plant else ())]}
    frame_rows: Dict[str, list] = {row: [] for row in frames}
    times: List[float] = []
    failure: Optional[str] = None
    try:
        slave.instantiate()
        io = _PortIO(target, slave, [n for names in in_names.values() for n in names],
                     [n for names in [*out_names.values(), *frame_names.values()] for n in names])
        slave.setup_experiment(0.0, None)
        slave.set_values(_parameter_values(target, role, vector.get("parameters", {})))
        slave.enter_initialization()
        slave.exit_initialization()
        arrays = {port: role.array(spec) for port, spec in frame_inputs.items()}
        shapes = {port: target.shape(port) for port in arrays}
        for k in range(steps):
            t = k * step_s
            for port, spec in vector.get("inputs", {}).items():
                if port in arrays:
                    io.set(in_names[port], _frame_slice(arrays[port], k, frame, shapes[port]))
                else:
                    value = _schedule_value(spec, t)
                    io.set(in_names[port][:len(np.ravel(value))], value)
            if plant is not None:
                aspect, valid = plant.cab(t)
                io.set(in_names["x"], [plant.state.x_m])
                io.set(in_names["v"], [plant.state.v_mps])
                io.set(in_names["aspect"], [aspect])
                io.set(in_names["code_valid"], [valid])
            slave.write_inputs()
            slave.do_step(t, step_s)
            slave.read_outputs()
            if plant is not None:
                command = io.get(out_names["command"])[0]
                brake = bool(io.get(out_names["emergency_brake"])[0])
                plant.state = plant.core.step(t, step_s, float(command), brake)
                for port, value in plant.values().items():
                    rows[port].append([value])
            for port, names in out_names.items():
                rows[port].append(io.get(names))
            for row, names in frame_names.items():
                frame_rows[row].append(io.get(names))
            times.append(t + step_s)
        slave.terminate()
    except SimulationError as error:
        failure = str(error)
    finally:
        slave.free()
    if failure is not None:
        return [Verdict(name, "the target accepts the parameters and completes every step", math.nan,
                        "no failure", "", False,
                        " ".join(failure.split()))]
    trace = Trace(np.asarray(times), {port: np.asarray(r, dtype=float) for port, r in rows.items()})
    if frames:
        trace.samples = {row: np.concatenate(r) for row, r in frame_rows.items()}
        trace.sample_time_s = (np.arange(steps * frame) / vector["step"]["fs_hz"])
    return [judge(name, trace, check) for check in vector["checks"]]


def _frame_size(target: Target, role: RoleVectors, vector_frame_port: Sequence[str], frame_inputs: Mapping,
                frames: Sequence[str]) -> int:
    """N of the target's frame ports (the last index of the step's ``frame_port``, an input's
    or a recorded row's elements)."""
    for port in [*vector_frame_port, *frame_inputs, *frames]:
        shape = target.shape(port)
        if shape:
            return shape[-1]
    raise UserError(f"{role.path}: a frame-stepped vector names no frame port")


def _frame_slice(samples: np.ndarray, k: int, frame: int, shape: Tuple[int, ...]) -> np.ndarray:
    """Frame k of a sample stream, laid out as the port's elements (rows beyond the vector's
    are silent)."""
    if samples.ndim == 1:
        return samples[k * frame:(k + 1) * frame]
    out = np.zeros(shape)
    rows = min(shape[0], samples.shape[0])
    out[:rows] = samples[:rows, k * frame:(k + 1) * frame]
    return out


def _parameter_values(target: Target, role: RoleVectors, parameters: Mapping) -> Dict[str, object]:
    """Parameters by variable name; a relative ``*_file`` names a data file beside the vector
    file (as a system's resources/ folder does for a run, docs/interfaces.md, Data files)."""
    values: Dict[str, object] = {}
    for name, value in parameters.items():
        if name.endswith("_file") and isinstance(value, str) and value and not Path(value).is_absolute():
            beside = role.path.parent / value
            if not beside.is_file():
                raise UserError(f"{role.path}: parameter {name}: data file {value} not found beside it")
            values[name] = str(beside.resolve())
        elif isinstance(value, list):
            values.update(zip(target.elements(name), value))
        else:
            values[name] = value
    return values


def conform(role_name: str, target_name: str, vectors_dir=None) -> RoleReport:
    """Every vector of ``role_name`` against ``target_name``."""
    if role_name not in ROLES:
        raise UserError(f"--role {role_name!r}: not a role (roles: {', '.join(ROLES)})")
    role = load_role(role_name, vectors_dir)
    target = open_target(target_name, role_name, role.required_ports)
    try:
        verdicts = [v for vector in role.vectors for v in run_vector(target, role, vector)]
    finally:
        target.close()
    return RoleReport(role_name, target_name, target.interface.model_identifier, verdicts)


def format_table(report: RoleReport) -> str:
    header = ("vector", "check", "measured", "bound", "result")
    rows = []
    for v in report.verdicts:
        measured = "never" if v.measured == math.inf else ("—" if math.isnan(v.measured) else f"{v.measured:.4g}")
        rows.append((v.vector, v.check, f"{measured} {v.unit}".strip(), f"{v.bound} {v.unit}".strip(),
                     "pass" if v.passed else "FAIL"))
    widths = [max(len(r[i]) for r in [header, *rows]) for i in range(len(header))]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(row, widths)).rstrip() for row in [header, *rows]]
    lines.insert(1, "  ".join("-" * w for w in widths))
    for v in report.verdicts:
        if not v.passed and v.note:
            lines.append(f"{v.vector}: {v.note}")
    failed = report.failed_vectors()
    total = len({v.vector for v in report.verdicts})
    lines.append(f"{report.role} on {report.target} ({report.model_identifier}): "
                 + (f"all {total} vectors pass" if not failed else
                    f"{len(failed)} of {total} vectors fail: {', '.join(failed)}"))
    return "\n".join(lines)


def format_json(report: RoleReport) -> str:
    return json.dumps({"role": report.role, "target": report.target, "model_identifier": report.model_identifier,
                       "passed": report.passed, "failed_vectors": report.failed_vectors(),
                       "checks": [v.as_dict() for v in report.verdicts]}, indent=1, ensure_ascii=False)
