"""Online driving: strategies that choose what the train should do now, and the two low-level
controllers that turn that into a command (speed holding, target braking).

Strategies (ATO book, docs/sources.md#ato-timetable-following):

* ``programme`` — АМ ЦНИИ coast-speed control on the energy-efficient programme: traction up
  to the programme's cruise speed, then the programme's regime (cruise / coast); ahead of
  time the cruise speed is lowered by k1·Δt, late the traction is kept k2·Δt longer where the
  programme starts to coast.
* ``predictive`` — НИИ УВМ / ATOMIC-like: at every step the remaining running time of each
  programme of the stage's family (one per cruise speed, computed offline) predicts the
  arrival; the most economical programme that arrives on time is driven (with hysteresis).
* ``flat_out`` — the minimum-time profile (maximum traction, line speed, latest braking):
  the energy baseline.

Rules common to all (docs/sources.md#ato-timetable-following): late by more than ``late_threshold_s`` (МИИТ: 16 s),
or after a restrictive cab signal has cleared while late, drive at the maximum permitted speed
until back on schedule.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from fmus.ato_controller.planner import REGIME_TRACTION, StagePlan
from fmus.ato_controller.train_model import NominalTrain

STRATEGIES = ("programme", "predictive", "flat_out")
_INF = math.inf


@dataclass
class Guidance:
    """What a strategy wants at the current position."""

    cruise_mps: float            # speed to accelerate to and hold (inf: the ceiling)
    coast: bool                  # True: no traction (the programme coasts here)
    v_ref_mps: float             # the reference programme's speed here
    t_ref_s: float               # the reference programme's time since departure here
    programme: int               # index in the stage family


class Strategy(ABC):
    def __init__(self, plan: StagePlan, k1: float, k2: float):
        self.plan, self.k1, self.k2 = plan, k1, k2
        self.current = plan.chosen
        self._extend_until = -_INF
        self._was_coasting = False

    def _index(self, x: float) -> int:
        plan = self.plan
        i = int((x - plan.start_m) / (plan.s[1] - plan.s[0]))
        return min(max(i, 0), plan.s.size - 2)

    def reference(self, programme: int, x: float):
        plan = self.plan
        v = np.interp(x, plan.s, plan.family.v[programme])
        t = np.interp(x, plan.s, plan.family.t[programme])
        return float(v), float(t)

    @abstractmethod
    def guide(self, t_run: float, x: float, v: float, deviation_s: float) -> Guidance:
        """What to do at head position x, t_run seconds after the scheduled departure."""


class ProgrammeFollowing(Strategy):
    """Coast-speed control with k1 (ahead) and k2 (late) corrections."""

    def guide(self, t_run, x, v, deviation_s):
        p = self.current
        plan = self.plan
        i = self._index(x)
        regime = int(plan.family.regime[p, i])
        cruise = float(plan.family.cruise_mps[p])
        v_ref, t_ref = self.reference(p, x)
        if deviation_s < 0.0:
            cruise = cruise + self.k1 * deviation_s          # ahead: lower the coast speed
        coasting = regime != REGIME_TRACTION
        if coasting and not self._was_coasting and deviation_s > 0.0:
            self._extend_until = t_run + self.k2 * deviation_s
        self._was_coasting = coasting
        if coasting and t_run < self._extend_until:
            coasting = False                                   # late: keep traction longer
        return Guidance(cruise, coasting, v_ref, t_ref, p)


class Predictive(Strategy):
    """Re-select, at every step, the most economical programme predicted to arrive on time."""

    HYSTERESIS_S = 4.0

    def guide(self, t_run, x, v, deviation_s):
        plan = self.plan
        family = plan.family
        times = family.time_s
        position = np.interp(x, plan.s, np.arange(plan.s.size))
        i0 = min(int(position), plan.s.size - 2)
        frac = position - i0
        t_here = family.t[:, i0] * (1.0 - frac) + family.t[:, i0 + 1] * frac
        remaining = times - t_here
        scheduled = plan.scheduled_time_s if plan.scheduled_time_s is not None else times[plan.minimum]
        arrival = t_run + remaining                       # predicted arrival (time since departure)
        current_arrival = arrival[self.current]
        if not (scheduled - 2.0 * self.HYSTERESIS_S <= current_arrival <= scheduled + 0.25 * self.HYSTERESIS_S):
            on_time = np.nonzero(arrival <= scheduled)[0]
            # family is sorted longest first: the first on-time programme is the most economical
            self.current = int(on_time[0]) if on_time.size else plan.minimum
        p = self.current
        regime = int(family.regime[p, min(i0, family.regime.shape[1] - 1)])
        v_ref, t_ref = self.reference(p, x)
        return Guidance(float(family.cruise_mps[p]), regime != REGIME_TRACTION, v_ref, t_ref, p)


class FlatOut(Strategy):
    def __init__(self, plan, k1, k2):
        super().__init__(plan, k1, k2)
        self.current = plan.minimum

    def guide(self, t_run, x, v, deviation_s):
        v_ref, t_ref = self.reference(self.current, x)
        return Guidance(_INF, False, v_ref, t_ref, self.current)


def make_strategy(name: str, plan: StagePlan, k1: float, k2: float) -> Strategy:
    return {"programme": ProgrammeFollowing, "predictive": Predictive, "flat_out": FlatOut}[name](plan, k1, k2)


class Controllers:
    """Speed holding and target braking over the nominal train model.

    Commands follow the traction unit's convention: share of maximum traction (> 0) or of the
    full-service brake demand m(1+γ)·a_service (< 0).
    """

    def __init__(self, train: NominalTrain, speed_gain: float, hysteresis_mps: float):
        self.train = train
        self.gain = speed_gain
        self.hysteresis = hysteresis_mps
        self.coasting = False

    def hold(self, x: float, v: float, v_set: float, may_brake: bool) -> float:
        """Accelerate to and hold ``v_set``; brake only when ``may_brake`` (above a ceiling)."""
        tr = self.train
        natural = float(tr.resistance(v)) + tr.path_accel_at(x)     # retardation, m/s²
        wanted = natural + self.gain * (v_set - v)
        if wanted > 0.0:
            if self.coasting and v > v_set - self.hysteresis:
                return 0.0
            self.coasting = False
            return min(wanted / max(float(tr.max_traction(v)), 1e-6), 1.0)
        self.coasting = True
        if may_brake:
            return max(wanted / tr.service_decel, -1.0)
        return 0.0

    def brake(self, x: float, v: float, decel_mps2: float) -> float:
        """Brake command for a total deceleration ``decel_mps2`` (resistance and grade help)."""
        tr = self.train
        self.coasting = True
        natural = float(tr.coasting_resistance(v)) + tr.path_accel_at(x)
        return -min(max((decel_mps2 - natural) / tr.service_decel, 0.0), 1.0)
