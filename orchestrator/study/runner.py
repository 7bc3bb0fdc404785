"""Running a study's runs on Dask distributed (docs/studies.md).

The submitting side (:func:`run_study`) sends one task per run to a Dask cluster: a
``LocalCluster`` of process workers with one thread each, or the scheduler the user names.
Each task (:func:`execute_run`, on a worker) runs its one run in a child process forked for it:
pythonfmu FMUs share the interpreter of the process that loads them, the child can be stopped
at the study's per-run timeout without losing the worker, and a crash in an FMU ends the child
only. The run writes its usual folder DIR/runs/<id>/ plus study_run.json (the run's record);
the task returns the record, and the submitting side writes DIR/study.csv and DIR/study.json.

A worker lost mid-run has its task re-run elsewhere by Dask; the run's folder is written
afresh and its record replaces nothing but itself, so nothing is counted twice.
"""
from __future__ import annotations

import csv
import gc
import json
import math
import os
import select
import signal
import sys
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence, TextIO

from orchestrator.errors import UserError
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
        import orchestrator.analysis.verdict  # noqa: F401
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
            from orchestrator.analysis.verdict import railway_verdicts
            from orchestrator.run import RunOptions, plan_run

            plan_run(description, RunOptions(fmu_dirs=[Path(p) for p in fmu_dirs], summaries=railway_verdicts,
                                             warn=lambda line: None))
        except Exception:                      # noqa: BLE001 — the run reports it
            pass
    finally:
        description.close()


def _run_system_here(job: dict, run_dir: Path, warnings: List[str]) -> dict:
    from functools import partial

    from orchestrator.analysis.verdict import railway_verdicts
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
    return run_system(job["system"], options).summary


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
    function = import_function(job["function"], job["python_path"], "function")
    keywords = {**job["arguments"], **job["values"]}
    if job["seed"] is not None:
        keywords["seed"] = job["seed"]
    began = time.perf_counter()
    summary = dict(function(**keywords))
    summary.setdefault("wall_time_s", time.perf_counter() - began)
    for name, data in (("summary.json", summary),
                       ("metadata.json", {"function": job["function"], "keywords": keywords})):
        (run_dir / name).write_text(json.dumps(data, indent=2, default=str) + "\n")
    return summary


def _child(job: dict, run_dir: Path, write_fd: int) -> None:
    """The forked run: its outcome as one JSON line on the pipe, then _exit (no exit-time
    handlers of the worker's)."""
    outcome = {"status": "ok", "error": None, "warnings": []}
    try:
        try:     # die with the worker: a lost worker leaves no run behind (Linux)
            import ctypes

            ctypes.CDLL(None).prctl(1, signal.SIGKILL)     # PR_SET_PDEATHSIG
        except (OSError, AttributeError):
            pass
        if job.get("function"):
            _run_function_here(job, run_dir)
        else:
            _run_system_here(job, run_dir, outcome["warnings"])
    except UserError as error:
        outcome.update(status="failed", error=" ".join(str(error).split()))
    except BaseException as error:                     # noqa: B902 — any failure is the run's
        outcome.update(status="failed", error=" ".join(f"{type(error).__name__}: {error}".split()))
    try:
        os.write(write_fd, (json.dumps(outcome, default=str)[:60000] + "\n").encode())
    finally:
        os._exit(0)


def _in_child(job: dict, run_dir: Path, timeout_s: float) -> dict:
    read_fd, write_fd = os.pipe()
    # what the worker holds goes to the collector's permanent generation: a collection in the
    # child would otherwise touch every object of the worker's and copy its memory page by page
    gc.freeze()
    pid = os.fork()
    if pid == 0:                                       # the child
        os.close(read_fd)
        _child(job, run_dir, write_fd)
    os.close(write_fd)
    chunks: List[bytes] = []
    os.set_blocking(read_fd, False)
    deadline, killed, status = time.monotonic() + timeout_s, None, None
    ended = False                    # the pipe's end seen: the child is exiting
    try:
        while status is None:
            try:
                while chunk := os.read(read_fd, 65536):
                    chunks.append(chunk)
                ended = True
            except BlockingIOError:
                pass
            done, status_code = os.waitpid(pid, os.WNOHANG)
            if done:
                status = status_code
                break
            now = time.monotonic()
            if killed is None and now > deadline:
                os.kill(pid, signal.SIGTERM)            # the run writes what it has, then stops
                killed = now
            elif killed is not None and now > killed + GRACE_S:
                os.kill(pid, signal.SIGKILL)
            if ended:                # only the reaping is left
                time.sleep(EXIT_POLL_S)
            else:                    # woken by the outcome (or the end) the moment it comes
                select.select([read_fd], [], [], POLL_S)
        try:
            while chunk := os.read(read_fd, 65536):
                chunks.append(chunk)
        except BlockingIOError:
            pass
    except BaseException:
        try:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
        except (ProcessLookupError, ChildProcessError):
            pass
        raise
    finally:
        os.close(read_fd)
    if killed is not None:
        return {"status": "timeout", "error": f"stopped after the study's timeout of {timeout_s:g} s",
                "warnings": []}
    text = b"".join(chunks).decode(errors="replace").strip()
    if not text:
        how = (f"signal {os.WTERMSIG(status)}" if os.WIFSIGNALED(status)
               else f"exit status {os.WEXITSTATUS(status)}")
        return {"status": "failed", "error": f"the run's process ended by {how} without a result",
                "warnings": []}
    return json.loads(text.splitlines()[-1])


def execute_run(job: dict) -> dict:
    """One run, on a worker: its folder DIR/runs/<id>/, its record study_run.json, returned."""
    run_dir = Path(job["output"]) / "runs" / job["id"]
    run_dir.mkdir(parents=True, exist_ok=True)
    for stale in (RECORD, "summary.json"):   # what an earlier attempt left must not be read as this run's
        (run_dir / stale).unlink(missing_ok=True)
    if not job.get("function"):
        prepare_worker()
        prepare_system(job["system"], job["fmu_dirs"])
    began = time.perf_counter()
    if hasattr(os, "fork"):
        outcome = _in_child(job, run_dir, job["timeout_s"])
    else:                                     # no fork (Windows): in the worker, without a timeout
        outcome = {"status": "ok", "error": None, "warnings": []}
        try:
            if job.get("function"):
                _run_function_here(job, run_dir)
            else:
                _run_system_here(job, run_dir, outcome["warnings"])
        except Exception as error:            # noqa: BLE001 — recorded as the run's failure
            outcome.update(status="failed", error=" ".join(str(error).split()))
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


# ---- the submitting side -------------------------------------------------------------------------
@dataclass
class StudyResult:
    output: Path
    records: List[dict]
    counts: Dict[str, int]
    skipped: int = 0
    dashboard: Optional[str] = None
    files: List[Path] = field(default_factory=list)


def jobs_of(spec: StudySpec, output: Path, system: Optional[Path], fmu_dirs: Sequence[Path],
            python_path: Sequence[str] = ()) -> List[dict]:
    """One plain dictionary per run: everything a worker needs, nothing of the client's."""
    data, spec_hash = spec.data, spec.hash
    common = {"output": str(output), "spec_hash": spec_hash, "collect": spec.collect,
              "timeout_s": spec.timeout_s, "stop_time": data.get("stop_time"),
              "options": data.get("options", {}), "seed_variables": data.get("seed_variables", []),
              "system": str(system) if system else None, "fmu_dirs": [str(p) for p in fmu_dirs],
              "function": data.get("function"), "arguments": data.get("arguments", {}),
              "python_path": [str(spec.path.parent.resolve()), *map(str, python_path)]}
    return [{**common, "id": run.id, "point": run.point, "values": run.values, "seed": run.seed,
             "scenario": run.scenario, "label": point_label(run)} for run in spec.runs]


def _resumable(output: Path, run: Run, spec_hash: str) -> Optional[dict]:
    """The record of a finished run of this very study (same hash), else None."""
    folder = output / "runs" / run.id
    try:
        record = json.loads((folder / RECORD).read_text())
    except (OSError, ValueError):
        return None
    if record.get("spec_hash") == spec_hash and record.get("status") == "ok" and (folder / "summary.json").is_file():
        return record
    return None


class _Progress:
    """``study: 5/8 done, 1 failed, 2 running, ETA 0:40`` — redrawn in place on a terminal, a
    line per tenth of the study otherwise."""

    def __init__(self, total: int, workers: int, stream: Optional[TextIO]):
        self.total, self.workers, self.stream = total, max(workers, 1), stream
        self.done = self.failed = 0
        self.began = time.monotonic()
        self.tty = bool(stream is not None and stream.isatty())
        self.shown = -1

    def update(self, record: dict) -> None:
        self.done += 1
        self.failed += record["status"] != "ok"
        if self.stream is None:
            return
        running = min(self.workers, self.total - self.done)
        elapsed = time.monotonic() - self.began
        left = elapsed / self.done * (self.total - self.done)
        eta = time.strftime("%H:%M:%S", time.gmtime(left)) if self.done < self.total else "done"
        text = (f"study: {self.done}/{self.total} done, {self.failed} failed, {running} running, "
                f"ETA {eta}")
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


def _client(workers: Optional[int], scheduler: Optional[str]):
    """(client, cluster or None, number of workers)."""
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
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                           dashboard_address=":0", silence_logs=logging.ERROR,
                           host="127.0.0.1")
    return Client(cluster), cluster, workers


def run_study(spec: StudySpec, output: Path, system: Optional[Path], fmu_dirs: Sequence[Path],
              workers: Optional[int] = None, scheduler: Optional[str] = None, resume: bool = False,
              progress: Optional[TextIO] = None, python_path: Sequence[str] = ()) -> StudyResult:
    """Run every run of ``spec`` not already done (``resume``) and write DIR/study.csv and
    DIR/study.json."""
    output = Path(output).resolve()
    (output / "runs").mkdir(parents=True, exist_ok=True)
    jobs = jobs_of(spec, output, system, fmu_dirs, python_path)
    records: Dict[str, dict] = {}
    if resume:
        for run in spec.runs:
            record = _resumable(output, run, spec.hash)
            if record is not None:
                records[run.id] = record
    skipped = len(records)
    todo = [job for job in jobs if job["id"] not in records]
    began = time.time()
    dashboard, worker_count = None, 0
    if todo:
        from distributed import as_completed

        client, cluster, worker_count = _client(workers, scheduler)
        dashboard = _dashboard(client)
        if progress is not None:
            where = scheduler or f"a local cluster of {worker_count} worker process(es)"
            progress.write(f"study {spec.name}: {len(todo)} run(s) on {where}"
                           + (f" ({skipped} done before, skipped)" if skipped else "")
                           + (f"; dashboard {dashboard}" if dashboard else "") + "\n")
            progress.flush()
        bar = _Progress(len(todo), worker_count, progress)
        token = uuid.uuid4().hex[:8]
        try:
            futures = {client.submit(execute_run, job, key=f"{spec.name}-{job['id']}-{token}",
                                     retries=0): job for job in todo}
            for future in as_completed(futures):
                job = futures[future]
                try:
                    record = future.result()
                except Exception as error:        # noqa: BLE001 — the task itself was lost
                    record = {"id": job["id"], "spec_hash": job["spec_hash"], "point": job["point"],
                              "values": job["label"], "seed": job["seed"], "status": "lost",
                              "error": " ".join(f"{type(error).__name__}: {error}".split()),
                              "warnings": [], "wall_time_s": None,
                              "collected": {k: None for k in job["collect"]}}
                records[job["id"]] = record
                bar.update(record)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    ordered = [records[job["id"]] for job in jobs]
    counts = {status: sum(r["status"] == status for r in ordered) for status in STATUSES}
    counts.update(runs=len(ordered), points=len({r["point"] for r in ordered}), skipped=skipped)
    files = [_write_csv(output / "study.csv", spec, ordered),
             _write_json(output / "study.json", spec, counts, began, worker_count, scheduler, system)]
    return StudyResult(output, ordered, counts, skipped, dashboard, files)


def columns_of(spec: StudySpec) -> List[str]:
    return ["id", "point", *spec.axes, "seed", "status", "wall_time_s", *spec.collect, "error"]


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else str(value)
    return str(value)


def _write_csv(path: Path, spec: StudySpec, records: List[dict]) -> Path:
    with open(path, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(columns_of(spec))
        for r in records:
            writer.writerow([r["id"], r["point"], *[_cell(r["values"].get(a)) for a in spec.axes],
                             _cell(r["seed"]), r["status"], _cell(r["wall_time_s"]),
                             *[_cell(r["collected"].get(k)) for k in spec.collect], r["error"] or ""])
    return path


def _write_json(path: Path, spec: StudySpec, counts: dict, began: float, workers: int,
                scheduler: Optional[str], system: Optional[Path]) -> Path:
    data = {"name": spec.name, "file": str(spec.path.resolve()), "hash": spec.hash, "spec": spec.data,
            "system": str(system) if system else None, "axes": spec.axes, "collect": spec.collect,
            "safety": spec.safety, "counts": counts,
            "started": time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(began)),
            "wall_time_s": time.time() - began, "workers": workers, "scheduler": scheduler}
    path.write_text(json.dumps(data, indent=1, default=str) + "\n")
    return path
