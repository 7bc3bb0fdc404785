"""Shortcuts into numpy's and scipy's own C routines, past their public functions' argument
handling, for the hot paths of a frame (no FMI here; docs/performance.md says what each saves).
The host side has its own (orchestrator/library_shortcuts.py): the engine imports nothing of
``fmus``.

Each name is the library's internal routine when this numpy or scipy is a release line the
routines were checked against (CHECKED_AGAINST: their code read, their answers compared with
the public functions' by tests/test_library_shortcuts.py) and has the routine where we look,
and the public function otherwise: on another release an internal routine may have kept its
name and changed its meaning. The choice is made once (numpy's at import, scipy's at the first
filter), never per call. A caller passes what the internal routine needs without checks:
contiguous float64 arrays of the right shapes. What the public fallbacks cost a call:
benchmarks/bench_library_shortcuts.py (docs/performance.md).

* ``count_nonzero(flags)`` — np.count_nonzero's routine.
* ``interp(x, xp, fp)`` — np.interp's routine, without its per-call checks.
* ``linear_filter(b, a, x, axis, zi)`` — scipy.signal.lfilter's C routine (transposed direct
  form II), without lfilter's validation; returns (y, zf) like lfilter with zi.
* ``sections_filter(sos, x, zi)`` — scipy.signal.sosfilt's routine along the last axis of x
  ((N,) or (rows, N)) with zi ((S, 2) or (rows, S, 2)), without sosfilt's validation and
  axis moves; returns (y, zf) like sosfilt with zi, leaving its arguments as they were.
"""
from __future__ import annotations

import numpy as np

#: the release lines (major.minor) whose internal routines these shortcuts were read and
#: compared against: numpy 2.4.6, scipy 1.17.1
CHECKED_AGAINST = {"numpy": "2.4", "scipy": "1.17"}


def _checked(version: str, library: str) -> bool:
    return ".".join(version.split(".")[:2]) == CHECKED_AGAINST[library]


count_nonzero, interp = np.count_nonzero, np.interp
if _checked(np.__version__, "numpy"):
    try:
        from numpy._core.multiarray import count_nonzero, interp
    except ImportError:                  # the checked line without them: the public functions
        count_nonzero, interp = np.count_nonzero, np.interp

_UNKNOWN = object()
_internal_linear_filter = _internal_sections_filter = _UNKNOWN


def _scipy_routines() -> None:
    """scipy's two filter routines, or None each; looked up at the first filter (scipy is not
    imported by the units that filter nothing: the traction and ATO FMUs need only numpy)."""
    global _internal_linear_filter, _internal_sections_filter
    import scipy

    _internal_linear_filter = _internal_sections_filter = None
    if _checked(scipy.__version__, "scipy"):
        try:
            from scipy.signal._sigtools import _linear_filter as _internal_linear_filter
            from scipy.signal._sosfilt import _sosfilt as _internal_sections_filter
        except ImportError:
            _internal_linear_filter = _internal_sections_filter = None


def linear_filter(b: np.ndarray, a: np.ndarray, x: np.ndarray, axis: int, zi: np.ndarray):
    """lfilter(b, a, x, axis, zi=zi) through its C routine where scipy has it (float64 in)."""
    if _internal_linear_filter is _UNKNOWN:
        _scipy_routines()
    if _internal_linear_filter is not None and x.dtype == np.float64 and zi.dtype == np.float64:
        return _internal_linear_filter(b, a, x, axis, zi)
    from scipy.signal import lfilter

    return lfilter(b, a, x, axis=axis, zi=zi)


def sections_filter(sos: np.ndarray, x: np.ndarray, zi: np.ndarray):
    """sosfilt(sos, x, axis=-1, zi=zi) through its routine where scipy has it (float64 in):
    the routine filters a C-contiguous (rows, N) copy and a (rows, S, 2) state in place."""
    if _internal_sections_filter is _UNKNOWN:
        _scipy_routines()
    if _internal_sections_filter is not None and x.dtype == np.float64 and zi.dtype == np.float64 \
            and sos.dtype == np.float64:
        y = np.array(x, dtype=np.float64, order="C", ndmin=2)
        state = np.array(zi, dtype=np.float64, order="C", ndmin=3)
        _internal_sections_filter(sos, y, state)
        return y.reshape(x.shape), state.reshape(zi.shape)
    return public_sections_filter(sos, x, zi)


def public_sections_filter(sos: np.ndarray, x: np.ndarray, zi: np.ndarray):
    """sections_filter through scipy.signal.sosfilt itself (the fallback)."""
    from scipy.signal import sosfilt

    if x.ndim == 1:
        return sosfilt(sos, x, zi=zi)
    y, state = sosfilt(sos, x, axis=-1, zi=np.moveaxis(zi, 1, 0))      # sosfilt's zi: (S, rows, 2)
    return y, np.ascontiguousarray(np.moveaxis(state, 0, 1))


def in_use() -> dict:
    """Which shortcuts this machine takes (False: the public function is used)."""
    if _internal_linear_filter is _UNKNOWN:
        _scipy_routines()
    return {"count_nonzero": count_nonzero is not np.count_nonzero, "interp": interp is not np.interp,
            "linear_filter": _internal_linear_filter is not None,
            "sections_filter": _internal_sections_filter is not None}
