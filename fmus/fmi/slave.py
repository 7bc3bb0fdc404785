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
  before the core is made, phrased in the port's own name.

A port's start value is the core's settings default (``Port(..., start=settings.field)``), so
a parameter's default is declared once, in the core.

No physics or logic lives here or in a facade.
"""
from __future__ import annotations

import inspect
import math
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
        self.core = None
        self.default_experiment = self.make_default_experiment()

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
        """Copy a core's output record to the ports: ``fields`` is ((port, attribute), ...)."""
        io = self.io
        for port, attribute in fields:
            io[port][...] = getattr(out, attribute)

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
        self._string_ports: Dict[str, int] = {}
        for port in ports:
            store = self._stores[port.type]
            first = next_slot[port.type]
            if port.type == "String":
                store.values[first] = str(port.start)
                self._string_ports[port.name] = first
                self.io[port.name] = store.values[first]
            else:
                view = store.values[first:first + port.size]
                view[:] = port.start
                self.io[port.name] = view.reshape(port.shape) if port.shape else view.reshape(())
            for k, element in enumerate(port.element_names()):
                slot = first + k
                var = self._make_variable(port, element, slot)
                self.register_variable(var, nested=False)
                store.slot_of_vr[var.value_reference] = slot
            next_slot[port.type] += port.size

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
            raise TypeError(f"unknown value reference in {list(vrs)}")
        slots = store.slot_of_vr[vr_array]
        if (slots < 0).any():
            raise TypeError(f"value reference(s) {vr_array[slots < 0].tolist()} are not {type_name}")
        return slots

    def value_view(self, type_name: str, vrs) -> Tuple[np.ndarray, np.ndarray]:
        """(store, slots): the flat value store of a numeric type and the slots of ``vrs`` in it,
        for a host in this interpreter that moves values without FMI (the in-process runner)."""
        return self._stores[type_name].values, self._slots(type_name, vrs)

    def set_string(self, vrs, values):
        for vr, value in zip(vrs, values):
            slot = self._slots("String", [vr])[0]
            self._stores["String"].values[slot] = str(value)
        for name, slot in self._string_ports.items():
            self.io[name] = self._stores["String"].values[slot]

    def get_string(self, vrs):
        strings = self._stores["String"].values
        return [strings[s] for s in self._slots("String", vrs)]

    def set_real(self, vrs, values):
        self._stores["Real"].values[self._slots("Real", vrs)] = values

    def get_real(self, vrs):
        return self._stores["Real"].values[self._slots("Real", vrs)].tolist()

    def set_integer(self, vrs, values):
        self._stores["Integer"].values[self._slots("Integer", vrs)] = values

    def get_integer(self, vrs):
        return self._stores["Integer"].values[self._slots("Integer", vrs)].tolist()

    def set_boolean(self, vrs, values):
        self._stores["Boolean"].values[self._slots("Boolean", vrs)] = values

    def get_boolean(self, vrs):
        return self._stores["Boolean"].values[self._slots("Boolean", vrs)].tolist()

    # ---- FMI lifecycle -----------------------------------------------------------------------
    def exit_initialization_mode(self):
        # Parameters are final here. A bad parameter or data file raises: pythonfmu reports
        # fmi2Fatal with our message, which is what the host (and our CLI) shows the user.
        try:
            self.check_parameter_ranges()
            self.core = self.create_core()
        except FmuInputError as error:
            self.log(f"{type(self).__name__}: {error}", Fmi2Status.error)
            raise
        self.publish_initial_outputs()

    def publish_initial_outputs(self) -> None:
        """Write the outputs that hold before the first step (default: leave starts)."""

    def do_step(self, current_time: float, step_size: float) -> bool:
        required = self.required_step_s
        if required is not None and not math.isclose(step_size, required, rel_tol=1e-9, abs_tol=1e-12):
            self.log(f"{type(self).__name__}: communication step {step_size:.9g} s refused; "
                     f"this build needs exactly {required:.9g} s (frame/fs)", Fmi2Status.error)
            return False
        try:
            self.step_core(current_time, step_size)
        except Exception as error:  # never let an exception reach pythonfmu's C layer
            detail = traceback.format_exception_only(type(error), error)[-1].strip()
            self.log(f"{type(self).__name__}: step at t={current_time:.6g} s failed: {detail}",
                     Fmi2Status.error)
            return False
        return True

    # ---- model description -------------------------------------------------------------------
    def to_xml(self, model_options: Dict[str, str] = dict()) -> Element:
        root = super().to_xml(model_options)
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
