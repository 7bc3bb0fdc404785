"""Every timetabled stop appears in summary.json, the CLI verdict line and the report's table:
reached (arrival, deviation, stop error) or ``reached: false`` with its scheduled arrival."""
import json

from helpers import railcosim


def test_a_run_ending_before_the_arrivals_lists_every_stop_as_not_reached(tmp_path, product_fmus):
    run = tmp_path / "run"
    code, stdout, stderr = railcosim("run", "ato_only", "--output", run, "--no-build", "--in-process",
                                     "--stop-time", "30")
    assert code == 0, stderr
    (train,) = json.loads((run / "summary.json").read_text())["trains"]
    assert [(s["station"], s["reached"], s["scheduled_arrival_s"], s["arrival_s"], s["arrival_deviation_s"])
            for s in train["stops"]] == [("B", False, 515.0, None, None), ("C", False, 1015.0, None, None)]
    assert "arrivals B not reached (due 515 s), C not reached (due 1015 s)" in stdout
    code, stdout, stderr = railcosim("report", run, "--output", tmp_path / "pictures")
    assert code == 0, stderr
    rows = [line.split() for line in stdout.splitlines() if line.startswith("train ")]
    assert ["train", "B", "515", "not", "reached"] in rows and ["train", "C", "1015", "not", "reached"] in rows


def test_stops_reached_and_missed_keep_timetable_order():
    from fmus.data.loader import TimetableStop
    from orchestrator.verdicts.verdict import TrainVerdict, _Train, missed_stops, stop_text

    train = _Train("train", "ato", [TimetableStop("A", 400.0, None, 60.0), TimetableStop("B", 10300.0, 515.0, 575.0),
                                    TimetableStop("C", 19600.0, 1015.0, None)])
    train.stops.append({"station": "B", "reached": True, "scheduled_arrival_s": 515.0, "arrival_s": 516.0,
                        "arrival_deviation_s": 1.0, "stop_error_m": -0.1, "stop_index": 2})
    stops = TrainVerdict.stops_of(train)
    assert [(s["station"], s["reached"]) for s in stops] == [("B", True), ("C", False)]
    assert "stop_index" not in stops[0]
    assert [stop_text(s) for s in stops] == ["B +1.0 s / -0.10 m", "C not reached (due 1015 s)"]
    assert missed_stops({"trains": [{"name": "train", "stops": stops}]}) == [("train", "C")]
