"""The receiver of each cab system, by its ``system`` name (fmus/signalling/cab_systems.py): the
core class, its settings and the parameters (port → settings field) it reads, how its display
hold is resolved, and — for a receiver that listens on carriers or tones of its own — why the
``carrier`` parameter must stay 0. The facade and parameters.py look the system up here; no
other module of the receiver tells the systems apart."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Dict, Optional

from fmus.loco_receiver import alsu as alsu_receiver
from fmus.loco_receiver import tvm430 as tvm430_receiver
from fmus.loco_receiver.alsu import AlsuReceiverCore, AlsuReceiverSettings
from fmus.loco_receiver.core import LocoReceiverCore, ReceiverSettings, resolve_inertia_s
from fmus.loco_receiver.digital_receiver import DigitalReceiverCore, DigitalReceiverSettings
from fmus.loco_receiver import tvm300 as tvm300_receiver
from fmus.loco_receiver.tvm300 import Tvm300ReceiverCore, Tvm300ReceiverSettings
from fmus.loco_receiver.tvm430 import Tvm430ReceiverCore, Tvm430ReceiverSettings
from fmus.signalling import cab_systems

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
# the TVM receivers' squelch is their own (tvm430.SQUELCH_V): `min_level`'s 0.1 V is the digital receivers'
UM71_PARAMETERS = {"fs": "fs_hz", "track": "track", "inertia": "inertia_s", "codes_file": "codes_file"}
DIGITAL_PARAMETERS = {
    "carrier": "carrier_hz", "fs": "fs_hz", "train_category": "train_category", "v_max": "v_max_mps",
    "filter_bandwidth": "filter_bandwidth_hz", "track_parity": "track_parity", "limiter": "limiter_v",
    "min_level": "min_level_v", "inertia": "inertia_s",
}


@dataclass(frozen=True)
class ReceiverKind:
    settings_class: type
    parameters: Dict[str, str]                          # port → settings field
    hold_s: Callable[[float], float]                    # the display hold of an `inertia` value (0: the system's)
    #: the core from (frame, settings, the system object of cab_systems.CabSystem.system)
    make_core: Callable[[int, object, object], object]
    own_carriers: Optional[str] = None                  # why `carrier` must stay 0; None: it is read


RECEIVERS: Dict[str, ReceiverKind] = {
    cab_systems.ALSN.name: ReceiverKind(ReceiverSettings, ALSN_PARAMETERS,
                                        lambda inertia_s: resolve_inertia_s(inertia_s, digital=False),
                                        lambda frame, settings, _system: LocoReceiverCore(frame, settings)),
    cab_systems.ALSU.name: ReceiverKind(AlsuReceiverSettings, ALSU_PARAMETERS, alsu_receiver.resolve_inertia_s,
                                        lambda frame, settings, system: AlsuReceiverCore(frame, settings, system.table),
                                        "ALSU listens to its own six tones (leave carrier 0)"),
    cab_systems.TVM430.name: ReceiverKind(Tvm430ReceiverSettings, UM71_PARAMETERS, tvm430_receiver.resolve_inertia_s,
                                          lambda frame, settings, system: Tvm430ReceiverCore(frame, settings, system),
                                          "TVM430 listens to its track's carriers (leave carrier 0, set track)"),
    cab_systems.TVM300.name: ReceiverKind(Tvm300ReceiverSettings, UM71_PARAMETERS, tvm300_receiver.resolve_inertia_s,
                                          lambda frame, settings, system: Tvm300ReceiverCore(frame, settings, system),
                                          "TVM300 listens to its track's carriers (leave carrier 0, set track)"),
}
for _name, _cab in cab_systems.REGISTRY.items():
    if _cab.family == cab_systems.DIGITAL_FAMILY:
        RECEIVERS[_name] = ReceiverKind(
            DigitalReceiverSettings, DIGITAL_PARAMETERS, lambda inertia_s: resolve_inertia_s(inertia_s, digital=True),
            lambda frame, settings, system: DigitalReceiverCore(system, frame, settings))


def receiver_kind(name: str) -> ReceiverKind:
    """The receiver of a registered system (an unknown name is an input error)."""
    return RECEIVERS[cab_systems.lookup(name).name]
