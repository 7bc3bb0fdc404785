"""ATP: the independent speed-supervision layer with priority over the ATO (docs/ato.md).

What it supervises at each step, as constraints (a ceiling now and targets ahead):

* the line's static limit for the train category, held until the tail clears a lower limit,
  and each lower limit ahead as a target;
* the cab signal. ``cab_signal="ALSN"``: the aspect, through the table in
  fmus/signalling/aspects.py (ceiling, and the speed to reach at the exit signal of the
  current block section: 60 km/h on yellow, a stop on red-yellow). ``"ALSU"``: the code shown
  (the receiver's ``code``), through the ALSU code table (fmus/signalling/alsu.py): its
  ceiling, its speed at the exit signal, and its braking — a permanent restriction's target is
  supervised on a gentler curve than a signal's (alsu.BRAKING_SHARE). ``"digital"``:
  ``v_permitted`` from now on, ``v_target`` at the next signal (the exit of the current section),
  and a stop at the end of the ``free_blocks``-th section ahead while ``free_blocks`` is below 6
  (the section after the free ones is occupied; fmus/signalling/digital_messages.py).
  ``"TVM430"``: the cab's speed step ``v_permitted`` with a trip at its control level (step +
  15 km/h), the next step ``v_target`` at the exit of the word's block, and a stop at the
  target point (the word's block start + ``target_distance``) on a continuous curve from the
  transmitted ``gradient`` and the train's braking; the word's block is found by its carrier
  (``word_carrier``, atp_tvm430.py ``TvmBlocks.word_block``). See "TVM-430 supervision" below.
  ``"TVM300"``: fixed steps, no continuous curve — the step ``v_permitted`` until the exit of the
  word's block, the next step ``v_target`` from there, each with a trip at its control level,
  and a stop at the exit of an 80→0 or 0→0 block (atp_tvm300.py).
  ``"off"``: line limits only (plant studies without a signalling chain).

  Each mode is a class (atp_modes.py, atp_tvm430.py, atp_tvm300.py) named in the table
  ``CAB_SIGNAL_MODES``; the ATP keeps the state of a run and asks its mode object (``Atp.cab``)
  what an indication imposes, what passing a signal does, and its trip levels.

Fail-safe rules (never more permissive than the last valid code):

* the receiver bridges short losses of code itself (its display holds through a loss shorter
  than the equipment's inertia, docs/loco_receiver.md); ``code_valid`` false means it
  displays the no-code indication: its constraints (white 40 km/h; red after red-yellow) are
  added to those of the last valid code, which stay in force anchored where they were (a
  red-yellow stop stays at *that* signal);
* a cab-signal ceiling that falls below the train's speed (a loss of code at speed, a change
  to red-yellow) is reached on a braking curve, not in one step: the new ceiling becomes a
  target where the train would reach it braking at the supervision deceleration after the
  driver's reaction time (ETCS T_driver 4 s, docs/sources.md#atp-margins-etcs), the old one
  holding until then;
* passing a block signal → until the receiver can have decoded the new section (its stated
  latency, or the longest display hold, the longer) the ATP adds what the worst code of the
  new section would impose at a signal: after a green signal the next signal may be yellow,
  so the one after it may be red — a stop target there; after a yellow signal, red-yellow
  (stop at the next signal). A steady green at line speed is therefore not capped by a
  speed step it may never need (docs/ato.md, ATP); passing the exit signal under red-yellow
  is a signal passed at danger: counted, and the emergency brake is applied.

Braking-curve supervision, ETCS-like margins (docs/sources.md#atp-margins-etcs): the permitted speed at the
head is min(ceiling, sqrt(v_t² + 2·a·(x_t − x)) over the targets) with the supervision
deceleration a. Above it by dV_sbi the ATP commands full service braking until the train is
back under the permitted speed; above it by dV_ebi (7.5 km/h up to 110 km/h, rising linearly
to 15 km/h at 210 km/h [S]) it applies the emergency brake until standstill.

TVM-430 supervision (docs/ato.md#tvm-430) replaces the emergency margin by trip levels: the
control level, step + 15 km/h, and for each target a trip curve at the stock's emergency
deceleration less the transmitted falling gradient — towards the next step, its control level
at the block exit; towards a stop, the highest speed from which the emergency brake, applied now
and effective after the brake's lead time, stands the train by the end of the buffer section
(the track circuit that begins at the target point). The service (warning) curve is the
supervision deceleration less the gradient, 0 at the target point, and towards a stop stays
``2·dV_sbi`` under the trip curve, so the service intervention always comes first. Passing a
stop's target point at a block marker is a signal passed at danger. A lost or invalid word is
the most restrictive indication, step 0: its control level (15 km/h) trips a moving train at
once; the last valid word's targets stay where they were.
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from typing import Dict, Optional, Type

from fmus.ato_controller.atp_modes import (DEPARTURE_ASPECTS, T_DRIVER_S, AlsnMode, AlsuMode,  # noqa: F401
                                          CabSignalMode, DigitalMode, Indication, NoCabSignal)
from fmus.ato_controller.atp_tvm300 import Tvm300Mode
from fmus.ato_controller.atp_tvm430 import Tvm430Mode
from fmus.ato_controller.speed_restrictions import SpeedRestrictions
from fmus.ato_controller.supervision import Constraints, Target, dv_ebi_mps, dv_sbi_mps
from fmus.signalling import aspects as sig
from fmus.signalling.ato_modes import AtoMode
from fmus.data.loader import Line
from fmus.errors import FmuInputError

#: the ATP's cab-signal modes by their ``cab_signal`` name: how it reads each (atp_modes.py,
#: atp_tvm430.py, atp_tvm300.py); adding a mode is a class and a row here
CAB_SIGNAL_MODES: Dict[str, Type[CabSignalMode]] = {
    AtoMode.ALSN: AlsnMode, AtoMode.ALSU: AlsuMode, AtoMode.DIGITAL: DigitalMode, AtoMode.TVM430: Tvm430Mode,
    AtoMode.TVM300: Tvm300Mode, AtoMode.OFF: NoCabSignal}
NO_INTERVENTION, SERVICE_INTERVENTION, EMERGENCY_INTERVENTION = 0, 1, 2
INTERVENTION_NAMES = {NO_INTERVENTION: "none", SERVICE_INTERVENTION: "service", EMERGENCY_INTERVENTION: "emergency"}
_INF = math.inf
# below this the train stands (a tachometer's resolution; the ATO's arrival test uses the same)
STANDSTILL_MPS = 1e-3


@dataclass
class AtpResult:
    intervention: int = NO_INTERVENTION
    permitted_mps: float = _INF          # supervised speed at the head (curves included)
    ceiling_mps: float = _INF            # line limit and cab-signal ceiling at the head, no curves
    constraints: Constraints = field(default_factory=Constraints)
    aspect: int = sig.WHITE              # shown aspect, or the last valid one while the code is lost
    stop_now: bool = False               # red: the ATO must stop the train


@dataclass
class VigilanceDevice:
    """Periodic driver-vigilance check with its emergency valve (ALSN's ДКСВ/ЭПК; docs/ato.md,
    "Vigilance device"). While a checked aspect is shown, a warning starts ``period_s`` after the
    last acknowledgement (or after the check became active); unanswered for ``answer_s`` it
    applies the emergency brake. An acknowledgement is a press: the input's rising edge (a held
    handle answers once), at any time it restarts the period."""

    period_s: float = 30.0
    answer_s: float = 7.0
    next_check_s: float = _INF
    warning_since_s: Optional[float] = None
    brakings: int = 0
    _pressed_before: bool = False

    @property
    def warning(self) -> bool:
        return self.warning_since_s is not None

    def step(self, t: float, checked: bool, pressed: bool, ato_answers: bool) -> bool:
        """Advance to ``t``; True when the check went unanswered (apply the emergency brake)."""
        press = pressed and not self._pressed_before
        self._pressed_before = pressed
        if not checked or self.period_s <= 0.0:
            self.next_check_s, self.warning_since_s = _INF, None
            return False
        if self.next_check_s == _INF:
            self.next_check_s = t + self.period_s
        if press or (ato_answers and self.warning):
            self.next_check_s, self.warning_since_s = t + self.period_s, None
            return False
        if self.warning_since_s is None and t + 1e-9 >= self.next_check_s:
            self.warning_since_s = t
        if self.warning and t - self.warning_since_s + 1e-9 >= self.answer_s:
            self.brakings += 1
            self.next_check_s, self.warning_since_s = t + self.period_s, None
            return True
        return False


class Atp:
    #: the vigilance device (attach_vigilance); None: no periodic check
    vigilance: Optional[VigilanceDevice] = None

    def __init__(self, line: Line, category: str, train_length_m: float, cab_signal: str,
                 supervision_decel_mps2: float, decoding_latency_s: float,
                 emergency_decel_mps2: float = 0.0, brake_lead_s: float = 0.0):
        """``emergency_decel_mps2`` and ``brake_lead_s`` (the stock's emergency deceleration and
        the time until a brake demand takes effect) set TVM430's trip curves; 0: the supervision
        deceleration, no lead."""
        if cab_signal not in CAB_SIGNAL_MODES:
            raise FmuInputError(f"parameter cab_signal: {cab_signal!r} is not one of {', '.join(CAB_SIGNAL_MODES)}")
        if not supervision_decel_mps2 > 0:
            raise FmuInputError(f"parameter atp_decel: must be positive, got {supervision_decel_mps2}")
        self.line, self.category, self.length_m = line, category, train_length_m
        self.mode = cab_signal
        self.decel = supervision_decel_mps2
        self.latency_s = decoding_latency_s
        self.emergency_decel = emergency_decel_mps2 if emergency_decel_mps2 > 0 else supervision_decel_mps2
        self.brake_lead_s = max(brake_lead_s, 0.0)
        # "sections" here are blocks, signal to signal (a track circuit without a signal at its
        # exit, e.g. in a station throat, is no signal to pass)
        self.section_starts = [start for start, _ in line.block_bounds]
        self.section_ends = [end for _, end in line.block_bounds]
        self.limit_starts = list(line.limit_starts)
        self.limits = list(line.limits_mps[category])
        self.section: Optional[int] = None
        self.last_valid: Optional[Constraints] = None
        self.last_valid_aspect = sig.WHITE
        self.last_valid_s = -_INF
        self.assumed: Optional[Constraints] = None
        self.assumed_aspect = sig.GREEN
        self.assumed_until = -_INF
        self.cab_ceiling_mps = _INF              # cab-signal ceiling in force at the last step
        self.ceiling_drop: Optional[Target] = None   # a lower cab ceiling being reached on a curve
        self.ceiling_before_mps = _INF           # the ceiling held until then
        self.emergency_latched = False
        self.service_active = False
        self.interventions = 0
        self.emergency_brakings = 0
        self.signals_passed_at_danger = 0
        self.max_overspeed_mps = 0.0
        self.restrictions = SpeedRestrictions(line, category, train_length_m, supervision_decel_mps2)
        #: how this run's mode reads the cab signal (CAB_SIGNAL_MODES)
        self.cab: CabSignalMode = CAB_SIGNAL_MODES[cab_signal](self)
        # the receiver's display hold: how long it may show the previous section's code
        self.inertia_s = self.cab.display_hold_s
        self.trip_mps = _INF                     # the mode's trip level at the head, last step (TVM)
        self.code_shown = False                  # a valid code at the last step (TVM: a word of ours)

    @property
    def tvm(self):
        """The TVM modes' block supervision (their words' blocks, their curves); None in the others."""
        return self.cab.tvm

    # ---- geometry ---------------------------------------------------------------------------
    def section_of(self, x: float) -> Optional[int]:
        k = bisect.bisect_right(self.section_starts, x) - 1
        if k < 0 or x >= self.section_ends[k]:
            return None
        return k

    def exit_signal_m(self, k: int, blocks_ahead: int = 0) -> float:
        return self.section_ends[min(k + blocks_ahead, len(self.section_ends) - 1)]

    def static_limit(self, x: float) -> float:
        """Line limit at the head, held until the tail has cleared a lower limit."""
        tail = x - self.length_m
        k_tail = max(bisect.bisect_right(self.limit_starts, tail) - 1, 0)
        k_head = max(bisect.bisect_right(self.limit_starts, x) - 1, 0)
        return min(self.limits[k_tail:k_head + 1])

    def line_constraints(self, x: float, v: float) -> Constraints:
        c = Constraints(self.static_limit(x))
        reach = x + v * v / (2.0 * self.decel) + 200.0
        k = bisect.bisect_right(self.limit_starts, x)
        while k < len(self.limit_starts) and self.limit_starts[k] <= reach:
            c.targets.append(Target(self.limit_starts[k], self.limits[k]))
            k += 1
        return c

    # ---- cab signal -------------------------------------------------------------------------
    def permits_departure(self, aspect: int, code_valid: bool, v_permitted_mps: float) -> bool:
        """A standing train may start only on a valid permissive cab code (docs/ato.md,
        departure hold): what the receiver shows now, not a remembered code. ``off`` (no cab
        signal) always permits; the modes with speeds also need a permitted speed above zero
        (CabSignalMode.permits_departure)."""
        return self.cab.permits_departure(aspect, code_valid, v_permitted_mps)

    def indication_constraints(self, x: float, aspect: int = sig.WHITE, code: int = 0, v_permitted: float = 0.0,
                               v_target: float = 0.0, free_blocks: int = 0, target_distance_m: float = 0.0,
                               gradient_permille: float = 0.0, word_carrier_hz: float = 0.0) -> Constraints:
        """What a valid cab indication imposes with the head at ``x`` (the receiver's outputs as
        :meth:`supervise` takes them), through the constraint builders it uses: no state read or
        kept — not the last valid code, the assumption after passing a signal, nor the curve of a
        falling ceiling — and no line limit. For planning without a run (the approach of a block,
        orchestrator/headway/approach.py). TVM430: a word on no carrier of ours is no word."""
        shown = Indication(aspect, True, v_permitted, v_target, free_blocks, code, target_distance_m,
                           gradient_permille, word_carrier_hz)
        return self.cab.constraints(x, self.section_of(x), shown)

    def supervise(self, t: float, x: float, v: float, aspect: int, code_valid: bool,
                  v_permitted: float, v_target: float, free_blocks: int, code: int = 0,
                  target_distance_m: float = 0.0, gradient_permille: float = 0.0,
                  word_carrier_hz: float = 0.0) -> AtpResult:
        """One step; ``code`` is the ALSU code shown (the receiver's ``code``), read in ALSU mode;
        ``target_distance_m``, ``gradient_permille`` and ``word_carrier_hz`` in TVM430 mode."""
        return self.supervise_indication(t, x, v, Indication(aspect, code_valid, v_permitted, v_target, free_blocks,
                                                             code, target_distance_m, gradient_permille,
                                                             word_carrier_hz))

    def supervise_indication(self, t: float, x: float, v: float, shown: Indication) -> AtpResult:
        """One step with the receiver's outputs ``shown`` (:meth:`supervise`)."""
        result = AtpResult()
        cab = self.cab
        code_valid = cab.validate(x, shown)
        self.code_shown = code_valid
        c = self.line_constraints(x, v)
        c.add(self.restrictions.constraints(x, v))
        k = self.section_of(x)
        acted_aspect = sig.GREEN
        if cab.has_cab_signal:
            crossed = self.section is not None and k != self.section
            if crossed:
                self._passed_signal(t)
            self.section = k
            constraints = cab.shown_constraints(x, k, shown, code_valid)
            acted_aspect = int(shown.aspect) if code_valid or cab.lost_code_aspect is None else cab.lost_code_aspect
            in_force = Constraints()
            if code_valid:
                self.last_valid, self.last_valid_aspect, self.last_valid_s = constraints, int(shown.aspect), t
                cab.remember(constraints, shown)
            elif self.last_valid is not None:
                # no code displayed (the receiver's hold is over): the last valid code's
                # constraints stay where they were, with the no-code ones
                in_force.add(self.last_valid)
                if sig.restrictiveness(self.last_valid_aspect) < sig.restrictiveness(acted_aspect):
                    acted_aspect = self.last_valid_aspect
            in_force.add(constraints)
            if t < self.assumed_until and self.assumed is not None:
                in_force.add(self.assumed)   # constraints only: the reported aspect stays the shown one
            c.add(self._ceiling_on_a_curve(in_force, x, v))
            result.stop_now = acted_aspect == sig.RED and cab.stops_on_red
        result.aspect = acted_aspect
        result.constraints = c
        result.ceiling_mps = c.ceiling_mps
        permitted = c.ceiling_mps
        for target in c.targets:
            if target.position_m >= x:
                decel = self.decel * target.braking_share
                permitted = min(permitted, math.sqrt(target.speed_mps ** 2 + 2.0 * decel * (target.position_m - x)))
            else:
                permitted = min(permitted, target.speed_mps)
        trip, permitted = cab.levels(c, x, v, permitted, self.cab_ceiling_mps)
        self.trip_mps = trip
        result.permitted_mps = permitted
        self.max_overspeed_mps = max(self.max_overspeed_mps, v - c.ceiling_mps)
        result.intervention = self._intervene(v, permitted, trip)
        return result

    def _ceiling_on_a_curve(self, cab: Constraints, x: float, v: float) -> Constraints:
        """The cab-signal constraints with a fall of their ceiling below the speed supervised
        on a braking curve: the lower ceiling becomes a target at the point the train reaches
        it braking at the supervision deceleration after the mode's reaction time (T_DRIVER_S;
        TVM: none), the ceiling before the fall holding until there (service brake first; the
        emergency brake only if the train overruns that curve by dV_ebi)."""
        ceiling = cab.ceiling_mps
        drop = self.ceiling_drop
        if drop is not None:
            if ceiling >= self.ceiling_before_mps or x >= drop.position_m or v <= ceiling:
                drop = None                          # the code came back, or the curve is done
            elif ceiling > drop.speed_mps:
                drop = Target(drop.position_m, ceiling)          # partly back: same point
            elif ceiling < drop.speed_mps:
                drop = Target(x + self._reach_m(v, ceiling), ceiling)   # fell further: from here
        elif ceiling < self.cab_ceiling_mps and v > ceiling:
            self.ceiling_before_mps = self.cab_ceiling_mps
            drop = Target(x + self._reach_m(v, ceiling), ceiling)
        self.ceiling_drop = drop
        self.cab_ceiling_mps = ceiling
        if drop is None:
            return cab
        return Constraints(max(ceiling, self.ceiling_before_mps), cab.targets + [drop])

    def _reach_m(self, v: float, ceiling: float) -> float:
        reaction = self.cab.reaction_s
        return v * reaction + (v * v - ceiling * ceiling) / (2.0 * self.decel)

    def _passed_signal(self, t: float) -> None:
        """The head passed the exit signal of the previous section: the mode says what the ATP
        assumes until the new section's code can have been decoded (CabSignalMode.passed_signal)."""
        active = self.last_valid_aspect
        if self.assumed is not None and t < self.assumed_until \
                and sig.restrictiveness(self.assumed_aspect) < sig.restrictiveness(active):
            active = self.assumed_aspect
        self.assumed_aspect, self.assumed = self.cab.passed_signal(self.section, active)
        # the receiver may display the previous section's code until it has decoded the new
        # one, or for its display hold when the new code is lost (at most the ALSN inertia)
        self.assumed_until = t + max(self.latency_s, self.inertia_s)

    def signal_passed_at_danger(self) -> None:
        """A signal (a stop point) passed at danger: counted, and the emergency brake applied."""
        self.signals_passed_at_danger += 1
        self._emergency()

    def apply_emergency(self) -> None:
        """Emergency brake until standstill, counted once per application (a fault: core.py)."""
        self._emergency()

    def _emergency(self) -> None:
        if not self.emergency_latched:
            self.emergency_latched = True
            self.emergency_brakings += 1
            self.interventions += 1

    def _intervene(self, v: float, permitted: float, trip: float = _INF) -> int:
        """``trip``: the mode's trip level (TVM: it replaces the dV_ebi margin); inf in the other modes."""
        if self.emergency_latched and v <= STANDSTILL_MPS:
            self.emergency_latched = False
        if v > (trip if trip < _INF else permitted + dv_ebi_mps(v)):
            self._emergency()
        if self.emergency_latched:
            self.service_active = False
            return EMERGENCY_INTERVENTION
        if v > permitted + dv_sbi_mps(v):
            if not self.service_active:
                self.interventions += 1
            self.service_active = True
        elif v <= permitted:
            self.service_active = False
        return SERVICE_INTERVENTION if self.service_active else NO_INTERVENTION

    # ---- vigilance device -------------------------------------------------------------------
    def attach_vigilance(self, period_s: float, answer_s: float) -> None:
        """Fit the periodic vigilance check (period 0: none). Checked aspects:
        fmus/signalling/aspects.py ``VIGILANCE_ASPECTS``; no check without a cab signal."""
        if not period_s >= 0:
            raise FmuInputError(f"parameter vigilance_period: must not be negative, got {period_s}")
        if not answer_s > 0:
            raise FmuInputError(f"parameter vigilance_answer: must be positive, got {answer_s}")
        self.vigilance = VigilanceDevice(period_s, answer_s)

    def check_vigilance(self, t: float, aspect: int, code_valid: bool, pressed: bool, ato_answers: bool) -> None:
        """One step of the vigilance device, before :meth:`supervise`: an unanswered check
        applies the emergency brake (held until standstill, counted as an emergency braking)."""
        if self.vigilance is None:
            return
        shown = int(aspect) if code_valid else sig.WHITE
        checked = self.cab.has_cab_signal and shown in sig.VIGILANCE_ASPECTS
        if self.vigilance.step(t, checked, pressed, ato_answers):
            self._emergency()
