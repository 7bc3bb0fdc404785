"""UIC 406 compression and capacity consumption (orchestrator/headway/capacity.py)."""
import json

import numpy as np
import pytest

from orchestrator.errors import UserError
from orchestrator.headway import blocking, capacity
from orchestrator.headway.blocking import BlockingTime, Trajectory


def _constant_speed(start_s: float) -> Trajectory:
    # head from -500 m at 10 m/s from start_s: approach point -300 m at +20 s, block entry 0 m
    # at +50 s, exit 1000 m at +150 s, tail clear (100 m train) at +160 s
    t = np.arange(0.0, 201.0)
    return Trajectory(t + start_s, -500.0 + 10.0 * t, np.full_like(t, 10.0))


def test_two_trains_on_one_block_compress_to_their_blocking_time():
    steps = [blocking.stairway(_constant_speed(s), [(0.0, 1000.0)], ["1"], [-300.0], 100.0, 2.0, 3.0)
             for s in (0.0, 300.0)]
    # blocking: 20 - 2 latency = 18 s to 160 + 3 release = 163 s: 145 s
    assert (steps[0][0].start_s, steps[0][0].end_s) == pytest.approx((18.0, 163.0))
    out = capacity.consumption(steps, ["a", "b"], [0.0, 300.0])
    # b moved 155 s earlier, to depart 145 s after a; the next period's a 145 s after b
    assert out["compressed_departures_s"] == [0.0, 145.0]
    assert [h["headway_s"] for h in out["headways"]] == [145.0, 145.0]
    assert out["compressed_s"] == 290.0
    # the window: 2 trains × the 300 s mean interval
    assert out["window_s"] == 600.0
    assert out["consumption_line"] == pytest.approx(290.0 / 600.0, abs=1e-4)
    section = out["sections"][0]
    assert section["occupied_s"] == 290.0 and section["consumption"] == out["consumption_line"]
    assert out["critical_section"]["section"] == 0


def _steps(*times):
    return [BlockingTime(k, str(k), 1000.0 * k, 1000.0 * (k + 1), 1000.0 * k, a, b, {})
            for k, (a, b) in times]


def test_a_train_is_compressed_against_every_train_before_not_only_the_last():
    a = _steps((0, (0.0, 100.0)), (1, (100.0, 200.0)))
    b = _steps((0, (300.0, 340.0)))                          # leaves the line after section 0
    c = _steps((0, (600.0, 650.0)), (1, (650.0, 800.0)))
    result = capacity.compress([a, b, c], ["a", "b", "c"], [0.0, 300.0, 600.0])
    # against b alone c could go 460 s earlier; a's section 1 (ends 200 s) allows only 450 s
    assert result.shifts_s == [0.0, -200.0, -450.0]
    assert result.headways[1]["binding"] == "a" and result.headways[1]["section"] == 1
    # the compressed stairways overlap nowhere
    for i, first in enumerate(result.stairways):
        for second in result.stairways[i + 1:]:
            for x in first:
                for y in second:
                    assert x.section != y.section or y.start_s >= x.end_s - 1e-9


def test_a_system_of_one_train_is_one_line():
    with pytest.raises(UserError, match="at least two trains; it has 1"):
        capacity.read_trains("ssp/free_run")


def test_the_following_system_compressed(product_fmus, tmp_path):
    out = capacity.capacity("ssp/following", [product_fmus], tmp_path)
    assert out["trains"] == ["leader", "follower"]
    assert json.loads((tmp_path / "capacity.json").read_text())["compressed_s"] == out["compressed_s"]
    # the leader keeps its time; the follower (timetabled 370 s behind, running through B where
    # the leader stops) goes to the least interval at which no section overlaps: later than its
    # timetable, the timetable asking more than the line allows (docs/capacity.md: over 100 %)
    leader, follower = out["compressed_departures_s"]
    assert leader == 60.0 and follower > 430.0 and out["consumption_line"] > 1.0
    # their stairways touch on one section and overlap on none
    shift = follower - 430.0
    ends = {b["section"]: b["end_s"] for b in out["stairways"]["leader"]}
    gaps = {b["section"]: b["start_s"] + shift - ends[b["section"]] for b in out["stairways"]["follower"]
            if b["section"] in ends}
    touching = min(gaps, key=gaps.get)
    assert gaps[touching] == pytest.approx(0.0, abs=0.02)
    assert out["headways"][0]["section"] == touching
    assert out["window_s"] == 740.0
    assert out["consumption_line"] == pytest.approx(out["compressed_s"] / 740.0, abs=1e-4)
    assert out["critical_section"]["consumption"] == max(s["consumption"] for s in out["sections"])
