"""One run of a system: load → graph → slaves → master with observers → results files.

Results (DESIGN §8): results.csv (recorder), capture_*.csv (waveform windows),
metadata.json and summary.json. They are written whether the run ends, fails or is
interrupted; a failure is re-raised after the files are complete.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Dict, List, Optional, Sequence

from threadpoolctl import threadpool_limits

from orchestrator.errors import UserError
from orchestrator.fmu import make_slave, new_workdir, remove_workdir
from orchestrator.graph import TICKS_PER_SECOND, SystemGraph, build_graph, seconds_to_ticks
from orchestrator.master import ALGORITHMS, Master
from orchestrator.observers import CaptureRequest, ProgressBar, Recorder, WaveformCapture, scalar_outputs
from orchestrator.scenario import ScenarioManipulator, load_scenario
from orchestrator.ssp import load_parameter_set, open_system


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
    algorithm: str = "gauss-seidel"
    in_process: bool = False
    fmu_dirs: Sequence[Path] = ()
    record: Optional[Sequence[str]] = None    # "comp.var"; None → all scalar outputs
    progress: bool = False
    blas_threads: int = 1                      # BLAS threads during the run (small matrices: 1 is fastest)
    manipulators: Sequence[object] = ()
    scenario: Optional[Path] = None           # timed events (orchestrator/scenario.py)
    default_scenario: bool = True             # use the system's scenario.json when no scenario is given
    #: observers that judge the run and contribute sections to summary.json, made from the
    #: graph once it is built (the railway verdicts: orchestrator.analysis.verdict.railway_verdicts)
    summaries: Optional[Callable[[SystemGraph], Sequence[object]]] = None


@dataclass
class RunResult:
    graph: SystemGraph
    summary: dict
    steps_taken: Dict[str, int]
    end_time_s: float
    output_dir: Path


def run_system(system_path, options: RunOptions) -> RunResult:
    if options.algorithm not in ALGORITHMS:
        raise UserError(f"--algorithm {options.algorithm}: choose {' or '.join(ALGORITHMS)}")
    if options.output_interval is not None and options.output_interval <= 0:
        raise UserError(f"--output-interval {options.output_interval}: must be positive")
    system = open_system(Path(system_path), list(options.fmu_dirs))
    workdir = new_workdir()
    try:
        extra = [v for name in options.param_sets for v in load_parameter_set(system, name)]
        graph = build_graph(system, options.overrides, extra)
        _resolve_data_files(system, graph)
        manipulators = list(options.manipulators)
        scenario = None
        scenario_file = options.scenario
        if scenario_file is None and options.default_scenario and (system.folder / DEFAULT_SCENARIO).is_file():
            scenario_file = system.folder / DEFAULT_SCENARIO       # the system's own events
        if scenario_file is not None:
            scenario = ScenarioManipulator(load_scenario(scenario_file), graph)
            manipulators.append(scenario)
        stop = options.stop_time if options.stop_time is not None else \
            (scenario.scenario.end_s if scenario is not None and scenario.scenario.end_s else system.stop_time)
        if stop is None:
            raise UserError(f"{system.ssd_path}: no stop time (give --stop-time or a DefaultExperiment stopTime)")
        if stop <= system.start_time:
            raise UserError(f"--stop-time {stop}: must be after the start time {system.start_time}")
        start_ticks = round(system.start_time * TICKS_PER_SECOND)
        stop_ticks = round(stop * TICKS_PER_SECOND)
        if options.output_interval is None:
            wanted = seconds_to_ticks(DEFAULT_OUTPUT_INTERVAL_S, "output interval")
            interval_ticks = -(-wanted // graph.base_ticks) * graph.base_ticks
        else:
            interval_ticks = seconds_to_ticks(options.output_interval, "--output-interval")
        if interval_ticks % graph.base_ticks:
            raise UserError(f"--output-interval {options.output_interval}: not a multiple of the "
                            f"base step {graph.base_ticks / TICKS_PER_SECOND:g} s")
        recorded = _recorded(graph, options.record)
        captures = []
        for text in options.captures:
            request = CaptureRequest.parse(text)
            if request.component not in graph.nodes:
                raise UserError(f"--capture {text}: no component {request.component!r}")
            captures.append((request, request.elements(graph.nodes[request.component].interface)))
        out = Path(options.output_dir)
        out.mkdir(parents=True, exist_ok=True)
        slaves = {name: make_slave(name, Path(node.fmu_path), node.interface, workdir, options.in_process)
                  for name, node in graph.nodes.items()}
        recorder = Recorder(out / "results.csv", recorded, interval_ticks)
        observers: List[object] = [recorder]
        for request, elements in captures:
            safe_port = request.port.replace("[", "_").replace("]", "").replace(",", "_")
            observers.append(WaveformCapture(out / f"capture_{request.component}_{safe_port}.csv",
                                             request, elements))
        progress = ProgressBar(stop_ticks, start_ticks) if options.progress else None
        if progress:
            observers.append(progress)
        extra_outputs: Dict[str, List[str]] = {}
        for comp, var in recorded:
            extra_outputs.setdefault(comp, []).append(var)
        for request, elements in captures:
            extra_outputs.setdefault(request.component, []).extend(elements)
        judges = list(options.summaries(graph)) if options.summaries is not None else []
        for judge in judges:
            observers.append(judge)
            for name, variables in judge.outputs_needed().items():
                extra_outputs.setdefault(name, []).extend(variables)
        master = Master(graph, slaves, options.algorithm, observers, manipulators)
        began = time.perf_counter()
        failure: Optional[BaseException] = None
        try:
            # the cores' matrices are small (≤ 60 states): a second BLAS thread only spins and
            # takes the other core from the process (measured 1.8× slower model generation)
            with threadpool_limits(limits=options.blas_threads, user_api="blas"):
                master.bind(extra_outputs)
                master.initialize(system.start_time, stop)
                master.run_until(stop_ticks)
        except BaseException as error:  # includes Ctrl-C: results so far are still written
            failure = error
        finally:
            wall = time.perf_counter() - began
            for observer in observers:
                if hasattr(observer, "close"):
                    observer.close()
            problems = master.shutdown()
        sim_time = master.time_s - system.start_time
        summary = _summary(graph, sim_time, wall, failure)
        for judge in judges:
            summary.update(judge.summary_section())
        if scenario is not None:
            summary["scenario"] = {"file": str(scenario.scenario.path), "description": scenario.scenario.description,
                                   "events_applied": scenario.applied}
        _write_json(out / "summary.json", summary)
        _write_json(out / "metadata.json", _metadata(system, graph, options, stop, master, interval_ticks))
        if failure is not None:
            raise failure
        if problems:
            raise UserError("; ".join(problems))
        return RunResult(graph, summary, dict(master.steps_taken), master.time_s, out)
    finally:
        remove_workdir(workdir)
        system.close()


def _resolve_data_files(system, graph: SystemGraph) -> None:
    """A relative ``*_file`` parameter names a file of the system (DESIGN §5): its resources/
    folder, or the system folder; anything else is left for the FMU (its own resources)."""
    for node in graph.nodes.values():
        for name, value in list(node.parameters.items()):
            if not name.endswith("_file") or not isinstance(value, str) or not value or Path(value).is_absolute():
                continue
            for folder in (system.folder / "resources", system.folder):
                if (folder / value).is_file():
                    node.parameters[name] = str((folder / value).resolve())
                    break


def _recorded(graph: SystemGraph, record) -> List[tuple]:
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


def _summary(graph: SystemGraph, sim_time: float, wall: float, failure) -> dict:
    summary = {
        "system": graph.name,
        "sim_time_s": sim_time,
        "wall_time_s": wall,
        "realtime_factor": sim_time / wall if wall > 0 else None,
        "completed": failure is None,
    }
    if failure is not None:
        summary["error"] = str(failure) or type(failure).__name__
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


def _write_json(path: Path, data: dict) -> None:
    path.write_text(json.dumps(data, indent=2, default=str) + "\n")
