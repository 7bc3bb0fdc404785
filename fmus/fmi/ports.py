"""The ports a facade declares: scalars and frame arrays, with their start value (the core
settings' default), unit, range, what a bad input does and, for an output, the core field it
shows and its fail-safe value (no FMI library here). Every other statement of a port is derived
from these declarations: the facade's output copy (:func:`output_fields`), the modelDescription,
the committed contract.json and the port tables of docs/interfaces.md
(orchestrator/packaging/declarations.py writes both and tests/test_declarations.py compares)."""
from __future__ import annotations

import inspect
import math
from dataclasses import dataclass
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np


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
    # an input outside its declared range or not finite: "refuse" the step (FacadeSlave),
    # "clamp" (finite values outside min/max are the unit's to clamp; non-finite refused) or
    # "unit" (the unit handles every value itself: the ATO's measurements fail safe), where the
    # facade's unit_handled_inputs says the unit reads it with its parameters; else "refuse"
    bad_input: str = "refuse"
    # an output: the attribute of the core's output record it shows (None: the port's own name)
    core_field: Optional[str] = None
    # an output: what a DCP master shows in its place while the slave's outputs are lost
    # (docs/hil.md, "What happens on loss"): the most restrictive value; None keeps the last one
    fail_safe: Any = None

    def __post_init__(self):
        if self.bad_input not in ("refuse", "clamp", "unit"):
            raise TypeError(f"port {self.name}: bad_input {self.bad_input!r} is not refuse, clamp or unit")
        if self.causality != "output" and (self.core_field is not None or self.fail_safe is not None):
            raise TypeError(f"port {self.name}: only an output has a core field and a fail-safe value")
        if self.fail_safe is not None and (self.type == "String" or self.shape
                                           or self.range_error(self.name, float(self.fail_safe)) is not None):
            raise TypeError(f"port {self.name}: fail-safe value {self.fail_safe!r} is not a value of this "
                            "scalar numeric port")

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


def output_fields(ports: Sequence[Port]) -> Tuple[Tuple[str, str], ...]:
    """((output port, the core's output-record attribute it shows), ...) in declaration order:
    what a facade copies from its core after each step (ValueStore.write_outputs)."""
    return tuple((p.name, p.core_field or p.name) for p in ports if p.causality == "output")


def fail_safe_values(ports: Sequence[Port]) -> Dict[str, float]:
    """Each output's fail-safe value by port name (a Boolean as 0 or 1), for those that have one."""
    return {p.name: float(p.fail_safe) for p in ports if p.fail_safe is not None}


def keyword_defaults(function) -> Dict[str, Any]:
    """The defaults of a core constructor's keyword parameters, for the start values of the
    ports that set them (a core without a settings record)."""
    return {name: p.default for name, p in inspect.signature(function).parameters.items()
            if p.default is not inspect.Parameter.empty}


def enumeration_text(names: Mapping[int, str]) -> str:
    """An enumeration's values and names as a port's description says them: ``0 white, 1 red``
    (the names are stated once, beside the values, and the results' legends read them there)."""
    return ", ".join(f"{value} {name}" for value, name in sorted(names.items()))


def line_file_port() -> Port:
    """The line description every unit reads: one file shared by a system's components."""
    return Port("line_file", "parameter", "String", start="", description="line JSON; empty: the bundled default line")


def cab_system_port(names: Sequence[str], default: str) -> Port:
    """The cab-signalling system a coder sends and a receiver decodes: one of ``names`` (the
    registry's, fmus/signalling/cab_systems.py, which the facades pass: a unit without a signal
    chain never loads the signalling library)."""
    return Port("system", "parameter", "String", start=default, description=" | ".join(names))


def sample_rate_port(fs_hz: float, frame: int) -> Port:
    """The sample rate of a signal-chain unit; its communication step is one frame."""
    return Port("fs", "parameter", unit="Hz", start=fs_hz, min=1.0,
                description=f"sample rate; the communication step must be frame/fs ({frame} samples)")
