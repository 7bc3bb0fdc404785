"""ATP + ATO controller: planner, ATP supervision, driving to the timetable, the FMU.

Most checks run the ATO and traction cores in one closed loop (harness/closed_loop.py);
the FMU checks run the shipped system through the orchestrator.
"""
import copy
import json
import math

import numpy as np
import pytest

from fmus.ato_controller.atp import EMERGENCY_INTERVENTION, SERVICE_INTERVENTION, Atp
from fmus.ato_controller.supervision import dv_ebi_mps
from fmus.ato_controller.core import AtoCore, AtoSettings
from harness.closed_loop import red_signal_ahead, run_closed_loop, timetable_with_supplement
from fmus.ato_controller.planner import StagePlanner
from fmus.ato_controller.train_model import NominalTrain
from fmus.signalling import aspects as sig
from fmus.data.loader import load_line, load_rolling_stock, load_timetable
from fmus.errors import FmuInputError
from helpers import railcosim, read_csv

KMH = 1 / 3.6
RUN_S = 1100.0
LINE_KM = (19600 - 400) / 1000


def _timetable(tmp_path, supplement, name="tt.json"):
    return timetable_with_supplement(tmp_path, supplement, name)


def _assert_on_time_and_on_the_mark(result, arrival_s=15.0, stop_m=0.5):
    arrivals = result.ato.arrivals
    assert [a["station"] for a in arrivals] == ["B", "C"]
    for a in arrivals:
        assert abs(a["arrival_deviation_s"]) <= arrival_s, a
        assert abs(a["stop_error_m"]) <= stop_m, a


# ---- planner ----------------------------------------------------------------------------------
def test_running_time_falls_continuously_with_the_cruise_speed():
    line, stock = load_line(), load_rolling_stock()
    planner = StagePlanner(NominalTrain(stock, line), line, "passenger", 0.5, 2 * KMH)
    s = np.linspace(10300, 19600, 931)
    ceiling = planner.ceiling(s, planner.static_profile(s))
    family = planner.programmes(s, ceiling, np.linspace(90, 110, 41) * KMH)
    steps = np.diff(family.time_s)
    assert np.all(steps < 0)                          # faster cruise, shorter time
    assert np.max(np.abs(steps)) < 3 * np.median(np.abs(steps))   # no jumps (cf. OSRD #1401)


def test_minimum_time_profile_respects_limits_and_the_stop():
    line, stock = load_line(), load_rolling_stock()
    planner = StagePlanner(NominalTrain(stock, line), line, "passenger", 0.5, 2 * KMH)
    plan = planner.plan(400, 10300, None)
    v = plan.family.v[plan.minimum]
    assert np.all(v <= plan.static_mps + 1e-9)
    assert v[-1] == 0.0 and v[0] == 0.0
    # braking into the stop at the planned 0.5 m/s²: v² = 2·a·d near the end
    d = plan.end_m - plan.s[-30:]
    assert np.allclose(v[-30:] ** 2, 2 * 0.5 * d, rtol=0.02, atol=0.5)


def test_fitted_programme_meets_the_scheduled_time_and_saves_energy():
    line, stock = load_line(), load_rolling_stock()
    planner = StagePlanner(NominalTrain(stock, line), line, "passenger", 0.5, 2 * KMH)
    minimum = planner.plan(400, 10300, None).minimum_time_s
    plan = planner.plan(400, 10300, 1.08 * minimum)
    f = plan.family
    assert f.time_s[plan.chosen] == pytest.approx(1.08 * minimum, abs=1.0)
    assert f.energy_j[plan.chosen] < 0.9 * f.energy_j[plan.minimum]


def _same_plan(a, b):
    assert (a.chosen, a.minimum, a.scheduled_time_s) == (b.chosen, b.minimum, b.scheduled_time_s)
    for name in ("cruise_mps", "coast_end_mps", "v", "t", "regime", "energy_j"):
        x, y = getattr(a.family, name), getattr(b.family, name)
        assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), name


def test_a_kept_stage_plan_is_the_computed_one_bit_for_bit(tmp_path, monkeypatch):
    """RAILCOSIM_PLAN_CACHE (a study's worker sets it): the second plan of a stage comes from
    the folder, byte for byte the plan computed without it; another schedule or another train
    is planned afresh; a damaged file is planned afresh too."""
    line, stock = load_line(), load_rolling_stock()
    planner = StagePlanner(NominalTrain(stock, line), line, "passenger", 0.5, 2 * KMH)
    minimum = planner.plan(400, 10300, None).minimum_time_s
    fresh = planner.plan(400, 10300, 1.08 * minimum)                  # no cache
    cache = tmp_path / "plans"
    monkeypatch.setenv("RAILCOSIM_PLAN_CACHE", str(cache))
    _same_plan(planner.plan(400, 10300, 1.08 * minimum), fresh)       # computed, then kept
    assert len(list(cache.glob("*.npz"))) == 1
    _same_plan(planner.plan(400, 10300, 1.08 * minimum), fresh)       # read from the folder
    assert len(list(cache.glob("*.npz"))) == 1
    later = planner.plan(400, 10300, 1.12 * minimum)                  # another schedule
    assert len(list(cache.glob("*.npz"))) == 2
    assert later.family.time_s[later.chosen] > fresh.family.time_s[fresh.chosen] + 10
    heavier = copy.deepcopy(stock)
    heavier.mass_kg *= 1.2
    other = StagePlanner(NominalTrain(heavier, line), line, "passenger", 0.5, 2 * KMH)
    assert other.plan(400, 10300, 1.08 * minimum).family.time_s[-1] > fresh.family.time_s[-1]
    assert len(list(cache.glob("*.npz"))) == 3
    for kept in cache.glob("*.npz"):
        kept.write_bytes(kept.read_bytes()[:100])                     # cut short
    _same_plan(planner.plan(400, 10300, 1.08 * minimum), fresh)


def test_identical_trains_plan_a_stage_once_and_share_it_read_only(monkeypatch):
    """N identical trains of one line and timetable (a headway study's) in one process: the
    second ATO's plan of a stage is the first's family, not planned again, and no ATO can
    change the arrays the others read."""
    line, stock = load_line(), load_rolling_stock()
    planner = StagePlanner(NominalTrain(stock, line), line, "passenger", 0.5, 2 * KMH)
    monkeypatch.delenv("RAILCOSIM_PLAN_CACHE", raising=False)
    first = planner.plan(400, 10300, 600.0)
    computed = []
    monkeypatch.setattr(StagePlanner, "_family", lambda self, *args: computed.append(args) or None)
    second = StagePlanner(NominalTrain(load_rolling_stock(), line), line, "passenger", 0.5, 2 * KMH).plan(400, 10300, 600.0)
    assert computed == [] and second.family is first.family and second.chosen == first.chosen
    with pytest.raises(ValueError):
        second.family.v[0, 0] = 0.0


def test_infeasible_timetable_is_an_initialisation_error_with_the_minimum_time(tmp_path):
    path = tmp_path / "tight.json"
    path.write_text(json.dumps({"train": "t", "stops": [{"station": "A", "departure_s": 0},
                                                        {"station": "B", "arrival_s": 300}]}))
    line, stock = load_line(), load_rolling_stock()
    with pytest.raises(FmuInputError) as error:
        AtoCore(line, stock, load_timetable(path, line), path, "passenger", AtoSettings())
    message = str(error.value)
    assert str(path) in message and "stops[1].arrival_s" in message
    assert "minimum running time 4" in message       # about 412 s on the default line


# ---- ATP ----------------------------------------------------------------------------------------
def _atp(cab="ALSN"):
    return Atp(load_line(), "passenger", 388.0, cab, 0.63, 4.22)


def test_red_yellow_code_loss_keeps_the_stop_at_that_signal():
    atp = _atp()
    # section 2 is 2600..5200: red-yellow → stop at 5200
    r = atp.supervise(0.0, 4000.0, 15.0, sig.RED_YELLOW, True, 0, 0, 0)
    assert any(t.signal and t.position_m == 5200.0 for t in r.constraints.targets)
    # the receiver's hold is over: it shows red (no code after red-yellow); the stop stays at
    # that signal, and red's 20 km/h is reached on a braking curve, not in one step
    lost = atp.supervise(1.0, 4015.0, 15.0, sig.RED, False, 0, 0, 0)
    assert any(t.signal and t.position_m == 5200.0 for t in lost.constraints.targets)
    assert lost.permitted_mps <= math.sqrt(2 * 0.63 * (5200 - 4015)) + 1e-9
    assert lost.aspect == sig.RED and lost.stop_now and lost.intervention == 0
    assert lost.ceiling_mps <= 80 * KMH + 1e-9
    assert any(t.speed_mps == pytest.approx(20 * KMH) and not t.signal for t in lost.constraints.targets)
    later = atp.supervise(30.0, 4300.0, 5.0, sig.RED, False, 0, 0, 0)
    assert any(t.signal and t.position_m == 5200.0 for t in later.constraints.targets)
    assert later.ceiling_mps <= 20 * KMH + 1e-9


def test_loss_of_code_is_never_more_permissive_than_the_last_valid_code():
    for last in (sig.GREEN, sig.YELLOW, sig.RED_YELLOW):
        atp = _atp()
        valid = atp.supervise(0.0, 3000.0, 10.0, last, True, 0, 0, 0)
        for t_lost in (1.0, 6.0):          # within and beyond the decoding latency
            lost = atp.supervise(t_lost, 3010.0, 10.0, sig.WHITE, False, 0, 0, 0)
            assert lost.permitted_mps <= valid.permitted_mps + 1e-9
            assert lost.ceiling_mps <= valid.ceiling_mps + 1e-9


def test_overspeed_gives_service_then_emergency_brake_and_counts():
    atp = _atp()
    limit = 80 * KMH                                  # 0..1200 m
    assert atp.supervise(0.0, 500.0, limit + 3 * KMH, sig.GREEN, True, 0, 0, 0).intervention == 0
    assert atp.supervise(1.0, 510.0, limit + 6 * KMH, sig.GREEN, True, 0, 0, 0).intervention == SERVICE_INTERVENTION
    result = atp.supervise(2.0, 520.0, limit + dv_ebi_mps(limit) + 0.5 * KMH, sig.GREEN, True, 0, 0, 0)
    assert result.intervention == EMERGENCY_INTERVENTION
    # emergency holds until standstill, even back under the limit
    assert atp.supervise(3.0, 530.0, 10 * KMH, sig.GREEN, True, 0, 0, 0).intervention == EMERGENCY_INTERVENTION
    assert atp.supervise(4.0, 531.0, 0.0, sig.GREEN, True, 0, 0, 0).intervention == 0
    assert (atp.interventions, atp.emergency_brakings) == (2, 1)


def test_passing_the_signal_under_red_yellow_is_a_spad_with_emergency_brake():
    atp = _atp()
    atp.supervise(0.0, 5150.0, 5.0, sig.RED_YELLOW, True, 0, 0, 0)
    result = atp.supervise(1.0, 5205.0, 5.0, sig.RED_YELLOW, True, 0, 0, 0)
    assert atp.signals_passed_at_danger == 1
    assert result.intervention == EMERGENCY_INTERVENTION


def test_after_a_yellow_signal_the_next_section_is_assumed_red_yellow_until_decoded():
    atp = _atp()
    atp.supervise(0.0, 5100.0, 15.0, sig.YELLOW, True, 0, 0, 0)
    # crossed into section 3 (5200..7800) while the receiver still shows the old yellow
    result = atp.supervise(1.0, 5215.0, 15.0, sig.YELLOW, True, 0, 0, 0)
    assert any(t.signal and t.position_m == 7800.0 for t in result.constraints.targets)
    # kept while the receiver may still display the old code (its hold, 5.5 s), then gone
    held = atp.supervise(6.0, 5290.0, 15.0, sig.GREEN, True, 0, 0, 0)
    assert any(t.signal and t.position_m == 7800.0 for t in held.constraints.targets)
    later = atp.supervise(7.0, 5305.0, 15.0, sig.GREEN, True, 0, 0, 0)
    assert not any(t.signal for t in later.constraints.targets)


def test_digital_cab_signal_targets_the_next_signal_and_a_stop_after_the_free_blocks():
    atp = _atp("digital")
    r = atp.supervise(0.0, 3000.0, 30.0, sig.GREEN, True, 120 * KMH, 100 * KMH, 2)
    assert r.ceiling_mps == pytest.approx(120 * KMH)
    targets = {(t.position_m, round(t.speed_mps * 3.6), t.signal) for t in r.constraints.targets}
    assert (5200.0, 100, False) in targets                      # the next signal (end of section 2)
    assert (10400.0, 0, True) in targets                        # the section after two free ones
    open_line = atp.supervise(0.5, 3010.0, 30.0, sig.GREEN, True, 120 * KMH, 120 * KMH, 6)
    assert not any(t.signal for t in open_line.constraints.targets)


@pytest.mark.parametrize("mode, aspect, valid, v_permitted, permits", [
    ("ALSN", sig.GREEN, True, 0.0, True), ("ALSN", sig.YELLOW, True, 0.0, True),
    ("ALSN", sig.RED_YELLOW, True, 0.0, True),           # moving up to the signal is permitted
    ("ALSN", sig.WHITE, False, 0.0, False), ("ALSN", sig.RED, True, 0.0, False),
    ("ALSN", sig.GREEN, False, 0.0, False),              # a remembered code is no departure code
    ("digital", sig.GREEN, True, 120 * KMH, True), ("digital", sig.RED_YELLOW, True, 0.0, False),
    ("digital", sig.WHITE, False, 0.0, False), ("off", sig.WHITE, False, 0.0, True)])
def test_a_standing_train_may_start_only_on_a_valid_permissive_code(mode, aspect, valid, v_permitted, permits):
    assert _atp(mode).permits_departure(aspect, valid, v_permitted) is permits


def _code_from(t_code_s, before=(sig.WHITE, False)):
    """Cab signal: ``before`` (aspect, code_valid) until ``t_code_s``, then green."""
    return lambda t, x: before if t < t_code_s else (sig.GREEN, True)


@pytest.mark.parametrize("before", [(sig.WHITE, False), (sig.RED, True)])
def test_without_a_permissive_code_at_departure_the_train_waits_then_departs_normally(before):
    """Departure hold (docs/ato.md): no code (or red) at the departure time (60 s) → the brake
    stays on and the train does not move; the code arrives at 250 s → it departs and runs
    to B as it would, late by the hold."""
    code_s = 250.0
    result = run_closed_loop(900.0, cab_signal=_code_from(code_s, before))
    t, x, command = result.column("t"), result.column("x"), result.column("command")
    waiting = t < code_s
    assert np.ptp(x[waiting]) < 1e-6 and np.all(command[waiting] < 0)       # braked, not a centimetre moved
    assert result.ato.out.departure_hold_s == pytest.approx(code_s - 60.0, abs=0.6)
    assert x[t > code_s + 30].min() > x[0] + 50                              # away once the code came
    arrival = result.ato.arrivals[0]
    assert arrival["station"] == "B" and abs(arrival["stop_error_m"]) <= 0.5
    assert 0 < arrival["arrival_deviation_s"] <= code_s - 60.0               # late by at most the hold
    assert result.ato.atp.interventions == 0 and result.ato.atp.signals_passed_at_danger == 0


def test_a_code_at_departure_does_not_hold_the_train():
    result = run_closed_loop(200.0, cab_signal=_code_from(0.0))
    assert result.ato.out.departure_hold_s == 0.0
    t, x = result.column("t"), result.column("x")
    assert x[t < 60.0].max() == x[0] and x[-1] > x[0] + 500               # leaves at 60 s as before


# ---- driving to the timetable ------------------------------------------------------------------
@pytest.mark.parametrize("strategy", ["programme", "predictive"])
def test_nominal_run_is_on_time_on_the_mark_without_interventions(strategy):
    result = run_closed_loop(RUN_S, settings=AtoSettings(strategy=strategy, cab_signal="off"))
    _assert_on_time_and_on_the_mark(result)
    ato = result.ato
    assert ato.atp.interventions == 0 and ato.atp.max_overspeed_mps <= 0.0
    assert ato.out.mode_changes / LINE_KM <= 1.0


def test_energy_efficient_driving_saves_over_flat_out_with_8_percent_supplement(tmp_path):
    timetable = _timetable(tmp_path, 0.08)
    arrival_b = json.loads(timetable.read_text())["stops"][1]["arrival_s"]
    results = {s: run_closed_loop(RUN_S, timetable_file=timetable, settings=AtoSettings(strategy=s, cab_signal="off"))
               for s in ("programme", "predictive", "flat_out")}
    _assert_on_time_and_on_the_mark(results["programme"])
    _assert_on_time_and_on_the_mark(results["predictive"])
    flat_stage = results["flat_out"].energy_at_kwh(arrival_b - 20)   # stage A–B, all standing at B by then
    for strategy in ("programme", "predictive"):
        assert results[strategy].energy_at_kwh(arrival_b - 20) <= 0.9 * flat_stage
        assert results[strategy].energy_kwh <= 0.9 * results["flat_out"].energy_kwh


@pytest.mark.parametrize("mass, resistance, voltage", [
    (1.1, 1.2, 2850.0), (1.1, 0.8, 3150.0), (0.9, 1.2, 2850.0), (0.9, 0.8, 3150.0)])
@pytest.mark.parametrize("strategy", ["programme", "predictive"])
def test_robust_to_mass_resistance_and_voltage(tmp_path, strategy, mass, resistance, voltage):
    timetable = _timetable(tmp_path, 0.08)
    result = run_closed_loop(RUN_S, timetable_file=timetable, mass_scale=mass, resistance_scale=resistance,
                             pantograph_voltage_v=voltage, settings=AtoSettings(strategy=strategy, cab_signal="off"))
    _assert_on_time_and_on_the_mark(result)


def test_stop_point_moves_less_than_half_a_metre_between_step_sizes():
    errors = []
    for step in (0.1, 1.0):
        result = run_closed_loop(RUN_S, step_s=step, settings=AtoSettings(cab_signal="off"))
        errors.append([a["stop_error_m"] for a in result.ato.arrivals])
    assert np.max(np.abs(np.subtract(*errors))) < 0.5


def _red_signal_ahead(clear_s):
    """A train standing beyond signal 9 (15 200 m): red-yellow in 12 800..15 200, yellow before."""
    return red_signal_ahead(load_line(), 15200.0, clear_s)


def test_yellow_then_red_yellow_stops_before_the_red_signal_and_recovers():
    result = run_closed_loop(1300.0, cab_signal=_red_signal_ahead(900.0))
    ato = result.ato
    x, v = result.column("x"), result.column("v")
    aspects = result.column("aspect")
    held = (v <= 1e-3) & (x > 12800) & (x < 15200)
    assert held.any(), "the train did not stop before the red signal"
    assert 15200 - 40 <= x[held][0] < 15200
    assert ato.atp.signals_passed_at_danger == 0
    assert ato.atp.interventions == 0
    # never above the ATP's permitted speed by more than its service-intervention margin
    assert np.max(v - result.column("v_atp")) <= 5.5 * KMH
    seen = [int(a) for k, a in enumerate(aspects) if k == 0 or a != aspects[k - 1]]
    assert seen[:4] == [sig.GREEN, sig.YELLOW, sig.RED_YELLOW, sig.GREEN]
    # after the signal clears the train runs on and reaches C, late but on the mark
    assert [a["station"] for a in ato.arrivals] == ["B", "C"]
    assert abs(ato.arrivals[-1]["stop_error_m"]) <= 0.5


def test_after_a_restriction_the_ato_runs_at_the_permitted_speed_until_on_time():
    result = run_closed_loop(1300.0, cab_signal=_red_signal_ahead(900.0))
    t, v = result.column("t"), result.column("v")
    mode = result.column("mode")
    after = (t > 905) & (t < 960) & (v > 1.0)
    # full traction while late (no coasting) right after the aspect clears
    assert np.all(mode[after] == 1)


# ---- the FMU through the orchestrator ----------------------------------------------------------
def test_train_and_ato_through_the_orchestrator_meet_the_acceptance(tmp_path, product_fmus):
    out = tmp_path / "run"
    code, _, stderr = railcosim("run", "ato_only", "--output", str(out), "--no-build")
    assert code == 0, stderr
    summary = json.loads((out / "summary.json").read_text())
    (train,) = summary["trains"]
    assert [s["station"] for s in train["stops"]] == ["B", "C"]
    for stop in train["stops"]:
        assert abs(stop["arrival_deviation_s"]) <= 15.0 and abs(stop["stop_error_m"]) <= 0.5
    assert train["atp_interventions"] == 0 and train["signals_passed_at_danger"] == 0
    assert train["max_overspeed_kmh"] == 0.0 and train["energy_kwh"] > 100


def test_infeasible_timetable_through_the_cli_is_one_line_exit_2(tmp_path, product_fmus):
    tight = tmp_path / "tight.json"
    tight.write_text(json.dumps({"train": "t", "stops": [{"station": "A", "departure_s": 0},
                                                         {"station": "B", "arrival_s": 300}]}))
    code, _, stderr = railcosim("run", "ato_only", "--output", str(tmp_path / "out"), "--no-build",
                                "--set", f"ato.timetable_file={tight}")
    assert code == 2
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and "stops[1].arrival_s" in lines[0] and "minimum running time" in lines[0]
    assert "Traceback" not in stderr


def test_unknown_strategy_is_an_initialisation_error(tmp_path, product_fmus):
    code, _, stderr = railcosim("run", "ato_only", "--output", str(tmp_path / "out"), "--no-build",
                                "--set", "ato.strategy=fastest")
    assert code == 2 and "parameter strategy" in stderr


def test_heavy_freight_on_the_ac_line_keeps_time_and_stops_within_the_book_tolerance(tmp_path):
    """ВЛ80 + 62 wagons (5152 t), pneumatic brake with 8 s delay and 25 s build-up: the brake is
    released ahead of departure, the train is held back when running away downhill, and the stop
    meets the book's ±10 m for loco-hauled trains (docs/sources.md#ato-precise-stopping)."""
    from fmus.data.loader import DATA

    timetable = tmp_path / "freight.json"
    timetable.write_text(json.dumps({"train": "freight", "stops": [
        {"station": "A", "departure_s": 60}, {"station": "B", "arrival_s": 900, "departure_s": 960},
        {"station": "C", "arrival_s": 1800}]}))
    result = run_closed_loop(1900.0, line_file=DATA / "default_line_ac.json", stock_file=DATA / "freight_vl80.json",
                             timetable_file=timetable, settings=AtoSettings(cab_signal="off"))
    _assert_on_time_and_on_the_mark(result, arrival_s=15.0, stop_m=10.0)
    assert result.ato.atp.interventions == 0
    # and better: predictive stopping (docs/sources.md#ato-precise-stopping) reaches the ATOMIC class's 0.5 m with this
    # brake too; braking on the distance left alone stopped 1.7 m short at C
    _assert_on_time_and_on_the_mark(result, arrival_s=15.0, stop_m=0.5)


@pytest.mark.parametrize("stock_file, line_file, v0_kmh", [
    ("freight_vl80.json", "default_line_ac.json", 40.0),
    ("freight_vl80.json", "default_line_ac.json", 15.0),
    ("passenger_chs7.json", "default_line.json", 80.0),
    ("emu_er2.json", "default_line.json", 60.0),
])
def test_the_atos_predicted_stopping_point_is_where_the_train_stops(stock_file, line_file, v0_kmh):
    """The ATO's copy of the brake pipeline (delay, build-up, electric brake first and fading)
    predicts where the traction unit stops for a constant brake command, while a brake demand
    sent earlier is still on its way to the pneumatic brake: to 0.3 m over up to 890 m of
    braking, with the ATO's own prediction step for each brake (0.375–1 s)."""
    from fmus.ato_controller.stopping import NominalBrake, StopApproach
    from fmus.data.loader import DATA
    from fmus.traction.core import TractionCore

    line, stock = load_line(DATA / line_file), load_rolling_stock(DATA / stock_file)
    train = NominalTrain(stock, line)
    pipeline = NominalBrake(train)
    plant = TractionCore(stock, line, x0_m=3000.0, v0_mps=v0_kmh * KMH)
    t, step = 0.0, 0.5
    for command in (0.0, -0.4, -0.4):      # a demand in flight when the prediction is made
        pipeline.advance(t, plant.out.v_mps)
        pipeline.command(t, command, False)
        plant.step(t, step, command)
        t += step
    pipeline.advance(t, plant.out.v_mps)
    shares = np.array([0.2, 0.5, 1.0])
    dt_s = StopApproach(train, 0.02).dt_s                  # the ATO's own step for this brake
    predicted = pipeline.stopping_points(plant.out.x_m, plant.out.v_mps, shares, math.inf,
                                         lambda x: np.interp(x, *_path_table(train, 3000.0)), dt_s)
    for share, point in zip(shares, predicted):     # 55–890 m of braking
        run = copy.deepcopy(plant)
        clock = t
        while run.out.v_mps > 0.0 and clock < t + 600.0:
            run.step(clock, step, -share)
            clock += step
        assert abs(point - run.out.x_m) < 0.3, (share, point, run.out.x_m)


def _path_table(train, start_m):
    grid = np.arange(start_m, start_m + 6000.0, 5.0)
    return grid, train.path_accel(grid)


def test_free_run_with_the_alsn_chain_departs_on_a_decoded_green(tmp_path, product_fmus):
    """The default system, shortened to the first two joints: coder → rail line → receiver →
    ATP/ATO → train. The receiver decodes З at the origin, the ATP acts on it, the train departs
    on time and passes the joints at 2.6 and 5.2 km with no aspect artefact and no intervention
    (the full run is benchmarks/bench_free_run.py)."""
    out = tmp_path / "run"
    code, _, stderr = railcosim("run", "free_run", "--output", str(out), "--no-build", "--stop-time", "280",
                                "--record", "rx.aspect", "--record", "ato.atp_aspect", "--record", "train.x",
                                "--record", "train.v", "--record", "rail.occupied[1]")
    assert code == 0, stderr
    header, data = read_csv(out / "results.csv")
    col = {name: data[:, i] for i, name in enumerate(header)}
    settled = col["time"] > 6.0
    # the receiver loses the code for a moment at a joint (gain recovery, docs/sources.md#interference-at-insulated-joints);
    # its display holds green through it (the equipment's inertia) and never shows a wrong code
    assert np.all(col["rx.aspect"][settled] == sig.GREEN)
    assert np.all(col["ato.atp_aspect"][settled] == sig.GREEN)
    standing = (col["time"] > 1.0) & (col["time"] < 100.0)
    assert np.all(col["rail.occupied[1]"][standing] == 1)
    assert col["rail.occupied[1]"][-1] == 0                  # the tail has left section 1
    moving = col["train.v"] > 0.01
    assert 60.0 <= col["time"][moving][0] <= 61.0
    assert col["train.x"][-1] > 5250.0
    summary = json.loads((out / "summary.json").read_text())
    train = summary["trains"][0]
    assert train["atp_interventions"] == 0
    assert [a["aspect"] for a in train["aspects"]] == ["white", "green"]
