"""What the ATO brakes for and how hard (core.py): the targets ahead — the timetable's stop
point, the ATP's targets with the ATO's margins, its own targets under an ALSN aspect — and the
deceleration each asks for, computed for where the train will be when a new brake demand takes
effect (the pneumatic brake's dead time, from the measured acceleration). The core decides
which target it brakes for and how (its controllers, the precise stop)."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import List, Optional, Tuple

from fmus.units import STANDARD_GRAVITY_MPS2

_INF = math.inf
ACCEL_FILTER_S = 1.0
# an immediate stop (the ATP's stop_now) is a target this far beyond the planned stopping point
STOP_NOW_SLACK_M = 0.5
# the predicted (dead-time compensated) deceleration is used only while the target lies more
# than this beyond the predicted position; nearer, the measured one
PREDICTION_MIN_DISTANCE_M = 0.5
# a target nearer than this is reached: brake fully if still too fast, else release
AT_TARGET_M = 0.05
# a speed target counts as reached within this of its speed (then it is held, not braked for)
TARGET_SPEED_REACHED_MPS = 0.05
# a target held is the same as a target offered when they are this close in place and speed
SAME_TARGET_M = 1.0
SAME_TARGET_MPS = 0.01


@dataclass(frozen=True, slots=True)
class BrakingTarget:
    """A point ahead the ATO brakes for: the train's head at ``position_m`` at no more than
    ``speed_mps`` (the timetable's stop point, a stop short of a signal at danger, a lower
    limit, a stop on red)."""

    position_m: float
    speed_mps: float
    is_stop_point: bool = False     # the timetable's stop point: arrival, precise stopping
    braking_share: float = 1.0      # of the planned deceleration (ALSU: gentler for a permanent restriction)


class TargetBraking:
    """The ATO's targets and their decelerations for one train: ``settings`` (AtoSettings: the
    margins, the cab signal), ``a_plan`` its planned deceleration, ``brake_lead_s`` the time
    until a brake demand takes effect, ``atp`` the ATP whose blocks the ALSN targets lie at,
    ``timetable`` the stops (each stage's stop point a target, built once)."""

    def __init__(self, settings, category: str, a_plan: float, brake_lead_s: float, atp, timetable):
        self.settings, self.category = settings, category
        self.a_plan = a_plan
        self.brake_lead_s = brake_lead_s
        self.atp = atp
        self._stop_targets = [BrakingTarget(stop.stop_m, 0.0, is_stop_point=True) for stop in timetable[1:]]
        self._t_prev, self.v_prev, self._accel = None, 0.0, 0.0

    def measure(self, t: float, v: float) -> None:
        """The speed measured at ``t``: the acceleration estimate follows it."""
        if self._t_prev is not None and t > self._t_prev:
            # measured acceleration, low-pass filtered (1 s) so the prediction does not depend
            # on the step size nor chatter when the electric brake steps in
            dt = t - self._t_prev
            self._accel += (dt / (ACCEL_FILTER_S + dt)) * ((v - self.v_prev) / dt - self._accel)
        self._t_prev, self.v_prev = t, v

    def targets(self, stage: int, x: float, v: float, atp_result) -> List[BrakingTarget]:
        """What the ATO brakes for in timetable stage ``stage``, ahead of the head: the stop
        point and the ATP's targets with the ATO's margins."""
        s = self.settings
        stop_point = self._stop_targets[stage]
        targets = [stop_point]
        for target in atp_result.constraints.targets:
            if target.signal and self.atp.cab.station_stop_replaces_signal_stops \
                    and target.position_m >= stop_point.position_m - s.stop_window_m:
                continue        # a TVM stop at the station's stop point (or beyond): the stop point itself
            share = target.braking_share * self._gradient_share(target)
            if target.signal:
                targets.append(BrakingTarget(target.position_m - s.stop_margin_m, 0.0, braking_share=share))
            else:
                targets.append(BrakingTarget(target.position_m, max(target.speed_mps - s.speed_margin_mps, 0.0),
                                             braking_share=share))
        if atp_result.stop_now:
            targets.append(BrakingTarget(x + v * v / (2.0 * self.a_plan) + STOP_NOW_SLACK_M, 0.0))
        targets.extend(self.aspect_driving(x, atp_result)[1])
        return targets

    def _gradient_share(self, target) -> float:
        """TVM430: the ATP's curves take a falling transmitted gradient's pull off the braking
        (atp.py); the ATO's planned curve for the same target gives up as much, so it stays under
        them on a falling grade (else its curve, braking on the level, crosses theirs and the ATP
        intervenes). 1 for every other target."""
        if target.trip_speed_mps is None or target.gradient_permille >= 0.0:
            return 1.0
        pull = STANDARD_GRAVITY_MPS2 * -target.gradient_permille / 1000.0
        return max(self.a_plan - pull, 0.1 * self.a_plan) / self.a_plan

    def aspect_driving(self, x: float, atp_result) -> Tuple[float, List[BrakingTarget]]:
        """How the ATO itself drives under the aspect the ATP acts upon, in the modes that give
        it speeds of its own (CabSignalMode.driving_speeds; ALSN: the book's МИИТ reactions,
        fmus/signalling/aspects.py ``ALSN_DRIVING_KMH``): the top of its band and its own target
        at the exit signal, below the supervised speeds."""
        band, at_signal = self.atp.cab.driving_speeds(self.category, atp_result.aspect)
        targets = []
        if at_signal is not None and at_signal > 0.0:
            k = self.atp.section_of(x)
            if k is not None:
                targets.append(BrakingTarget(self.atp.exit_signal_m(k), at_signal))
        return (_INF if band is None else band), targets

    def _predict(self, x: float, v: float):
        """Head position and speed one brake lead time ahead at the measured acceleration: the
        pneumatic brake answers a new demand only after its delay and build-up, so demands
        are computed for where the train will be when they take effect (dead-time compensation)."""
        lead = self.brake_lead_s
        a = self._accel
        if v + a * lead <= 0.0:
            return x, v
        return x + v * lead + 0.5 * a * lead * lead, v + a * lead

    def decel_to(self, x: float, v: float, position: float, speed: float) -> float:
        """The deceleration that brings the train from (x, v) to ``speed`` at ``position``: from
        where the train will be when a new demand takes effect (_predict) while that lies short
        of the target, else from now; inf for a target reached too fast."""
        xp, vp = self._predict(x, v)
        if vp > speed and position - xp > PREDICTION_MIN_DISTANCE_M:
            return (vp * vp - speed * speed) / (2.0 * (position - xp))
        distance = position - x
        if distance <= AT_TARGET_M:
            return _INF if v > speed else 0.0
        return max((v * v - speed * speed) / (2.0 * distance), 0.0)

    def required_decel(self, x: float, v: float,
                       targets: List[BrakingTarget]) -> Tuple[float, Optional[BrakingTarget]]:
        """The highest deceleration the targets ask for now, each relative to its braking share
        (a gentle target's need counts as if the planned deceleration were its share of it),
        and which one asks for it."""
        best, which = 0.0, None
        for target in targets:
            if v <= target.speed_mps:
                continue
            need = self.decel_to(x, v, target.position_m, target.speed_mps) / target.braking_share
            if need > best:
                best, which = need, target
        return best, which

    def lets_go(self, held: Optional[BrakingTarget], v: float, targets: List[BrakingTarget]) -> bool:
        """Whether the target braked for (``held``) is let go: a speed target once its speed is
        reached (then held) or when it is lifted (no target of ``targets`` is it any more); the
        stop point never (only by arriving or creeping on)."""
        if held is None or held.is_stop_point:
            return False
        if v <= held.speed_mps + TARGET_SPEED_REACHED_MPS:
            return True                         # target speed reached: hold it
        # lifted: a better code, or the ATP's assumption after passing a signal expired once
        # the new section was decoded: release the brake
        return not any(abs(other.position_m - held.position_m) < SAME_TARGET_M
                       and other.speed_mps <= held.speed_mps + SAME_TARGET_MPS for other in targets)
