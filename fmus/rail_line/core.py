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
import math
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Tuple

import numpy as np

from fmus.data.loader import Line
from fmus.errors import FmuInputError
from fmus.dsp.periodic import period_samples
from fmus.rail_line.network import ShuntFamily, discretise
from fmus.rail_line.track_circuit import CircuitParameters, Faults, TrackCircuit
from fmus.sizes import DEFAULT_SAMPLE_RATE_HZ

CONFIG_TICK_S = 0.01
_COIL_POINTS = 5
_CACHE_SIZE = 64
_RIPPLE_MAX_SAMPLES = 1 << 14    # traction ripple kept as a table when it repeats within this


@dataclass
class RailSettings:
    fs_hz: float = DEFAULT_SAMPLE_RATE_HZ
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
    shunt_o: np.ndarray     # (N, nx) state at the frame start → shunt current per sample
    shunt_t: np.ndarray     # (N, N) inputs of the frame → shunt current per sample
    entry_o: np.ndarray     # (N, nx) the same for the entry-end current
    entry_t: np.ndarray     # (N, N)
    relay_level: float      # relay-end voltage relative to the free circuit at the design ballast


class _FrameCurrents:
    """A frame's per-sample shunt and entry-end currents of a section, computed only for the
    sections a coil sees (from the states at the frame start and the frame's code input)."""

    __slots__ = ("core", "states", "u")

    def __init__(self, core: "RailLineCore", states: np.ndarray, u: np.ndarray):
        self.core, self.states, self.u = core, states, u

    def shunt(self, k: int) -> np.ndarray:
        model = self.core._active[k][1]
        return model.shunt_o @ self.states[k, :model.shunt_o.shape[1]] + model.shunt_t @ self.u[k]

    def entry(self, k: int) -> np.ndarray:
        model = self.core._active[k][1]
        return model.entry_o @ self.states[k, :model.entry_o.shape[1]] + model.entry_t @ self.u[k]


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
        bands = sorted([(lo - margin, hi + margin) for lo, _, hi in self.joint_zones] +
                       [(c.feed_m - margin, c.end_m + margin) for c in self.circuits])
        merged: List[List[float]] = []
        for lo, hi in bands:                    # touching or overlapping bands merged: disjoint, sorted
            if merged and lo <= merged[-1][1]:
                merged[-1][1] = max(merged[-1][1], hi)
            else:
                merged.append([lo, hi])
        self._band_lo = [lo for lo, _ in merged]
        self._band_hi = [hi for _, hi in merged]
        self._ends_list = self.ends.tolist()
        self._feed_list = self._feed_m.tolist()
        self._spacing_list = [float(c.nodes_m[1] - c.nodes_m[0]) for c in self.circuits]
        self._segments_list = [c.segments for c in self.circuits]
        self._train_lengths = [float(length) for length in s.train_length_m]
        # positions where a train's shunt configuration may change, whatever its own section
        self._config_edges = {length: sorted(set(self._starts_list + self._ends_list + self._feed_list +
                                                 [end + length for end in self._ends_list]))
                              for length in self._train_lengths}
        self._fault_inputs = None
        self._relay_levels = np.ones(self.count)
        self._relays_settled = False
        self.faults = [Faults() for _ in range(self.count)]
        self.broken_rail_m = -1.0
        self._refresh_faults()
        self._models: List[OrderedDict] = [OrderedDict() for _ in range(self.count)]
        self._families: Dict[Tuple[int, Faults], Tuple[ShuntFamily, Dict[str, int]]] = {}
        self._phasors: Dict[Tuple[int, Faults], Tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        # |relay-end voltage| of the free circuit at the design ballast, unit feed
        self._relay_ref = np.array([self._phasor_table(k, Faults())[2][-1] for k in range(self.count)])
        size = max(self._model(k, None).phi_n.shape[0] for k in range(self.count))
        self.states = np.zeros((self.count, size))
        self._spare_states = np.zeros((self.count, size))       # the two alternate frame by frame
        self._input_response = np.zeros((self.count, size, 1))
        self._phi_stack = np.zeros((self.count, size, size))
        self._psi_stack = np.zeros((self.count, size, frame))
        self.relay_up = np.ones(self.count, dtype=bool)
        self._relay_timer = np.zeros(self.count)
        self._index = np.arange(frame)
        self._coil_spread = (np.linspace(0.0, 1.0, _COIL_POINTS) - 0.5) * s.coil_length_m
        lag = np.exp(-self.dt / s.traction_time_constant_s)
        self._lag_powers = lag ** np.arange(1, frame + 1)
        self._traction_last = [0.0] * trains                   # smoothed current at the last sample
        self._traction_on = [False] * trains
        self._i_traction = np.zeros((trains, frame))
        self._ripple_first = None                              # the frame's ripple waveform, once computed
        self._ripple = np.zeros(frame)
        ripple_hz = (300.0, 600.0) if self.dc else (50.0, 150.0, 250.0)
        self._ripple_period = period_samples([1.0 / f for f in ripple_hz], s.fs_hz, _RIPPLE_MAX_SAMPLES)
        if self._ripple_period is not None and (self.dc or self.ac):
            self._ripple_table = self._ripple_wave(np.arange(self._ripple_period) * self.dt)
        self._emf_gain = s.fs_hz * s.coil_gain_h
        self._last_current = np.zeros(trains)
        self._sensing = np.zeros(trains, dtype=bool)
        self._anchors: List[Optional[Tuple[float, float, float]]] = [None] * trains   # (x_k, v_k, t_k)
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
        self._nodes = [-2] * self.count             # (−1 is "no shunt"): every section re-activates
        self._node_bounds = [(0.0, 0.0)] * self.trains

    def _model(self, k: int, node: Optional[int]) -> _Model:
        faults = self._fault_of(k)
        key = (node, faults)
        cache = self._models[k]
        if key in cache:
            cache.move_to_end(key)
            return cache[key]
        family_key = (k, faults)
        if family_key not in self._families:
            net = self.circuits[k].network(None, faults, self.settings.transformer_ratio)
            self._families[family_key] = (ShuntFamily(net, 1.0 / self.settings.circuit.shunt_r_ohm), net.node_index)
        family, node_index = self._families[family_key]
        system = family.state_space(None if node is None else node_index[f"n{node}"])
        phi, gamma = discretise(system, self.dt)
        n = self.frame
        nx = phi.shape[0]
        # output rows: shunt current (node voltage / R_sh) and entry-end current (−segment 0)
        rows = np.zeros((2, nx))
        direct = np.zeros(2)
        if node is not None:
            index = node_index[f"n{node}"]
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
        # outputs of all samples at once: (N, nx) and (N, N) matrices per output
        model = _Model(np.linalg.matrix_power(phi, n), psi, np.ascontiguousarray(out_o[:, 0]),
                       np.ascontiguousarray(out_t[:, 0]), np.ascontiguousarray(out_o[:, 1]),
                       np.ascontiguousarray(out_t[:, 1]), self._relay_voltage(k, node))
        cache[key] = model
        if len(cache) > _CACHE_SIZE:
            cache.popitem(last=False)
        return model

    def _phasor_table(self, k: int, faults: Optional[Faults] = None) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For a wheelset shunt at each node of section k (the current faults unless given; unit
        feed, phasor at the carrier): |shunt current|, its log, and |relay-end voltage|; the last
        relay entry is the circuit without a shunt."""
        faults = self._fault_of(k) if faults is None else faults
        key = (k, faults)
        if key not in self._phasors:
            circuit, g_sh = self.circuits[k], 1.0 / self.settings.circuit.shunt_r_ohm
            net = circuit.network(None, faults, 1.0)
            nodes = [net.node_index[f"n{node}"] for node in range(circuit.segments + 1)]
            at_node, at_relay, free_relay = net.phasor_with_shunt(2 * np.pi * self.carriers[k], [1.0], g_sh,
                                                                  net.node_index["n0"])
            amplitude = np.maximum(np.abs(at_node[nodes]) * g_sh, 1e-12)
            relay = np.append(np.abs(at_relay[nodes]), abs(free_relay))    # last: no shunt
            self._phasors[key] = (amplitude, np.log(amplitude), relay)
        return self._phasors[key]

    def _amplitudes(self, k: int) -> np.ndarray:
        """|shunt current| for a shunt at each node (unit feed, phasor at the carrier)."""
        return self._phasor_table(k)[0]

    def _relay_voltage(self, k: int, node: Optional[int], faults: Optional[Faults] = None) -> float:
        """Relay-end voltage (the current faults unless given), relative to the free circuit at
        the design ballast."""
        relay = self._phasor_table(k, faults)[2]
        return float(relay[-1 if node is None else node]) / self._relay_ref[k]

    # ---- step -------------------------------------------------------------------------------
    def set_faults(self, broken_rail_m: float, ballast_override: np.ndarray, feed_open: np.ndarray) -> None:
        raw = (float(broken_rail_m), ballast_override[:self.count].tobytes(), feed_open[:self.count].tobytes())
        if raw == self._fault_inputs:                # the usual frame: nothing changed
            return
        self._fault_inputs = raw
        faults = [Faults(float(max(ballast_override[k], 0.0)), -1.0, bool(feed_open[k])) for k in range(self.count)]
        if faults != self.faults or float(broken_rail_m) != self.broken_rail_m:
            self.faults, self.broken_rail_m = faults, float(broken_rail_m)
            self._refresh_faults()

    def _update_anchor(self, j: int, t: float, x: float, v: float) -> Tuple[float, float, float]:
        """A new position update starts x(t) = x_k + v_k·(t − t_k) (DESIGN §3)."""
        anchor = self._anchors[j]
        if anchor is None or x != anchor[0] or v != anchor[1]:
            anchor = self._anchors[j] = (x, v, t)
        return anchor

    def section_of(self, x):
        k = np.searchsorted(self.starts, x, side="right") - 1
        return np.where(x < self._ends_ext[k], k, -1)      # k = −1 reads −inf: outside

    def _section_at(self, x: float) -> int:
        k = bisect.bisect_right(self._starts_list, x) - 1
        return k if k >= 0 and x < self._ends_list[k] else -1

    def _shunt_nodes(self, at_tick: List[float]) -> List[int]:
        """Network node of the front-most wheelset in each section at the configuration tick
        (−1: no train in the section). Unchanged while every train stays strictly inside the
        interval, found with the last evaluation, over which its own contribution is constant."""
        heads = at_tick
        if all(lo < head < hi for head, (lo, hi) in zip(heads, self._node_bounds)):
            return self._nodes
        front = [-math.inf] * self.count
        bounds = []
        for head, length in zip(heads, self._train_lengths):
            # sections with start ≤ head and end > head − length (sorted, disjoint)
            last = bisect.bisect_right(self._starts_list, head) - 1
            for k in range(bisect.bisect_right(self._ends_list, head - length), last + 1):
                front[k] = max(front[k], min(head, self._feed_list[k]))
            bounds.append(self._node_interval(head, length, last))
        self._node_bounds = bounds
        return [-1 if f == -math.inf else
                min(max(round((f - self._starts_list[k]) / self._spacing_list[k]), 0), self._segments_list[k])
                for k, f in enumerate(front)]

    def _node_interval(self, head: float, length: float, k: int) -> Tuple[float, float]:
        """Open interval of head positions around ``head`` over which a train's shunt nodes do
        not change: no section start, section end + length, feed end or node-rounding boundary
        of its own section in between."""
        edges = self._config_edges[length]
        i = bisect.bisect_right(edges, head)
        lo, hi = (edges[i - 1] if i > 0 else -math.inf), (edges[i] if i < len(edges) else math.inf)
        if 0 <= k and head < self._feed_list[k]:
            start, spacing = self._starts_list[k], self._spacing_list[k]
            middle = round((head - start) / spacing)
            lo, hi = max(lo, start + (middle - 0.5) * spacing), min(hi, start + (middle + 0.5) * spacing)
        return lo, hi

    def _activate(self, k: int, node: Optional[int]) -> None:
        model = self._model(k, node)
        log_amplitude = self._phasor_table(k)[1]
        # (node, model, log amplitude at the nodes, at the model's node): see _scale
        self._active[k] = (node, model, log_amplitude, log_amplitude[node if node is not None else 0])
        size = model.phi_n.shape[0]
        self._phi_stack[k] = 0.0                             # sections padded to one size:
        self._psi_stack[k] = 0.0                             # one product advances them all
        self._phi_stack[k, :size, :size] = model.phi_n
        self._psi_stack[k, :size] = model.psi
        self.states[k, size:] = 0.0       # a branch the new network lacks (feed opened) carries nothing
        self._relay_levels[k] = model.relay_level
        self._relays_settled = False

    def step(self, t: float, u_tx: np.ndarray, x_head: np.ndarray, v: np.ndarray, i_traction: np.ndarray) -> RailOutputs:
        s, out = self.settings, self.out
        n = u_tx.shape[1] if u_tx.ndim == 2 else self.frame
        first = round(t * s.fs_hz)
        times = (first + self._index[:n]) * self.dt
        first_s, last_s = float(times[0]), float(times[-1])
        tick = math.floor(t / CONFIG_TICK_S + 1e-9) * CONFIG_TICK_S
        at_tick = []
        for j in range(self.trains):
            x_k, v_k, t_k = self._update_anchor(j, t, float(x_head[j]), float(v[j]))
            at_tick.append(x_k + v_k * (tick - t_k))
        self._smooth_traction(i_traction, n)
        self._ripple_first = None
        # the front-most wheelset of each train in each section shunts it
        nodes = self._shunt_nodes(at_tick)
        if nodes != self._nodes:
            for k, (node, was) in enumerate(zip(nodes, self._nodes)):
                if node != was:
                    self._activate(k, None if node < 0 else node)
            self._nodes = nodes
        u = u_tx[:self.count]
        before = self.states               # the frame's currents start from these (computed lazily)
        self.states, self._spare_states = self._spare_states, before
        np.matmul(self._phi_stack, before[..., None], out=self.states[..., None])
        self.states += np.matmul(self._psi_stack, u[..., None], out=self._input_response)[..., 0]
        if not self._relays_settled:
            self._update_relays(n * self.dt)
        currents = _FrameCurrents(self, before, u)
        ends = self._ends_list
        for j in range(self.trains):
            # per sample from the anchor: the same positions for any frame length
            x_k, v_k, t_k = self._anchors[j]
            head_first, head_last = x_k + v_k * (first_s - t_k), x_k + v_k * (last_s - t_k)
            out.coil_section[j] = self._section_at(head_last + s.coil_offset_m) + 1
            if head_last + s.coil_offset_m + s.coil_length_m < 0.0 or head_first > self.line.length_m:
                out.off_line[j] = True                   # no coil over the line: nothing to sense
                if self._sensing[j]:
                    out.e_coil[j, :n] = 0.0
                    out.i_axle[j] = 0.0
                    self._sensing[j] = False
                continue
            out.off_line[j] = head_last < 0 or head_last > self.line.length_m
            head = x_k + v_k * (times - t_k)
            k = self._section_at(head_first)
            first_coil = head_first + s.coil_offset_m + self._coil_spread[0]
            last_coil = head_last + s.coil_offset_m + self._coil_spread[-1]
            if (k >= 0 and head_last < ends[k] and last_coil <= self._feed_list[k]
                    and not self._near_joint(first_coil, last_coil)):
                # the usual frame: wheelset and whole coil over the same section, clear of joints
                shunt_current = currents.shunt(k) * self._scale(k, head)
                current = shunt_current + self.asymmetry[k] * self._traction_wave(j, first, times)
                i_axle = shunt_current
            else:
                current, i_axle = self._coil_general(j, first, times, head, currents)
            self._emf(j, current, n)
            out.i_axle[j] = math.sqrt(float(np.dot(i_axle, i_axle)) / n)
        out.occupied[:self.count] = ~self.relay_up
        return out

    def _update_relays(self, step_s: float) -> None:
        s = self.settings
        levels = self._relay_levels
        wants_up = np.where(self.relay_up, levels > s.relay_drop_out, levels >= s.relay_pick_up)
        changing = wants_up != self.relay_up
        if not changing.any():
            self._relay_timer[:] = 0.0
            self._relays_settled = True              # nothing to do until a level changes
            return
        self._relay_timer = np.where(changing, self._relay_timer + step_s, 0.0)
        delay = np.where(wants_up, s.relay_pick_up_delay_s, s.relay_drop_out_delay_s)
        done = changing & (self._relay_timer >= delay - 1e-12)
        if done.any():
            self.relay_up = np.where(done, wants_up, self.relay_up)
            self._relay_timer[done] = 0.0

    def _emf(self, j: int, current: np.ndarray, n: int) -> None:
        """EMF = M·di/dt on the sampled current, continuing from the previous frame's last sample."""
        emf = self.out.e_coil[j]
        previous = self._last_current[j] if self._sensing[j] else current[0]   # no step at the first sample
        emf[0] = current[0] - previous
        np.subtract(current[1:], current[:-1], out=emf[1:n])
        emf[:n] *= self._emf_gain
        self._last_current[j] = current[-1]
        self._sensing[j] = True

    def _near_joint(self, lo: float, hi: float) -> bool:
        """Does [lo, hi] touch a joint band (bands merged, sorted, disjoint)?"""
        i = bisect.bisect_right(self._band_hi, lo)         # first band ending after lo
        return i < len(self._band_lo) and self._band_lo[i] <= hi

    def _scale(self, k: int, head: np.ndarray) -> np.ndarray:
        """Code-current amplitude at the exact wheelset position over the one at the model's node."""
        _, _, log_amplitude, at_node = self._active[k]
        return np.exp(np.interp(head, self.circuits[k].nodes_m, log_amplitude) - at_node)

    def _coil_general(self, j: int, first: int, times: np.ndarray, head: np.ndarray, currents: _FrameCurrents):
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
            own = axle_section == k
            shunt_current = currents.shunt(k) * self._scale(k, head)
            i_axle = np.where(own, shunt_current, i_axle)
            view = share(-np.inf, self.circuits[k].feed_m) * shunt_current
            if k + 1 < self.count:
                beyond = share(self.ends[k], np.inf)
                if beyond.any():
                    view = view + beyond * currents.entry(k + 1)
            seen = np.where(own, view, seen)
        coil = centre[None, :] + self._coil_spread[:, None]
        return seen + self._traction(j, first, times, coil), i_axle

    def _smooth_traction(self, i_traction: np.ndarray, n: int) -> None:
        """The traction current reaches the rails through the traction circuit's inductance
        (smoothing reactor, motors): a first-order lag of ``traction_time_constant`` [U]. It
        also turns the steps of a slowly sampled traction FMU into ramps, which the coils would
        otherwise see as EMF spikes of tens of volts. The input is held over the frame, so the
        lag's response is closed-form: y[i] = c + (y[−1] − c)·λ^(i+1)."""
        for j in range(self.trains):
            held, last = float(i_traction[j]), self._traction_last[j]
            row = self._i_traction[j, :n]
            if held == last == 0.0:
                if self._traction_on[j]:
                    row[:] = 0.0
                    self._traction_on[j] = False
                continue
            np.multiply(self._lag_powers[:n], last - held, out=row)
            row += held
            self._traction_last[j] = float(row[-1])
            self._traction_on[j] = True

    def _traction_wave(self, j: int, first: int, times: np.ndarray) -> np.ndarray:
        """Traction return current i_tr(t) of train j (DC with rectifier ripple, or AC 50 Hz);
        ``first`` is the frame's first sample index, ``times`` its sample times."""
        if not (self.ac or self.dc) or not self._traction_on[j]:
            return np.zeros(times.size)
        if self._ripple_first != first:       # the waveform is the same for every train: once a frame
            if self._ripple_period is not None:
                self._ripple = self._ripple_table.take((first + self._index[:times.size]) % self._ripple_period)
            else:
                self._ripple = self._ripple_wave(times)
            self._ripple_first = first
        return self._i_traction[j, :times.size] * self._ripple     # smoothed per sample (_smooth_traction)

    def _ripple_wave(self, times: np.ndarray) -> np.ndarray:
        """Waveform of a unit traction current: DC with 300/600 Hz rectifier ripple, AC 50 Hz
        with odd harmonics (rms 1)."""
        s = self.settings
        if self.dc:
            r300, r600 = s.dc_ripple
            return 1.0 + r300 * np.sin(2 * np.pi * 300 * times) + r600 * np.sin(2 * np.pi * 600 * times)
        h3, h5 = s.ac_harmonics
        w = 2 * np.pi * 50 * times
        return np.sqrt(2.0) * (np.sin(w) + h3 * np.sin(3 * w) + h5 * np.sin(5 * w))

    def _traction(self, j: int, first: int, times: np.ndarray, coil: np.ndarray) -> np.ndarray:
        """Asymmetric part of the traction return current under the coil, a(x)·i_tr(t)."""
        section = self.section_of(coil)
        a = np.where(section >= 0, self.asymmetry[np.clip(section, 0, self.count - 1)], 0.0)
        for lo, joint, hi in self.joint_zones:
            # between the bond leads the centre-tap jumper evens the rails out: the asymmetric
            # part falls linearly to zero at the joint and rises again beyond it
            a = np.where((coil >= lo) & (coil < hi), a * np.abs(coil - joint) / (joint - lo), a)
        return a.mean(axis=0) * self._traction_wave(j, first, times)

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
