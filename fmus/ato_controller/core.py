"""ATP + ATO controller core (no FMI): one train, one timetable, one line.

Per communication step: the ATP supervises (atp.py); the ATO follows the timetable stage by
stage — wait for the departure time, drive the stage with the chosen strategy (driving.py)
over the programmes planned at initialisation (planner.py), brake to the stop point,
dwell — and the ATP's intervention overrides the ATO's command.

Phases: waiting at a stop (before departure) → running → stopped at the stop point (arrival
recorded, dwell) → … → finished at the last stop.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import List, Optional, Tuple

import numpy as np

from fmus.signalling import alsn
from fmus.signalling import aspects as sig
from fmus.signalling.ato_modes import AtoMode
from fmus.data.loader import Line, RollingStock, TemporaryRestriction, TimetableStop
from fmus.errors import FmuInputError
from fmus.ato_controller.atp import (CAB_SIGNAL_MODES, EMERGENCY_INTERVENTION, NO_INTERVENTION,
                                     SERVICE_INTERVENTION, STANDSTILL_MPS, Atp, AtpResult)
from fmus.ato_controller.atp_modes import CabSignalMode, Indication
from fmus.ato_controller.braking import BrakingTarget, TargetBraking
from fmus.ato_controller.supervision import Constraints
from fmus.ato_controller.driving import STRATEGIES, Controllers, make_strategy
from fmus.ato_controller.planner import InfeasibleStage, StagePlanner
from fmus.ato_controller.stopping import StopApproach
from fmus.ato_controller.train_model import NominalTrain
from fmus.traction.brake_pipeline import brake_lead_s
from fmus.traction.core import MAX_SPEED_MPS  # noqa: F401  (the facade's declared bound of speed_margin)
from fmus.units import MPS_PER_KMH

_INF = math.inf

# mode output (Integer)
MODE_STANDSTILL, MODE_TRACTION, MODE_COAST, MODE_BRAKE, MODE_ATP_SERVICE, MODE_ATP_EMERGENCY = range(6)
MODE_NAMES = {MODE_STANDSTILL: "standstill", MODE_TRACTION: "traction", MODE_COAST: "coast", MODE_BRAKE: "brake",
              MODE_ATP_SERVICE: "ATP service", MODE_ATP_EMERGENCY: "ATP emergency"}
WAITING, RUNNING, DWELLING, FINISHED = "waiting", "running", "dwelling", "finished"
# no train brakes harder: the adhesion limit is about 0.35 g (declared maximum of the decelerations)
MAX_DECEL_MPS2 = 5.0
# a measured speed below −this is impossible, not noise at standstill (docs/ato.md, "Measurement faults")
NEGATIVE_SPEED_TOLERANCE_MPS = 0.2
MIN_BRAKE_SHARE = 0.02
# the decelerations derived from the stock's service deceleration when no parameter sets them
# (docs/ato.md): the ATP supervises at 0.7 × it, the ATO plans at 0.6 × it but at most
# 0.5 m/s², so the ATO's curve stays inside the ATP's
ATP_DECEL_SHARE = 0.7
PLAN_DECEL_SHARE = 0.6
PLAN_DECEL_MAX_MPS2 = 0.5
# braking for a target begins once it needs this share of the planned deceleration (a little
# before it needs all of it, so the brake's build-up does not overshoot the curve)
BRAKE_ONSET_SHARE = 0.97
# a target is braked for at most this multiple of the planned deceleration (the ATP's curve
# lies between the two)
TARGET_DECEL_CAP = 2.0
# coasting in a restriction's band starts this close below the set speed
BAND_TOP_MPS = 0.05
# speeds that differ by float rounding only compare equal
SPEED_ROUNDING_MPS = 1e-6
# the departure time counts as come when the clock is this close to it (float rounding)
DEPARTURE_ROUNDING_S = 1e-9
# a cab signal permits going only above this speed (a "stop" code permits 0)
MIN_PERMITTED_TO_START_MPS = 1.0
CREEP_SPEED_MPS = 5.0 * MPS_PER_KMH      # to close up to the stop point after stopping short of the window
# two-stage stop with a slow brake (docs/sources.md#ato-precise-stopping, ATOMIC): the planned deceleration down to this
# speed, then the brake share whose predicted stopping point is the stop point (stopping.py)
FINAL_APPROACH_MPS = 30.0 * MPS_PER_KMH
# inside a temporary restriction the ATO drives traction–coast between v_limit − 8 km/h and its
# ceiling (the ATO book's МИИТ rule, docs/sources.md#temporary-speed-restrictions)
RESTRICTION_BAND_MPS = 8.0 * MPS_PER_KMH
# temporary restrictions the FMU can be given while running (its tsr_* input slots)
TSR_SLOTS = 4
# a digital receiver shows no code at once while it re-acquires the next section's signal after
# a joint (0.8-2.7 s in the shipped digital systems); for this long a loss only shuts off
# traction, then the ATO brakes for the no-code speed on the ATP's curve (docs/ato.md,
# "Short losses of a digital code") [U]
DIGITAL_CODE_LOSS_GRACE_S = 3.0


def judged_measurements(cab_signal: str) -> Tuple[str, ...]:
    """The measurements whose impossible values the ATP answers with the emergency brake
    (measurement_fault) in a cab-signal mode: position and speed always, and the inputs the
    mode reads (CabSignalMode.inputs: the aspect with a cab signal, the digital speeds and free
    blocks with a digital one, …). The others the controller does not read in that mode."""
    mode = CAB_SIGNAL_MODES.get(cab_signal)
    return ("x", "v") + (() if mode is None else mode.inputs)


def measurement_fault(mode: CabSignalMode, x: float, v: float, shown: Indication) -> Optional[Tuple[str, str]]:
    """(input, why) when a measurement the ATP relies on cannot be true in cab-signal mode
    ``mode`` (the ATP's), else None. Which measurements it judges: :func:`judged_measurements`."""
    if not math.isfinite(x):
        return "x", f"measured position x = {x:g} m is not finite"
    if not math.isfinite(v) or v < -NEGATIVE_SPEED_TOLERANCE_MPS:
        return "v", f"measured speed v = {v:g} m/s is impossible"
    return mode.fault(shown)


def plan_stages(planner: StagePlanner, timetable: List[TimetableStop], timetable_path) -> list:
    """The programme of every stage of the timetable (planner.py), planned at initialisation; a
    stage whose scheduled running time is shorter than the minimum is the timetable's error."""
    plans = []
    for k in range(len(timetable) - 1):
        origin, destination = timetable[k], timetable[k + 1]
        scheduled = destination.arrival_s - origin.departure_s
        try:
            plans.append(planner.plan(origin.stop_m, destination.stop_m, scheduled))
        except InfeasibleStage as infeasible:
            raise FmuInputError(
                f"{timetable_path}: field stops[{k + 1}].arrival_s: scheduled running time {scheduled:g} s "
                f"from {origin.station} to {destination.station} is shorter than the minimum running time "
                f"{infeasible.minimum_time_s:.1f} s (earliest arrival "
                f"{origin.departure_s + infeasible.minimum_time_s:.1f} s)") from None
    return plans


def event_restrictions(starts_m, ends_m, speeds_mps) -> List[TemporaryRestriction]:
    """The restrictions in force among the FMU's ``tsr_*`` slots: speed > 0 and end > start."""
    return [TemporaryRestriction(float(a), float(b), float(v), name=f"tsr[{k + 1}]")
            for k, (a, b, v) in enumerate(zip(np.ravel(starts_m), np.ravel(ends_m), np.ravel(speeds_mps)))
            if v > 0.0 and b > a]


def default_plan_decel_mps2(stock, cab_signal: str) -> float:
    """The ATO's planned deceleration when parameter ``braking_decel`` is 0: 0.6 × the stock's
    service deceleration, at most 0.5 m/s² — except in the modes that take off the cap
    (CabSignalMode.plan_decel_capped): TVM430, whose block rules announce a stop only four blocks
    ahead, so a train at 300 km/h must plan at 0.58 m/s² or more (docs/ato.md#tvm-430)."""
    planned = PLAN_DECEL_SHARE * stock.service_decel
    mode = CAB_SIGNAL_MODES.get(cab_signal)
    return planned if mode is not None and not mode.plan_decel_capped else min(PLAN_DECEL_MAX_MPS2, planned)


def default_atp_decel_mps2(stock) -> float:
    """The ATP's supervision deceleration when parameter ``atp_decel`` is 0: 0.7 × the stock's service deceleration."""
    return ATP_DECEL_SHARE * stock.service_decel


@dataclass
class AtoSettings:
    strategy: str = "programme"
    cab_signal: str = AtoMode.ALSN
    braking_decel_mps2: float = 0.0       # 0: min(0.5, 0.6 × service deceleration)
    atp_decel_mps2: float = 0.0           # 0: 0.7 × service deceleration
    speed_margin_mps: float = 2.0 * MPS_PER_KMH   # ATO drives this far below every limit
    stop_margin_m: float = 30.0           # stop this far before a signal at danger
    k1: float = 0.1                       # m/s of cruise speed per s ahead
    k2: float = 1.0                       # s of extra traction per s late
    late_threshold_s: float = 16.0        # МИИТ: later than this → maximum permitted speed
    early_threshold_s: float = 8.0        # earlier than this → hold the programme speed (brake if need be)
    min_dwell_s: float = 20.0
    stop_window_m: float = 5.0            # standing at most this far short of the stop point is an arrival
    hold_brake: float = 0.3               # brake share held while standing
    decoding_latency_s: float = alsn.STATED_LATENCY_S   # the ALSN receiver's stated latency, 4.5 s (docs/loco_receiver.md#latency-of-a-change)
    speed_gain: float = 0.2               # 1/s, speed-holding loop
    hysteresis_mps: float = 1.0 * MPS_PER_KMH     # coast → traction again only this far below the set speed
    brake_lead_s: float = -1.0            # < 0: brake delay + half its time constant (nominal stock)
    # stop by predicting the stopping point (stopping.py) when the brake lead is longer than this:
    # a freight pneumatic brake (20.5 s); an EP brake (1.75–2.5 s) stops within 0.2 m without it,
    # and the prediction costs about 1 ms per ATO step on the final approach (the ATO step target is 200 µs, docs/performance.md)
    predictive_stop_lead_s: float = 5.0
    # vigilance device (docs/ato.md, "Vigilance device"): ДКСВ-1-Д checks every 30–40 s
    # (docs/sources.md#vigilance-device), we take 30 s; the answer window 7 s [U]; 0: no device
    vigilance_period_s: float = 30.0
    vigilance_answer_s: float = 7.0
    ato_acknowledges: bool = True         # the ATO answers each check while it drives


@dataclass
class AtoOutputs:
    command: float = 0.0
    emergency_brake: bool = False
    mode: int = MODE_STANDSTILL
    v_ref_mps: float = 0.0
    schedule_deviation_s: float = 0.0
    v_ceiling_mps: float = 0.0            # what the ATO allows itself now
    v_permitted_mps: float = 0.0          # ATP's supervised speed at the head
    aspect: int = sig.WHITE               # aspect the ATP acts upon
    atp_intervention: int = NO_INTERVENTION
    atp_interventions: int = 0
    emergency_brakings: int = 0
    signals_passed_at_danger: int = 0
    max_overspeed_mps: float = 0.0
    stop_index: int = 0                   # stops reached so far (the first stop counts as reached)
    arrival_time_s: float = -1.0          # at the last stop reached; −1 before any arrival
    stop_error_m: float = 0.0             # head position − stop point at the last arrival
    mode_changes: int = 0                 # traction/coast/brake changes while running
    stage: int = 0
    departure_hold_s: float = 0.0         # time standing past a departure time for want of a permissive cab code
    vigilance_warning: bool = False       # a vigilance check awaits its acknowledgement
    vigilance_brakings: int = 0           # emergency brakings for an unanswered check


class AtoCore:
    def __init__(self, line: Line, stock: RollingStock, timetable: List[TimetableStop], timetable_path,
                 category: str, settings: AtoSettings):
        s = settings
        if s.strategy not in STRATEGIES:
            raise FmuInputError(f"parameter strategy: {s.strategy!r} is not one of {', '.join(STRATEGIES)}")
        if category not in sig.ALSN_SPEEDS_KMH:
            raise FmuInputError(f"parameter train_category: {category!r} is not one of {', '.join(sig.ALSN_SPEEDS_KMH)}")
        for name, value in (("speed_margin", s.speed_margin_mps), ("stop_margin", s.stop_margin_m),
                            ("min_dwell", s.min_dwell_s), ("k1", s.k1), ("k2", s.k2),
                            ("late_threshold", s.late_threshold_s), ("early_threshold", s.early_threshold_s),
                            ("stop_window", s.stop_window_m)):
            if not value >= 0:
                raise FmuInputError(f"parameter {name}: must not be negative, got {value}")
        self.settings = s
        self.line, self.stock, self.category = line, stock, category
        self.timetable = timetable
        self.train = NominalTrain(stock, line)
        self.a_plan = s.braking_decel_mps2 if s.braking_decel_mps2 > 0 else default_plan_decel_mps2(stock, s.cab_signal)
        a_atp = s.atp_decel_mps2 if s.atp_decel_mps2 > 0 else default_atp_decel_mps2(stock)
        if self.a_plan >= a_atp:
            raise FmuInputError(f"parameter braking_decel: {self.a_plan} m/s² must be below the ATP "
                                f"supervision deceleration {a_atp} m/s²")
        self.brake_lead_s = s.brake_lead_s if s.brake_lead_s >= 0 else brake_lead_s(stock)
        self.atp = Atp(line, category, stock.length_m, s.cab_signal, a_atp, s.decoding_latency_s,
                       emergency_decel_mps2=stock.emergency_decel, brake_lead_s=self.brake_lead_s)
        self.atp.attach_vigilance(s.vigilance_period_s, s.vigilance_answer_s)
        self.plans = plan_stages(StagePlanner(self.train, line, category, self.a_plan, s.speed_margin_mps,
                                              head_limits=self.atp.cab.planned_limits()),
                                 timetable, timetable_path)
        self.controllers = Controllers(self.train, s.speed_gain, s.hysteresis_mps)
        self.braking = TargetBraking(s, category, self.a_plan, self.brake_lead_s, self.atp, timetable)
        self.phase = WAITING
        self.stage = 0
        self.strategy = None
        self.braking_target: Optional[BrakingTarget] = None
        self.restricted = False
        self.recovering = False
        self.creeping = False
        self.band_coasting = False            # coasting down through a restriction's band
        self.code_lost_s: Optional[float] = None   # when the digital code was lost, while it is
        self._last_regime = None
        # a driver releases the train brake before the departure time: its delay + build-down
        self.release_lead_s = stock.brake_delay_s + stock.brake_time_constant_s
        # a slow brake: the ATO follows its pipeline every step and predicts the stopping point
        self.stop_approach = StopApproach(self.train, MIN_BRAKE_SHARE) \
            if self.brake_lead_s > s.predictive_stop_lead_s else None
        self.out = AtoOutputs(stop_index=1, aspect=sig.WHITE if self.atp.cab.has_cab_signal else sig.GREEN)
        self.arrivals: List[dict] = []
        # (input, message) of the measurement fault of the last step, None while all are valid
        self.fault: Optional[Tuple[str, str]] = None

    # ---- helpers ----------------------------------------------------------------------------
    def departure_time(self, k: int) -> float:
        stop = self.timetable[k]
        earliest = stop.departure_s
        if self.arrivals and k > 0:
            earliest = max(earliest, self.arrivals[-1]["arrival_s"] + self.settings.min_dwell_s)
        return earliest

    # ---- step ------------------------------------------------------------------------------
    def step(self, t: float, h: float, x: float, v: float, aspect: int = sig.WHITE, code_valid: bool = False,
             v_permitted: float = 0.0, v_target: float = 0.0, free_blocks: int = 0,
             vigilance_ack: bool = False, cab_code: int = 0, target_distance: float = 0.0,
             gradient: float = 0.0, word_carrier: float = 0.0) -> AtoOutputs:
        """One ATO step; ``target_distance`` (m), ``gradient`` (‰) and ``word_carrier`` (Hz) are
        the TVM-430 receiver's outputs, read in TVM430 mode (``word_carrier`` in TVM300 mode too);
        which inputs a mode reads: CabSignalMode.inputs."""
        shown = Indication(aspect, code_valid, v_permitted, v_target, free_blocks, cab_code, target_distance,
                           gradient, word_carrier)
        self.fault = measurement_fault(self.atp.cab, x, v, shown)
        if self.fault is not None:
            return self._fail_safe(t)
        self.braking.measure(t, v)
        if self.stop_approach is not None:
            self.stop_approach.brake.advance(t, v)
        self.atp.check_vigilance(t, aspect, code_valid, vigilance_ack, self.settings.ato_acknowledges)
        atp = self.atp.supervise_indication(t, x, v, shown)
        # TVM: a word on a carrier of no block of ours is no word (TvmBlocks.word_block)
        permissive = self.atp.permits_departure(aspect, self.atp.code_shown, v_permitted)
        bridging = self._bridging_code_loss(t, code_valid)
        command, mode = self._drive(t, h, x, v, self._as_before_the_loss(atp) if bridging else atp, permissive)
        if bridging and command > 0.0:
            command, mode = 0.0, MODE_COAST
        if atp.intervention == SERVICE_INTERVENTION:
            command, mode = -1.0, MODE_ATP_SERVICE
        elif atp.intervention == EMERGENCY_INTERVENTION:
            command, mode = -1.0, MODE_ATP_EMERGENCY
        emergency = atp.intervention == EMERGENCY_INTERVENTION
        if self.stop_approach is not None:
            self.stop_approach.brake.command(t, command, emergency)
        return self._publish(command, mode, emergency, atp)

    def _bridging_code_loss(self, t: float, code_valid: bool) -> bool:
        """A digital code lost for less than DIGITAL_CODE_LOSS_GRACE_S after a valid one (the modes
        that bridge a loss: CabSignalMode.bridges_code_loss)."""
        if code_valid or not self.atp.cab.bridges_code_loss:
            self.code_lost_s = None
            return False
        if self.code_lost_s is None:
            self.code_lost_s = t
        return self.atp.last_valid is not None and t - self.code_lost_s < DIGITAL_CODE_LOSS_GRACE_S

    def _as_before_the_loss(self, atp: AtpResult) -> AtpResult:
        """What the ATO drives by while it bridges a short loss: the ATP's constraints without the
        fall of its ceiling to the no-code speed, and the last valid aspect. The ATP itself
        supervises that fall all the while (after the driver's reaction time)."""
        drop = self.atp.ceiling_drop
        targets = [target for target in atp.constraints.targets if target is not drop]
        return replace(atp, constraints=Constraints(atp.constraints.ceiling_mps, targets),
                       aspect=self.atp.last_valid_aspect)

    def _fail_safe(self, t: float) -> AtoOutputs:
        """A measurement cannot be true: nothing computed from it is trusted. The ATP applies
        the emergency brake, held until the train stands with valid measurements again."""
        self.atp.apply_emergency()
        if self.stop_approach is not None:
            self.stop_approach.brake.advance(t, self.braking.v_prev)
            self.stop_approach.brake.command(t, -1.0, True)
        self.out.v_ref_mps, self.out.v_ceiling_mps = 0.0, 0.0
        atp = AtpResult(intervention=EMERGENCY_INTERVENTION, permitted_mps=0.0, ceiling_mps=0.0,
                        aspect=self.out.aspect)
        return self._publish(-1.0, MODE_ATP_EMERGENCY, True, atp)

    def _publish(self, command: float, mode: int, emergency: bool, atp) -> AtoOutputs:
        out = self.out
        if self.phase == RUNNING:
            regime = 1 if command > 0.0 else (-1 if command < 0.0 else 0)
            if self._last_regime is not None and regime != self._last_regime:
                out.mode_changes += 1
            self._last_regime = regime
        out.command = command
        out.mode = mode
        out.emergency_brake = emergency
        out.v_permitted_mps = min(atp.permitted_mps, 1e3)
        out.aspect = atp.aspect
        out.atp_intervention = atp.intervention
        out.atp_interventions = self.atp.interventions
        out.emergency_brakings = self.atp.emergency_brakings
        out.signals_passed_at_danger = self.atp.signals_passed_at_danger
        out.max_overspeed_mps = max(self.atp.max_overspeed_mps, 0.0)
        out.stage = self.stage
        vigilance = self.atp.vigilance
        if vigilance is not None:
            out.vigilance_warning, out.vigilance_brakings = vigilance.warning, vigilance.brakings
        return out

    def _drive(self, t: float, h: float, x: float, v: float, atp, permissive: bool):
        s = self.settings
        out = self.out
        if self.phase == FINISHED:
            out.v_ref_mps, out.v_ceiling_mps = 0.0, 0.0
            return -s.hold_brake, MODE_STANDSTILL
        if self.phase in (WAITING, DWELLING):
            out.v_ref_mps, out.v_ceiling_mps = 0.0, 0.0
            departure = self.departure_time(self.stage)
            out.schedule_deviation_s = max(t - self.timetable[self.stage].departure_s, 0.0) \
                if self.phase == DWELLING or t > departure else 0.0
            # departure hold: the ATO knows only the cab signal and the line, never where the
            # train ahead is, so it starts only on a valid permissive code (atp.permits_departure)
            may_go = atp.permitted_mps > MIN_PERMITTED_TO_START_MPS and not atp.stop_now and permissive
            due = t + DEPARTURE_ROUNDING_S >= departure
            if due and may_go:
                self._depart(t)
            elif may_go and t + self.release_lead_s >= departure:
                return 0.0, MODE_STANDSTILL    # release the brake ahead of the departure time
            else:
                if due and not permissive:
                    out.departure_hold_s += h
                return -s.hold_brake, MODE_STANDSTILL
        return self._run(t, x, v, atp)

    def _depart(self, t: float) -> None:
        self.phase = RUNNING
        self.strategy = make_strategy(self.settings.strategy, self.plans[self.stage], self.settings.k1, self.settings.k2)
        self.braking_target = None
        self._last_regime = None

    def _run(self, t: float, x: float, v: float, atp):
        """Running between two stops: arrive, brake for a target, or follow the strategy."""
        s = self.settings
        out = self.out
        plan = self.plans[self.stage]
        stop = self.timetable[self.stage + 1]
        # arrival: standing at (or just past) the stop point
        if v <= STANDSTILL_MPS and x >= stop.stop_m - s.stop_window_m and self.braking_target is not None \
                and self.braking_target.is_stop_point:
            self._arrive(t, x)
            return -s.hold_brake, MODE_STANDSTILL

        if self._standing_at_stop_target(x, v, atp):
            # standing before a signal at danger (or on red): hold the brake until the target
            # moves; releasing it would alternate traction and braking and creep towards the signal
            out.v_ceiling_mps = 0.0
            return -s.hold_brake, MODE_STANDSTILL

        t_run = t - self.timetable[self.stage].departure_s
        guide = self.strategy.guide(t_run, x, v, out.schedule_deviation_s)
        deviation = t_run - guide.t_ref_s
        out.schedule_deviation_s = deviation
        out.v_ref_mps = guide.v_ref_mps
        flat_out = self._drive_flat_out(atp, deviation, self.atp.restrictions.speed_at(x) < _INF)

        ceiling = min(float(np.interp(x, plan.s, plan.ceiling_mps)), atp.ceiling_mps - s.speed_margin_mps,
                      self.braking.aspect_driving(x, atp)[0])
        out.v_ceiling_mps = max(ceiling, 0.0)
        braking = self._brake_for_targets(t, x, v, atp, stop.stop_m)
        if braking is not None:
            return braking
        return self._follow(x, v, atp, guide, deviation, ceiling, flat_out)

    def _standing_at_stop_target(self, x: float, v: float, atp) -> bool:
        """Standing with a stop target other than the stop point (a signal at danger less the
        stop margin, a stop on red) no more than ``stop_window`` ahead of the head, or behind it.
        Farther short of it the train moves up (and brakes for it as for any target)."""
        if v > STANDSTILL_MPS:
            return False
        window = self.settings.stop_window_m
        return atp.stop_now or any(
            target.speed_mps <= 0.0 and not target.is_stop_point and target.position_m - x <= window
            for target in self.braking.targets(self.stage, x, v, atp))

    def _drive_flat_out(self, atp, deviation: float, in_restriction: bool = False) -> bool:
        """The book's recovery rule: late by more than the threshold, or late when a restrictive
        cab signal or a temporary restriction clears, drive at the maximum permitted speed until
        back on schedule."""
        if in_restriction or (self.atp.cab.has_cab_signal and atp.aspect != sig.GREEN):
            self.restricted = True
        elif self.restricted:
            self.restricted = False
            self.recovering = deviation > 0.0
        if self.recovering and deviation <= 0.0:
            self.recovering = False
        return self.recovering or deviation > self.settings.late_threshold_s

    def _brake_for_targets(self, t: float, x: float, v: float, atp, stop_m: float):
        """(command, mode) while braking for a target; None when no target binds."""
        targets = self.braking.targets(self.stage, x, v, atp)
        need, candidate = self.braking.required_decel(x, v, targets)
        if self.braking.lets_go(self.braking_target, v, targets):
            self.braking_target = None
        if need >= BRAKE_ONSET_SHARE * self.a_plan and candidate is not None:
            self.braking_target = candidate
        target = self.braking_target
        if target is None:
            return None
        if target.is_stop_point and v <= STANDSTILL_MPS and x < stop_m - self.settings.stop_window_m:
            self.braking_target = None            # stopped short of the window: creep on
            self.creeping = True
            return None
        if target.is_stop_point and self.stop_approach is not None and v <= FINAL_APPROACH_MPS:
            # the stop point: the brake share whose predicted stopping point it is
            return -self.stop_approach.share(t, x, v, target.position_m), MODE_BRAKE
        # the brake stays applied until the target is reached (no release/re-apply)
        decel = min(self.braking.decel_to(x, v, target.position_m, target.speed_mps),
                    TARGET_DECEL_CAP * self.a_plan * target.braking_share)
        return min(self.controllers.brake(x, v, decel), -MIN_BRAKE_SHARE), MODE_BRAKE

    def _follow(self, x: float, v: float, atp, guide, deviation: float, ceiling: float, flat_out: bool):
        """No target binds: the strategy's cruise speed or coasting, under the ceiling."""
        s = self.settings
        if self.creeping:
            cruise, coast = CREEP_SPEED_MPS, False
        elif flat_out:
            cruise, coast = _INF, False
        else:
            cruise, coast = guide.cruise_mps, guide.coast
        if atp.stop_now:
            return self.controllers.brake(x, v, self.a_plan), MODE_BRAKE
        v_set = min(cruise, ceiling)
        band = self._restriction_band(x, v, v_set, ceiling, atp)
        if band is not None:
            return band
        if deviation < -s.early_threshold_s and not self.creeping:
            # well ahead (e.g. a heavy train running away down a grade): hold the programme speed,
            # braking if need be (ЭР200 rule "well ahead → drop one grade", docs/sources.md#ato-timetable-following)
            return self._hold(x, v, min(guide.v_ref_mps, ceiling), may_brake=True)
        if coast:
            self.controllers.coasting = True
            if v <= ceiling:
                return 0.0, MODE_COAST
            command = min(self.controllers.hold(x, v, ceiling, may_brake=True), 0.0)
            return command, MODE_BRAKE if command < 0 else MODE_COAST
        return self._hold(x, v, v_set, may_brake=v > ceiling)

    def _restriction_band(self, x: float, v: float, v_set: float, ceiling: float, atp):
        """Inside a temporary restriction, or under an aspect with a driving band (КЖ), that
        binds the set speed: traction up to the ceiling, then coast down to the band's bottom
        (v_limit − 8 km/h; КЖ 42 km/h: the book's traction–coast bands); None otherwise."""
        limit = self.atp.restrictions.speed_at(x)
        bottom = limit - RESTRICTION_BAND_MPS
        # the mode's own band under the aspect acted upon (ALSN's КЖ), when it binds
        cab = self.atp.cab
        top, aspect_bottom = cab.driving_speeds(self.category, atp.aspect)[0], cab.band_bottom_mps(self.category, atp.aspect)
        if top is not None and aspect_bottom is not None and top < limit:
            limit, bottom = top, aspect_bottom
        if not (limit < _INF and v_set >= limit - self.settings.speed_margin_mps - SPEED_ROUNDING_MPS):
            self.band_coasting = False
            return None
        if v >= v_set - BAND_TOP_MPS:
            self.band_coasting = True
        elif v <= bottom:
            self.band_coasting = False
        if self.band_coasting and v <= ceiling:
            self.controllers.coasting = True
            return 0.0, MODE_COAST
        return None

    def set_restrictions(self, restrictions) -> None:
        """Temporary restrictions set while running (the FMU's ``tsr_*`` inputs, scenario
        events): the ATP supervises them and the ATO brakes for them; not in the programmes."""
        self.atp.restrictions.set_events(restrictions)

    def _hold(self, x: float, v: float, v_set: float, may_brake: bool):
        command = self.controllers.hold(x, v, v_set, may_brake=may_brake)
        return command, MODE_TRACTION if command > 0 else (MODE_BRAKE if command < 0 else MODE_COAST)

    def _arrive(self, t: float, x: float) -> None:
        out = self.out
        stop = self.timetable[self.stage + 1]
        error = x - stop.stop_m
        self.arrivals.append({"station": stop.station, "scheduled_arrival_s": stop.arrival_s, "arrival_s": t,
                              "arrival_deviation_s": t - stop.arrival_s, "stop_error_m": error})
        out.stop_index = self.stage + 2
        out.arrival_time_s = t
        out.stop_error_m = error
        out.schedule_deviation_s = t - stop.arrival_s
        self.stage += 1
        self.braking_target = None
        self.creeping = False
        self.strategy = None
        self.phase = FINISHED if self.stage >= len(self.plans) else DWELLING
