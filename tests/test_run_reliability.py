"""A run's lifecycle (docs/reliability.md): interruptions keep the results so far and exit
128 + signal, a results folder holds one run and is locked while in use, write errors are one
line with the FMUs shut down, temp folders never stay behind, .ssp archives are replaced
atomically. Each test sets a private TMPDIR and checks that it is empty afterwards."""
import csv
import json
import os
import resource
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import threading
import time
import zipfile

import pytest

from helpers import ComponentSpec, ConnectionSpec, cli_environment, railcosim, without_progress, write_ssd
from orchestrator.errors import UserError
from orchestrator.interrupts import Interrupted
from orchestrator.protocols import Manipulator, SummaryObserver
from orchestrator.run import RunOptions, run_system


# ---- helpers ---------------------------------------------------------------------------------------
def _one_error_line(code, stderr, *fragments):
    """One line says what stopped the run (after the progress lines of a run that went on a while)."""
    assert code == 2, stderr
    lines = [line for line in without_progress(stderr).splitlines() if line.strip()]
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


def _pair(tmp_path, fmus, stop_time=3.0, step=0.1):
    folder = tmp_path / "pair"
    write_ssd(folder, "pair", [
        ComponentSpec("a", str(fmus / "TestCounter.fmu"), step),
        ComponentSpec("b", str(fmus / "TestCounter.fmu"), step),
    ], [ConnectionSpec("a.t_end", "b.u")], stop_time=stop_time)
    return folder


def _check_results_csv(path, sim_time_s=None):
    """Every row whole (as many fields as the header, all numbers), times increasing."""
    with open(path, newline="") as handle:
        rows = list(csv.reader(handle))
    header, data = rows[0], rows[1:]
    assert header[0] == "time"
    times = []
    for row in data:
        assert len(row) == len(header), f"torn row {row!r}"
        values = [float(x) for x in row]
        times.append(values[0])
    assert times == sorted(times)
    if sim_time_s is not None and times:
        assert times[-1] <= sim_time_s + 1e-9
    return header, data


def _no_leftovers(tmpdir, out=None):
    assert sorted(os.listdir(tmpdir)) == [], "temp folders left behind"
    if out is not None and out.exists():
        assert not [n for n in os.listdir(out) if n.endswith(".tmp")]


@pytest.fixture
def private_tmp(tmp_path, monkeypatch):
    """A private temp folder for this process (tempfile caches its choice) and subprocesses."""
    folder = tmp_path / "tmp"
    folder.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    monkeypatch.setenv("TMPDIR", str(folder))
    return folder


class _SignalAt(Manipulator):
    """Sends signals to this process before the tick at ``t_s``."""

    def __init__(self, t_s, *signums):
        self.tick = round(t_s * 1e9)
        self.signums = signums

    def before_tick(self, master, tick):
        if tick == self.tick:
            for signum in self.signums:
                os.kill(os.getpid(), signum)


class _SignalInSummary(SummaryObserver):
    """Sends a signal while the summary is being made (the run has ended; files are written)."""

    def __init__(self, signum):
        self.signum = signum

    def summary_section(self):
        os.kill(os.getpid(), self.signum)
        return {}


# ---- interruptions, in this process: a signal at a chosen instant -----------------------------------
def test_a_signal_while_stepping_stops_between_macro_steps_and_keeps_the_results(tmp_path, test_fmus, private_tmp):
    before = signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)
    out = tmp_path / "out"
    with pytest.raises(Interrupted) as stop:
        run_system(_pair(tmp_path, test_fmus), RunOptions(output_dir=out, output_interval=0.1,
                                                          manipulators=[_SignalAt(1.5, signal.SIGTERM)]))
    assert stop.value.exit_code == 143 and "SIGTERM at t = 1.6 s" in str(stop.value)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] is False and summary["interrupted"] == "SIGTERM"
    assert summary["sim_time_s"] == pytest.approx(1.6)        # the tick under way was finished
    header, data = _check_results_csv(out / "results.csv", summary["sim_time_s"])
    assert float(data[-1][0]) == pytest.approx(1.6) and float(data[-1][header.index("a.steps")]) == 16
    metadata = json.loads((out / "metadata.json").read_text())
    assert metadata["components"]["a"]["steps_taken"] == 16
    assert (signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)) == before
    _no_leftovers(private_tmp, out)


def test_a_second_and_third_signal_change_nothing(tmp_path, test_fmus, private_tmp):
    out = tmp_path / "out"
    with pytest.raises(Interrupted) as stop:
        run_system(_pair(tmp_path, test_fmus), RunOptions(
            output_dir=out, output_interval=0.1,
            manipulators=[_SignalAt(0.5, signal.SIGINT, signal.SIGINT, signal.SIGHUP)]))
    assert stop.value.exit_code == 130
    summary = json.loads((out / "summary.json").read_text())
    assert summary["interrupted"] == "SIGINT" and summary["sim_time_s"] == pytest.approx(0.6)
    _check_results_csv(out / "results.csv", summary["sim_time_s"])
    _no_leftovers(private_tmp, out)


def test_a_signal_during_initialisation(tmp_path, test_fmus, private_tmp, monkeypatch):
    """The signal arrives once the first FMU is loaded, before the FMUs are initialised."""
    import orchestrator.components

    out = tmp_path / "out"
    make_slave = orchestrator.components.make_slave

    def make_slave_then_signal(*args, **kwargs):
        slave = make_slave(*args, **kwargs)
        os.kill(os.getpid(), signal.SIGINT)
        return slave

    monkeypatch.setattr(orchestrator.components, "make_slave", make_slave_then_signal)
    with pytest.raises(Interrupted) as stop:
        run_system(_pair(tmp_path, test_fmus), RunOptions(output_dir=out))
    assert stop.value.exit_code == 130 and "during initialisation" in str(stop.value)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] is False and summary["interrupted"] == "SIGINT" and summary["sim_time_s"] == 0
    _no_leftovers(private_tmp, out)


def test_a_signal_while_the_results_are_written(tmp_path, test_fmus, private_tmp):
    """The run reached its stop time, then the signal came: the summary says it was interrupted."""
    out = tmp_path / "out"
    with pytest.raises(Interrupted) as stop:
        run_system(_pair(tmp_path, test_fmus), RunOptions(
            output_dir=out, summaries=lambda graph: [_SignalInSummary(signal.SIGHUP)]))
    assert stop.value.exit_code == 129
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] is False and summary["interrupted"] == "SIGHUP"
    assert "while the results were written" in summary["error"]
    assert summary["sim_time_s"] == pytest.approx(3.0)
    _check_results_csv(out / "results.csv", 3.0)
    _no_leftovers(private_tmp, out)


# ---- interruptions from outside: real signals to `railcosim run ato_only` through FMI ---------------
def _catches(pid, signum):
    """True once the process handles ``signum`` (our handlers are installed)."""
    try:
        with open(f"/proc/{pid}/status") as handle:
            for line in handle:
                if line.startswith("SigCgt:"):
                    return bool(int(line.split()[1], 16) >> (signum - 1) & 1)
    except OSError:
        pass
    return False


def _wait_for(proc, ready, what):
    deadline = time.monotonic() + 120
    while not ready():
        assert proc.poll() is None, f"the run ended before {what}: {proc.communicate()[1]}"
        assert time.monotonic() < deadline, f"no {what} in 120 s"
        time.sleep(0.005)


# (marker, value): signal once our handlers are installed (+ delay), once the folder is locked
# (+ delay: FMUs being loaded and initialised), or once results.csv holds so many bytes (stepping)
INSTANTS = [("handlers", 0.0), ("handlers", 0.3), ("lock", 0.0), ("rows", 20_000), ("rows", 250_000)]


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("marker,value", INSTANTS, ids=[f"{m}-{v}" for m, v in INSTANTS])
def test_signal_to_a_run_through_fmi(tmp_path, product_fmus, private_tmp, signum, marker, value):
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator", "run", "ato_only", "--no-build",
                             "--output", str(out)], env=cli_environment(TMPDIR=private_tmp),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        if marker == "handlers":
            _wait_for(proc, lambda: _catches(proc.pid, signal.SIGTERM), "signal handlers")
            time.sleep(value)
        elif marker == "lock":
            _wait_for(proc, lambda: (out / ".railcosim.lock").exists(), "lock file")
            time.sleep(value)
        else:
            results = out / "results.csv"
            _wait_for(proc, lambda: results.exists() and results.stat().st_size >= value, "results")
        proc.send_signal(signum)
        if signum == signal.SIGINT:           # a second Ctrl-C corrupts nothing
            time.sleep(0.01)
            proc.send_signal(signum)
        _, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    name = signal.Signals(signum).name
    assert proc.returncode == 128 + signum, stderr
    assert "Traceback" not in stderr and stderr.strip().splitlines()[-1].startswith(f"railcosim: interrupted by {name}")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] is False and summary["interrupted"] == name
    if marker == "rows":
        assert summary["sim_time_s"] > 0
        _check_results_csv(out / "results.csv", summary["sim_time_s"])
    elif (out / "results.csv").exists():
        _check_results_csv(out / "results.csv", summary["sim_time_s"])
    _no_leftovers(private_tmp, out)


def test_a_signal_while_the_process_exits_changes_nothing(tmp_path, test_fmus, private_tmp):
    """stdout to a pipe is flushed at exit: its first line comes while the interpreter finalises
    and unloads the FMUs, when Python has put SIG_DFL back (killed by SIGINT before the fix)."""
    out = tmp_path / "out"
    env = cli_environment(TMPDIR=private_tmp)
    # unbuffered, the line would come while the command still runs: a signal then is reported
    # (exit 130, results complete), which is another case than the one tested here
    env.pop("PYTHONUNBUFFERED", None)
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator", "run", str(_pair(tmp_path, test_fmus)),
                             "--no-build", "--output", str(out)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    proc.stdout.readline()
    for _ in range(20):
        if proc.poll() is not None:
            break
        proc.send_signal(signal.SIGINT)
        time.sleep(0.01)
    _, stderr = proc.communicate(timeout=60)
    assert proc.returncode == 0, stderr
    assert json.loads((out / "summary.json").read_text())["completed"] is True


# ---- one run per folder ------------------------------------------------------------------------------
def test_a_second_run_into_a_folder_in_use_fails_at_once(tmp_path, product_fmus, private_tmp):
    out = tmp_path / "out"
    # the first run goes on to 6000 s (the train stands at its last station), paced at 500x so
    # that it holds the folder for 12 s however fast the machine steps ato_only (unpaced, a
    # faster ATO step once let it end before the second run had started)
    first = subprocess.Popen([sys.executable, "-m", "orchestrator", "run", "ato_only", "--no-build",
                              "--stop-time", "6000", "--real-time", "500", "--output", str(out)],
                             env=cli_environment(),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(first, lambda: (out / ".railcosim.lock").exists(), "lock file")
        began = time.monotonic()
        code, _, stderr = railcosim("run", "ato_only", "--no-build", "--output", out)
        _one_error_line(code, stderr, str(out), "in use by another run", f"process {first.pid}")
        assert time.monotonic() - began < 30
        _, first_err = first.communicate(timeout=300)
    finally:
        if first.poll() is None:
            first.kill()
    assert first.returncode == 0, first_err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] is True
    _, data = _check_results_csv(out / "results.csv", summary["sim_time_s"])
    interval = json.loads((out / "metadata.json").read_text())["output_interval_s"]
    assert float(data[-1][0]) == pytest.approx(6000.0)
    assert len(data) == round(6000.0 / interval) + 1          # whole, not interleaved with another run
    _no_leftovers(private_tmp, out)


def test_a_run_failing_at_initialisation_leaves_no_earlier_results(tmp_path, product_fmus, private_tmp):
    out = tmp_path / "out"
    code, _, stderr = railcosim("run", "ato_only", "--no-build", "--output", out, "--stop-time", "5")
    assert code == 0, stderr
    for name in ("capture_rail_e_coil_1.csv", "energy.png", "speed_distance.png"):
        (out / name).write_text("an earlier run's file")
    (out / "notes.txt").write_text("the user's own file")
    code, _, stderr = railcosim("run", "ato_only", "--no-build", "--output", out,
                                "--set", "train.mass_scale=0.05")
    _one_error_line(code, stderr, "mass_scale")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] is False and "mass_scale" in summary["error"]
    assert sorted(os.listdir(out)) == [".railcosim.lock", "columns.json", "metadata.json", "notes.txt",
                                     "summary.json"]
    code, _, stderr = railcosim("report", out)
    assert code != 0                         # nothing of the earlier run left to plot
    _no_leftovers(private_tmp, out)


# ---- files the run writes: never through a link planted in the folder -----------------------------
USERS_OWN = "the user's own file\n"


def _victim(tmp_path, kind):
    """What a planted link points at: a file of the user's (it must keep its content), or a
    name where nothing is (nothing may be made there)."""
    victim = tmp_path / "elsewhere" / "victim.txt"
    victim.parent.mkdir(exist_ok=True)
    if kind == "file":
        victim.write_text(USERS_OWN)
    return victim


def _victim_untouched(victim, kind):
    if kind == "file":
        assert victim.read_text() == USERS_OWN
    else:
        assert not victim.exists()
    assert os.listdir(victim.parent) == ([victim.name] if kind == "file" else [])


@pytest.mark.parametrize("kind", ["file", "dangling"])
@pytest.mark.parametrize("name", [".railcosim.lock", "results.csv", "summary.json", "metadata.json",
                                  "capture_src_y.csv", "energy.png", "report.html"])
def test_a_link_planted_in_the_output_folder_is_refused_never_followed(tmp_path, test_fmus, private_tmp,
                                                                      name, kind):
    """A symbolic link at a name the run writes (planted by someone else in a shared folder):
    one line naming it, exit 2, before any FMU is loaded; the link and what it points at stay."""
    victim = _victim(tmp_path, kind)
    out = tmp_path / "out"
    out.mkdir()
    (out / name).symlink_to(victim)
    code, stdout, stderr = railcosim("run", _pair(tmp_path, test_fmus), "--no-build", "--output", out)
    _one_error_line(code, stderr, str(out / name), "is a symbolic link", str(victim))
    assert "results in" not in stdout
    _victim_untouched(victim, kind)
    assert os.readlink(out / name) == str(victim)
    _no_leftovers(private_tmp, out)


@pytest.mark.parametrize("kind", ["file", "dangling"])
def test_links_at_the_temporary_files_are_replaced_never_followed(tmp_path, test_fmus, private_tmp, kind):
    """summary.json and metadata.json are written beside (``.NAME.tmp``) and renamed: a link
    planted at a temporary name, before the run or while it steps, is removed, not written
    through, and so is a link planted at summary.json while the run steps."""
    victim = _victim(tmp_path, kind)
    out = tmp_path / "out"
    out.mkdir()
    (out / ".summary.json.tmp").symlink_to(victim)

    class PlantLinks(Manipulator):
        def before_tick(self, master, tick):
            if tick == 10**9:
                for name in (".metadata.json.tmp", "summary.json", "metadata.json"):
                    (out / name).symlink_to(victim)

    run_system(_pair(tmp_path, test_fmus), RunOptions(output_dir=out, manipulators=[PlantLinks()]))
    _victim_untouched(victim, kind)
    for name in ("summary.json", "metadata.json"):
        assert not (out / name).is_symlink() and json.loads((out / name).read_text())["system"] == "pair"
    assert json.loads((out / "summary.json").read_text())["completed"] is True
    assert sorted(os.listdir(out)) == [".railcosim.lock", "columns.json", "metadata.json", "results.csv",
                                     "summary.json"]


def test_an_output_folder_that_is_a_link_is_refused(tmp_path, test_fmus, private_tmp):
    """--output naming a symbolic link to a folder: one line naming the link and where it points;
    nothing is written into (or removed from) the folder it points at."""
    real = tmp_path / "real"
    real.mkdir()
    (real / "summary.json").write_text(USERS_OWN)
    (tmp_path / "out").symlink_to(real)
    code, _, stderr = railcosim("run", _pair(tmp_path, test_fmus), "--no-build", "--output", tmp_path / "out")
    _one_error_line(code, stderr, f"--output {tmp_path / 'out'}", "is a symbolic link", str(real))
    assert os.listdir(real) == ["summary.json"] and (real / "summary.json").read_text() == USERS_OWN
    _no_leftovers(private_tmp)


def test_report_writes_no_file_through_a_link(tmp_path, test_fmus, private_tmp):
    out = tmp_path / "out"
    code, _, stderr = railcosim("run", _pair(tmp_path, test_fmus), "--no-build", "--output", out)
    assert code == 0, stderr
    victim = _victim(tmp_path, "file")
    (out / "report.html").symlink_to(victim)
    code, _, stderr = railcosim("report", out)
    _one_error_line(code, stderr, str(out / "report.html"), "is a symbolic link")
    _victim_untouched(victim, "file")


# ---- the output folder removed while the run writes it ---------------------------------------------
@pytest.mark.parametrize("then", ["removed", "made again"])
def test_an_output_folder_removed_during_a_run_is_an_error_not_results(tmp_path, product_fmus, private_tmp, then):
    """rm -rf of the folder while `railcosim run` steps (and a new empty folder made at its name):
    one line saying the folder went, exit 2, never "results in"."""
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "orchestrator", "run", "ato_only", "--no-build",
                             "--stop-time", "2000", "--real-time", "500", "--output", str(out)],
                            env=cli_environment(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(proc, lambda: (out / "results.csv").is_file() and (out / "results.csv").stat().st_size > 0,
                  "results.csv")
        shutil.rmtree(out)
        if then == "made again":
            out.mkdir()
        stdout, stderr = proc.communicate(timeout=300)
    finally:
        if proc.poll() is None:
            proc.kill()
    what = "removed" if then == "removed" else "replaced by another folder"
    errors = "\n".join(line for line in stderr.splitlines()   # not the pace warning of a loaded machine
                       if not line.startswith("railcosim: warning: --real-time"))
    _one_error_line(proc.returncode, errors, f"--output {out}", f"the folder was {what}")
    assert "results in" not in stdout
    if then == "made again":         # not this run's folder: nothing written into it
        assert sorted(p.name for p in out.iterdir()) == []
    _no_leftovers(private_tmp)


def test_results_csv_replaced_by_a_link_during_a_run_is_an_error(tmp_path, test_fmus, private_tmp):
    out = tmp_path / "out"
    victim = _victim(tmp_path, "file")

    class SwapResults(Manipulator):
        def before_tick(self, master, tick):
            if tick == 10**9:
                (out / "results.csv").unlink()
                (out / "results.csv").symlink_to(victim)

    with pytest.raises(UserError, match="results.csv: removed or replaced while the run wrote it"):
        run_system(_pair(tmp_path, test_fmus), RunOptions(output_dir=out, manipulators=[SwapResults()]))
    _victim_untouched(victim, "file")


# ---- full disks and write errors ------------------------------------------------------------------
@pytest.mark.skipif(os.geteuid() != 0, reason="a character device in tmp_path needs root (mknod)")
def test_results_csv_on_a_full_disk(tmp_path, test_fmus, private_tmp):
    """results.csv is the full device (1, 7: /dev/full) itself, made in the folder: every write
    fails with ENOSPC (a link to /dev/full is refused, above)."""
    out = tmp_path / "out"
    out.mkdir()
    os.mknod(out / "results.csv", 0o666 | stat.S_IFCHR, os.makedev(1, 7))
    code, _, stderr = railcosim("run", _pair(tmp_path, test_fmus, stop_time=30.0), "--no-build",
                                "--output", out)
    _one_error_line(code, stderr, "results.csv", "No space left on device")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] is False and "No space left on device" in summary["error"]
    assert json.loads((out / "metadata.json").read_text())["components"]["a"]["steps_taken"] > 0
    assert stat.S_ISCHR(os.lstat(out / "results.csv").st_mode)      # a device is written to, not removed
    _no_leftovers(private_tmp, out)


def _limit_file_size(limit):
    def apply():
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


def test_file_size_limit_mid_run_through_fmi(tmp_path, product_fmus, private_tmp):
    """results.csv stops growing at 400 kB (the FMUs' libraries still fit): one line, FMUs shut
    down (the process exits with its own status), the summary is written."""
    out = tmp_path / "out"
    code, _, stderr = railcosim("run", "ato_only", "--no-build", "--output", out,
                                preexec_fn=_limit_file_size(400_000))
    _one_error_line(code, stderr, "results.csv", "File too large")
    summary = json.loads((out / "summary.json").read_text())
    assert summary["completed"] is False and 0 < summary["sim_time_s"] < 1100
    _no_leftovers(private_tmp, out)


def test_results_csv_is_a_folder(tmp_path, test_fmus, private_tmp):
    out = tmp_path / "out"
    (out / "results.csv").mkdir(parents=True)
    code, _, stderr = railcosim("run", _pair(tmp_path, test_fmus), "--no-build", "--output", out)
    _one_error_line(code, stderr, "results.csv", "Is a directory")
    assert json.loads((out / "summary.json").read_text())["completed"] is False
    _no_leftovers(private_tmp, out)


def test_an_output_name_too_long(tmp_path, test_fmus, private_tmp):
    out = tmp_path / ("x" * 300)
    code, _, stderr = railcosim("run", _pair(tmp_path, test_fmus), "--no-build", "--output", out)
    _one_error_line(code, stderr, "--output", "File name too long")
    _no_leftovers(private_tmp)


def test_the_temp_folder_full_while_an_fmu_is_extracted(tmp_path, test_fmus, private_tmp):
    """RLIMIT_FSIZE below the FMU's library: its extraction fails; one line, nothing left."""
    out = tmp_path / "out"
    code, _, stderr = railcosim("run", _pair(tmp_path, test_fmus), "--no-build", "--output", out,
                                preexec_fn=_limit_file_size(100_000))
    _one_error_line(code, stderr, "File too large")
    assert json.loads((out / "summary.json").read_text())["completed"] is False
    _no_leftovers(private_tmp, out)


# ---- options ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("option,value", [("--stop-time", "nan"), ("--stop-time", "inf"),
                                          ("--stop-time", "1e300"), ("--output-interval", "nan"),
                                          ("--output-interval", "-inf"), ("--output-interval", "1e300")])
def test_non_finite_or_huge_times_are_refused(tmp_path, option, value):
    code, _, stderr = railcosim("run", "ato_only", "--no-build", "--output", tmp_path / "out", f"{option}={value}")
    _one_error_line(code, stderr, option, "finite number of seconds")
    assert not (tmp_path / "out").exists()


def test_a_scenario_ending_at_infinity_is_refused(tmp_path, test_fmus, private_tmp):
    scenario = tmp_path / "scenario.json"
    scenario.write_text('{"events": [], "end": Infinity}')        # Python's json reads it
    code, _, stderr = railcosim("run", _pair(tmp_path, test_fmus), "--no-build", "--output", tmp_path / "out",
                                "--scenario", scenario)
    _one_error_line(code, stderr, "scenario.json: field end", "finite")
    assert not (tmp_path / "out").exists()
    _no_leftovers(private_tmp)


@pytest.mark.parametrize("option,value", [("--frame", "100000"), ("--sections", "65"), ("--trains", "0"),
                                          ("--trains", "17")])
def test_build_sizes_are_bounded(tmp_path, option, value):
    code, _, stderr = railcosim("build", option, value, "--dest", tmp_path / "fmus")
    _one_error_line(code, stderr, f"{option} {value}", "must be from 1 to")
    assert not (tmp_path / "fmus").exists()


def test_captures_and_events_beyond_the_stop_time_are_warned_about(tmp_path, test_fmus, private_tmp):
    folder = tmp_path / "src"
    write_ssd(folder, "src", [ComponentSpec("src", str(test_fmus / "TestFrameSource.fmu"), 0.001),
                              ComponentSpec("c", str(test_fmus / "TestCounter.fmu"), 0.1)], [], stop_time=1.0)
    scenario = tmp_path / "scenario.json"
    scenario.write_text(json.dumps({"events": [
        {"time": 0.5, "model": "c", "variable": "u", "action": "set", "value": 1.0},
        {"time": 1.0, "model": "c", "variable": "u", "action": "set", "value": 2.0},
        {"time": 7.0, "model": "c", "variable": "u", "action": "set", "value": 3.0}]}))
    out = tmp_path / "out"
    code, _, stderr = railcosim("run", folder, "--no-build", "--output", out, "--scenario", scenario,
                                "--capture", "src.y@2:3", "--capture", "src.y@0.5:0.6")
    assert code == 0, stderr
    warnings = [line for line in stderr.splitlines() if line.startswith("railcosim: warning:")]
    assert len(warnings) == 3, stderr
    assert "--capture src.y@2:3" in warnings[0] and "stop time 1 s" in warnings[0]
    assert "t = 1 s" in warnings[1] and "t = 7 s" in warnings[2]
    applied = json.loads((out / "summary.json").read_text())["scenario"]["events_applied"]
    assert [event["t"] for event in applied] == [0.5]


# ---- temp folders and archives -----------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["not a zip", "zip-slip", "no SSD"])
def test_a_refused_ssp_leaves_no_extraction_folder(tmp_path, private_tmp, kind):
    archive = tmp_path / "bad.ssp"
    if kind == "not a zip":
        archive.write_bytes(b"this is not a zip")
    else:
        with zipfile.ZipFile(archive, "w") as handle:
            handle.writestr("readme.txt", "x")
            if kind == "zip-slip":
                handle.writestr("../../escaped.txt", "x")
    code, _, stderr = railcosim("run", archive, "--no-build", "--output", tmp_path / "out")
    _one_error_line(code, stderr, *(["bad.ssp"] if kind != "no SSD" else ["SystemStructure.ssd"]))
    _no_leftovers(private_tmp)


def test_packing_replaces_the_archive_atomically(tmp_path, test_fmus):
    """A reader opening the .ssp while it is packed again and again always finds a whole zip."""
    from orchestrator.packaging.packing import pack_system

    folder = _pair(tmp_path, test_fmus)
    (folder / "big.bin").write_bytes(os.urandom(3_000_000))   # long enough writes to be caught mid-way
    dest = tmp_path / "packed"
    target = pack_system(folder, test_fmus, dest)
    stop = threading.Event()
    problems = []

    def read():
        while not stop.is_set():
            try:
                with zipfile.ZipFile(target) as archive:
                    assert "SystemStructure.ssd" in archive.namelist()
            except Exception as error:  # noqa: BLE001  (what a reader would see)
                problems.append(repr(error))

    reader = threading.Thread(target=read)
    reader.start()
    try:
        for _ in range(8):
            pack_system(folder, test_fmus, dest, force=True)
    finally:
        stop.set()
        reader.join()
    assert problems == []
    assert sorted(os.listdir(dest)) == ["pair.ssp"]


def test_run_system_refuses_options_before_touching_anything(tmp_path):
    with pytest.raises(UserError, match="--stop-time nan"):
        run_system(tmp_path / "nowhere", RunOptions(stop_time=float("nan"), output_dir=tmp_path / "out"))
    assert not (tmp_path / "out").exists()
