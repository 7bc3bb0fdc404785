"""The conformance runner: a role's vectors (vectors.py) against a target (target.py), step by
step as a host would (docs/interfaces.md, "Time and frames": a signal unit steps N/fs, sample n
of the frame from doStep(t, h) is the value at t + (n−1)·h/N), each vector on a fresh instance
(its ports through port_io.py, an ATO's closed loop through plant.py); the recorded trace goes
to the judges (judges.py), their verdicts into a report (report.py)."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from orchestrator.conformance import ROLES
from orchestrator.conformance.judges import Trace, Verdict, judge, ports_of
from orchestrator.conformance.plant import ReferenceTrain
from orchestrator.conformance.port_io import PortIO
from orchestrator.conformance.report import RoleReport
from orchestrator.conformance.target import Target, open_target
from orchestrator.conformance.vectors import RoleVectors, load_role
from orchestrator.errors import SimulationError, UserError, did_you_mean

PLANT_PREFIX = "plant."


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
    plant = ReferenceTrain(vector["plant"]) if "plant" in vector else None
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
        io = PortIO(target, slave, [n for names in in_names.values() for n in names],
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
        raise UserError(f"--role {role_name!r}: not a role{did_you_mean(role_name, ROLES)} (roles: {', '.join(ROLES)})")
    role = load_role(role_name, vectors_dir)
    target = open_target(target_name, role_name, role.required_ports)
    try:
        verdicts = [v for vector in role.vectors for v in run_vector(target, role, vector)]
    finally:
        target.close()
    return RoleReport(role_name, target_name, target.interface.model_identifier, verdicts)


