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
from scipy.signal import lfilter


def _public_linear_filter(b, a, x, axis, zi):
    return lfilter(b, a, x, axis=axis, zi=zi)


try:
    from numpy._core.multiarray import count_nonzero
except ImportError:                      # another numpy layout: the public function
    count_nonzero = np.count_nonzero

try:
    from numpy._core.multiarray import interp
except ImportError:
    interp = np.interp

try:
    from scipy.signal._sigtools import _linear_filter as _internal_linear_filter
except ImportError:
    _internal_linear_filter = None


def linear_filter(b: np.ndarray, a: np.ndarray, x: np.ndarray, axis: int, zi: np.ndarray):
    """lfilter(b, a, x, axis, zi=zi) through its C routine where scipy has it (float64 in)."""
    if _internal_linear_filter is not None and x.dtype == np.float64 and zi.dtype == np.float64:
        try:
            return _internal_linear_filter(b, a, x, axis, zi)
        except (TypeError, ValueError):               # pragma: no cover - a changed signature
            pass
    return _public_linear_filter(b, a, x, axis, zi)


#: which shortcuts this machine takes (False: the public function is used)
IN_USE = {"count_nonzero": count_nonzero is not np.count_nonzero, "interp": interp is not np.interp,
          "linear_filter": _internal_linear_filter is not None}
