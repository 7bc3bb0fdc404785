"""Errors the model cores raise, and the one test every data file passes before its fields are
read (no number that is not finite). No dependencies: every core, the data layer and the
orchestrator's analysis import this without pulling in any FMI library."""
import math
from typing import Optional, Tuple


class FmuInputError(ValueError):
    """A parameter or data file given to an FMU is invalid; the message names what and where."""


class FmuCallError(RuntimeError):
    """An FMI call out of order or with unknown value references (the host's mistake)."""


def non_finite_number(document) -> Optional[Tuple[str, float]]:
    """The field (``gradients[1].permille``) and value of the first number in a parsed JSON or
    TOML document that is not finite, or None. Python's json reads NaN, Infinity and -Infinity,
    and a literal beyond the double range (1e400) as infinity; tomllib reads nan and inf."""
    pending = [("", document)]
    while pending:
        field, value = pending.pop()
        if isinstance(value, float) and not math.isfinite(value):
            return field or "(top level)", value
        if isinstance(value, dict):
            pending.extend((f"{field}.{key}" if field else str(key), item) for key, item in reversed(value.items()))
        elif isinstance(value, list):
            pending.extend((f"{field}[{index}]", item) for index, item in reversed(list(enumerate(value))))
    return None
