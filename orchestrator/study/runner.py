"""Running a study's runs on Dask distributed (docs/studies.md).

The submitting side (:func:`run_study`) sends the runs to a Dask cluster, one task per run or,
in a study of many runs, per few runs (:func:`default_runs_per_task`): a ``LocalCluster`` of
process workers with one thread each, or the scheduler the user names. A task
(:func:`execute_runs`, on a worker) hands each of its runs (:func:`execute_run`) to the
worker's run process (:class:`RunProcess`), forked from the worker once for the runs of a
system and kept while its runs end ``ok``: pythonfmu FMUs share the interpreter of the process
that loads them, the run process can be stopped at the study's per-run timeout without losing
the worker, and a crash in an FMU ends the run process only; after a run that did not end
``ok`` the next run gets a run process forked afresh. The run writes its usual folder
DIR/runs/<id>/ plus study_run.json (the run's record); the task returns its runs' records, and
the submitting side writes DIR/study.csv and DIR/study.json.

A worker lost mid-task has its task (all its runs) re-run elsewhere by Dask; each run's folder
is written afresh and its record replaces nothing but itself, so nothing is counted twice.
"""
from __future__ import annotations

import csv
import gc
import json
import math
import os
import re
import select
import signal
import sys
import threading
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence, TextIO

from orchestrator.errors import UserError
from orchestrator.folders import create_file, refuse_link, replace_file
from orchestrator.interrupts import signal_name
from orchestrator.study.collect import collect
from orchestrator.study.spec import Run, StudySpec, point_label, set_text

RECORD = "study_run.json"
#: the ATO's cache of stage plans (fmus/ato_controller/planner.py reads this variable)
PLAN_CACHE_ENV = "RAILCOSIM_PLAN_CACHE"
#: after SIGTERM at a timeout, the run has this long to write its files before SIGKILL
GRACE_S = 10.0
POLL_S = 0.02
EXIT_POLL_S = 0.001
STATUSES = ("ok", "failed", "timeout", "lost")


# ---- the worker's side ---------------------------------------------------------------------------
_WORKER_FOLDER: Optional[Path] = None


def prepare_worker() -> Path:
    """Once per worker process, before its first run is forked: what every run needs and no
    run changes is made here, so each run starts from it: the imports of a run (numpy,
    scipy, fmpy, the orchestrator and the railway analysis), a folder of the worker's own
    where each FMU is extracted once for all its runs (orchestrator/fmu.py keep_extractions)
    and where the ATO keeps the stage plans of a line, timetable, rolling stock and settings
    it has planned (unless the environment names a folder for them already). The folder is
    removed when the worker exits. Returns the folder."""
    global _WORKER_FOLDER
    if _WORKER_FOLDER is None:
        import atexit
        import shutil
        import tempfile

        import fmpy.fmi2  # noqa: F401 — imported here once rather than in every run
        import jsonschema  # noqa: F401 — the data files' schema check
        import orchestrator.verdicts.verdict  # noqa: F401
        import orchestrator.run  # noqa: F401
        from orchestrator.fmu import keep_extractions

        from multiprocessing.util import Finalize

        folder = Path(tempfile.mkdtemp(prefix="railcosim_worker_"))
        # removed at the worker's exit: a plain process runs atexit, a multiprocessing child
        # (a LocalCluster's or `dask worker`'s) only multiprocessing's finalizers
        atexit.register(shutil.rmtree, folder, True)
        Finalize(None, shutil.rmtree, args=(folder, True), exitpriority=0)
        keep_extractions(folder / "fmus")
        os.environ.setdefault(PLAN_CACHE_ENV, str(folder / "ato_plans"))
        _WORKER_FOLDER = folder
    return _WORKER_FOLDER


_PREPARED_SYSTEMS: set = set()


def prepare_system(system: str, fmu_dirs: Sequence[str]) -> None:
    """Once per system in a worker (after :func:`prepare_worker`): each of its Python FMUs
    extracted into the worker's folder and its module imported, so that a run forked from the
    worker instantiates them without compiling and importing their code. Whatever fails here
    is left for the run to meet and report."""
    key = (system, tuple(fmu_dirs))
    if key in _PREPARED_SYSTEMS:
        return
    _PREPARED_SYSTEMS.add(key)
    from orchestrator.fmu import import_python_module
    from orchestrator.ssp import open_system

    try:
        description = open_system(Path(system), [Path(p) for p in fmu_dirs])
    except Exception:                          # noqa: BLE001 — the run reports it
        return
    try:
        for component in description.components.values():
            if component.fmu_path is not None and Path(component.fmu_path).suffix == ".fmu":
                try:
                    import_python_module(Path(component.fmu_path))
                except Exception:              # noqa: BLE001 — the run reports it
                    pass
        try:    # the run's plan as far as it goes without the run's values: the FMUs' interfaces
            # read and the data files' schema checks done (both kept for the forked runs)
            from orchestrator.verdicts.verdict import railway_verdicts
            from orchestrator.run import RunOptions, plan_run

            plan_run(description, RunOptions(fmu_dirs=[Path(p) for p in fmu_dirs], summaries=railway_verdicts,
                                             warn=lambda line: None))
        except Exception:                      # noqa: BLE001 — the run reports it
            pass
    finally:
        description.close()


def prepare_function(name: str, python_path: Sequence[str]) -> None:
    """A function study's module imported once in the worker (its runs are forked from it
    and find it imported); whatever fails here is left for the run to meet and report."""
    try:
        import_function(name, python_path, "function")
    except Exception:                          # noqa: BLE001 — the run reports it
        pass


#: in a run process, each system folder's description as read for its first run (pickled):
#: every run gets a copy of its own (0.03 ms for ato_only, 0.6 ms for free_run, where reading
#: the SSD takes 0.5-1 ms and 6 ms); its FMUs are looked for anew for each run
_OPENED_SYSTEMS: Dict[tuple, bytes] = {}


def _opened_system(system: str, fmu_dirs: Sequence[str]):
    """A system folder's description, read once per process; a .ssp stays a path (it is
    unpacked for each run)."""
    import pickle

    from orchestrator.ssp import resolve_fmu, open_system

    if not Path(system).is_dir():
        return system
    key = (system, tuple(fmu_dirs))
    if key not in _OPENED_SYSTEMS:
        _OPENED_SYSTEMS[key] = pickle.dumps(open_system(Path(system), [Path(p) for p in fmu_dirs]))
    description = pickle.loads(_OPENED_SYSTEMS[key])
    for component in description.components.values():      # an FMU put in place meanwhile
        component.fmu_path = resolve_fmu(description.folder, component.source, [Path(p) for p in fmu_dirs])
    return description


def _run_system_here(job: dict, run_dir: Path, warnings: List[str], opened: bool = False) -> dict:
    """The job's system run here; ``opened``: the system read once per process
    (:func:`_opened_system`)."""
    from functools import partial

    from orchestrator.verdicts.verdict import railway_verdicts
    from orchestrator.run import RunOptions, run_system

    opts = job["options"]
    overrides = {key: set_text(v) for key, v in opts.get("set", {}).items()}
    overrides.update({key: set_text(v) for key, v in job["values"].items()})
    if job["seed"] is not None:
        overrides.update({key: str(job["seed"]) for key in job["seed_variables"]})
    scenario = job["scenario"] or opts.get("scenario")
    options = RunOptions(
        stop_time=job["stop_time"], output_dir=run_dir, overrides=overrides,
        param_sets=opts.get("param_sets", []), output_interval=opts.get("output_interval"),
        captures=opts.get("captures", []), record=opts.get("record"),
        algorithm=opts.get("algorithm", "gauss-seidel"), in_process=opts.get("in_process", False),
        fmu_dirs=[Path(p) for p in job["fmu_dirs"]], scenario=Path(scenario) if scenario else None,
        default_scenario=not opts.get("no_scenario", False), progress=False, warn=warnings.append)
    options.summaries = partial(railway_verdicts, warn=options.warn)
    system = _opened_system(job["system"], job["fmu_dirs"]) if opened else job["system"]
    return run_system(system, options).summary


def import_function(name: str, python_path: Sequence[str], where: str):
    """``module:callable``, imported with ``python_path`` searched first; a UserError naming
    ``where`` when it cannot be."""
    import importlib

    for folder in python_path:
        if folder not in sys.path:
            sys.path.insert(0, folder)
    module_name, _, attribute = name.partition(":")
    try:
        function = getattr(importlib.import_module(module_name), attribute)
    except ImportError as error:
        raise UserError(f"{where}: {name}: cannot import {module_name} ({error}); a study of a function "
                        "needs its module importable on every worker") from None
    except AttributeError:
        raise UserError(f"{where}: {name}: module {module_name} has no {attribute!r}") from None
    if not callable(function):
        raise UserError(f"{where}: {name}: not callable")
    return function


def _run_function_here(job: dict, run_dir: Path) -> dict:
    import inspect

    function = import_function(job["function"], job["python_path"], "function")
    keywords = {**job["arguments"], **job["values"]}
    try:          # a function that takes fmu_dirs gets the study's FMU folders (docs/studies.md)
        takes_fmu_dirs = "fmu_dirs" in inspect.signature(function).parameters
    except (TypeError, ValueError):
        takes_fmu_dirs = False
    if takes_fmu_dirs:
        keywords.setdefault("fmu_dirs", list(job["fmu_dirs"]))
    if job["seed"] is not None:
        keywords["seed"] = job["seed"]
    began = time.perf_counter()
    summary = dict(function(**keywords))
    summary.setdefault("wall_time_s", time.perf_counter() - began)
    for name, data in (("summary.json", summary),
                       ("metadata.json", {"function": job["function"], "keywords": keywords})):
        (run_dir / name).write_text(json.dumps(data, indent=2, default=str) + "\n")
    return summary


def _outcome_of(job: dict, caught=BaseException, opened: bool = False) -> dict:
    """Run ``job`` here: its outcome (status, error, warnings); any failure of the ``caught``
    kinds is the run's. ``opened``: a system read once per process."""
    outcome = {"status": "ok", "error": None, "warnings": []}
    run_dir = Path(job["output"]) / "runs" / job["id"]
    try:
        if job.get("function"):
            _run_function_here(job, run_dir)
        else:
            _run_system_here(job, run_dir, outcome["warnings"], opened)
    except UserError as error:
        outcome.update(status="failed", error=" ".join(str(error).split()))
    except caught as error:                            # noqa: B902 — any failure is the run's
        outcome.update(status="failed", error=" ".join(f"{type(error).__name__}: {error}".split()))
    return outcome


#: the C library, opened once in the worker for its run processes' prctl (opening it in each
#: run process cost 5 ms of a 15 ms function run)
_LIBC = None


def _open_libc() -> None:
    global _LIBC
    if _LIBC is None and sys.platform.startswith("linux"):
        try:
            import ctypes

            _LIBC = ctypes.CDLL(None)
            _LIBC.prctl     # noqa: B018 — a C library without prctl is no use here
        except (OSError, AttributeError):
            _LIBC = False


def _serve(job_fd: int, outcome_fd: int, one_shot: bool) -> None:
    """A run process's loop: a job as one JSON line in, its outcome as one JSON line out, until
    the worker closes the job pipe, a run does not end ``ok`` (the next run gets a process
    forked afresh: nothing a failed run left behind reaches it) or, ``one_shot``, after the
    first run; then _exit (no exit-time handlers of the worker's)."""
    try:
        if _LIBC:                # die with the worker: a lost worker leaves no run behind (Linux)
            _LIBC.prctl(1, signal.SIGKILL)                 # PR_SET_PDEATHSIG
        # the worker's objects were frozen before the fork and stay so; each run's own garbage
        # is collected after it (below). A function's worker has not imported the run module
        # and its run processes need not (half a second each)
        run_module = sys.modules.get("orchestrator.run")
        if run_module is not None:
            run_module.HOST_KEEPS_FROZEN = True
        with os.fdopen(job_fd, "rb") as jobs:
            for line in jobs:
                outcome = _outcome_of(json.loads(line), opened=not one_shot)
                data = (json.dumps(outcome, default=str)[:60000] + "\n").encode()
                while data:
                    data = data[os.write(outcome_fd, data):]
                if one_shot or outcome["status"] != "ok":
                    break
                # the run's cyclic garbage collected now, while the worker records the run,
                # rather than by chance inside the next run's stepping
                gc.collect()
    finally:
        os._exit(0)


class _NotStarted(Exception):
    """The run process had ended before it could take the job."""


#: the worker's ends of the pipes of its run processes
_WORKER_ENDS: set = set()


class RunProcess:
    """A process forked from the worker that runs its runs, one at a time: what the worker
    prepared it has from the start, and each run goes in and comes out through a pipe, so a run
    can be stopped at its timeout (SIGTERM: it writes its results so far) and a crash in an FMU
    ends this process only. The runs of one system go to one process in turn (``one_shot``
    False): no fork per run. A run that is not ``ok`` ends the process (docs/studies.md)."""

    def __init__(self, key: tuple, one_shot: bool = False):
        self.key = key
        self._job_fd = self._outcome_fd = None
        self.pid: Optional[int] = None
        _open_libc()
        job_read, self._job_fd = os.pipe()
        try:
            self._outcome_fd, outcome_write = os.pipe()
        except OSError:
            os.close(job_read)
            self.close()
            raise
        # what the worker holds goes to the collector's permanent generation: a collection in
        # the child would otherwise touch every object of the worker's and copy its memory
        # page by page
        gc.freeze()
        try:
            pid = os.fork()
        except OSError:                                # no process to be had: no pipe kept either
            os.close(job_read)
            os.close(outcome_write)
            self.close()
            raise
        if pid == 0:                                   # the run process
            # the worker's ends of its other run processes' pipes, inherited: held here they
            # would keep those processes from seeing the worker close their job pipe
            for fd in (self._job_fd, self._outcome_fd, *_WORKER_ENDS):
                os.close(fd)
            _serve(job_read, outcome_write, one_shot)
        os.close(job_read)
        os.close(outcome_write)
        os.set_blocking(self._outcome_fd, False)
        _WORKER_ENDS.update((self._job_fd, self._outcome_fd))
        self.pid: Optional[int] = pid

    def ready(self) -> bool:
        """Still running and waiting for a job (False when it ended meanwhile: killed, or its
        parent thread gone)."""
        if self.pid is None:
            return False
        try:
            done, _ = os.waitpid(self.pid, os.WNOHANG)
        except ChildProcessError:
            done = self.pid
        if done:
            self.pid = None
            self.close()
        return self.pid is not None

    def run(self, job: dict, timeout_s: float) -> dict:
        """The job's outcome; after anything but ``ok`` the process has ended (reaped)."""
        data = (json.dumps(job) + "\n").encode()
        try:
            while data:
                data = data[os.write(self._job_fd, data):]
        except BrokenPipeError:              # it ended since ready(): the run did not begin
            self.close()
            raise _NotStarted from None
        chunks: List[bytes] = []
        deadline, killed, ended = time.monotonic() + timeout_s, None, False
        # poll, not select: select cannot watch a descriptor numbered 1024 or above
        waiting = select.poll()
        waiting.register(self._outcome_fd, select.POLLIN)
        try:
            while True:
                try:
                    while chunk := os.read(self._outcome_fd, 65536):
                        chunks.append(chunk)
                        if chunk.endswith(b"\n"):
                            break
                    else:
                        ended = True                   # the pipe's end: the process is exiting
                except BlockingIOError:
                    pass
                if ended or (chunks and chunks[-1].endswith(b"\n")):
                    break
                now = time.monotonic()
                if killed is None and now > deadline:
                    os.kill(self.pid, signal.SIGTERM)   # the run writes what it has, then stops
                    killed = now
                elif killed is not None and now > killed + GRACE_S:
                    os.kill(self.pid, signal.SIGKILL)
                waiting.poll(POLL_S * 1000)
        except BaseException:            # the worker itself stopped: so does the run
            self.close(kill=True)
            raise
        received = b"".join(chunks)
        # a whole line only: a process killed while it wrote leaves a part
        outcome = json.loads(received.decode(errors="replace").splitlines()[-1]) if received.endswith(b"\n") else None
        if killed is not None or outcome is None or outcome["status"] != "ok":
            status = self.close()
        if killed is not None:
            return {"status": "timeout", "error": f"stopped after the study's timeout of {timeout_s:g} s",
                    "warnings": []}
        if outcome is None:
            how = ("an unknown cause" if status is None else f"signal {os.WTERMSIG(status)}"
                   if os.WIFSIGNALED(status) else f"exit status {os.WEXITSTATUS(status)}")
            return {"status": "failed", "error": f"the run's process ended by {how} without a result",
                    "warnings": []}
        return outcome

    def close(self, kill: bool = False) -> Optional[int]:
        """End the process and reap it: with ``kill`` at once, else as it ends by itself (at once
        when it waits for a job: the job pipe closed, it exits); its wait status, None when it
        was reaped before."""
        for fd in (self._job_fd, self._outcome_fd):
            if fd is not None:
                _WORKER_ENDS.discard(fd)
                os.close(fd)
        self._job_fd = self._outcome_fd = None
        pid, self.pid = self.pid, None
        if pid is None:
            return None
        try:
            if kill:
                os.kill(pid, signal.SIGKILL)
            for _ in range(int(GRACE_S / EXIT_POLL_S)):
                done, status = os.waitpid(pid, os.WNOHANG)
                if done:
                    return status
                time.sleep(EXIT_POLL_S)
            os.kill(pid, signal.SIGKILL)
            return os.waitpid(pid, 0)[1]
        except ChildProcessError:
            return None


#: the process that runs this worker's runs of one system, per thread running tasks (a worker
#: runs one task at a time: `--nthreads 1`)
_RUN_PROCESSES = threading.local()


def _run_elsewhere(job: dict) -> dict:
    """The job's outcome from this thread's run process of the job's system (made, or made
    anew for another system or after a run that did not end ``ok``); a function's run from a
    process of its own."""
    if job.get("function"):
        process = RunProcess(("function",), one_shot=True)
        try:
            return process.run(job, job["timeout_s"])
        except _NotStarted:
            return {"status": "failed", "error": "the run's process ended before the run began", "warnings": []}
        finally:                 # its pipes closed and the process reaped, whatever the outcome
            process.close()
    key = (job["system"], tuple(job["fmu_dirs"]))
    process = getattr(_RUN_PROCESSES, "process", None)
    if process is not None and (process.key != key or not process.ready()):
        process.close()
        process = None
    if process is not None:
        try:
            return process.run(job, job["timeout_s"])
        except _NotStarted:
            pass
    process = _RUN_PROCESSES.process = RunProcess(key)
    try:
        return process.run(job, job["timeout_s"])
    except _NotStarted:
        return {"status": "failed", "error": "the run's process ended before the run began", "warnings": []}


def execute_run(job: dict) -> dict:
    """One run, on a worker: its folder DIR/runs/<id>/, its record study_run.json, returned."""
    run_dir = Path(job["output"]) / "runs" / job["id"]
    run_dir.mkdir(parents=True, exist_ok=True)
    for stale in (RECORD, "summary.json"):   # what an earlier attempt left must not be read as this run's
        (run_dir / stale).unlink(missing_ok=True)
    if job.get("function"):
        prepare_function(job["function"], job["python_path"])
    else:
        prepare_worker()
        prepare_system(job["system"], job["fmu_dirs"])
    began = time.perf_counter()
    if hasattr(os, "fork"):
        outcome = _run_elsewhere(job)
    else:                                     # no fork (Windows): in the worker, without a timeout
        outcome = _outcome_of(job, caught=Exception)
    wall_s = time.perf_counter() - began
    summary_path = run_dir / "summary.json"
    summary = json.loads(summary_path.read_text()) if summary_path.is_file() else {}
    record = {"id": job["id"], "spec_hash": job["spec_hash"], "point": job["point"],
              "values": job["label"], "seed": job["seed"], "status": outcome["status"],
              "error": outcome["error"], "warnings": outcome["warnings"][:20], "wall_time_s": wall_s,
              "collected": collect(summary, job["collect"], derived=not job.get("function"),
                                   results_csv=run_dir / "results.csv") if summary else
              {k: None for k in job["collect"]}}
    (run_dir / RECORD).write_text(json.dumps(record, indent=1, default=str) + "\n")
    return record


def execute_runs(jobs: List[dict]) -> List[dict]:
    """Several runs in one task, one after the other, their records in order. A short run
    costs the scheduler and the submitting side about as much per task as it costs the worker
    (docs/studies.md#runs-per-task)."""
    return [execute_run(job) for job in jobs]


# ---- the submitting side -------------------------------------------------------------------------
#: a task takes at most this many runs, and each worker gets at least this many tasks (so
#: the last tasks of a study still spread over the workers)
MAX_RUNS_PER_TASK = 8
TASKS_PER_WORKER = 8


def default_runs_per_task(runs: int, workers: int) -> int:
    """How many runs a task takes: one until every worker has TASKS_PER_WORKER tasks, then
    more, up to MAX_RUNS_PER_TASK."""
    return max(1, min(MAX_RUNS_PER_TASK, runs // (max(workers, 1) * TASKS_PER_WORKER)))


def _lost(job: dict, error: BaseException) -> dict:
    return {"id": job["id"], "spec_hash": job["spec_hash"], "point": job["point"],
            "values": job["label"], "seed": job["seed"], "status": "lost",
            "error": " ".join(f"{type(error).__name__}: {error}".split()),
            "warnings": [], "wall_time_s": None, "collected": {k: None for k in job["collect"]}}


@dataclass
class StudyResult:
    output: Path
    records: List[dict]
    counts: Dict[str, int]
    skipped: int = 0
    dashboard: Optional[str] = None
    files: List[Path] = field(default_factory=list)


def _common_job(spec: StudySpec, output: Path, system: Optional[Path], fmu_dirs: Sequence[Path],
                python_path: Sequence[str] = ()) -> dict:
    """What every job of the study shares."""
    data = spec.data
    return {"output": str(output), "spec_hash": spec.hash, "collect": spec.collect,
            "timeout_s": spec.timeout_s, "stop_time": data.get("stop_time"),
            "options": data.get("options", {}), "seed_variables": data.get("seed_variables", []),
            "system": str(system) if system else None, "fmu_dirs": [str(p) for p in fmu_dirs],
            "function": data.get("function"), "arguments": data.get("arguments", {}),
            "python_path": [str(spec.path.parent.resolve()), *map(str, python_path)]}


def _job(common: dict, run: Run) -> dict:
    return {**common, "id": run.id, "point": run.point, "values": run.values, "seed": run.seed,
            "scenario": run.scenario, "label": point_label(run)}


def jobs_of(spec: StudySpec, output: Path, system: Optional[Path], fmu_dirs: Sequence[Path],
            python_path: Sequence[str] = ()) -> List[dict]:
    """One plain dictionary per run: everything a worker needs, nothing of the client's."""
    common = _common_job(spec, output, system, fmu_dirs, python_path)
    return [_job(common, run) for run in spec.runs]


#: a run's folder under DIR/runs/ (Run.id)
RUN_ID = re.compile(r"r\d{4,}")


def _resumable(folder: Path, spec_hash: str) -> Optional[dict]:
    """The record of a finished run of this very study (same hash) in ``folder``, else None."""
    try:
        record = json.loads((folder / RECORD).read_text())
    except (OSError, ValueError):
        return None
    if (isinstance(record, dict) and record.get("spec_hash") == spec_hash and record.get("status") == "ok"
            and (folder / "summary.json").is_file()):
        return record
    return None


def _is_run_folder(path: Path) -> bool:
    """A folder a study's run made: empty (made, the run not begun) or holding a run's own
    files (its record, a function's summary, a system run's lock and results)."""
    from orchestrator.folders import LOCK_FILE
    from orchestrator.run import RUN_FILES

    if path.is_symlink() or not path.is_dir():
        return False
    names = set(os.listdir(path))
    return not names or bool(names & {RECORD, LOCK_FILE, *RUN_FILES})


STUDY_CSV, STUDY_JSON = "study.csv", "study.json"


def _clear_runs(output: Path, spec: StudySpec, resume: bool) -> Dict[str, dict]:
    """DIR/runs/ made ready for this study: with ``resume`` the records of its finished runs
    kept (returned by id); every other run folder — a run to do again, or a run of an earlier,
    different study — removed, so the folder holds this study's runs only. Anything under
    runs/ named like a run that is not a run folder is refused before anything is removed."""
    import shutil

    runs = output / "runs"
    # nothing of the study written through a link planted in its folder (docs/reliability.md,
    # "What a run writes"): refused before any run starts
    for name in (STUDY_CSV, STUDY_JSON, "runs"):
        refuse_link(output / name)
    try:
        runs.mkdir(exist_ok=True)
        entries = [entry for entry in os.scandir(runs) if RUN_ID.fullmatch(entry.name)]
    except OSError as error:
        raise UserError(f"--output {output}: cannot use {runs} as the folder of the runs "
                        f"({error.strerror or error})") from None
    ids = {run.id for run in spec.runs} if resume else set()
    kept: Dict[str, dict] = {}
    stale: List[Path] = []
    for entry in entries:
        folder = Path(entry.path)
        record = _resumable(folder, spec.hash) if entry.name in ids else None
        if record is not None and record.get("id") == entry.name:
            kept[entry.name] = record
        elif _is_run_folder(folder):
            stale.append(folder)
        else:
            raise UserError(f"--output {output}: {folder} is not a study's run folder; move it away or "
                            "choose another --output")
    for folder in stale:
        try:
            shutil.rmtree(folder)
        except OSError as error:
            raise UserError(f"--output {output}: cannot remove the earlier run folder {folder} "
                            f"({error.strerror or error})") from None
    return kept


def _clock(seconds: float) -> str:
    """``1 d 02:03:04``, ``00:06:10``."""
    days, rest = divmod(int(seconds + 0.5), 86400)
    return (f"{days} d " if days else "") + time.strftime("%H:%M:%S", time.gmtime(rest))


class _Progress:
    """``study: 5/8 done, 1 failed, 2 running, ETA 0:40`` — redrawn in place on a terminal, a
    line per tenth of the study otherwise; once, after a few seconds or a tenth of the study,
    the estimate of the whole study's time. The pace is taken from the first task's end on:
    before it lie the workers' own start (imports, the FMUs' extraction)."""

    #: the estimate is stated once this long has passed or a tenth of the runs are done
    ESTIMATE_AFTER_S = 3.0

    def __init__(self, total: int, workers: int, stream: Optional[TextIO]):
        self.total, self.workers, self.stream = total, max(workers, 1), stream
        self.done = self.failed = 0
        self.began = time.monotonic()
        self.first: Optional[tuple] = None          # (time, runs done) at the first task's end
        self.tty = bool(stream is not None and stream.isatty())
        self.shown = -1
        self.estimated = False
        self.run_s, self.timed = 0.0, 0            # the runs' own wall time, over so many runs

    def left_s(self) -> float:
        """The time still to go at the slower of two paces: the study's since the first task
        ended (once each worker has ended a run since), and the runs' own mean time per worker."""
        now = time.monotonic()
        since, done = self.first if self.first and self.done - self.first[1] >= self.workers else (self.began, 0)
        pace = (now - since) / max(self.done - done, 1)
        return max(pace, self.run_s / max(self.timed, 1) / self.workers) * (self.total - self.done)

    def update(self, records: List[dict]) -> None:
        self.done += len(records)
        timed = [r["wall_time_s"] for r in records if r.get("wall_time_s") is not None]
        self.run_s += sum(timed)
        self.timed += len(timed)
        self.failed += sum(record["status"] != "ok" for record in records)
        if self.first is None:
            self.first = (time.monotonic(), self.done)
        if self.stream is None:
            return
        running = min(self.workers, self.total - self.done)
        left = self.left_s()
        eta = _clock(left) if self.done < self.total else "done"
        text = (f"study: {self.done}/{self.total} done, {self.failed} failed, {running} running, "
                f"ETA {eta}")
        elapsed = time.monotonic() - self.began
        if (not self.estimated and self.done < self.total and self.done > self.first[1]
                and (elapsed >= self.ESTIMATE_AFTER_S or self.done * 10 >= self.total)):
            self.estimated = True
            self.stream.write(("\r" if self.tty else "")
                              + f"study: about {_clock(left + elapsed)} for the {self.total} run(s) at the pace so "
                              f"far ({_clock(left)} to go); Ctrl-C stops it, keeping the runs done (--resume "
                              "runs the rest)\n")
        if self.tty:
            self.stream.write("\r" + text + ("\n" if self.done == self.total else ""))
        elif self.done * 10 // self.total != self.shown or self.done == self.total:
            self.shown = self.done * 10 // self.total
            self.stream.write(text + "\n")
        self.stream.flush()


def _dashboard(client) -> Optional[str]:
    """The scheduler's dashboard address, when it serves one (its pages need bokeh: without it
    here, none is shown)."""
    import importlib.util

    if importlib.util.find_spec("bokeh") is None:
        return None
    try:
        services = client.scheduler_info().get("services", {})
        return client.dashboard_link if "dashboard" in services else None
    except Exception:                              # noqa: BLE001 — no dashboard to show
        return None


def dask_setup(worker) -> None:
    """A local cluster's worker process at its start (a Dask preload): Ctrl-C in the terminal
    reaches every process of the study; the submitting side stops the study and then the
    workers, so a worker ignores SIGINT rather than dying mid-run with a traceback (its run
    processes inherit that; a system run still stops in order on its own handlers)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


def _client(workers: Optional[int], scheduler: Optional[str], scratch: Optional[Path] = None):
    """(client, cluster or None, number of workers). A local cluster's workers keep all their
    temporary files (Dask's own, the worker folders, the runs' temp folders) in ``scratch``,
    which the submitting side removes however the workers end."""
    import logging

    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError, ValueError) as error:
            raise UserError(f"--scheduler {scheduler}: cannot connect ({' '.join(str(error).split())})") from None
        count = len(client.scheduler_info().get("workers", {}))
        if count == 0:
            try:
                client.wait_for_workers(1, timeout=30)
            except TimeoutError:
                client.close()
                raise UserError(f"--scheduler {scheduler}: no worker joined within 30 s "
                                "(start some with: dask worker ADDRESS --nthreads 1)") from None
            count = len(client.scheduler_info().get("workers", {}))
        return client, None, count
    if workers is None:
        workers = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    import dask

    where = {} if scratch is None else {"temporary-directory": str(scratch)}
    with dask.config.set(where):          # the scheduler's and the workers' dask-scratch-space
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               dashboard_address=":0", silence_logs=logging.ERROR, host="127.0.0.1",
                               preload=[__name__], env={"TMPDIR": str(scratch)} if scratch else None)
    return Client(cluster), cluster, workers


#: how often the submitting side looks for finished tasks and for a signal
WAIT_S = 0.02
#: how long the workers of a local cluster get to close after an interruption
CLOSE_S = 2.0


def run_study(spec: StudySpec, output: Path, system: Optional[Path], fmu_dirs: Sequence[Path],
              workers: Optional[int] = None, scheduler: Optional[str] = None, resume: bool = False,
              progress: Optional[TextIO] = None, python_path: Sequence[str] = (),
              runs_per_task: Optional[int] = None) -> StudyResult:
    """Run every run of ``spec`` not already done (``resume``) and write DIR/study.csv and
    DIR/study.json. ``runs_per_task`` fixes how many runs a task takes (default: chosen by
    :func:`default_runs_per_task` from the number of runs and workers).

    The folder is locked for the study as a run's folder is (orchestrator/folders.py
    FolderLock: a second study or run into it is refused). SIGINT, SIGTERM or SIGHUP stop
    the study: no run is handed out any more, the workers are stopped, the runs done are
    kept and written to study.csv, and :class:`~orchestrator.interrupts.Interrupted` is raised
    (``--resume`` goes on from there)."""
    from orchestrator import interrupts
    from orchestrator.folders import FolderLock

    output = Path(output).resolve()
    with interrupts.deferred() as flag:
        if flag is not None:
            flag.check("before the study started; nothing written")
        folder = FolderLock(output, f"--output {output}", "another study or run").acquire()
        try:
            return _run_claimed(spec, output, system, fmu_dirs, workers, scheduler, resume, progress,
                                python_path, runs_per_task, flag)
        finally:
            folder.release()


def _run_claimed(spec, output, system, fmu_dirs, workers, scheduler, resume, progress, python_path,
                 runs_per_task, flag) -> StudyResult:
    import shutil
    import tempfile

    records: Dict[str, dict] = _clear_runs(output, spec, resume)
    skipped = len(records)
    common = _common_job(spec, output, system, fmu_dirs, python_path)
    todo = [run for run in spec.runs if run.id not in records]
    began = time.time()
    dashboard, worker_count, stopped = None, 0, 0
    if todo:
        from distributed import as_completed

        scratch = None if scheduler else Path(tempfile.mkdtemp(prefix="railcosim_study_"))
        client = cluster = None
        try:
            client, cluster, worker_count = _client(workers, scheduler, scratch)
            if flag is not None:
                flag.check(f"before the first run; nothing run ({output})")
            dashboard = _dashboard(client)
            if progress is not None:
                where = scheduler or f"a local cluster of {worker_count} worker process(es)"
                progress.write(f"study {spec.name}: {len(todo)} run(s) of {len({r.point for r in todo})} point(s) "
                               f"on {where}" + (f" ({skipped} done before, skipped)" if skipped else "")
                               + (f"; dashboard {dashboard}" if dashboard else "") + "\n")
                progress.flush()
            bar = _Progress(len(todo), worker_count, progress)
            token = uuid.uuid4().hex[:8]
            size = runs_per_task if runs_per_task else default_runs_per_task(len(todo), worker_count)
            batches = ([_job(common, run) for run in todo[i:i + size]] for i in range(0, len(todo), size))
            # a bounded number of tasks handed out at a time: the scheduler holds a few per
            # worker, not the whole study, and an interruption has only these to cancel
            pending: Dict[object, List[dict]] = {}
            finished = as_completed()

            def hand_out() -> None:
                batch = next(batches, None)
                if batch is not None:
                    future = client.submit(execute_runs, batch, key=f"{spec.name}-{batch[0]['id']}-{token}",
                                           retries=0)
                    pending[future] = batch
                    finished.add(future)

            for _ in range(max(worker_count, 1) * TASKS_PER_WORKER):
                hand_out()
            while pending and not (flag is not None and flag.signum):
                ready = finished.next_batch(block=False)
                if not ready:
                    time.sleep(WAIT_S)
                for future in ready:
                    batch = pending.pop(future)
                    try:
                        done = future.result()
                    except Exception as error:        # noqa: BLE001 — the task itself was lost
                        done = [_lost(job, error) for job in batch]
                    for record in done:
                        records[record["id"]] = record
                    bar.update(done)
                    hand_out()
            if pending:
                client.cancel(list(pending))
                stopped = len(todo) - bar.done
        finally:
            _close(client, cluster, quick=bool(flag is not None and flag.signum))
            if scratch is not None:
                shutil.rmtree(scratch, ignore_errors=True)
    ordered = [records[run.id] for run in spec.runs if run.id in records]
    counts = {status: sum(r["status"] == status for r in ordered) for status in STATUSES}
    counts.update(runs=len(ordered), points=len({r["point"] for r in ordered}), skipped=skipped)
    if stopped:
        counts["not_run"] = stopped
    files = [_write_csv(output / STUDY_CSV, spec, ordered),
             _write_json(output / STUDY_JSON, spec, counts, began, worker_count, scheduler, system,
                         interrupted=signal_name(flag.signum) if stopped else None)]
    if stopped:
        from orchestrator.interrupts import Interrupted

        raise Interrupted(flag.signum, f"after {len(ordered) - skipped} of {len(todo)} run(s) had ended; every run "
                                       f"done is kept in {output} (--resume runs the rest)")
    return StudyResult(output, ordered, counts, skipped, dashboard, files)


def _close(client, cluster, quick: bool) -> None:
    """The client and a local cluster closed; after an interruption within :data:`CLOSE_S`
    each (a worker's run processes die with it)."""
    # a close that times out (a loaded machine after an interruption) must not stop the study
    # from writing study.csv and study.json: the workers die with the cluster's processes anyway
    for part in (client, cluster):
        if part is None:
            continue
        try:
            part.close(**({"timeout": CLOSE_S} if quick else {}))
        except (TimeoutError, OSError) as error:
            print(f"railcosim study: closing the Dask {type(part).__name__} took too long ({error or 'timed out'}); "
                  "its processes end with this one", file=sys.stderr)


def columns_of(spec: StudySpec) -> List[str]:
    return ["id", "point", *spec.axes, "seed", "status", "wall_time_s", *spec.collect, "error"]


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else str(value)
    return str(value)


def _write_csv(path: Path, spec: StudySpec, records: List[dict]) -> Path:
    with create_file(path) as f:
        writer = csv.writer(f)
        writer.writerow(columns_of(spec))
        for r in records:
            writer.writerow([r["id"], r["point"], *[_cell(r["values"].get(a)) for a in spec.axes],
                             _cell(r["seed"]), r["status"], _cell(r["wall_time_s"]),
                             *[_cell(r["collected"].get(k)) for k in spec.collect], r["error"] or ""])
    return path


def _write_json(path: Path, spec: StudySpec, counts: dict, began: float, workers: int,
                scheduler: Optional[str], system: Optional[Path], interrupted: Optional[str] = None) -> Path:
    data = {"name": spec.name, "file": str(spec.path.resolve()), "hash": spec.hash, "spec": spec.data,
            "system": str(system) if system else None, "axes": spec.axes, "collect": spec.collect,
            "safety": spec.safety, "counts": counts,
            "started": time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(began)),
            "wall_time_s": time.time() - began, "workers": workers, "scheduler": scheduler,
            "interrupted": interrupted}
    replace_file(path, json.dumps(data, indent=1, default=str) + "\n")
    return path
