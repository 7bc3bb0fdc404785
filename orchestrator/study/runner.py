"""Running a study's runs on Dask distributed (docs/studies.md): the submitting side.

:func:`run_study` sends the runs to a Dask cluster, one task per run or, in a study of many
runs, per few runs (:func:`default_runs_per_task`): a ``LocalCluster`` of process workers with
one thread each, or the scheduler the user names. A task (:func:`execute_runs` of
orchestrator/study/worker.py) runs its runs on a worker, each in the worker's run process, and
returns their records; the submitting side writes DIR/study.csv and DIR/study.json.

A worker lost mid-task has its task (all its runs) re-run elsewhere by Dask; each run's folder
is written afresh and its record replaces nothing but itself, so nothing is counted twice.
"""
from __future__ import annotations

import csv
import json
import math
import os
import re
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
from orchestrator.study.spec import Run, StudySpec, point_label
from orchestrator.study.worker import RECORD, execute_runs

STATUSES = ("ok", "failed", "timeout", "lost")


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
    from orchestrator.results import RUN_FILES

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
    earlier = _earlier_sessions(output / STUDY_JSON, spec) if resume else []
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
             _write_json(output / STUDY_JSON, spec, counts, earlier + [{
                 "started": _timestamp(began), "wall_time_s": time.time() - began, "workers": worker_count,
                 "scheduler": scheduler, "runs": len(ordered) - skipped,
                 "interrupted": signal_name(flag.signum) if stopped else None}], system)]
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


def _timestamp(seconds: float) -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(seconds))


#: what study.json says of each session (the first run of a study, each --resume)
SESSION_KEYS = ("started", "wall_time_s", "workers", "scheduler", "runs", "interrupted")


def _earlier_sessions(path: Path, spec: StudySpec) -> List[dict]:
    """The sessions the study.json in the folder records, when it is this study's (a --resume
    goes on from them); a study.json of before sessions were recorded is its one session."""
    try:
        earlier = json.loads(path.read_text())
    except (OSError, ValueError):
        return []
    if not isinstance(earlier, dict) or earlier.get("hash") != spec.hash:
        return []
    sessions = earlier.get("sessions")
    if isinstance(sessions, list):
        return [{k: s.get(k) for k in SESSION_KEYS} for s in sessions if isinstance(s, dict)]
    return [{k: earlier.get(k) for k in SESSION_KEYS}]


def _write_json(path: Path, spec: StudySpec, counts: dict, sessions: List[dict], system: Optional[Path]) -> Path:
    """study.json: the study, its counts, and every session that ran its runs (``sessions``, the
    last this one); ``started`` is the first session's, ``wall_time_s`` their sum, ``workers``,
    ``scheduler`` and ``interrupted`` the last one's."""
    last = sessions[-1]
    data = {"name": spec.name, "file": str(spec.path.resolve()), "hash": spec.hash, "spec": spec.data,
            "system": str(system) if system else None, "axes": spec.axes, "collect": spec.collect,
            "safety": spec.safety, "counts": counts, "started": sessions[0]["started"],
            "wall_time_s": sum(float(s.get("wall_time_s") or 0.0) for s in sessions), "workers": last["workers"],
            "scheduler": last["scheduler"], "interrupted": last["interrupted"], "sessions": sessions}
    replace_file(path, json.dumps(data, indent=1, default=str) + "\n")
    return path
