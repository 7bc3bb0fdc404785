"""The reference train an ATO under test drives in its conformance vectors' closed loop."""
from __future__ import annotations

import math
from typing import Dict, Mapping, Tuple

from fmus.signalling.aspects import GREEN


class ReferenceTrain:
    """The reference train an ATO drives in a closed loop: our traction core (fmus/traction)
    with the bundled rolling stock and line, stepped after the ATO with its command
    (Gauss-Seidel, as the shipped systems couple them)."""

    def __init__(self, spec: Mapping):
        from fmus.data.loader import DEFAULT_LINE, DEFAULT_ROLLING_STOCK, load_line, load_rolling_stock
        from fmus.traction.core import TractionCore

        line = load_line(str(DEFAULT_LINE))
        self.core = TractionCore(load_rolling_stock(str(DEFAULT_ROLLING_STOCK)), line, x0_m=spec["x0_m"])
        self.zones = [tuple(z) for z in spec.get("cab_zones", ())]
        self.clear_s = spec.get("cab_clear_s", math.inf)
        self.state = self.core.out

    def cab(self, t: float) -> Tuple[int, bool]:
        if t < self.clear_s:
            for start, end, aspect in self.zones:
                if start <= self.state.x_m < end:
                    return int(aspect), True
        return GREEN, True

    def values(self) -> Dict[str, float]:
        return {"plant.x": self.state.x_m, "plant.v": self.state.v_mps, "plant.a": self.state.a_mps2}
