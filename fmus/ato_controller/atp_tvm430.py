"""The ATP's TVM-430 supervision (atp.py's module docstring, "TVM-430 supervision";
docs/ato.md#tvm-430): which track circuit a word comes from (``TvmBlocks``, TVM-300's too), the
constraints of a word, the trip curves at the stock's emergency deceleration and the service
curves, and the stop point passed at danger. The line's track circuits are TVM's blocks; the ATP owns the state of a run
(the last valid word, the intervention) and asks this for the curves; ``Tvm430Mode`` is the
ATP's TVM430 mode (atp.py's CAB_SIGNAL_MODES) over them."""
from __future__ import annotations

import bisect
import math
from typing import Optional, Tuple

from fmus.ato_controller.atp_modes import CabSignalMode, Indication
from fmus.ato_controller.supervision import Constraints, Target, dv_sbi_mps
from fmus.data.loader import Line
from fmus.signalling import aspects as sig
from fmus.units import MPS_PER_KMH, STANDARD_GRAVITY_MPS2

# the control (trip) level lies this far above the cab's speed step (300 → 315 km/h,
# docs/ato.md#tvm-430) [U]
TVM_CONTROL_MARGIN_MPS = 15.0 * MPS_PER_KMH
# a word is looked for in the head's block and at most this many blocks behind it (the
# receiver shows the previous block's word only just after a boundary, until it has decoded the
# new one); a carrier found in neither is no word of ours: treated as lost
TVM_WORD_BLOCKS_BACK = 1


def tvm_decel(decel: float, gradient_permille: float) -> float:
    """A deceleration less what a falling gradient (‰, negative) takes from it; at least a tenth
    of it, so a curve always exists (a steeper line is refused by the line schema anyway)."""
    return max(decel + STANDARD_GRAVITY_MPS2 * gradient_permille / 1000.0, 0.1 * decel)


class TvmBlocks:
    """A TVM line's blocks (its track circuits) for one train, shared by TVM-430 and TVM-300
    (atp_tvm300.py): which block a word comes from, by its carrier, and the stop point of the last
    valid word at a block marker, passing which is a signal passed at danger."""

    def __init__(self, line: Line):
        self.section_carriers = [sec.carrier_hz for sec in line.sections]
        self.circuit_starts = [sec.start_m for sec in line.sections]
        self.circuit_ends = [sec.end_m for sec in line.sections]
        self.stop_m: Optional[float] = None      # the stop point of the last valid word, at a block marker
        self._x_before: Optional[float] = None   # the head at the last step

    def word_block(self, x: float, word_carrier_hz: float) -> Optional[int]:
        """The track circuit (TVM block) the shown word comes from: the latest one at or behind
        the head whose line-file carrier is the word's, looking back at most
        TVM_WORD_BLOCKS_BACK circuits; None when no such circuit (then the word is not ours)."""
        k = bisect.bisect_right(self.circuit_starts, x) - 1
        if k < 0 or x >= self.circuit_ends[-1] or word_carrier_hz <= 0.0:
            return None
        for j in range(k, max(k - TVM_WORD_BLOCKS_BACK, 0) - 1, -1):
            if abs(self.section_carriers[j] - word_carrier_hz) < 0.5:
                return j
        return None

    def is_block_marker(self, position_m: float) -> bool:
        """A stop point at a block boundary (its marker board), within 0.5 m."""
        k = bisect.bisect_left(self.circuit_starts, position_m - 0.5)
        return k < len(self.circuit_starts) and abs(self.circuit_starts[k] - position_m) <= 0.5

    def remember_stop(self, shown: Constraints) -> None:
        """A valid word's stop point, if it lies at a block's marker board: passing it is passing
        a signal at danger; a station's stop point inside a block is not (a precise stop may end
        a little past it)."""
        self.stop_m = next((tg.position_m for tg in shown.targets
                            if tg.signal and self.is_block_marker(tg.position_m)), None)

    def passes_stop_point(self, x: float) -> bool:
        """Whether the head, now at ``x``, passed the stop point of the last valid word at a block
        marker (the entry of the buffer section) since the last step: a signal passed at danger."""
        before, self._x_before = self._x_before, x
        stop = self.stop_m
        return stop is not None and before is not None and before < stop <= x


class Tvm430Supervision(TvmBlocks):
    """The TVM-430 curves on one line for one train: ``supervision_decel_mps2`` the service
    curves', ``emergency_decel_mps2`` and ``brake_lead_s`` (the time until a brake demand takes
    effect) the trip curves'."""

    def __init__(self, line: Line, supervision_decel_mps2: float, emergency_decel_mps2: float,
                 brake_lead_s: float):
        super().__init__(line)
        self.decel = supervision_decel_mps2
        self.emergency_decel = emergency_decel_mps2
        self.brake_lead_s = brake_lead_s

    def constraints(self, v_step: float, v_next: float, target_distance_m: float, gradient_permille: float,
                    block: int) -> Constraints:
        """The constraints of a TVM-430 word from track circuit ``block``: the step from now on
        (trip at its control level), the next step at the block's exit (trip at the next
        control level), and — when a lower step is announced or the step is 0 — a stop at the
        target point, the block's start + ``target_distance_m`` (the block rules put it at the
        entry of the buffer section before the occupied block)."""
        v_step, v_next = max(v_step, 0.0), max(v_next, 0.0)
        c = Constraints(v_step)
        grade = min(gradient_permille, 0.0)        # only a falling gradient lengthens the braking
        exit_m = self.circuit_ends[block]
        if v_next < v_step:
            c.targets.append(Target(exit_m, v_next, trip_speed_mps=v_next + TVM_CONTROL_MARGIN_MPS,
                                    gradient_permille=grade))
        if v_next < v_step or v_step == 0.0:
            stop_m = self.circuit_starts[block] + max(target_distance_m, 0.0)
            c.targets.append(Target(stop_m, 0.0, signal=True, trip_speed_mps=0.0, gradient_permille=grade,
                                    trip_position_m=self.danger_point_m(stop_m)))
        return c

    def danger_point_m(self, stop_m: float) -> float:
        """Where a stop's trip curve ends: the end of the track circuit that begins at (or
        holds) the stop point — the buffer section before the occupied block is the overlap
        the emergency brake may use; the service curve ends at the stop point itself."""
        k = bisect.bisect_right(self.circuit_starts, stop_m) - 1
        if k < 0 or stop_m >= self.circuit_ends[-1]:
            return stop_m
        return self.circuit_ends[k]

    def trip_curve(self, target: Target, x: float) -> float:
        """Trip speed at ``x`` for a TVM430 target: the highest speed v with
        v·T_lead + (v² − v_t²)/(2·a_e) ≤ x_t − x, so the emergency brake applied now, effective
        after the brake's lead time, brings the train to the target's trip speed v_t at x_t; v_t
        beyond the target. The lead counts towards a stop only: at a block exit the next step's
        control level takes over and trips at once."""
        v_t = target.trip_speed_mps
        end = target.position_m if target.trip_position_m is None else target.trip_position_m
        distance = end - x
        if distance <= 0.0:
            return v_t
        a = tvm_decel(self.emergency_decel, target.gradient_permille)
        lead = self.brake_lead_s if v_t == 0.0 else 0.0
        return -a * lead + math.sqrt(a * a * lead * lead + v_t * v_t + 2.0 * a * distance)

    def levels(self, c: Constraints, x: float, v: float, permitted: float,
               cab_ceiling_mps: float) -> Tuple[float, float]:
        """(trip level, permitted speed) at the head. The trip is the control level of the cab's
        step (+ 15 km/h; of the step shown, ``cab_ceiling_mps``, not of a higher one held while a
        fall is braked for) and the targets' trip curves. The permitted speed is the ceiling and
        the service curves (supervision deceleration less the gradient); towards a stop, where
        the trip curve's brake lead brings it down to the service curve, it stays 2·dV_sbi under
        the trip curve, so the service intervention always comes first."""
        trip = min(c.ceiling_mps, cab_ceiling_mps) + TVM_CONTROL_MARGIN_MPS
        for target in c.targets:
            if target.trip_speed_mps is None:
                continue
            curve = self.trip_curve(target, x)
            trip = min(trip, curve)
            if target.position_m >= x:
                decel = tvm_decel(self.decel, target.gradient_permille)
                service = math.sqrt(target.speed_mps ** 2 + 2.0 * decel * (target.position_m - x))
                if target.trip_speed_mps == 0.0:
                    service = min(service, curve - 2.0 * dv_sbi_mps(v))
                permitted = min(permitted, max(service, 0.0))
        return trip, permitted


class TvmMode(CabSignalMode):
    """What both TVM modes share: a code is read only from the block at or just behind the head
    whose carrier it came on (:meth:`TvmBlocks.word_block`), a lost code is step 0 braked for at
    once and acted upon as red-yellow, passing the last valid code's stop point at a block marker
    is a signal passed at danger. A subclass makes ``self.tvm``, its TvmBlocks supervision."""

    reaction_s = 0.0
    lost_code_aspect = sig.RED_YELLOW
    # the block rules announce a stop only a few blocks ahead: a train at 300 km/h must plan
    # above the 0.5 m/s² cap (docs/ato.md#tvm-430, #tvm-300)
    plan_decel_capped = False
    station_stop_replaces_signal_stops = True
    tvm: TvmBlocks

    def validate(self, x: float, shown: Indication) -> bool:
        """A code from no block at or just behind the head is none; passing the last valid
        code's stop point at a block marker is a signal passed at danger."""
        valid = shown.code_valid and self.tvm.word_block(x, shown.word_carrier_hz) is not None
        if self.tvm.passes_stop_point(x):
            self.atp.signal_passed_at_danger()
        return valid

    def no_code(self) -> Constraints:
        return Constraints(0.0)               # the most restrictive indication: step 0

    def remember(self, constraints, shown):
        self.tvm.remember_stop(constraints)


class Tvm430Mode(TvmMode):
    """TVM430: the cab's speed step ``v_permitted`` with a trip at its control level (step +
    15 km/h), the next step ``v_target`` at the exit of the word's block, and a stop at the
    target point (the word's block start + ``target_distance``) on a continuous curve from the
    transmitted ``gradient`` and the train's braking; the word's block is found by its carrier
    (``word_carrier``, :meth:`TvmBlocks.word_block`). A lost or invalid word is step 0,
    acted upon as red-yellow and braked for at once (no driver's reaction)."""

    inputs = ("aspect", "v_permitted", "v_target", "target_distance", "gradient", "word_carrier")

    def __init__(self, atp):
        super().__init__(atp)
        self.tvm = Tvm430Supervision(atp.line, atp.decel, atp.emergency_decel, atp.brake_lead_s)

    def constraints(self, x, k, shown):
        block = self.tvm.word_block(x, shown.word_carrier_hz)
        if block is None:
            return self.no_code()
        return self.tvm.constraints(shown.v_permitted_mps, shown.v_target_mps, shown.target_distance_m,
                                    shown.gradient_permille, block)

    # passing a block exit (the base rule): the word's targets lie where they are on the line
    # (carrier matching), so the last valid word's constraints hold as they are until the new
    # block's word shows; passing a stop point is counted where it lies (validate), not at a
    # block exit

    def levels(self, c, x, v, permitted, cab_ceiling_mps):
        return self.tvm.levels(c, x, v, permitted, cab_ceiling_mps)

    def fault(self, shown):
        fault = super().fault(shown)
        if fault is not None:
            return fault
        for name, value, lowest in (("v_permitted", shown.v_permitted_mps, 0.0), ("v_target", shown.v_target_mps, 0.0),
                                    ("target_distance", shown.target_distance_m, 0.0),
                                    ("gradient", shown.gradient_permille, -math.inf),
                                    ("word_carrier", shown.word_carrier_hz, 0.0)):
            if not (math.isfinite(value) and value >= lowest):
                return name, f"TVM-430 {name} = {value:g} is impossible"
        return None
