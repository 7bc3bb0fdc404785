"""Multi-rate fixed-step master algorithm on integer nanosecond ticks.

The algorithm only steps slaves and moves values along links; loading is ssp.py/graph.py,
recording is observers.py, timed events are manipulators (orchestrator/protocols.py says what
each plug-in provides; docs/architecture.md, "Master algorithm").

Semantics (docs/interfaces.md, "Time and frames"): a component with step h (a whole multiple of
the base step) steps at every tick T with T % h == 0, from T to T + h. Every component steps
through three stages: gather its inputs (and let manipulators adjust them); write them and
doStep; read what is needed of its outputs (and let manipulators adjust them) and tell the
interpolating links of the new source value. In which order the due components go through
them is the algorithm's (orchestrator/algorithms.py: Gauss-Seidel by default, Jacobi).
Rate transitions per connection: hold (latest value), linear (extrapolated from the last
two values of the source to the consumer's step start), mean (average of the source's
values since the consumer last read).
"""
from __future__ import annotations

import math
from typing import Dict, FrozenSet, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from orchestrator.algorithms import algorithm as _algorithm
from orchestrator.fmu import contiguous
from orchestrator.graph import TICKS_PER_SECOND, SystemGraph
from orchestrator.interrupts import NEVER, InterruptFlag
from orchestrator.protocols import Algorithm, Manipulator, Observer, Slave, StepRecord, Transition

__all__ = ["Link", "Master", "shutdown_slaves"]

#: schedules of distinct tick phases kept (a general multi-rate layout past that is planned per tick)
_MAX_PLANS = 4096


class Link:
    """All connections from one source to one target of one FMI type and one transition kind:
    index arrays into the two components' buffers and the scratch the hot path works in."""

    __slots__ = ("source", "target", "type", "transition", "source_index", "target_index", "factor",
                 "offset", "scratch", "source_values", "target_values", "source_slave", "source_stale",
                 "type_only", "gather", "current", "previous", "current_t", "previous_t", "sum", "count",
                 "slope", "slope_t")

    def __init__(self, source: str, target: str, type_name: str, transition: Transition,
                 source_index: np.ndarray, target_index: np.ndarray,
                 factor: Optional[np.ndarray], offset: Optional[np.ndarray]):
        self.source, self.target, self.type, self.transition = source, target, type_name, transition
        self.source_index, self.target_index = source_index, target_index
        self.factor, self.offset = factor, offset
        n = len(source_index)
        # scratch for the hot path: a hold link moves values without allocating
        self.scratch = np.zeros(n, dtype=np.float64 if type_name == "Real" else np.intc)
        self.type_only = (type_name,)
        # the kind is chosen once, not tested at every gather
        self.gather = {"hold": self._gather_hold, "linear": self._gather_linear,
                       "mean": self._gather_mean}[transition]
        self.current = np.zeros(n)
        self.previous = np.zeros(n)
        self.current_t: Optional[float] = None
        self.previous_t: Optional[float] = None
        self.sum = np.zeros(n)
        self.count = 0
        self.slope = np.zeros(n)
        self.slope_t: Optional[float] = None
        self.source_values = self.target_values = self.source_slave = self.source_stale = None

    def attach(self, source_slave: Slave, target_slave: Slave, source_stale: set) -> None:
        """Resolve the buffers once the slaves are bound (they never move afterwards)."""
        self.source_slave, self.source_stale = source_slave, source_stale
        self.source_values = source_slave.outputs[self.type].values
        self.target_values = target_slave.inputs[self.type].values
        source, target = contiguous(self.source_index), contiguous(self.target_index)
        if self.transition == "hold" and self.factor is None and isinstance(source, slice) \
                and isinstance(target, slice):
            # a frame port wired whole: one block copy instead of a gather and a scatter
            self.source_index, self.target_index = source, target
            self.gather = self._gather_block

    def source_updated(self, time_s: float) -> None:
        """The source has new values at ``time_s`` (linear and mean links track them)."""
        if self.transition == "linear":
            self.previous, self.previous_t = self.current, self.current_t
            self.current, self.current_t = self.source_values[self.source_index].astype(float), time_s
        elif self.transition == "mean":
            self.sum += self.source_values[self.source_index]
            self.count += 1

    def _gather_hold(self, time_s: float) -> None:
        value = self.source_values.take(self.source_index, out=self.scratch)
        if self.factor is not None:
            value = np.multiply(value, self.factor, out=self.scratch)
            value += self.offset
        self.target_values[self.target_index] = value

    def _gather_block(self, time_s: float) -> None:
        self.target_values[self.target_index] = self.source_values[self.source_index]

    def _gather_linear(self, time_s: float) -> None:
        if self.previous_t is not None and self.current_t > self.previous_t:
            if self.slope_t != self.current_t:       # once per source step
                self.slope = (self.current - self.previous) / (self.current_t - self.previous_t)
                self.slope_t = self.current_t
            value = np.multiply(self.slope, time_s - self.current_t, out=self.scratch)
            value += self.current
        else:
            value = self.current
        self._deliver(value)

    def _gather_mean(self, time_s: float) -> None:
        if self.count:
            value = self.sum / self.count
            self.sum[:] = 0.0
            self.count = 0
        else:
            value = self.source_values[self.source_index]
        self._deliver(value)

    def _deliver(self, value: np.ndarray) -> None:
        if self.factor is not None:
            value = np.multiply(value, self.factor, out=self.scratch)
            value += self.offset
        self.target_values[self.target_index] = value


class _Component:
    """One component as the step sequence needs it, every lookup resolved once."""

    __slots__ = ("name", "slave", "step_ticks", "step_s", "links_in", "tracked_links", "adjust_inputs",
                 "adjust_outputs", "output_types", "eager_types", "stale")

    def __init__(self, name: str, slave: Slave, step_ticks: int):
        self.name, self.slave, self.step_ticks = name, slave, step_ticks
        self.step_s = step_ticks / TICKS_PER_SECOND
        self.links_in: Tuple[Link, ...] = ()
        self.tracked_links: Tuple[Link, ...] = ()     # links from it that interpolate or average
        self.adjust_inputs: Tuple = ()
        self.adjust_outputs: Tuple = ()
        self.output_types: frozenset = frozenset()
        # output types read right after each step; None: all of them (a manipulator adjusts them)
        self.eager_types: Optional[Tuple[str, ...]] = ()
        self.stale: set = set()                       # output types not read since the last step


class Master:
    """Steps the slaves of a graph from start to stop; observers and manipulators plug in
    (orchestrator/protocols.py). ``interrupt`` is the flag the signal handlers set
    (orchestrator/interrupts.py): it is tested between components while initialising and once
    per tick, and a set flag stops the run with :class:`~orchestrator.interrupts.Interrupted`."""

    def __init__(self, graph: SystemGraph, slaves: Mapping[str, Slave],
                 algorithm: Union[str, Algorithm] = "gauss-seidel",
                 observers: Sequence[Observer] = (), manipulators: Sequence[Manipulator] = (),
                 interrupt: InterruptFlag = NEVER):
        self.graph = graph
        self.slaves = slaves
        self.algorithm: Algorithm = _algorithm(algorithm)
        self.observers = list(observers)
        self.manipulators = list(manipulators)
        self.steps_taken = {name: 0 for name in graph.nodes}
        self.time_ticks = 0
        self.interrupt = interrupt
        self._components = {name: _Component(name, slaves[name], graph.nodes[name].step_ticks)
                            for name in graph.order}
        # the components due at each phase of the steps' common period, kept across run_until
        # calls (a caller stepping in pieces plans each phase once, as one call does): the
        # components and their steps do not change after construction
        self._plans: Dict[int, tuple] = {}

    # ---- setup ------------------------------------------------------------------------------
    def bind(self, extra_outputs: Mapping[str, Sequence[str]] = None,
             extra_inputs: Mapping[str, Sequence[str]] = None) -> None:
        """Lay out every buffer and link once; nothing is allocated on the hot path. Besides the
        connections, the buffers hold what observers and manipulators say they need and
        ``extra_outputs`` / ``extra_inputs`` (unconnected inputs a caller writes)."""
        wanted_outputs: Dict[str, List[str]] = {}
        wanted_inputs: Dict[str, List[str]] = {}
        for table, more in ((wanted_outputs, extra_outputs), (wanted_inputs, extra_inputs)):
            for name, variables in (more or {}).items():
                table.setdefault(name, []).extend(variables)
        for plugin in self.observers:
            for name, variables in plugin.outputs_needed().items():
                wanted_outputs.setdefault(name, []).extend(variables)
        for manipulator in self.manipulators:
            for name, variables in manipulator.outputs_needed().items():
                wanted_outputs.setdefault(name, []).extend(variables)
            for name, variables in manipulator.inputs_needed().items():
                wanted_inputs.setdefault(name, []).extend(variables)
        inputs = {n: {} for n in self.graph.nodes}
        outputs = {n: {} for n in self.graph.nodes}

        def slot(table, name, var):
            per_type = table[name].setdefault(var.type, [])
            if var.vr not in per_type:
                per_type.append(var.vr)
            return per_type.index(var.vr)

        grouped: Dict[tuple, list] = {}
        for edge in self.graph.edges:
            key = (edge.source, edge.target, edge.source_var.type, edge.transition)
            grouped.setdefault(key, []).append(
                (slot(outputs, edge.source, edge.source_var), slot(inputs, edge.target, edge.target_var),
                 edge.factor, edge.offset))
        for table, wanted in ((outputs, wanted_outputs), (inputs, wanted_inputs)):
            for name, variables in wanted.items():
                node = self.graph.nodes[name]
                for var_name in variables:
                    slot(table, name, node.interface.variables[var_name])
        self._buffer_layout = (inputs, outputs)  # slaves get their buffers once instantiated
        self.links: List[Link] = []
        for (source, target, type_name, transition), rows in grouped.items():
            src, dst, factor, offset = (np.array(col) for col in zip(*rows))
            scaled = type_name == "Real" and (np.any(factor != 1.0) or np.any(offset != 0.0))
            self.links.append(Link(source, target, type_name, transition, src.astype(np.int64),
                                   dst.astype(np.int64), factor if scaled else None,
                                   offset if scaled else None))
        adjusted_inputs: Dict[str, list] = {}
        adjusted_outputs: Dict[str, list] = {}
        for manipulator in self.manipulators:
            input_components, output_components = manipulator.adjusted_components()
            for name in input_components:
                adjusted_inputs.setdefault(name, []).append(manipulator.adjust_inputs)
            for name in output_components:
                adjusted_outputs.setdefault(name, []).append(manipulator.adjust_outputs)
        for name, component in self._components.items():
            component.links_in = tuple(link for link in self.links if link.target == name)
            component.tracked_links = tuple(link for link in self.links
                                            if link.source == name and link.transition != "hold")
            component.adjust_inputs = tuple(adjusted_inputs.get(name, ()))
            component.adjust_outputs = tuple(adjusted_outputs.get(name, ()))
            # read after every step: the types a linear or mean link tracks; everything when a
            # manipulator adjusts the outputs (all read at once); the rest on demand
            component.eager_types = None if name in adjusted_outputs else \
                tuple({link.type for link in component.tracked_links})

    def fresh(self, component: str, type_name: Optional[str] = None) -> None:
        """Make a component's output buffers (or those of one FMI type) current. Outputs are
        read from a slave when something needs them, not after every step: an FMI get is a
        call into the FMU per type, and most outputs of the signal chain are looked at only
        at the recorder's or a verdict's interval."""
        entry = self._components[component]
        stale = entry.stale
        if not stale:
            return
        if type_name is None:
            entry.slave.read_outputs(tuple(stale))
            stale.clear()
        elif type_name in stale:
            entry.slave.read_outputs((type_name,))
            stale.discard(type_name)

    def fresh_all(self) -> None:
        for name in self.graph.order:
            self.fresh(name)

    def output_slot(self, component: str, variable: str):
        """(buffer, index) where the latest value of an output lives; call :meth:`fresh`
        for the component before reading it."""
        var = self.graph.nodes[component].interface.variables[variable]
        buffer = self.slaves[component].outputs[var.type]
        return buffer, int(np.flatnonzero(buffer.vr_array == var.vr)[0])

    # ---- lifecycle ---------------------------------------------------------------------------
    def initialize(self, start_time_s: float, stop_time_s: Optional[float]) -> None:
        components = [self._components[name] for name in self.graph.order]
        inputs, outputs = self._buffer_layout
        check = self.interrupt.check
        for component in components:
            check("during initialisation")
            slave, name = component.slave, component.name
            slave.instantiate()
            slave.bind(inputs[name], outputs[name])
            slave.setup_experiment(start_time_s, stop_time_s)
            if self.graph.nodes[name].parameters:
                slave.set_values(self.graph.nodes[name].parameters)
        for component in components:
            component.output_types = frozenset(component.slave.outputs)
        for link in self.links:
            source = self._components[link.source]
            link.attach(source.slave, self.slaves[link.target], source.stale)
        for component in components:
            component.slave.enter_initialization()
        # outputs known in initialisation mode (a train's initial position) reach every consumer,
        # also one that comes first in a cycle: read them all before the exchange, and let the
        # linear links start from them instead of zeros
        for component in components:
            component.slave.read_outputs()
        for link in self.links:
            if link.transition == "linear":
                link.source_updated(start_time_s)
        for component in components:  # initial exchange along the data flow
            self.gather(component, start_time_s)
            component.slave.write_inputs()
            component.slave.read_outputs()
        for component in components:
            check("during initialisation")
            component.slave.exit_initialization()
            component.slave.read_outputs()
            for link in component.tracked_links:
                link.source_updated(start_time_s)
        check("during initialisation")
        self.time_ticks = round(start_time_s * TICKS_PER_SECOND)
        for manipulator in self.manipulators:
            manipulator.bound(self)
        start = StepRecord(self.time_ticks, self.time_ticks / TICKS_PER_SECOND, frozenset())
        for observer in self.observers:
            observer.started(self, start)

    # ---- the three stages of a step (protocols.Stages); the algorithm orders them --------------
    def gather(self, component: _Component, time_s: float) -> None:
        """Stage 1: the component's inputs from its links (and the manipulators' adjustments)."""
        for link in component.links_in:
            stale = link.source_stale
            if link.type in stale:               # the source's outputs are read on demand
                link.source_slave.read_outputs(link.type_only)
                stale.discard(link.type)
            link.gather(time_s)
        for adjust in component.adjust_inputs:
            adjust(component.name)

    def step(self, component: _Component, time_s: float) -> None:
        """Stage 2: write the inputs, step from ``time_s`` by the component's own step."""
        component.slave.write_inputs()
        component.slave.do_step(time_s, component.step_s)
        self.steps_taken[component.name] += 1

    def conclude(self, component: _Component, tick: int) -> None:
        """Stage 3: read what must be read at once (what linear and mean links track, or all
        that a manipulator adjusts; the rest on demand), then update the tracking links."""
        slave = component.slave
        eager = component.eager_types
        if eager is None:
            slave.read_outputs()
        else:
            stale = component.stale
            stale.update(component.output_types)
            if eager:
                slave.read_outputs(eager)
                stale.difference_update(eager)
        for adjust in component.adjust_outputs:
            adjust(component.name)
        if component.tracked_links:
            end_s = (tick + component.step_ticks) / TICKS_PER_SECOND
            for link in component.tracked_links:
                link.source_updated(end_s)

    def _plan(self, tick: int) -> Tuple[Tuple[_Component, ...], FrozenSet[str]]:
        """The components due at ``tick`` in data-flow order, and their names."""
        due = tuple(c for c in (self._components[name] for name in self.graph.order) if tick % c.step_ticks == 0)
        return due, frozenset(c.name for c in due)

    def run_until(self, stop_ticks: int) -> None:
        base = self.graph.base_ticks
        # the due components repeat with the least common multiple of the steps: one plan per
        # phase, made once (a layout with too many phases is planned at each tick)
        period = math.lcm(*(c.step_ticks for c in self._components.values())) if self._components else base
        plans = self._plans
        manipulators = self.manipulators
        observers = self.observers
        step_due = self.algorithm.step_due
        tick = self.time_ticks
        interrupt = self.interrupt
        while tick < stop_ticks:
            if interrupt.signum:      # a signal arrived: stop between two macro steps
                break
            for manipulator in manipulators:
                manipulator.before_tick(self, tick)
            time_s = tick / TICKS_PER_SECOND
            phase = tick % period
            plan = plans.get(phase)
            if plan is None:
                plan = self._plan(tick)
                if len(plans) < _MAX_PLANS:
                    plans[phase] = plan
            due, stepped = plan
            if due:
                step_due(due, self, time_s, tick)
            tick += base
            self.time_ticks = tick
            if observers:
                record = StepRecord(tick, tick / TICKS_PER_SECOND, stepped)
                for observer in observers:
                    observer.after_tick(self, record)
        self.fresh_all()           # the final state, for summaries and whoever reads it next
        interrupt.check(f"at t = {self.time_s:g} s")

    def shutdown(self) -> List[str]:
        """Terminate and free every slave, whatever happened; returns the problems met."""
        return shutdown_slaves(self.graph.order, self.slaves)

    @property
    def time_s(self) -> float:
        return self.time_ticks / TICKS_PER_SECOND


def shutdown_slaves(order: Sequence[str], slaves: Mapping[str, Slave]) -> List[str]:
    """Terminate and free the slaves of ``order`` that exist (also those of a run that failed
    before its master was made), whatever happened; returns the problems met."""
    problems = []
    for name in order:
        slave = slaves.get(name)
        if slave is None:
            continue
        try:
            slave.terminate()
        except Exception as error:
            problems.append(str(error))
        try:
            slave.free()
        except Exception as error:
            problems.append(f"{name}: freeInstance failed: {error}")
    return problems
