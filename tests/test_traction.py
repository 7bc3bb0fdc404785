"""Traction: dynamics core against textbook figures and a solve_ivp reference, data-file
validation, and the FMU through the orchestrator (step-size robustness)."""
import dataclasses
import json

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fmus.data.loader import DATA, DEFAULT_LINE, load_line, load_rolling_stock, load_timetable
from fmus.errors import FmuInputError
from fmus.traction.core import TractionCore
from helpers import ComponentSpec, ConnectionSpec, railcosim, read_csv, write_ssd

KMH = 1 / 3.6


def _line_variant(tmp_path, name="flat", **changes):
    ac = changes.get("electrification", {}).get("system") == "AC25000"
    doc = json.loads((DATA / "default_line_ac.json" if ac else DEFAULT_LINE).read_text())   # 25 Hz carriers on AC
    doc.update(changes)
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(doc, ensure_ascii=False))
    return load_line(path)


def _flat_line(tmp_path, grade=0.0, ac=False):
    power = {"system": "AC25000", "nominal_voltage_v": 25000} if ac else {"system": "DC3000"}
    return _line_variant(tmp_path, f"grade{grade}{ac}", gradients=[{"start_m": 0, "permille": grade}], curves=[],
                         electrification=power)


def _ideal_brake_stock(decel):
    """No resistance, no rotating mass, an instantaneous brake of exactly `decel` at full command."""
    stock = load_rolling_stock(DATA / "emu_er2.json")
    return dataclasses.replace(stock, resistance_terms=[(1.0, 1e-12, 0.0, 0.0)], idle_resistance_terms=None,
                               starting_resistance=0.0,
                               gamma=0.0, brake_delay_s=0.0, brake_time_constant_s=0.0,
                               service_decel=decel, auxiliary_w=0.0)


@pytest.mark.parametrize("decel, distance, duration", [(0.3, (822, 823), 74.0), (0.5, (493, 494), 44.4)])
@pytest.mark.parametrize("step", [0.1, 1.0])
def test_constant_deceleration_stops_match_the_ato_book(tmp_path, decel, distance, duration, step):
    core = TractionCore(_ideal_brake_stock(decel), _flat_line(tmp_path), x0_m=1000.0, v0_mps=80 * KMH)
    t = 0.0
    while t < 120.0:
        out = core.step(t, step, -1.0)
        t += step
        assert out.v_mps >= 0.0
    # exact kinematics: v²/2a = 823.05 m and 493.83 m; the book quotes 822 and 493 (rounded down)
    assert round(out.x_m - 1000.0) in distance
    assert abs(out.stop_time_s - duration) < 0.1          # book: 74 s and 44.4 s (v/a = 74.07, 44.44)
    assert out.x_m == core.step(t, step, -1.0).x_m         # a braked, stopped train stays stopped


def test_ptr_worked_example_locomotive_resistance():
    stock = load_rolling_stock()
    loco_only = dataclasses.replace(stock, resistance_terms=[(1.0, 1.9, 0.01, 0.0003)])  # ЧС7 alone
    core = TractionCore(loco_only, load_line())
    assert round(core.main_resistance(56 * KMH) / core.weight_kn, 1) == 3.4   # N/kN at 56 km/h


def test_balancing_speed_on_a_constant_grade(tmp_path):
    grade = 6.0
    stock = load_rolling_stock(DATA / "freight_vl80.json")
    line = _flat_line(tmp_path, grade, ac=True)
    core = TractionCore(stock, line, x0_m=1000.0, v0_mps=70 * KMH)  # approaches from above
    for k in range(2400):
        out = core.step(float(k), 1.0, 1.0)
        if out.x_m > 19000:
            break
    v = out.v_mps
    resisting = core.main_resistance(v) + grade * core.weight_kn    # (P+Q)·(w0 + i)
    assert abs(out.a_mps2) < 2e-4
    assert core.max_traction_force(v) == pytest.approx(resisting, rel=5e-3)
    assert 20 * KMH < v < stock.max_speed_mps


def _schedule(t):
    return 1.0 if t < 180.0 else (0.0 if t < 260.0 else -0.5)


def test_core_matches_a_tight_solve_ivp_reference(tmp_path):
    line, stock = load_line(), load_rolling_stock()
    core = TractionCore(stock, line, x0_m=400.0)
    t = 0.0
    while core.out.stop_time_s < 0 or t < 10:
        out = core.step(t, 1.0, _schedule(t))
        t += 1.0
        assert t < 1000
    stop_time, stop_x, energy = out.stop_time_s, out.x_m, core.energy_drawn

    ref = TractionCore(stock, line, x0_m=400.0)   # its force functions, integrated by scipy

    def demand(time):  # brake demand as commanded, and as the pneumatic brake sees it (delayed)
        share = max(-_schedule(time), 0.0)
        return share * ref.m_eff * stock.service_decel

    def rhs(time, y):
        x, v, f_p, e = y
        share_t = max(_schedule(time), 0.0)
        now = demand(time)
        delayed = demand(time - stock.brake_delay_s) if time >= stock.brake_delay_s else 0.0
        f_e = min(now, ref.electric_brake_force(v)) if now > 0 else 0.0
        f_t = share_t * ref.max_traction_force(v)
        target = max(delayed - f_e, 0.0)
        resistance = ref.main_resistance(v) if share_t > 0 else ref.coasting_resistance(v)
        a = (f_t - f_e - f_p - resistance - ref.path_resistance(x)) / ref.m_eff
        return [v, a, (target - f_p) / stock.brake_time_constant_s, f_t * v / stock.efficiency + stock.auxiliary_w]

    def stopped(time, y):
        return y[1] - 1e-9
    stopped.terminal, stopped.direction = True, -1

    breaks = [0.0, 180.0, 260.0, 260.0 + stock.brake_delay_s, 1000.0]
    y = [400.0, 0.0, 0.0, 0.0]
    end_time = None
    for a, b in zip(breaks[:-1], breaks[1:]):
        sol = solve_ivp(rhs, (a, b), y, method="DOP853", rtol=1e-10, atol=1e-8, events=stopped if a > 0 else None,
                        max_step=0.5)
        y = sol.y[:, -1]
        if sol.status == 1:
            end_time = sol.t_events[0][0]
            y = sol.y_events[0][0]
            break
    assert end_time is not None
    assert stop_time == pytest.approx(end_time, rel=1e-3)
    assert stop_x - 400.0 == pytest.approx(y[0] - 400.0, rel=1e-3)
    assert energy - stock.auxiliary_w * (t - stop_time) == pytest.approx(y[3], rel=1e-3)


def test_speed_never_negative_and_command_clamped(tmp_path):
    core = TractionCore(load_rolling_stock(), _flat_line(tmp_path), x0_m=500.0, v0_mps=10.0)
    for k, command in enumerate([-7.0, float("nan"), 3.0, -1.0]):
        out = core.step(float(k), 1.0, command)
        assert out.v_mps >= 0.0
    assert out.commands_clamped == 3


def test_stopped_train_on_a_grade_holds_until_traction_exceeds_resistance(tmp_path):
    line = _flat_line(tmp_path, grade=8.0, ac=True)
    core = TractionCore(load_rolling_stock(DATA / "freight_vl80.json"), line, x0_m=5000.0)
    out = core.step(0.0, 1.0, 0.05)          # 5 % traction cannot lift 5152 t up 8 ‰
    assert out.v_mps == 0.0 and out.x_m == 5000.0
    for k in range(1, 20):
        out = core.step(float(k), 1.0, 1.0)
    assert out.v_mps > 0.0 and out.x_m > 5000.0


def test_the_brake_pipeline_delays_the_pneumatic_demand_and_lets_the_electric_brake_act_first():
    """fmus/traction/brake_pipeline.py, the one pipeline of the plant and the ATO's copy: the
    pneumatic brake gets a demand after its delay, less what the electric brake takes at once
    (up to its curve, which fades at low speed), and builds up with its time constant."""
    import math

    from fmus.traction.brake_pipeline import BrakePipeline

    def electric_brake(v_mps):
        return 30.0 if v_mps > 3.0 else 0.0                        # fades below 3 m/s

    pipeline = BrakePipeline(delay_s=8.0, time_constant_s=25.0, emergency_demand=100.0,
                             electric_brake=electric_brake, due_tolerance_s=1e-12)
    pipeline.command(2.0, 50.0, emergency=False)
    pipeline.command(3.0, 50.0, emergency=False)                  # unchanged: nothing new queued
    assert list(pipeline.events) == [(10.0, 50.0)] and pipeline.next_change_s() == 10.0
    pipeline.take_due(9.9)
    assert pipeline.delayed == 0.0 and pipeline.electric(20.0) == 30.0   # electric at once
    pipeline.take_due(10.0)
    assert pipeline.delayed == 50.0 and pipeline.next_change_s() == math.inf
    assert pipeline.pneumatic_target(pipeline.electric(20.0)) == 20.0    # the rest
    assert pipeline.pneumatic_target(pipeline.electric(1.0)) == 50.0     # electric faded
    assert pipeline.relax(0.0, 50.0, 25.0) == pytest.approx(50.0 * (1.0 - math.exp(-1.0)))
    assert pipeline.build_up_rate(0.0, 50.0) == pytest.approx(2.0)
    pipeline.command(12.0, 50.0, emergency=True)
    assert pipeline.electric(20.0) == 0.0 and list(pipeline.events) == [(20.0, 100.0)]


def test_regenerative_braking_returns_energy_and_current(tmp_path):
    line = _line_variant(tmp_path, "ac", electrification={"system": "AC25000", "nominal_voltage_v": 25000})
    core = TractionCore(load_rolling_stock(DATA / "freight_vl80.json"), line, x0_m=3000.0, v0_mps=60 * KMH)
    out = core.step(0.0, 1.0, -0.3)
    assert out.energy_returned_j > 0.0 and out.i_traction_a < 0.0
    assert out.force_brake_n > 0.0


# ---- bad data files: message names file and field ----------------------------------------------
def _write(tmp_path, name, doc):
    path = tmp_path / name
    path.write_text(json.dumps(doc, ensure_ascii=False))
    return path


@pytest.mark.parametrize("mutate, field", [
    (lambda d: d.pop("length_m"), "length_m"),
    (lambda d: d["units"][0].__setitem__("mass_t", -5), "units[0].mass_t"),
    (lambda d: d["traction"].__setitem__("effort_kn", [[0, 300], [50, 320]]), "traction.effort_kn[1]"),
    (lambda d: d["pneumatic_brake"].__setitem__("delay_s", 500), "pneumatic_brake.delay_s"),
])
def test_bad_rolling_stock_names_file_and_field(tmp_path, mutate, field):
    _assert_rejected(tmp_path, DATA / "passenger_chs7.json", mutate, load_rolling_stock, field)


@pytest.mark.parametrize("mutate, field", [
    (lambda d: d["units"][0].__setitem__("vehicle_length_m", 300.0), "units"),
    (lambda d: d["units"][0].__setitem__("bogie_centres_m", 16.0), "units[0].bogie_centres_m"),
    (lambda d: d["units"][1].__setitem__("axles", 3), "units[1].axles"),
])
def test_wheelset_geometry_that_cannot_be_names_file_and_field(tmp_path, mutate, field):
    _assert_rejected(tmp_path, DATA / "passenger_chs7.json", mutate, load_rolling_stock, field)


def test_wheelsets_follow_the_bodies_and_bogies():
    """The ЧС7's two 17.02 m bodies on bogies 7.9 m apart with 3.2 m wheelbase, then the
    coaches sharing what the file's 388 m leaves (docs/sources.md#rolling-stock-wheelsets); a
    file without wheelset geometry gets defaults that fit its bodies."""
    offsets = load_rolling_stock(DATA / "passenger_chs7.json").wheelset_offsets_m
    assert len(offsets) == 8 + 14 * 4 and offsets[0] == 0.0 and np.all(np.diff(offsets) > 0)
    assert offsets[1:4] == pytest.approx([3.2, 7.9, 11.1])            # the first body's bogies
    assert offsets[4] == pytest.approx(17.02)                         # the second body's first axle
    coach = (388.0 - 34.04) / 14
    assert offsets[-1] - offsets[-5] == pytest.approx(coach)          # coach to coach
    assert offsets[-1] < 388.0
    for name, axles in (("freight_vl80.json", 8 + 62 * 4), ("emu_er2.json", 10 * 4)):
        stock = load_rolling_stock(DATA / name)
        assert len(stock.wheelset_offsets_m) == axles and stock.wheelset_offsets_m[-1] < stock.length_m


def test_a_rolling_stock_file_without_wheelset_geometry_gets_bogies_that_fit(tmp_path):
    doc = json.loads((DATA / "freight_vl80.json").read_text())
    for unit in doc["units"]:
        for key in ("bodies", "vehicle_length_m", "bogie_centres_m", "bogie_wheelbase_m"):
            unit.pop(key, None)
    offsets = load_rolling_stock(_write(tmp_path, "plain.json", doc)).wheelset_offsets_m
    body = 944.0 / 63                                 # 63 bodies share the train's length
    assert len(offsets) == 256 and offsets[-1] < 944.0
    assert offsets[7] < body < offsets[8]             # the locomotive's 8 axles on its one body


def _assert_rejected(tmp_path, template, mutate, loader, field):
    doc = json.loads(template.read_text())
    mutate(doc)
    path = _write(tmp_path, "data.json", doc)
    with pytest.raises(FmuInputError) as error:
        loader(path)
    assert str(path) in str(error.value) and f"field {field}" in str(error.value)


@pytest.mark.parametrize("mutate, field", [
    (lambda d: d["block_sections"][1].__setitem__("start_m", 2000), "block_sections[1].start_m"),
    (lambda d: d["insulated_joints"].append({"position_m": 25000}), "insulated_joints[9].position_m"),
    (lambda d: d["gradients"][2].__setitem__("permille", 80), "gradients[2].permille"),
])
def test_bad_line_names_file_and_field(tmp_path, mutate, field):
    _assert_rejected(tmp_path, DEFAULT_LINE, mutate, load_line, field)


@pytest.mark.parametrize("stops, field", [
    ([{"station": "A", "departure_s": 0}, {"station": "Z", "arrival_s": 100}], "stops[1].station"),
    ([{"station": "A", "departure_s": 500}, {"station": "B", "arrival_s": 100}], "stops[1].arrival_s"),
    ([{"station": "A", "departure_s": 0}, {"station": "B", "arrival_s": 100, "dwell_s": -5}], "stops[1].dwell_s"),
])
def test_bad_timetable_names_file_and_field(tmp_path, stops, field):
    path = _write(tmp_path, "tt.json", {"train": "x", "stops": stops})
    with pytest.raises(FmuInputError) as error:
        load_timetable(path, load_line())
    assert f"field {field}" in str(error.value)


# ---- the FMU through the orchestrator -----------------------------------------------------------
def _traction_system(tmp_path, product_fmus, test_fmus, step, params=None, name="motion"):
    folder = tmp_path / f"{name}{step}"
    write_ssd(folder, "motion", [
        ComponentSpec("driver", str(test_fmus / "TestSchedule.fmu"), step,
                      {"schedule": "0:1;180:0;260:-0.5"}),
        ComponentSpec("train", str(product_fmus / "Traction.fmu"), step, params or {}),
    ], [ConnectionSpec("driver.command", "train.command")], stop_time=420.0)
    return folder


def test_step_size_robustness_through_the_orchestrator(tmp_path, product_fmus, test_fmus):
    from orchestrator.verdicts.verdict import railway_verdicts
    from orchestrator.run import RunOptions, run_system
    finals = {}
    for step in (0.1, 1.0):
        out = tmp_path / f"out{step}"
        run_system(_traction_system(tmp_path, product_fmus, test_fmus, step),
                   RunOptions(summaries=railway_verdicts, output_dir=out, output_interval=1.0, record=["train.x", "train.stop_time", "train.v", "train.energy"]))
        header, data = read_csv(out / "results.csv")
        finals[step] = dict(zip(header, data[-1]))
    summary = json.loads((tmp_path / "out1.0" / "summary.json").read_text())
    assert summary["trains"] == [{"name": "train", "energy_kwh": pytest.approx(finals[1.0]["train.energy"] / 3.6e6)}]
    assert finals[0.1]["train.v"] == finals[1.0]["train.v"] == 0.0
    assert abs(finals[0.1]["train.x"] - finals[1.0]["train.x"]) < 0.5
    assert abs(finals[0.1]["train.stop_time"] - finals[1.0]["train.stop_time"]) < 0.5


def test_bad_rolling_stock_file_through_the_cli(tmp_path, product_fmus, test_fmus):
    bad = _write(tmp_path, "bad_stock.json", {"name": "x"})
    folder = _traction_system(tmp_path, product_fmus, test_fmus, 1.0, {"rolling_stock_file": str(bad)})
    code, _, stderr = railcosim("run", folder, "--no-build", "--output", tmp_path / "o", "--output-interval", "1")
    assert code == 2 and len(stderr.strip().splitlines()) == 1 and "Traceback" not in stderr
    assert "bad_stock.json" in stderr and "field" in stderr


def test_a_rejected_data_file_ends_the_process_cleanly(tmp_path, product_fmus, test_fmus):
    """pythonfmu answers a rejected file with fmi2Fatal; the instance is then neither freed nor
    its library unloaded, and pythonfmu's interpreter state must still be released before its
    library's exit-time destructor (or the process aborts now and then at exit: SIGABRT seen
    in CI). The FMUs' forwarding binary does it (docs/architecture.md): every run exits 2.
    A bad data file is refused before any FMU is loaded (orchestrator/verdicts/system_checks.py),
    so a parameter below its minimum makes the facade refuse exitInitializationMode instead."""
    folder = _traction_system(tmp_path, product_fmus, test_fmus, 1.0, {"mass_scale": 0.05})
    for run in range(5):
        code, _, stderr = railcosim("run", folder, "--no-build", "--output", tmp_path / "o", "--output-interval", "1")
        assert code == 2 and "Traceback" not in stderr, (run, code, stderr[-500:])


def test_relative_data_file_resolves_against_the_system_folder(tmp_path, product_fmus, test_fmus):
    from orchestrator.verdicts.verdict import railway_verdicts
    from orchestrator.run import RunOptions, run_system
    folder = _traction_system(tmp_path, product_fmus, test_fmus, 1.0, {"rolling_stock_file": "resources/emu.json"})
    (folder / "resources").mkdir()
    (folder / "resources" / "emu.json").write_text((DATA / "emu_er2.json").read_text())
    result = run_system(folder, RunOptions(summaries=railway_verdicts, output_dir=tmp_path / "o", output_interval=1.0, stop_time=30.0))
    resolved = result.graph.nodes["train"].parameters["rolling_stock_file"]
    assert resolved == str((folder / "resources" / "emu.json").resolve())
    header, data = read_csv(tmp_path / "o" / "results.csv")
    # the lighter EMU accelerates harder than the default ЧС7 train: 30 s at full traction
    assert data[-1, header.index("train.v")] > 15.0
