"""The cab-signal systems a coder or receiver can be built for, by their `system` parameter:
the frequency systems ALSN (numeric codes on one carrier) and ALSU (two of six tones,
alsu.py), TVM-430 (a 27-bit word of very-low tones on an audio-frequency carrier, tvm430.py),
and the digital systems (digital_messages.py)."""
from __future__ import annotations

from typing import Optional

from fmus.signalling import als_en, fire_dqpsk
from fmus.signalling.digital_messages import DigitalSystem
from fmus.errors import FmuInputError

ALSN = "ALSN"
ALSU = "ALSU"
TVM430 = "TVM430"
DIGITAL = {als_en.SYSTEM.name: als_en.SYSTEM, fire_dqpsk.SYSTEM.name: fire_dqpsk.SYSTEM}
NAMES = (ALSN, ALSU, TVM430) + tuple(DIGITAL)


class AtoMode:
    """The ATO's ``cab_signal`` modes: how its ATP reads the receiver's indication
    (fmus/ato_controller/atp.py). One mode may serve several systems (``digital``: ALS-EN and
    FIRE_DQPSK); ``off`` runs without a cab signal."""

    ALSN = "ALSN"
    ALSU = "ALSU"
    DIGITAL = "digital"
    TVM430 = "TVM430"
    TVM300 = "TVM300"
    OFF = "off"
    ALL = (ALSN, ALSU, DIGITAL, TVM430, TVM300, OFF)


def check_name(name: str) -> str:
    """The name itself; an unknown name is an input error."""
    if name not in NAMES:
        raise FmuInputError(f"parameter system: {name!r} is not one of {', '.join(NAMES)}")
    return name


def digital_system(name: str) -> Optional[DigitalSystem]:
    """The digital system of that name, None for ALSN, ALSU and TVM430; an unknown name is an input error."""
    return DIGITAL.get(check_name(name))


def is_alsu(name: str) -> bool:
    return check_name(name) == ALSU


def is_tvm430(name: str) -> bool:
    return check_name(name) == TVM430
