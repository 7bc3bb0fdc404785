"""``railcosim validate``: every problem a run of a system would meet before its first step, as a
list of one-line problems (empty: the run would start), in FMPy's style of validation.

The options, the system and its parameter sets, the scenario and the data files are checked
through the run's own planning (orchestrator/run.py ``plan_run``), each problem noted and the
next part checked with what is still known; then every component is instantiated, given its
parameters and initialised together as a run does, a failing one noted and skipped, nothing
stepped and nothing written. A DCP component is checked against its description without
contacting the rig.
"""
from __future__ import annotations

from pathlib import Path
from typing import Dict, List, Set

from orchestrator import interrupts
from orchestrator.dcp.remote_slave import OfflineRemoteDcpSlave
from orchestrator.errors import RefusedComponents, UserError
from orchestrator.fmu import make_slave, new_workdir, remove_workdir
from orchestrator.master import shutdown_slaves
from orchestrator.protocols import Slave
from orchestrator.run import (RunOptions, RunPlan, blas_threads_limited, check_options, os_error, plan_run,
                              start_master, warn_beyond_stop, warn_rounded_stop)
from orchestrator.ssp import SystemDescription, open_system


def problems_of(system_path, options: RunOptions) -> List[str]:
    """Every problem a run of this system with these options would meet before its first step
    (``railcosim validate``): the options, the system and its parameter sets, the scenario,
    the data files, and each component instantiated, given its parameters and initialised
    together as a run does. One line per problem; empty when the run would start."""
    problems: List[str] = []
    refused: Set[str] = set()           # components whose problem is said already: not initialised

    def attempt(step):
        try:
            return step()
        except RefusedComponents as error:
            for text, names in error.problems:
                _note(problems, UserError(text))
                refused.update(names)
            return None
        except UserError as error:
            _note(problems, error)
            return None

    attempt(lambda: check_options(options))
    try:
        system = open_system(Path(system_path), list(options.fmu_dirs))
    except (UserError, OSError) as error:
        return _note(problems, os_error(error) if isinstance(error, OSError) else error)
    try:
        try:
            plan = plan_run(system, options, attempt)
        except UserError as error:          # no graph: nothing further can be checked
            return _note(problems, error)
        if plan.stop_s is not None:         # what a run would warn about, said the same way
            warn_beyond_stop(options, plan.scenario, plan.captures, plan.stop_s)
            warn_rounded_stop(options, plan)
        _initialise_only(plan, system, options, problems, refused)
    finally:
        system.close()
    return problems


def _note(problems: List[str], error: BaseException) -> List[str]:
    text = " ".join(str(error).split()) or type(error).__name__
    if text not in problems:
        problems.append(text)
    return problems


class CheckedSlave:
    """A slave as ``railcosim validate`` drives it: a lifecycle call that fails is noted, not
    raised, and the component's later calls are skipped, so the initialisation goes on and
    every component's problem is seen (the others get the values a run would give them).
    A ``refused`` component (its problem found by the checks before) is instantiated, so that
    it can be bound, and nothing more: the same problem is not met again."""

    def __init__(self, slave: Slave, problems: List[str], refused: bool = False):
        self._slave, self._problems, self.failed = slave, problems, False
        self._instantiated, self._refused = False, refused

    @property
    def inputs(self):
        return self._slave.inputs

    @property
    def outputs(self):
        return self._slave.outputs

    def _call(self, method: str, *args) -> None:
        if self.failed or (self._refused and method != "instantiate"):
            return
        try:
            getattr(self._slave, method)(*args)
        except Exception as error:
            self.failed = True
            _note(self._problems, error)

    def instantiate(self) -> None:                # instantiated once, before the master is made
        if not self._instantiated:
            self._instantiated = True
            self._call("instantiate")

    def bind(self, inputs, outputs) -> None:
        self._slave.bind(inputs, outputs)

    def setup_experiment(self, start_time, stop_time) -> None:
        self._call("setup_experiment", start_time, stop_time)

    def set_values(self, values) -> None:
        self._call("set_values", values)

    def enter_initialization(self) -> None:
        self._call("enter_initialization")

    def exit_initialization(self) -> None:
        self._call("exit_initialization")

    def write_inputs(self) -> None:
        self._call("write_inputs")

    def read_outputs(self, types=None) -> None:
        self._call("read_outputs", types)

    def do_step(self, time_s, step_s) -> None:
        raise AssertionError("validate never steps")

    def terminate(self) -> None:
        self._slave.terminate()

    def free(self) -> None:
        self._slave.free()


def _initialise_only(plan: RunPlan, system: SystemDescription, options: RunOptions, problems: List[str],
                     refused: Set[str]) -> None:
    """Instantiate every component, then bind and initialise them together as a run does
    (:func:`_start`), noting each component's failure; nothing is stepped, nothing written.
    The ``refused`` components (their problem noted by the checks before) are only
    instantiated and bound."""
    workdir = new_workdir()
    slaves: Dict[str, Slave] = {}
    try:
        def make(name, node):
            if name in plan.hil:          # a DCP slave: its description checked, the rig not contacted
                made = OfflineRemoteDcpSlave(name, node.interface, plan.targets[name], plan.hil[name], node.step_ticks)
            else:
                made = make_slave(name, Path(node.fmu_path), node.interface, workdir, options.in_process)
            slave = CheckedSlave(made, problems, refused=name in refused)
            slave.instantiate()
            return slave

        try:
            with blas_threads_limited(options.blas_threads):
                start_master(plan.graph, options, slaves, make, list(plan.judges), plan.scenario, interrupts.NEVER,
                       system.start_time, plan.stop_s, ready=lambda: not any(s.failed for s in slaves.values()))
        except Exception as error:
            _note(problems, error)
    finally:
        for problem in shutdown_slaves(plan.graph.order, slaves):
            _note(problems, UserError(problem))
        remove_workdir(workdir)
