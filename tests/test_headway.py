"""railcosim headway: the blocking-time stairway on a hand-computable case, the trials' queue and
timetables, a co-simulated headway search on a short line that brackets, and bad input
(docs/capacity.md)."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from orchestrator.headway import blocking, trials
from orchestrator.headway.blocking import Trajectory

REPO = Path(__file__).resolve().parents[1]
DATA = REPO / "tests" / "data" / "headway"


def _constant_speed(speed_mps=20.0, start_m=0.0, stand_s=0.0, until_s=400.0):
    t = np.arange(0.0, until_s, 0.5)
    x = start_m + speed_mps * np.clip(t - stand_s, 0.0, None)
    v = np.where(t > stand_s, speed_mps, 0.0)
    return Trajectory(t, x, v)


def test_stairway_of_one_block_at_constant_speed_is_exact():
    # 20 m/s from 0 m at t = 0; block 1000-3000 m, approach point 500 m, a 200 m train:
    # approach 25 s, running 100 s, clearing 10 s; latency 4.5 s before, release 1 s after
    run = _constant_speed()
    (step,) = blocking.stairway(run, [(1000.0, 3000.0)], ["1"], [500.0], 200.0, 4.5, 1.0)
    assert step.parts_s == {"latency": 4.5, "approach": 25.0, "running": 100.0, "clearing": 10.0, "release": 1.0}
    assert step.start_s == 25.0 - 4.5 and step.end_s == 160.0 + 1.0
    assert step.duration_s == 140.5
    # identical trains: the headway is the blocking time, on that section
    assert blocking.minimum_headway_s([step], [step]) == (140.5, 0)


def test_a_train_standing_needs_its_indication_before_it_departs():
    # standing at 100 m until 30 s, then 20 m/s; the block it stands in is blocked from its
    # departure (less the latency): an approach point behind it counts from there
    run = _constant_speed(start_m=100.0, stand_s=30.0)
    (first, second) = blocking.stairway(run, [(0.0, 1000.0), (1000.0, 2000.0)], ["1", "2"], [None, 0.0],
                                        200.0, 4.0, 1.0)
    assert first.start_s == 30.0 - 4.0 and first.parts_s["approach"] == 0.0
    assert second.parts_s["approach"] == 45.0          # from the departure at 100 m to 1000 m
    assert second.end_s == 30.0 + (2200.0 - 100.0) / 20.0 + 1.0


def test_sections_not_cleared_are_left_out():
    run = _constant_speed(until_s=100.0)                # reaches 1980 m
    steps = blocking.stairway(run, [(0.0, 1000.0), (1000.0, 1900.0)], ["1", "2"], [None, None], 200.0, 0.0, 0.0)
    assert [s.section for s in steps] == [0]


def test_minimum_headway_of_different_trains_is_the_worst_section():
    slow = _constant_speed(speed_mps=10.0, until_s=800.0)
    fast = _constant_speed(speed_mps=40.0, until_s=800.0)
    blocks = [(0.0, 1000.0), (1000.0, 3000.0)]
    a = blocking.stairway(slow, blocks, ["1", "2"], [None, None], 100.0, 0.0, 0.0)
    b = blocking.stairway(fast, blocks, ["1", "2"], [None, None], 100.0, 0.0, 0.0)
    # a fast train behind a slow one: the last section it shares decides (slow clears 3100 m at 310 s,
    # fast enters 1000 m at 25 s)
    assert blocking.minimum_headway_s(a, b) == (310.0 - 25.0, 1)


def test_trial_plan_holds_each_follower_in_a_track_circuit_of_its_own(tmp_path):
    """No two trains share a track circuit at the start (docs/capacity.md#co-simulated-headway):
    the leader stands at the origin, each follower on a holding circuit of its own before the
    line, and calls at the origin (j − 1)·h after the leader; each ends in sidings of its own."""
    system = _short_system(tmp_path)
    base = trials.read_base(system)
    plan = trials.TrialPlan(base, 3)
    length = base.stock.length_m
    sections = plan.line_doc["block_sections"]
    assert [s["name"] for s in sections[:2]] == ["H3", "H2"] and sections[2]["start_m"] == plan.offset_m
    starts = [slot.start_m for slot in plan.slots]
    assert starts[0] == base.x0_m + plan.offset_m and plan.origin_slot is plan.slots[0]
    for slot in plan.slots[1:]:      # the whole train inside one holding circuit
        inside = [s for s in sections if s["start_m"] <= slot.start_m - length and slot.start_m <= s["end_m"]]
        assert [s["name"] for s in inside] == [f"H{slot.index}"]
    leader, last = plan.timetable(plan.slots[0], 0.0), plan.timetable(plan.slots[-1], 240.0)
    assert leader["stops"][0]["station"] == "A" and last["stops"][0]["station"] == "holding 3"
    assert last["stops"][1]["station"] == "A"
    assert last["stops"][1]["departure_s"] == pytest.approx(leader["stops"][0]["departure_s"] + 240.0)
    assert last["stops"][0]["departure_s"] >= 0.0 and leader["stops"][0]["departure_s"] > 0.0
    # positions judged are the base line's: the trial's less the holding tracks
    assert plan.timing_points_m()[0] == 0.0
    # every train ends in sidings of its own beyond the last track circuit, clear of each other
    sidings = sorted(slot.sidings_m for slot in plan.slots)
    assert sidings[0] - length >= 4200.0 + plan.offset_m and np.all(np.diff(sidings) >= length)


def _short_system(tmp_path: Path) -> Path:
    folder = tmp_path / "short"
    subprocess.run([sys.executable, "-m", "orchestrator", "new", str(folder), "--line", str(DATA / "short_line.json"),
                    "--timetable", str(DATA / "short_timetable.json")], check=True, cwd=REPO, capture_output=True)
    return folder


def _railcosim(*args, cwd):
    return subprocess.run([sys.executable, "-m", "orchestrator", *args], cwd=cwd, capture_output=True, text=True,
                          env={**__import__("os").environ, "PYTHONPATH": str(REPO)})


@pytest.mark.parametrize("args, says", [
    (["headway", "free_run", "--trains", "1"], "--trains 1: the co-simulated headway needs at least 2 trains"),
    (["headway", "free_run", "--trains", "0"], "--trains 0"),
    (["headway", "ato_only", "--method", "blocking"], "no signal chain"),
    (["headway", "following", "--method", "blocking"], "one train to copy"),
    (["headway", "no_such_system"], "not a shipped system"),
    (["headway", "free_run", "--method", "timetable"], "invalid choice"),
])
def test_bad_input_is_one_line_and_exit_2(tmp_path, args, says):
    result = _railcosim(*args, "--no-build", "-o", str(tmp_path / "out"), cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert says in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "Traceback" not in result.stderr


def test_headway_search_on_a_short_line_brackets_to_one_second(tmp_path):
    """Two trains on a 4 km ALSN line: the search ends with an unhindered trial at the headway it
    reports and a hindered one at most 1 s below it, every trial safe, the leader always as it
    runs alone."""
    system = _short_system(tmp_path)
    out = tmp_path / "headway"
    result = _railcosim("headway", str(system), "--trains", "2", "--format", "json", "-o", str(out), "--workers", "2",
                        cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    document = json.loads(result.stdout)
    for key in ("system", "cab_signal", "trains", "headway_blocking_s", "headway_cosim_s", "critical_section",
                "parts_s", "trials"):
        assert key in document
    found = document["headway_cosim_s"]
    outcomes = {t["headway_s"]: t for t in document["trials"]}
    assert outcomes[found]["hindered"] is False
    below = [h for h, t in outcomes.items() if t["hindered"] and h < found]
    assert below and found - max(below) <= 1.0
    for trial in document["trials"]:
        assert trial["verdict"] == "safe" and trial["signals_passed_at_danger"] == 0
        assert abs(trial["leader_late_s"]) <= trials.LATE_TOLERANCE_S
        assert Path(trial["run_dir"], "results.csv").is_file()
    assert set(document["parts_s"]) == set(blocking.PARTS)
    assert (out / "stairway.png").is_file() and (out / "report.html").is_file()
    assert json.loads((out / "headway.json").read_text())["headway_cosim_s"] == found
