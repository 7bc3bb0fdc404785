"""Reductions of the small arrays a frame holds, each one cheap C call (no FMI here).

numpy's ufunc reductions (``np.logical_and.reduce``, ``np.maximum.reduce``) and the ndarray
methods built on them (``all``, ``any``, ``max``) cost about 1 µs of set-up per call whatever
the size; on 40-sample frames that is nearly all of their cost, and a frame of the signal
chain makes a dozen. These give the same answers through cheaper routines: a count of the
true elements, or the position of the largest or smallest value (docs/performance.md).
"""
from __future__ import annotations

import numpy as np

from fmus.library_shortcuts import count_nonzero as _count_nonzero


def all_true(flags: np.ndarray) -> bool:
    """Every element of a bool array true (an empty one: true)."""
    return _count_nonzero(flags) == flags.size


def any_true(flags: np.ndarray) -> bool:
    """Some element of a bool array true."""
    return _count_nonzero(flags) != 0


def largest(values: np.ndarray) -> float:
    """The largest value of a non-empty float array; NaN if any is NaN (argmax stops at the
    first NaN), as ``np.max`` gives."""
    return values.item(values.argmax())


def smallest(values: np.ndarray) -> float:
    """The smallest value, likewise."""
    return values.item(values.argmin())
