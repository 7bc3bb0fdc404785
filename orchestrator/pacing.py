"""Real-time pacing of the master (``railcosim run … --real-time [FACTOR]``).

A manipulator that changes no value: before each base step it waits for that step's wall-clock
deadline, so simulated time advances ``factor`` times as fast as the wall clock (1: real time,
as a bench or a soft-real-time DCP slave needs). Deadlines are absolute from the first tick, so
a late step is caught up by the steps after it and the run does not drift. A step that starts
after its deadline is an overrun: counted, with the worst lateness (docs/interfaces.md,
"summary.json", ``real_time``). Without ``--real-time`` the pacer is not made at all: nothing
costs anything.
"""
from __future__ import annotations

import math
import time
from typing import Dict, Optional

from orchestrator.errors import UserError
from orchestrator.graph import TICKS_PER_SECOND
from orchestrator.interrupts import NEVER, InterruptFlag
from orchestrator.protocols import Manipulator, MasterView

#: the last part of a wait is spun rather than slept: a sleep on a loaded machine wakes up to a
#: few hundred microseconds late, a spin of this length costs little CPU
SPIN_S = 0.0005
#: sleeps in slices of this length, so a signal (Ctrl-C) is seen at once even at slow factors
SLICE_S = 0.05
#: the fastest and slowest pacing accepted: beyond, a base step of 1 ms would be far below the
#: timer's resolution, or a 1-s step would wait longer than a day
MAX_FACTOR, MIN_FACTOR = 1000.0, 1e-4


def check_factor(factor: float) -> float:
    if not (math.isfinite(factor) and MIN_FACTOR <= factor <= MAX_FACTOR):
        raise UserError(f"--real-time {factor!r}: must be a number from {MIN_FACTOR:g} to {MAX_FACTOR:g} "
                        "(simulated seconds per wall-clock second; 1 is real time)")
    return float(factor)


class Pacer(Manipulator):
    """Holds each tick back until its wall-clock deadline; counts the ticks that start late."""

    def __init__(self, factor: float, interrupt: InterruptFlag = NEVER, clock=time.perf_counter,
                 sleep=time.sleep):
        self.factor = check_factor(factor)
        self.interrupt = interrupt
        self._clock, self._sleep = clock, sleep
        self._epoch: Optional[float] = None       # wall time of the first tick
        self._first_tick = 0
        self.steps = 0                            # base steps paced (the first one sets the epoch)
        self.overruns = 0
        self.worst_lateness_s = 0.0
        self.total_lateness_s = 0.0
        self.step_wall_s = 0.0                    # one base step in wall-clock seconds

    def bound(self, master: MasterView) -> None:
        self.step_wall_s = master.graph.base_ticks / TICKS_PER_SECOND / self.factor

    def deadline(self, tick: int) -> float:
        return self._epoch + (tick - self._first_tick) / TICKS_PER_SECOND / self.factor

    def before_tick(self, master: MasterView, tick: int) -> None:
        clock = self._clock
        self.steps += 1
        if self._epoch is None:               # the first step starts the wall clock: never late
            self._epoch, self._first_tick = clock(), tick
            return
        deadline = self.deadline(tick)
        now = clock()
        if now > deadline:                  # the step before this one ended late
            lateness = now - deadline
            self.overruns += 1
            self.total_lateness_s += lateness
            if lateness > self.worst_lateness_s:
                self.worst_lateness_s = lateness
            return
        self.wait_until(deadline)

    def wait_until(self, deadline: float) -> None:
        """Sleep most of the way (in slices, a signal ends the wait), spin the rest."""
        clock, interrupt = self._clock, self.interrupt
        remaining = deadline - clock()
        while remaining > SPIN_S:
            if interrupt.signum:
                return
            self._sleep(min(remaining - SPIN_S, SLICE_S))
            remaining = deadline - clock()
        while clock() < deadline:
            pass

    @property
    def kept_pace(self) -> bool:
        """[U] kept pace: no step started a whole base step (of wall time) late, i.e. the master
        was never a full step behind the wall clock; smaller lateness is caught up at once."""
        return self.worst_lateness_s < self.step_wall_s

    def summary_section(self) -> Dict[str, object]:
        return {"real_time": {
            "factor": self.factor,
            "steps": self.steps,
            "overruns": self.overruns,
            "worst_lateness_ms": self.worst_lateness_s * 1e3,
            "mean_lateness_ms": self.total_lateness_s / self.overruns * 1e3 if self.overruns else 0.0,
            "step_wall_ms": self.step_wall_s * 1e3,
            "kept_pace": self.kept_pace,
        }}

    def verdict_line(self) -> Optional[str]:
        """One line for stderr when the run could not keep pace, else None (also when it never
        stepped: a run that failed before its first step has no pace to judge)."""
        if self.kept_pace or self.steps == 0:
            return None
        return (f"--real-time {self.factor:g}: the run could not keep pace: {self.overruns} of {self.steps} "
                f"steps started late, worst by {self.worst_lateness_s * 1e3:.1f} ms "
                f"(a base step is {self.step_wall_s * 1e3:.3g} ms of wall time)")
