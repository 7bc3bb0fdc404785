"""The temporary speed restrictions one train keeps (docs/ato.md): the line file's for its
category and those set while running (the ATO FMU's ``tsr_*`` inputs), each a ceiling from the
head reaching its start until the tail has cleared its end (the tail rule of the line's
limits), and a target at its start while ahead. The ATP supervises them (atp.py); the ATO
drives under them."""
from __future__ import annotations

import functools
import math
from typing import Tuple

from fmus.ato_controller.supervision import Constraints, Target
from fmus.data.loader import Line, TemporaryRestriction


class SpeedRestrictions:
    #: temporary restrictions set while running (set_events), besides the line file's
    events: Tuple[TemporaryRestriction, ...] = ()

    def __init__(self, line: Line, category: str, train_length_m: float, supervision_decel_mps2: float):
        self.line, self.category, self.length_m = line, category, train_length_m
        self.decel = supervision_decel_mps2

    def set_events(self, restrictions) -> None:
        """The restrictions set while running, replacing the last set."""
        self.events = tuple(restrictions)

    @functools.cached_property
    def of_line(self) -> Tuple[TemporaryRestriction, ...]:
        """The line file's temporary restrictions for this train's category."""
        return tuple(self.line.restrictions_for(self.category))

    def in_force(self) -> Tuple[TemporaryRestriction, ...]:
        """Every temporary restriction this train keeps: the line file's, then those set while running."""
        return self.of_line + self.events

    def speed_at(self, x: float) -> float:
        """The lowest restriction in force at the head (held until the tail clears its end); inf: none."""
        tail = x - self.length_m
        return min((r.speed_mps for r in self.in_force() if r.start_m <= x and tail < r.end_m), default=math.inf)

    def constraints(self, x: float, v: float) -> Constraints:
        """The ceiling of the restrictions at the head, and a target at the start of each one
        ahead within braking reach (+ 200 m)."""
        c = Constraints(self.speed_at(x))
        reach = x + v * v / (2.0 * self.decel) + 200.0
        c.targets.extend(Target(r.start_m, r.speed_mps) for r in self.in_force() if x < r.start_m <= reach)
        return c
