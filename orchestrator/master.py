"""Multi-rate fixed-step master algorithm on integer nanosecond ticks.

The algorithm only steps slaves and moves values along links; loading is ssp.py/graph.py,
recording is observers.py, timed events are manipulators (hooks called before each tick).

Semantics (DESIGN §3): a component with step h (a whole multiple of the base step) steps
at every tick T with T % h == 0, from T to T + h. Gauss-Seidel (default) visits the due
components in data-flow order, so a consumer in the same macro step sees what its producer
has just computed (no latency along a chain). Jacobi first gathers every due component's
inputs, then steps them all: each hop adds one step of latency.
Rate transitions per connection: hold (latest value), linear (extrapolated from the last
two values of the source to the consumer's step start), mean (average of the source's
values since the consumer last read).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Optional, Sequence

import numpy as np

from orchestrator.graph import TICKS_PER_SECOND, SystemGraph

ALGORITHMS = ("gauss-seidel", "jacobi")


@dataclass
class Link:
    """All connections from one source to one target of one type and transition kind."""

    source: str
    target: str
    type: str
    transition: str
    source_index: np.ndarray   # slots in the source's output buffer
    target_index: np.ndarray   # slots in the target's input buffer
    factor: Optional[np.ndarray]
    offset: Optional[np.ndarray]

    def __post_init__(self):
        n = len(self.source_index)
        # scratch for the hot path: hold links move values without allocating
        self.scratch = np.zeros(n, dtype=np.float64 if self.type == "Real" else np.intc)
        self.current = np.zeros(n)
        self.previous = np.zeros(n)
        self.current_t: Optional[float] = None
        self.previous_t: Optional[float] = None
        self.sum = np.zeros(n)
        self.count = 0
        self.slope = np.zeros(n)
        self.slope_t: Optional[float] = None

    def source_updated(self, values: np.ndarray, time_s: float) -> None:
        if self.transition == "linear":
            self.previous, self.previous_t = self.current, self.current_t
            self.current, self.current_t = values[self.source_index].astype(float), time_s
        elif self.transition == "mean":
            self.sum += values[self.source_index]
            self.count += 1

    def gather(self, source_values, target_values, time_s: float) -> None:
        if self.transition == "hold":
            value = np.take(source_values, self.source_index, out=self.scratch)
        elif self.transition == "linear":
            if self.previous_t is not None and self.current_t > self.previous_t:
                if self.slope_t != self.current_t:       # once per source step
                    self.slope = (self.current - self.previous) / (self.current_t - self.previous_t)
                    self.slope_t = self.current_t
                value = np.multiply(self.slope, time_s - self.current_t, out=self.scratch)
                value += self.current
            else:
                value = self.current
        else:
            if self.count:
                value = self.sum / self.count
                self.sum[:] = 0.0
                self.count = 0
            else:
                value = source_values[self.source_index]
        if self.factor is not None:
            value = np.multiply(value, self.factor, out=self.scratch)
            value += self.offset
        target_values[self.target_index] = value


class Master:
    """Steps the slaves of a graph from start to stop; observers and manipulators plug in."""

    def __init__(self, graph: SystemGraph, slaves: Dict[str, object], algorithm: str = "gauss-seidel",
                 observers: Sequence[object] = (), manipulators: Sequence[object] = ()):
        if algorithm not in ALGORITHMS:
            raise ValueError(f"algorithm must be one of {ALGORITHMS}")
        self.graph = graph
        self.slaves = slaves
        self.algorithm = algorithm
        self.observers = list(observers)
        self.manipulators = list(manipulators)
        self.steps_taken = {name: 0 for name in graph.nodes}
        self.time_ticks = 0

    # ---- setup ------------------------------------------------------------------------------
    def bind(self, extra_outputs: Dict[str, List[str]] = None, extra_inputs: Dict[str, List[str]] = None) -> None:
        """Preallocate every buffer and link once; nothing is allocated on the hot path.
        ``extra_inputs``: unconnected inputs a manipulator writes."""
        extra_outputs = extra_outputs or {}
        for manipulator in self.manipulators:
            for name, variables in getattr(manipulator, "outputs_needed", dict)().items():
                extra_outputs.setdefault(name, []).extend(variables)
            for name, variables in getattr(manipulator, "inputs_needed", dict)().items():
                extra_inputs = extra_inputs or {}
                extra_inputs.setdefault(name, []).extend(variables)
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
        for name, variables in extra_outputs.items():
            node = self.graph.nodes[name]
            for var_name in variables:
                slot(outputs, name, node.interface.variables[var_name])
        for name, variables in (extra_inputs or {}).items():
            node = self.graph.nodes[name]
            for var_name in variables:
                slot(inputs, name, node.interface.variables[var_name])
        self._buffer_layout = (inputs, outputs)  # slaves get their buffers once instantiated
        self.links: List[Link] = []
        for (source, target, type_name, transition), rows in grouped.items():
            src, dst, factor, offset = (np.array(col) for col in zip(*rows))
            scaled = type_name == "Real" and (np.any(factor != 1.0) or np.any(offset != 0.0))
            self.links.append(Link(source, target, type_name, transition, src.astype(np.int64),
                                   dst.astype(np.int64), factor if scaled else None,
                                   offset if scaled else None))
        self.links_into = {n: [l for l in self.links if l.target == n] for n in self.graph.nodes}
        self.links_from = {n: [l for l in self.links if l.source == n and l.transition != "hold"]
                           for n in self.graph.nodes}

    def fresh(self, component: str, type_name: Optional[str] = None) -> None:
        """Make a component's output buffers (or those of one FMI type) current. Outputs are
        read from a slave when something needs them, not after every step: an FMI get is a
        call into the FMU per type, and most outputs of the signal chain are looked at only
        at the recorder's or a verdict's interval."""
        stale = self._stale[component]
        if not stale:
            return
        if type_name is None:
            self.slaves[component].read_outputs(tuple(stale))
            stale.clear()
        elif type_name in stale:
            self.slaves[component].read_outputs((type_name,))
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
        order = self.graph.order
        for name in order:
            slave = self.slaves[name]
            slave.instantiate()
            slave.bind(self._buffer_layout[0][name], self._buffer_layout[1][name])
            slave.setup_experiment(start_time_s, stop_time_s)
            if self.graph.nodes[name].parameters:
                slave.set_values(self.graph.nodes[name].parameters)
        self._output_types = {name: set(self.slaves[name].outputs) for name in order}
        self._stale = {name: set() for name in order}
        self._eager_types = {name: tuple({link.type for link in self.links_from[name]}) for name in order}
        for manipulator in self.manipulators:
            if hasattr(manipulator, "components"):
                for name in manipulator.components()[1]:
                    self._eager_types[name] = None          # adjusted outputs: read them all at once
        for name in order:
            self.slaves[name].enter_initialization()
        for name in order:  # initial exchange along the data flow
            self._gather(name, start_time_s)
            self.slaves[name].write_inputs()
            self.slaves[name].read_outputs()
        for name in order:
            self.slaves[name].exit_initialization()
            self.slaves[name].read_outputs()
            self._source_updated(name, start_time_s)
        self.time_ticks = round(start_time_s * TICKS_PER_SECOND)
        for manipulator in self.manipulators:
            if hasattr(manipulator, "bound"):
                manipulator.bound(self)
        for observer in self.observers:
            observer.started(self, self.time_ticks)

    def _gather(self, name: str, time_s: float) -> None:
        slave = self.slaves[name]
        stale = self._stale
        for link in self.links_into[name]:
            if link.type in stale[link.source]:
                self.fresh(link.source, link.type)
            link.gather(self.slaves[link.source].outputs[link.type].values,
                        slave.inputs[link.type].values, time_s)

    def _stepped(self, name: str, slave) -> None:
        """After a step: read what is needed at once (links that interpolate or average the
        source, manipulators that adjust the outputs); the rest is read on demand."""
        eager = self._eager_types[name]
        if eager is None:
            slave.read_outputs()
        else:
            self._stale[name].update(self._output_types[name])
            if eager:
                slave.read_outputs(eager)
                self._stale[name].difference_update(eager)

    def _source_updated(self, name: str, time_s: float) -> None:
        for link in self.links_from[name]:
            link.source_updated(self.slaves[name].outputs[link.type].values, time_s)

    def run_until(self, stop_ticks: int) -> None:
        graph, slaves = self.graph, self.slaves
        base = graph.base_ticks
        schedule = [(name, graph.nodes[name].step_ticks, slaves[name]) for name in graph.order]
        gauss_seidel = self.algorithm == "gauss-seidel"
        steps_taken = self.steps_taken
        observers = [o for o in self.observers if hasattr(o, "after_tick")]
        manipulators = self.manipulators
        # components whose inputs / outputs a manipulator adjusts after each gather / read
        adjust_in: Dict[str, list] = {}
        adjust_out: Dict[str, list] = {}
        for manipulator in manipulators:
            if hasattr(manipulator, "components"):
                ins, outs = manipulator.components()
                for name in ins:
                    adjust_in.setdefault(name, []).append(manipulator.adjust_inputs)
                for name in outs:
                    adjust_out.setdefault(name, []).append(manipulator.adjust_outputs)
        # the components due at a tick that is not a multiple of every step: those stepping at
        # the base step (the signal chain), the same list every time
        every_tick = [entry for entry in schedule if entry[1] == base]
        slowest = int(np.lcm.reduce([step for _, step, _ in schedule])) if schedule else 1
        if any(step not in (base, slowest) for _, step, _ in schedule):
            slowest = 1                    # a general multi-rate layout: evaluate every tick
        tick = self.time_ticks
        while tick < stop_ticks:
            for manipulator in manipulators:
                manipulator.before_tick(self, tick)
            time_s = tick / TICKS_PER_SECOND
            due = every_tick if tick % slowest else [entry for entry in schedule if tick % entry[1] == 0]
            if gauss_seidel:
                for name, step, slave in due:
                    self._gather(name, time_s)
                    for adjust in adjust_in.get(name, ()):
                        adjust(name)
                    slave.write_inputs()
                    slave.do_step(time_s, step / TICKS_PER_SECOND)
                    self._stepped(name, slave)
                    for adjust in adjust_out.get(name, ()):
                        adjust(name)
                    steps_taken[name] += 1
                    self._source_updated(name, (tick + step) / TICKS_PER_SECOND)
            else:
                for name, step, slave in due:
                    self._gather(name, time_s)
                    for adjust in adjust_in.get(name, ()):
                        adjust(name)
                for name, step, slave in due:
                    slave.write_inputs()
                    slave.do_step(time_s, step / TICKS_PER_SECOND)
                    steps_taken[name] += 1
                for name, step, slave in due:
                    self._stepped(name, slave)
                    for adjust in adjust_out.get(name, ()):
                        adjust(name)
                    self._source_updated(name, (tick + step) / TICKS_PER_SECOND)
            tick += base
            self.time_ticks = tick
            for observer in observers:
                observer.after_tick(self, tick, due)
        self.fresh_all()           # the final state, for summaries and whoever reads it next

    def shutdown(self) -> List[str]:
        """Terminate and free every slave, whatever happened; returns the problems met."""
        problems = []
        for name in self.graph.order:
            slave = self.slaves[name]
            try:
                slave.terminate()
            except Exception as error:
                problems.append(str(error))
            try:
                slave.free()
            except Exception as error:
                problems.append(f"{name}: freeInstance failed: {error}")
        return problems

    @property
    def time_s(self) -> float:
        return self.time_ticks / TICKS_PER_SECOND
