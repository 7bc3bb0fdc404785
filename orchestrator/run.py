"""One run of a system, a straight pipe: its plan (orchestrator/plan.py: the options checked
when made, then everything decided before anything starts) → the components made and stepped by
the master with its observers (:func:`run_system`) → the results written
(orchestrator/results.py).

Results (docs/interfaces.md, "Results"): results.csv (recorder), capture_*.csv (waveform
windows), metadata.json and summary.json. They are written whether the run ends, fails or is
interrupted (SIGINT, SIGTERM, SIGHUP); a failure is re-raised after the files are complete.
The output folder is locked for the run and holds one run only (docs/reliability.md).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Dict, List, Optional

from orchestrator import interrupts
from orchestrator.errors import os_error
from orchestrator.fmu import extractions_kept, new_workdir, remove_workdir
from orchestrator.graph import TICKS_PER_SECOND, SystemGraph
from orchestrator.interrupts import InterruptFlag, Interrupted
from orchestrator.master import Master, shutdown_slaves
from orchestrator.observers import Progress, Recorder, WaveformCapture
from orchestrator.pacing import Pacer
from orchestrator.plan import RunOptions, RunPlan, plan_run
from orchestrator.protocols import Observer, Slave
from orchestrator.results import (Outcome, OutputFolder, interrupted_before_start, metadata, raise_failure,
                                  summary, write_columns, write_results)
from orchestrator.ssp import SystemDescription, open_system


@dataclass
class RunResult:
    graph: SystemGraph
    summary: dict
    steps_taken: Dict[str, int]
    end_time_s: float
    output_dir: Path


def run_system(system_path, options: RunOptions) -> RunResult:
    """Load a system, run it and write its results. ``system_path`` is a system folder or
    .ssp, or a system already opened (a :class:`SystemDescription` of a folder: a study's run
    process reads its system once, orchestrator/study/worker.py), which the run may change
    (a parameter set's units) and does not close.

    While it runs, SIGINT, SIGTERM and SIGHUP only set a flag (orchestrator/interrupts.py);
    the run stops at the next safe point and raises :class:`Interrupted` once its files are
    written. The output folder is locked for the run and holds this run only
    (orchestrator/results.py ``OutputFolder``). Once the folder is claimed the result files are
    written whether the run ends, fails or is interrupted; a failure is raised after they are
    complete (docs/reliability.md)."""
    with interrupts.deferred() as flag:
        return _run_system(system_path, options, flag if flag is not None else interrupts.NEVER)


def _run_system(system_path, options: RunOptions, flag: InterruptFlag) -> RunResult:
    out = OutputFolder(options.output_dir)
    opened = isinstance(system_path, SystemDescription)
    try:
        flag.check("before the run started")
        system = system_path if opened else open_system(Path(system_path), list(options.fmu_dirs))
    except Interrupted as stop:
        interrupted_before_start(out, system_path.name if opened else Path(system_path).stem, stop)
    except OSError as error:            # a .ssp extracted into a full temp folder
        raise os_error(error) from None
    close_system = (lambda: None) if opened else system.close
    try:
        flag.check("before the run started")
        plan = plan_run(system, options)
        plan.warn_before_start()
        flag.check("before the run started")
    except Interrupted as stop:
        close_system()
        interrupted_before_start(out, system.name, stop)
    except BaseException:
        close_system()
        raise
    workdir: Optional[Path] = None
    try:
        out.claim()                       # from here on the folder holds this run's files
        write_columns(out.path, plan)
        # the FMUs' extractions: in a folder of the run's, unless the process keeps them
        workdir = None if extractions_kept() else new_workdir()
        outcome = _run(plan, out.path, workdir, flag)
        master = outcome.master
        end_s = master.time_s if master is not None and master.time_ticks >= plan.start_ticks else system.start_time
        sim_time = end_s - system.start_time
        written = summary(plan, sim_time, outcome)
        # the folder (or a file streamed into it) removed or replaced meanwhile: never "results
        # in", and no summary written into a folder that is no longer the one locked (another
        # run's, perhaps); checked again after the writes
        streamed = outcome.streamed if outcome.failure is None else ()
        lost = out.lost(streamed)
        problems = write_results(out.path, written, metadata(plan, outcome.steps_taken)) if lost is None else []
        if flag.signum and outcome.failure is None:
            # the signal came while the files were closed or written: the run says so
            outcome.failure = Interrupted(flag.signum, "while the results were written")
            written = summary(plan, sim_time, outcome)
            if lost is None:
                problems = write_results(out.path, written, None) + problems
        if outcome.pacer is not None and outcome.pacer.verdict_line():
            options.warn(outcome.pacer.verdict_line())
        lost = lost or out.lost(streamed)
        if lost is not None:
            problems = [lost]          # what could not be written there follows from it
        raise_failure(outcome, problems, out.path)
        return RunResult(plan.graph, written, dict(outcome.steps_taken), end_s, out.path)
    finally:
        if workdir is not None:
            remove_workdir(workdir)
        close_system()
        out.release()


# ---- the components made and stepped -------------------------------------------------------------
def _observers(plan: RunPlan, out: Path) -> List[Observer]:
    """results.csv, one capture file per --capture, the progress bar and the judges, in the
    order they are called after each tick."""
    observers: List[Observer] = [Recorder(out / "results.csv", plan.recorded, plan.interval_ticks)]
    for request, elements in plan.captures:
        safe_port = request.port.replace("[", "_").replace("]", "").replace(",", "_")
        observers.append(WaveformCapture(out / f"capture_{request.component}_{safe_port}.csv",
                                         request, elements))
    if plan.options.progress != "none":
        observers.append(Progress(plan.options.progress, plan.system.start_time, plan.stop_ticks / TICKS_PER_SECOND,
                                  len(plan.graph.nodes), plan.options.progress_interval))
    observers.extend(plan.judges)
    return observers


def start_master(plan: RunPlan, slaves: Dict[str, Slave], make: Callable[[str, object], Slave],
                 observers: List[Observer], flag: InterruptFlag, pacer: Optional[Pacer] = None,
                 ready: Callable[[], bool] = lambda: True) -> Optional[Master]:
    """Make every component (into ``slaves``, so that whatever was made is shut down), then the
    master; bind and initialise. ``ready`` false after the components are made: no master
    (validate: a component that cannot be instantiated). A ``pacer`` comes first among the
    manipulators: each tick's work starts once its wall-clock deadline has come."""
    for name, node in plan.graph.nodes.items():
        flag.check("during initialisation")
        slaves[name] = make(name, node)
    if not ready():
        return None
    manipulators = ([pacer] if pacer is not None else []) + list(plan.options.manipulators) \
        + ([plan.scenario] if plan.scenario is not None else [])
    master = Master(plan.graph, slaves, plan.options.algorithm, observers, manipulators, interrupt=flag)
    master.bind()
    master.initialize(plan.system.start_time, plan.stop_s)
    return master


def _run(plan: RunPlan, out: Path, workdir: Optional[Path], flag: InterruptFlag) -> Outcome:
    """Make the slaves (their FMUs extracted into ``workdir``), bind, initialise and step;
    whatever happens (a failure, a signal, a write error), close every observer and shut every
    slave made down, so the results so far can be written."""
    began = time.perf_counter()
    failure: Optional[BaseException] = None
    graph, process = plan.graph, plan.options.process
    slaves: Dict[str, Slave] = {}
    observers: List[Observer] = []
    master: Optional[Master] = None
    # a slave that runs on its own clock (soft real time) needs the master at real time
    factor = plan.options.real_time
    if factor is None and plan.components.needs_real_time:
        factor = 1.0
    pacer = Pacer(factor, flag) if factor is not None else None
    initialised: Optional[float] = None
    try:
        with process.blas_limited():
            observers = _observers(plan, out)
            for observer in observers:
                if isinstance(observer, Progress):
                    observer.initialising()
            master = start_master(plan, slaves, lambda name, node: plan.components.make(name, node, workdir),
                                  observers, flag, pacer)
            initialised = time.perf_counter()
            with process.stepping():
                master.run_until(plan.stop_ticks)
    except BaseException as error:  # a failure or an interruption: results so far are still written
        failure = error
    ended = time.perf_counter()
    wall = ended - began
    init_s = (initialised if initialised is not None else ended) - began
    problems: List[str] = []
    for observer in observers:       # every one, even when an earlier one cannot close its file
        try:
            observer.close()
        except Exception as error:
            if failure is None:
                failure = error
            elif str(error) != str(failure):
                problems.append(str(error))
    problems.extend(shutdown_slaves(graph.order, slaves))
    steps = dict(master.steps_taken) if master is not None else {name: 0 for name in graph.nodes}
    streamed = [observer.path for observer in observers if isinstance(observer, (Recorder, WaveformCapture))]
    hil = {name: slave for name, slave in slaves.items() if name in plan.components.remote}
    return Outcome(wall, failure, problems, master, steps, pacer, hil, streamed, init_s)
