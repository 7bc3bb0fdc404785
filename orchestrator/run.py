"""One run of a system: load → graph → slaves → master with observers → results files.

Results (docs/interfaces.md, "Results"): results.csv (recorder), capture_*.csv (waveform
windows), metadata.json and summary.json. They are written whether the run ends, fails or is
interrupted (SIGINT, SIGTERM, SIGHUP); a failure is re-raised after the files are complete.
The output folder is locked for the run and holds one run only (docs/reliability.md).
"""
from __future__ import annotations

import contextlib
import gc
import json
import math
import os
import stat
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from threadpoolctl import threadpool_limits

from orchestrator import interrupts
from orchestrator.errors import UserError, print_warning, shown_paths
from orchestrator.folders import FolderLock, refuse_link, replace_file
from orchestrator.fmu import extractions_kept, make_slave, new_workdir, remove_workdir
from orchestrator.graph import TICKS_PER_SECOND, SystemGraph, build_graph, seconds_to_ticks
from orchestrator.dcp.dcpx import SlaveDescription
from orchestrator.dcp.pdu import OpMode
from orchestrator.dcp.master import DcpTarget, component_interface, declared_targets, swapped_descriptions
from orchestrator.dcp.remote_slave import RemoteDcpSlave
from orchestrator.interrupts import InterruptFlag, Interrupted
from orchestrator.master import Master, shutdown_slaves
from orchestrator.observers import (CaptureRequest, ProgressBar, Recorder, WaveformCapture, cannot_write,
                                    scalar_outputs)
from orchestrator.pacing import Pacer, check_factor
from orchestrator.protocols import ALGORITHMS, AlgorithmName, Manipulator, Observer, Slave, SummaryObserver
from orchestrator.scenario import ScenarioManipulator, load_scenario
from orchestrator.ssp import SystemDescription, load_parameter_set, open_system


DEFAULT_OUTPUT_INTERVAL_S = 0.1
DEFAULT_SCENARIO = "scenario.json"           # a shipped system's own timed events
#: the longest time a run may name (--stop-time, --output-interval): 11.6 days of simulated
#: time; integer-nanosecond sample instants of the longest frames stay within 64 bits
MAX_TIME_S = 1e6


@dataclass
class RunOptions:
    stop_time: Optional[float] = None
    output_dir: Path = Path("results")
    overrides: Dict[str, str] = field(default_factory=dict)
    param_sets: Sequence[str] = ()
    output_interval: Optional[float] = None   # None: 0.1 s, rounded up to a multiple of the base step
    captures: Sequence[str] = ()
    algorithm: AlgorithmName = "gauss-seidel"
    in_process: bool = False
    fmu_dirs: Sequence[Path] = ()
    record: Optional[Sequence[str]] = None    # "comp.var"; None → all scalar outputs
    progress: bool = False
    blas_threads: int = 1                      # BLAS threads during the run (small matrices: 1 is fastest)
    manipulators: Sequence[Manipulator] = ()
    scenario: Optional[Path] = None           # timed events (orchestrator/scenario.py)
    default_scenario: bool = True             # use the system's scenario.json when no scenario is given
    #: observers that judge the run and contribute sections to summary.json, made from the
    #: graph once it is built (the railway verdicts: orchestrator.verdicts.verdict.railway_verdicts,
    #: bound to ``warn`` with functools.partial for its warnings to go there too)
    summaries: Optional[Callable[[SystemGraph], Sequence[SummaryObserver]]] = None
    #: one line per suspicious thing that still runs: a capture window or scenario event beyond
    #: the stop time, a rounded stop time, a paced run that could not keep pace (default: stderr)
    warn: Callable[[str], None] = field(default_factory=lambda: print_warning)
    #: pace the master to the wall clock: simulated seconds per wall-clock second (1: real
    #: time; orchestrator/pacing.py); None runs as fast as it can
    real_time: Optional[float] = None
    #: components driven as remote DCP slaves instead of their FMUs (orchestrator/dcp/master.py;
    #: the CLI's --swap NAME=dcp://HOST:PORT)
    swaps: Dict[str, "DcpTarget"] = field(default_factory=dict)


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
    (:class:`OutputFolder`). Once the folder is claimed the result files are written whether
    the run ends, fails or is interrupted; a failure is raised after they are complete
    (docs/reliability.md)."""
    with interrupts.deferred() as flag:
        return _run_system(system_path, options, flag if flag is not None else interrupts.NEVER)


def _run_system(system_path, options: RunOptions, flag: InterruptFlag) -> RunResult:
    check_options(options)
    out = OutputFolder(Path(options.output_dir))
    try:
        flag.check("before the run started")
        system = (system_path if isinstance(system_path, SystemDescription)
                  else open_system(Path(system_path), list(options.fmu_dirs)))
    except Interrupted as stop:
        _interrupted_before_start(out, system_path.name if isinstance(system_path, SystemDescription)
                                  else Path(system_path).stem, stop)
    except OSError as error:            # a .ssp extracted into a full temp folder
        raise os_error(error) from None
    close_system = (lambda: None) if system is system_path else system.close
    try:
        flag.check("before the run started")
        plan = plan_run(system, options)
        warn_beyond_stop(options, plan.scenario, plan.captures, plan.stop_s)
        warn_rounded_stop(options, plan)
        flag.check("before the run started")
    except Interrupted as stop:
        close_system()
        _interrupted_before_start(out, system.name, stop)
    except BaseException:
        close_system()
        raise
    graph, scenario, stop_s, judges = plan.graph, plan.scenario, plan.stop_s, plan.judges
    start_ticks = plan.start_ticks
    stop_ticks = _stop_ticks(plan)
    interval_ticks, recorded, captures = plan.interval_ticks, plan.recorded, plan.captures
    workdir: Optional[Path] = None
    try:
        out.claim()                       # from here on the folder holds this run's files
        # the FMUs' extractions: in a folder of the run's, unless the process keeps them
        workdir = None if extractions_kept() else new_workdir()
        setup = _Setup(graph, options, workdir, out.path, recorded, interval_ticks, captures,
                       ProgressBar(stop_ticks, start_ticks) if options.progress else None, scenario, flag,
                       judges, plan.hil, plan.targets)
        outcome = _run(setup, system.start_time, stop_s, stop_ticks, options.blas_threads)
        master = outcome.master
        end_s = master.time_s if master is not None and master.time_ticks >= start_ticks else system.start_time
        sim_time = end_s - system.start_time
        summary = _summary(graph, sim_time, outcome, scenario)
        metadata = _metadata(system, graph, options, stop_s, outcome.steps_taken, interval_ticks)
        # the folder (or a file streamed into it) removed or replaced meanwhile: never "results
        # in", and no summary written into a folder that is no longer the one locked (another
        # run's, perhaps); checked again after the writes
        streamed = outcome.streamed if outcome.failure is None else ()
        lost = out.lost(streamed)
        problems = _write_results(out.path, summary, metadata) if lost is None else []
        if flag.signum and outcome.failure is None:
            # the signal came while the files were closed or written: the run says so
            outcome.failure = Interrupted(flag.signum, "while the results were written")
            summary = _summary(graph, sim_time, outcome, scenario)
            if lost is None:
                problems = _write_results(out.path, summary, None) + problems
        if outcome.pacer is not None and outcome.pacer.verdict_line():
            options.warn(outcome.pacer.verdict_line())
        lost = lost or out.lost(streamed)
        if lost is not None:
            problems = [lost]          # what could not be written there follows from it
        _raise_failure(outcome, problems, out.path)
        return RunResult(graph, summary, dict(outcome.steps_taken), end_s, out.path)
    finally:
        if workdir is not None:
            remove_workdir(workdir)
        close_system()
        out.release()


# ---- options and loading -------------------------------------------------------------------------
#: a --capture and the frame elements it records, one list per row, each in sample order
Capture = Tuple[CaptureRequest, List[List[str]]]


@dataclass
class RunPlan:
    """What a run is made from, decided before any component exists (each part a UserError
    when the system, its data or the options are wrong)."""

    graph: SystemGraph
    start_ticks: int = 0
    scenario: Optional[ScenarioManipulator] = None
    stop_s: Optional[float] = None
    interval_ticks: Optional[int] = None
    recorded: List[tuple] = field(default_factory=list)
    captures: List[Capture] = field(default_factory=list)
    judges: Sequence[SummaryObserver] = ()
    hil: Dict[str, SlaveDescription] = field(default_factory=dict)   # swapped components' .dcpx
    targets: Dict[str, DcpTarget] = field(default_factory=dict)      # … and their addresses


def plan_run(system: SystemDescription, options: RunOptions,
          attempt: Callable[[Callable[[], object]], object] = lambda step: step()) -> RunPlan:
    """The graph (needed by everything after it), then each further part through ``attempt``:
    a run lets the first problem raise (the default); validation (orchestrator/validation.py)
    notes each one and goes on with what it can still check."""
    graph = _load_graph(system, options)
    plan = RunPlan(graph, start_ticks=round(system.start_time * TICKS_PER_SECOND))
    attempt(lambda: _refuse_connected_overrides(graph, options.overrides))
    plan.scenario = attempt(lambda: _scenario(system, graph, options))
    plan.stop_s = attempt(lambda: _stop_time(system, options, plan.scenario))
    plan.interval_ticks = attempt(lambda: _output_interval_ticks(graph, options))
    plan.recorded = attempt(lambda: _recorded(graph, options.record)) or []
    plan.captures = attempt(lambda: _captures(graph, options.captures)) or []
    plan.targets = {**(attempt(lambda: declared_targets(system)) or {}), **options.swaps}
    plan.hil = attempt(lambda: swapped_descriptions(plan.targets, graph)) or {}
    # the judges before the folder and the FMUs: making them checks the system's data files
    # (orchestrator/verdicts/system_checks.py), a UserError that leaves the folder untouched
    if options.summaries is not None:
        plan.judges = attempt(lambda: list(options.summaries(graph))) or []
    return plan


def check_options(options: RunOptions) -> None:
    if options.algorithm not in ALGORITHMS:
        raise UserError(f"--algorithm {options.algorithm}: choose {' or '.join(ALGORITHMS)}")
    for label, value in (("--stop-time", options.stop_time), ("--output-interval", options.output_interval)):
        if value is not None and not (math.isfinite(value) and abs(value) <= MAX_TIME_S):
            raise UserError(f"{label} {value!r}: must be a finite number of seconds up to {MAX_TIME_S:g}")
    if options.real_time is not None:
        check_factor(options.real_time)
    if options.output_interval is not None and options.output_interval <= 0:
        raise UserError(f"--output-interval {options.output_interval}: must be positive")


def _load_graph(system: SystemDescription, options: RunOptions) -> SystemGraph:
    """The system's graph with the parameter sets and --set overrides applied (relative data
    files resolved by the graph: graph.resolve_data_file)."""
    extra = [v for name in options.param_sets for v in load_parameter_set(system, name)]
    return build_graph(system, options.overrides, extra, interface_of=component_interface)


def _refuse_connected_overrides(graph: SystemGraph, overrides: Dict[str, str]) -> None:
    """A --set on an input a connection feeds would be overwritten at the first exchange."""
    fed = {(edge.target, edge.target_var.name): edge for edge in graph.edges}
    for key in overrides:
        edge = fed.get(tuple(key.split(".", 1)))
        if edge is not None:
            raise UserError(f"--set {key}: this input is fed by the connection from "
                            f"{edge.source}.{edge.source_var.name}, which overrides any value set; "
                            f"set a parameter, or use a scenario event (docs/scenarios.md)")


def _scenario(system: SystemDescription, graph: SystemGraph,
              options: RunOptions) -> Optional[ScenarioManipulator]:
    """The timed events: the scenario given, else the system's own scenario.json, if any."""
    scenario_file = options.scenario
    if scenario_file is None and options.default_scenario and (system.folder / DEFAULT_SCENARIO).is_file():
        scenario_file = system.folder / DEFAULT_SCENARIO
    if scenario_file is None:
        return None
    return ScenarioManipulator(load_scenario(scenario_file), graph)


def _stop_time(system: SystemDescription, options: RunOptions,
               scenario: Optional[ScenarioManipulator]) -> float:
    """--stop-time, else the scenario's end, else the SSD's DefaultExperiment stopTime."""
    if options.stop_time is not None:
        stop, origin = options.stop_time, "--stop-time"
    elif scenario is not None and scenario.scenario.end_s:
        stop, origin = scenario.scenario.end_s, f"{scenario.scenario.path}: field end"
    else:
        stop, origin = system.stop_time, f"{system.ssd_path}: DefaultExperiment stopTime"
    if stop is None:
        raise UserError(f"{system.ssd_path}: no stop time (give --stop-time or a DefaultExperiment stopTime)")
    if not (math.isfinite(stop) and abs(stop) <= MAX_TIME_S):
        raise UserError(f"{origin} {stop!r}: must be a finite number of seconds up to {MAX_TIME_S:g}")
    if stop <= system.start_time:
        raise UserError(f"--stop-time {stop}: must be after the start time {system.start_time}")
    return stop


def _output_interval_ticks(graph: SystemGraph, options: RunOptions) -> int:
    """--output-interval, by default 0.1 s rounded up to a multiple of the base step."""
    if options.output_interval is None:
        wanted = seconds_to_ticks(DEFAULT_OUTPUT_INTERVAL_S, "output interval")
        interval_ticks = -(-wanted // graph.base_ticks) * graph.base_ticks
    else:
        interval_ticks = seconds_to_ticks(options.output_interval, "--output-interval")
    if interval_ticks % graph.base_ticks:
        raise UserError(f"--output-interval {options.output_interval}: not a multiple of the "
                        f"base step {graph.base_ticks / TICKS_PER_SECOND:g} s")
    return interval_ticks


def _recorded(graph: SystemGraph, record) -> List[tuple]:
    """(component, output) pairs results.csv records: --record, by default every scalar output."""
    if record is None:
        return [(name, var) for name in graph.order
                for var in scalar_outputs(graph.nodes[name].interface)]
    chosen = []
    for item in record:
        comp, _, var = item.partition(".")
        node = graph.nodes.get(comp)
        if node is None or var not in node.interface.variables:
            raise UserError(f"--record {item}: no such variable")
        if node.interface.variables[var].causality != "output":
            raise UserError(f"--record {item}: only outputs can be recorded")
        chosen.append((comp, var))
    return chosen


def _captures(graph: SystemGraph, texts: Sequence[str]) -> List[Capture]:
    """Each --capture as a request and the frame elements it records, in sample order."""
    captures = []
    for text in texts:
        request = CaptureRequest.parse(text)
        if request.component not in graph.nodes:
            raise UserError(f"--capture {text}: no component {request.component!r}")
        captures.append((request, request.elements(graph.nodes[request.component].interface)))
    return captures


def warn_beyond_stop(options: RunOptions, scenario: Optional[ScenarioManipulator],
                      captures: List[Capture], stop_s: float) -> None:
    """One warning line on stderr per capture window and per scenario event the run never
    reaches (they are kept out of the results, not refused: the same file serves shorter runs)."""
    for request, _ in captures:
        if request.t0 >= stop_s:
            options.warn(f"--capture {request.component}.{request.port}@{request.t0:g}:{request.t1:g}: "
                         f"the window starts at or after the stop time {stop_s:g} s; its file stays empty")
    if scenario is not None:
        for event in scenario.scenario.events:
            if event.time_s >= stop_s:
                options.warn(f"{scenario.scenario.path}: event at t = {event.time_s:g} s on "
                             f"{event.component}.{event.variable} is at or after the stop time "
                             f"{stop_s:g} s; not applied")


def _stop_ticks(plan: RunPlan) -> int:
    """The stop time on the master's clock: whole nanoseconds, at least one after the start (a
    stop time after the start by less than half a nanosecond, 1e-12 s, is not the start)."""
    return max(round(plan.stop_s * TICKS_PER_SECOND), plan.start_ticks + 1)


def warn_rounded_stop(options: RunOptions, plan: RunPlan) -> None:
    """The master steps in whole base steps: a stop time between two of them ends the run at
    the next one, said in one warning line (also a stop time too close to the start to be a
    whole nanosecond after it)."""
    base = plan.graph.base_ticks
    start_ticks = plan.start_ticks
    span = _stop_ticks(plan) - start_ticks
    if span % base:
        end_s = (start_ticks + -(-span // base) * base) / TICKS_PER_SECOND
        options.warn(f"stop time {plan.stop_s:g} s is not a whole number of base steps "
                     f"({base / TICKS_PER_SECOND:g} s) after the start; the run ends at {end_s:g} s")


# ---- the output folder ---------------------------------------------------------------------------
#: what a run (and `railcosim report` into the run folder) writes; a run removes these before it
#: starts, so the folder never mixes two runs. Nothing else in the folder is touched.
RUN_FILES = ("results.csv", "summary.json", "metadata.json")
RUN_PATTERNS = ("capture_*.csv",)
REPORT_FILES = ("speed_distance.png", "time_distance.png", "coil_emf.png", "energy.png", "report.html")


class OutputFolder:
    """A run's results folder: locked while the run uses it (:class:`FolderLock`, so a second
    run into it fails at once) and cleared of an earlier run's files before this run writes
    (docs/reliability.md, "One run per folder"). The run writes in place, so ``tail -f
    results.csv`` follows it live; no file is written through a symbolic link (orchestrator/
    folders.py)."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self._lock = FolderLock(self.path, f"--output {self.path}", "another run")

    def claim(self) -> None:
        if self._lock.held:
            return
        self._lock.acquire()
        try:
            self._clear()
        except UserError:
            self.release()
            raise
        except OSError as error:
            self.release()
            raise UserError(f"--output {self.path}: cannot remove an earlier run's "
                            f"{Path(error.filename or '?').name} ({error.strerror or error})") from None

    def _clear(self) -> None:
        """Remove the files an earlier run (or its report) wrote: regular files only (a named
        pipe at results.csv was put there on purpose and is written through); a symbolic link at
        one of these names is refused, before anything is removed."""
        names = list(RUN_FILES) + list(REPORT_FILES)
        for pattern in RUN_PATTERNS:
            names.extend(p.name for p in self.path.glob(pattern))
        for name in names:
            refuse_link(self.path / name)
        for name in names:
            path = self.path / name
            if path.is_file():
                path.unlink()

    def lost(self, streamed: Sequence[Path] = ()) -> Optional[str]:
        """None while the folder claimed is still there (:meth:`FolderLock.lost`) and each of
        the ``streamed`` files (results.csv, the captures) is still a file at its name; else the
        one line saying what is gone (a file written to after its name went is lost with it)."""
        lost = self._lock.lost()
        if lost is not None:
            return lost
        for path in streamed:
            try:
                mode = os.lstat(path).st_mode
            except OSError:
                mode = 0
            if stat.S_ISREG(mode) or stat.S_ISFIFO(mode) or stat.S_ISCHR(mode):   # not a link put there
                continue
            return f"{path}: removed or replaced while the run wrote it; what it held is lost"
        return None

    def release(self) -> None:
        """Unlock (the lock file stays: removing it could let two runs lock different files)."""
        self._lock.release()


def _interrupted_before_start(out: OutputFolder, system_name: str, stop: Interrupted) -> None:
    """A signal before the components were made: the folder gets this run's summary (nothing
    simulated), then :class:`Interrupted` is raised."""
    try:
        out.claim()
    except UserError as error:          # the folder is another run's (or cannot be made): leave it
        raise Interrupted(stop.signum, f"{stop.where}; nothing written ({error})") from None
    try:
        summary = {"system": system_name, "sim_time_s": 0.0, "wall_time_s": 0.0, "realtime_factor": None,
                   "completed": False, "interrupted": stop.signal_name, "error": str(stop)}
        problems = _write_results(out.path, summary, None)
    finally:
        out.release()
    _raise_failure(_Outcome(0.0, stop, [], None, {}), problems, out.path)


# ---- observers, the run, the results -------------------------------------------------------------
def _observers(out: Path, recorded: List[tuple], interval_ticks: int,
               captures: List[Capture], progress: Optional[ProgressBar],
               judges: Sequence[SummaryObserver]) -> List[Observer]:
    """results.csv, one capture file per --capture, the progress bar and the judges, in the
    order they are called after each tick."""
    observers: List[Observer] = [Recorder(out / "results.csv", recorded, interval_ticks)]
    for request, elements in captures:
        safe_port = request.port.replace("[", "_").replace("]", "").replace(",", "_")
        observers.append(WaveformCapture(out / f"capture_{request.component}_{safe_port}.csv",
                                         request, elements))
    if progress is not None:
        observers.append(progress)
    observers.extend(judges)
    return observers


@dataclass
class _Setup:
    """What :func:`_run` makes the components, observers and master from."""

    graph: SystemGraph
    options: RunOptions
    workdir: Optional[Path]             # None: the process keeps the extractions (a study's worker)
    out: Path
    recorded: List[tuple]
    interval_ticks: int
    captures: List[Capture]
    progress: Optional[ProgressBar]
    scenario: Optional[ScenarioManipulator]
    flag: InterruptFlag
    judges: Sequence[SummaryObserver]
    hil: Dict[str, SlaveDescription] = field(default_factory=dict)
    targets: Dict[str, DcpTarget] = field(default_factory=dict)


@dataclass
class _Outcome:
    wall_s: float                       # stepping time, initialisation included
    failure: Optional[BaseException]    # what stopped the run (an interruption included), if anything
    problems: List[str]                 # what closing the files and shutting the slaves down met
    master: Optional[Master]
    steps_taken: Dict[str, int]
    judges: Sequence[SummaryObserver] = ()
    pacer: Optional[Pacer] = None
    hil: Dict[str, RemoteDcpSlave] = field(default_factory=dict)
    streamed: List[Path] = field(default_factory=list)   # results.csv and the captures


def start_master(graph: SystemGraph, options: RunOptions, slaves: Dict[str, Slave],
           make: Callable[[str, object], Slave], observers: List[Observer],
           scenario: Optional[ScenarioManipulator], flag: InterruptFlag, start_s: float,
           stop_s: Optional[float], ready: Callable[[], bool] = lambda: True,
           pacer: Optional[Pacer] = None) -> Optional[Master]:
    """Make every component (into ``slaves``, so that whatever was made is shut down), then the
    master; bind and initialise. ``ready`` false after the components are made: no master
    (validate: a component that cannot be instantiated). A ``pacer`` comes first among the
    manipulators: each tick's work starts once its wall-clock deadline has come."""
    for name, node in graph.nodes.items():
        flag.check("during initialisation")
        slaves[name] = make(name, node)
    if not ready():
        return None
    manipulators = ([pacer] if pacer is not None else []) + list(options.manipulators) \
        + ([scenario] if scenario is not None else [])
    master = Master(graph, slaves, options.algorithm, observers, manipulators, interrupt=flag)
    master.bind()
    master.initialize(start_s, stop_s)
    return master


#: the BLAS libraries' own variables for their number of threads, read when a library loads
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS")


@contextlib.contextmanager
def blas_threads_limited(threads: int):
    """At most ``threads`` BLAS threads for the run: threadpoolctl limits the libraries loaded
    already, and the libraries' own environment variables, set for the run's duration, hold
    for those loaded during it. An FMU's module loads scipy.linalg (and with it scipy's own
    OpenBLAS) when the component is made, after the limit was entered: threadpoolctl does not
    see it, and two threads summing in another order change results in their last digit."""
    saved = {name: os.environ.get(name) for name in BLAS_THREAD_VARIABLES}
    os.environ.update({name: str(threads) for name in BLAS_THREAD_VARIABLES})
    try:
        with threadpool_limits(limits=threads, user_api="blas"):
            yield
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value


#: freeze and turn off Python's garbage collector while the master steps (a module constant so
#: that benchmarks/bench_deadline.py can compare without)
FREEZE_GC_WHILE_STEPPING = True
#: set by a process that froze what it holds for good and then makes run after run (a study's
#: run process, orchestrator/study/worker.py): its runs turn the collector off while stepping
#: and freeze nothing — what a run froze would stay frozen after it, its cyclic garbage never
#: collected — nor count what is frozen (gc.get_freeze_count walks every frozen object:
#: 5–20 ms in a study's worker)
HOST_KEEPS_FROZEN = False


@contextlib.contextmanager
def collector_off_while_stepping():
    """Python's cyclic garbage collector frozen and off for the stepping, as it was after.

    A collection stops the step it falls in: up to a millisecond for the oldest generation
    over everything initialisation made (measured at one sample per frame,
    docs/performance.md#one-sample-per-frame-as-a-deadline), four deadlines of a 4 kHz sample.
    Frozen, what exists before the first step is left out of every collection; off, none runs
    while stepping. Stepping makes no cyclic garbage (tests/test_run_gc.py), so nothing
    accumulates meanwhile; reference counting frees everything else as before. In a process
    that keeps its own objects frozen (HOST_KEEPS_FROZEN) the collector is only turned off."""
    if not FREEZE_GC_WHILE_STEPPING:
        yield
        return
    was_enabled = gc.isenabled()
    freeze = not HOST_KEEPS_FROZEN and gc.get_freeze_count() == 0
    if freeze:
        gc.freeze()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()
        if freeze:                  # what a caller froze stays frozen
            gc.unfreeze()


def _run(setup: _Setup, start_s: float, stop_s: float, stop_ticks: int, blas_threads: int) -> _Outcome:
    """Make the slaves, bind, initialise and step; whatever happens (a failure, a signal, a
    write error), close every observer and shut every slave made down, so the results so far
    can be written."""
    began = time.perf_counter()
    failure: Optional[BaseException] = None
    graph, options, flag = setup.graph, setup.options, setup.flag
    slaves: Dict[str, Slave] = {}
    observers: List[Observer] = []
    judges = setup.judges
    master: Optional[Master] = None
    # a slave that runs on its own clock (soft real time) needs the master at real time
    factor = options.real_time
    if factor is None and any(OpMode.NRT not in d.op_modes for d in setup.hil.values()):
        factor = 1.0
    pacer = Pacer(factor, flag) if factor is not None else None
    swapped: Dict[str, RemoteDcpSlave] = {}

    def make(name: str, node) -> Slave:
        if name in setup.hil:
            swapped[name] = RemoteDcpSlave(name, node.interface, setup.targets[name], setup.hil[name], node.step_ticks)
            return swapped[name]
        return make_slave(name, Path(node.fmu_path), node.interface, setup.workdir, options.in_process)

    try:
        # the cores' matrices are small (≤ 60 states): a second BLAS thread only spins and
        # takes the other core from the process (measured 1.8× slower model generation)
        with blas_threads_limited(blas_threads):
            observers = _observers(setup.out, setup.recorded, setup.interval_ticks, setup.captures,
                                   setup.progress, judges)
            master = start_master(graph, options, slaves, make, observers, setup.scenario, flag, start_s, stop_s,
                            pacer=pacer)
            with collector_off_while_stepping():
                master.run_until(stop_ticks)
    except BaseException as error:  # a failure or an interruption: results so far are still written
        failure = error
    wall = time.perf_counter() - began
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
    return _Outcome(wall, failure, problems, master, steps, judges, pacer, swapped, streamed)


def _summary(graph: SystemGraph, sim_time: float, outcome: _Outcome,
             scenario: Optional[ScenarioManipulator]) -> dict:
    """summary.json: the run's own keys, then each judge's section, then the scenario's."""
    wall, failure = outcome.wall_s, outcome.failure
    summary = {
        "system": graph.name,
        "sim_time_s": sim_time,
        "wall_time_s": wall,
        "realtime_factor": sim_time / wall if wall > 0 else None,
        "completed": failure is None,
        "interrupted": failure.signal_name if isinstance(failure, Interrupted) else None,
    }
    if failure is not None:
        summary["error"] = str(failure) or type(failure).__name__
    for judge in outcome.judges:
        summary.update(judge.summary_section())
    if outcome.pacer is not None:
        summary.update(outcome.pacer.summary_section())
    if outcome.hil:
        summary["hil"] = {name: slave.summary_section() for name, slave in outcome.hil.items()}
    if scenario is not None:
        summary["scenario"] = {"file": str(scenario.scenario.path), "description": scenario.scenario.description,
                               "events_applied": scenario.applied}
    return summary


def _metadata(system, graph: SystemGraph, options: RunOptions, stop: float, steps_taken: Dict[str, int],
              interval_ticks: int) -> dict:
    return {
        "system": graph.name,
        "ssd": str(system.ssd_path),
        "algorithm": options.algorithm,
        "in_process": options.in_process,
        "start_time_s": system.start_time,
        "stop_time_s": stop,
        "base_step_s": graph.base_ticks / TICKS_PER_SECOND,
        "output_interval_s": interval_ticks / TICKS_PER_SECOND,
        "execution_order": graph.order,
        "cycles_broken": graph.cycles,
        "components": {
            name: {
                "fmu": node.fmu_path,
                "model_identifier": node.interface.model_identifier,
                "guid": node.interface.guid,
                "generation_tool": node.interface.generation_tool,
                "version": node.interface.version,
                "step_size_s": node.step_ticks / TICKS_PER_SECOND,
                "steps_taken": steps_taken[name],
                "parameters": {k: v for k, v in node.parameters.items()},
                "seeds": {k: v for k, v in node.parameters.items() if "seed" in k.lower()},
            } for name, node in graph.nodes.items()
        },
    }


def _write_results(out: Path, summary: dict, metadata: Optional[dict]) -> List[str]:
    """summary.json and metadata.json (results.csv and the captures are streamed as the run
    goes), each whole or not at all; returns what could not be written."""
    problems = []
    for name, data in (("summary.json", summary), ("metadata.json", metadata)):
        if data is None:
            continue
        try:
            _write_json(out / name, data)
        except OSError as error:
            problems.append(str(cannot_write(out / name, error)))
        except UserError as error:      # a link planted at its temporary file's name
            problems.append(str(error))
    return problems


def _raise_failure(outcome: _Outcome, problems: List[str], out: Path) -> None:
    """Once the results are written: what stopped the run, else what closing, shutting down or
    writing met — with the files that could not be written."""
    failure = outcome.failure
    also = "; ".join(outcome.problems + problems)
    if isinstance(failure, Interrupted):
        raise Interrupted(failure.signum, f"{failure.where}; results so far in {out}"
                          + (f"; {also}" if also else ""))
    if isinstance(failure, OSError):    # e.g. the temp folder full while an FMU is extracted
        failure = os_error(failure)
    if failure is not None:
        if also and isinstance(failure, UserError):
            raise type(failure)(f"{failure}; {also}")
        raise failure
    if also:
        raise UserError(also)


def os_error(error: OSError) -> UserError:
    return UserError(f"{error.filename or 'a file'}: {error.strerror or error}")


def _write_json(path: Path, data: dict) -> None:
    """Written beside, then renamed (orchestrator/folders.py, replace_file). Paths inside an
    unpacked .ssp are written ``<archive>!<member>`` (the extraction folder is gone once the
    run ends)."""
    replace_file(path, shown_paths(json.dumps(data, indent=2, default=str)) + "\n")
