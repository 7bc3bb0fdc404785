"""The pneumatic brake pipeline, written once: the traction plant (core.py) moves the train with
it, and the ATO keeps a nominal copy of it to predict where the train will stop
(fmus/ato_controller/stopping.py). docs/traction.md describes the physics.

A brake demand reaches the pneumatic brake only after the application (or release) delay; the
electric brake, where there is one, takes the demand as commanded at once, up to its curve, and
the pneumatic brake is asked for the rest of the delayed demand; its force follows that target
with a first-order build-up, dF/dt = (target − F)/T (T = 0: at once).

Units are the caller's: the plant works in newtons, the ATO's copy per effective mass (m/s²).
"""
from __future__ import annotations

import math
from collections import deque
from typing import Callable, Deque, Tuple


def brake_lead_s(stock) -> float:
    """How long a brake demand takes to act, to first order: the application delay plus half
    the build-up time constant (ЧС7's EP brake 2.5 s, ВЛ80 + 62 wagons 20.5 s)."""
    return stock.brake_delay_s + 0.5 * stock.brake_time_constant_s


def relax(force, target, dt_s: float, time_constant_s: float):
    """The pneumatic force after ``dt_s`` at a constant target: the exact solution of the
    build-up law (floats or numpy arrays)."""
    if time_constant_s <= 0.0:
        return target
    return target + (force - target) * math.exp(-dt_s / time_constant_s)


class BrakePipeline:
    """Brake demands on their way to the pneumatic brake, and what the pneumatic brake is asked
    for. The pneumatic force itself is the caller's state: the plant integrates it together
    with the motion, the ATO's copy in closed form (``relax``)."""

    def __init__(self, delay_s: float, time_constant_s: float, emergency_demand: float,
                 electric_brake: Callable[[float], float], due_tolerance_s: float):
        self.delay_s = delay_s
        self.time_constant_s = time_constant_s
        self.emergency_demand = emergency_demand
        self._electric_brake = electric_brake     # the electric brake's curve at a speed (0: none)
        # a queued demand acts from this much before its time on: the plant's own sub-step clock
        # lands on the event times but for rounding (1e-12 s), the ATO's on whole steps (1e-9 s)
        self.due_tolerance_s = due_tolerance_s
        self.events: Deque[Tuple[float, float]] = deque()   # (time the pneumatic brake acts on it, demand)
        self.delayed = 0.0                 # demand the pneumatic brake acts on now
        self.demand_now = 0.0              # demand as commanded (the electric brake acts at once)
        self.emergency = False
        self._last_requested = 0.0

    def command(self, time_s: float, service_demand: float, emergency: bool) -> None:
        """The brake demand commanded at ``time_s``: a service demand, or the emergency demand
        (the electric brake is then off)."""
        self.emergency = emergency
        self.demand_now = service_demand
        demand = self.emergency_demand if emergency else service_demand
        if demand != self._last_requested:
            # the pneumatic brake acts after its application (or release) delay
            self.events.append((time_s + self.delay_s, demand))
            self._last_requested = demand

    def take_due(self, time_s: float) -> None:
        """Hand the pneumatic brake every demand due by ``time_s``."""
        events = self.events
        while events and events[0][0] <= time_s + self.due_tolerance_s:
            self.delayed = events.popleft()[1]

    def next_change_s(self) -> float:
        """When the delayed demand changes next (inf: nothing queued)."""
        return self.events[0][0] if self.events else math.inf

    def electric(self, v_mps: float) -> float:
        """Electric brake: takes the current demand first, up to its curve; off in emergency."""
        if self.emergency or self.demand_now <= 0.0:
            return 0.0
        return min(self.demand_now, self._electric_brake(v_mps))

    def pneumatic_target(self, electric: float) -> float:
        """What the pneumatic brake is asked for: the delayed demand less the electric brake."""
        return max(self.delayed - electric, 0.0)

    def build_up_rate(self, force: float, target: float) -> float:
        """dF/dt of the pneumatic force (0 for an immediate brake: the caller sets it to its target)."""
        tau = self.time_constant_s
        return (target - force) / tau if tau > 0.0 else 0.0

    def relax(self, force, target, dt_s: float):
        return relax(force, target, dt_s, self.time_constant_s)
