"""Waveforms that repeat after a whole number of samples, so a core can compute one period
once and read each frame from it at (sample index mod period) instead of evaluating sines and
comparisons every frame (the coder's keyed carrier, the rail line's traction ripple)."""
from __future__ import annotations

import math
from typing import Iterable, Optional

_TOLERANCE = 1e-6      # samples: a period this close to a whole number is taken as whole
_MAX_MULTIPLE = 64     # 75 Hz at 4 kHz: 53⅓ samples, whole after 3 periods


def period_samples(periods_s: Iterable[float], fs_hz: float, limit: int) -> Optional[int]:
    """The fewest samples after which waveforms with these periods all repeat at the sample
    rate ``fs_hz``, or None when that is not a whole number within ``limit`` samples."""
    total = 1
    for period_s in periods_s:
        samples = period_s * fs_hz
        whole = next((round(m * samples) for m in range(1, _MAX_MULTIPLE + 1)
                      if abs(m * samples - round(m * samples)) < _TOLERANCE), None)
        if whole is None or whole <= 0:
            return None
        total = math.lcm(total, whole)
        if total > limit:
            return None
    return total
