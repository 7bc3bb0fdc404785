"""Longitudinal train dynamics: the plant that moves the train (no FMI here).

Equation of motion (ПТР form, SI):

    m·(1+γ)·dv/dt = F_t(v, command) − F_e(v) − F_p(t) − W(v) − m·g·(i + w_r)/1000

* F_t: traction share × min(effort curve F_U(v), adhesion ψ(v)·m_powered·g); zero above the
  vehicle's maximum speed. F_U is the effort table at the catenary voltage U (EffortCurve).
* F_e: electric brake (rheostatic or regenerative), immediate, covers the brake demand first.
* F_p: pneumatic brake, a state: it follows (brake demand delayed by the application
  delay − electric brake force) with a first-order build-up, dF_p/dt = (target − F_p)/T
  (brake_pipeline.py, shared with the ATO's nominal copy).
* W(v): main resistance Σ share_k·(a + bV + cV²)·m·g/1000 (V in km/h, coefficients in N/kN),
  under traction the units' traction formulas, with no tractive effort (coasting, braking)
  their idle formulas (ПТР: a locomotive's idle resistance is higher); starting resistance
  28/(q0+7) N/kN only as a breakaway threshold at standstill.
* i + w_r: gradient (‰) and curve resistance 700/R (N/kN), averaged over the train length.

Integration: classical RK4 on (x, v, F_p, energy drawn, energy returned) with sub-steps no longer
than ``max_substep_s`` and split where the delayed brake demand changes; a stop inside a sub-step is located so
the speed never goes negative, and a stopped train stays stopped until the tractive (or
gravity) force exceeds what holds it (breakaway resistance, curve, brakes).

Electrical side: P = F_t·v/η + P_aux drawn from the line; a regenerative brake returns
F_e·v·η_e. i_traction = P_net/U on DC, P_net/(U·cos φ) on AC (positive = drawn).
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import List, Optional

from fmus.data.loader import NOMINAL_VOLTAGE_V, Line, RollingStock
from fmus.units import KMH_PER_MPS, STANDARD_GRAVITY_MPS2
from fmus.errors import FmuInputError
from fmus.traction.brake_pipeline import BrakePipeline


def _interp(xs: List[float], ys: List[float], x: float) -> float:
    """Piecewise-linear table look-up, held constant outside the table (plain floats: hot path)."""
    if x <= xs[0]:
        return ys[0]
    if x >= xs[-1]:
        return ys[-1]
    k = bisect.bisect_right(xs, x) - 1
    x0 = xs[k]
    return ys[k] + (ys[k + 1] - ys[k]) * (x - x0) / (xs[k + 1] - x0)


#: the voltage at which a rolling-stock file's effort table holds, per electrical system
RATED_VOLTAGE_V = {system: volts for system, volts in NOMINAL_VOLTAGE_V.items() if volts > 0}
#: relative spread of F·v within which the end of an effort table counts as the constant-power
#: (natural) characteristic of the motors
CONSTANT_POWER_TOLERANCE = 0.01


def natural_characteristic_start(speeds: List[float], forces: List[float]) -> Optional[int]:
    """Index of the first point of the effort table's constant-power tail (F·v within 1 % of the
    last point's), or None when the table ends in fewer than two such points (docs/traction.md)."""
    power = speeds[-1] * forces[-1]
    k = len(speeds) - 1
    while k > 0 and speeds[k - 1] > 0 and abs(speeds[k - 1] * forces[k - 1] - power) <= CONSTANT_POWER_TOLERANCE * power:
        k -= 1
    return k if k < len(speeds) - 1 and power > 0 else None


class EffortCurve:
    """The effort table at a catenary voltage U (docs/traction.md#effort-and-catenary-voltage).

    The table holds at the stock's rated voltage U_n (RATED_VOLTAGE_V). Below its transition speed v_t it is the limit
    set by the starting current and adhesion, which the voltage does not change; from v_t on it
    is the motors' natural characteristic. At a given motor current (so a given effort) a
    series motor's speed is proportional to the voltage at its terminals, which on DC is the
    catenary voltage and on AC the rectified secondary voltage, itself proportional to the
    catenary voltage at the top regulation zone; so the natural characteristic at U is
    F_n(v·U_n/U), and

        F_U(v) = min(F_limit(v), F_natural(v·U_n/U))
        F_limit(v) = F(min(v, v_t))                    (the current limit held above v_t)
        F_natural(w) = F(w) for w ≥ v_t, max(F(w), F(v_t)·v_t/w) below (the hyperbola)

    which is the table itself at U = U_n. A table without a constant-power tail does not
    depend on the voltage."""

    def __init__(self, speeds: List[float], forces: List[float], voltage_ratio: float):
        self.speeds, self.forces = list(speeds), list(forces)
        k = natural_characteristic_start(self.speeds, self.forces)
        self.scaled = k is not None and voltage_ratio != 1.0
        if self.scaled:
            self.v_t = self.speeds[k]
            self.f_t = self.forces[k]
            self.speed_factor = 1.0 / voltage_ratio            # U_n/U

    def __call__(self, v: float) -> float:
        if not self.scaled:
            return _interp(self.speeds, self.forces, v)
        v_t, f_t = self.v_t, self.f_t
        limit = _interp(self.speeds, self.forces, v) if v < v_t else f_t
        w = v * self.speed_factor
        natural = _interp(self.speeds, self.forces, w)
        if w < v_t:
            natural = max(natural, f_t * v_t / w) if w > 0.0 else math.inf
        return min(limit, natural)


def _train_poly(terms, scale: float):
    """(a, b, c) of the train's specific resistance in N/kN (V in km/h): the units' mass-weighted sum."""
    return tuple(sum(share * coefs[k] for share, *coefs in terms) * scale for k in range(3))


@dataclass
class TractionOutputs:
    x_m: float = 0.0
    v_mps: float = 0.0
    a_mps2: float = 0.0
    force_traction_n: float = 0.0
    force_brake_n: float = 0.0
    i_traction_a: float = 0.0
    energy_j: float = 0.0             # net energy from the line (drawn − returned)
    energy_returned_j: float = 0.0
    notch: int = 0
    brake_step: int = 0
    commands_clamped: int = 0
    stop_time_s: float = -1.0         # when the train last came to a stop; −1 while moving
    off_line: bool = False


#: declared bounds of the parameters (docs/interfaces.md): a line position (10 000 km), a speed
#: above any train's (540 km/h) and a pantograph voltage above any system's (25 kV AC: 29 kV peak)
MAX_LINE_M = 1.0e7
MAX_SPEED_MPS = 150.0
MAX_PANTOGRAPH_V = 50_000.0
#: most RK4 sub-steps one communication step may take (about two seconds of computing): a longer
#: step is refused before anything changes, never integrated for hours (docs/traction.md)
MAX_SUBSTEPS_PER_STEP = 100_000


class TractionCore:
    """One train's longitudinal dynamics over one line."""

    def __init__(self, stock: RollingStock, line: Line, x0_m: float = 400.0, v0_mps: float = 0.0,
                 pantograph_voltage_v: float = 0.0, mass_scale: float = 1.0, resistance_scale: float = 1.0,
                 max_substep_s: float = 0.5):
        if stock.electrical_system != "none" and line.electrification != "none" \
                and stock.electrical_system != line.electrification:
            raise FmuInputError(f"{stock.path}: field electrical.system: {stock.electrical_system} stock "
                                f"cannot run on {line.path} ({line.electrification})")
        for name, value in (("mass_scale", mass_scale), ("resistance_scale", resistance_scale),
                            ("max_substep_s", max_substep_s)):
            if not value > 0:
                raise FmuInputError(f"parameter {name}: must be positive, got {value}")
        if not 0.0 <= v0_mps <= MAX_SPEED_MPS:
            raise FmuInputError(f"parameter v0: must lie in 0..{MAX_SPEED_MPS:g} m/s, got {v0_mps}")
        if not 0.0 <= x0_m <= line.length_m:
            raise FmuInputError(f"parameter x0: {x0_m:g} m is outside the line {line.path} (0..{line.length_m:g} m)")
        self.stock, self.line = stock, line
        self.mass_kg = stock.mass_kg * mass_scale
        self.powered_mass_kg = stock.powered_mass_kg * mass_scale
        self.m_eff = self.mass_kg * (1.0 + stock.gamma)
        self.weight_kn = self.mass_kg * STANDARD_GRAVITY_MPS2 / 1000.0    # N per (N/kN)
        self.traction_resistance_poly = _train_poly(stock.resistance_terms, resistance_scale)
        # no tractive effort (coasting, braking): a locomotive's idle formula (ПТР, docs/traction.md#resistance)
        self.idle_resistance_poly = _train_poly(stock.idle_resistance_terms or stock.resistance_terms, resistance_scale)
        self.breakaway_n_per_kn = stock.starting_resistance * resistance_scale
        self.voltage_v = pantograph_voltage_v if pantograph_voltage_v > 0 else line.nominal_voltage_v
        if stock.electrical_system != "none" and self.voltage_v <= 0:
            raise FmuInputError("parameter pantograph_voltage: an electric train needs a positive voltage")
        self.power_factor = stock.power_factor if stock.electrical_system == "AC25000" else 1.0
        # the effort table holds at the stock's rated voltage (docs/traction.md#effort-and-catenary-voltage)
        rated_v = RATED_VOLTAGE_V.get(stock.electrical_system)
        self.effort = EffortCurve(stock.effort_speeds, stock.effort_forces,
                                  self.voltage_v / rated_v if rated_v else 1.0)
        self.max_substep_s = max_substep_s
        self.x, self.v = float(x0_m), float(v0_mps)
        self.energy_drawn = 0.0
        self.energy_returned = 0.0
        self.brake_force = 0.0                                # pneumatic, N
        # brake demands in N; the sub-steps end on the demands' times, so only rounding separates them
        self.brake_pipeline = BrakePipeline(stock.brake_delay_s, stock.brake_time_constant_s,
                                            self.m_eff * stock.emergency_decel, self.electric_brake_force,
                                            due_tolerance_s=1e-12)
        self.out = TractionOutputs(x_m=self.x, v_mps=self.v, stop_time_s=0.0 if self.v == 0 else -1.0)
        self._share_t = 0.0

    # ---- forces ---------------------------------------------------------------------------
    def max_traction_force(self, v: float) -> float:
        stock = self.stock
        if v >= stock.max_speed_mps:
            return 0.0
        vk = v * KMH_PER_MPS
        p0, p1, p2, p3, p4 = stock.adhesion
        adhesion = (p0 + p1 / (p2 + p3 * vk) + p4 * vk) * self.powered_mass_kg * STANDARD_GRAVITY_MPS2
        return min(self.effort(v), adhesion)

    def electric_brake_force(self, v: float) -> float:
        if self.stock.ebrake_kind is None:
            return 0.0
        return _interp(self.stock.ebrake_speeds, self.stock.ebrake_forces, v)

    def main_resistance(self, v: float) -> float:
        """Main resistance [N] under traction (the units' traction formulas)."""
        return self._resistance(v, self.traction_resistance_poly)

    def coasting_resistance(self, v: float) -> float:
        """Main resistance [N] with no tractive effort: coasting and braking (idle formulas)."""
        return self._resistance(v, self.idle_resistance_poly)

    def _resistance(self, v: float, poly=None) -> float:
        """Main resistance [N] in the present mode (``poly`` None: the traction formulas while a
        tractive effort is commanded, the idle ones otherwise), or with ``poly``."""
        a, b, c = poly or (self.traction_resistance_poly if self._share_t > 0.0 else self.idle_resistance_poly)
        vk = v * KMH_PER_MPS
        return (a + b * vk + c * vk * vk) * self.weight_kn

    def path_resistance(self, x: float) -> float:
        """Gradient + curve force [N], positive against the running direction."""
        return self.line.mean_path_resistance(x, self.stock.length_m) * self.weight_kn

    def _derivatives(self, x: float, v: float, f_p: float):
        """(dv/dt, dF_p/dt, power drawn W, power returned W) while moving."""
        brakes = self.brake_pipeline
        f_t = self._share_t * self.max_traction_force(v)
        f_e = brakes.electric(v)
        net = f_t - f_e - f_p - self._resistance(v) - self.path_resistance(x)
        df_p = brakes.build_up_rate(f_p, brakes.pneumatic_target(f_e))
        drawn = f_t * v / self.stock.efficiency + self.stock.auxiliary_w
        returned = f_e * v * self.stock.ebrake_efficiency if self.stock.ebrake_kind == "regenerative" else 0.0
        return net / self.m_eff, df_p, drawn, returned

    # ---- stepping -------------------------------------------------------------------------
    def set_command(self, time_s: float, command: float, emergency: bool) -> None:
        out = self.out
        if not (command == command):      # NaN: fail safe to full service brake
            command = -1.0
            out.commands_clamped += 1
        elif command > 1.0 or command < -1.0:
            command = max(-1.0, min(1.0, command))
            out.commands_clamped += 1
        self._share_t = command if command > 0.0 and not emergency else 0.0
        share_b = -command if command < 0.0 else 0.0
        self.brake_pipeline.command(time_s, share_b * self.m_eff * self.stock.service_decel, bool(emergency))
        out.notch = math.ceil(self._share_t * self.stock.notches - 1e-9) if self._share_t > 0 else 0
        out.brake_step = (self.stock.brake_steps + 1 if emergency else
                          math.ceil(share_b * self.stock.brake_steps - 1e-9) if share_b > 0 else 0)

    def step_refusal(self, step_s: float) -> Optional[str]:
        """Why a communication step of ``step_s`` is refused (too many sub-steps), or None."""
        needed = step_s / self.max_substep_s
        if not needed <= MAX_SUBSTEPS_PER_STEP:
            return (f"a step of {step_s:g} s needs {needed:.3g} sub-steps of at most max_substep = "
                    f"{self.max_substep_s:g} s; at most {MAX_SUBSTEPS_PER_STEP} are taken per step")
        return None

    def step(self, time_s: float, step_s: float, command: float, emergency: bool = False) -> TractionOutputs:
        refusal = self.step_refusal(step_s)
        if refusal is not None:
            raise FmuInputError(refusal)
        self.set_command(time_s, command, emergency)
        end = time_s + step_s
        t = time_s
        brakes = self.brake_pipeline
        while t < end - 1e-12:
            brakes.take_due(t)
            limit = min(brakes.next_change_s(), end)
            n = max(1, math.ceil((limit - t) / self.max_substep_s - 1e-9))
            dt = (limit - t) / n
            for _ in range(n):
                self._substep(t, dt)
                t += dt
            t = limit
        return self._publish(end)

    def _rk4(self, x: float, v: float, f_p: float, dt: float):
        d = self._derivatives
        a1, b1, p1, r1 = d(x, v, f_p)
        v2, f2 = v + 0.5 * dt * a1, f_p + 0.5 * dt * b1
        a2, b2, p2, r2 = d(x + 0.5 * dt * v, v2, f2)
        v3, f3 = v + 0.5 * dt * a2, f_p + 0.5 * dt * b2
        a3, b3, p3, r3 = d(x + 0.5 * dt * v2, v3, f3)
        v4, f4 = v + dt * a3, f_p + dt * b3
        a4, b4, p4, r4 = d(x + dt * v3, v4, f4)
        return (x + dt * (v + 2 * v2 + 2 * v3 + v4) / 6.0,
                v + dt * (a1 + 2 * a2 + 2 * a3 + a4) / 6.0,
                f_p + dt * (b1 + 2 * b2 + 2 * b3 + b4) / 6.0,
                dt * (p1 + 2 * p2 + 2 * p3 + p4) / 6.0,
                dt * (r1 + 2 * r2 + 2 * r3 + r4) / 6.0)

    def _substep(self, t: float, dt: float) -> None:
        if self.stock.brake_time_constant_s <= 0.0:
            brakes = self.brake_pipeline
            self.brake_force = brakes.pneumatic_target(brakes.electric(self.v))
        if self.v <= 0.0:
            self._standstill(dt)
            return
        x, v, f_p = self.x, self.v, self.brake_force
        x1, v1, f1, drawn, returned = self._rk4(x, v, f_p, dt)
        if v1 > 0.0:
            self.x, self.v, self.brake_force = x1, v1, f1
            self.energy_drawn += drawn
            self.energy_returned += returned
            return
        # the train stops inside this sub-step: find the stop instant (regula falsi on
        # v(t_stop) = 0 with RK4 from the sub-step start), then stand for the rest
        lo, v_lo, hi, v_hi = 0.0, v, dt, v1
        t_stop = dt
        for _ in range(40):
            t_stop = lo + (hi - lo) * v_lo / (v_lo - v_hi)
            x1, v1, f1, drawn, returned = self._rk4(x, v, f_p, t_stop)
            if abs(v1) < 1e-7 or hi - lo < 1e-9:
                break
            if v1 > 0.0:
                lo, v_lo = t_stop, v1
            else:
                hi, v_hi = t_stop, v1
        self.x, self.v, self.brake_force = x1, 0.0, f1
        self.energy_drawn += drawn
        self.energy_returned += returned
        self.out.stop_time_s = t + t_stop
        if dt - t_stop > 1e-12:
            self._standstill(dt - t_stop)

    def _standstill(self, dt: float) -> None:
        """At v = 0: start only when the driving force beats everything that holds the train."""
        brakes = self.brake_pipeline
        target = brakes.pneumatic_target(brakes.electric(0.0))
        f0 = self.brake_force
        f_end = brakes.relax(f0, target, dt)
        length = self.stock.length_m
        gradient = self.line.mean_gradient(self.x, length)
        curve = self.line.mean_curve_resistance(self.x, length)
        driving = self._share_t * self.max_traction_force(0.0) - gradient * self.weight_kn  # downhill helps
        holding = (self.breakaway_n_per_kn + curve) * self.weight_kn + self._resistance(0.0) + max(f0, f_end)
        self.energy_drawn += dt * self.stock.auxiliary_w
        self.brake_force = f_end
        if driving > holding:
            # breakaway: once moving, the starting resistance no longer holds; integrate the
            # rest of the sub-step as motion from (practically) zero speed
            x1, v1, f1, drawn, returned = self._rk4(self.x, 1e-9, f0, dt)
            if v1 > 0.0:
                self.x, self.v, self.brake_force = x1, v1, f1
                self.energy_drawn += drawn - dt * self.stock.auxiliary_w
                self.energy_returned += returned
                self.out.stop_time_s = -1.0

    def _publish(self, time_s: float) -> TractionOutputs:
        out = self.out
        v = self.v
        out.x_m, out.v_mps = self.x, v
        f_e = self.brake_pipeline.electric(v) if v > 0 else 0.0
        out.force_traction_n = self._share_t * self.max_traction_force(v) if v > 0 or self._share_t > 0 else 0.0
        out.force_brake_n = f_e + self.brake_force
        if v > 0:
            out.a_mps2 = self._derivatives(self.x, v, self.brake_force)[0]
        else:
            out.a_mps2 = 0.0
        drawn = out.force_traction_n * v / self.stock.efficiency + self.stock.auxiliary_w
        returned = f_e * v * self.stock.ebrake_efficiency if self.stock.ebrake_kind == "regenerative" else 0.0
        if self.stock.electrical_system == "none":
            out.i_traction_a = 0.0
        else:
            out.i_traction_a = (drawn - returned) / (self.voltage_v * self.power_factor)
        out.energy_j = self.energy_drawn - self.energy_returned
        out.energy_returned_j = self.energy_returned
        out.off_line = not (0.0 <= self.x <= self.line.length_m)
        return out
