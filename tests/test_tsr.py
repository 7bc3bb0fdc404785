"""Temporary speed restrictions (warnings): the line file's list and the scenario's ``restrict``
events; supervised by the ATP (braking curve to the start, held until the tail clears the end),
planned by the ATO (brake to v_limit, then a traction–coast band down to v_limit − 8 km/h)."""
import json
from pathlib import Path

import numpy as np
import pytest

from harness.closed_loop import run_closed_loop
from fmus.ato_controller.atp import NO_INTERVENTION, Atp
from fmus.ato_controller.supervision import dv_ebi_mps
from fmus.ato_controller.core import MODE_COAST, RESTRICTION_BAND_MPS, AtoCore, AtoSettings
from fmus.data.loader import (DEFAULT_LINE, DEFAULT_ROLLING_STOCK, TemporaryRestriction, load_line, load_rolling_stock,
                              load_timetable)
from fmus.errors import FmuInputError
from fmus.traction.core import TractionCore
from orchestrator.errors import UserError
from orchestrator.scenario import load_scenario

KMH = 1 / 3.6
TSR = {"name": "track works", "start_m": 5000, "end_m": 6000, "speed_kmh": 40}
TRAIN_LENGTH_M = 388.0          # ЧС7 + 14 coaches (the default rolling stock)
# the default line's stops with room in the running times for a 40 km/h restriction
SLOW_TIMETABLE = {"train": "slow", "stops": [{"station": "A", "departure_s": 60},
                                             {"station": "B", "arrival_s": 640, "departure_s": 700},
                                             {"station": "C", "arrival_s": 1200}]}


def _line_with(tmp_path, *restrictions) -> Path:
    document = json.loads(Path(DEFAULT_LINE).read_text())
    document["temporary_restrictions"] = list(restrictions)
    path = tmp_path / "line_tsr.json"
    path.write_text(json.dumps(document))
    return path


def _timetable(tmp_path) -> Path:
    path = tmp_path / "slow.json"
    path.write_text(json.dumps(SLOW_TIMETABLE))
    return path


# ---- line file ---------------------------------------------------------------------------------
def test_the_line_file_lists_restrictions_per_category(tmp_path):
    line = load_line(_line_with(tmp_path, TSR, {"start_m": 8000, "end_m": 8500, "speed_kmh": 60,
                                                "categories": ["freight"]}))
    assert [r.name for r in line.restrictions] == ["track works", ""]
    assert line.restrictions[0] == TemporaryRestriction(5000.0, 6000.0, 40 * KMH, ("passenger", "freight", "high_speed"),
                                                        "track works")
    assert [r.start_m for r in line.restrictions_for("passenger")] == [5000.0]
    assert [r.start_m for r in line.restrictions_for("freight")] == [5000.0, 8000.0]


@pytest.mark.parametrize("restriction, field", [
    ({"start_m": 6000, "end_m": 5000, "speed_kmh": 40}, "temporary_restrictions[0].end_m"),
    ({"start_m": 5000, "end_m": 90000, "speed_kmh": 40}, "temporary_restrictions[0].end_m"),
    ({"start_m": 5000, "end_m": 6000}, "temporary_restrictions[0].speed_kmh"),
    ({"start_m": 5000, "end_m": 6000, "speed_kmh": 2}, "temporary_restrictions[0].speed_kmh"),
    ({"start_m": 5000, "end_m": 6000, "speed_kmh": 40, "categories": ["metro"]},
     "temporary_restrictions[0].categories[0]"),
    ({"start_m": 5000, "end_m": 6000, "speed_kmh": 40, "speed": 3}, "temporary_restrictions[0]"),
])
def test_a_bad_restriction_is_one_line_naming_the_field(tmp_path, restriction, field):
    with pytest.raises(FmuInputError) as error:
        load_line(_line_with(tmp_path, restriction))
    message = str(error.value)
    assert f"field {field}" in message and "\n" not in message


# ---- ATP ---------------------------------------------------------------------------------------
def test_the_atp_supervises_a_braking_curve_to_the_start_and_holds_until_the_tail_clears(tmp_path):
    atp = Atp(load_line(_line_with(tmp_path, TSR)), "passenger", TRAIN_LENGTH_M, "off", 0.63, 4.22)
    ahead = atp.supervise(0.0, 4500.0, 30.0, 0, True, 0, 0, 0)
    assert ahead.permitted_mps == pytest.approx(np.sqrt((40 * KMH) ** 2 + 2 * 0.63 * 500.0))
    assert atp.supervise(1.0, 5000.0, 10.0, 0, True, 0, 0, 0).ceiling_mps == pytest.approx(40 * KMH)
    # head past the end, tail still inside: still in force; tail clear: lifted
    assert atp.supervise(2.0, 6000.0 + TRAIN_LENGTH_M - 1.0, 10.0, 0, True, 0, 0, 0).ceiling_mps == pytest.approx(40 * KMH)
    assert atp.supervise(3.0, 6000.0 + TRAIN_LENGTH_M + 1.0, 10.0, 0, True, 0, 0, 0).ceiling_mps > 100 * KMH


# ---- closed loop: ATO + train ------------------------------------------------------------------
def _restrict_at(time_s, restriction):
    """A restriction given to the ATO at ``time_s``, as a scenario event would give it."""
    def before_step(t, ato):
        if t == time_s:
            ato.set_restrictions([restriction])
    return before_step


def _inside(x):
    return (x >= TSR["start_m"]) & (x - TRAIN_LENGTH_M < TSR["end_m"])


def test_the_train_runs_through_a_restriction_at_or_below_its_speed_without_intervention(tmp_path):
    result = run_closed_loop(1300.0, line_file=_line_with(tmp_path, TSR), timetable_file=_timetable(tmp_path))
    x, v, mode = result.column("x"), result.column("v"), result.column("mode")
    inside = _inside(x)
    assert inside.any() and v[inside].max() <= 40 * KMH
    # the book's band: traction–coast between v_limit − 8 km/h and the limit
    assert v[inside].min() >= 40 * KMH - RESTRICTION_BAND_MPS - 0.3
    assert (mode[inside] == MODE_COAST).any()
    assert result.ato.atp.interventions == 0
    assert [a["station"] for a in result.ato.arrivals] == ["B", "C"]
    assert all(abs(a["arrival_deviation_s"]) <= 15.0 for a in result.ato.arrivals)


def test_the_atp_intervenes_when_the_ato_ignores_the_restriction(tmp_path):
    """The ATO drives from a line file without the restriction; the ATP knows it."""
    line_tsr = load_line(_line_with(tmp_path, TSR))
    line = load_line()
    stock = load_rolling_stock(DEFAULT_ROLLING_STOCK)
    timetable_path = _timetable(tmp_path)
    ato = AtoCore(line, stock, load_timetable(timetable_path, line), timetable_path, "passenger",
                  AtoSettings(cab_signal="off"))
    atp = Atp(line_tsr, "passenger", stock.length_m, "off", ato.atp.decel, 4.22)
    train = TractionCore(stock, line, x0_m=400.0)
    state, interventions, at_start = train.out, [], None
    for k in range(int(700.0 / 0.5)):
        t = k * 0.5
        out = ato.step(t, 0.5, state.x_m, state.v_mps)
        supervised = atp.supervise(t, state.x_m, state.v_mps, 0, True, 0, 0, 0)
        command, emergency = out.command, False
        if supervised.intervention != NO_INTERVENTION:
            interventions.append(t)
            command, emergency = -1.0, supervised.intervention == 2
        if at_start is None and state.x_m >= TSR["start_m"]:
            at_start = state.v_mps
        state = train.step(t, 0.5, command, emergency)
    assert interventions and atp.interventions >= 1
    # the intervention brings the train to the restriction within the emergency margin
    assert at_start is not None and at_start <= 40 * KMH + dv_ebi_mps(at_start)
    print(f"ATP interventions {atp.interventions} (emergency {atp.emergency_brakings}), "
          f"at the start {at_start / KMH:.1f} km/h")


def test_a_restriction_set_while_running_is_kept(tmp_path):
    """Set at 100 s (the train near 2 km), 5–6 km at 40 km/h: the ATO brakes for it, no intervention."""
    loop = run_closed_loop(800.0, timetable_file=_timetable(tmp_path),
                           before_step=_restrict_at(100.0, TemporaryRestriction(5000.0, 6000.0, 40 * KMH)))
    ato, x, v = loop.ato, loop.column("x"), loop.column("v")
    assert v[_inside(x)].max() <= 40 * KMH
    assert ato.atp.interventions == 0 and [a["station"] for a in ato.arrivals] == ["B"]


# ---- scenario events ---------------------------------------------------------------------------
def test_a_restrict_event_sets_the_next_tsr_slot_and_lifts_it(tmp_path):
    path = tmp_path / "scenario.json"
    path.write_text(json.dumps({"events": [
        {"time": 100, "model": "ato", "action": "restrict", "start_m": 5000, "end_m": 6000, "speed_kmh": 36,
         "until": 400},
        {"time": 120, "model": "ato", "action": "restrict", "start_m": 9000, "end_m": 9500, "speed_kmh": 72}]}))
    events = [(e.time_s, e.variable, e.action, e.value) for e in load_scenario(path).events]
    assert events == [(100.0, "tsr_start[1]", "set", 5000.0), (100.0, "tsr_end[1]", "set", 6000.0),
                      (100.0, "tsr_speed[1]", "set", 10.0),
                      (120.0, "tsr_start[2]", "set", 9000.0), (120.0, "tsr_end[2]", "set", 9500.0),
                      (120.0, "tsr_speed[2]", "set", 20.0),
                      (400.0, "tsr_start[1]", "reset", None), (400.0, "tsr_end[1]", "reset", None),
                      (400.0, "tsr_speed[1]", "reset", None)]


def test_a_slot_lifted_is_taken_again_by_a_later_restriction(tmp_path):
    path = tmp_path / "scenario.json"
    # five restrictions in file order (not time order), at most two in force at once
    times = [(300, 500), (100, 200), (200, 400), (150, None), (450, 600)]
    path.write_text(json.dumps({"events": [
        {"time": t, "model": "ato", "action": "restrict", "start_m": 1000 * k, "end_m": 1000 * k + 500,
         "speed_kmh": 40, **({} if until is None else {"until": until})} for k, (t, until) in enumerate(times)]}))
    starts = [(e.time_s, e.variable, e.action) for e in load_scenario(path).events if e.variable.startswith("tsr_start")]
    assert starts == [(100.0, "tsr_start[1]", "set"), (150.0, "tsr_start[2]", "set"),
                      (200.0, "tsr_start[1]", "reset"), (200.0, "tsr_start[1]", "set"),
                      (300.0, "tsr_start[3]", "set"), (400.0, "tsr_start[1]", "reset"),
                      (450.0, "tsr_start[1]", "set"), (500.0, "tsr_start[3]", "reset"),
                      (600.0, "tsr_start[1]", "reset")]


def test_more_restrictions_in_force_than_slots_is_one_line_naming_the_event(tmp_path, product_fmus):
    from helpers import railcosim

    path = tmp_path / "scenario.json"
    path.write_text(json.dumps({"events": [
        {"time": 100 + k, "model": "ato", "action": "restrict", "start_m": 1000 * k, "end_m": 1000 * k + 500,
         "speed_kmh": 40} for k in range(5)]}))
    code, _, stderr = railcosim("validate", "ato_only", "--scenario", path)
    assert code == 2 and len(stderr.strip().splitlines()) == 1, stderr
    assert "field events[4]: more restrictions in force at once on ato than its 4 tsr_* input slots" in stderr
    path.write_text(json.dumps({"events": [
        {"time": 100, "model": "train", "action": "restrict", "start_m": 0, "end_m": 500, "speed_kmh": 40}]}))
    code, _, stderr = railcosim("validate", "ato_only", "--scenario", path)
    assert code == 2 and "field events[0].model: train takes no restrictions" in stderr, stderr


@pytest.mark.parametrize("event, field", [
    ({"end_m": 6000, "speed_kmh": 40}, "events[0].start_m"),
    ({"start_m": 6000, "end_m": 5000, "speed_kmh": 40}, "events[0].end_m"),
    ({"start_m": 5000, "end_m": 6000, "speed_kmh": 0}, "events[0].speed_kmh"),
    ({"start_m": 5000, "end_m": 6000, "speed_kmh": 40, "until": 50}, "events[0].until"),
])
def test_a_bad_restrict_event_names_the_field(tmp_path, event, field):
    path = tmp_path / "scenario.json"
    path.write_text(json.dumps({"events": [{"time": 100, "model": "ato", "action": "restrict", **event}]}))
    with pytest.raises(UserError) as error:
        load_scenario(path)
    assert f"field {field}:" in str(error.value) and "\n" not in str(error.value)


# ---- through the FMUs, the CLI and the report ----------------------------------------------------
def test_a_restrict_event_through_the_fmu_is_kept_and_drawn_in_the_report(tmp_path, product_fmus):
    from helpers import railcosim, read_csv
    from orchestrator.reports.report import _line_of, restrictions_drawn

    scenario = tmp_path / "tsr.json"
    scenario.write_text(json.dumps({"events": [
        {"time": 100, "model": "ato", "action": "restrict", "start_m": 5000, "end_m": 6000, "speed_kmh": 40}]}))
    out = tmp_path / "run"
    code, _, stderr = railcosim("run", "ato_only", "--output", out, "--no-build", "--scenario", scenario,
                                "--stop-time", "700")
    assert code == 0, stderr
    header, data = read_csv(out / "results.csv")
    x, v = data[:, header.index("train.x")], data[:, header.index("train.v")]
    assert v[_inside(x)].size and v[_inside(x)].max() <= 40 * KMH
    summary = json.loads((out / "summary.json").read_text())
    assert summary["trains"][0]["atp_interventions"] == 0
    code, _, stderr = railcosim("report", out)
    assert code == 0, stderr
    assert (out / "speed_distance.png").is_file()
    metadata = json.loads((out / "metadata.json").read_text())
    components = metadata["components"]
    drawn = restrictions_drawn(_line_of(components, "ato"), components, "ato",
                               summary["scenario"]["events_applied"])
    assert drawn == [(5.0, 6.0, pytest.approx(40.0), "set at 100 s")]


def test_after_a_restriction_the_ato_runs_at_the_permitted_speed_until_on_time():
    """The book's recovery: late when a restriction clears → maximum permitted speed (full
    traction, no coasting) until back on schedule, also once less than 16 s late."""
    loop = run_closed_loop(560.0, before_step=_restrict_at(100.0, TemporaryRestriction(7000.0, 7400.0, 70 * KMH)))
    x, mode, deviation = loop.column("x"), loop.column("mode"), loop.column("deviation")
    cleared = x > 7400.0 + TRAIN_LENGTH_M
    first = np.argmax(cleared)
    assert 0.0 < deviation[first] < 30.0
    late = cleared & (np.arange(x.size) >= first) & (np.maximum.accumulate(deviation[::-1])[::-1] > 0.5)
    recovering = late & (x < 9000.0)              # before braking for B
    assert recovering.sum() > 20 and not (mode[recovering] == MODE_COAST).any()
