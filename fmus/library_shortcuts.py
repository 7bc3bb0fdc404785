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
* ``sections_filter(sos, x, zi)`` — scipy.signal.sosfilt's routine along the last axis of x
  ((N,) or (rows, N)) with zi ((S, 2) or (rows, S, 2)), without sosfilt's validation and
  axis moves; returns (y, zf) like sosfilt with zi, leaving its arguments as they were.
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
            "linear_filter": _linear_filter_routine() is not None,
            "sections_filter": _sections_filter_routine() is not None}


def _sections_filter_routine():
    """scipy's in-place second-order-sections routine, or None (as _linear_filter_routine)."""
    global _internal_sections_filter
    if _internal_sections_filter is _UNKNOWN:
        try:
            from scipy.signal._sosfilt import _sosfilt as routine
        except ImportError:
            routine = None
        _internal_sections_filter = routine
    return _internal_sections_filter


_internal_sections_filter = _UNKNOWN


def sections_filter(sos: np.ndarray, x: np.ndarray, zi: np.ndarray):
    """sosfilt(sos, x, axis=-1, zi=zi) through its routine where scipy has it (float64 in):
    the routine filters a C-contiguous (rows, N) copy and a (rows, S, 2) state in place."""
    routine = _internal_sections_filter if _internal_sections_filter is not _UNKNOWN else _sections_filter_routine()
    if routine is not None and x.dtype == np.float64 and zi.dtype == np.float64 and sos.dtype == np.float64:
        y = np.array(x, dtype=np.float64, order="C", ndmin=2)
        state = np.array(zi, dtype=np.float64, order="C", ndmin=3)
        try:
            routine(sos, y, state)
            return y.reshape(x.shape), state.reshape(zi.shape)
        except (TypeError, ValueError):               # pragma: no cover - a changed signature
            pass
    from scipy.signal import sosfilt

    if x.ndim == 1:
        return sosfilt(sos, x, zi=zi)
    y, state = sosfilt(sos, x, axis=-1, zi=np.moveaxis(zi, 1, 0))      # sosfilt's zi: (S, rows, 2)
    return y, np.ascontiguousarray(np.moveaxis(state, 0, 1))
