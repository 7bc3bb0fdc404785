"""The pythonfmu slave every facade derives from: the FMI side of a unit (docs/architecture.md).

A facade declares its ports (fmus/fmi/ports.py) and maps them onto a model core. This module
owns the FMI life cycle that pythonfmu does not police for us; the values live in a
:class:`~fmus.fmi.value_store.ValueStore`, and fmus/fmi/model_description.py adds to the
modelDescription what pythonfmu omits.

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

:class:`FacadeSlave` is the base of every facade; :class:`FrameFacadeSlave` of the signal-chain
units, whose every step is one frame (frame/fs). A port's start value is the core's settings
default (``Port(..., start=settings.field)``), so a parameter's default is declared once, in the
core. No physics or logic lives here or in a facade.
"""
from __future__ import annotations

import math
import os
import traceback
from typing import Any, Dict, List, Optional, Sequence
from xml.etree.ElementTree import Element

from pythonfmu import Fmi2Slave
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Causality, Fmi2Initial, Fmi2Status, Fmi2Variability
from pythonfmu.variables import Boolean, Integer, Real, String

from fmus.errors import FmuCallError, FmuInputError
from fmus.fmi import model_description
from fmus.fmi.ports import (Port, cab_system_port, keyword_defaults, line_file_port,  # noqa: F401  (the facades' imports)
                            output_fields, sample_rate_port)
from fmus.fmi.value_store import FALLBACK, FMI_TYPES, InputChecks, ValueStore
from fmus.sizes import BuildConfig

_TYPE_CLASSES = {"Real": Real, "Integer": Integer, "Boolean": Boolean, "String": String}

#: FMI life cycle states of a facade (docs/interfaces.md, "Bad parameters, inputs and calls")
INSTANTIATED, INITIALISATION, STEPPING, TERMINATED, FAILED = (
    "instantiated", "initialisation", "stepping", "terminated", "failed")
#: communication points closer than this to the expected one continue it (host rounding)
_TIME_REL_TOL, _TIME_ABS_TOL = 1e-12, 1e-9


def resources_folder(resources: Optional[str]) -> Optional[str]:
    """The FMU's resources folder from pythonfmu's ``resources`` argument: a path (pythonfmu 0.7.0
    strips "file://" and decodes nothing; our forwarding binary hands it the decoded path, and the
    orchestrator's in-process FMUs pass a path), or a ``file:`` URI, decoded per RFC 3986
    (``file:///home/%D0%B2%20x/resources`` is ``/home/в x/resources``). As in the forwarder, a
    '#' or '?' is part of the path (hosts that do not encode) and a '%' without two hex digits
    stays as it is."""
    if not resources or resources[:5].lower() != "file:":
        return resources
    from urllib.parse import unquote_to_bytes

    path = resources[5:]
    if path[:12].lower() == "//localhost/":
        path = path[11:]
    elif path.startswith("///"):
        path = path[2:]
    elif path.startswith("//"):
        raise FmuInputError(f"resource location {resources!r} names another host")
    return os.fsdecode(unquote_to_bytes(path))


class FacadeSlave(Fmi2Slave):
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
    #: canHandleVariableCommunicationStepSize).
    variable_step: bool = True
    description = "railcosim FMU"
    author = "railcosim"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.resources = resources_folder(self.resources)
        self.build = BuildConfig(**self.build_config)
        self.ports: List[Port] = list(self.declare_ports(self.build))
        self.output_fields = output_fields(self.ports)
        self.store = ValueStore(self.ports, self._register)
        self.io: Dict[str, Any] = self.store.io
        self.input_checks = InputChecks(self.ports, self.store)
        self.core = None
        self.default_experiment = self.make_default_experiment()
        self.state = INSTANTIATED
        self._next_time_s: Optional[float] = None      # where the next doStep must start
        self._call_error: Optional[str] = None          # a refused get/set, reported at the next step

    def _register(self, port: Port, element: str, getter) -> int:
        """One element of a port as a pythonfmu variable (its value read from the store)."""
        variable = _TYPE_CLASSES[port.type](
            element, causality=Fmi2Causality[port.causality],
            variability=Fmi2Variability[port.resolved_variability()],
            initial=Fmi2Initial.exact if port.causality == "parameter" else None,
            description=port.description or None, getter=getter, setter=None)
        self.register_variable(variable, nested=False)
        return variable.value_reference

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

    def unit_handled_inputs(self) -> Optional[Sequence[str]]:
        """The ``bad_input="unit"`` inputs the unit reads and judges itself with the parameters
        now set (asked at exitInitializationMode), or None for all of them. An input the unit
        ignores in this configuration (the ATO's aspect with ``cab_signal = off``) is checked as
        any other: an impossible value is refused, not accepted unread."""
        return None

    def step_refusal(self, current_time: float, step_size: float) -> Optional[str]:
        """Why the core cannot take this step (checked before anything changes), or None."""
        return None

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

    def write_outputs(self, out) -> None:
        """A core's output record to the output ports, each from its declared core field
        (ValueStore.write_outputs)."""
        self.store.write_outputs(out, self.output_fields)

    def resource_path(self, path: str) -> str:
        """A data file named by a parameter: absolute, or relative to the working folder, else
        to this FMU's resources folder (where the bundled defaults live). A default inside the
        imported ``fmus`` package (whose module-level paths point where this interpreter first
        imported it: maybe another FMU's extraction, removed since) is this FMU's own copy."""
        package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        if self.resources and os.path.isabs(path) and os.path.commonpath([path, package]) == package:
            own = os.path.join(self.resources, "fmus", os.path.relpath(path, package))
            if os.path.exists(own):
                return own
        if os.path.isabs(path) or os.path.exists(path) or not self.resources:
            return path
        return os.path.join(self.resources, path)

    # ---- values through FMI: a bad value reference is refused, logged, never raised ------------
    def _refuse_call(self, call: str, error: FmuCallError) -> None:
        """A get/set with a bad value reference: refused and logged. pythonfmu 0.7.0 turns an
        exception here into fmi2Fatal and then uses freed objects on the next call, so nothing is
        raised; the next doStep (or exitInitializationMode) fails with this message instead."""
        message = f"{call} refused: {error}; nothing was {'written' if call.startswith('fmi2Set') else 'read'}"
        self.log(f"{type(self).__name__}: {message}", Fmi2Status.error)
        if self._call_error is None:
            self._call_error = message

    def value_view(self, type_name: str, vrs):
        """(store, slots): the flat value store of a numeric type and the slots of ``vrs`` in it,
        for a host in this interpreter that moves values without FMI (the in-process runner)."""
        return self.store.view(type_name, vrs)

    def set_string(self, vrs, values):
        try:
            self.store.set_strings(vrs, values)
        except FmuCallError as error:
            self._refuse_call("fmi2SetString", error)

    def get_string(self, vrs):
        try:
            return self.store.get_strings(vrs)
        except FmuCallError as error:
            self._refuse_call("fmi2GetString", error)
            return [""] * len(vrs)

    def _set(self, type_name: str, vrs, values) -> None:
        try:
            self.store.set(type_name, vrs, values)
        except FmuCallError as error:
            self._refuse_call(f"fmi2Set{type_name}", error)

    def _get(self, type_name: str, vrs) -> list:
        try:
            return self.store.get(type_name, vrs)
        except FmuCallError as error:
            self._refuse_call(f"fmi2Get{type_name}", error)
            return [FALLBACK[type_name]] * len(vrs)

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
        table: Dict[str, Dict[str, List[int]]] = {t: {} for t in FMI_TYPES}
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
            handled = self.unit_handled_inputs()
            if handled is not None:             # the unit's own judgement depends on its parameters
                self.input_checks = InputChecks(self.ports, self.store, handled)
            problem = self.input_checks.error()        # the inputs a core reads when it is made
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
        problem = self.input_checks.error()
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
        return model_description.complete(super().to_xml(model_options), self.ports, self.variable_step)


class FrameFacadeSlave(FacadeSlave):
    """Base of the signal-chain facades (coder, rail line, receiver): every step is one frame of
    ``build.frame`` samples at the sample rate, and the FMU takes no other step."""

    variable_step = False

    def frame_experiment(self, fs_hz: float, stop_time_s: float = 10.0) -> DefaultExperiment:
        """DefaultExperiment of a signal FMU: its step is one frame at the default sample rate."""
        return DefaultExperiment(start_time=0.0, stop_time=stop_time_s, step_size=self.build.frame / fs_hz)

    def require_frame_step(self, fs_hz: float) -> None:
        """From now on every doStep must be one frame at ``fs_hz`` (the sample-rate parameter)."""
        self.required_step_s = self.build.frame / fs_hz
