"""The traction role's vectors (data/traction.json and the data files beside it): the ATO book's
braking examples, stops under service and emergency braking, a balancing speed against the
book's balance of forces, and the stop point's robustness to the step size (docs/traction.md).
"""
from __future__ import annotations

import json
from typing import Callable

import numpy as np

from fmus.data.loader import DEFAULT_LINE, DEFAULT_ROLLING_STOCK, load_line, load_rolling_stock
from orchestrator.conformance.generate.role_file import RoleFile, in_range, schedule_input


def _traction_core(**kwargs):
    from fmus.traction.core import TractionCore

    return TractionCore(load_rolling_stock(str(DEFAULT_ROLLING_STOCK)), load_line(str(DEFAULT_LINE)), **kwargs)


def _drive(core, seconds: float, step_s: float, schedule: Callable[[float], tuple]) -> np.ndarray:
    """Rows (t_end, x, v, a) of the traction core under a (command, emergency) schedule."""
    rows = []
    for k in range(int(round(seconds / step_s))):
        t = k * step_s
        command, emergency = schedule(t)
        out = core.step(t, step_s, command, emergency)
        rows.append((t + step_s, out.x_m, out.v_mps, out.a_mps2))
    return np.array(rows)


def _ideal_brake_stock(decel_mps2: float) -> dict:
    """The bundled EMU made an ideal brake: no resistance to speak of, no rotating mass, the
    full service brake at once and exactly ``decel_mps2`` (the ATO book's constant-deceleration
    examples, docs/traction.md#our-figures-beside-the-sources)."""
    stock = json.loads((DEFAULT_ROLLING_STOCK.parent / "emu_er2.json").read_text(encoding="utf-8"))
    stock["name"] = f"ideal brake {decel_mps2:g} m/s2 (conformance vectors)"
    stock["rotating_mass_factor"] = 0.0
    for unit in stock["units"]:
        unit["resistance"] = {"a": 1e-9, "b": 0.0, "c": 0.0, "per_axle_load": [0.0, 0.0, 0.0]}
    stock["traction"]["auxiliary_kw"] = 0
    stock["pneumatic_brake"].update(service_decel_mps2=decel_mps2, delay_s=0.0, time_constant_s=0.0)
    return stock


def _flat_line() -> dict:
    line = json.loads(DEFAULT_LINE.read_text(encoding="utf-8"))
    line["name"] = "the bundled line made level and straight (conformance vectors)"
    line["gradients"], line["curves"] = [{"start_m": 0, "permille": 0.0}], []
    return line


#: the ATO book's stops from 80 km/h at a constant deceleration: distance, time (docs/traction.md)
BOOK_STOPS = {0.3: (822.0, 74.0), 0.5: (493.0, 44.4)}


def traction_vectors() -> RoleFile:
    role = RoleFile("traction", ["rolling_stock_file", "line_file", "x0", "v0", "command", "emergency_brake",
                                 "x", "v", "a", "stop_time"])
    _book_stops(role)
    _brake_to_a_stop(role)
    _balancing_speed(role)
    _step_size(role)
    return role


def _book_stops(role: RoleFile) -> None:
    """The book's braking examples through the FMU's own data-file parameters, at 0.1 s and 1 s."""
    role.data_files["traction_flat_line.json"] = _flat_line()
    v0 = 80.0 / 3.6
    for decel, (book_m, book_s) in BOOK_STOPS.items():
        stock_file = f"traction_ideal_brake_{decel:g}.json"
        role.data_files[stock_file] = _ideal_brake_stock(decel)
        exact_m, exact_s = v0 ** 2 / (2 * decel), v0 / decel
        for step_s in (0.1, 1.0):
            stopped = [in_range("v", None, 0.0)]
            role.vectors.append({
                "name": f"book_stop_80kmh_{decel:g}mps2_step{step_s:g}s",
                "what": f"ideal brake of {decel:g} m/s² from 80 km/h on a level line, step {step_s:g} s "
                        f"(the ATO book: {book_m:g} m, {book_s:g} s)",
                "parameters": {"rolling_stock_file": stock_file, "line_file": "traction_flat_line.json",
                               "x0": 1000.0, "v0": v0},
                "step": {"step_s": step_s}, "duration_s": round(exact_s + 10.0),
                "inputs": {"command": schedule_input([0.0], [-1.0])},
                "checks": [
                    {"kind": "when", "label": f"stopping distance (v²/2a = {exact_m:.2f} m; book {book_m:g} m)",
                     "trigger": stopped, "port": "x", "expected": round(1000.0 + exact_m, 4), "tolerance": 1.5,
                     "unit": "m"},
                    {"kind": "when", "label": f"stopping time (v/a = {exact_s:.2f} s; book {book_s:g} s)",
                     "trigger": stopped, "port": "stop_time", "expected": round(exact_s, 4), "tolerance": 0.25,
                     "unit": "s"},
                    {"kind": "extreme", "label": "speed never negative", "port": "v", "extreme": "min",
                     "at_least": 0.0, "unit": "m/s"}]})


def _brake_to_a_stop(role: RoleFile) -> None:
    """Braking: from 80 km/h (service, command −1) and 100 km/h (emergency) to a stop; stopping
    distance and time against our core (the braking model of docs/traction.md), speed never
    negative."""
    for name, v0_kmh, command, emergency in (("service_brake_80kmh", 80.0, -1.0, False),
                                             ("emergency_brake_100kmh", 100.0, 0.0, True)):
        step_s, seconds = 0.5, 90.0
        rows = _drive(_traction_core(x0_m=2000.0, v0_mps=v0_kmh / 3.6), seconds, step_s,
                      lambda t, c=command, e=emergency: (c, e))
        stopped = rows[np.flatnonzero(rows[:, 2] <= 0.0)[0]]
        role.vectors.append({
            "name": name, "what": f"from {v0_kmh:g} km/h at 2000 m, {'emergency brake' if emergency else 'full service brake'} to a stop",
            "parameters": {"x0": 2000.0, "v0": v0_kmh / 3.6}, "step": {"step_s": step_s}, "duration_s": seconds,
            "inputs": {"command": schedule_input([0.0], [command]),
                       "emergency_brake": schedule_input([0.0], [emergency])},
            "checks": [
                {"kind": "when", "label": "stopping point (reference train model)", "trigger": [in_range("v", None, 0.0)],
                 "port": "x", "expected": float(stopped[1]), "tolerance": 2.0, "unit": "m"},
                {"kind": "latency", "label": "stopped within the reference time + one step", "from_s": 0.0,
                 "until": [in_range("v", None, 0.0)], "bound_s": float(stopped[0]) + step_s},
                {"kind": "extreme", "label": "speed never negative", "port": "v", "extreme": "min",
                 "at_least": 0.0, "unit": "m/s"}]})


def _balancing_speed(role: RoleFile) -> None:
    """Balancing speed: the bundled freight train at full traction on a constant +6 ‰ of the AC
    line, from 70 km/h; the speed it settles at against the book's balance of forces F(v) = (P +
    Q)·(w0(v) + i) (docs/traction.md#our-figures-beside-the-sources), solved with the train's own
    effort and resistance."""
    from scipy.optimize import brentq

    from fmus.traction.core import TractionCore

    grade = 6.0
    ac_line = json.loads((DEFAULT_LINE.parent / "default_line_ac.json").read_text(encoding="utf-8"))
    ac_line["name"] = f"the bundled AC line at a constant +{grade:g} permille (conformance vectors)"
    ac_line["gradients"], ac_line["curves"] = [{"start_m": 0, "permille": grade}], []
    role.data_files["traction_ac_line_6permille.json"] = ac_line
    freight = load_rolling_stock(str(DEFAULT_ROLLING_STOCK.parent / "freight_vl80.json"))
    probe = TractionCore(freight, load_line(str(DEFAULT_LINE.parent / "default_line_ac.json")))
    v_bal = brentq(lambda v: probe.max_traction_force(v) - (probe.main_resistance(v) + grade * probe.weight_kn),
                   20.0 / 3.6, freight.max_speed_mps)
    settled_s = 1000.0
    role.vectors.append({
        "name": "balancing_speed_freight_6permille",
        "what": f"ВЛ80 + 62 wagons at full traction on +{grade:g} ‰ from 70 km/h for {settled_s:g} s, step 1 s",
        "parameters": {"rolling_stock_file": "traction_freight_vl80.json",
                       "line_file": "traction_ac_line_6permille.json", "x0": 1000.0, "v0": 70.0 / 3.6},
        "step": {"step_s": 1.0}, "duration_s": settled_s,
        "inputs": {"command": schedule_input([0.0], [1.0])},
        "checks": [
            {"kind": "near", "label": f"settled speed against F = (P + Q)(w0 + i): {v_bal * 3.6:.2f} km/h",
             "port": "v", "at_s": [settled_s], "expected": [round(v_bal, 6)], "tolerance": 0.005, "relative": True},
            {"kind": "extreme", "label": "settled: acceleration ≥ −2e-4 m/s²", "port": "a", "extreme": "min",
             "from_s": settled_s - 10.0, "at_least": -2e-4, "unit": "m/s2"},
            {"kind": "extreme", "label": "settled: acceleration ≤ 2e-4 m/s²", "port": "a", "extreme": "max",
             "from_s": settled_s - 10.0, "at_most": 2e-4, "unit": "m/s2"}]})
    role.data_files["traction_freight_vl80.json"] = json.loads(
        (DEFAULT_ROLLING_STOCK.parent / "freight_vl80.json").read_text(encoding="utf-8"))


def _step_size(role: RoleFile) -> None:
    """Step-size robustness: one command profile at 0.1, 0.5 and 1 s; position at 120 s against the
    0.1 s reference within 0.5 m (docs/ato.md: the stop point between 0.1 s and 1 s steps)."""
    profile_t = [0.0, 60.0, 90.0]
    profile_c = [1.0, 0.0, -0.6]
    profile = lambda t: (profile_c[int(np.searchsorted(profile_t, t, side="right")) - 1], False)
    reference = _drive(_traction_core(x0_m=400.0), 120.0, 0.1, profile)
    x_ref = float(reference[-1, 1])
    for step_s in (0.1, 0.5, 1.0):
        role.vectors.append({
            "name": f"step_size_{step_s:g}s", "what": f"traction 60 s, coast 30 s, brake 0.6 for 30 s, step {step_s:g} s",
            "parameters": {"x0": 400.0, "v0": 0.0}, "step": {"step_s": step_s}, "duration_s": 120.0,
            "inputs": {"command": schedule_input(profile_t, profile_c)},
            "checks": [{"kind": "near", "label": "position at 120 s against the 0.1 s reference", "port": "x",
                        "at_s": [120.0], "expected": [x_ref], "tolerance": 0.5, "unit": "m"}]})
