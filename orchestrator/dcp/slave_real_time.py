"""Soft real time in ``railcosim dcp-slave`` (docs/hil.md#operating-modes): once running, the
slave follows its own monotonic clock; every period it applies the latest inputs, steps the
FMU and sends the outputs due, whether or not the master keeps up (late steps are counted and
reported, none skipped), and it stops a session whose FMU cannot keep the period.
"""
from __future__ import annotations

import math
import time

from orchestrator.dcp.pdu import State
from orchestrator.errors import SimulationError, UserError

#: a soft real-time session stops when, over a window of this many seconds holding at least this
#: many steps, at least this share of the steps overran: a stall caught up (the steps after it
#: on time) stays far below the share, an FMU that cannot keep its period (or a host that gives it
#: too little time) stays above it, whether or not a step now and then is on time
OVERRUN_STOP_S, OVERRUN_STOP_STEPS, OVERRUN_STOP_SHARE = 2.0, 50, 0.9
#: overruns are reported as they happen, at most one line per this many seconds
OVERRUN_REPORT_S = 1.0


class SoftRealTime:
    """The clock of one running session (``slave``: its DcpSlaveServer). The FMU steps by the
    greatest common divisor of the outputs' periods; each output goes out at its own period."""

    def __init__(self, slave, start_time: int):
        self.slave = slave
        periods = [config.steps for config in slave.config.outputs.values()]
        own = slave.served.own_step_units(slave.config.resolution)
        self.steps = math.gcd(*periods, *([own] if own else [])) or 1
        num, den = slave.config.resolution
        self.period_s = self.steps * num / den
        start = time.time() if start_time <= 0 else float(start_time)
        #: the next step's deadline: the first at the start time (wall clock), on the monotonic clock
        self.deadline = time.monotonic() + max(0.0, start - time.time())
        self.count = 0                  # resolution units stepped
        self.overrun_reported = -math.inf
        self._new_overrun_window(time.monotonic())

    def _new_overrun_window(self, now: float) -> None:
        self.window_start, self.window_steps, self.window_overruns = now, 0, 0

    def _kept(self, now: float, late: bool, lateness: float) -> bool:
        """Count one real-time step in the current window of OVERRUN_STOP_S; at the window's end,
        stop the session (False) when it held OVERRUN_STOP_STEPS steps or more of which the share
        OVERRUN_STOP_SHARE or more overran: the FMU cannot be stepped at this period in real time."""
        self.window_steps += 1
        self.window_overruns += late
        if now - self.window_start < OVERRUN_STOP_S:
            return True
        steps, overruns = self.window_steps, self.window_overruns
        self._new_overrun_window(now)
        if steps < OVERRUN_STOP_STEPS or overruns < OVERRUN_STOP_SHARE * steps:
            return True
        self.slave.clock = None
        self.slave.fail(f"real time not kept, session stopped: {overruns} of the last {steps} real-time steps started "
                        f"more than a period ({self.period_s * 1e3:g} ms) late, {lateness * 1e3:.1f} ms at the last: "
                        "the FMU cannot be stepped at this period in real time")
        return False

    def _overrun(self, now: float, lateness: float) -> None:
        """Count and report an overrun as it happens (one line at most every OVERRUN_REPORT_S)."""
        counters = self.slave.counters
        counters.overruns += 1
        period_ms = self.period_s * 1e3
        if now - self.overrun_reported >= OVERRUN_REPORT_S:
            self.overrun_reported = now
            self.slave.warn(f"overrun: real-time step {self.count // self.steps + 1} started "
                            f"{lateness * 1e3:.1f} ms late (period {period_ms:g} ms); {counters.overruns} "
                            f"overrun(s) so far")

    def tick(self) -> None:
        """One real-time step (called at or after its deadline)."""
        slave = self.slave
        now = time.monotonic()
        lateness = now - self.deadline
        slave.counters.worst_lateness_s = max(slave.counters.worst_lateness_s, lateness)
        late = lateness > self.period_s      # started more than a period late
        if late:
            self._overrun(now, lateness)
        if not self._kept(now, late, lateness):
            return
        try:
            slave.step(self.steps)
        except (SimulationError, UserError) as error:
            slave.clock = None
            slave.fail(str(error))
            return
        self.count += self.steps
        due = {d for d, c in slave.config.outputs.items() if self.count % c.steps == 0}
        slave.exchange.send_outputs(initialization=False, due=due)
        self.deadline += self.period_s
        if slave.state == State.SYNCHRONIZING:       # the clock has started: synchronised
            slave.set_state(State.SYNCHRONIZED)
