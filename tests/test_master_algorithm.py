"""The master algorithm with in-memory fake slaves (no FMI, no FMU build): rate transitions
(hold, linear, mean) with exact values, decimation, Gauss-Seidel against Jacobi latency along a
chain, cycle breaking, the plug-in hooks.

Steps are powers of two in seconds (0.25 s, 1 s) so every time and every interpolated value in
these tests is exact in binary floating point: the expected values are written out, not
recomputed with the master's own arithmetic.
"""
from typing import Callable, Dict, List, Optional

import pytest

from orchestrator.errors import UserError
from orchestrator.fmu import Interface, ValueBuffer, Variable
from orchestrator.graph import TICKS_PER_SECOND, graph_of
from orchestrator.master import Master
from orchestrator.protocols import Manipulator, Observer, StepRecord


def interface(inputs=(), outputs=("y",)) -> Interface:
    variables = {}
    for causality, names in (("input", inputs), ("output", outputs)):
        for name in names:
            variables[name] = Variable(name, len(variables), "Real", causality, "continuous", None, 0.0)
    return Interface("Fake", variables, {}, None, "", "fake", None)


class FakeSlave:
    """A component in memory implementing the slave protocol. ``rule(steps, end_time_s, inputs)``
    gives the outputs after each step (``steps`` counts this one); before the first step every
    output is 0. It keeps what it received at each step and counts the calls it gets."""

    def __init__(self, interface: Interface, rule: Callable[[int, float, Dict[str, float]], Dict[str, float]]):
        self.interface = interface
        self.rule = rule
        self.inputs: Dict[str, ValueBuffer] = {}
        self.outputs: Dict[str, ValueBuffer] = {}
        self.steps = 0
        self.seen: List[tuple] = []                 # (step start in s, {input: value})
        self.calls: Dict[str, int] = {}
        self._received: Dict[int, float] = {}
        self._values = {var.vr: 0.0 for var in interface.variables.values() if var.causality == "output"}

    def _count(self, call: str) -> None:
        self.calls[call] = self.calls.get(call, 0) + 1

    def instantiate(self) -> None:
        self._count("instantiate")

    def bind(self, inputs, outputs) -> None:
        self.inputs = {t: ValueBuffer(t, vrs) for t, vrs in inputs.items() if vrs}
        self.outputs = {t: ValueBuffer(t, vrs) for t, vrs in outputs.items() if vrs}

    def setup_experiment(self, start_time, stop_time) -> None:
        self._count("setup_experiment")

    def set_values(self, values) -> None:
        self._count("set_values")

    def enter_initialization(self) -> None:
        self._count("enter_initialization")

    def exit_initialization(self) -> None:
        self._count("exit_initialization")

    def write_inputs(self) -> None:
        self._count("write_inputs")
        for buffer in self.inputs.values():
            self._received.update(zip(buffer.vr_array.tolist(), buffer.values.tolist()))

    def do_step(self, time_s: float, step_s: float) -> None:
        self._count("do_step")
        received = {name: self._received.get(var.vr, 0.0) for name, var in self.interface.variables.items()
                    if var.causality == "input"}
        self.seen.append((time_s, received))
        self.steps += 1
        for name, value in self.rule(self.steps, time_s + step_s, received).items():
            self._values[self.interface.variables[name].vr] = value

    def read_outputs(self, types=None) -> None:
        self._count("read_outputs")
        for buffer in self.outputs.values():
            if types is None or buffer.type in types:
                buffer.values[:] = [self._values[vr] for vr in buffer.vr_array.tolist()]

    def terminate(self) -> None:
        self._count("terminate")

    def free(self) -> None:
        self._count("free")

    def received(self, name: str) -> List[float]:
        """What input ``name`` was at each step."""
        return [inputs[name] for _, inputs in self.seen]


def counter(steps, end_time_s, inputs):
    return {"y": float(steps)}


def square(steps, end_time_s, inputs):
    return {"y": float(steps * steps)}


def passthrough(steps, end_time_s, inputs):
    return {"y": inputs["u"]}


def run(components, connections, stop_s: float, algorithm="gauss-seidel", observers=(), manipulators=(),
        base_step_s: Optional[float] = None):
    """components: (name, step in s, rule, has an input u) in declaration order."""
    graph = graph_of("fake", [(name, interface(("u",) if has_input else ()), step)
                              for name, step, _, has_input in components], connections, base_step_s)
    slaves = {name: FakeSlave(graph.nodes[name].interface, rule) for name, _, rule, _ in components}
    master = Master(graph, slaves, algorithm, observers, manipulators)
    master.bind()
    master.initialize(0.0, stop_s)
    try:
        master.run_until(round(stop_s * TICKS_PER_SECOND))
    finally:
        assert master.shutdown() == []
    return master, slaves


def fast_to_slow(rule, transition, algorithm="gauss-seidel"):
    """A source stepping every 0.25 s feeding a consumer stepping every 1 s, for 4 s."""
    return run([("source", 0.25, rule, False), ("slow", 1.0, passthrough, True)],
               [("source.y", "slow.u", transition)], 4.0, algorithm)[1]["slow"]


# ---- rate transitions ----------------------------------------------------------------------------
def test_hold_gives_the_latest_value_the_source_has_computed():
    # the source's value after n steps is n²; Gauss-Seidel: the source has just stepped at the
    # consumer's step start (tick 4k: n = 4k + 1), Jacobi: not yet (n = 4k)
    assert fast_to_slow(square, "hold").received("u") == [1.0, 25.0, 81.0, 169.0]
    assert fast_to_slow(square, "hold", "jacobi").received("u") == [0.0, 16.0, 64.0, 144.0]


def test_mean_averages_every_value_since_the_consumer_last_read():
    # values since the last read: at t = 0 the initial value 0 and the first step's 1; then the
    # four values of the steps since (n = 2..5 → 4, 9, 16, 25, and so on)
    slow = fast_to_slow(square, "mean")
    assert slow.received("u") == [(0 + 1) / 2, (4 + 9 + 16 + 25) / 4, (36 + 49 + 64 + 81) / 4,
                                  (100 + 121 + 144 + 169) / 4]
    # Jacobi reads before the source steps: the initial value alone, then n = 1..4, 5..8, 9..12
    slow = fast_to_slow(square, "mean", "jacobi")
    assert slow.received("u") == [0.0, (1 + 4 + 9 + 16) / 4, (25 + 36 + 49 + 64) / 4, (81 + 100 + 121 + 144) / 4]


def test_mean_of_a_source_as_fast_as_its_consumer_is_its_latest_value():
    received = run([("source", 0.25, square, False), ("sink", 0.25, passthrough, True)],
                   [("source.y", "sink.u", "mean")], 1.0)[1]["sink"].received("u")
    assert received == [0.5, 4.0, 9.0, 16.0]      # the first read also averages the initial value


def test_linear_interpolates_the_sources_last_two_values_at_the_consumers_step_start():
    # slow source (1 s, n² at its step's end n s) into a fast consumer (0.25 s): at t in [m, m+1)
    # the source's last two values are m² at m and (m+1)² at m+1, so the consumer sees the
    # straight line between them: m² + (2m+1)(t − m); hold sees (m+1)² throughout
    def consumer_of(transition, algorithm="gauss-seidel"):
        return run([("source", 1.0, square, False), ("fast", 0.25, passthrough, True)],
                   [("source.y", "fast.u", transition)], 3.0, algorithm)[1]["fast"].received("u")

    assert consumer_of("linear") == [0.0, 0.25, 0.5, 0.75, 1.0, 1.75, 2.5, 3.25, 4.0, 5.25, 6.5, 7.75]
    assert consumer_of("hold") == [1.0] * 4 + [4.0] * 4 + [9.0] * 4
    # Jacobi at t = m: the source has not stepped yet and its last value, m², is at m itself
    assert consumer_of("linear", "jacobi") == consumer_of("linear")
    assert consumer_of("hold", "jacobi") == [0.0, 1.0, 1.0, 1.0, 1.0, 4.0, 4.0, 4.0, 4.0, 9.0, 9.0, 9.0]


@pytest.mark.parametrize("transition", ["linear", "mean"])
def test_interpolating_transitions_need_real_values(transition):
    graph_parts = [("a", Interface("Fake", {"y": Variable("y", 0, "Integer", "output", "discrete", None, 0)},
                                   {}, None, "", "fake", None), 1.0),
                   ("b", Interface("Fake", {"u": Variable("u", 0, "Integer", "input", "discrete", None, 0)},
                                   {}, None, "", "fake", None), 1.0)]
    with pytest.raises(UserError, match=f"rate transition '{transition}' needs Real values"):
        graph_of("fake", graph_parts, [("a.y", "b.u", transition)])


# ---- decimation ----------------------------------------------------------------------------------
def test_a_slow_component_steps_at_its_own_rate_and_sees_the_fast_ones_latest_value():
    master, slaves = run([("fast", 0.25, counter, True), ("slow", 1.0, counter, True)],
                         [("fast.y", "slow.u"), ("slow.y", "fast.u")], 3.0)
    assert master.steps_taken == {"fast": 12, "slow": 3}
    assert slaves["fast"].steps == 12 and slaves["slow"].steps == 3
    assert [t for t, _ in slaves["slow"].seen] == [0.0, 1.0, 2.0]
    # the order is fast, slow (fast is declared first in the cycle): the slow one sees the fast
    # one's count after its step at the same tick; the fast one holds the slow one's count from
    # the tick after the slow one stepped (before the first slow step: the initial 0)
    assert slaves["slow"].received("u") == [1.0, 5.0, 9.0]
    assert slaves["fast"].received("u") == [0.0] + [1.0] * 4 + [2.0] * 4 + [3.0] * 3
    assert master.graph.cycles == [["fast", "slow"]]


def test_the_base_step_is_the_greatest_common_divisor_and_idle_ticks_step_nothing():
    records = []

    class Steps(Observer):
        def after_tick(self, master, step: StepRecord) -> None:
            records.append((step.tick, step.stepped))

    master, _ = run([("a", 0.5, counter, False), ("b", 0.75, counter, False)], [], 3.0, observers=[Steps()])
    assert master.graph.base_ticks == 250_000_000
    assert master.steps_taken == {"a": 6, "b": 4}
    quarter = TICKS_PER_SECOND // 4
    assert records[:6] == [(quarter, frozenset({"a", "b"})), (2 * quarter, frozenset()), (3 * quarter, frozenset({"a"})),
                           (4 * quarter, frozenset({"b"})), (5 * quarter, frozenset({"a"})), (6 * quarter, frozenset())]
    assert len(records) == 12


# ---- algorithms ----------------------------------------------------------------------------------
def chain(algorithm):
    # declared out of data-flow order: the graph orders them source, stage1, stage2
    return run([("stage2", 0.25, passthrough, True), ("source", 0.25, counter, False),
                ("stage1", 0.25, passthrough, True)],
               [("source.y", "stage1.u"), ("stage1.y", "stage2.u")], 2.0, algorithm)


def test_gauss_seidel_passes_a_value_along_a_chain_in_the_same_step():
    master, slaves = chain("gauss-seidel")
    assert master.graph.order == ["source", "stage1", "stage2"] and master.graph.cycles == []
    assert slaves["stage2"].received("u") == [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0]


def test_jacobi_adds_one_step_of_latency_per_hop():
    _, slaves = chain("jacobi")
    assert slaves["stage1"].received("u") == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]
    assert slaves["stage2"].received("u") == [0.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0]


def test_a_cycle_is_broken_by_declaration_order_and_reported():
    # b is declared first: it steps first and sees a's output from the step before
    master, slaves = run([("b", 0.25, lambda n, t, u: {"y": u["u"] + 10.0}, True),
                          ("a", 0.25, lambda n, t, u: {"y": u["u"] + 1.0}, True)],
                         [("a.y", "b.u"), ("b.y", "a.u")], 1.0)
    assert master.graph.order == ["b", "a"]
    assert master.graph.cycles == [["b", "a"]]
    assert slaves["b"].received("u") == [0.0, 11.0, 22.0, 33.0]
    assert slaves["a"].received("u") == [10.0, 21.0, 32.0, 43.0]


def test_an_unknown_algorithm_is_refused():
    graph = graph_of("fake", [("a", interface(), 1.0)], [])
    with pytest.raises(ValueError, match="gauss-seidel"):
        Master(graph, {"a": FakeSlave(graph.nodes["a"].interface, counter)}, "newton")


# ---- lifecycle and plug-ins ----------------------------------------------------------------------
def test_every_slave_goes_through_the_whole_lifecycle_once():
    _, slaves = chain("gauss-seidel")
    for slave in slaves.values():
        for call in ("instantiate", "setup_experiment", "enter_initialization", "exit_initialization",
                     "terminate", "free"):
            assert slave.calls[call] == 1, call
        assert slave.calls["do_step"] == 8
        assert "set_values" not in slave.calls            # no parameters bound


def test_outputs_nobody_needs_between_ticks_are_not_read_after_every_step():
    # stage2's output feeds nothing: it is read at initialisation and at the end of the run only
    _, slaves = chain("gauss-seidel")
    assert slaves["stage2"].calls["read_outputs"] < slaves["stage2"].calls["do_step"]
    assert slaves["source"].calls["read_outputs"] >= slaves["source"].calls["do_step"]


def test_observers_get_a_record_of_each_tick_and_manipulators_adjust_what_a_consumer_sees():
    events = []

    class Watch(Observer):
        def outputs_needed(self):
            return {"stage2": ["y"]}

        def started(self, master, step: StepRecord) -> None:
            self.slot = master.output_slot("stage2", "y")
            events.append(("started", step.tick, step.time_s, step.stepped))

        def after_tick(self, master, step: StepRecord) -> None:
            master.fresh("stage2")
            buffer, index = self.slot
            events.append(("tick", step.tick, step.time_s, step.stepped, float(buffer.values[index])))

    class DoubleStage1(Manipulator):
        """Doubles stage1's output from t = 1 s on (only before_tick and the adjustments)."""

        def __init__(self):
            self.active = False

        def adjusted_components(self):
            return (), ("stage1",)

        def bound(self, master) -> None:
            self.slot = master.output_slot("stage1", "y")

        def before_tick(self, master, tick: int) -> None:
            self.active = tick >= TICKS_PER_SECOND

        def adjust_outputs(self, component: str) -> None:
            if self.active:
                buffer, index = self.slot
                buffer.values[index] *= 2

    watch = Watch()
    master, slaves = run([("source", 0.25, counter, False), ("stage1", 0.25, passthrough, True),
                          ("stage2", 0.25, passthrough, True)],
                         [("source.y", "stage1.u"), ("stage1.y", "stage2.u")], 2.0,
                         observers=[watch], manipulators=[DoubleStage1()])
    everything = frozenset({"source", "stage1", "stage2"})
    assert events[0] == ("started", 0, 0.0, frozenset())
    assert [e[1:4] for e in events[1:]] == [(k * TICKS_PER_SECOND // 4, k / 4, everything) for k in range(1, 9)]
    assert [e[4] for e in events[1:]] == [1.0, 2.0, 3.0, 4.0, 10.0, 12.0, 14.0, 16.0]
    assert slaves["stage2"].received("u") == [1.0, 2.0, 3.0, 4.0, 10.0, 12.0, 14.0, 16.0]
    with pytest.raises(AttributeError):
        StepRecord(0, 0.0, frozenset()).tick = 1                  # a record is not to be changed


def test_the_product_slaves_implement_every_method_of_the_slave_protocol():
    from orchestrator.fmu import FmuSlave, InProcessSlave
    from orchestrator.protocols import Slave

    methods = [name for name, value in vars(Slave).items() if callable(value) and not name.startswith("_")]
    assert "do_step" in methods and "read_outputs" in methods
    for cls in (FmuSlave, InProcessSlave, FakeSlave):
        assert [m for m in methods if not callable(getattr(cls, m, None))] == [], cls.__name__
