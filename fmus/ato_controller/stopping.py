"""Precise stopping with a slow train brake: where will the train stop for each brake command?

A freight train's pneumatic brake answers a new demand only after its application delay
(ВЛ80 + 62 wagons: 8 s) and builds up or releases with a time constant (25 s), and the
locomotive's electric brake fades below 10 km/h. A controller that maps the distance left to
a deceleration now (braking.py ``TargetBraking.decel_to``) then keeps braking on the force it asked for
20–30 s earlier and stops metres short. The ATO instead keeps its own copy of the brake
pipeline (the demands it sent, their delay and the build-up, from the nominal stock data:
the traction unit's model, fmus/traction/brake_pipeline.py, docs/traction.md#physics-fmustractioncorepy) and, braking for a station stop below 30 km/h,
simulates the nominal train forward for a set of constant brake commands at once, choosing
the one whose predicted stopping point is the stop point (receding horizon: chosen again
every tenth of the brake's lead from the measured position and speed, so model errors are
corrected as the train closes in). The ATO book's НИИ УВМ predictive stopping (docs/sources.md#ato-precise-stopping): the
stopping point is predicted, not the deceleration. Used for brakes slower than
``AtoSettings.predictive_stop_lead_s``; docs/ato.md has the figures and the reasons.
"""
from __future__ import annotations

import math

import numpy as np

from fmus.ato_controller.train_model import NominalTrain
from fmus.traction.brake_pipeline import BrakePipeline, brake_lead_s

CANDIDATES = 21           # brake shares tried at once, MIN_SHARE … 1 (interpolated between)
HORIZON_S = 180.0         # longer than any stop from the final approach
PATH_GRID_M = 5.0         # gradient table resolution ahead of the train
NO_EFFECT_M = 0.01        # a command moving the stopping point less than this cannot act in time
# the share is chosen again every tenth of the brake's lead (delay + half the build-up), within
# these bounds, and held in between as the prediction assumes: a freight brake (lead 20.5 s)
# cannot act on a new choice sooner than 8 s anyway
REPLAN_MIN_S, REPLAN_MAX_S = 0.5, 2.0


class NominalBrake:
    """The ATO's nominal copy of the traction unit's pneumatic brake: the shared pipeline
    (per effective mass, m/s²) fed with the commands the ATO sent, its force in closed form."""

    def __init__(self, train: NominalTrain):
        stock = train.stock
        self.train = train
        # the ATO's clock runs on whole communication steps: a demand is due from 1e-9 s before
        self.pipeline = BrakePipeline(stock.brake_delay_s, stock.brake_time_constant_s, stock.emergency_decel,
                                      lambda v_mps: float(train.electric_brake(v_mps)), due_tolerance_s=1e-9)
        self.force = 0.0                 # pneumatic brake, m/s²
        self.time_s = None

    def command(self, t: float, command: float, emergency: bool) -> None:
        """The command sent to the train at ``t`` (the traction unit's convention)."""
        self.pipeline.command(t, max(-command, 0.0) * self.train.stock.service_decel, emergency)
        self.time_s = t

    def advance(self, t: float, v: float) -> None:
        """Bring the pneumatic force up to ``t`` (speed taken as ``v`` over the interval)."""
        if self.time_s is None:
            self.time_s = t
        if t <= self.time_s:
            return
        pipeline = self.pipeline
        now = self.time_s
        electric = pipeline.electric(v)
        while now < t:
            pipeline.take_due(now)
            until = min(pipeline.next_change_s(), t)
            self.force = pipeline.relax(self.force, pipeline.pneumatic_target(electric), until - now)
            now = until
        self.time_s = t

    def stopping_points(self, x: float, v: float, shares: np.ndarray, stop_m: float, path_accel,
                        dt_s: float) -> np.ndarray:
        """Predicted head position at standstill [m] for each constant brake share in ``shares``,
        starting now from (x, v) with the pipeline's current state. ``path_accel(x)`` is the
        gradient + curve retardation [m/s²] (vectorised). A candidate still moving past
        ``stop_m`` is not followed further: its point is extrapolated at its deceleration there
        (it only has to be known to lie beyond the stop point)."""
        train, pipeline = self.train, self.pipeline
        demand = shares * train.stock.service_decel
        x_k = np.full(shares.size, float(x))
        v_k = np.full(shares.size, float(v))
        force = np.full(shares.size, self.force)
        delayed = np.full(shares.size, pipeline.delayed)
        # the times at which the pneumatic brake's demand changes: what is queued, then the
        # command sent now, after the delay (integration steps end exactly there)
        changes = [(when, np.full(shares.size, value)) for when, value in pipeline.events]
        changes.append((self.time_s + pipeline.delay_s, demand))
        t = self.time_s
        end = t + HORIZON_S
        moving = v_k > 0.0
        while t < end:
            while changes and changes[0][0] <= t + pipeline.due_tolerance_s:
                delayed = changes.pop(0)[1]
            h = min(dt_s, changes[0][0] - t) if changes else dt_s
            electric = np.minimum(demand, train.electric_brake(v_k))
            target = np.maximum(delayed - electric, 0.0)
            # midpoint rule (second order: a 1 s step is then as good as the plant's RK4 to a
            # decimetre over a stop); the brake force at mid-step from its exponential
            force_mid = pipeline.relax(force, target, 0.5 * h)
            force_end = pipeline.relax(force, target, h)
            decel = electric + force_mid + train.coasting_resistance(v_k) + path_accel(x_k)
            v_mid = np.maximum(v_k - 0.5 * h * decel, 0.0)
            decel = np.maximum(np.minimum(demand, train.electric_brake(v_mid)) + force_mid
                               + train.coasting_resistance(v_mid) + path_accel(x_k + 0.5 * h * v_mid), 1e-6)
            force = force_end
            v_next = v_k - decel * h
            stopping = moving & (v_next <= 0.0)
            passed = moving & ~stopping & (x_k > stop_m)
            # standstill inside the step, or past the stop point: the distance still to run at
            # this deceleration
            ending = stopping | passed
            travelled = np.where(ending, v_k * v_k / (2.0 * decel), v_mid * h)
            x_k = np.where(moving, x_k + travelled, x_k)
            v_k = np.where(moving & ~ending, v_next, 0.0)
            moving = v_k > 0.0
            t += h
            if not moving.any():
                break
        return x_k


class StopApproach:
    """Chooses the brake share that stops the head at the stop point (see the module doc)."""

    def __init__(self, train: NominalTrain, min_share: float):
        self.train = train
        self.brake = NominalBrake(train)          # the ATO feeds it every step (AtoCore.step)
        self.shares = np.linspace(min_share, 1.0, CANDIDATES)
        stock = train.stock
        # integration step: a quarter of the build-up time constant, 0.1–1 s (midpoint rule: the
        # ВЛ80's stop predicted to 0.1 m at 1 s, test_ato.py)
        self.dt_s = max(0.1, min(1.0, 0.25 * max(stock.brake_time_constant_s, 0.4)))
        self.replan_s = max(REPLAN_MIN_S, min(REPLAN_MAX_S, 0.1 * brake_lead_s(stock)))
        self._path = None
        self._last = (-math.inf, None, 0.0)    # (time, stop point, share) of the last choice

    def _path_table(self, x: float, stop_m: float):
        if self._path is None or not (self._path[0][0] <= x and stop_m + 50.0 <= self._path[0][-1]):
            grid = np.arange(x - PATH_GRID_M, stop_m + 200.0, PATH_GRID_M)
            self._path = (grid, self.train.path_accel(grid))
        grid, values = self._path
        return lambda position: np.interp(position, grid, values)

    def share(self, t: float, x: float, v: float, stop_m: float) -> float:
        """Brake share (0–1) whose predicted stopping point is ``stop_m``."""
        planned_at, planned_for, planned_share = self._last
        if planned_for == stop_m and t < planned_at + self.replan_s - 1e-9:
            return planned_share
        points = self.brake.stopping_points(x, v, self.shares, stop_m, self._path_table(x, stop_m), self.dt_s)
        # more brake, shorter stop: the points fall with the share
        if points[0] - points[-1] < NO_EFFECT_M and planned_for == stop_m:
            share = planned_share      # the train stops before any new command acts: keep it
        elif points[0] <= stop_m:
            share = float(self.shares[0])
        elif points[-1] >= stop_m:
            share = 1.0
        else:
            k = int(np.argmax(points <= stop_m))
            s0, s1, p0, p1 = self.shares[k - 1], self.shares[k], points[k - 1], points[k]
            share = float(s0 + (s1 - s0) * (p0 - stop_m) / (p0 - p1)) if p0 != p1 else float(s1)
        self._last = (t, stop_m, share)
        return share
