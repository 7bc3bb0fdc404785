"""Shortcuts into numpy's and scipy's own C routines, past their public functions' argument
handling, for the hot paths of a frame (no FMI here; docs/performance.md says what each saves).

Each name is the library's internal routine when this numpy or scipy has it where we look, and
its public function otherwise; the two give the same answers (tests/test_library_shortcuts.py
compares them on every shortcut this machine has). A caller passes what the internal routine
needs without checks: contiguous float64 arrays of the right shapes.

* ``count_nonzero(flags)`` — np.count_nonzero's routine (about 0.08 µs a call against 0.36 µs).
* ``interp(x, xp, fp)`` — np.interp's routine, without its per-call checks.
* ``linear_filter(b, a, x, axis, zi)`` — scipy.signal.lfilter's C routine (transposed direct
  form II), without lfilter's validation (about 4 µs a call); returns (y, zf) like lfilter
  with zi.
"""
from __future__ import annotations

import numpy as np

try:
    from numpy._core.multiarray import count_nonzero
except ImportError:                      # another numpy layout: the public function
    count_nonzero = np.count_nonzero

try:
    from numpy._core.multiarray import interp
except ImportError:
    interp = np.interp



def _linear_filter_routine():
    """scipy's routine, or None; looked up at the first filter (scipy is not imported by the
    units that filter nothing: the traction and ATO FMUs need only numpy)."""
    global _internal_linear_filter
    if _internal_linear_filter is _UNKNOWN:
        try:
            from scipy.signal._sigtools import _linear_filter as routine
        except ImportError:
            routine = None
        _internal_linear_filter = routine
    return _internal_linear_filter


_UNKNOWN = object()
_internal_linear_filter = _UNKNOWN


def linear_filter(b: np.ndarray, a: np.ndarray, x: np.ndarray, axis: int, zi: np.ndarray):
    """lfilter(b, a, x, axis, zi=zi) through its C routine where scipy has it (float64 in)."""
    routine = _internal_linear_filter if _internal_linear_filter is not _UNKNOWN else _linear_filter_routine()
    if routine is not None and x.dtype == np.float64 and zi.dtype == np.float64:
        try:
            return routine(b, a, x, axis, zi)
        except (TypeError, ValueError):               # pragma: no cover - a changed signature
            pass
    from scipy.signal import lfilter

    return lfilter(b, a, x, axis=axis, zi=zi)


def in_use() -> dict:
    """Which shortcuts this machine takes (False: the public function is used)."""
    return {"count_nonzero": count_nonzero is not np.count_nonzero, "interp": interp is not np.interp,
            "linear_filter": _linear_filter_routine() is not None}
