"""A run's progress (``railcosim run --progress auto|bar|lines|none``): into a log a line every few
seconds with the simulated time, the elapsed wall time, the stepping's real-time factor and the
time still to go; on a terminal a bar redrawn in place; the initialisation said and timed; at the
end the wall time parted into initialisation and stepping, in the first line and summary.json,
and the command that draws the run."""
import io
import json
import os
import pty
import re
import select
import subprocess
import sys
import time

import pytest

from helpers import PROGRESS_LINE, cli_environment, railcosim, without_progress
from orchestrator.observers import Progress, duration_text
from orchestrator.protocols import StepRecord

LINE = re.compile(r"t=(?P<t>\d+\.\d)/(?P<stop>\d+) s  (?P<pct>\d+)%  elapsed (?P<elapsed>\d+ s|\d+ m \d+ s)  "
                  r"ETA (?P<eta>\d+ s|\d+ m \d+ s|\d+ h \d+ m)  RTF (?P<rtf>\d+\.\d)×")
FIRST = re.compile(r"free_run: (?P<sim>[\d.]+) s simulated in (?P<wall>[\d.]+) s \(initialisation (?P<init>[\d.]+) s, "
                   r"then (?P<rtf>[\d.]+)x real time\); results in (?P<out>.+)")


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def _step(time_s: float) -> StepRecord:
    return StepRecord(tick=round(time_s * 1e9), time_s=time_s, stepped=())


def test_without_a_terminal_a_run_writes_progress_lines_with_eta(tmp_path, product_fmus):
    """The acceptance of issue 50: `railcosim run free_run > log 2>&1` (here every 0.5 s)."""
    out = tmp_path / "run"
    code, stdout, stderr = railcosim("run", "free_run", "--no-build", "--stop-time", "120", "--output", out,
                                     "--progress-interval", "0.5")
    assert code == 0, stderr
    lines = [LINE.fullmatch(line) for line in stderr.splitlines() if line.startswith("t=")]
    assert len(lines) >= 2 and all(lines), stderr
    times = [float(m["t"]) for m in lines]
    assert times == sorted(times) and 0 < times[0] and times[-1] <= 120 and {m["stop"] for m in lines} == {"120"}
    assert all(float(m["rtf"]) > 0 for m in lines)
    assert re.search(r"^initialised 5 components in \d+\.\d s$", stderr, re.M) or "initialising" not in stderr
    assert without_progress(stderr) == "" and all(PROGRESS_LINE.match(line) for line in stderr.splitlines())
    first, *_, hint = stdout.splitlines()
    match = FIRST.fullmatch(first)
    assert match and match["out"] == str(out), first
    assert hint == f"  draw it: railcosim report {out}"
    summary = json.loads((out / "summary.json").read_text())
    assert summary["init_wall_time_s"] + summary["stepping_wall_time_s"] == pytest.approx(summary["wall_time_s"])
    assert summary["stepping_realtime_factor"] == pytest.approx(summary["sim_time_s"] / summary["stepping_wall_time_s"])
    assert summary["realtime_factor"] == pytest.approx(summary["sim_time_s"] / summary["wall_time_s"])
    assert summary["stepping_realtime_factor"] > summary["realtime_factor"]
    assert float(match["init"]) == pytest.approx(summary["init_wall_time_s"], abs=5e-4)
    assert float(match["rtf"]) == pytest.approx(summary["stepping_realtime_factor"], abs=0.05)


def test_progress_none_and_a_run_shorter_than_the_interval_print_no_progress(tmp_path, product_fmus):
    for extra in (["--progress", "none", "--progress-interval", "0.1"], ["--progress", "lines"]):
        code, stdout, stderr = railcosim("run", "ato_only", "--no-build", "--stop-time", "60", "--output",
                                         tmp_path / "run", *extra)
        assert code == 0 and stderr == "", stderr
        assert stdout.startswith("ato_only: 60.000 s simulated in ")


def test_on_a_terminal_the_bar_is_redrawn_in_place(tmp_path, product_fmus):
    """--progress auto with stderr a terminal: the initialisation line at once, then the bar."""
    master, slave = pty.openpty()
    process = subprocess.Popen([sys.executable, "-m", "orchestrator", "run", "free_run", "--no-build",
                                "--stop-time", "200", "--output", str(tmp_path / "run")],
                               stdout=subprocess.PIPE, stderr=slave, env=cli_environment(), text=True)
    os.close(slave)
    seen = b""
    while True:
        ready, _, _ = select.select([master], [], [], 0.2)
        if ready:
            try:
                chunk = os.read(master, 4096)
            except OSError:           # the terminal closed with the process
                chunk = b""
            if not chunk:
                break
            seen += chunk
        elif process.poll() is not None:
            break
    os.close(master)
    stdout, _ = process.communicate(timeout=60)
    assert process.returncode == 0, seen
    text = seen.decode()
    assert text.startswith("initialising 5 components…\rinitialised 5 components in "), text
    bars = re.findall(r"\r\[(#*) *\] (t=[^\r\x1b]*)\x1b\[K", text)
    assert bars and all(LINE.fullmatch(status) for _, status in bars), text
    assert text.endswith("\n") and "free_run: 200.000 s simulated" in stdout


def test_the_status_says_simulated_time_share_elapsed_eta_and_the_stepping_rate():
    clock, stream = Clock(), io.StringIO()
    progress = Progress("lines", 0.0, 100.0, 3, interval_s=5.0, stream=stream, clock=clock)
    progress.initialising()
    clock.now += 2.0                                   # initialisation: 2 s
    progress.started(None, _step(0.0))
    clock.now += 2.0
    progress.after_tick(None, _step(4.0))              # 4 s into the run, before the first interval: quiet
    assert stream.getvalue() == ""
    clock.now += 8.0                                   # 10 s of stepping for 20 s: 2×, 80 s to go
    progress.after_tick(None, _step(20.0))
    assert stream.getvalue() == "t=20.0/100 s  20%  elapsed 12 s  ETA 40 s  RTF 2.0×\n"
    clock.now += 1.0
    progress.after_tick(None, _step(22.0))             # the next one interval_s later
    assert stream.getvalue().count("\n") == 1
    progress.close()
    assert stream.getvalue().count("\n") == 1


def test_a_long_initialisation_is_said_while_it_lasts_and_timed():
    stream = io.StringIO()
    progress = Progress("lines", 0.0, 10.0, 1, interval_s=0.05, stream=stream)
    progress.initialising()
    time.sleep(0.3)
    assert stream.getvalue() == "initialising 1 component…\n"
    progress.started(None, _step(0.0))
    assert re.fullmatch(r"initialising 1 component…\ninitialised 1 component in 0\.[3-9] s\n", stream.getvalue())
    progress.close()


def test_a_bar_whose_initialisation_fails_is_erased_for_the_error_line():
    clock, stream = Clock(), io.StringIO()
    progress = Progress("bar", 0.0, 10.0, 5, stream=stream, clock=clock)
    progress.initialising()
    progress.close()                                   # the run failed before it stepped
    assert stream.getvalue() == "initialising 5 components…\r\x1b[K"


@pytest.mark.parametrize("seconds, text", [(0.4, "0 s"), (12.4, "12 s"), (59.4, "59 s"), (59.6, "1 m 0 s"),
                                           (90, "1 m 30 s"), (3599, "59 m 59 s"), (7500, "2 h 5 m")])
def test_durations_read_as_a_person_says_them(seconds, text):
    assert duration_text(seconds) == text


def test_a_progress_interval_that_is_not_positive_is_one_line(tmp_path):
    code, _, stderr = railcosim("run", "free_run", "--no-build", "--progress-interval", "0", "--output", tmp_path)
    assert code == 2 and stderr.strip() == "railcosim: error: run: --progress-interval 0: must be more than 0"
