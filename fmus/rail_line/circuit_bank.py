"""The track-circuit bank: the line's K coded track circuits under the trains' wheelsets, their
network states frame by frame, and the track relays (no FMI here).

Per section the network of track_circuit.py is generated for the current position of the
front-most wheelset in it (snapped to the network's nodes), turned into a state-space model by
modified nodal analysis (network.py) and discretised exactly at fs (zero-order hold). Models
are cached per (shunt node, faults); the branch currents (the states) carry over when the
train moves to the next node, and the code-current amplitude is interpolated between nodes
from the phasor solution, so it varies continuously with position ("regenerated and
interpolated as the trains move"). The rail line core takes the configuration every 10 ms of
simulated time, whatever the frame length, so frames of any length give the same result.

Track relays: the relay-end voltage of the track circuit's own feed (phasor at the carrier,
relative to the free circuit at the design ballast) against pick-up / drop-out ratios, with
pick-up and drop-out delays → occupancy.
"""
from __future__ import annotations

import bisect
import math
from collections import OrderedDict
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

import numpy as np

from fmus.data.loader import Line
from fmus.rail_line.network import ShuntFamily, discretise
from fmus.rail_line.track_circuit import Faults, TrackCircuit

_CACHE_SIZE = 64


@dataclass
class _Model:
    phi_n: np.ndarray       # (nx, nx) state after a frame
    psi: np.ndarray         # (nx, N) input → state after a frame
    shunt_o: np.ndarray     # (N, nx) state at the frame start → shunt current per sample
    shunt_t: np.ndarray     # (N, N) inputs of the frame → shunt current per sample
    entry_o: np.ndarray     # (N, nx) the same for the entry-end current
    entry_t: np.ndarray     # (N, N)
    relay_level: float      # relay-end voltage relative to the free circuit at the design ballast


class FrameCurrents:
    """A frame's per-sample shunt and entry-end currents of a section, computed only for the
    sections a coil sees (from the states at the frame start and the frame's code input)."""

    __slots__ = ("bank", "states", "u")

    def __init__(self, bank: "TrackCircuitBank", states: np.ndarray, u: np.ndarray):
        self.bank, self.states, self.u = bank, states, u

    def shunt(self, k: int) -> np.ndarray:
        model = self.bank._active[k][1]
        return model.shunt_o @ self.states[k, :model.shunt_o.shape[1]] + model.shunt_t @ self.u[k]

    def entry(self, k: int) -> np.ndarray:
        model = self.bank._active[k][1]
        return model.entry_o @ self.states[k, :model.entry_o.shape[1]] + model.entry_t @ self.u[k]


class TrackCircuitBank:
    """The line's track circuits: geometry, faults, network models and states, relays."""

    def __init__(self, line: Line, settings, trains: int, frame: int):
        s, c = settings, settings.circuit
        self.settings = s
        self.count, self.trains, self.frame = len(line.sections), trains, frame
        self.dt = 1.0 / s.fs_hz
        leads = [(float(j["position_m"]), float(j.get("bond_lead_offset_m", 1.0))) for j in line.joints]
        offsets = {round(position, 6): offset for position, offset in leads}
        self.circuits = [TrackCircuit(sec.start_m, sec.end_m, offsets.get(round(sec.end_m, 6), 1.0), c)
                         for sec in line.sections]
        # (bond lead before, joint, bond lead beyond) of every insulated joint
        self.joint_zones = [(position - offset, position, position + offset) for position, offset in leads]
        self.starts = np.array([sec.start_m for sec in line.sections])
        self.ends = np.array([sec.end_m for sec in line.sections])
        self._ends_ext = np.append(self.ends, -np.inf)
        self._starts_list = self.starts.tolist()
        self.ends_list = self.ends.tolist()
        self.feed_list = [float(circuit.feed_m) for circuit in self.circuits]
        self.carriers = np.array([s.carrier_hz or sec.carrier_hz for sec in line.sections], dtype=float)
        self._spacing_list = [float(circuit.nodes_m[1] - circuit.nodes_m[0]) for circuit in self.circuits]
        self._segments_list = [circuit.segments for circuit in self.circuits]
        self._train_lengths = [float(length) for length in s.train_length_m]
        # positions where a train's shunt configuration may change, whatever its own section
        self._config_edges = {length: sorted(set(self._starts_list + self.ends_list + self.feed_list +
                                                 [end + length for end in self.ends_list]))
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

    # ---- geometry ---------------------------------------------------------------------------
    def section_of(self, x):
        k = np.searchsorted(self.starts, x, side="right") - 1
        return np.where(x < self._ends_ext[k], k, -1)      # k = −1 reads −inf: outside

    def section_at(self, x: float) -> int:
        k = bisect.bisect_right(self._starts_list, x) - 1
        return k if k >= 0 and x < self.ends_list[k] else -1

    # ---- faults -----------------------------------------------------------------------------
    def set_faults(self, broken_rail_m: float, ballast_override: np.ndarray, feed_open: np.ndarray) -> None:
        raw = (float(broken_rail_m), ballast_override[:self.count].tobytes(), feed_open[:self.count].tobytes())
        if raw == self._fault_inputs:                # the usual frame: nothing changed
            return
        self._fault_inputs = raw
        faults = [Faults(float(max(ballast_override[k], 0.0)), -1.0, bool(feed_open[k])) for k in range(self.count)]
        if faults != self.faults or float(broken_rail_m) != self.broken_rail_m:
            self.faults, self.broken_rail_m = faults, float(broken_rail_m)
            self._refresh_faults()

    def _refresh_faults(self) -> None:
        self._effective_faults = [
            Faults(f.ballast_ohm_km, self.broken_rail_m if self.starts[k] <= self.broken_rail_m < self.ends[k] else -1.0,
                   f.feed_open) for k, f in enumerate(self.faults)]
        self._active = [None] * self.count          # models and relay levels follow the new faults
        self._nodes = [-2] * self.count             # (−1 is "no shunt"): every section re-activates
        self._node_bounds = [(0.0, 0.0)] * self.trains

    # ---- models -----------------------------------------------------------------------------
    def _model(self, k: int, node: Optional[int]) -> _Model:
        faults = self._effective_faults[k]
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
                       np.ascontiguousarray(out_t[:, 1]), self.relay_voltage(k, node))
        cache[key] = model
        if len(cache) > _CACHE_SIZE:
            cache.popitem(last=False)
        return model

    def _phasor_table(self, k: int, faults: Optional[Faults] = None) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For a wheelset shunt at each node of section k (the current faults unless given; unit
        feed, phasor at the carrier): |shunt current|, its log, and |relay-end voltage|; the last
        relay entry is the circuit without a shunt."""
        faults = self._effective_faults[k] if faults is None else faults
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

    def relay_voltage(self, k: int, node: Optional[int], faults: Optional[Faults] = None) -> float:
        """Relay-end voltage of section k with a shunt at ``node`` (None: none) under the current
        faults unless given, relative to the free circuit at the design ballast."""
        relay = self._phasor_table(k, faults)[2]
        return float(relay[-1 if node is None else node]) / self._relay_ref[k]

    def scale(self, k: int, head: np.ndarray) -> np.ndarray:
        """Code-current amplitude at the exact wheelset position over the one at the model's node."""
        _, _, log_amplitude, at_node = self._active[k]
        return np.exp(np.interp(head, self.circuits[k].nodes_m, log_amplitude) - at_node)

    # ---- the trains' shunts -----------------------------------------------------------------
    def follow_shunts(self, heads: List[float]) -> None:
        """Take the front-most wheelset of each train in each section (heads at the
        configuration tick) as its shunt, activating the models of the sections whose shunt
        node changed."""
        nodes = self._shunt_nodes(heads)
        if nodes != self._nodes:
            for k, (node, was) in enumerate(zip(nodes, self._nodes)):
                if node != was:
                    self._activate(k, None if node < 0 else node)
            self._nodes = nodes

    def _shunt_nodes(self, heads: List[float]) -> List[int]:
        """Network node of the front-most wheelset in each section (−1: no train in the
        section). Unchanged while every train stays strictly inside the interval, found with the
        last evaluation, over which its own contribution is constant."""
        if all(lo < head < hi for head, (lo, hi) in zip(heads, self._node_bounds)):
            return self._nodes
        front = [-math.inf] * self.count
        bounds = []
        for head, length in zip(heads, self._train_lengths):
            # sections with start ≤ head and end > head − length (sorted, disjoint)
            last = bisect.bisect_right(self._starts_list, head) - 1
            for k in range(bisect.bisect_right(self.ends_list, head - length), last + 1):
                front[k] = max(front[k], min(head, self.feed_list[k]))
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
        if 0 <= k and head < self.feed_list[k]:
            start, spacing = self._starts_list[k], self._spacing_list[k]
            middle = round((head - start) / spacing)
            lo, hi = max(lo, start + (middle - 0.5) * spacing), min(hi, start + (middle + 0.5) * spacing)
        return lo, hi

    def _activate(self, k: int, node: Optional[int]) -> None:
        model = self._model(k, node)
        log_amplitude = self._phasor_table(k)[1]
        # (node, model, log amplitude at the nodes, at the model's node): see scale
        self._active[k] = (node, model, log_amplitude, log_amplitude[node if node is not None else 0])
        size = model.phi_n.shape[0]
        self._phi_stack[k] = 0.0                             # sections padded to one size:
        self._psi_stack[k] = 0.0                             # one product advances them all
        self._phi_stack[k, :size, :size] = model.phi_n
        self._psi_stack[k, :size] = model.psi
        self.states[k, size:] = 0.0       # a branch the new network lacks (feed opened) carries nothing
        self._relay_levels[k] = model.relay_level
        self._relays_settled = False

    # ---- a frame ----------------------------------------------------------------------------
    def advance(self, u: np.ndarray, n: int) -> FrameCurrents:
        """Every section's states over a frame of code input ``u`` (K, n) and the relays; the
        frame's currents, computed on demand from the states it started from."""
        before = self.states
        self.states, self._spare_states = self._spare_states, before
        np.matmul(self._phi_stack, before[..., None], out=self.states[..., None])
        self.states += np.matmul(self._psi_stack, u[..., None], out=self._input_response)[..., 0]
        if not self._relays_settled:
            self._update_relays(n * self.dt)
        return FrameCurrents(self, before, u)

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

    # ---- studies ------------------------------------------------------------------------------
    def minimum_code_current(self, k: int, ballast_ohm_km: float) -> float:
        """ALS mode: the smallest code current (A rms) under the first wheelset over all positions
        in section k, for the nominal code amplitude 4 V × transformer ratio."""
        saved = self._effective_faults[k]
        self._effective_faults[k] = Faults(ballast_ohm_km, -1.0, False)
        try:
            amplitude = self._phasor_table(k)[0]
        finally:
            self._effective_faults[k] = saved
        return float(amplitude.min() * 4.0 * self.settings.transformer_ratio / np.sqrt(2.0))
