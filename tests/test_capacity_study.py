"""The capacity_ato study's run (orchestrator/headway/interval_study.py): intervals measured on
a real co-simulation, a late leader holding its follower through the signal chain."""
import csv
from pathlib import Path

import pytest

from orchestrator.headway import interval_study
from orchestrator.packaging.builder import build_sizes
from orchestrator.systems.queued import TrialPlan, read_base

REPO = Path(__file__).resolve().parent.parent


def _first_passing_s(results_csv, train, point_m):
    with open(results_csv, newline="") as handle:
        rows = list(csv.DictReader(handle))
    for row in rows:
        if float(row[f"{train}.x"]) >= point_m:
            return float(row["time"])
    return None


def test_a_late_leader_holds_its_follower_and_the_interval_is_measured(product_fmus, tmp_path):
    # the leader 300 s late: its follower is scheduled 1.3 × headway − 300 s behind it, well
    # less than the headway (blocking 459 s, co-simulated 453 s), and must be held by its codes
    plan = TrialPlan(read_base(REPO / "ssp" / "free_run"), 2)       # the chain for its holding circuit
    build_sizes(product_fmus, [{"sections": plan.sections, "trains": 2, "frame": 40}])
    out = interval_study.interval_trial("ato", 0, trains=2, build_dir=str(product_fmus), keep_in=str(tmp_path),
                                        deviations_s=[300.0, 0.0])
    scheduled_gap = out["scheduled_passing_s"][1] - out["scheduled_passing_s"][0]
    assert scheduled_gap == pytest.approx(out["scheduled_interval_s"] - 300.0, abs=0.01)
    assert scheduled_gap < out["headway_blocking_s"]
    # the intervals, read back from the run's own results.csv (sampled every 0.5 s)
    # (results.csv holds the trial line's positions: the base line's plus the holding tracks)
    passed = [_first_passing_s(tmp_path / "run" / "results.csv", t, out["timing_point_m"] + plan.offset_m)
              for t in ("train1", "train2")]
    assert out["interval_1_s"] == pytest.approx(passed[1] - passed[0], abs=0.6)
    assert out["passing_s"][0] == pytest.approx(passed[0], abs=0.6)
    # the leader runs as it would alone; the follower is held well past its schedule
    assert abs(out["delays_s"][0]) < 2.0
    assert out["delays_s"][1] > 5.0 and out["held"] == [True]
    assert out["interval_1_s"] > scheduled_gap + 5.0
    assert out["signals_passed_at_danger"] == 0
    assert out["rms_s"] == pytest.approx(abs(out["interval_1_s"] - out["scheduled_interval_s"]), abs=0.01)
