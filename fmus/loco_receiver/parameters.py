"""The receiver's parameters by port name → its core settings, FMI-free, so the facade and the
run report (``railcosim report`` redraws the receiver's band-pass) read a parameter set alike.
The ports themselves (units, bounds, descriptions) are declared in facade.py, their start
values taken from the settings defaults here."""
from __future__ import annotations

from typing import Mapping, Optional, Union

from fmus.loco_receiver import alsu as alsu_receiver
from fmus.loco_receiver import tvm430 as tvm430_receiver
from fmus.loco_receiver.alsu import AlsuReceiverSettings
from fmus.loco_receiver.tvm430 import Tvm430ReceiverSettings
from fmus.loco_receiver.core import ReceiverSettings, resolve_inertia_s
from fmus.loco_receiver.digital_receiver import DigitalReceiverSettings
from fmus.signalling.alsu import AlsuSystem
from fmus.signalling.digital_messages import DigitalSystem
from fmus.signalling.tvm430 import Tvm430System

# port → settings field
ALSN_PARAMETERS = {
    "carrier": "carrier_hz", "fs": "fs_hz", "train_category": "train_category", "v_max": "v_max_mps",
    "filter_order": "filter_order", "filter_bandwidth": "filter_bandwidth_hz", "agc_limit": "agc_limit_v",
    "agc_recovery": "agc_recovery_db_per_s", "pick_up": "pick_up_v", "drop_out": "drop_out_v", "inertia": "inertia_s",
}
ALSU_PARAMETERS = {
    "fs": "fs_hz", "train_category": "train_category", "v_max": "v_max_mps", "filter_bandwidth": "filter_bandwidth_hz",
    "pick_up": "pick_up_v", "drop_out": "drop_out_v", "inertia": "inertia_s", "codes_file": "codes_file",
}
# TVM430's squelch is its own (tvm430.SQUELCH_V): `min_level`'s 0.1 V is the digital receivers'
TVM430_PARAMETERS = {"fs": "fs_hz", "track": "track", "inertia": "inertia_s", "codes_file": "codes_file"}
DIGITAL_PARAMETERS = {
    "carrier": "carrier_hz", "fs": "fs_hz", "train_category": "train_category", "v_max": "v_max_mps",
    "filter_bandwidth": "filter_bandwidth_hz", "track_parity": "track_parity", "limiter": "limiter_v",
    "min_level": "min_level_v", "inertia": "inertia_s",
}


def receiver_settings(system: Optional[Union[DigitalSystem, AlsuSystem, Tvm430System]],
                      parameters: Mapping[str, object]
                      ) -> Union[ReceiverSettings, AlsuReceiverSettings, Tvm430ReceiverSettings, DigitalReceiverSettings]:
    """Settings of an ALSN receiver (``system`` None), an ALSU one, a TVM430 one or a digital one from
    parameter values by port name; a parameter not given keeps its default, one the system does
    not use is ignored."""
    settings_class, fields = ((ReceiverSettings, ALSN_PARAMETERS) if system is None
                              else (AlsuReceiverSettings, ALSU_PARAMETERS) if isinstance(system, AlsuSystem)
                              else (Tvm430ReceiverSettings, TVM430_PARAMETERS) if isinstance(system, Tvm430System)
                              else (DigitalReceiverSettings, DIGITAL_PARAMETERS))
    defaults = settings_class()
    values = {field: type(getattr(defaults, field))(parameters[port])
              for port, field in fields.items() if port in parameters}
    return settings_class(**values)


def display_hold_s(system: Optional[DigitalSystem], parameters: Mapping[str, object]) -> float:
    """The longest loss of code the receiver's display bridges (its `inertia`, or the system's
    default): how long after the code under the coils disappears it may still show the last
    one (the run verdicts allow it, docs/scenarios.md#results-summaryjson)."""
    settings = receiver_settings(system, parameters)
    if isinstance(system, AlsuSystem):
        return alsu_receiver.resolve_inertia_s(settings.inertia_s)
    if isinstance(system, Tvm430System):
        return tvm430_receiver.resolve_inertia_s(settings.inertia_s)
    return resolve_inertia_s(settings.inertia_s, digital=system is not None)
