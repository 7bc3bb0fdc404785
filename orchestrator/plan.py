"""A run's plan: what it is asked for (:class:`RunOptions`, checked when made) and what it is
made from (:class:`RunPlan`, decided by :func:`plan_run` before any component exists). The plan
is passed on whole: to the run that makes and steps the components (orchestrator/run.py), to
what writes its results (orchestrator/results.py), and to validation, which plans as a run
does and notes every problem (orchestrator/validation.py).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, List, Mapping, Optional, Sequence, Tuple

from orchestrator.components import Components, interface_of, plan_components
from orchestrator.dcp.master import DcpTarget
from orchestrator.errors import UserError, did_you_mean, print_warning
from orchestrator.graph import (MAX_TIME_S, TICKS_PER_SECOND, SystemGraph, build_graph, closest_variable,
                                 seconds_to_ticks)
from orchestrator.observers import DEFAULT_PROGRESS_INTERVAL_S, PROGRESS_MODES, CaptureRequest, scalar_outputs
from orchestrator.pacing import check_factor
from orchestrator.ports import base_of
from orchestrator.process_policy import ProcessPolicy
from orchestrator.protocols import ALGORITHMS, AlgorithmName, Manipulator, SummaryObserver
from orchestrator.scenario import ScenarioManipulator, load_scenario
from orchestrator.ssp import SystemDescription, load_parameter_set

DEFAULT_OUTPUT_INTERVAL_S = 0.1
DEFAULT_SCENARIO = "scenario.json"           # a shipped system's own timed events


@dataclass(frozen=True)
class RunOptions:
    """What a run is asked for, checked when made: a value no run could use is one UserError
    naming its option (``--stop-time nan``), before anything is loaded. What depends on the
    system (a --record's variable, a capture's component, a stop time between base steps) is
    checked by the plan (:func:`plan_run`)."""

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
    #: the run's progress on stderr (orchestrator/observers.py Progress): "bar" (a terminal),
    #: "lines" (a log: one every ``progress_interval`` seconds of wall time) or "none" (True:
    #: "bar", False: "none")
    progress: str = "none"
    progress_interval: float = DEFAULT_PROGRESS_INTERVAL_S
    manipulators: Sequence[Manipulator] = ()
    scenario: Optional[Path] = None           # timed events (orchestrator/scenario.py)
    default_scenario: bool = True             # use the system's scenario.json when no scenario is given
    #: observers that judge the run and contribute sections to summary.json, made from the
    #: graph once it is built (the railway verdicts: orchestrator.verdicts.verdict.railway_verdicts,
    #: bound to ``warn`` with functools.partial for its warnings to go there too)
    summaries: Optional[Callable[[SystemGraph], Sequence[SummaryObserver]]] = None
    #: the labels of the enumerations among the graph's ports, (component, port) → value →
    #: label, for columns.json (the railway's: orchestrator.verdicts.labels.railway_labels);
    #: None: a Boolean's false/true only
    labels: Optional[Callable[[SystemGraph], Mapping[Tuple[str, str], Mapping[int, str]]]] = None
    #: one line per suspicious thing that still runs: a capture window or scenario event beyond
    #: the stop time, a rounded stop time, a paced run that could not keep pace (default: stderr)
    warn: Callable[[str], None] = print_warning
    #: pace the master to the wall clock: simulated seconds per wall-clock second (1: real
    #: time; orchestrator/pacing.py); None runs as fast as it can
    real_time: Optional[float] = None
    #: components driven as remote DCP slaves instead of their FMUs (orchestrator/components.py;
    #: the CLI's --swap NAME=dcp://HOST:PORT)
    swaps: Dict[str, DcpTarget] = field(default_factory=dict)
    #: the process's BLAS threads and garbage collector while the run steps
    process: ProcessPolicy = ProcessPolicy()

    def __post_init__(self):
        if self.algorithm not in ALGORITHMS:
            raise UserError(f"--algorithm {self.algorithm}: choose {' or '.join(ALGORITHMS)}")
        for label, value in (("--stop-time", self.stop_time), ("--output-interval", self.output_interval)):
            if value is not None:
                _check_time(label, value)
        if self.real_time is not None:
            check_factor(self.real_time)
        if isinstance(self.progress, bool):
            object.__setattr__(self, "progress", "bar" if self.progress else "none")
        if self.progress not in PROGRESS_MODES:
            raise UserError(f"--progress {self.progress}: choose {', '.join(PROGRESS_MODES)}")
        if not (math.isfinite(self.progress_interval) and self.progress_interval > 0):
            raise UserError(f"--progress-interval {self.progress_interval!r}: must be a positive number of seconds")
        if self.output_interval is not None and self.output_interval <= 0:
            raise UserError(f"--output-interval {self.output_interval}: must be positive")
        for name in ("param_sets", "captures", "record", "fmu_dirs"):
            value = getattr(self, name)
            if isinstance(value, (str, Path)):
                raise UserError(f"RunOptions.{name} {str(value)!r}: a list of them, not a single one")
        object.__setattr__(self, "output_dir", Path(self.output_dir))


def _check_time(origin: str, seconds: float) -> None:
    if not (math.isfinite(seconds) and abs(seconds) <= MAX_TIME_S):
        raise UserError(f"{origin} {seconds!r}: must be a finite number of seconds up to {MAX_TIME_S:g}")


#: a --capture and the frame elements it records, one list per row, each in sample order
Capture = Tuple[CaptureRequest, List[List[str]]]


@dataclass
class RunPlan:
    """What a run is made from, decided before any component exists (each part a UserError
    when the system, its data or the options are wrong), and passed on whole: to what makes
    and steps the components (orchestrator/run.py) and to what writes the results."""

    system: SystemDescription
    options: RunOptions
    graph: SystemGraph
    components: Components = Components()
    scenario: Optional[ScenarioManipulator] = None
    stop_s: Optional[float] = None
    interval_ticks: Optional[int] = None
    recorded: List[tuple] = field(default_factory=list)
    captures: List[Capture] = field(default_factory=list)
    judges: Sequence[SummaryObserver] = ()

    @property
    def start_ticks(self) -> int:
        return round(self.system.start_time * TICKS_PER_SECOND)

    @property
    def stop_ticks(self) -> int:
        """The stop time on the master's clock: whole nanoseconds, at least one after the start
        (a stop time after the start by less than half a nanosecond, 1e-12 s, is not the start)."""
        return max(round(self.stop_s * TICKS_PER_SECOND), self.start_ticks + 1)

    def warn_before_start(self) -> None:
        """One warning line (``options.warn``) per capture window and per scenario event the
        run never reaches (kept out of the results, not refused: the same file serves shorter
        runs), and for a stop time between two base steps: the master steps in whole base steps,
        so the run ends at the next one (also a stop time too close to the start to be a whole
        nanosecond after it). Nothing without a stop time."""
        stop_s, warn = self.stop_s, self.options.warn
        if stop_s is None:
            return
        for request, _ in self.captures:
            if request.t0 >= stop_s:
                warn(f"--capture {request.component}.{request.port}@{request.t0:g}:{request.t1:g}: "
                     f"the window starts at or after the stop time {stop_s:g} s; its file stays empty")
        if self.scenario is not None:
            for event in self.scenario.scenario.events:
                if event.time_s >= stop_s:
                    warn(f"{self.scenario.scenario.path}: event at t = {event.time_s:g} s on "
                         f"{event.component}.{event.variable} is at or after the stop time {stop_s:g} s; not applied")
        base = self.graph.base_ticks
        span = self.stop_ticks - self.start_ticks
        if span % base:
            end_s = (self.start_ticks + -(-span // base) * base) / TICKS_PER_SECOND
            warn(f"stop time {stop_s:g} s is not a whole number of base steps "
                 f"({base / TICKS_PER_SECOND:g} s) after the start; the run ends at {end_s:g} s")


def plan_run(system: SystemDescription, options: RunOptions,
             attempt: Callable[[Callable[[], object]], object] = lambda step: step()) -> RunPlan:
    """The graph (needed by everything after it), then each further part through ``attempt``:
    a run lets the first problem raise (the default); validation (orchestrator/validation.py)
    notes each one and goes on with what it can still check."""
    extra = [v for name in options.param_sets for v in load_parameter_set(system, name)]
    # relative data files resolved by the graph: graph.resolve_data_file
    graph = build_graph(system, options.overrides, extra, interface_of=interface_of)
    plan = RunPlan(system, options, graph)
    attempt(lambda: _refuse_connected_overrides(graph, options.overrides))
    plan.scenario = attempt(lambda: _scenario(system, graph, options))
    plan.stop_s = attempt(lambda: _stop_time(system, options, plan.scenario))
    plan.interval_ticks = attempt(lambda: _output_interval_ticks(graph, options))
    plan.recorded = attempt(lambda: _recorded(graph, options.record)) or []
    plan.captures = attempt(lambda: _captures(graph, options.captures)) or []
    plan.components = plan_components(system, graph, options.swaps, options.in_process, attempt)
    # the judges before the folder and the FMUs: making them checks the system's data files
    # (orchestrator/verdicts/system_checks.py), a UserError that leaves the folder untouched
    if options.summaries is not None:
        plan.judges = attempt(lambda: list(options.summaries(graph))) or []
    return plan


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
    _check_time(origin, stop)
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
            raise UserError(f"--record {item}: no such variable"
                            + closest_variable(graph.nodes, item, lambda v: v.causality == "output"))
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
            raise UserError(f"--capture {text}: no component {request.component!r}"
                            + did_you_mean(request.component, graph.nodes))
        interface = graph.nodes[request.component].interface
        try:
            elements = request.elements(interface)
        except UserError as error:
            frames = [f"{request.component}.{port}" for port in sorted(interface.frame_ports)
                      if any(base_of(n) == port and v.causality == "output" for n, v in interface.variables.items())]
            given = f"{request.component}.{request.port}"
            if f"{request.component}.{base_of(request.port)}" in frames:
                raise
            raise UserError(f"{error}{did_you_mean(given, frames)}") from None
        captures.append((request, elements))
    return captures
