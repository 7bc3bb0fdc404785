"""Interruptions of a run: SIGINT (Ctrl-C), SIGTERM (a batch scheduler's time limit), SIGHUP.

The FMUs' Python code runs in this interpreter, called through C (pythonfmu): an exception
raised by a signal handler inside it surfaces as a component failure, or worse, in the middle
of pythonfmu's own C++ code. So while a run is under way the handlers only *record* the
signal; the master looks at the flag between macro steps (one attribute test per tick) and the
run stops at the next safe point, closes its files, shuts its FMUs down and writes its summary
(docs/reliability.md, "Interruptions"). The command then exits with 128 + the signal number:
130 (SIGINT), 143 (SIGTERM), 129 (SIGHUP).
"""
from __future__ import annotations

import signal
import threading
from contextlib import contextmanager
from typing import Dict, Iterator, Optional

#: the signals a run turns into an orderly stop
HANDLED = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))


class Interrupted(Exception):
    """A run stopped because a signal arrived; its results so far are written."""

    def __init__(self, signum: int, where: str = ""):
        self.signum = signum
        self.signal_name = signal_name(signum)
        self.exit_code = 128 + signum
        self.where = where
        super().__init__(f"interrupted by {self.signal_name} {where}".strip())


def signal_name(signum: int) -> str:
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


class InterruptFlag:
    """The first handled signal that arrived while handlers were installed (0: none).

    ``signum`` is a plain attribute so the master's per-tick test costs one attribute read.
    """

    __slots__ = ("signum", "count")

    def __init__(self) -> None:
        self.signum = 0
        self.count = 0           # how many arrived (a second Ctrl-C changes nothing else)

    def check(self, where: str = "") -> None:
        """Raise :class:`Interrupted` if a signal arrived."""
        if self.signum:
            raise Interrupted(self.signum, where)


#: the process's flag: set by the handlers :func:`deferred` installs, read by the master
FLAG = InterruptFlag()
#: a flag that is never set, for masters driven without signal handling
NEVER = InterruptFlag()

_depth = 0
_previous: Dict[int, object] = {}


def _record(signum, frame) -> None:
    # never raise here: this may run inside an FMU's Python code, called from C
    FLAG.count += 1
    if not FLAG.signum:
        FLAG.signum = signum


def hold_until_exit() -> Optional[InterruptFlag]:
    """Install the recording handlers for the rest of the process (a command line that ends
    when the run ends): a signal while the interpreter finalises — unloading the FMUs takes
    a while — is recorded and changes nothing, where Python's own handlers would turn it into
    a traceback or a death by the signal after the results were complete. Later
    :func:`deferred` uses nest inside it. None outside the main thread."""
    if threading.current_thread() is not threading.main_thread():
        return None
    return _install()


def _install() -> InterruptFlag:
    """The recording handlers, installed by the outermost user (which also clears the flag)."""
    global _depth
    if _depth == 0:
        FLAG.signum = 0
        FLAG.count = 0
        for signum in HANDLED:
            _previous[signum] = signal.signal(signum, _record)
    _depth += 1
    return FLAG


@contextmanager
def deferred() -> Iterator[Optional[InterruptFlag]]:
    """While inside, SIGINT/SIGTERM/SIGHUP only set :data:`FLAG`; the previous handlers are put
    back on leaving. Nested uses share the outermost installation (and its flag). Outside the
    main thread signals cannot be handled: it yields None and installs nothing."""
    global _depth
    if threading.current_thread() is not threading.main_thread():
        yield None
        return
    flag = _install()
    try:
        yield flag
    finally:
        _depth -= 1
        if _depth == 0:
            for signum, handler in _previous.items():
                signal.signal(signum, handler if handler is not None else signal.SIG_DFL)
            _previous.clear()


def ignore_until_exit() -> None:
    """Once a held run's command has returned: ignore the handled signals for the rest of the
    process. The interpreter's finalisation puts SIG_DFL back for every signal with a Python
    handler and then unloads the FMUs for a few hundred milliseconds: a signal then killed the
    process after its results were complete (SIG_IGN is left as it is; blocking would not do,
    a process-wide signal goes to any thread that does not block it, numpy's included)."""
    if _depth > 0 and threading.current_thread() is threading.main_thread():
        for signum in HANDLED:
            signal.signal(signum, signal.SIG_IGN)
