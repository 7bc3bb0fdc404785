"""The ATP's cab-signal modes (atp.py): how it reads the receiver's indication in one
``cab_signal`` mode — the constraints of an indication, those of no code, what passing a block
signal does, whether a standing train may start, the reaction before a lower ceiling, the trip
levels, the inputs the ATO reads and judges, its own driving under an aspect. One class per
mode; the ATP and the ATO (core.py, braking.py) ask the mode object of their run and never
branch on a mode's name. The frequency systems' and the digital systems' modes live here, the
TVM modes in their own modules (atp_tvm430.py, atp_tvm300.py); the table that names them all is
atp.py's ``CAB_SIGNAL_MODES``.

The base class holds the rules most modes share; a mode overrides what it does otherwise.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Optional, Tuple

from fmus.ato_controller.supervision import Constraints, Target
from fmus.signalling import alsu
from fmus.signalling import aspects as sig
from fmus.signalling.alsn import EQUIPMENT_INERTIA_S
from fmus.signalling.digital_messages import FREE_BLOCKS_OPEN
from fmus.units import MPS_PER_KMH

_INF = math.inf
# aspects a train may start on (docs/ato.md, departure hold): red-yellow too, since it permits
# moving up to the exit signal, which the ATP supervises as a stop target; white (no code) and
# red never
DEPARTURE_ASPECTS = (sig.GREEN, sig.YELLOW, sig.RED_YELLOW)
# driver's (here the ATO's) reaction time before a lower ceiling is supervised on its braking
# curve: ETCS T_driver (docs/sources.md#atp-margins-etcs)
T_DRIVER_S = 4.0


@dataclass(slots=True)
class Indication:
    """What the receiver shows at one step: the ATO's cab-signal inputs (core.py), each read
    by the modes whose ``inputs`` name it."""

    aspect: int = sig.WHITE
    code_valid: bool = False
    v_permitted_mps: float = 0.0
    v_target_mps: float = 0.0
    free_blocks: int = 0
    code: int = 0                       # ALSU: the code shown
    target_distance_m: float = 0.0      # TVM-430: from the word's block entry to the target point
    gradient_permille: float = 0.0      # TVM-430: the most falling gradient to the target point
    word_carrier_hz: float = 0.0        # TVM: the carrier the word came from


class CabSignalMode(ABC):
    """One ``cab_signal`` mode of the ATP of one run (``atp``: its geometry, its last valid
    indication, its counters). The class attributes are the mode's fixed rules."""

    #: the ATO's inputs this mode reads besides x and v; an impossible value of one is a
    #: measurement fault (core.py)
    inputs: Tuple[str, ...] = ("aspect",)
    has_cab_signal = True
    #: before a lower cab ceiling is supervised on its braking curve (docs/ato.md, ATP)
    reaction_s = T_DRIVER_S
    #: the receiver's display hold: how long it may show the previous section's code
    display_hold_s = EQUIPMENT_INERTIA_S
    #: red (the aspect acted upon) is an immediate stop (the ATP's stop_now)
    stops_on_red = False
    #: the aspect acted upon while no valid code is shown; None: the one shown
    lost_code_aspect: Optional[int] = None
    #: a standing train needs a permitted speed above 0 to start (as well as a departure aspect)
    departure_needs_speed = True
    #: the ATO's default planned deceleration is capped at 0.5 m/s² (core.default_plan_decel_mps2)
    plan_decel_capped = True
    #: the ATO brakes for the station's stop point, not for a stop target at or beyond it (braking.py)
    station_stop_replaces_signal_stops = False
    #: a short loss of code shuts off traction only (core.py, DIGITAL_CODE_LOSS_GRACE_S)
    bridges_code_loss = False
    #: the mode's block supervision (the TVM modes: their words' blocks and curves), else None
    tvm = None

    def __init__(self, atp):
        self.atp = atp

    @classmethod
    def reads(cls) -> str:
        """What the mode reads, for the ``cab_signal`` parameter's description."""
        return ", ".join(name for name in cls.inputs if name != "aspect") or "aspect"

    # ---- indications ----------------------------------------------------------------------
    def validate(self, x: float, shown: Indication) -> bool:
        """Whether the indication shown is a valid one of ours (one step, before the constraints)."""
        return shown.code_valid

    @abstractmethod
    def constraints(self, x: float, k: Optional[int], shown: Indication) -> Constraints:
        """What a valid indication imposes with the head at ``x`` in section ``k``: no state read
        (each mode its own)."""

    def no_code(self) -> Constraints:
        """What the no-code indication imposes: ALSN's white (40 km/h)."""
        return self.aspect_constraints(sig.WHITE, None)

    def shown_constraints(self, x: float, k: Optional[int], shown: Indication, code_valid: bool) -> Constraints:
        """What the indication shown this step imposes (``code_valid``: as :meth:`validate` judged)."""
        return self.constraints(x, k, shown) if code_valid else self.no_code()

    def remember(self, constraints: Constraints, shown: Indication) -> None:
        """A valid indication's constraints were taken as the last valid ones."""

    def passed_signal(self, previous: Optional[int], active: int) -> Tuple[int, Optional[Constraints]]:
        """The head passed the exit signal of section ``previous`` under aspect ``active``:
        (aspect, constraints) the ATP assumes until the new section can have been decoded; a
        signal passed at danger is counted here (atp.signal_passed_at_danger)."""
        return active, self.atp.last_valid

    def levels(self, c: Constraints, x: float, v: float, permitted: float,
               cab_ceiling_mps: float) -> Tuple[float, float]:
        """(trip level, permitted speed) at the head: no trip level of its own (inf: the ETCS
        dV_ebi margin applies), the permitted speed as the ATP computed it."""
        return _INF, permitted

    def permits_departure(self, aspect: int, code_valid: bool, v_permitted_mps: float) -> bool:
        """A standing train may start only on a valid permissive cab code (docs/ato.md,
        departure hold): what the receiver shows now, not a remembered code."""
        if not code_valid or int(aspect) not in DEPARTURE_ASPECTS:
            return False
        return not self.departure_needs_speed or v_permitted_mps > 0.0

    def fault(self, shown: Indication) -> Optional[Tuple[str, str]]:
        """(input, why) when an input this mode reads cannot be true, else None."""
        if not sig.WHITE <= shown.aspect <= sig.GREEN:
            return "aspect", f"cab-signal aspect = {shown.aspect} is not an aspect (0..4)"
        return None

    # ---- the ATO's planning ----------------------------------------------------------------
    def planned_limits(self) -> Tuple[Tuple[float, float, float], ...]:
        """Limits (start m, end m, speed m/s) the ATO's running-time planner plans under besides
        the line's (planner.StagePlanner ``head_limits``), each in force while the head is in
        [start, end): what the mode's cab signal shows on a free line where it is below the
        line's limits. None here: the line's limits are what a free line permits."""
        return ()

    # ---- the ATO's own driving under an aspect --------------------------------------------
    def driving_speeds(self, category: str, aspect: int) -> Tuple[Optional[float], Optional[float]]:
        """(top of the ATO's band, its speed at the exit signal) under ``aspect``, below the
        supervised speeds; None: none of its own."""
        return None, None

    def band_bottom_mps(self, category: str, aspect: int) -> Optional[float]:
        """The bottom of the ATO's traction–coast band under ``aspect``; None: none."""
        return None

    # ---- shared builders ------------------------------------------------------------------
    def aspect_constraints(self, aspect: int, k: Optional[int]) -> Constraints:
        """The constraints of an ALSN aspect (fmus/signalling/aspects.py): its ceiling, and its
        speed at the exit signal of section ``k`` (a stop on red-yellow)."""
        ceiling, at_signal = sig.alsn_speeds_mps(self.atp.category, aspect)
        c = Constraints(_INF if ceiling is None else ceiling)
        if at_signal is not None and k is not None:
            c.targets.append(Target(self.atp.exit_signal_m(k), at_signal, signal=at_signal == 0.0))
        return c

    def entered_section(self, previous: Optional[int]) -> Optional[int]:
        """The section entered on passing the exit of ``previous``; None past the line's last
        block signal (there is no section whose code to assume)."""
        return None if previous is None or previous + 1 >= len(self.atp.section_ends) else previous + 1


class NoCabSignal(CabSignalMode):
    """``off``: line limits only (plant studies without a signalling chain)."""

    inputs = ()
    has_cab_signal = False

    @classmethod
    def reads(cls) -> str:
        return "line limits only"

    def constraints(self, x, k, shown):
        return Constraints()

    def permits_departure(self, aspect, code_valid, v_permitted_mps):
        return True

    def fault(self, shown):
        return None


class AlsnMode(CabSignalMode):
    """ALSN: the aspect, through the table in fmus/signalling/aspects.py. The receiver shows
    white when it has no code, so the aspect is read whether the code is valid or not."""

    stops_on_red = True
    departure_needs_speed = False

    def constraints(self, x, k, shown):
        return self.aspect_constraints(shown.aspect, k)

    def shown_constraints(self, x, k, shown, code_valid):
        return self.aspect_constraints(shown.aspect, k)

    def passed_signal(self, previous, active):
        if active == sig.RED_YELLOW:
            self.atp.signal_passed_at_danger()
        entered = self.entered_section(previous)
        if active == sig.GREEN:
            # the worst the new section can carry is yellow (a yellow-green signal is sent as
            # green too), whose consequence is a red signal at its end: a stop target at the
            # exit of the section after the new one, not yellow's speed step
            return sig.YELLOW, Constraints() if entered is None else \
                Constraints(_INF, [Target(self.atp.exit_signal_m(entered, 1), 0.0, signal=True)])
        degraded = sig.RED_YELLOW if active == sig.YELLOW else sig.RED
        return degraded, self.aspect_constraints(degraded, entered)

    def driving_speeds(self, category, aspect):
        # the book's МИИТ reactions (fmus/signalling/aspects.py ALSN_DRIVING_KMH)
        return sig.alsn_driving_mps(category, aspect)

    def band_bottom_mps(self, category, aspect):
        return sig.alsn_band_bottom_mps(category, aspect)


class AlsuMode(CabSignalMode):
    """ALSU: the code shown (the receiver's ``code``), through the ALSU code table
    (fmus/signalling/alsu.py): its ceiling, its speed at the exit signal, and its braking — a
    permanent restriction's target is supervised on a gentler curve than a signal's
    (alsu.BRAKING_SHARE)."""

    inputs = ("aspect", "cab_code")
    display_hold_s = alsu.EQUIPMENT_INERTIA_S
    stops_on_red = True
    departure_needs_speed = False

    def __init__(self, atp):
        super().__init__(atp)
        self.system = alsu.system()
        self.last_valid_code = 0                 # the code of the last valid indication

    def constraints(self, x, k, shown):
        return self.code_constraints(shown.code, k)

    def code_constraints(self, code: int, k: Optional[int]) -> Constraints:
        """The constraints of an ALSU code: its ceiling from now on, and its speed at the exit
        signal of section ``k`` on its braking's curve (a stop there if 0)."""
        ind = self.system.indication(code, self.atp.category)
        c = Constraints(ind.permitted_kmh * MPS_PER_KMH)
        if k is not None and ind.target_kmh < ind.permitted_kmh:
            target = ind.target_kmh * MPS_PER_KMH
            c.targets.append(Target(self.atp.exit_signal_m(k), target, signal=target == 0.0,
                                    braking_share=alsu.BRAKING_SHARE[self.system.braking(code)]))
        return c

    def remember(self, constraints, shown):
        self.last_valid_code = int(shown.code)

    def passed_signal(self, previous, active):
        shown = self.last_valid_code if self.atp.last_valid is not None else 0
        if shown and self.system.indication(shown, self.atp.category).target_kmh == 0.0:
            self.atp.signal_passed_at_danger()      # passed the signal its code said to stop at
        worst = self.system.worst_next(shown) if shown else alsu.RED_CODE
        return self.system.indication(worst, self.atp.category).aspect, \
            self.code_constraints(worst, self.entered_section(previous))

    def fault(self, shown):
        fault = super().fault(shown)
        if fault is None and shown.code_valid and self.system.command_of_code(shown.code) is None:
            return "cab_code", f"cab_code = {shown.code} is not an ALSU code a wayside sends"
        return fault


class DigitalMode(CabSignalMode):
    """The digital systems (ALS-EN, FIRE_DQPSK): ``v_permitted`` from now on, ``v_target`` at
    the next signal (the exit of the current section), and a stop at the end of the
    ``free_blocks``-th section ahead while ``free_blocks`` is below 6 (the section after the
    free ones is occupied; fmus/signalling/digital_messages.py)."""

    inputs = ("aspect", "v_permitted", "v_target", "free_blocks")
    bridges_code_loss = True

    def constraints(self, x, k, shown):
        c = Constraints(max(shown.v_permitted_mps, 0.0))
        if k is not None:
            target = max(shown.v_target_mps, 0.0)
            c.targets.append(Target(self.atp.exit_signal_m(k), target, signal=target == 0.0))
            if shown.free_blocks < FREE_BLOCKS_OPEN:       # the section after the free ones is occupied
                c.targets.append(Target(self.atp.exit_signal_m(k, max(shown.free_blocks, 0)), 0.0, signal=True))
        return c

    def passed_signal(self, previous, active):
        last = self.atp.last_valid
        stop_here = last is not None and any(
            tg.signal and abs(tg.position_m - self.atp.section_ends[previous]) < 1e-6
            for tg in last.targets) if previous is not None else False
        if stop_here:
            self.atp.signal_passed_at_danger()
        return active, last

    def fault(self, shown):
        fault = super().fault(shown)
        if fault is not None:
            return fault
        for name, value in (("v_permitted", shown.v_permitted_mps), ("v_target", shown.v_target_mps)):
            if not (math.isfinite(value) and value >= 0.0):
                return name, f"cab-signal speed {name} = {value:g} m/s is impossible"
        if shown.free_blocks < 0:
            return "free_blocks", f"free_blocks = {shown.free_blocks} is negative"
        return None
