"""The rail_line role's vectors (data/rail_line.json, .npz): the first axle's current against
the two-port cascade and our plant, the track relays' three modes, the null zone at a joint
(docs/rail_line.md#validation).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from fmus.data.loader import DEFAULT_LINE, load_line
from fmus.rail_line.track_circuit import cascade_shunt_current
from orchestrator.conformance.generate.coder_signals import CYCLE_S, coder_core
from orchestrator.conformance.generate.role_file import FRAME, FS_HZ, RoleFile, schedule_input


OFF_LINE_M = -1000.0


def _coder_stream(seconds: float) -> np.ndarray:
    """The coder core's output for a free line (З into every section), K × samples."""
    coder = coder_core()
    frames = [coder.step(k * FRAME / FS_HZ, np.zeros(8, dtype=bool)).u_tx.copy()
              for k in range(int(round(seconds * FS_HZ / FRAME)))]
    return np.concatenate(frames, axis=1)


def _rail_run(u_tx: np.ndarray, schedule: Callable[[float], tuple]):
    """Our rail-line core fed as the runner feeds a target: per frame (t_end, i_axle[1],
    occupied[1..8]) and train 1's coil EMF samples; ``schedule(t)`` → (x_head, v, broken_rail_at)."""
    from fmus.rail_line.core import RailLineCore, RailSettings

    core = RailLineCore(load_line(str(DEFAULT_LINE)), 8, 2, FRAME, RailSettings(fs_hz=FS_HZ))
    core.start(np.array([OFF_LINE_M, OFF_LINE_M]))
    rows, emf = [], []
    for k in range(u_tx.shape[1] // FRAME):
        t = k * FRAME / FS_HZ
        x_head, v, broken = schedule(t)
        core.set_faults(broken, np.zeros(8), np.zeros(8, dtype=bool))
        out = core.step(t, u_tx[:, k * FRAME:(k + 1) * FRAME], np.array([x_head, OFF_LINE_M]), np.array([v, 0.0]),
                        np.zeros(2))
        rows.append((t + FRAME / FS_HZ, out.i_axle[0], *out.occupied.astype(int)))
        emf.append(out.e_coil[0].copy())
    return np.array(rows), np.concatenate(emf)


def _check_worked_example() -> None:
    """two_port reproduces the sourced worked example (docs/sources.md#track-circuits-and-rail-impedance:
    z = 0.52 + j1.224 Ω/km, 1 Ω·km, 0.3 km → A 1.023 + j0.055, B 0.151 + j0.373 Ω, C 0.302 + j0.006 S)."""
    from fmus.rail_line.track_circuit import two_port

    abcd = two_port(0.52 + 1.224j, 1.0, 0.3)
    for got, want, tol in ((abcd[0, 0], 1.023 + 0.055j, 1e-3), (abcd[0, 1], 0.151 + 0.373j, 1.5e-3),
                           (abcd[1, 0], 0.302 + 0.006j, 1e-3)):
        if abs(got - want) > tol:
            raise RuntimeError(f"two_port no longer reproduces the worked example: {got} against {want}")


def rail_vectors() -> RoleFile:
    role = RoleFile("rail_line", ["fs", "transformer_ratio", "u_tx", "x_head", "v", "broken_rail_at", "e_coil",
                                  "occupied", "i_axle"])
    step = {"fs_hz": FS_HZ, "frame_port": "u_tx"}
    params = {"fs": FS_HZ}
    _two_port_first_axle(role, step, params)
    _code_current_first_axle(role, step, params)
    _track_circuit_modes(role, step, params)
    _joint_null_zone(role, step, params)
    return role


def _two_port_first_axle(role: RoleFile, step: dict, params: dict) -> None:
    """The two-port cascade of the worked example's method: a steady 1 V 50 Hz carrier into section
    4 (transformer ratio 1), a standing 400 m train (the default rolling stock's wheelsets at their
    axles) at five places; the rms of i_axle over each place against the cascade's current
    (amplitude / √2), within 1 % (docs/rail_line.md#validation)."""
    from fmus.rail_line.core import RailLineCore, RailSettings

    _check_worked_example()
    line = load_line(str(DEFAULT_LINE))
    plant = RailLineCore(line, 8, 2, FRAME, RailSettings(fs_hz=FS_HZ, transformer_ratio=1.0))
    section, carrier = 3, line.sections[3].carrier_hz
    circuit = plant.circuits[section]
    places = [7850.0, 8600.0, 9137.0, 9900.0, 10350.0]
    place_s = 0.6
    seconds = place_s * len(places)
    u_tx = np.zeros((8, int(round(seconds * FS_HZ))))
    u_tx[section] = np.sin(2 * np.pi * carrier * np.arange(u_tx.shape[1]) / FS_HZ)
    expected = [cascade_shunt_current(circuit, x, carrier_hz=carrier, wheelsets_m=plant.settings.wheelset_offsets_m[0])
                / np.sqrt(2.0) for x in places]
    name = "two_port_first_axle"
    role.vectors.append({
        "name": name, "what": f"1 V {carrier:g} Hz steady into section {section + 1}, transformer ratio 1; a standing "
                              f"400 m train at {', '.join(f'{x:g}' for x in places)} m, {place_s:g} s each",
        "parameters": {**params, "transformer_ratio": 1.0}, "step": step, "duration_s": seconds,
        "inputs": {"u_tx": role.samples(name, "u_tx", u_tx),
                   "x_head": schedule_input([round(i * place_s, 4) for i in range(len(places))], [[x] for x in places]),
                   "v": schedule_input([0.0], [[0.0]])},
        "checks": [{"kind": "near", "label": "i_axle[1] (rms) against the two-port cascade", "port": "i_axle[1]",
                    "windows": [[round(i * place_s + 0.4, 4), round((i + 1) * place_s, 4)] for i in range(len(places))],
                    "statistic": "rms", "expected": [round(e, 9) for e in expected], "tolerance": 0.01,
                    "relative": True}]})


def _code_current_first_axle(role: RoleFile, step: dict, params: dict) -> None:
    """The keyed code current under the first axle of a standing train at three places in section 1:
    its rms over whole code cycles against our plant (which follows the two-port cascade within 0.5
    %, above); bound 1 %. The port is an rms over each frame, so the rms of the frames' values is
    the window's at any frame size."""
    hold_s, heads = 2 * CYCLE_S["KPT-5"] + 0.4, [900.0, 1800.0, 2500.0]
    seconds = hold_s * len(heads)
    u_tx = _coder_stream(seconds)
    place = lambda t: (heads[min(int(t // hold_s), len(heads) - 1)], 0.0, -1.0)
    rows, _ = _rail_run(u_tx, place)
    windows = [[round(i * hold_s + 0.4, 4), round((i + 1) * hold_s, 4)] for i in range(len(heads))]
    rms = [float(np.sqrt(np.mean(rows[(rows[:, 0] > lo + 1e-9) & (rows[:, 0] <= hi + 1e-9), 1] ** 2)))
           for lo, hi in windows]
    name = "code_current_first_axle"
    role.vectors.append({
        "name": name, "what": f"З (4 V) into every section; a standing train's head at {', '.join(f'{h:g}' for h in heads)} m, {hold_s:g} s each",
        "parameters": params, "step": step, "duration_s": seconds,
        "inputs": {"u_tx": role.samples(name, "u_tx", u_tx),
                   "x_head": schedule_input([i * hold_s for i in range(len(heads))], [[h] for h in heads]),
                   "v": schedule_input([0.0], [[0.0]])},
        "checks": [{"kind": "near", "label": "i_axle[1], rms over two code cycles at each place (our plant)",
                    "port": "i_axle[1]", "windows": windows, "statistic": "rms", "expected": rms,
                    "tolerance": 0.01, "relative": True}]})


def _track_circuit_modes(role: RoleFile, step: dict, params: dict) -> None:
    """The track relays: normal (free), shunt (a train in section 3), control (a broken rail in
    section 4) modes, 2 s each."""
    mode_s = 2.0
    phases = [(OFF_LINE_M, -1.0), (6000.0, -1.0), (OFF_LINE_M, 9000.0)]
    seconds = mode_s * len(phases)
    u_tx = _coder_stream(seconds)
    rows, _ = _rail_run(u_tx, lambda t: (*phases[min(int(t // mode_s), 2)][:1], 0.0, phases[min(int(t // mode_s), 2)][1]))
    at = [mode_s * (i + 1) for i in range(len(phases))]
    expected = [rows[int(round(a * FS_HZ / FRAME)) - 1, 2:].astype(int).tolist() for a in at]
    assert expected == [[0] * 8, [0, 0, 1, 0, 0, 0, 0, 0], [0, 0, 0, 1, 0, 0, 0, 0]], expected
    name = "track_circuit_modes"
    role.vectors.append({
        "name": name, "what": "free line (normal mode), a train with its head at 6000 m (shunt mode), "
                              "a broken rail at 9000 m (control mode), 2 s each",
        "parameters": params, "step": step, "duration_s": seconds,
        "inputs": {"u_tx": role.samples(name, "u_tx", u_tx),
                   "x_head": schedule_input([i * mode_s for i in range(3)], [[p[0]] for p in phases]),
                   "v": schedule_input([0.0], [[0.0]]),
                   "broken_rail_at": schedule_input([i * mode_s for i in range(3)], [p[1] for p in phases])},
        "checks": [{"kind": "table", "label": "occupied: none; section 3; section 4", "port": "occupied",
                    "at_s": at, "expected": expected}]})


def _joint_null_zone(role: RoleFile, step: dict, params: dict) -> None:
    """The joint between sections 1 and 2 (2600 m) passed at 20 m/s: the coil EMF vanishes in the
    null zone between the feed leads and the joint (docs/rail_line.md)."""
    seconds, speed, start = 4.0, 20.0, 2540.0
    u_tx = _coder_stream(seconds)
    rows, emf = _rail_run(u_tx, lambda t: (start + speed * t, speed, -1.0))
    frame_peak = np.abs(emf).reshape(-1, FRAME).max(axis=1)
    t_end = rows[:, 0]
    near_joint = np.abs(t_end - (2600.0 - 1.5 - start) / speed) < 0.1
    null = np.flatnonzero(near_joint & (frame_peak == 0.0))
    null_window = [round(float(t_end[null[0]] - FRAME / FS_HZ), 4), round(float(t_end[null[-1]]), 4)]
    entry_level = float(frame_peak[t_end > 3.2].max())
    name = "joint_null_zone"
    role.vectors.append({
        "name": name, "what": f"З into every section; a train from {start:g} m at {speed:g} m/s across the joint at 2600 m",
        "parameters": params, "step": step, "duration_s": seconds,
        "inputs": {"u_tx": role.samples(name, "u_tx", u_tx),
                   "x_head": schedule_input([0.0], [[start]]), "v": schedule_input([0.0], [[speed]])},
        "record_frames": ["e_coil[1]"],
        "checks": [
            {"kind": "frame_peak", "label": "code before the joint (≥ half our core's level)", "port": "e_coil[1]",
             "from_s": 1.0, "to_s": 2.5, "at_least": 0.5 * float(frame_peak[(t_end > 1.0) & (t_end <= 2.5)].max()),
             "unit": "V"},
            {"kind": "frame_peak", "label": "null zone: EMF ≤ 5 % of the next section's entry level",
             "port": "e_coil[1]", "from_s": null_window[0], "to_s": null_window[1],
             "at_most": round(0.05 * entry_level, 6), "unit": "V"},
            {"kind": "frame_peak", "label": "next section's code after the joint (≥ half our core's level)",
             "port": "e_coil[1]", "from_s": 3.2, "at_least": 0.5 * entry_level, "unit": "V"}]})
