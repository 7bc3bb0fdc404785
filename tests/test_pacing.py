"""Real-time pacing (`railcosim run --real-time [FACTOR]`): deadlines, overrun counting, the
summary's real_time block and the line said when a run cannot keep pace. No test asserts a
wall time: the clock is simulated, or only the consistency of the counts is checked."""
import json

import pytest

from helpers import ComponentSpec, ConnectionSpec, railcosim, write_ssd
from orchestrator.errors import UserError
from orchestrator.pacing import Pacer
from orchestrator.run import RunOptions, run_system


class _FakeMaster:
    class graph:
        base_ticks = 10_000_000          # 10 ms


class _Clock:
    """A wall clock the test moves: each step's work takes ``work[i]`` seconds, a sleep what it
    asks, and each reading 1 µs (so the pacer's final spin ends)."""

    def __init__(self):
        self.now = 100.0
        self.slept = []

    def __call__(self):
        self.now += 1e-6
        return self.now

    def sleep(self, seconds):
        self.slept.append(seconds)
        self.now += seconds


def _pace(factor, work_s):
    clock = _Clock()
    pacer = Pacer(factor, clock=clock, sleep=clock.sleep)
    pacer.bound(_FakeMaster)
    tick = 0
    for work in work_s:
        pacer.before_tick(_FakeMaster, tick)
        clock.now += work
        tick += _FakeMaster.graph.base_ticks
    return pacer, clock


def test_steps_wait_for_their_deadlines_and_late_ones_are_counted():
    # 10 ms steps at real time; the third step's work takes 25 ms: the fourth starts 15 ms late,
    # the fifth 7 ms late (absolute deadlines: the run catches up instead of drifting)
    pacer, clock = _pace(1.0, [0.002, 0.002, 0.025, 0.002, 0.002, 0.002])
    assert pacer.steps == 6
    assert pacer.overruns == 2
    assert pacer.worst_lateness_s == pytest.approx(0.015, abs=1e-4)
    assert not pacer.kept_pace                   # a whole 10 ms step behind
    section = pacer.summary_section()["real_time"]
    assert section["overruns"] == 2 and section["worst_lateness_ms"] == pytest.approx(15.0, abs=0.1)
    assert section["mean_lateness_ms"] == pytest.approx(11.0, abs=0.1)
    assert "could not keep pace" in pacer.verdict_line() and "2 of 6" in pacer.verdict_line()
    # every wait ends on its deadline: the last step started at 100 + 5 × 10 ms
    assert clock.now - 0.002 == pytest.approx(100.05, abs=1e-4)


def test_a_faster_factor_shortens_the_deadlines():
    pacer, clock = _pace(4.0, [0.001] * 8)      # 10 ms of simulated time in 2.5 ms of wall time
    assert pacer.overruns == 0 and pacer.kept_pace and pacer.verdict_line() is None
    assert clock.now - 0.001 == pytest.approx(100.0 + 7 * 0.0025, abs=1e-4)
    assert pacer.summary_section()["real_time"]["step_wall_ms"] == pytest.approx(2.5)


def test_small_lateness_is_counted_but_keeps_pace():
    pacer, _ = _pace(1.0, [0.002, 0.013, 0.002])
    assert pacer.overruns == 1 and pacer.worst_lateness_s == pytest.approx(0.003, abs=1e-4)
    assert pacer.kept_pace and pacer.verdict_line() is None


@pytest.mark.parametrize("factor", [0.0, -1.0, float("nan"), 1e6])
def test_a_factor_out_of_range_is_refused(factor):
    with pytest.raises(UserError, match="--real-time"):
        Pacer(factor)




@pytest.mark.parametrize("factor", [1.0, 20.0])
def test_a_paced_run_reports_consistent_counts(tmp_path, test_fmus, factor):
    system = tmp_path / "paced"
    write_ssd(system, "paced", [
        ComponentSpec("fast", str(test_fmus / "TestCounter.fmu"), 0.01),
        ComponentSpec("slow", str(test_fmus / "TestCounter.fmu"), 0.05),
    ], [ConnectionSpec("slow.t_end", "fast.u")], stop_time=1.0)
    lines = []
    result = run_system(system, RunOptions(output_dir=tmp_path / "out", real_time=factor, warn=lines.append))
    block = json.loads((tmp_path / "out" / "summary.json").read_text())["real_time"]
    assert block == result.summary["real_time"]
    assert block["factor"] == factor
    assert block["steps"] == 100                          # one per 10 ms base step
    assert 0 <= block["overruns"] <= block["steps"]
    assert (block["overruns"] == 0) == (block["worst_lateness_ms"] == 0.0)
    assert block["step_wall_ms"] == pytest.approx(10.0 / factor)
    assert block["kept_pace"] == (block["worst_lateness_ms"] < block["step_wall_ms"])
    # a run that fell behind says so in one line; one that kept pace says nothing
    assert len(lines) == (0 if block["kept_pace"] else 1)
    assert result.steps_taken == {"fast": 100, "slow": 20}


def test_an_unpaced_run_has_no_real_time_block(tmp_path, test_fmus):
    system = tmp_path / "plain"
    write_ssd(system, "plain", [ComponentSpec("fast", str(test_fmus / "TestCounter.fmu"), 0.01)], [],
              stop_time=0.1)
    result = run_system(system, RunOptions(output_dir=tmp_path / "out"))
    assert "real_time" not in result.summary


def test_cli_real_time_without_a_factor_is_real_time_and_a_bad_one_is_one_line(tmp_path, test_fmus):
    system = tmp_path / "cli"
    write_ssd(system, "cli", [ComponentSpec("fast", str(test_fmus / "TestCounter.fmu"), 0.01)], [],
              stop_time=0.2)
    code, _, err = railcosim("run", system, "--no-build", "--real-time", "--output", tmp_path / "a")
    assert code == 0, err
    assert json.loads((tmp_path / "a" / "summary.json").read_text())["real_time"]["factor"] == 1.0
    code, _, err = railcosim("run", system, "--no-build", "--real-time", "0", "--output", tmp_path / "b")
    assert code == 2 and err.count("\n") == 1 and "--real-time 0" in err
