"""What the master plugs together: slaves, observers and manipulators, as libcosim separates
them (docs/architecture.md, "Master algorithm"), and the engine's small vocabulary.

* A **slave** is what the master steps: an FMU through fmpy, a facade in process
  (orchestrator/fmu.py) or an in-memory fake in a test. It owns one preallocated value buffer
  per FMI type for the inputs and the outputs the master binds.
* An **observer** looks at the outputs after each tick (results, captures, progress, the
  verdicts); a **summary observer** also contributes a section to summary.json.
* A **manipulator** changes values before each tick and, for the components it names, right
  after their inputs are gathered or their outputs read (timed events, faults).

:class:`Observer` and :class:`Manipulator` carry no-op defaults: a plug-in that subclasses one
inherits the hooks it does not need, and the master calls every hook without probing for it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import (TYPE_CHECKING, Any, Collection, FrozenSet, Literal, Mapping, Optional, Protocol,
                    Sequence, Tuple, get_args)

if TYPE_CHECKING:
    import numpy as np

#: rate transition of a connection (docs/interfaces.md, "SSP conventions")
Transition = Literal["hold", "linear", "mean"]
TRANSITIONS: Tuple[str, ...] = get_args(Transition)
#: the master algorithms by name (the CLI's --algorithm; orchestrator/algorithms.py)
AlgorithmName = Literal["gauss-seidel", "jacobi"]
ALGORITHMS: Tuple[str, ...] = get_args(AlgorithmName)
#: FMI 2.0 causality of a variable, spelled as in modelDescription.xml
Causality = Literal["parameter", "calculatedParameter", "input", "output", "local", "independent"]
FmiType = Literal["Real", "Integer", "Boolean", "String"]


@dataclass(frozen=True)
class UnitDef:
    """SSP/FMI unit: SI base exponents plus factor/offset to the SI value."""

    name: str
    exponents: Tuple[int, ...] = (0, 0, 0, 0, 0, 0, 0, 0)  # kg m s A K mol cd rad
    factor: float = 1.0
    offset: float = 0.0


class Buffer(Protocol):
    """Preallocated values of one FMI type, in the order of their value references."""

    type: str
    vr_array: "np.ndarray"
    values: Any               # a numpy array (a list of str for String)


class Slave(Protocol):
    """One component instance as the master drives it, in lifecycle order."""

    inputs: Mapping[str, Buffer]      # by FMI type, filled by the master before write_inputs
    outputs: Mapping[str, Buffer]     # by FMI type, filled by read_outputs

    def instantiate(self) -> None: ...

    def bind(self, inputs: Mapping[str, Sequence[int]], outputs: Mapping[str, Sequence[int]]) -> None:
        """Allocate the buffers for these value references (per FMI type), once."""
        ...

    def setup_experiment(self, start_time: float, stop_time: Optional[float]) -> None: ...

    def set_values(self, values: Mapping[str, object]) -> None:
        """Parameters (and start values of inputs) by variable name, before initialisation."""
        ...

    def enter_initialization(self) -> None: ...

    def exit_initialization(self) -> None: ...

    def write_inputs(self) -> None:
        """Hand the input buffers to the component."""
        ...

    def do_step(self, time_s: float, step_s: float) -> None: ...

    def read_outputs(self, types: Optional[Collection[str]] = None) -> None:
        """Fill the output buffers (all, or only those of the given FMI types)."""
        ...

    def terminate(self) -> None: ...

    def free(self) -> None: ...


@dataclass(frozen=True, slots=True)
class StepRecord:
    """What an observer is told after a tick (or, from :meth:`Observer.started`, at the start)."""

    tick: int                    # the master's clock now, integer nanoseconds
    time_s: float                # the same in seconds
    stepped: FrozenSet[str]      # components that stepped in the tick just done (none at the start)


class GraphView(Protocol):
    """What plug-ins see of the system graph (orchestrator/graph.py ``SystemGraph``)."""

    name: str
    nodes: Mapping[str, Any]       # component name → its node: interface, fmu_path, step_ticks, parameters
    edges: Sequence[Any]           # the connections, each source, source_var, target, target_var, …
    order: Sequence[str]           # the components in data-flow order
    base_ticks: int                # the master's base step, integer nanoseconds


class MasterView(Protocol):
    """What observers and manipulators may use of the master."""

    graph: GraphView
    slaves: Mapping[str, Slave]

    def fresh(self, component: str, type_name: Optional[str] = None) -> None:
        """Make a component's output buffers current before reading them."""
        ...

    def output_slot(self, component: str, variable: str) -> Tuple[Buffer, int]: ...


class Stages(Protocol):
    """The three stages every component goes through when it steps (the master provides
    them): gather its inputs, step it, conclude (read its outputs, update the links that
    track them). ``component`` is the master's record of one component."""

    def gather(self, component: Any, time_s: float) -> None: ...

    def step(self, component: Any, time_s: float) -> None: ...

    def conclude(self, component: Any, tick: int) -> None: ...


class Algorithm(Protocol):
    """How the components due at one tick are stepped: the order in which they go through
    the :class:`Stages` (libcosim's algorithm interface; Gauss-Seidel and Jacobi in
    orchestrator/algorithms.py). ``due`` is in data-flow order. Another algorithm (one that
    steps again after a rejected step, say) is another class with this method."""

    name: str

    def step_due(self, due: Sequence[Any], stages: Stages, time_s: float, tick: int) -> None: ...


class Observer(Protocol):
    """Looks at the outputs; never changes a value the components see."""

    def outputs_needed(self) -> Mapping[str, Sequence[str]]:
        """Outputs (component → variable names) the master must read for this observer."""
        return {}

    def started(self, master: MasterView, step: StepRecord) -> None:
        """Once, after initialisation: the state at the start time."""
        return None

    def after_tick(self, master: MasterView, step: StepRecord) -> None:
        """After every tick; called often, keep it cheap."""
        return None

    def close(self) -> None:
        """At the end of the run, also after a failure or Ctrl-C."""
        return None


class SummaryObserver(Observer, Protocol):
    """An observer that judges the run (RunOptions.summaries)."""

    def summary_section(self) -> Mapping[str, object]:
        """Its keys of summary.json; also called when the run failed before it started."""
        ...


class Manipulator(Protocol):
    """Changes values the components see: before each tick, and after the inputs of the
    components it names are gathered or their outputs read."""

    def outputs_needed(self) -> Mapping[str, Sequence[str]]:
        """Outputs it reads or adjusts: the master binds them into the output buffers."""
        return {}

    def inputs_needed(self) -> Mapping[str, Sequence[str]]:
        """Unconnected inputs it drives: the master binds them into the input buffers."""
        return {}

    def adjusted_components(self) -> Tuple[Collection[str], Collection[str]]:
        """(components whose gathered inputs it adjusts, components whose outputs it adjusts)."""
        return (), ()

    def bound(self, master: MasterView) -> None:
        """Once the slaves and their buffers exist (before the first tick)."""
        return None

    def before_tick(self, master: MasterView, tick: int) -> None:
        return None

    def adjust_inputs(self, component: str) -> None:
        """After the master gathered ``component``'s inputs, before they are written."""
        return None

    def adjust_outputs(self, component: str) -> None:
        """After the master read ``component``'s outputs, before any consumer gathers them."""
        return None
