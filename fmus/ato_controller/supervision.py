"""What the ATP supervises (atp.py): constraints, a ceiling now and targets ahead, and the
ETCS-like intervention margins above the permitted speed (docs/sources.md#atp-margins-etcs).
Shared by the ATP, its TVM-430 curves (atp_tvm430.py), the temporary restrictions
(speed_restrictions.py) and the ATO's planning."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import List, Optional

from fmus.units import KMH_PER_MPS, MPS_PER_KMH


def dv_ebi_mps(v_mps: float) -> float:
    """Emergency-brake intervention margin (ETCS dV_ebi, docs/sources.md#atp-margins-etcs)."""
    v_kmh = v_mps * KMH_PER_MPS
    if v_kmh <= 110.0:
        return 7.5 * MPS_PER_KMH
    return min(7.5 + 7.5 * (v_kmh - 110.0) / 100.0, 15.0) * MPS_PER_KMH


def dv_sbi_mps(v_mps: float) -> float:
    """Service-brake intervention margin: 5.5 km/h up to 110 km/h, rising to 10 km/h at
    210 km/h (ETCS national-value defaults as commonly quoted [U])."""
    v_kmh = v_mps * KMH_PER_MPS
    if v_kmh <= 110.0:
        return 5.5 * MPS_PER_KMH
    return min(5.5 + 4.5 * (v_kmh - 110.0) / 100.0, 10.0) * MPS_PER_KMH


@dataclass(frozen=True)
class Target:
    """A speed to be reached at a position, supervised on a braking curve towards it."""

    position_m: float
    speed_mps: float
    signal: bool = False          # a stop target at a signal (the ATO stops short of it)
    braking_share: float = 1.0    # of the supervision deceleration (ALSU: a permanent restriction's is gentler)
    # TVM430: the speed of the trip curve at the target (its control level; a stop: 0), and the
    # transmitted gradient (‰, + uphill) the curves are computed on; None: an ETCS-like target
    trip_speed_mps: Optional[float] = None
    gradient_permille: float = 0.0
    trip_position_m: Optional[float] = None   # TVM430: where the trip curve ends; None: position_m


@dataclass
class Constraints:
    """What one source imposes (the line, a restriction, a cab indication): a ceiling from now
    on and targets ahead; :meth:`add` combines two (the lower ceiling, every target)."""

    ceiling_mps: float = math.inf
    targets: List[Target] = field(default_factory=list)

    def add(self, other: "Constraints") -> None:
        self.ceiling_mps = min(self.ceiling_mps, other.ceiling_mps)
        self.targets.extend(other.targets)
