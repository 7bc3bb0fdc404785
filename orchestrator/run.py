"""One run of a system: load → graph → slaves → master with observers → results files.

Results (docs/interfaces.md, "Results"): results.csv (recorder), capture_*.csv (waveform
windows), metadata.json and summary.json. They are written whether the run ends, fails or is
interrupted; a failure is re-raised after the files are complete.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from threadpoolctl import threadpool_limits

from orchestrator.errors import UserError
from orchestrator.fmu import make_slave, new_workdir, remove_workdir
from orchestrator.graph import TICKS_PER_SECOND, SystemGraph, build_graph, seconds_to_ticks
from orchestrator.master import Master
from orchestrator.observers import CaptureRequest, ProgressBar, Recorder, WaveformCapture, scalar_outputs
from orchestrator.protocols import ALGORITHMS, Algorithm, Manipulator, Observer, SummaryObserver
from orchestrator.scenario import ScenarioManipulator, load_scenario
from orchestrator.ssp import SystemDescription, load_parameter_set, open_system


DEFAULT_OUTPUT_INTERVAL_S = 0.1
DEFAULT_SCENARIO = "scenario.json"           # a shipped system's own timed events


@dataclass
class RunOptions:
    stop_time: Optional[float] = None
    output_dir: Path = Path("results")
    overrides: Dict[str, str] = field(default_factory=dict)
    param_sets: Sequence[str] = ()
    output_interval: Optional[float] = None   # None: 0.1 s, rounded up to a multiple of the base step
    captures: Sequence[str] = ()
    algorithm: Algorithm = "gauss-seidel"
    in_process: bool = False
    fmu_dirs: Sequence[Path] = ()
    record: Optional[Sequence[str]] = None    # "comp.var"; None → all scalar outputs
    progress: bool = False
    blas_threads: int = 1                      # BLAS threads during the run (small matrices: 1 is fastest)
    manipulators: Sequence[Manipulator] = ()
    scenario: Optional[Path] = None           # timed events (orchestrator/scenario.py)
    default_scenario: bool = True             # use the system's scenario.json when no scenario is given
    #: observers that judge the run and contribute sections to summary.json, made from the
    #: graph once it is built (the railway verdicts: orchestrator.analysis.verdict.railway_verdicts)
    summaries: Optional[Callable[[SystemGraph], Sequence[SummaryObserver]]] = None


@dataclass
class RunResult:
    graph: SystemGraph
    summary: dict
    steps_taken: Dict[str, int]
    end_time_s: float
    output_dir: Path


def run_system(system_path, options: RunOptions) -> RunResult:
    """Load a system, run it and write its results. The result files are written whether the
    run ends, fails or is interrupted (Ctrl-C); a failure is raised after they are complete."""
    _check_options(options)
    system = open_system(Path(system_path), list(options.fmu_dirs))
    workdir = new_workdir()
    try:
        graph = _load_graph(system, options)
        scenario = _scenario(system, graph, options)
        stop_s = _stop_time(system, options, scenario)
        start_ticks = round(system.start_time * TICKS_PER_SECOND)
        stop_ticks = round(stop_s * TICKS_PER_SECOND)
        interval_ticks = _output_interval_ticks(graph, options)
        recorded = _recorded(graph, options.record)
        captures = _captures(graph, options.captures)
        out = Path(options.output_dir)
        out.mkdir(parents=True, exist_ok=True)
        # the judges first: making them checks the system's data (a UserError before any FMU is loaded)
        judges = list(options.summaries(graph)) if options.summaries is not None else []
        slaves = {name: make_slave(name, Path(node.fmu_path), node.interface, workdir, options.in_process)
                  for name, node in graph.nodes.items()}
        observers = _observers(out, recorded, interval_ticks, captures,
                               ProgressBar(stop_ticks, start_ticks) if options.progress else None, judges)
        manipulators = list(options.manipulators) + ([scenario] if scenario is not None else [])
        master = Master(graph, slaves, options.algorithm, observers, manipulators)
        outcome = _run(master, system.start_time, stop_s, stop_ticks, options.blas_threads)
        summary = _summary(graph, master.time_s - system.start_time, outcome, judges, scenario)
        _write_results(out, summary, _metadata(system, graph, options, stop_s, master, interval_ticks))
        _raise_failure(outcome)
        return RunResult(graph, summary, dict(master.steps_taken), master.time_s, out)
    finally:
        remove_workdir(workdir)
        system.close()


# ---- options and loading -------------------------------------------------------------------------
def _check_options(options: RunOptions) -> None:
    if options.algorithm not in ALGORITHMS:
        raise UserError(f"--algorithm {options.algorithm}: choose {' or '.join(ALGORITHMS)}")
    if options.output_interval is not None and options.output_interval <= 0:
        raise UserError(f"--output-interval {options.output_interval}: must be positive")


def _load_graph(system: SystemDescription, options: RunOptions) -> SystemGraph:
    """The system's graph with the parameter sets and --set overrides applied (relative data
    files resolved by the graph: graph.resolve_data_file)."""
    extra = [v for name in options.param_sets for v in load_parameter_set(system, name)]
    return build_graph(system, options.overrides, extra)


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
        stop = options.stop_time
    elif scenario is not None and scenario.scenario.end_s:
        stop = scenario.scenario.end_s
    else:
        stop = system.stop_time
    if stop is None:
        raise UserError(f"{system.ssd_path}: no stop time (give --stop-time or a DefaultExperiment stopTime)")
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


def _captures(graph: SystemGraph, texts: Sequence[str]) -> List[Tuple[CaptureRequest, List[str]]]:
    """Each --capture as a request and the frame elements it records, in sample order."""
    captures = []
    for text in texts:
        request = CaptureRequest.parse(text)
        if request.component not in graph.nodes:
            raise UserError(f"--capture {text}: no component {request.component!r}")
        captures.append((request, request.elements(graph.nodes[request.component].interface)))
    return captures


# ---- observers, the run, the results -------------------------------------------------------------
def _observers(out: Path, recorded: List[tuple], interval_ticks: int,
               captures: List[Tuple[CaptureRequest, List[str]]], progress: Optional[ProgressBar],
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
class _Outcome:
    wall_s: float                       # stepping time, initialisation included
    failure: Optional[BaseException]    # what stopped the run (Ctrl-C included), if anything
    problems: List[str]                 # what terminating and freeing the slaves met


def _run(master: Master, start_s: float, stop_s: float, stop_ticks: int, blas_threads: int) -> _Outcome:
    """Bind, initialise and step; whatever happens, close the observers and shut the slaves
    down, so the results so far can be written."""
    began = time.perf_counter()
    failure: Optional[BaseException] = None
    try:
        # the cores' matrices are small (≤ 60 states): a second BLAS thread only spins and
        # takes the other core from the process (measured 1.8× slower model generation)
        with threadpool_limits(limits=blas_threads, user_api="blas"):
            master.bind()
            master.initialize(start_s, stop_s)
            master.run_until(stop_ticks)
    except BaseException as error:  # includes Ctrl-C: results so far are still written
        failure = error
    finally:
        wall = time.perf_counter() - began
        for observer in master.observers:
            observer.close()
        problems = master.shutdown()
    return _Outcome(wall, failure, problems)


def _summary(graph: SystemGraph, sim_time: float, outcome: _Outcome, judges: Sequence[SummaryObserver],
             scenario: Optional[ScenarioManipulator]) -> dict:
    """summary.json: the run's own keys, then each judge's section, then the scenario's."""
    wall, failure = outcome.wall_s, outcome.failure
    summary = {
        "system": graph.name,
        "sim_time_s": sim_time,
        "wall_time_s": wall,
        "realtime_factor": sim_time / wall if wall > 0 else None,
        "completed": failure is None,
    }
    if failure is not None:
        summary["error"] = str(failure) or type(failure).__name__
    for judge in judges:
        summary.update(judge.summary_section())
    if scenario is not None:
        summary["scenario"] = {"file": str(scenario.scenario.path), "description": scenario.scenario.description,
                               "events_applied": scenario.applied}
    return summary


def _metadata(system, graph: SystemGraph, options: RunOptions, stop: float, master: Master,
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
                "steps_taken": master.steps_taken[name],
                "parameters": {k: v for k, v in node.parameters.items()},
                "seeds": {k: v for k, v in node.parameters.items() if "seed" in k.lower()},
            } for name, node in graph.nodes.items()
        },
    }


def _write_results(out: Path, summary: dict, metadata: dict) -> None:
    """summary.json and metadata.json (results.csv and the captures are streamed as the run goes)."""
    _write_json(out / "summary.json", summary)
    _write_json(out / "metadata.json", metadata)


def _raise_failure(outcome: _Outcome) -> None:
    """Once the results are written: what stopped the run, else what shutting down met."""
    if outcome.failure is not None:
        raise outcome.failure
    if outcome.problems:
        raise UserError("; ".join(outcome.problems))


def _write_json(path: Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=2, default=str) + "\n")
