"""The ATO's own, nominal picture of the train: what it assumes when it plans and predicts.

It is tabulated from the traction unit's force functions (one source of physics) over a
speed grid and a distance grid, so planning can evaluate accelerations for many speeds at
once with ``np.interp``. The plant may differ (mass ±10 %, resistance ±20 %, voltage ±5 %):
the ATO copes by feedback, as the book's robustness section asks (docs/sources.md#ato-robustness-to-train-parameters).
"""
from __future__ import annotations

import numpy as np

from fmus.data.loader import Line, RollingStock
from fmus.traction.core import TractionCore

SPEED_STEP_MPS = 0.05


class NominalTrain:
    """Specific (per effective mass) forces of the nominal train, in m/s²."""

    def __init__(self, stock: RollingStock, line: Line):
        self.stock, self.line = stock, line
        core = TractionCore(stock, line)
        self.m_eff = core.m_eff
        self.length_m = stock.length_m
        self.max_speed_mps = stock.max_speed_mps
        self.speeds = np.arange(0.0, stock.max_speed_mps + 10.0, SPEED_STEP_MPS)
        self.traction_accel = np.array([core.max_traction_force(v) for v in self.speeds]) / core.m_eff
        self.resistance_accel = np.array([core.main_resistance(v) for v in self.speeds]) / core.m_eff
        # coasting and braking: the locomotive's idle resistance (docs/traction.md#resistance)
        self.coasting_resistance_accel = np.array([core.coasting_resistance(v) for v in self.speeds]) / core.m_eff
        self.electric_brake_accel = np.array([core.electric_brake_force(v) for v in self.speeds]) / core.m_eff
        self.service_decel = stock.service_decel
        self._core = core

    def max_traction(self, v):
        return np.interp(v, self.speeds, self.traction_accel)

    def resistance(self, v):
        """Main resistance under traction [m/s²]."""
        return np.interp(v, self.speeds, self.resistance_accel)

    def coasting_resistance(self, v):
        """Main resistance with no tractive effort (coasting, braking) [m/s²]."""
        return np.interp(v, self.speeds, self.coasting_resistance_accel)

    def electric_brake(self, v):
        return np.interp(v, self.speeds, self.electric_brake_accel)

    def path_accel(self, head_m) -> np.ndarray:
        """Gradient + curve retardation [m/s²] (positive uphill), averaged over the train."""
        head = np.atleast_1d(np.asarray(head_m, dtype=float))
        return np.array([self._core.path_resistance(x) for x in head]) / self.m_eff

    def path_accel_at(self, head_m: float) -> float:
        return self._core.path_resistance(head_m) / self.m_eff

    def resistance_slope(self, v: float) -> float:
        """dR/dv of the main resistance per effective mass [1/s] (MARECO's R')."""
        h = 0.01
        return float((self.resistance(v + h) - self.resistance(max(v - h, 0.0))) / (v + h - max(v - h, 0.0)))
