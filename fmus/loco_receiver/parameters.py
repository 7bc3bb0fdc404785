"""The receiver's parameters by port name → its core settings, FMI-free, so the facade and the
run report (``railcosim report`` redraws the receiver's band-pass) read a parameter set alike.
The ports themselves (units, bounds, descriptions) are declared in facade.py, their start
values taken from the settings defaults; each system's settings class and parameters:
cores.py."""
from __future__ import annotations

from typing import Mapping

from fmus.loco_receiver.cores import receiver_kind


def receiver_settings(system: str, parameters: Mapping[str, object]):
    """Settings of the receiver of cab system ``system`` (its name) from parameter values by
    port name; a parameter not given keeps its default, one the system does not use is ignored."""
    kind = receiver_kind(system)
    defaults = kind.settings_class()
    values = {field: type(getattr(defaults, field))(parameters[port])
              for port, field in kind.parameters.items() if port in parameters}
    return kind.settings_class(**values)


def display_hold_s(system: str, parameters: Mapping[str, object]) -> float:
    """The longest loss of code the receiver's display bridges (its `inertia`, or the system's
    default): how long after the code under the coils disappears it may still show the last
    one (the run verdicts allow it, docs/scenarios.md#results-summaryjson)."""
    return receiver_kind(system).hold_s(receiver_settings(system, parameters).inertia_s)
