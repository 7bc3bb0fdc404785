"""The ATO book's statistical capacity method (docs/sources.md#headway-and-capacity, rows 5–9;
docs/capacity.md#the-books-statistical-method).

Trains keep their schedule only approximately; a follower's actual interval differs from the
scheduled one by the difference of two successive deviations, and the automatic block lets no
interval fall below the design interval, so the deviations are counted without sign, by their
root mean square. From the mean actual interval ``i_mean`` and that RMS ``Δi``:

* under-use of capacity = Δi / i_mean;
* the exact interval (the schedule kept exactly) i_exact = i_mean − Δi;
* the achievable interval with a driving that holds an RMS r (an ATO): i_achievable = i_exact + r;
* the capacity gain = (i_mean − i_achievable) / i_mean.

All intervals in seconds, fractions as fractions (0.267, not 26.7 %).
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Sequence

import numpy as np


def rms_deviation_s(actual_s: Sequence[float], scheduled_s) -> float:
    """The root mean square of the actual intervals' deviations from the scheduled ones (s);
    ``scheduled_s``: one interval for all, or one per actual interval."""
    actual = np.asarray(actual_s, dtype=float)
    if actual.size == 0:
        raise ValueError("no intervals")
    return float(np.sqrt(np.mean((actual - np.broadcast_to(np.asarray(scheduled_s, dtype=float), actual.shape)) ** 2)))


def under_use(mean_interval_s: float, rms_s: float) -> float:
    """The degree of under-use of capacity, RMS / mean interval."""
    return rms_s / mean_interval_s


def exact_interval_s(mean_interval_s: float, rms_s: float) -> float:
    """The interval were the schedule kept exactly: mean − RMS."""
    return mean_interval_s - rms_s


def achievable_interval_s(mean_interval_s: float, rms_s: float, held_rms_s: float) -> float:
    """The mean interval achievable by a driving that holds an RMS ``held_rms_s``: exact + held."""
    return exact_interval_s(mean_interval_s, rms_s) + held_rms_s


def capacity_gain(mean_interval_s: float, rms_s: float, held_rms_s: float) -> float:
    """(mean − achievable) / mean: the share of trains added by the more exact driving."""
    return (mean_interval_s - achievable_interval_s(mean_interval_s, rms_s, held_rms_s)) / mean_interval_s


@dataclass(frozen=True)
class Assessment:
    """The method's figures for one set of intervals and a driving that holds ``held_rms_s``."""

    intervals: int
    mean_interval_s: float
    rms_s: float
    under_use: float
    exact_interval_s: float
    held_rms_s: float
    achievable_interval_s: float
    capacity_gain: float

    def as_dict(self) -> dict:
        return asdict(self)


def assess(actual_s: Sequence[float], scheduled_s, held_rms_s: float) -> Assessment:
    """The method applied to measured intervals (s) against their schedule, for a driving that
    holds ``held_rms_s``."""
    actual = np.asarray(actual_s, dtype=float)
    rms = rms_deviation_s(actual, scheduled_s)
    mean = float(actual.mean())
    return Assessment(int(actual.size), mean, rms, under_use(mean, rms), exact_interval_s(mean, rms),
                      float(held_rms_s), achievable_interval_s(mean, rms, held_rms_s),
                      capacity_gain(mean, rms, held_rms_s))
