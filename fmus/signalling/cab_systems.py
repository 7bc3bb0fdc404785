"""The cab-signal systems a coder or receiver can be built for, by their `system` parameter."""
from __future__ import annotations

from typing import Optional

from fmus.signalling import als_en, fire_dqpsk
from fmus.signalling.digital_messages import DigitalSystem
from fmus.errors import FmuInputError

ALSN = "ALSN"
DIGITAL = {als_en.SYSTEM.name: als_en.SYSTEM, fire_dqpsk.SYSTEM.name: fire_dqpsk.SYSTEM}
NAMES = (ALSN,) + tuple(DIGITAL)


def digital_system(name: str) -> Optional[DigitalSystem]:
    """The digital system of that name, None for ALSN; an unknown name is an input error."""
    if name not in NAMES:
        raise FmuInputError(f"parameter system: {name!r} is not one of {', '.join(NAMES)}")
    return DIGITAL.get(name)
