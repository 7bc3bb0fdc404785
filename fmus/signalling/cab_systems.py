"""The cab-signal systems a coder or receiver can be built for, by their `system` parameter:
the frequency systems ALSN (numeric codes on one carrier) and ALSU (two of six tones,
alsu.py), and the digital systems (digital_messages.py)."""
from __future__ import annotations

from typing import Optional

from fmus.signalling import als_en, fire_dqpsk
from fmus.signalling.digital_messages import DigitalSystem
from fmus.errors import FmuInputError

ALSN = "ALSN"
ALSU = "ALSU"
DIGITAL = {als_en.SYSTEM.name: als_en.SYSTEM, fire_dqpsk.SYSTEM.name: fire_dqpsk.SYSTEM}
NAMES = (ALSN, ALSU) + tuple(DIGITAL)


def check_name(name: str) -> str:
    """The name itself; an unknown name is an input error."""
    if name not in NAMES:
        raise FmuInputError(f"parameter system: {name!r} is not one of {', '.join(NAMES)}")
    return name


def digital_system(name: str) -> Optional[DigitalSystem]:
    """The digital system of that name, None for ALSN and ALSU; an unknown name is an input error."""
    return DIGITAL.get(check_name(name))


def is_alsu(name: str) -> bool:
    return check_name(name) == ALSU
