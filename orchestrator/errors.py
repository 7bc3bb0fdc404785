"""Errors the CLI turns into one line on stderr and exit code 2."""
import difflib
import math
import os
import sys
from typing import Dict, FrozenSet, Iterable, List, Optional, Sequence, Tuple

#: extraction folder of an .ssp archive → the archive as the user named it (orchestrator/ssp.py
#: registers each folder it unpacks); see :func:`shown_paths`
_ARCHIVES: Dict[str, str] = {}


def register_archive(folder, archive) -> None:
    """Messages naming a file under ``folder`` name it ``<archive>!<member>`` from now on."""
    _ARCHIVES[os.path.realpath(str(folder))] = str(archive)
    _ARCHIVES[os.path.abspath(str(folder))] = str(archive)


def forget_archive(folder) -> None:
    _ARCHIVES.pop(os.path.realpath(str(folder)), None)
    _ARCHIVES.pop(os.path.abspath(str(folder)), None)


def shown_paths(text: str) -> str:
    """``text`` with every path inside a registered extraction folder written as
    ``<archive>!<member>`` (docs/interfaces.md, SSP conventions: the file the user gave, never
    a temporary extraction path)."""
    for folder in sorted(_ARCHIVES, key=len, reverse=True):   # longest first: nested folders
        if folder in text:
            text = text.replace(folder + os.sep, _ARCHIVES[folder] + "!").replace(folder, _ARCHIVES[folder])
    return text


class UserError(Exception):
    """Bad input from the user: a file, a parameter or a command-line argument.

    The message is complete on its own (it names what is wrong and where); the CLI prints it
    as one line without a traceback. A path inside an unpacked .ssp is shown as
    ``<archive>!<member>`` (:func:`shown_paths`), whoever raised the error.
    """

    def __init__(self, message: str = "", *rest):
        super().__init__(shown_paths(str(message)), *rest)


class RefusedComponents(UserError):
    """Problems found before the components are made (orchestrator/verdicts/system_checks.py),
    each with the components that would refuse the same problem at their initialisation.

    The message is the first problem (a run stops there, in one line); ``problems`` holds every
    one as (text, component names), so ``railcosim validate`` lists them all and does not
    initialise those components to meet the same problem again."""

    def __init__(self, problems: Sequence[Tuple[str, FrozenSet[str]]]):
        super().__init__(problems[0][0])
        self.problems: List[Tuple[str, FrozenSet[str]]] = [(shown_paths(str(text)), frozenset(names))
                                                            for text, names in problems]

    @property
    def refused(self) -> FrozenSet[str]:
        """Every component some problem names."""
        return frozenset().union(*(names for _, names in self.problems))


class SimulationError(UserError):
    """A component failed during a run; results computed so far have been written."""


def os_error(error: OSError) -> UserError:
    """An OSError as one line naming its file (a .ssp extracted into a full temp folder)."""
    return UserError(f"{error.filename or 'a file'}: {error.strerror or error}")


def print_warning(message: str) -> None:
    """One warning line on stderr (the message's line breaks and runs of spaces made one space)."""
    print(f"railcosim: warning: {' '.join(str(message).split())}", file=sys.stderr)


def did_you_mean(given: str, choices: Iterable[str]) -> str:
    """``; did you mean NAME?`` for the choice closest to a mistyped name (difflib's ratio at
    least 0.6, case aside), to end the one line that says what is wrong; "" when none is close."""
    by_lower: Dict[str, str] = {}
    for choice in choices:
        by_lower.setdefault(str(choice).lower(), str(choice))
    close = difflib.get_close_matches(str(given).lower(), list(by_lower), n=1, cutoff=0.6)
    return f"; did you mean {by_lower[close[0]]}?" if close else ""


def where(path, line=None) -> str:
    """'file' or 'file:line' for messages."""
    return f"{path}:{line}" if line else f"{path}"


def non_finite_number(document) -> Optional[Tuple[str, float]]:
    """The field (``gradients[1].permille``) and value of the first number in a parsed JSON or
    TOML document that is not finite, or None. Python's json reads NaN, Infinity and -Infinity,
    and a literal beyond the double range (1e400) as infinity; tomllib reads nan and inf. (The
    same test as ``fmus.errors.non_finite_number``, which the engine may not import.)"""
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
