"""A study's runs on a Dask worker (docs/studies.md): what the worker prepares once (the imports
of a run, a folder where each FMU is extracted once, each system's FMUs imported and its plan
read), and its run process (:class:`RunProcess`), forked from it once for the runs of a
system and kept while its runs end ``ok``: pythonfmu FMUs share the interpreter of the process
that loads them, the run process can be stopped at the study's per-run timeout without losing
the worker, and a crash in an FMU ends the run process only; after a run that did not end
``ok`` the next run gets a run process forked afresh. Each run writes its usual folder
DIR/runs/<id>/ plus study_run.json, its record (:func:`execute_run`); a task's runs
(:func:`execute_runs`) are what orchestrator/study/runner.py submits.
"""
from __future__ import annotations

import gc
import json
import os
import select
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Dict, List, Optional, Sequence

from orchestrator.errors import UserError
from orchestrator.study.collect import collect
from orchestrator.study.spec import set_text

RECORD = "study_run.json"
#: the ATO's cache of stage plans (fmus/ato_controller/planner.py reads this variable)
PLAN_CACHE_ENV = "RAILCOSIM_PLAN_CACHE"
#: after SIGTERM at a timeout, the run has this long to write its files before SIGKILL
GRACE_S = 10.0
POLL_S = 0.02
EXIT_POLL_S = 0.001

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
            from orchestrator.plan import RunOptions, plan_run

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


def _run_system_here(job: dict, run_dir: Path, warnings: List[str], opened: bool = False,
                     host_keeps_frozen: bool = False) -> dict:
    """The job's system run here; ``opened``: the system read once per process
    (:func:`_opened_system`); ``host_keeps_frozen``: in a run process, whose objects stay frozen
    (:func:`_serve`)."""
    from functools import partial

    from orchestrator.verdicts.labels import railway_labels
    from orchestrator.verdicts.verdict import railway_verdicts
    from orchestrator.process_policy import ProcessPolicy
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
        default_scenario=not opts.get("no_scenario", False), progress=False, warn=warnings.append,
        summaries=partial(railway_verdicts, warn=warnings.append), labels=railway_labels,
        process=ProcessPolicy(host_keeps_frozen=host_keeps_frozen))
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


def _outcome_of(job: dict, caught=BaseException, opened: bool = False, host_keeps_frozen: bool = False) -> dict:
    """Run ``job`` here: its outcome (status, error, warnings); any failure of the ``caught``
    kinds is the run's. ``opened``: a system read once per process; ``host_keeps_frozen``: this
    process's objects stay frozen (a run process)."""
    outcome = {"status": "ok", "error": None, "warnings": []}
    run_dir = Path(job["output"]) / "runs" / job["id"]
    try:
        if job.get("function"):
            _run_function_here(job, run_dir)
        else:
            _run_system_here(job, run_dir, outcome["warnings"], opened, host_keeps_frozen)
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
        # the worker's objects were frozen before the fork and stay so (its runs freeze
        # nothing); each run's own garbage is collected after it (below)
        with os.fdopen(job_fd, "rb") as jobs:
            for line in jobs:
                outcome = _outcome_of(json.loads(line), opened=not one_shot, host_keeps_frozen=True)
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
