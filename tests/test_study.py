"""`railcosim study`: study files expanded into runs, run on Dask (a 2-worker LocalCluster, and a
real `dask scheduler` + `dask worker` on loopback), failures and timeouts recorded, --resume,
the report, the noise-immunity study against the benchmark's own chain, bad input.

Short runs only: ato_only for 20 s of simulated time, noise conditions of a few hundred messages.
"""
import json
import os
import signal
import socket
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from orchestrator.verdicts.verdict import railway_verdicts
from orchestrator.cli import main
from orchestrator.run import RunOptions, run_system
from orchestrator.study.runner import run_study
from orchestrator.study.spec import load_study

REPO = Path(__file__).resolve().parent.parent
GRID_STUDY = """
name = "grid"
system = "ato_only"
stop_time = 20
seeds = [1, 2]
collect = ["final.train.x", "final.train.v", "trains.train.energy_kwh", "verdict"]
[options]
output_interval = 1.0
[grid]
"train.v0" = [5.0, 10.0]
"train.mass_scale" = [0.9, 1.1]
"""


def _write(folder: Path, name: str, text: str) -> Path:
    path = folder / name
    path.write_text(textwrap.dedent(text))
    return path


def _csv(path: Path):
    import csv

    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def grid_study(product_fmus, tmp_path_factory):
    """The 4 points × 2 seeds of ato_only, on a LocalCluster of 2 workers, through the CLI."""
    folder = tmp_path_factory.mktemp("grid")
    study = _write(folder, "grid.toml", GRID_STUDY)
    status = main(["study", str(study), "--workers", "2", "--output", str(folder / "out"), "--no-build"])
    return study, folder / "out", status


def test_grid_study_gives_the_values_of_the_runs_made_one_by_one(grid_study, product_fmus, tmp_path):
    study, out, status = grid_study
    assert status == 0
    rows = _csv(out / "study.csv")
    assert [r["id"] for r in rows] == [f"r{k:04d}" for k in range(8)]
    assert all(r["status"] == "ok" for r in rows)
    for row in rows:
        for name in ("results.csv", "summary.json", "metadata.json"):
            assert (out / "runs" / row["id"] / name).is_file()
    positions = set()
    for v0 in (5.0, 10.0):
        for mass in (0.9, 1.1):
            alone = run_system(REPO / "ssp" / "ato_only", RunOptions(
                stop_time=20, output_interval=1.0, fmu_dirs=[product_fmus], output_dir=tmp_path / f"{v0}-{mass}",
                overrides={"train.v0": str(v0), "train.mass_scale": str(mass)}, summaries=railway_verdicts))
            final = _csv(tmp_path / f"{v0}-{mass}" / "results.csv")[-1]
            mine = [r for r in rows if float(r["train.v0"]) == v0 and float(r["train.mass_scale"]) == mass]
            assert sorted(r["seed"] for r in mine) == ["1", "2"]
            for row in mine:
                assert float(row["final.train.x"]) == float(final["train.x"])
                assert float(row["final.train.v"]) == float(final["train.v"])
                assert float(row["trains.train.energy_kwh"]) == alone.summary["trains"][0]["energy_kwh"]
                assert row["verdict"] == "safe"
            positions.add(float(final["train.x"]))
    assert len(positions) == 4                 # every point is a different run
    study_json = json.loads((out / "study.json").read_text())
    assert study_json["counts"]["ok"] == 8 and study_json["counts"]["points"] == 4
    assert study_json["hash"] == load_study(study).hash


def _without_wall_clock(summary_path: Path) -> dict:
    summary = json.loads(summary_path.read_text())
    for key in ("wall_time_s", "realtime_factor", "init_wall_time_s", "stepping_wall_time_s",
                "stepping_realtime_factor"):
        summary.pop(key)
    return summary


def test_runs_on_a_warm_worker_equal_fresh_runs_bit_for_bit(grid_study, product_fmus, tmp_path):
    """A worker runs each run forked from itself with the FMUs extracted once and the ATO's stage
    plans kept (docs/studies.md): every run's results.csv is byte for byte, and its summary
    key for key, the run made alone in a fresh process state."""
    study, out, _ = grid_study
    assert "RAILCOSIM_PLAN_CACHE" not in os.environ        # this process plans afresh
    for row in _csv(out / "study.csv"):
        alone = tmp_path / row["id"]
        run_system(REPO / "ssp" / "ato_only", RunOptions(
            stop_time=20, output_interval=1.0, fmu_dirs=[product_fmus], output_dir=alone,
            overrides={"train.v0": row["train.v0"], "train.mass_scale": row["train.mass_scale"]},
            summaries=railway_verdicts))
        run = out / "runs" / row["id"]
        assert (run / "results.csv").read_bytes() == (alone / "results.csv").read_bytes(), row["id"]
        assert _without_wall_clock(run / "summary.json") == _without_wall_clock(alone / "summary.json")


WARM_WORKER = """
import json, os, sys, zipfile
from pathlib import Path
from orchestrator.study.runner import jobs_of
from orchestrator.study.worker import execute_run, prepare_worker
from orchestrator.study.spec import load_study

study, system, fmus, out = map(Path, sys.argv[1:5])
jobs = jobs_of(load_study(study), out, system, [fmus])
folder = prepare_worker()
statuses = [execute_run(job)["status"] for job in jobs[:2]]
first = sorted(p.name for p in (folder / "fmus").iterdir())
with zipfile.ZipFile(fmus / "Traction.fmu", "a") as fmu:   # the FMU rebuilt in place
    fmu.writestr("documentation/rebuilt.txt", "another build")
statuses.append(execute_run(jobs[2])["status"])
print(json.dumps({"folder": str(folder), "statuses": statuses, "first": first,
                  "then": sorted(p.name for p in (folder / "fmus").iterdir()),
                  "plans": len(list((folder / "ato_plans").glob("*.npz")))}))
"""


def test_a_worker_extracts_each_fmu_once_and_removes_its_folder_at_exit(product_fmus, tmp_path):
    import shutil

    fmus = tmp_path / "fmus"
    fmus.mkdir()
    for name in ("Traction.fmu", "AtoController.fmu"):
        shutil.copy2(product_fmus / name, fmus / name)
    study = _write(tmp_path, "three.toml", """
        system = "ato_only"
        stop_time = 2
        collect = ["final.train.x"]
        [grid]
        "train.v0" = [1.0, 2.0, 3.0]
        """)
    script = _write(tmp_path, "warm_worker.py", WARM_WORKER)
    env = {key: value for key, value in os.environ.items() if key != "RAILCOSIM_PLAN_CACHE"}
    done = subprocess.run([sys.executable, str(script), str(study), str(REPO / "ssp" / "ato_only"),
                           str(fmus), str(tmp_path / "out")], capture_output=True, text=True,
                          env={**env, "PYTHONPATH": str(REPO)}, timeout=300)
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout.splitlines()[-1])
    assert seen["statuses"] == ["ok", "ok", "ok"]
    # one extraction per FMU for both runs; the rebuilt one extracted anew for the third
    assert [name.split("_")[0] for name in seen["first"]] == ["AtoController", "Traction"]
    assert len(seen["then"]) == 3 and set(seen["first"]) < set(seen["then"])
    assert seen["plans"] == 2                          # ato_only's two stages, planned once
    assert not Path(seen["folder"]).exists()           # removed when the worker exited


RUN_PROCESS_WORKER = """
import json, os, signal, sys, threading, time
from pathlib import Path
import orchestrator.study.worker as worker
from orchestrator.study.runner import jobs_of
from orchestrator.study.spec import load_study

study, system, fmus, out = map(Path, sys.argv[1:5])
jobs = jobs_of(load_study(study), out, system, [fmus])
seen = []

def run(job):
    record = worker.execute_run(job)
    process = getattr(worker._RUN_PROCESSES, "process", None)
    seen.append({"id": job["id"], "status": record["status"], "error": record["error"],
                 "pid": process.pid if process is not None else None})

def kill_when_running(pid, results):
    while not results.is_file():
        time.sleep(0.01)
    os.kill(pid, signal.SIGKILL)

run(jobs[0])
run(jobs[1])                                                         # the same run process
run({**jobs[2], "values": {"train.mass_scale": 20.0}})               # refused: the process ends
run(jobs[3])                                                         # a new one
run({**jobs[4], "stop_time": 100000.0, "timeout_s": 2})              # stopped at its timeout
run(jobs[5])                       # the process killed below is this run's, kept for the next
killer = threading.Thread(target=kill_when_running, args=(
    worker._RUN_PROCESSES.process.pid, out / "runs" / jobs[6]["id"] / "results.csv"))
killer.start()
run({**jobs[6], "stop_time": 100000.0})                              # its process killed mid-run
killer.join()
run(jobs[7])
print(json.dumps(seen))
"""


def test_a_run_process_serves_ok_runs_and_is_forked_afresh_after_any_other(product_fmus, tmp_path):
    """A worker's runs of one system go to one run process in turn while they end ok; a refused
    value, a timeout or the run process killed mid-run fails that run only, and the next run
    gets a process forked afresh. Every ok run's results.csv is byte for byte, and its summary
    key for key, the run made alone in a fresh process state."""
    study = _write(tmp_path, "eight.toml", """
        system = "ato_only"
        stop_time = 20
        collect = ["final.train.x"]
        [options]
        output_interval = 1.0
        [grid]
        "train.v0" = [3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0]
        """)
    script = _write(tmp_path, "run_process_worker.py", RUN_PROCESS_WORKER)
    env = {key: value for key, value in os.environ.items() if key != "RAILCOSIM_PLAN_CACHE"}
    out = tmp_path / "out"
    done = subprocess.run([sys.executable, str(script), str(study), str(REPO / "ssp" / "ato_only"),
                           str(product_fmus), str(out)], capture_output=True, text=True,
                          env={**env, "PYTHONPATH": str(REPO)}, timeout=600)
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout.splitlines()[-1])
    assert [run["status"] for run in seen] == ["ok", "ok", "failed", "ok", "timeout", "ok", "failed", "ok"]
    assert "mass_scale = 20 is above its maximum 10" in seen[2]["error"]
    assert "2 s" in seen[4]["error"]
    assert seen[6]["error"] == "the run's process ended by signal 9 without a result"
    pids = [run["pid"] for run in seen]
    assert pids[0] == pids[1] is not None                              # kept while its runs end ok
    assert pids[2] is None and pids[4] is None and pids[6] is None     # ended after any other
    assert len({pids[0], pids[3], pids[5], pids[7]}) == 4              # forked afresh each time
    stopped = json.loads((out / "runs" / seen[4]["id"] / "summary.json").read_text())
    assert stopped["interrupted"] == "SIGTERM" and stopped["sim_time_s"] > 20.0
    for run in seen:
        if run["status"] != "ok":
            continue
        record = json.loads((out / "runs" / run["id"] / "study_run.json").read_text())
        alone = tmp_path / "alone" / run["id"]
        run_system(REPO / "ssp" / "ato_only", RunOptions(
            stop_time=20, output_interval=1.0, fmu_dirs=[product_fmus], output_dir=alone,
            overrides={"train.v0": str(record["values"]["train.v0"])}, summaries=railway_verdicts))
        mine = out / "runs" / run["id"]
        assert (mine / "results.csv").read_bytes() == (alone / "results.csv").read_bytes(), run["id"]
        assert _without_wall_clock(mine / "summary.json") == _without_wall_clock(alone / "summary.json")


def test_resume_reruns_nothing_of_a_finished_study(grid_study):
    study, out, _ = grid_study
    records = sorted((out / "runs").glob("*/study_run.json"))
    before = {p: p.stat().st_mtime_ns for p in records}
    result = run_study(load_study(study), out, REPO / "ssp" / "ato_only", [], resume=True)
    assert result.skipped == 8 and result.counts["ok"] == 8
    assert {p: p.stat().st_mtime_ns for p in records} == before
    # another stop time is another study: nothing of this one would be reused
    other = _write(study.parent, "other.toml", GRID_STUDY.replace("stop_time = 20", "stop_time = 21"))
    from orchestrator.study.runner import _resumable

    assert all(_resumable(out / "runs" / run.id, load_study(other).hash) is None for run in load_study(other).runs)


def test_report_aggregates_per_point_and_plots_two_axes(grid_study, capsys):
    _, out, _ = grid_study
    assert main(["study", "report", str(out)]) == 0
    text = capsys.readouterr().out
    table = [line for line in text.splitlines() if line.startswith("| ") and line[2].isdigit()]
    assert len(table) == 4 and all("safe×2" in line for line in table)
    assert (out / "report.txt").read_text() in text
    # the energy over 20 s is one figure at every point: its plot would be a flat line
    assert sorted(p.name for p in out.glob("study_*.png")) == ["study_final_train_v.png", "study_final_train_x.png"]
    # the same on one page: a row per point, the two plots inlined (nothing to fetch), no worst run
    page = (out / "report.html").read_text()
    assert page.count('<tr class="point">') == 4 and page.count('src="data:image/png;base64,') == 2
    assert ('<li class="left-out">trains.train.energy_kwh: one value over the sweep, or figures at a single '
            'train.v0</li>') in page and '<li class="left-out">verdict: not a number at every point</li>' in page
    assert 'src="http' not in page and "none: no safety key collected, no failed run" in page


def test_only_plots_that_carry_information_are_drawn():
    """A key with one value everywhere (all zeros) or figures at a single x value says nothing a
    plot adds to the table: no picture of it."""
    from orchestrator.study.report import informative

    def entry(x, low, high):
        return {"axes": {"x": x}, "keys": {"k": {"mean": (low + high) / 2, "min": low, "max": high}}}

    assert informative([entry("1", 0.0, 0.0), entry("2", 0.0, 1.0)], "k", "x")
    assert not informative([entry("1", 0.0, 0.0), entry("2", 0.0, 0.0)], "k", "x")          # all zeros
    assert not informative([entry("1", 3.0, 5.0)], "k", "x")                                  # one point
    assert not informative([entry("1", 3.0, 5.0), {"axes": {"x": "2"}, "keys": {"k": {"values": {}}}}], "k", "x")


WORKER_MODULE = """
import time

def work(x, seed, scale=1):
    if x == 2:
        raise ValueError("x = 2 is refused")
    if x == 3:
        time.sleep(120)
    return {"y": scale * x * x + seed}
"""


def test_failing_and_timed_out_runs_are_recorded_and_the_rest_complete(tmp_path):
    _write(tmp_path, "worker_module_of_test.py", WORKER_MODULE)
    study = _write(tmp_path, "f.json", json.dumps({
        "function": "worker_module_of_test:work", "arguments": {"scale": 10}, "grid": {"x": [1, 2, 3, 4]},
        "seeds": [0, 1], "collect": ["y"], "timeout_s": 3, "safety": ["y"]}))
    spec = load_study(study)
    result = run_study(spec, tmp_path / "out", None, [], workers=2)
    by_x = {}
    for r in result.records:
        by_x.setdefault(r["values"]["x"], []).append(r)
    assert [(r["status"], r["collected"]["y"]) for r in by_x[1]] == [("ok", 10), ("ok", 11)]
    assert [(r["status"], r["collected"]["y"]) for r in by_x[4]] == [("ok", 160), ("ok", 161)]
    assert all(r["status"] == "failed" and r["error"] == "ValueError: x = 2 is refused" for r in by_x[2])
    assert all(r["status"] == "timeout" and "3 s" in r["error"] for r in by_x[3])
    assert result.counts == {"ok": 4, "failed": 2, "timeout": 2, "lost": 0, "runs": 8, "points": 4, "skipped": 0}
    # the study's page links each run that did not end ok to its folder
    from orchestrator.study.report import make_study_report

    make_study_report(tmp_path / "out")
    page = (tmp_path / "out" / "report.html").read_text()
    for record in result.records:
        assert (f'<a href="runs/{record["id"]}/">{record["id"]}</a>' in page) == (record["status"] != "ok" or
                                                                                record["collected"]["y"] > 0)
    # resuming runs the failed and timed-out points again, and only those
    again = run_study(spec, tmp_path / "out", None, [], workers=1, resume=True)
    assert again.skipped == 4 and again.counts["ok"] == 4


FLAKY_MODULE = """
from pathlib import Path

def work(x, marker, seed=None):
    if x > 2 and not Path(marker).exists():
        raise ValueError("not yet")
    return {"y": x}
"""


def test_resume_keeps_the_earlier_sessions_in_study_json(tmp_path):
    """study.json after a --resume: both sessions, each with its wall time, workers and runs;
    the study's wall time their sum, its start the first session's (a resume used to replace
    them with its own)."""
    _write(tmp_path, "flaky_module_of_test.py", FLAKY_MODULE)
    marker = tmp_path / "go"
    study = _write(tmp_path, "f.json", json.dumps({
        "function": "flaky_module_of_test:work", "arguments": {"marker": str(marker)}, "grid": {"x": [1, 2, 3, 4]},
        "collect": ["y"]}))
    spec = load_study(study)
    first = run_study(spec, tmp_path / "out", None, [], workers=2)
    assert first.counts["ok"] == 2 and first.counts["failed"] == 2, first.records
    marker.touch()
    time.sleep(1.0)                                   # the second session starts a second later at least
    again = run_study(spec, tmp_path / "out", None, [], workers=1, resume=True)
    assert again.skipped == 2 and again.counts["ok"] == 4
    data = json.loads((tmp_path / "out" / "study.json").read_text())
    sessions = data["sessions"]
    assert [(s["workers"], s["runs"], s["interrupted"]) for s in sessions] == [(2, 4, None), (1, 2, None)]
    assert sessions[0]["started"] < sessions[1]["started"] and data["started"] == sessions[0]["started"]
    assert all(s["wall_time_s"] > 0 for s in sessions)
    assert data["wall_time_s"] == pytest.approx(sum(s["wall_time_s"] for s in sessions))
    assert data["workers"] == 1


def test_the_report_does_not_call_a_safety_key_never_collected_zero(tmp_path, capsys):
    """A study.json of an earlier version naming a safety key its runs did not collect: the
    report says that key is not collected, and does not count it among the keys found zero."""
    _write(tmp_path, "worker_module_of_test.py", WORKER_MODULE)
    study = _write(tmp_path, "f.json", json.dumps({
        "function": "worker_module_of_test:work", "grid": {"x": [1, 4]}, "seeds": [0], "collect": ["y"],
        "safety": ["y"]}))
    run_study(load_study(study), tmp_path / "out", None, [], workers=1)
    path = tmp_path / "out" / "study.json"
    data = json.loads(path.read_text())
    data["safety"] = ["signals_passed_at_danger", "y"]       # as the earlier version wrote it
    path.write_text(json.dumps(data))
    assert main(["study", "report", str(tmp_path / "out")]) == 0
    text = capsys.readouterr().out
    assert "Safety keys not collected (no run reports them; not judged): signals_passed_at_danger." in text
    assert "- r0001 (x 4, seed 0): y = 16" in text
    data["safety"] = ["signals_passed_at_danger"]
    path.write_text(json.dumps(data))
    assert main(["study", "report", str(tmp_path / "out")]) == 0
    text = capsys.readouterr().out
    assert "none: no safety key collected, no failed run" in text and "no safety key above zero" not in text


def test_runs_taken_several_per_task_are_each_recorded_in_order(tmp_path):
    """A task of several runs: a failing run in it fails alone, the runs after it in the same
    task still run, and the records come back in the study's order."""
    _write(tmp_path, "worker_module_of_test.py", WORKER_MODULE)
    study = _write(tmp_path, "f.json", json.dumps({
        "function": "worker_module_of_test:work", "grid": {"x": [1, 2, 4, 5, 6, 7, 8]}, "seeds": [0], "collect": ["y"]}))
    result = run_study(load_study(study), tmp_path / "out", None, [], workers=1, runs_per_task=3)
    assert [(r["values"]["x"], r["status"], r["collected"]["y"]) for r in result.records] == [
        (1, "ok", 1), (2, "failed", None), (4, "ok", 16), (5, "ok", 25), (6, "ok", 36), (7, "ok", 49), (8, "ok", 64)]


def test_many_short_runs_go_several_to_a_task_and_every_worker_keeps_tasks():
    from orchestrator.study.runner import MAX_RUNS_PER_TASK, TASKS_PER_WORKER, default_runs_per_task

    assert default_runs_per_task(16, 2) == 1                 # a small study: a task per run
    assert default_runs_per_task(64, 2) == 4
    assert default_runs_per_task(100_000, 2) == MAX_RUNS_PER_TASK
    for runs, workers in ((16, 2), (64, 2), (512, 2), (512, 64), (7, 1)):
        tasks = -(-runs // default_runs_per_task(runs, workers))
        assert tasks >= min(runs, workers * TASKS_PER_WORKER)


def test_a_bad_parameter_value_fails_its_run_only(product_fmus, tmp_path):
    study = _write(tmp_path, "bad.toml", """
        system = "ato_only"
        stop_time = 5
        collect = ["final.train.x"]
        [grid]
        "train.mass_scale" = [1.0, 20.0]
        """)
    assert main(["study", str(study), "--workers", "1", "--output", str(tmp_path / "out"), "--no-build"]) == 1
    rows = _csv(tmp_path / "out" / "study.csv")
    assert [r["status"] for r in rows] == ["ok", "failed"]
    assert "mass_scale = 20 is above its maximum 10" in rows[1]["error"] and "\n" not in rows[1]["error"]
    assert rows[0]["final.train.x"] != ""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_study_on_a_dask_scheduler_and_worker_started_as_processes(product_fmus, tmp_path):
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    processes = []
    try:
        processes.append(subprocess.Popen(
            ["dask", "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
            env=env, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True))
        processes.append(subprocess.Popen(
            ["dask", "worker", address, "--nthreads", "1", "--nworkers", "1", "--no-dashboard",
             "--host", "127.0.0.1"],
            env=env, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True))
        study = _write(tmp_path, "one.toml", """
            system = "ato_only"
            stop_time = 10
            seeds = [1, 2]
            collect = ["final.train.x", "verdict"]
            [grid]
            "train.v0" = [10.0]
            """)
        deadline = time.monotonic() + 60
        while True:                            # the scheduler takes a moment to listen
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                break
            except OSError:
                assert time.monotonic() < deadline, "dask scheduler did not start"
                time.sleep(0.5)
        assert main(["study", str(study), "--scheduler", address, "--output", str(tmp_path / "out"),
                     "--no-build"]) == 0
        rows = _csv(tmp_path / "out" / "study.csv")
        assert [r["status"] for r in rows] == ["ok", "ok"]
        assert rows[0]["final.train.x"] == rows[1]["final.train.x"] != ""
        assert json.loads((tmp_path / "out" / "study.json").read_text())["scheduler"] == address
    finally:
        for process in reversed(processes):
            try:
                os.killpg(process.pid, signal.SIGTERM)
            except ProcessLookupError:
                continue
        for process in reversed(processes):
            try:
                process.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait()


def test_noise_study_gives_the_counts_of_the_harness_chain(tmp_path):
    """The noise-immunity study's runs against the benchmark's chain called as its loop did,
    with the loop's seeds (reduced: a few hundred messages, two conditions)."""
    import harness.noise_immunity as noise

    shipped = load_study(REPO / "orchestrator" / "study" / "studies" / "noise_immunity.toml")
    data = {**shipped.data, "arguments": {"messages": 300, "alsn_cycles": 30},
            "cases": [{"noise": "white", "level": -10.0}, {"noise": "impulse", "level": 2.0}]}
    study = _write(tmp_path, "noise.json", json.dumps(data))
    result = run_study(load_study(study), tmp_path / "out", None, [], workers=2, python_path=[str(REPO)])
    assert result.counts["ok"] == 6
    # the loop: white noise seeds 100 + k / 7 + k (FIRE_DQPSK k = 0, ALS-EN k = 1), ALSN 99 / 5;
    # impulse noise 200 + k / 17 + k, ALSN 199 / 5
    expected = {("white", "FIRE_DQPSK"): noise.run_digital("FIRE_DQPSK", 300, noise.white(-10.0, np.random.default_rng(100)), 7),
                ("white", "ALS-EN"): noise.run_digital("ALS-EN", 300, noise.white(-10.0, np.random.default_rng(101)), 8),
                ("white", "ALSN"): noise.alsn_chain(30, noise.white(-10.0, np.random.default_rng(99)), 5),
                ("impulse", "FIRE_DQPSK"): noise.run_digital("FIRE_DQPSK", 300, noise.impulses(2.0, np.random.default_rng(200)), 17),
                ("impulse", "ALS-EN"): noise.run_digital("ALS-EN", 300, noise.impulses(2.0, np.random.default_rng(201)), 18),
                ("impulse", "ALSN"): noise.alsn_chain(30, noise.impulses(2.0, np.random.default_rng(199)), 5)}
    for record in result.records:
        want = expected[(record["values"]["noise"], record["values"]["system"])]
        for key in ("messages", "correct", "undetected", "detected", "wrong_side_events"):
            assert record["collected"][key] == want[key], (record["values"], key)
        assert record["collected"]["mer"] == pytest.approx(want["mer"])
        assert record["collected"]["availability"] == pytest.approx(want["availability"])
    assert len({r["collected"]["correct"] for r in result.records}) > 1


def test_alsu_noise_study_gives_the_counts_of_the_benchmarks_chain(tmp_path):
    """The ALSU noise study's runs (white noise, DC joint pulses) against the chain called
    directly with the study's seeds (reduced: 200 messages)."""
    import harness.noise_immunity as noise

    shipped = load_study(REPO / "orchestrator" / "study" / "studies" / "noise_immunity_alsu.toml")
    data = {**shipped.data, "arguments": {"messages": 200},
            "cases": [{"noise": "white", "level": -6.0}, {"noise": "joint", "level": 160.0}]}
    study = _write(tmp_path, "noise_alsu.json", json.dumps(data))
    result = run_study(load_study(study), tmp_path / "out", None, [], workers=2, python_path=[str(REPO)])
    assert result.counts["ok"] == 2
    offset = 10 * np.log10(2 * noise.ALSU_TONE_V ** 2 / noise.AMPLITUDE_V ** 2)     # the code's power, both tones
    expected = {"white": noise.alsu_chain(200, noise.white(-6.0 - offset, np.random.default_rng(98)), 6),
                "joint": noise.alsu_chain(200, noise.joints(160.0, np.random.default_rng(298)), 26)}
    for record in result.records:
        want = expected[record["values"]["noise"]]
        for key in ("messages", "correct", "undetected", "detected", "wrong_side_events"):
            assert record["collected"][key] == want[key], (record["values"], key)
        assert record["collected"]["wrong_side_events"] == 0


def test_tvm430_noise_study_is_never_wrong_side_and_errs_more_in_more_noise(tmp_path):
    """The shipped TVM-430 noise study, every condition (reduced: 200 messages): no word shown
    more permissive than every word sent within the stated latency, in white, impulse and
    in-band noise and with the neighbour's carrier leaking; the message error rate in white
    noise rises as the SNR falls; and a run's counts are the chain's with the study's seeds."""
    import harness.noise_immunity as noise

    shipped = load_study(REPO / "orchestrator" / "study" / "studies" / "noise_immunity_tvm430.toml")
    data = {**shipped.data, "arguments": {"messages": 200}}
    study = _write(tmp_path, "noise_tvm430.json", json.dumps(data))
    result = run_study(load_study(study), tmp_path / "out", None, [], workers=2, python_path=[str(REPO)])
    assert result.counts["ok"] == len(shipped.runs) == 10
    for record in result.records:
        assert record["collected"]["messages"] == 200
        assert record["collected"]["wrong_side_events"] == 0, record["values"]
        assert record["collected"]["wrong_side_s"] == 0.0, record["values"]
    white = sorted((r["values"]["level"], r["collected"]["mer"]) for r in result.records
                   if r["values"]["noise"] == "white")
    assert [level for level, _ in white] == [-6.0, -3.0, 0.0, 3.0]
    mers = [mer for _, mer in white]                        # lowest SNR first
    assert all(a > b for a, b in zip(mers, mers[1:])), white
    # white noise at -3 dB: noise seed 97, message seed 9
    want = noise.tvm430_chain(200, noise.white(-3.0, np.random.default_rng(97), noise.TVM_CARRIER_V), 9)
    record = next(r for r in result.records if r["values"] == {"noise": "white", "level": -3.0, "system": "TVM430"})
    for key in ("correct", "undetected", "detected", "decisions_other_word", "wrong_side_events"):
        assert record["collected"][key] == want[key], key


def test_tvm300_noise_study_is_never_wrong_side_and_errs_more_in_more_noise(tmp_path):
    """The shipped TVM-300 noise study, every condition (reduced: 60 messages of 1 s): no code
    shown more permissive than every code sent within the stated latency and no decision
    reading a more permissive code, in white, impulse and in-band noise and with the
    neighbour's carrier leaking; the message error rate in white noise does not fall as the
    SNR falls and is far higher at the lowest; and a run's counts are the chain's with the
    study's seeds."""
    import harness.noise_immunity as noise

    shipped = load_study(REPO / "orchestrator" / "study" / "studies" / "noise_immunity_tvm300.toml")
    assert shipped.data["arguments"]["messages"] >= 10000
    data = {**shipped.data, "arguments": {"messages": 60}}
    study = _write(tmp_path, "noise_tvm300.json", json.dumps(data))
    result = run_study(load_study(study), tmp_path / "out", None, [], workers=2, python_path=[str(REPO)])
    assert result.counts["ok"] == len(shipped.runs) == 13
    for record in result.records:
        assert record["collected"]["messages"] == 60
        assert record["collected"]["wrong_side_events"] == 0, record["values"]
        assert record["collected"]["undetected_permissive"] == 0, record["values"]
    white = sorted((r["values"]["level"], r["collected"]["mer"]) for r in result.records
                   if r["values"]["noise"] == "white")
    assert [level for level, _ in white] == [-10.0, -8.0, -6.0, 0.0]
    mers = [mer for _, mer in white]                        # lowest SNR first
    assert all(a >= b for a, b in zip(mers, mers[1:])) and mers[0] > 0.5 > mers[-1], white
    # the leaking neighbour at -6 dB: noise seed 496, message seed 40
    want = noise.tvm300_chain(60, noise.white(-6.0, np.random.default_rng(496), noise.TVM_CARRIER_V), 40,
                              noise.tvm_leak_ratio())
    record = next(r for r in result.records if r["values"] == {"noise": "leak", "level": -6.0, "system": "TVM300"})
    for key in ("correct", "undetected", "detected", "decisions_other_code", "wrong_side_events"):
        assert record["collected"][key] == want[key], key


@pytest.mark.parametrize("text, message", [
    ('system = "ato_only"\n[grid]\n"train.mass_scal" = [1.0]\n',
     "field grid.train.mass_scal: component 'train' of ato_only has no variable 'mass_scal'"),
    ('system = "ato_only"\n[grid]\n"trian.mass_scale" = [1.0]\n',
     "field grid.trian.mass_scale: 'trian.mass_scale' is not COMPONENT.VARIABLE of ato_only"),
    ('system = "no_such_system"\n', "system 'no_such_system': no such folder"),
    ('system = "ato_only"\n[random]\ncount = 3\nseed = 1\n[random.variables]\n"train.mass_scale" = '
     '{distribution = "uniform", low = 1.1, high = 0.9}\n',
     "field random.variables.train.mass_scale: low 1.1 must be below high 0.9"),
    ('system = "ato_only"\n[random]\ncount = 3\nseed = 1\n[random.variables]\n"train.mass_scale" = '
     '{distribution = "normal", mean = 1.0}\n', "a normal distribution takes mean and std (missing std)"),
    ('system = "ato_only"\n[random]\ncount = 3\nseed = 1\n[random.variables]\n"train.mass_scale" = '
     '{distribution = "poisson", mean = 1.0}\n', "field random.variables.train.mass_scale.distribution"),
    ('system = "ato_only"\nstop_time = -1\n', "field stop_time: -1 is less than or equal to the minimum of 0"),
    ('system = "ato_only"\n[grid]\n"train.x" = [1.0]\n', "field grid.train.x: train.x is an output"),
    ('system = "ato_only"\n[grid]\n"train.mass_scale" = ["heavy"]\n', "'heavy' is not a valid Real"),
    # TOML's nan and inf are floats: refused when the file is read, named by their field
    ('system = "ato_only"\n[grid]\n"train.mass_scale" = [1.0, nan]\n',
     "field grid.train.mass_scale[1]: nan is not a finite number"),
    ('system = "ato_only"\nstop_time = inf\n', "field stop_time: inf is not a finite number"),
    # a safety key no run collects would be summed from nothing (docs/studies.md's example did so)
    ('system = "ato_only"\ncollect = ["verdict"]\nsafety = ["signals_passed_at_danger"]\n',
     "field safety.0: 'signals_passed_at_danger' is not collected"),
    ('system = "ato_only"\nsafety = ["signals_passed_at_danger", "atp_interventions"]\n',
     "field safety.1: 'atp_interventions' is not collected"),
])
def test_bad_study_files_are_one_line_and_exit_2(product_fmus, tmp_path, capsys, text, message):
    study = _write(tmp_path, "s.toml", text)
    assert main(["study", str(study), "--no-build", "--output", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("railcosim: error: ") and message in err, err
    assert not (tmp_path / "out").exists()


def test_unreachable_scheduler_is_one_line_and_exit_2(tmp_path, capsys):
    study = _write(tmp_path, "f.json", json.dumps({"function": "math:hypot", "grid": {"x": [1]}, "collect": ["y"]}))
    address = f"tcp://127.0.0.1:{_free_port()}"
    assert main(["study", str(study), "--scheduler", address, "--output", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"--scheduler {address}: cannot connect" in err
