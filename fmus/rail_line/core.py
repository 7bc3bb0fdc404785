"""Rail line plant: K coded track circuits, M trains, receiver coil EMF, traction interference,
track relays (no FMI here).

Per section the network of track_circuit.py is generated for the current position of the
front-most wheelset in it (snapped to the network's nodes), turned into a state-space model by
modified nodal analysis (network.py) and discretised exactly at fs (zero-order hold). Models
are cached per (shunt node, faults); the branch currents (the states) carry over when the
train moves to the next node, and the code-current amplitude is interpolated between nodes
from the phasor solution, so it varies continuously with position ("regenerated and
interpolated as the trains move"). The configuration is taken every 10 ms of simulated time,
whatever the frame length, so frames of any length give the same result.

Coil EMF (DESIGN §4, seed 002 §3): coils ``coil_offset`` (1.5 m) ahead of the first wheelset,
EMF = M·d/dt of the loop current they see, which is

* over their own section, between the wheelset and the feed leads: the shunt current;
* between the feed leads and the exit joint: nothing (the ≈ 1 m null zone);
* over the next section, before the wheelset has crossed: that section's entry-end current,
  weak because it is not shunted yet (the ≈ 1.5 m weak zone);

averaged over the coil's sensitivity length, plus the traction return current's asymmetric
part a(x)·i_traction(t): a per-section asymmetry (seeded, 1–5 %), falling linearly to zero
between the bond leads and the joint where the centre-tap jumper balances the rails, so each
joint gives
two pulses of opposite polarity, each (lead offset + coil length)/v wide: 1.3 m, 0.059 s at
80 km/h as seed 002 measured (table row 6), amplitude ∝ v. DC
traction adds 300/600 Hz rectifier ripple, AC traction 50 Hz with odd harmonics. The time
derivative is taken on the sampled current, so the motion term v·∂i/∂x is included.

Track relays: the relay-end voltage of the track circuit's own feed (phasor at the carrier,
relative to the free circuit at the design ballast) against pick-up / drop-out ratios, with
pick-up and drop-out delays → ``occupied[k]``. Positions outside the line are reported, not
errors.
"""
from __future__ import annotations

import bisect
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

import numpy as np
from scipy.signal import lfilter

from ..common.data import Line
from ..common.slave import FmuInputError
from .network import discretise
from .track_circuit import CircuitParameters, Faults, TrackCircuit

CONFIG_TICK_S = 0.01
_COIL_POINTS = 5
_CACHE_SIZE = 64


@dataclass
class RailSettings:
    fs_hz: float = 4000.0
    circuit: CircuitParameters = field(default_factory=CircuitParameters)
    transformer_ratio: float = 2.5        # u_tx → rails: 1.4 A rms at the entry of a 2.6 km section at 1 Ω·km
    coil_offset_m: float = 1.5            # ahead of the first wheelset [S seed 002]
    coil_gain_h: float = 4.5e-4           # EMF = M·di/dt: 0.28 V at 2 A peak, 50 Hz (seed 002's weak level)
    coil_length_m: float = 0.3            # sensitivity length of the coil core [U]
    train_length_m: Tuple[float, ...] = (400.0, 400.0)
    asymmetry_range: Tuple[float, float] = (0.01, 0.05)
    seed: int = 1
    dc_ripple: Tuple[float, float] = (0.02, 0.01)       # 300 Hz, 600 Hz shares of the DC traction current [U]
    ac_harmonics: Tuple[float, float] = (0.10, 0.05)    # 150 Hz, 250 Hz shares on AC lines [U]
    traction_time_constant_s: float = 0.1               # traction circuit lag seen in the rails [U]
    relay_pick_up: float = 0.8            # share of the free-circuit relay voltage at the design ballast
    relay_drop_out: float = 0.5
    relay_pick_up_delay_s: float = 1.0
    relay_drop_out_delay_s: float = 0.2
    carrier_hz: float = 0.0               # 0: each section's carrier from the line file (ALSN); else this
                                          # one (a digital system's 174.38 / 175 Hz) for the phasors


@dataclass
class RailOutputs:
    e_coil: np.ndarray
    occupied: np.ndarray
    i_axle: np.ndarray
    off_line: np.ndarray
    coil_section: np.ndarray      # (M,) 1-based section under each train's coil at the frame end, 0 none


@dataclass
class _Model:
    phi_n: np.ndarray       # (nx, nx) state after a frame
    psi: np.ndarray         # (nx, N) input → state after a frame
    out_o: np.ndarray       # (N·2, nx) state → outputs per sample (shunt current, entry current)
    out_t: np.ndarray       # (N·2, N) inputs → outputs per sample
    relay_level: float      # relay-end voltage relative to the free circuit at the design ballast


class RailLineCore:
    def __init__(self, line: Line, sections: int, trains: int, frame: int, settings: RailSettings):
        s = settings
        if len(line.sections) > sections:
            raise FmuInputError(f"{line.path}: field block_sections: {len(line.sections)} sections, but this "
                                f"build models {sections}; rebuild with `railcosim build --sections {len(line.sections)}`")
        c = s.circuit
        for name, value in (("fs", s.fs_hz), ("transformer_ratio", s.transformer_ratio), ("coil_gain", s.coil_gain_h),
                            ("coil_length", s.coil_length_m), ("rail_r", c.rail_r_ohm_per_km), ("rail_l", c.rail_l_h_per_km),
                            ("ballast", c.ballast_ohm_km), ("feed_r", c.feed_r_ohm), ("relay_r", c.relay_r_ohm),
                            ("bond_l", c.bond_l_h), ("shunt_r", c.shunt_r_ohm), ("segment", c.segment_m),
                            ("traction_time_constant", s.traction_time_constant_s)):
            if not value > 0:
                raise FmuInputError(f"parameter {name}: must be positive, got {value}")
        if s.carrier_hz < 0 or s.carrier_hz > s.fs_hz / 4:
            raise FmuInputError(f"parameter carrier: {s.carrier_hz:g} Hz (0: the line file's; else up to fs/4)")
        if not 0 < s.relay_drop_out < s.relay_pick_up <= 1.0:
            raise FmuInputError("parameter relay_drop_out: must be positive and below relay_pick_up (≤ 1)")
        if len(s.train_length_m) != trains or min(s.train_length_m) <= 0:
            raise FmuInputError(f"parameter train_length: {trains} positive lengths expected")
        lo, hi = s.asymmetry_range
        if not 0 <= lo <= hi < 1:
            raise FmuInputError("parameter asymmetry_min/asymmetry_max: need 0 ≤ min ≤ max < 1")
        self.line, self.settings = line, s
        self.count, self.sections, self.trains, self.frame = len(line.sections), sections, trains, frame
        self.dt = 1.0 / s.fs_hz
        leads = [(float(j["position_m"]), float(j.get("bond_lead_offset_m", 1.0))) for j in line.joints]
        offsets = {round(position, 6): offset for position, offset in leads}
        self.circuits = [TrackCircuit(sec.start_m, sec.end_m, offsets.get(round(sec.end_m, 6), 1.0), c)
                         for sec in line.sections]
        self.starts = np.array([sec.start_m for sec in line.sections])
        self.ends = np.array([sec.end_m for sec in line.sections])
        self._ends_ext = np.append(self.ends, -np.inf)
        self._starts_list = self.starts.tolist()
        self.carriers = np.array([s.carrier_hz or sec.carrier_hz for sec in line.sections], dtype=float)
        self.ac = line.electrification == "AC25000"
        self.dc = line.electrification == "DC3000"
        rng = np.random.default_rng(s.seed)
        self.asymmetry = rng.uniform(lo, hi, self.count) * rng.choice([-1.0, 1.0], self.count)
        self.joint_zones = [(position - offset, position, position + offset) for position, offset in leads]
        self._feed_m = np.array([c.feed_m for c in self.circuits])
        margin = s.coil_length_m
        self._joint_band = [(lo - margin, hi + margin) for lo, _, hi in self.joint_zones] + \
            [(c.feed_m - margin, c.end_m + margin) for c in self.circuits]
        self.faults = [Faults() for _ in range(self.count)]
        self.broken_rail_m = -1.0
        self._refresh_faults()
        self._models: List[OrderedDict] = [OrderedDict() for _ in range(self.count)]
        self._amplitude: Dict[Tuple[int, Faults], np.ndarray] = {}
        self._log_amplitude: Dict[Tuple[int, Faults], np.ndarray] = {}
        self._relay_ref = np.array([self._relay_voltage(k, None, Faults(), reference=True) for k in range(self.count)])
        size = max(self._model(k, None).phi_n.shape[0] for k in range(self.count))
        self.states = np.zeros((self.count, size))
        self._phi_stack = np.zeros((self.count, size, size))
        self._psi_stack = np.zeros((self.count, size, frame))
        self.relay_up = np.ones(self.count, dtype=bool)
        self._relay_timer = np.zeros(self.count)
        self._index = np.arange(frame)
        self._coil_spread = (np.linspace(0.0, 1.0, _COIL_POINTS) - 0.5) * s.coil_length_m
        lag = np.exp(-self.dt / s.traction_time_constant_s)
        self._lag_b, self._lag_a = np.array([1.0 - lag]), np.array([1.0, -lag])
        self._traction_state = np.zeros((trains, 1))
        self._i_traction = np.zeros((trains, frame))
        self._last_current = np.zeros(trains)
        self._sensing = np.zeros(trains, dtype=bool)
        self._anchor = [(None, 0.0, 0.0)] * trains             # (x_k, v_k, t_k) of the last position update
        self.out = RailOutputs(np.zeros((trains, frame)), np.zeros(sections, dtype=bool),
                               np.zeros(trains), np.zeros(trains, dtype=bool), np.zeros(trains, dtype=np.int64))

    # ---- models -----------------------------------------------------------------------------
    def _fault_of(self, k: int) -> Faults:
        return self._effective_faults[k]

    def _refresh_faults(self) -> None:
        self._effective_faults = [
            Faults(f.ballast_ohm_km, self.broken_rail_m if self.starts[k] <= self.broken_rail_m < self.ends[k] else -1.0,
                   f.feed_open) for k, f in enumerate(self.faults)]
        self._active = [None] * self.count          # models and relay levels follow the new faults

    def _model(self, k: int, node: Optional[int]) -> _Model:
        faults = self._fault_of(k)
        key = (node, faults)
        cache = self._models[k]
        if key in cache:
            cache.move_to_end(key)
            return cache[key]
        circuit = self.circuits[k]
        net = circuit.network(node, faults, self.settings.transformer_ratio)
        system = net.state_space()
        phi, gamma = discretise(system, self.dt)
        n = self.frame
        nx = phi.shape[0]
        # output rows: shunt current (node voltage / R_sh) and entry-end current (−segment 0)
        rows = np.zeros((2, nx))
        direct = np.zeros(2)
        if node is not None:
            index = net.node_index[f"n{node}"]
            g_sh = 1.0 / self.settings.circuit.shunt_r_ohm
            rows[0] = system.node_from_state[index] * g_sh
            direct[0] = system.node_from_input[index, 0] * g_sh
        rows[1, 0] = -1.0
        out_o = np.empty((n, 2, nx))
        markov = np.empty((n, 2))              # C·Φ^k·Γ
        row_power = rows.copy()
        for i in range(n):
            out_o[i] = row_power
            markov[i] = row_power @ gamma[:, 0]
            row_power = row_power @ phi
        # block Toeplitz: sample i responds to input m < i through C·Φ^(i−1−m)·Γ, to m = i through D
        lag = np.arange(n)[:, None] - 1 - np.arange(n)[None, :]
        out_t = np.where((lag >= 0)[:, None, :], markov[np.clip(lag, 0, None)].transpose(0, 2, 1), 0.0)
        out_t[np.arange(n), :, np.arange(n)] = direct
        psi = np.empty((nx, n))
        column = gamma[:, 0].copy()
        for m in range(n - 1, -1, -1):
            psi[:, m] = column
            column = phi @ column
        # outputs of all samples at once: (N·2, nx) and (N·2, N) matrices
        model = _Model(np.linalg.matrix_power(phi, n), psi, out_o.reshape(n * 2, nx), out_t.reshape(n * 2, n),
                       self._relay_voltage(k, node, faults))
        cache[key] = model
        if len(cache) > _CACHE_SIZE:
            cache.popitem(last=False)
        return model

    def _amplitudes(self, k: int) -> np.ndarray:
        """|shunt current| for a shunt at each node (unit feed, phasor at the carrier)."""
        faults = self._fault_of(k)
        key = (k, faults)
        if key not in self._amplitude:
            circuit = self.circuits[k]
            omega = 2 * np.pi * self.carriers[k]
            values = []
            for node in range(circuit.segments + 1):
                net = circuit.network(node, faults, 1.0)
                v, _ = net.phasor(omega, [1.0])
                values.append(abs(v[net.node_index[f"n{node}"]]) / self.settings.circuit.shunt_r_ohm)
            self._amplitude[key] = np.maximum(np.array(values), 1e-12)
        return self._amplitude[key]

    def _log_amplitudes(self, k: int) -> np.ndarray:
        key = (k, self._fault_of(k))
        if key not in self._log_amplitude:
            self._log_amplitude[key] = np.log(self._amplitudes(k))
        return self._log_amplitude[key]

    def _relay_voltage(self, k: int, node: Optional[int], faults: Faults, reference: bool = False) -> float:
        circuit = self.circuits[k]
        net = circuit.network(node, faults, 1.0)
        v, _ = net.phasor(2 * np.pi * self.carriers[k], [1.0])
        value = abs(v[net.node_index["n0"]])
        return value if reference else value / self._relay_ref[k]

    # ---- step -------------------------------------------------------------------------------
    def set_faults(self, broken_rail_m: float, ballast_override: np.ndarray, feed_open: np.ndarray) -> None:
        faults = [Faults(float(max(ballast_override[k], 0.0)), -1.0, bool(feed_open[k])) for k in range(self.count)]
        if faults != self.faults or float(broken_rail_m) != self.broken_rail_m:
            self.faults, self.broken_rail_m = faults, float(broken_rail_m)
            self._refresh_faults()

    def _update_anchor(self, j: int, t: float, x: float, v: float) -> None:
        """A new position update starts x(t) = x_k + v_k·(t − t_k) (DESIGN §3)."""
        anchor = self._anchor[j]
        if anchor[0] is None or x != anchor[0] or v != anchor[1]:
            self._anchor[j] = (x, v, t)

    def section_of(self, x):
        k = np.searchsorted(self.starts, x, side="right") - 1
        return np.where(x < self._ends_ext[k], k, -1)      # k = −1 reads −inf: outside

    def _section_at(self, x: float) -> int:
        k = bisect.bisect_right(self._starts_list, x) - 1
        return k if k >= 0 and x < self.ends[k] else -1

    def step(self, t: float, u_tx: np.ndarray, x_head: np.ndarray, v: np.ndarray, i_traction: np.ndarray) -> RailOutputs:
        s, out = self.settings, self.out
        n = u_tx.shape[1] if u_tx.ndim == 2 else self.frame
        first = round(t * s.fs_hz)
        times = (first + self._index[:n]) * self.dt
        tick = np.floor(t / CONFIG_TICK_S + 1e-9) * CONFIG_TICK_S
        heads, at_tick = [], []
        for j in range(self.trains):
            self._update_anchor(j, t, float(x_head[j]), float(v[j]))
            x_k, v_k, t_k = self._anchor[j]
            heads.append(x_k + v_k * (times - t_k))          # per sample from the anchor: same for any frame
            at_tick.append(x_k + v_k * (tick - t_k))
        self._smooth_traction(i_traction, n)
        # the front-most wheelset of each train in each section shunts it
        front = np.full(self.count, -np.inf)
        for j in range(self.trains):
            head = at_tick[j]
            inside = (head >= self.starts) & (head - s.train_length_m[j] < self.ends)
            if inside.any():
                front = np.where(inside, np.maximum(front, np.minimum(head, self._feed_m)), front)
        configs = [None if front[k] == -np.inf else self.circuits[k].nearest_node(front[k]) for k in range(self.count)]
        # sections whose currents a coil needs this frame
        coil_sections = set()
        for j in range(self.trains):
            k_axle = self._section_at(float(heads[j][0]))
            k_coil = self._section_at(float(heads[j][-1]) + s.coil_offset_m + s.coil_length_m)
            coil_sections.update(k for k in (k_axle, k_coil) if k >= 0)
            if 0 <= k_axle < self.count - 1:
                coil_sections.add(k_axle + 1)
        for k in range(self.count):
            active = self._active[k]
            if active is None or active[0] != configs[k]:
                model = self._model(k, configs[k])
                self._active[k] = (configs[k], model)
                size = model.phi_n.shape[0]
                self._phi_stack[k] = 0.0                             # sections padded to one size:
                self._psi_stack[k] = 0.0                             # one product advances them all
                self._phi_stack[k, :size, :size] = model.phi_n
                self._psi_stack[k, :size] = model.psi
                self.states[k, size:] = 0.0       # a branch the new network lacks (feed opened) carries nothing
        u = u_tx[:self.count]
        currents = {}
        for k in coil_sections:
            model, x0 = self._active[k][1], self.states[k, :self._active[k][1].phi_n.shape[0]]
            currents[k] = (model.out_o @ x0 + model.out_t @ u[k]).reshape(n, 2)
        self.states = (self._phi_stack @ self.states[..., None])[..., 0] + (self._psi_stack @ u[..., None])[..., 0]
        self._update_relays(n * self.dt)
        for j in range(self.trains):
            out.coil_section[j] = self._section_at(float(heads[j][-1]) + s.coil_offset_m) + 1
            if heads[j][-1] + s.coil_offset_m + s.coil_length_m < 0.0 or heads[j][0] > self.line.length_m:
                out.off_line[j] = True                   # no coil over the line: nothing to sense
                out.e_coil[j, :n] = 0.0
                out.i_axle[j] = 0.0
                self._sensing[j] = False
                continue
            self._coil(j, times, heads[j], currents, configs)
        out.occupied[:self.count] = ~self.relay_up
        return out

    def _update_relays(self, step_s: float) -> None:
        s = self.settings
        levels = np.array([active[1].relay_level for active in self._active])
        wants_up = np.where(self.relay_up, levels > s.relay_drop_out, levels >= s.relay_pick_up)
        changing = wants_up != self.relay_up
        self._relay_timer = np.where(changing, self._relay_timer + step_s, 0.0)
        delay = np.where(wants_up, s.relay_pick_up_delay_s, s.relay_drop_out_delay_s)
        done = changing & (self._relay_timer >= delay - 1e-12)
        if done.any():
            self.relay_up = np.where(done, wants_up, self.relay_up)
            self._relay_timer[done] = 0.0

    def _coil(self, j: int, times: np.ndarray, head: np.ndarray, currents, configs) -> None:
        s, out = self.settings, self.out
        n = times.size
        out.off_line[j] = bool(head[-1] < 0 or head[-1] > self.line.length_m)
        first_coil = head[0] + s.coil_offset_m + self._coil_spread[0]
        last_coil = head[-1] + s.coil_offset_m + self._coil_spread[-1]
        k = self._section_at(float(head[0]))
        circuit = self.circuits[k] if k >= 0 else None
        if (circuit is not None and k in currents and head[-1] < self.ends[k]
                and last_coil <= circuit.feed_m and not self._near_joint(first_coil, last_coil)):
            # the usual frame: wheelset and whole coil over the same section, clear of joints
            shunt_current = currents[k][:, 0] * self._scale(k, head, configs[k])
            current = shunt_current + self.asymmetry[k] * self._traction_wave(j, times)
            i_axle = shunt_current
        else:
            current, i_axle = self._coil_general(j, times, head, currents, configs)
        previous = self._last_current[j] if self._sensing[j] else current[0]   # no step at the first sample
        emf = np.diff(np.concatenate([[previous], current])) * (s.fs_hz * s.coil_gain_h)
        self._last_current[j] = current[-1]
        self._sensing[j] = True
        out.e_coil[j, :n] = emf
        out.i_axle[j] = float(np.sqrt(np.mean(i_axle ** 2)))

    def _near_joint(self, lo: float, hi: float) -> bool:
        return any(z_lo <= hi and lo < z_hi for z_lo, z_hi in self._joint_band)

    def _scale(self, k: int, head: np.ndarray, node: Optional[int]) -> np.ndarray:
        """Code-current amplitude at the exact wheelset position over the one at the model's node."""
        log_amplitude = self._log_amplitudes(k)
        node = node if node is not None else 0
        return np.exp(np.interp(head, self.circuits[k].nodes_m, log_amplitude) - log_amplitude[node])

    def _coil_general(self, j: int, times: np.ndarray, head: np.ndarray, currents, configs):
        """Sample by sample, the share of the coil's sensitivity window over each stretch of
        rail: its own section up to the feed leads (shunt current), the dead end from the leads to
        the joint (nothing), the next section's entry end (its unshunted current)."""
        s = self.settings
        n = times.size
        axle_section = self.section_of(head)
        centre = head + s.coil_offset_m
        lo, hi = centre - 0.5 * s.coil_length_m, centre + 0.5 * s.coil_length_m
        width = max(s.coil_length_m, 1e-9)

        def share(a, b):
            return np.clip(np.minimum(hi, b) - np.maximum(lo, a), 0.0, None) / width if s.coil_length_m > 0 \
                else ((centre >= a) & (centre < b)).astype(float)
        seen = np.zeros(n)
        i_axle = np.zeros(n)
        for k in set(int(k) for k in np.unique(axle_section) if k >= 0):
            if k not in currents:
                continue
            own = axle_section == k
            shunt_current = currents[k][:, 0] * self._scale(k, head, configs[k])
            i_axle = np.where(own, shunt_current, i_axle)
            view = share(-np.inf, self.circuits[k].feed_m) * shunt_current
            if k + 1 in currents:
                view = view + share(self.ends[k], np.inf) * currents[k + 1][:, 1]
            seen = np.where(own, view, seen)
        coil = centre[None, :] + self._coil_spread[:, None]
        return seen + self._traction(j, times, coil), i_axle

    def _smooth_traction(self, i_traction: np.ndarray, n: int) -> None:
        """The traction current reaches the rails through the traction circuit's inductance
        (smoothing reactor, motors): a first-order lag of ``traction_time_constant`` [U]. It
        also turns the steps of a slowly sampled traction FMU into ramps, which the coils would
        otherwise see as EMF spikes of tens of volts."""
        held = np.repeat(np.asarray(i_traction[:self.trains], dtype=float)[:, None], n, axis=1)
        self._i_traction, self._traction_state = lfilter(self._lag_b, self._lag_a, held, axis=1,
                                                          zi=self._traction_state)

    def _traction_wave(self, j: int, times: np.ndarray) -> np.ndarray:
        """Traction return current i_tr(t) of train j (DC with rectifier ripple, or AC 50 Hz)."""
        s = self.settings
        i_tr = self._i_traction[j]            # smoothed per sample (see _smooth_traction)
        if not (self.ac or self.dc) or not i_tr.any():
            return np.zeros(times.size)
        if self.dc:
            r300, r600 = s.dc_ripple
            return i_tr * (1.0 + r300 * np.sin(2 * np.pi * 300 * times) + r600 * np.sin(2 * np.pi * 600 * times))
        h3, h5 = s.ac_harmonics
        w = 2 * np.pi * 50 * times
        return i_tr * np.sqrt(2.0) * (np.sin(w) + h3 * np.sin(3 * w) + h5 * np.sin(5 * w))

    def _traction(self, j: int, times: np.ndarray, coil: np.ndarray) -> np.ndarray:
        """Asymmetric part of the traction return current under the coil, a(x)·i_tr(t)."""
        section = self.section_of(coil)
        a = np.where(section >= 0, self.asymmetry[np.clip(section, 0, self.count - 1)], 0.0)
        for lo, joint, hi in self.joint_zones:
            # between the bond leads the centre-tap jumper evens the rails out: the asymmetric
            # part falls linearly to zero at the joint and rises again beyond it
            a = np.where((coil >= lo) & (coil < hi), a * np.abs(coil - joint) / (joint - lo), a)
        return a.mean(axis=0) * self._traction_wave(j, times)

    # ---- studies ------------------------------------------------------------------------------
    def minimum_code_current(self, k: int, ballast_ohm_km: float) -> float:
        """ALS mode: the smallest code current (A rms) under the first wheelset over all positions
        in section k, for the nominal code amplitude 4 V × transformer ratio."""
        saved = self._effective_faults[k]
        self._effective_faults[k] = Faults(ballast_ohm_km, -1.0, False)
        try:
            amplitude = self._amplitudes(k)
        finally:
            self._effective_faults[k] = saved
        return float(amplitude.min() * 4.0 * self.settings.transformer_ratio / np.sqrt(2.0))
