"""`railcosim study` at the sizes users reach: thousands of runs on one worker with the worker's
descriptors flat, a study's size bounded before it is expanded, Ctrl-C ending a study within
seconds with its runs kept and nothing left behind, one study per folder (docs/studies.md).

Function studies of trivial runs only: no FMU is built or loaded here.
"""
import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from orchestrator.cli import main
from orchestrator.study.runner import run_study
from orchestrator.study.spec import HARD_MAX_RUNS, MAX_RUNS, SCHEMA, load_study

REPO = Path(__file__).resolve().parent.parent
MODULE = """
import os
import time


def descriptors(x, seed=None):
    # the worker is the run process's parent: its open descriptors, counted from /proc
    return {"worker_fds": len(os.listdir(f"/proc/{os.getppid()}/fd"))}


def slow(x, seed=None):
    time.sleep(0.2)
    return {"y": 2 * x}
"""


def _study(folder: Path, name: str, function: str, points: int) -> Path:
    (folder / "limits_module_of_test.py").write_text(textwrap.dedent(MODULE))
    path = folder / name
    path.write_text(json.dumps({"function": f"limits_module_of_test:{function}", "grid": {"x": list(range(points))},
                                "collect": ["worker_fds" if function == "descriptors" else "y"]}))
    return path


@pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="counts descriptors in /proc")
def test_3000_runs_on_one_worker_all_end_ok_and_its_descriptors_stay_flat(tmp_path):
    """Every run's process and pipes are closed when it ends: a worker's descriptors beyond
    1024 made select() fail every later run (1004 of 1500 lost)."""
    study = _study(tmp_path, "many.json", "descriptors", 3000)
    began = time.monotonic()
    result = run_study(load_study(study), tmp_path / "out", None, [], workers=1)
    took_s = time.monotonic() - began
    assert result.counts["ok"] == 3000, (result.counts, [r["error"] for r in result.records if r["error"]][:3])
    counts = [record["collected"]["worker_fds"] for record in result.records]
    # a leak of two descriptors a run would add 6000; Dask's own connections come and go
    assert max(counts) - min(counts) <= 8, (min(counts), max(counts))
    assert max(counts[-100:]) <= max(counts[:100]) + 4
    print(f"3000 function runs on one worker in {took_s:.1f} s")


def test_a_study_of_a_million_points_is_refused_with_its_size(tmp_path, capsys):
    study = _study(tmp_path, "big.json", "slow", 1)
    data = json.loads(study.read_text())
    data["grid"] = {"x": list(range(1000)), "z": list(range(1000))}
    study.write_text(json.dumps(data))
    began = time.monotonic()
    assert main(["study", str(study), "--output", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("railcosim: error: "), err
    assert "1000000 runs (1000000 points × 1 seed(s)): more than 10000 runs" in err and "--yes" in err
    assert time.monotonic() - began < 5          # refused from its lengths, before any point is made
    assert not (tmp_path / "out").exists()
    # above the hard bound, --yes or not
    data["seeds"] = [1, 2]
    study.write_text(json.dumps(data))
    assert main(["study", str(study), "--yes", "--output", str(tmp_path / "out")]) == 2
    assert f"more than the {HARD_MAX_RUNS} a study can hold" in capsys.readouterr().err
    assert MAX_RUNS < HARD_MAX_RUNS
    # the draws are bounded by the same number in the schema, before numpy is asked for them
    assert json.loads(SCHEMA.read_text())["properties"]["random"]["properties"]["count"]["maximum"] == HARD_MAX_RUNS


@pytest.mark.parametrize("make, message", [
    (lambda out: out.write_text("a file"), "cannot create the folder (File exists)"),
    (lambda out: (out.mkdir(), (out / "runs").write_text("a file")), "as the folder of the runs"),
    (lambda out: (out.mkdir(), (out / "runs").mkdir(), (out / "runs" / "r0000").mkdir(),
                  (out / "runs" / "r0000" / "notes.txt").write_text("mine")), "runs/r0000 is not a study's run folder"),
], ids=["output-a-file", "runs-a-file", "a-run-folder-not-a-study-s"])
def test_an_output_folder_that_cannot_hold_the_study_is_one_line(tmp_path, capsys, make, message):
    study = _study(tmp_path, "s.json", "slow", 2)
    out = tmp_path / "out"
    make(out)
    assert main(["study", str(study), "--output", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("railcosim: error: --output ") and message in err, err


@pytest.mark.parametrize("text, message", [
    ('function = "m:f"\ncollect = ["y"]\n[arguments]\na = ' + "[" * 50000 + "]" * 50000 + "\n", "nested more than 32 deep"),
    ('function = "m:f"\ncollect = ["y"]\n[arguments]\na = ' + "[" * 40 + "]" * 40 + "\n", "nested more than 32 deep"),
    ('function = "m:f"\ncollect = ["y"]\n[random]\ncount = 1000000000\nseed = 1\n[random.variables]\n'
     'x = {distribution = "uniform", low = 0, high = 1}\n', "field random.count: 1000000000 is greater than the maximum"),
], ids=["50000-deep", "40-deep", "a-billion-draws"])
def test_study_files_too_deep_or_too_many_draws_are_one_line(tmp_path, capsys, text, message):
    study = tmp_path / "s.toml"
    study.write_text(text)
    assert main(["study", str(study), "--output", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("railcosim: error: ") and message in err, err


def test_a_resume_record_that_is_a_folder_runs_that_run_again(tmp_path):
    study = _study(tmp_path, "s.json", "slow", 2)
    (tmp_path / "out" / "runs" / "r0000" / "study_run.json").mkdir(parents=True)
    result = run_study(load_study(study), tmp_path / "out", None, [], workers=1, resume=True)
    assert result.counts["ok"] == 2 and result.skipped == 0
    assert (tmp_path / "out" / "runs" / "r0000" / "study_run.json").is_file()


def test_a_study_replaces_the_run_folders_of_an_earlier_different_study(tmp_path):
    """A smaller, different study into a folder leaves none of the earlier study's runs."""
    out = tmp_path / "out"
    run_study(load_study(_study(tmp_path, "five.json", "slow", 5)), out, None, [], workers=1)
    assert sorted(p.name for p in (out / "runs").iterdir()) == [f"r{k:04d}" for k in range(5)]
    other = _study(tmp_path, "two.json", "slow", 2)
    other.write_text(other.read_text().replace('"x": [0, 1]', '"x": [7, 8]'))
    result = run_study(load_study(other), out, None, [], workers=1, resume=True)
    assert result.skipped == 0 and result.counts["ok"] == 2
    assert sorted(p.name for p in (out / "runs").iterdir()) == ["r0000", "r0001"]
    assert (out / "study.csv").read_text().count("\n") == 3
    assert [r["collected"]["y"] for r in result.records] == [14, 16]


def _start(study: Path, out: Path, tmp: Path, *extra: str) -> subprocess.Popen:
    """`python -m orchestrator study` in a session of its own (a terminal's Ctrl-C reaches the
    whole process group), its temporary files in ``tmp``."""
    env = dict(os.environ, TMPDIR=str(tmp), PYTHONPATH=str(REPO))
    return subprocess.Popen([sys.executable, "-m", "orchestrator", "study", str(study), "--workers", "2",
                             "--output", str(out), *extra], cwd=tmp.parent, env=env, stderr=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True, start_new_session=True)


def _wait_for_runs(process: subprocess.Popen) -> list:
    """stderr's lines until the first run has ended."""
    lines = []
    while not any("done, " in line for line in lines):
        line = process.stderr.readline()
        assert line, "".join(lines)
        lines.append(line)
    return lines


def _group_gone(pgid: int, within_s: float) -> bool:
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline:
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False


@pytest.mark.parametrize("to_group", [True, False], ids=["ctrl-c-in-a-terminal", "kill-INT-the-command"])
def test_sigint_ends_a_study_within_5_s_keeps_its_runs_and_resume_completes_it(tmp_path, to_group):
    study = _study(tmp_path, "slow.json", "slow", 40)
    out, tmp = tmp_path / "out", tmp_path / "tmp"
    tmp.mkdir()
    process = _start(study, out, tmp)
    _wait_for_runs(process)
    sent = time.monotonic()
    (os.killpg if to_group else os.kill)(process.pid, signal.SIGINT)
    try:
        _, err = process.communicate(timeout=5)
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
    assert process.returncode == 130, err
    assert time.monotonic() - sent < 5
    # progress lines printed before the signal arrived may come first: the interruption is one
    # line, the last, and nothing else speaks of it (no traceback)
    said = [line for line in err.splitlines() if not line.startswith("study: ")]
    assert len(said) == 1 and said[0].startswith("railcosim: interrupted by SIGINT after ") \
        and "--resume runs the rest" in said[0] and err.splitlines()[-1] == said[0], err
    assert _group_gone(process.pid, 5 - (time.monotonic() - sent) + 0.5), "a worker or run process outlived it"
    assert os.listdir(tmp) == []                 # the workers' folders, Dask's scratch space
    done = [json.loads(p.read_text()) for p in (out / "runs").glob("*/study_run.json")]
    ok = [r for r in done if r["status"] == "ok"]
    assert ok and len(ok) < 40
    assert all((out / "runs" / r["id"] / "summary.json").is_file() for r in ok)
    assert json.loads((out / "study.json").read_text())["interrupted"] == "SIGINT"
    again = _start(study, out, tmp, "--resume")
    stdout, err = again.communicate(timeout=120)
    assert again.returncode == 0, err
    assert "40 run(s) of 40 point(s): 40 ok" in stdout and f"({len(ok)} done before)" in stdout, stdout
    assert os.listdir(tmp) == []


def test_a_second_study_into_a_folder_in_use_is_refused_in_one_line(tmp_path, capsys):
    study = _study(tmp_path, "slow.json", "slow", 40)
    out, tmp = tmp_path / "out", tmp_path / "tmp"
    tmp.mkdir()
    first = _start(study, out, tmp)
    try:
        _wait_for_runs(first)
        assert main(["study", str(study), "--output", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"--output {out.resolve()}: in use by another study or run (process {first.pid})" in err, err
    finally:
        os.killpg(first.pid, signal.SIGINT)
        first.communicate(timeout=30)
    assert first.returncode == 130


@pytest.mark.parametrize("name", ["study.csv", "study.json", "runs"])
def test_a_study_writes_nothing_through_a_link_in_its_folder(tmp_path, capsys, name):
    study = _study(tmp_path, "s.json", "slow", 2)
    out, victim = tmp_path / "out", tmp_path / "victim"
    victim.mkdir() if name == "runs" else victim.write_text("the user's own file\n")
    out.mkdir()
    (out / name).symlink_to(victim)
    assert main(["study", str(study), "--output", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{out / name}: is a symbolic link" in err, err
    assert (list(victim.iterdir()) == []) if name == "runs" else victim.read_text() == "the user's own file\n"
