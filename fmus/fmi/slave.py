"""Thin pythonfmu facade base shared by every railcosim FMU.

A facade declares its ports as a list of :class:`Port` (scalars and frame arrays) and maps
them onto a model core. This module owns everything FMI-specific that pythonfmu does not
do for us:

* one flat numpy value store per FMI type, so ``set_real``/``get_real`` are a single
  fancy-indexing operation instead of one Python setter call per variable (docs/architecture.md#build-pipeline-railcosim-build);
* the modelDescription additions pythonfmu omits (units, min/max, ModelStructure
  InitialUnknowns and output dependencies, DefaultExperiment), so ``fmpy validate`` is clean;
* error handling that never lets a Python exception escape ``do_step``: pythonfmu 0.7.0 turns
  an exception into fmi2Fatal and then releases its Python references twice on
  ``fmi2FreeInstance`` (see docs/architecture.md), so a failed step logs at error status and
  returns False, which pythonfmu reports as fmi2Discard;
* one range check of every parameter against its port's declared min/max (Reals also finite)
  before the core is made, phrased in the port's own name;
* one vectorised check of the numeric inputs before each step (finite, within a declared
  min/max): a bad input refuses the step before anything is computed, so the state is untouched;
* the FMI call order (setupExperiment → enterInitializationMode → exitInitializationMode → doStep
  from the last communication point → terminate) and value references: an unknown reference is
  refused without a Python exception, which pythonfmu 0.7.0 would turn into fmi2Fatal. Our
  FMUs' forwarding binary refuses such a call with fmi2Error before it gets here; this is the
  backstop without it (docs/interfaces.md, "Bad parameters, inputs and calls").

A port's start value is the core's settings default (``Port(..., start=settings.field)``), so
a parameter's default is declared once, in the core.

No physics or logic lives here or in a facade.
"""
from __future__ import annotations

import inspect
import math
import operator
import traceback
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple
from xml.etree.ElementTree import Element, SubElement

import numpy as np
from pythonfmu import Fmi2Slave
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Causality, Fmi2Initial, Fmi2Status, Fmi2Variability
from pythonfmu.variables import Boolean, Integer, Real, String

from fmus.errors import FmuInputError
from fmus.fmi.units import unit_definition
from fmus.reductions import all_true
from fmus.sizes import BuildConfig

_TYPE_CLASSES = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}
_NUMPY_DTYPES = {"Real": np.float64, "Integer": np.int64, "Boolean": np.bool_}


@dataclass(frozen=True)
class Port:
    """One FMU port: a scalar or a structured array ``name[i]`` / ``name[i,j]``."""

    name: str
    causality: str                      # input | output | parameter
    type: str = "Real"                  # Real | Integer | Boolean | String
    unit: Optional[str] = None
    start: Any = 0.0
    shape: Tuple[int, ...] = ()
    min: Optional[float] = None
    max: Optional[float] = None
    description: str = ""
    variability: Optional[str] = None   # default derived from causality and type
    frame: bool = False                 # last index runs over the samples of a frame
    # an input outside its declared range or not finite: "refuse" the step (FrameSlave),
    # "clamp" (finite values outside min/max are the unit's to clamp; non-finite refused) or
    # "unit" (the unit handles every value itself: the ATO's measurements fail safe)
    bad_input: str = "refuse"

    def __post_init__(self):
        if self.bad_input not in ("refuse", "clamp", "unit"):
            raise TypeError(f"port {self.name}: bad_input {self.bad_input!r} is not refuse, clamp or unit")

    @property
    def size(self) -> int:
        return int(np.prod(self.shape)) if self.shape else 1

    def element_names(self) -> List[str]:
        if not self.shape:
            return [self.name]
        index = np.indices(self.shape).reshape(len(self.shape), -1).T + 1
        return [f"{self.name}[{','.join(str(i) for i in idx)}]" for idx in index]

    def resolved_variability(self) -> str:
        if self.variability:
            return self.variability
        if self.causality == "parameter":
            return "fixed"
        return "continuous" if self.type == "Real" else "discrete"

    def range_error(self, element: str, value) -> Optional[str]:
        """Why ``value`` of this port's ``element`` is out of its declared range, or None."""
        if self.type not in ("Real", "Integer"):
            return None
        if not math.isfinite(value):
            return f"{element} = {value:g} is not a finite number"
        if self.min is not None and value < self.min:
            return f"{element} = {value:g} is below its minimum {self.min:g}"
        if self.max is not None and value > self.max:
            return f"{element} = {value:g} is above its maximum {self.max:g}"
        return None


def keyword_defaults(function) -> Dict[str, Any]:
    """The defaults of a core constructor's keyword parameters, for the start values of the
    ports that set them (a core without a settings record)."""
    return {name: p.default for name, p in inspect.signature(function).parameters.items()
            if p.default is not inspect.Parameter.empty}


def line_file_port() -> Port:
    """The line description every unit reads: one file shared by a system's components."""
    return Port("line_file", "parameter", "String", start="", description="line JSON; empty: the bundled default line")


def cab_system_port() -> Port:
    """The cab-signalling system a coder sends and a receiver decodes."""
    return Port("system", "parameter", "String", start="ALSN", description="ALSN | ALS-EN | FIRE_DQPSK")


def sample_rate_port(fs_hz: float, frame: int) -> Port:
    """The sample rate of a signal-chain unit; its communication step is one frame."""
    return Port("fs", "parameter", unit="Hz", start=fs_hz, min=1.0,
                description=f"sample rate; the communication step must be frame/fs ({frame} samples)")


class FmuCallError(RuntimeError):
    """An FMI call out of order or with unknown value references (the host's mistake)."""


#: FMI life cycle states of a FrameSlave (docs/interfaces.md, "Bad parameters, inputs and calls")
INSTANTIATED, INITIALISATION, STEPPING, TERMINATED, FAILED = (
    "instantiated", "initialisation", "stepping", "terminated", "failed")
#: communication points closer than this to the expected one continue it (host rounding)
_TIME_REL_TOL, _TIME_ABS_TOL = 1e-12, 1e-9
_FALLBACK = {"Real": math.nan, "Integer": 0, "Boolean": False, "String": ""}


@dataclass
class _InputCheck:
    """The inputs of one numeric type checked before each step: a view of them in the value
    store (their slots when not contiguous); whether they must be finite (Reals), with a scratch
    buffer; those with a declared range (a few: (position, min, max) tested in plain Python,
    cheaper than numpy for a handful; many: positions and bound arrays); (port, element) of each
    value, for the message."""

    view: Optional[np.ndarray]
    index: Any
    finite: bool
    scratch: np.ndarray
    few: Optional[List[Tuple[int, float, float]]]
    bounded: Optional[np.ndarray]
    low: np.ndarray
    high: np.ndarray
    elements: List[Tuple[Port, str]]


#: at most this many range-checked inputs of a type are tested in plain Python
_FEW_BOUNDED = 8


def _slot_index(slots: List[int]):
    """Store slots as an index: a slice when they are consecutive (numpy then copies a block,
    and a slice of a store is a view of it), else an index array."""
    if slots == list(range(slots[0], slots[0] + len(slots))):
        return slice(slots[0], slots[0] + len(slots))
    return np.array(slots, dtype=np.int64)


@dataclass
class _Store:
    """Flat value store of one FMI type plus the value-reference → slot table."""

    values: Any
    slot_of_vr: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


class FrameSlave(Fmi2Slave):
    """Base of every railcosim facade.

    Subclasses implement :meth:`declare_ports` (a classmethod of the build configuration),
    :meth:`create_core` (called once parameters are final, at exit of initialisation) and
    :meth:`step_core` (map ``self.io`` inputs → core → outputs for one communication step).
    """

    #: Replaced in the generated slave script by the build pipeline.
    build_config: Dict[str, int] = {}
    #: Communication step the FMU requires, in seconds; None when any step is allowed.
    required_step_s: Optional[float] = None
    #: Whether doStep takes a communication step of any length (the modelDescription's
    #: canHandleVariableCommunicationStepSize); a signal FMU takes only frame/fs.
    variable_step: bool = True
    description = "railcosim FMU"
    author = "railcosim"
    version = "0.1.0"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.build = BuildConfig(**self.build_config)
        self.ports: List[Port] = list(self.declare_ports(self.build))
        self.io: Dict[str, np.ndarray] = {}
        self._slot_cache: Dict[tuple, Tuple[list, np.ndarray]] = {}
        self._allocate(self.ports)
        self._input_checks = self._make_input_checks(self.ports)
        self.core = None
        self.default_experiment = self.make_default_experiment()
        self.state = INSTANTIATED
        self._next_time_s: Optional[float] = None      # where the next doStep must start
        self._call_error: Optional[str] = None          # a refused get/set, reported at the next step
        self._output_plans: Dict[tuple, tuple] = {}      # write_outputs: the ports of each field list

    # ---- to be provided by a facade -------------------------------------------------------
    @classmethod
    def declare_ports(cls, build: BuildConfig) -> Sequence[Port]:
        raise TypeError(f"{cls.__name__} must declare its ports")

    def create_core(self):
        raise TypeError(f"{type(self).__name__} must create its core")

    def step_core(self, current_time: float, step_size: float) -> None:
        raise TypeError(f"{type(self).__name__} must step its core")

    def make_default_experiment(self) -> Optional[DefaultExperiment]:
        return None

    def step_refusal(self, current_time: float, step_size: float) -> Optional[str]:
        """Why the core cannot take this step (checked before anything changes), or None."""
        return None

    def frame_experiment(self, fs_hz: float, stop_time_s: float = 10.0) -> DefaultExperiment:
        """DefaultExperiment of a signal FMU: its step is one frame at the default sample rate."""
        return DefaultExperiment(start_time=0.0, stop_time=stop_time_s, step_size=self.build.frame / fs_hz)

    # ---- helpers for facades -----------------------------------------------------------------
    def param(self, name: str):
        """Current value of a scalar parameter (Python scalar)."""
        value = self.io[name]
        return value if isinstance(value, str) else value.item()

    def scalar_parameters(self) -> Dict[str, Any]:
        """Every scalar parameter's current value by port name (Python scalars)."""
        return {p.name: self.param(p.name) for p in self.ports if p.causality == "parameter" and not p.shape}

    def check_parameter_ranges(self) -> None:
        """Every numeric parameter element against its port's min/max, Reals also finite."""
        for port in self.ports:
            if port.causality != "parameter" or port.type not in ("Real", "Integer"):
                continue
            values = self.io[port.name].reshape(-1).tolist()
            for element, value in zip(port.element_names(), values):
                problem = port.range_error(element, value)
                if problem is not None:
                    raise FmuInputError(problem)

    def write_outputs(self, out, fields) -> None:
        """Copy a core's output record to the ports: ``fields`` is ((port, attribute), ...).
        The scalar ports of each type are written together, one assignment of all their values
        into the type's store (a receiver has a dozen, read every frame); array ports are
        copied one by one."""
        plan = self._output_plans.get(fields)
        if plan is None:
            plan = self._output_plans[fields] = self._output_plan(fields)
        arrays, scalars = plan
        for port, attribute in arrays:
            port[...] = getattr(out, attribute)
        for values, slots, read in scalars:
            values[slots] = read(out)

    def _output_plan(self, fields):
        """(array ports and their attributes; per type of scalar port: the type's store, the
        ports' slots in it, a getter of their attributes' values in that order)."""
        arrays = tuple((self.io[port], attribute) for port, attribute in fields if self.io[port].ndim)
        by_type: Dict[str, List[Tuple[int, str]]] = {}
        for port, attribute in fields:
            if not self.io[port].ndim:
                type_name, slot = self._port_slots[port]
                by_type.setdefault(type_name, []).append((slot, attribute))
        scalars = []
        for type_name, entries in by_type.items():
            slots = [slot for slot, _ in entries]
            read = operator.attrgetter(*(attribute for _, attribute in entries))
            scalars.append((self._stores[type_name].values, _slot_index(slots) if len(slots) > 1 else slots[0], read))
        return arrays, tuple(scalars)

    def resource_path(self, path: str) -> str:
        """A data file named by a parameter: absolute, or relative to the working folder, else
        to this FMU's resources folder (where the bundled defaults live). A default inside the
        imported ``fmus`` package (whose module-level paths point where this interpreter first
        imported it: maybe another FMU's extraction, removed since) is this FMU's own copy."""
        import os

        package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        if self.resources and os.path.isabs(path) and os.path.commonpath([path, package]) == package:
            own = os.path.join(self.resources, "fmus", os.path.relpath(path, package))
            if os.path.exists(own):
                return own
        if os.path.isabs(path) or os.path.exists(path) or not self.resources:
            return path
        return os.path.join(self.resources, path)

    # ---- storage ---------------------------------------------------------------------------
    def _allocate(self, ports: Sequence[Port]) -> None:
        counts = {t: sum(p.size for p in ports if p.type == t) for t in _TYPE_CLASSES}
        self._stores: Dict[str, _Store] = {
            t: _Store(np.zeros(n, dtype=_NUMPY_DTYPES[t]) if t in _NUMPY_DTYPES else [""] * n)
            for t, n in counts.items()
        }
        total_vrs = sum(p.size for p in ports)
        for store in self._stores.values():
            store.slot_of_vr = np.full(total_vrs, -1, dtype=np.int64)
        next_slot = {t: 0 for t in _TYPE_CLASSES}
        self._string_ports: Dict[str, Tuple[int, int]] = {}    # String port → (first slot, elements; 0: scalar)
        self._port_slots: Dict[str, Tuple[str, int]] = {}      # numeric port → (type, its first slot)
        for port in ports:
            store = self._stores[port.type]
            first = next_slot[port.type]
            if port.type == "String":
                store.values[first:first + port.size] = [str(port.start)] * port.size
                self._string_ports[port.name] = (first, port.size if port.shape else 0)
                self.io[port.name] = self._string_value(port.name)
            else:
                self._port_slots[port.name] = (port.type, first)
                view = store.values[first:first + port.size]
                view[:] = port.start
                self.io[port.name] = view.reshape(port.shape) if port.shape else view.reshape(())
            for k, element in enumerate(port.element_names()):
                slot = first + k
                var = self._make_variable(port, element, slot)
                self.register_variable(var, nested=False)
                store.slot_of_vr[var.value_reference] = slot
            next_slot[port.type] += port.size

    def _make_input_checks(self, ports: Sequence[Port]) -> List[Tuple[str, _InputCheck]]:
        """Per numeric type, the input slots checked before each step and their bounds."""
        checks = []
        for type_name in ("Real", "Integer"):
            slots, bounded, low, high, elements = [], [], [], [], []
            first = 0
            for port in ports:
                if port.type != type_name:
                    continue
                if port.causality == "input" and port.bad_input != "unit":
                    if port.bad_input != "clamp" and (port.min is not None or port.max is not None):
                        bounded.extend(range(len(slots), len(slots) + port.size))
                        low.extend([-math.inf if port.min is None else port.min] * port.size)
                        high.extend([math.inf if port.max is None else port.max] * port.size)
                    slots.extend(range(first, first + port.size))
                    elements.extend((port, element) for element in port.element_names())
                first += port.size
            if not slots or (type_name == "Integer" and not bounded):
                continue                  # an integer without a declared range cannot be wrong
            index = _slot_index(slots)
            # the stores are allocated once and written in place, so a slice stays their view
            view = self._stores[type_name].values[index] if isinstance(index, slice) else None
            few = list(zip(bounded, low, high)) if 0 < len(bounded) <= _FEW_BOUNDED else None
            checks.append((type_name, _InputCheck(
                view, index, type_name == "Real", np.zeros(len(slots), dtype=bool), few,
                np.array(bounded, dtype=np.int64) if bounded and few is None else None,
                np.array(low, dtype=np.float64), np.array(high, dtype=np.float64), elements)))
        return checks

    def input_error(self) -> Optional[str]:
        """The first input that is not finite or outside its declared range, or None: per numeric
        type one vectorised finiteness test over all its inputs (no warnings, unlike a sum or dot
        product of ±inf) and one test of the few with a declared range."""
        for type_name, check in self._input_checks:
            values = check.view if check.view is not None else self._stores[type_name].values[check.index]
            if check.finite:
                finite = np.isfinite(values, out=check.scratch)
                if not all_true(finite):
                    return self._input_message(check, int(np.argmin(finite)), values)
            if check.few is not None:
                item = values.item
                for k, low, high in check.few:
                    if not low <= item(k) <= high:
                        return self._input_message(check, k, values)
            elif check.bounded is not None:
                inside = values[check.bounded]
                good = (inside >= check.low) & (inside <= check.high)
                if not all_true(good):
                    return self._input_message(check, int(check.bounded[int(np.argmin(good))]), values)
        return None

    @staticmethod
    def _input_message(check: _InputCheck, k: int, values: np.ndarray) -> str:
        port, element = check.elements[k]
        return "input " + port.range_error(element, values[k].item())

    def _make_variable(self, port: Port, element: str, slot: int):
        causality = Fmi2Causality[port.causality]
        variability = Fmi2Variability[port.resolved_variability()]
        initial = Fmi2Initial.exact if port.causality == "parameter" else None
        values = self._stores[port.type].values
        cls = _TYPE_CLASSES[port.type]
        return cls(element, causality=causality, variability=variability, initial=initial,
                   description=port.description or None,
                   getter=lambda: values[slot], setter=None)

    def _slots(self, type_name: str, vrs) -> np.ndarray:
        # an FMI host (pythonfmu's C layer passes lists) sends the same value-reference lists
        # every step: resolve each list once
        if not isinstance(vrs, list) or not vrs:
            return self._resolve_slots(type_name, vrs)
        key = (type_name, len(vrs), vrs[0], vrs[-1])
        cached = self._slot_cache.get(key)
        if cached is not None and cached[0] == vrs:
            return cached[1]
        slots = self._resolve_slots(type_name, vrs)
        self._slot_cache[key] = (list(vrs), slots)
        return slots

    def _resolve_slots(self, type_name: str, vrs) -> np.ndarray:
        store = self._stores[type_name]
        vr_array = np.asarray(vrs, dtype=np.int64)
        if vr_array.size and (vr_array.max() >= store.slot_of_vr.size or vr_array.min() < 0):
            unknown = [int(vr) for vr in vr_array if not 0 <= vr < store.slot_of_vr.size]
            raise FmuCallError(f"unknown value reference(s) {unknown[:10]}")
        slots = store.slot_of_vr[vr_array]
        if (slots < 0).any():
            raise FmuCallError(f"value reference(s) {vr_array[slots < 0].tolist()[:10]} are not {type_name}")
        return slots

    def _refuse_call(self, call: str, error: FmuCallError) -> None:
        """A get/set with a bad value reference: refused and logged. pythonfmu 0.7.0 turns an
        exception here into fmi2Fatal and then uses freed objects on the next call, so nothing is
        raised; the next doStep (or exitInitializationMode) fails with this message instead."""
        message = f"{call} refused: {error}; nothing was {'written' if call.startswith('fmi2Set') else 'read'}"
        self.log(f"{type(self).__name__}: {message}", Fmi2Status.error)
        if self._call_error is None:
            self._call_error = message

    def value_view(self, type_name: str, vrs) -> Tuple[np.ndarray, np.ndarray]:
        """(store, slots): the flat value store of a numeric type and the slots of ``vrs`` in it,
        for a host in this interpreter that moves values without FMI (the in-process runner)."""
        return self._stores[type_name].values, self._slots(type_name, vrs)

    def set_string(self, vrs, values):
        try:
            slots = self._slots("String", list(vrs))
        except FmuCallError as error:
            return self._refuse_call("fmi2SetString", error)
        for slot, value in zip(slots, values):
            self._stores["String"].values[slot] = str(value)
        for name in self._string_ports:
            self.io[name] = self._string_value(name)

    def _string_value(self, name: str):
        """A String port's value: a str, or a tuple of them for an array port."""
        first, size = self._string_ports[name]
        strings = self._stores["String"].values
        return strings[first] if size == 0 else tuple(strings[first:first + size])

    def get_string(self, vrs):
        strings = self._stores["String"].values
        try:
            return [strings[s] for s in self._slots("String", vrs)]
        except FmuCallError as error:
            self._refuse_call("fmi2GetString", error)
            return [""] * len(vrs)

    # numeric get/set: one fancy-indexing operation; a bad value reference costs nothing until
    # it happens (the C layer needs a list of len(vrs) back from a get, whatever happens)
    def _set(self, type_name: str, vrs, values) -> None:
        try:
            self._stores[type_name].values[self._slots(type_name, vrs)] = values
        except FmuCallError as error:
            self._refuse_call(f"fmi2Set{type_name}", error)

    def _get(self, type_name: str, vrs) -> list:
        try:
            return self._stores[type_name].values[self._slots(type_name, vrs)].tolist()
        except FmuCallError as error:
            self._refuse_call(f"fmi2Get{type_name}", error)
            return [_FALLBACK[type_name]] * len(vrs)

    def set_real(self, vrs, values):
        self._set("Real", vrs, values)

    def get_real(self, vrs):
        return self._get("Real", vrs)

    def set_integer(self, vrs, values):
        self._set("Integer", vrs, values)

    def get_integer(self, vrs):
        return self._get("Integer", vrs)

    def set_boolean(self, vrs, values):
        self._set("Boolean", vrs, values)

    def get_boolean(self, vrs):
        return self._get("Boolean", vrs)

    def value_reference_table(self) -> Dict[str, Dict[str, List[int]]]:
        """Per FMI type, the value references by causality. The forwarding binary's table
        (written at build from the modelDescription) is this table: every reference per type, and
        the parameters and inputs as the settable ones (tests/test_forwarder_build.py)."""
        table: Dict[str, Dict[str, List[int]]] = {t: {} for t in _TYPE_CLASSES}
        port_of = {element: port for port in self.ports for element in port.element_names()}
        for vr, variable in self.vars.items():
            port = port_of[variable.name]
            table[port.type].setdefault(port.causality, []).append(int(vr))
        return table

    # ---- FMI lifecycle -----------------------------------------------------------------------
    # pythonfmu 0.7.0 reports an exception from any call as fmi2Fatal (and then uses freed Python
    # objects: docs/architecture.md), and a False from do_step as fmi2Discard; it has no way to
    # fmi2Error. So doStep refuses with False and a logged message; an initialisation call out of
    # order raises (fmi2Fatal, like a bad parameter: the instance never starts).
    def _refuse_init(self, call: str, allowed: str) -> None:
        message = f"{type(self).__name__}: {call} refused in state {self.state!r}; allowed only {allowed}"
        self.log(message, Fmi2Status.error)
        raise FmuCallError(message)

    def setup_experiment(self, start_time: float, stop_time: Optional[float], tolerance: Optional[float]):
        if self.state != INSTANTIATED:
            self._refuse_init("fmi2SetupExperiment", "after fmi2Instantiate")
        if not math.isfinite(start_time):
            self.log(f"{type(self).__name__}: fmi2SetupExperiment refused: start time {start_time:g} is not finite",
                     Fmi2Status.error)
            raise FmuCallError(f"start time {start_time:g} is not finite")
        self._next_time_s = float(start_time)

    def enter_initialization_mode(self):
        if self.state != INSTANTIATED:
            self._refuse_init("fmi2EnterInitializationMode", "once, after fmi2Instantiate / fmi2SetupExperiment")
        self.state = INITIALISATION

    def exit_initialization_mode(self):
        # Parameters are final here. A bad parameter or data file raises: pythonfmu reports
        # fmi2Fatal with our message, which is what the host (and our CLI) shows the user.
        if self.state != INITIALISATION:
            self._refuse_init("fmi2ExitInitializationMode", "after fmi2EnterInitializationMode")
        try:
            if self._call_error is not None:
                message, self._call_error = self._call_error, None
                self.log(f"{type(self).__name__}: fmi2ExitInitializationMode refused after an earlier call: {message}",
                         Fmi2Status.error)
                raise FmuCallError(message)
            self.check_parameter_ranges()
            problem = self.input_error()        # the inputs a core reads when it is made
            if problem is not None:
                raise FmuInputError(problem)
            self.core = self.create_core()
            self.publish_initial_outputs()
        except Exception as error:
            self.state = FAILED
            self.core = None
            if isinstance(error, FmuInputError):
                self.log(f"{type(self).__name__}: {error}", Fmi2Status.error)
            elif not isinstance(error, FmuCallError):       # (already logged)
                detail = traceback.format_exception_only(type(error), error)[-1].strip()
                self.log(f"{type(self).__name__}: initialisation failed: {detail}", Fmi2Status.error)
            raise
        self.state = STEPPING

    def publish_initial_outputs(self) -> None:
        """Write the outputs that hold before the first step (default: leave starts)."""

    def terminate(self):
        if self.state == TERMINATED:
            self.log(f"{type(self).__name__}: fmi2Terminate called twice", Fmi2Status.warning)
        self.state = TERMINATED

    def _step_refusal(self, current_time: float, step_size: float) -> Optional[str]:
        """Why this doStep must not run (nothing has changed yet), or None."""
        if self.state != STEPPING:
            why = {INSTANTIATED: "before fmi2ExitInitializationMode", INITIALISATION: "before fmi2ExitInitializationMode",
                   TERMINATED: "after fmi2Terminate",
                   FAILED: "after a failed step or initialisation (the state is not valid)"}[self.state]
            return f"doStep {why}"
        if self._call_error is not None:
            message, self._call_error = self._call_error, None
            return f"doStep refused once after an earlier call: {message}"
        expected, required = self._next_time_s, self.required_step_s
        # the usual step of a signal FMU: its exact frame from the last point (to the tolerance;
        # a NaN or an infinite time fails the test): nothing more to test
        if expected is None or step_size != required or not abs(current_time - expected) <= _TIME_ABS_TOL:
            problem = self._time_error(current_time, step_size, expected, required)
            if problem is not None:
                return problem
        problem = self.input_error()
        if problem is not None:
            return f"step at t={current_time:.6g} s refused, state unchanged: {problem}"
        return self.step_refusal(current_time, step_size)

    @staticmethod
    def _time_error(current_time: float, step_size: float, expected: Optional[float],
                    required: Optional[float]) -> Optional[str]:
        """What is wrong with a doStep's time or step, or None."""
        if not (math.isfinite(current_time) and math.isfinite(step_size) and step_size > 0.0):
            return f"doStep(t={current_time:g} s, h={step_size:g} s): time and step must be finite, the step positive"
        if expected is not None and not abs(current_time - expected) <= _TIME_ABS_TOL \
                and not math.isclose(current_time, expected, rel_tol=_TIME_REL_TOL, abs_tol=_TIME_ABS_TOL):
            return (f"doStep from t={current_time:.9g} s refused: the last communication point is "
                    f"{expected:.9g} s (time must continue from it)")
        if required is not None and step_size != required \
                and not math.isclose(step_size, required, rel_tol=1e-9, abs_tol=1e-12):
            return (f"communication step {step_size:.9g} s refused; "
                    f"this build needs exactly {required:.9g} s (frame/fs)")
        return None

    def do_step(self, current_time: float, step_size: float) -> bool:
        refusal = self._step_refusal(current_time, step_size)
        if refusal is not None:
            self.log(f"{type(self).__name__}: {refusal}", Fmi2Status.error)
            return False
        try:
            self.step_core(current_time, step_size)
        except FmuInputError as error:
            # a core refuses an input it cannot take before it changes anything (the digital
            # coder's unknown wrong_command): the step may be retried with other inputs
            self.log(f"{type(self).__name__}: step at t={current_time:.6g} s refused: {error}", Fmi2Status.error)
            return False
        except Exception as error:  # never let an exception reach pythonfmu's C layer
            detail = traceback.format_exception_only(type(error), error)[-1].strip()
            self.log(f"{type(self).__name__}: step at t={current_time:.6g} s failed: {detail}",
                     Fmi2Status.error)
            self.state = FAILED       # the core may be half-way through the step
            return False
        self._next_time_s = current_time + step_size
        return True

    # ---- model description -------------------------------------------------------------------
    def to_xml(self, model_options: Dict[str, str] = dict()) -> Element:
        root = super().to_xml(model_options)
        root.find("CoSimulation").set("canHandleVariableCommunicationStepSize",
                                      "true" if self.variable_step else "false")
        port_of_element = {}
        for port in self.ports:
            for element in port.element_names():
                port_of_element[element] = port
        units = []
        variables = root.find("ModelVariables")
        output_indices = []
        for index, sv in enumerate(variables.findall("ScalarVariable"), start=1):
            port = port_of_element[sv.get("name")]
            type_node = sv[0]
            if port.unit and port.type == "Real":
                type_node.set("unit", port.unit)
                if port.unit not in units:
                    units.append(port.unit)
            for bound in ("min", "max"):
                value = getattr(port, bound)
                if value is not None and port.type in ("Real", "Integer"):
                    type_node.set(bound, f"{value:.16g}" if port.type == "Real" else str(int(value)))
            if port.causality == "output":
                output_indices.append(index)
        if units:
            position = list(root).index(root.find("CoSimulation")) + 1
            unit_defs = Element("UnitDefinitions")
            for unit in units:
                unit_defs.append(unit_definition(unit))
            root.insert(position, unit_defs)
        frame_ports = [p.name for p in self.ports if p.frame]
        if frame_ports:
            vendor = Element("VendorAnnotations")
            tool = SubElement(vendor, "Tool", name="railcosim")
            SubElement(tool, "FramePorts").text = " ".join(frame_ports)
            root.insert(list(root).index(variables), vendor)
        structure = root.find("ModelStructure")
        for child in list(structure):
            structure.remove(child)
        if output_indices:
            outputs = SubElement(structure, "Outputs")
            initial = SubElement(structure, "InitialUnknowns")
            for index in output_indices:
                # Outputs are computed in doStep: no direct feedthrough from inputs.
                SubElement(outputs, "Unknown", index=str(index), dependencies="")
                SubElement(initial, "Unknown", index=str(index))
        return root
