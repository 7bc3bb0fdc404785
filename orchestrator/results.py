"""A run's results folder and the files written at its end (docs/interfaces.md, "Results").

results.csv and the capture files are streamed as the run steps (orchestrator/observers.py);
summary.json and metadata.json are written here once the stepping has ended, however it ended,
each replaced whole (orchestrator/folders.py ``replace_file``). The folder is locked for the run
and holds one run only (docs/reliability.md, "One run per folder"); what stopped the run is
raised once the files are complete (:func:`raise_failure`).
"""
from __future__ import annotations

import json
import os
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional, Sequence

from orchestrator.errors import UserError, os_error, shown_paths
from orchestrator.folders import FolderLock, refuse_link, replace_file
from orchestrator.graph import TICKS_PER_SECOND
from orchestrator.ports import base_of
from orchestrator.interrupts import Interrupted
from orchestrator.master import Master
from orchestrator.observers import cannot_write
from orchestrator.pacing import Pacer
from orchestrator.plan import RunPlan
from orchestrator.provenance import (content_hash, data_file_hashes, railcosim_version, source_revision,
                                     utc_now_iso)
from orchestrator.protocols import Slave

#: what a run (and `railcosim report` into the run folder) writes; a run removes these before it
#: starts, so the folder never mixes two runs. Nothing else in the folder is touched.
RUN_FILES = ("results.csv", "columns.json", "summary.json", "metadata.json")
RUN_PATTERNS = ("capture_*.csv",)
REPORT_FILES = ("speed_distance.png", "time_distance.png", "coil_emf.png", "energy.png", "report.html")
#: what ``railcosim plot`` draws into the run folder (orchestrator/reports/plot.py), cleared with it
REPORT_PATTERNS = ("plot_*.png", "plot_*.svg")


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
        for pattern in RUN_PATTERNS + REPORT_PATTERNS:
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


@dataclass
class Outcome:
    """What the stepping left, however it ended."""

    wall_s: float                       # the components made, initialised and stepped
    failure: Optional[BaseException]    # what stopped the run (an interruption included), if anything
    problems: List[str]                 # what closing the files and shutting the slaves down met
    master: Optional[Master]
    steps_taken: Dict[str, int]
    pacer: Optional[Pacer] = None
    hil: Dict[str, Slave] = field(default_factory=dict)     # the remote DCP slaves, by name
    streamed: List[Path] = field(default_factory=list)       # results.csv and the captures
    init_s: Optional[float] = None      # of wall_s: the components made and initialised (None: none made)


def summary_of(system_name: str, sim_time_s: float, wall_s: float, failure: Optional[BaseException],
               init_s: Optional[float] = None) -> dict:
    """summary.json's own keys: what was simulated, how fast, and how the run ended. The wall
    time and ``realtime_factor`` are the whole run's (the components made and initialised, then
    stepped); ``init_wall_time_s``, ``stepping_wall_time_s`` and ``stepping_realtime_factor``
    part them: the stepping's factor is the rate a run keeps (``--real-time``'s)."""
    stepping_s = wall_s - init_s if init_s is not None else None
    summary = {
        "system": system_name,
        "sim_time_s": sim_time_s,
        "wall_time_s": wall_s,
        "realtime_factor": sim_time_s / wall_s if wall_s > 0 else None,
        "init_wall_time_s": init_s,
        "stepping_wall_time_s": stepping_s,
        "stepping_realtime_factor": sim_time_s / stepping_s if stepping_s else None,
        "completed": failure is None,
        "interrupted": failure.signal_name if isinstance(failure, Interrupted) else None,
    }
    if failure is not None:
        summary["error"] = str(failure) or type(failure).__name__
    return summary


def summary(plan: RunPlan, sim_time_s: float, outcome: Outcome) -> dict:
    """summary.json: the run's own keys, then each judge's section, the pacer's, the remote
    slaves' and the scenario's."""
    summary = summary_of(plan.graph.name, sim_time_s, outcome.wall_s, outcome.failure, outcome.init_s)
    for judge in plan.judges:
        summary.update(judge.summary_section())
    if outcome.pacer is not None:
        summary.update(outcome.pacer.summary_section())
    if outcome.hil:
        summary["hil"] = {name: slave.summary_section() for name, slave in outcome.hil.items()}
    if plan.scenario is not None:
        scenario = plan.scenario
        summary["scenario"] = {"file": str(scenario.scenario.path), "description": scenario.scenario.description,
                               "events_applied": scenario.applied}
    return summary


def metadata(plan: RunPlan, steps_taken: Dict[str, int]) -> dict:
    """metadata.json: what was run, with which settings, and each component's part in it."""
    system, graph = plan.system, plan.graph
    return {
        "system": graph.name,
        "ssd": str(system.ssd_path),
        "railcosim_version": railcosim_version(),
        "railcosim_source": source_revision(),
        "date_utc": utc_now_iso(),
        # of the system folder (an .ssp: of what it unpacked to), so an edited copy is told apart
        "system_sha256": content_hash(system.folder),
        "data_files_sha256": data_file_hashes({name: node.parameters for name, node in graph.nodes.items()}),
        "overrides": dict(plan.options.overrides),
        "param_sets": list(plan.options.param_sets),
        "algorithm": plan.options.algorithm,
        "in_process": plan.options.in_process,
        "start_time_s": system.start_time,
        "stop_time_s": plan.stop_s,
        "base_step_s": graph.base_ticks / TICKS_PER_SECOND,
        "output_interval_s": plan.interval_ticks / TICKS_PER_SECOND,
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


def columns(plan: RunPlan) -> dict:
    """columns.json: every column of results.csv in its order, with its unit, FMI type and
    description as the component's modelDescription states them, and for an enumeration the
    label of each value (``plan.options.labels``; a Boolean: false, true). A unit the
    modelDescription gives (on the variable, else its declaredType) is the unit; else an Integer
    is a count or an index, "1", and an enumeration, a Boolean or a Real without a unit have "".
    """
    named = plan.options.labels(plan.graph) if plan.options.labels is not None else {}
    entries = [{"name": "time", "unit": "s", "type": "Real", "description": "simulated time"}]
    for component, name in plan.recorded:
        variable = plan.graph.nodes[component].interface.variables[name]
        labels = named.get((component, base_of(name)))
        if labels is None and variable.type == "Boolean":
            labels = {0: "false", 1: "true"}
        unit = variable.unit or variable.declared_unit or ("1" if variable.type == "Integer" and not labels else "")
        entry = {"name": f"{component}.{name}", "unit": unit, "type": variable.type,
                 "description": variable.description}
        if labels:
            entry["labels"] = {str(value): text for value, text in sorted(labels.items())}
        entries.append(entry)
    return {"file": "results.csv", "columns": entries}


def write_columns(out: Path, plan: RunPlan) -> None:
    """columns.json beside results.csv, written whole before the run steps (a file that cannot
    be written stops the run before it starts: one line naming it)."""
    path = out / "columns.json"
    try:
        replace_file(path, json.dumps(columns(plan), indent=1, ensure_ascii=False) + "\n")
    except OSError as error:
        raise cannot_write(path, error) from None


def write_results(out: Path, summary: dict, metadata: Optional[dict]) -> List[str]:
    """summary.json and metadata.json (results.csv and the captures are streamed as the run
    goes), each whole or not at all; returns what could not be written. Paths inside an
    unpacked .ssp are written ``<archive>!<member>`` (the extraction folder is gone once the
    run ends)."""
    problems = []
    for name, data in (("summary.json", summary), ("metadata.json", metadata)):
        if data is None:
            continue
        try:
            replace_file(out / name, shown_paths(json.dumps(data, indent=2, default=str)) + "\n")
        except OSError as error:
            problems.append(str(cannot_write(out / name, error)))
        except UserError as error:      # a link planted at its temporary file's name
            problems.append(str(error))
    return problems


def interrupted_before_start(out: OutputFolder, system_name: str, stop: Interrupted) -> None:
    """A signal before the components were made: the folder gets this run's summary (nothing
    simulated), then :class:`Interrupted` is raised."""
    try:
        out.claim()
    except UserError as error:          # the folder is another run's (or cannot be made): leave it
        raise Interrupted(stop.signum, f"{stop.where}; nothing written ({error})") from None
    try:
        problems = write_results(out.path, summary_of(system_name, 0.0, 0.0, stop), None)
    finally:
        out.release()
    raise_failure(Outcome(0.0, stop, [], None, {}), problems, out.path)


def raise_failure(outcome: Outcome, problems: List[str], out: Path) -> None:
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
