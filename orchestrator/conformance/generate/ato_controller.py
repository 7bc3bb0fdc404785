"""The ato_controller role's vectors (data/ato_controller.json): closed loops with the reference
train, the bundled timetable and a signal at danger ahead (docs/ato.md).
"""
from __future__ import annotations

from fmus.signalling import cab_systems
from fmus.data.loader import DEFAULT_LINE, DEFAULT_TIMETABLE, load_line, load_timetable
from fmus.signalling import aspects as sig
from orchestrator.conformance.generate.role_file import RoleFile, cond, in_range


ARRIVAL_TOLERANCE_S, STOP_TOLERANCE_M = 15.0, 0.5        # docs/ato.md, Tests


def ato_vectors() -> RoleFile:
    """Closed loops with the reference train (our traction core, the runner's plant): the
    default timetable, and a signal at danger ahead (ALSN codes by position)."""
    role = RoleFile("ato_controller", ["cab_signal", "x", "v", "aspect", "code_valid", "command", "emergency_brake",
                                       "atp_interventions", "emergency_brakings", "signals_passed_at_danger",
                                       "stop_index", "arrival_time", "stop_error"])
    line = load_line(str(DEFAULT_LINE))
    timetable = load_timetable(str(DEFAULT_TIMETABLE), line)
    step = {"step_s": 0.5}
    never = [{"kind": "extreme", "label": f"no {what}", "port": port, "extreme": "max", "at_most": 0.0}
             for what, port in (("ATP intervention", "atp_interventions"), ("emergency braking", "emergency_brakings"),
                                ("signal passed at danger", "signals_passed_at_danger"))]
    checks = []
    for index, stop in enumerate(timetable[1:], start=2):
        reached = [cond("stop_index", [index])]
        checks += [
            {"kind": "when", "label": f"arrival at {stop.station} (timetable {stop.arrival_s:g} s)", "trigger": reached,
             "port": "arrival_time", "expected": float(stop.arrival_s), "tolerance": ARRIVAL_TOLERANCE_S, "unit": "s"},
            {"kind": "when", "label": f"stop error at {stop.station}", "trigger": reached, "port": "stop_error",
             "expected": 0.0, "tolerance": STOP_TOLERANCE_M, "unit": "m"}]
    role.vectors.append({
        "name": "timetable_closed_loop", "what": "the bundled timetable A → B → C (19.2 km) with green codes throughout; "
                                                "the reference train from A",
        "parameters": {"cab_signal": cab_systems.AtoMode.ALSN}, "step": step, "duration_s": float(timetable[-1].arrival_s) + 60.0,
        "plant": {"x0_m": timetable[0].stop_m},
        "checks": checks + never + [{"kind": "extreme", "label": "speed never negative", "port": "plant.v",
                                     "extreme": "min", "at_least": 0.0, "unit": "m/s"}]})
    # a signal at danger at the end of section 2 until 300 s: yellow in section 1, red-yellow in
    # section 2 (3-aspect block), green after the clear
    red_m = line.sections[1].end_m
    ry = (line.sections[1].start_m, red_m)
    y = (line.sections[0].start_m, line.sections[0].end_m)
    clear_s = 300.0
    ceiling_kmh, _ = sig.ALSN_SPEEDS_KMH["passenger"][sig.RED_YELLOW]
    _, yellow_at_signal_kmh = sig.ALSN_SPEEDS_KMH["passenger"][sig.YELLOW]
    role.vectors.append({
        "name": "red_signal_ahead", "what": f"signal at {red_m:g} m at danger until {clear_s:g} s: Ж from {y[0]:g} m, "
                                            f"КЖ from {ry[0]:g} m; green after",
        "parameters": {"cab_signal": cab_systems.AtoMode.ALSN}, "step": step, "duration_s": clear_s + 150.0,
        "plant": {"x0_m": timetable[0].stop_m, "cab_zones": [[*y, sig.YELLOW], [*ry, sig.RED_YELLOW]],
                  "cab_clear_s": clear_s},
        "checks": never + [
            {"kind": "extreme", "label": "stops before the signal at danger", "port": "plant.x", "extreme": "max",
             "to_s": clear_s, "offset": red_m, "at_most": 0.0, "unit": "m"},
            {"kind": "extreme", "label": f"at most {yellow_at_signal_kmh:g} km/h passing the yellow's exit signal",
             "port": "plant.v", "extreme": "max", "where": [in_range("plant.x", ry[0], ry[0] + 50.0)],
             "to_s": clear_s, "at_most": round(yellow_at_signal_kmh / 3.6, 4), "unit": "m/s"},
            {"kind": "extreme", "label": f"within the red-yellow ceiling ({ceiling_kmh:g} km/h)", "port": "plant.v",
             "extreme": "max", "where": [in_range("plant.x", *ry)], "to_s": clear_s,
             "at_most": round(ceiling_kmh / 3.6, 4), "unit": "m/s"},
            {"kind": "extreme", "label": "drives on after the clear", "port": "plant.x", "extreme": "max",
             "offset": red_m, "at_least": 0.0, "unit": "m"}]})
    return role

