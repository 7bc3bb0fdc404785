"""Timed events (scenario files): set / bias / reset on linked and unconnected inputs and on
outputs, applied at the right tick; bad scenario files give one clear line."""
import json

import pytest

from helpers import ComponentSpec, ConnectionSpec, railcosim, read_csv, write_ssd
from orchestrator.verdicts.verdict import railway_verdicts
from orchestrator.run import RunOptions, run_system


def _system(tmp_path, fmus):
    system = tmp_path / "pair"
    write_ssd(system, "pair", [
        ComponentSpec("a", str(fmus / "TestCounter.fmu"), 0.1),
        ComponentSpec("b", str(fmus / "TestCounter.fmu"), 0.1),
    ], [ConnectionSpec("a.t_end", "b.u")], stop_time=3.0)
    return system


def _scenario(tmp_path, events, **extra):
    path = tmp_path / "scenario.json"
    path.write_text(json.dumps({"description": "test", "events": events, **extra}))
    return path


def _run(tmp_path, fmus, events, **extra):
    out = tmp_path / "out"
    result = run_system(_system(tmp_path, fmus), RunOptions(summaries=railway_verdicts, output_dir=out, output_interval=0.1,
                                                            scenario=_scenario(tmp_path, events, **extra)))
    header, data = read_csv(out / "results.csv")
    rows = {round(row[0], 3): dict(zip(header, row)) for row in data}
    return result, rows


def test_set_bias_and_reset_on_a_linked_and_an_unconnected_input(tmp_path, test_fmus):
    events = [
        {"time": 1.0, "model": "b", "variable": "u", "action": "bias", "value": 100.0},
        {"time": 1.5, "model": "a", "variable": "u", "action": "set", "value": 7.0},
        {"time": 2.0, "model": "b", "variable": "u", "action": "override", "value": -5.0},
        {"time": 2.5, "model": "b", "variable": "u", "action": "reset"},
    ]
    result, rows = _run(tmp_path, test_fmus, events)
    # b.u_seen is the input b saw in its step ending at the row's time
    assert rows[1.0]["b.u_seen"] == pytest.approx(1.0)          # a.t_end after a's step to 1.0 (Gauss-Seidel)
    assert rows[1.1]["b.u_seen"] == pytest.approx(101.1)        # biased from the tick at 1.0
    assert rows[1.5]["a.u_seen"] == 0.0 and rows[1.6]["a.u_seen"] == 7.0
    assert rows[2.1]["b.u_seen"] == -5.0 and rows[2.5]["b.u_seen"] == -5.0
    assert rows[2.6]["b.u_seen"] == pytest.approx(2.6)          # reset: the link again
    applied = result.summary["scenario"]["events_applied"]
    assert [(e["t"], e["action"]) for e in applied] == [(1.0, "bias"), (1.5, "set"), (2.0, "set"), (2.5, "reset")]


@pytest.mark.parametrize("in_process", [False, True])
def test_an_input_set_back_to_an_earlier_value_reaches_the_fmu(tmp_path, test_fmus, in_process):
    # the master skips writing an input buffer that has not changed: A → B → A must still arrive
    events = [{"time": 1.0, "model": "a", "variable": "u", "action": "set", "value": 7.0},
              {"time": 1.5, "model": "a", "variable": "u", "action": "reset"},
              {"time": 2.0, "model": "a", "variable": "u", "action": "set", "value": 7.0}]
    out = tmp_path / "out"
    run_system(_system(tmp_path, test_fmus), RunOptions(summaries=railway_verdicts, output_dir=out, output_interval=0.1, in_process=in_process,
                                                        scenario=_scenario(tmp_path, events)))
    header, data = read_csv(out / "results.csv")
    seen = {round(row[0], 3): dict(zip(header, row))["a.u_seen"] for row in data}
    assert [seen[t] for t in (1.0, 1.1, 1.4, 1.5, 1.6, 1.9, 2.0, 2.1, 3.0)] == [0, 7, 7, 7, 0, 0, 0, 7, 7]


def test_an_event_on_an_output_is_what_every_consumer_and_the_recorder_see(tmp_path, test_fmus):
    _, rows = _run(tmp_path, test_fmus, [{"time": 2.0, "model": "a", "variable": "t_end", "action": "set", "value": 42}])
    assert rows[2.0]["a.t_end"] == pytest.approx(2.0)
    assert rows[2.1]["a.t_end"] == 42.0 and rows[2.1]["b.u_seen"] == 42.0


def test_scenario_end_sets_the_stop_time(tmp_path, test_fmus):
    result, _ = _run(tmp_path, test_fmus, [], end=1.2)
    assert result.end_time_s == pytest.approx(1.2)


@pytest.mark.parametrize("events, message", [
    ([{"time": 1, "model": "c", "variable": "u", "action": "set", "value": 1}], "events[0].model: no component 'c'"),
    ([{"time": 1, "model": "a", "variable": "w", "action": "set", "value": 1}], "events[0].variable: a has no variable 'w'"),
    ([{"time": 1, "model": "a", "variable": "fail_at", "action": "set", "value": 1}], "is a parameter"),
    ([{"time": -1, "model": "a", "variable": "u", "action": "set", "value": 1}], "events[0].time"),
    ([{"time": 1, "model": "a", "variable": "u", "action": "jump", "value": 1}], "events[0].action: 'jump'"),
    ([{"time": 1, "model": "a", "variable": "u", "action": "set"}], "events[0].value: required"),
    ([{"time": 1, "model": "a", "variable": "steps", "action": "set", "value": 1.5}], "1.5 is not a Integer"),
])
def test_bad_scenarios_name_the_event_and_field(tmp_path, test_fmus, events, message):
    system = _system(tmp_path, test_fmus)
    code, _, stderr = railcosim("run", system, "--output", tmp_path / "out", "--no-build",
                                "--scenario", _scenario(tmp_path, events))
    assert code == 2 and message in stderr and "Traceback" not in stderr
    assert len(stderr.strip().splitlines()) == 1


def test_a_missing_or_broken_scenario_file(tmp_path, test_fmus):
    system = _system(tmp_path, test_fmus)
    code, _, stderr = railcosim("run", system, "--no-build", "--output", tmp_path / "o", "--scenario", tmp_path / "no.json")
    assert code == 2 and "scenario file not found" in stderr
    broken = tmp_path / "broken.json"
    broken.write_text("{")
    code, _, stderr = railcosim("run", system, "--no-build", "--output", tmp_path / "o", "--scenario", broken)
    assert code == 2 and "not valid JSON" in stderr
