"""Longitudinal train dynamics: the plant that moves the train (no FMI here).

Equation of motion (ПТР form, SI):

    m·(1+γ)·dv/dt = F_t(v, command) − F_e(v) − F_p(t) − W(v) − m·g·(i + w_r)/1000

* F_t: traction share × min(effort curve F(v), adhesion ψ(v)·m_powered·g); zero above the
  vehicle's maximum speed.
* F_e: electric brake (rheostatic or regenerative), immediate, covers the brake demand first.
* F_p: pneumatic brake. Its target steps with the command after an application delay and
  the force follows it with a first-order build-up (analytic within constant-target pieces).
* W(v): main resistance Σ share_k·(a + bV + cV²)·m·g/1000 (V in km/h, coefficients in N/kN),
  starting resistance 28/(q0+7) N/kN only as a breakaway threshold at standstill.
* i + w_r: gradient (‰) and curve resistance 700/R (N/kN), averaged over the train length.

Integration: classical RK4 on (x, v, energy drawn, energy returned) with sub-steps no longer
than ``max_substep_s`` and split at brake-force kinks; a stop inside a sub-step is located so
the speed never goes negative, and a stopped train stays stopped until the tractive (or
gravity) force exceeds what holds it (breakaway resistance, curve, brakes).

Electrical side: P = F_t·v/η + P_aux drawn from the line; a regenerative brake returns
F_e·v·η_e. i_traction = P_net/U on DC, P_net/(U·cos φ) on AC (positive = drawn).
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass
from typing import List, Optional, Tuple

from ..common.data import G, Line, RollingStock
from ..common.slave import FmuInputError

KMH = 3.6


def _interp(xs: List[float], ys: List[float], x: float) -> float:
    """Piecewise-linear table look-up, held constant outside the table (plain floats: hot path)."""
    if x <= xs[0]:
        return ys[0]
    if x >= xs[-1]:
        return ys[-1]
    k = bisect.bisect_right(xs, x) - 1
    x0 = xs[k]
    return ys[k] + (ys[k + 1] - ys[k]) * (x - x0) / (xs[k + 1] - x0)


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


class TractionCore:
    """One train's longitudinal dynamics over one line."""

    def __init__(self, stock: RollingStock, line: Line, x0_m: float = 0.0, v0_mps: float = 0.0,
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
        if v0_mps < 0:
            raise FmuInputError(f"parameter v0: must not be negative, got {v0_mps}")
        self.stock, self.line = stock, line
        self.mass_kg = stock.mass_kg * mass_scale
        self.powered_mass_kg = stock.powered_mass_kg * mass_scale
        self.m_eff = self.mass_kg * (1.0 + stock.gamma)
        self.weight_kn = self.mass_kg * G / 1000.0    # N per (N/kN)
        self.resistance_poly = tuple(
            sum(share * coef for share, *coefs in stock.resistance_terms for coef in [coefs[k]]) * resistance_scale
            for k in range(3))
        self.breakaway_n_per_kn = stock.starting_resistance * resistance_scale
        self.voltage_v = pantograph_voltage_v if pantograph_voltage_v > 0 else line.nominal_voltage_v
        if stock.electrical_system != "none" and self.voltage_v <= 0:
            raise FmuInputError("parameter pantograph_voltage_v: an electric train needs a positive voltage")
        self.power_factor = stock.power_factor if stock.electrical_system == "AC25000" else 1.0
        self.max_substep_s = max_substep_s
        self.x, self.v = float(x0_m), float(v0_mps)
        self.energy_drawn = 0.0
        self.energy_returned = 0.0
        self.brake_force = 0.0                            # pneumatic, N
        self._brake_events: List[Tuple[float, float]] = []   # (effective time, target N)
        self._brake_target_now = 0.0
        self._last_requested_target = 0.0
        self.out = TractionOutputs(x_m=self.x, v_mps=self.v, stop_time_s=0.0 if self.v == 0 else -1.0)
        self._share_t, self._share_b, self._emergency = 0.0, 0.0, False

    # ---- forces ---------------------------------------------------------------------------
    def max_traction_force(self, v: float) -> float:
        stock = self.stock
        if v >= stock.max_speed_mps:
            return 0.0
        vk = v * KMH
        p0, p1, p2, p3, p4 = stock.adhesion
        adhesion = (p0 + p1 / (p2 + p3 * vk) + p4 * vk) * self.powered_mass_kg * G
        return min(_interp(stock.effort_speeds, stock.effort_forces, v), adhesion)

    def electric_brake_force(self, v: float) -> float:
        if self.stock.ebrake_kind is None:
            return 0.0
        return _interp(self.stock.ebrake_speeds, self.stock.ebrake_forces, v)

    def main_resistance(self, v: float) -> float:
        a, b, c = self.resistance_poly
        vk = v * KMH
        return (a + b * vk + c * vk * vk) * self.weight_kn

    def path_resistance(self, x: float) -> float:
        """Gradient + curve force [N], positive against the running direction."""
        return self.line.mean_path_resistance(x, self.stock.length_m) * self.weight_kn

    def _electric_share(self, v: float) -> float:
        if self._emergency or self._share_b <= 0.0:
            return 0.0
        demand = self._share_b * self.m_eff * self.stock.service_decel
        return min(demand, self.electric_brake_force(v))

    def _accel(self, x: float, v: float, f_pneumatic: float) -> Tuple[float, float, float]:
        """(dv/dt, power drawn W, power returned W) while moving."""
        f_t = self._share_t * self.max_traction_force(v)
        f_e = self._electric_share(v)
        net = f_t - f_e - f_pneumatic - self.main_resistance(v) - self.path_resistance(x)
        drawn = f_t * v / self.stock.efficiency + self.stock.auxiliary_w
        returned = f_e * v * self.stock.ebrake_efficiency if self.stock.ebrake_kind == "regenerative" else 0.0
        return net / self.m_eff, drawn, returned

    # ---- pneumatic brake ------------------------------------------------------------------
    def _request_brake(self, time_s: float, target_n: float) -> None:
        if target_n != self._last_requested_target:
            # release acts after the same delay as application (triple valve), kept simple
            self._brake_events.append((time_s + self.stock.brake_delay_s, target_n))
            self._last_requested_target = target_n

    def _brake_force_at(self, f0: float, target: float, dt: float) -> float:
        tau = self.stock.brake_time_constant_s
        if tau <= 0.0:
            return target
        return target + (f0 - target) * math.exp(-dt / tau)

    # ---- stepping -------------------------------------------------------------------------
    def set_command(self, time_s: float, command: float, emergency: bool) -> None:
        out = self.out
        if not (command == command):      # NaN: fail safe to full service brake
            command = -1.0
            out.commands_clamped += 1
        elif command > 1.0 or command < -1.0:
            command = max(-1.0, min(1.0, command))
            out.commands_clamped += 1
        self._emergency = bool(emergency)
        self._share_t = command if command > 0.0 and not emergency else 0.0
        self._share_b = -command if command < 0.0 else 0.0
        if emergency:
            target = self.m_eff * self.stock.emergency_decel
        else:
            # the pneumatic target is what the electric brake cannot give at the current speed
            demand = self._share_b * self.m_eff * self.stock.service_decel
            target = max(demand - self.electric_brake_force(self.v) if self.stock.ebrake_kind else demand, 0.0)
        self._request_brake(time_s, target)
        out.notch = math.ceil(self._share_t * self.stock.notches - 1e-9) if self._share_t > 0 else 0
        out.brake_step = (self.stock.brake_steps + 1 if emergency else
                          math.ceil(self._share_b * self.stock.brake_steps - 1e-9) if self._share_b > 0 else 0)

    def step(self, time_s: float, step_s: float, command: float, emergency: bool = False) -> TractionOutputs:
        self.set_command(time_s, command, emergency)
        end = time_s + step_s
        t = time_s
        while t < end - 1e-12:
            # next kink of the pneumatic target inside this step
            while self._brake_events and self._brake_events[0][0] <= t + 1e-12:
                self._brake_target_now = self._brake_events.pop(0)[1]
            limit = end
            if self._brake_events and self._brake_events[0][0] < end:
                limit = self._brake_events[0][0]
            n = max(1, math.ceil((limit - t) / self.max_substep_s - 1e-9))
            dt = (limit - t) / n
            for _ in range(n):
                self._substep(t, dt)
                t += dt
            t = limit
        return self._publish(end)

    def _substep(self, t: float, dt: float) -> None:
        target = self._brake_target_now
        f0 = self.brake_force
        f_mid = self._brake_force_at(f0, target, 0.5 * dt)
        f_end = self._brake_force_at(f0, target, dt)
        if self.v <= 0.0:
            self._standstill(t, dt, f0, f_end)
            return
        x, v = self.x, self.v
        a1, p1, r1 = self._accel(x, v, f0)
        a2, p2, r2 = self._accel(x + 0.5 * dt * v, v + 0.5 * dt * a1, f_mid)
        v2 = v + 0.5 * dt * a1
        a3, p3, r3 = self._accel(x + 0.5 * dt * v2, v + 0.5 * dt * a2, f_mid)
        v3 = v + 0.5 * dt * a2
        v4 = v + dt * a3
        a4, p4, r4 = self._accel(x + dt * v3, v4, f_end)
        v_new = v + dt * (a1 + 2 * a2 + 2 * a3 + a4) / 6.0
        if v_new > 0.0:
            self.x = x + dt * (v + 2 * v2 + 2 * v3 + v4) / 6.0
            self.v = v_new
            self.energy_drawn += dt * (p1 + 2 * p2 + 2 * p3 + p4) / 6.0
            self.energy_returned += dt * (r1 + 2 * r2 + 2 * r3 + r4) / 6.0
            self.brake_force = f_end
            return
        # the train stops inside this sub-step: locate the stop with the mean deceleration,
        # refine once with an RK4 step of that length, then stand for the rest
        a_mean = (v_new - v) / dt
        t_stop = min(dt, v / -a_mean)
        for _ in range(2):
            a1, p1, _ = self._accel(x, v, f0)
            f_half = self._brake_force_at(f0, target, 0.5 * t_stop)
            a2, _, _ = self._accel(x + 0.5 * t_stop * v, v + 0.5 * t_stop * a1, f_half)
            v_half = v + 0.5 * t_stop * a2
            v_end = v + t_stop * a2
            if abs(v_end) < 1e-6 or a2 >= 0:
                break
            t_stop = min(dt, t_stop + v_end / -a2)
        self.x = x + t_stop * v_half
        self.energy_drawn += t_stop * p1
        self.v = 0.0
        self.brake_force = self._brake_force_at(f0, target, t_stop)
        self.out.stop_time_s = t + t_stop
        if dt - t_stop > 1e-12:
            self._standstill(t + t_stop, dt - t_stop, self.brake_force, f_end)

    def _standstill(self, t: float, dt: float, f0: float, f_end: float) -> None:
        """At v = 0: start only when the driving force beats everything that holds the train."""
        length = self.stock.length_m
        gradient = self.line.mean_gradient(self.x, length)
        curve = self.line.mean_curve_resistance(self.x, length)
        driving = self._share_t * self.max_traction_force(0.0) - gradient * self.weight_kn  # downhill helps
        holding = (self.breakaway_n_per_kn + curve) * self.weight_kn + self.main_resistance(0.0) + max(f0, f_end)
        net = driving - holding
        self.energy_drawn += dt * self.stock.auxiliary_w
        self.brake_force = f_end
        if net > 0.0:
            # breakaway: accelerate with the net force for the rest of the (short) sub-step
            a = net / self.m_eff
            self.v = a * dt
            self.x += 0.5 * a * dt * dt
            self.out.stop_time_s = -1.0

    def _publish(self, time_s: float) -> TractionOutputs:
        out = self.out
        v = self.v
        out.x_m, out.v_mps = self.x, v
        f_e = self._electric_share(v) if v > 0 else 0.0
        out.force_traction_n = self._share_t * self.max_traction_force(v) if v > 0 or self._share_t > 0 else 0.0
        out.force_brake_n = f_e + self.brake_force
        if v > 0:
            out.a_mps2 = self._accel(self.x, v, self.brake_force)[0]
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
