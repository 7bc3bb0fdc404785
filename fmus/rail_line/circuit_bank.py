"""The track-circuit bank: the line's K coded track circuits under the trains' wheelsets, their
network states frame by frame, and the track relays (no FMI here; docs/rail_line.md).

Every train is a set of wheelset shunts over its whole length: a 0.06 Ω conductance at every
network node it covers, its head and tail snapped to the nearest node (nodes are ≤ 50 m apart,
bogies closer: docs/rail_line.md, trains as shunts). Per section ONE network holds all shunts of
all trains in it, turned into a state-space model by modified nodal analysis and a Woodbury
update of the free network (network.py), discretised exactly at fs (zero-order hold). Models are
cached per (shunt nodes, train heads, faults); the branch currents (the states) carry over when
a train moves. The current a train's coils see is the rail-loop current arriving at its first
axle from the feed (a branch current: a state), so a train behind another one in the same
circuit gets only what the front train's axles leave; for the train whose head is the
front-most shunt the amplitude is interpolated between nodes from the phasor solution, so it
varies continuously with position. The rail line core takes the configuration every 10 ms of
simulated time, whatever the frame length, so frames of any length give the same result.

Track relays: the relay-end voltage of the track circuit's own feed (phasor at the track circuit's frequency
from the line file, whatever cab-signal carrier is superimposed) with
every shunt and fault, relative to each circuit's calibrated reference (see ``_calibrate``), against
pick-up / drop-out levels with pick-up and drop-out delays → occupancy.
"""
from __future__ import annotations

import bisect
import math
from collections import OrderedDict
from dataclasses import dataclass, replace
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from fmus.data.loader import Line, check_carrier_under_traction
from fmus.errors import FmuInputError
from fmus.reductions import any_true
from fmus.rail_line.network import PhasorFamily, ShuntFamily, discretise
from fmus.rail_line.track_circuit import OPEN_OHM, Faults, TrackCircuit

try:        # np.interp's own routine, without its per-call checks (the arguments are float arrays)
    from numpy._core.multiarray import interp as _interp
except ImportError:          # another numpy layout: the public function
    _interp = np.interp

_CACHE_SIZE = 64          # network models kept per section (shared by the sections of one design)
# a parked section (no train, no coil over it) is caught up from its inputs' history when it is
# needed again: over as many frames as its free network's slowest mode takes to fall below
# this share (a few units in the last place of the states), the history at most this many
# floats; a section that would need more is never parked
_SETTLED_SHARE = 2.0 ** -64
_HISTORY_FLOATS = 2 ** 20
SHUNT_BLEND_S = 0.1      # the front train's amplitude handed over from one node's model to the next
# a section's configuration: (shunt nodes, sorted; head nodes, one per train head in it, front first)
Config = Tuple[Tuple[int, ...], Tuple[int, ...]]
_NO_TRAIN: Config = ((), ())


@dataclass
class _Model:
    phi_n: np.ndarray       # (nx, nx) state after a frame
    psi: np.ndarray         # (nx, N) input → state after a frame
    ahead_o: np.ndarray     # (H, N, nx) state at the frame start → current arriving at head h, per sample
    ahead_t: np.ndarray     # (H, N, N) inputs of the frame → the same
    entry_o: np.ndarray     # (N, nx) the same for the entry-end current
    entry_t: np.ndarray     # (N, N)
    relay_level: float      # relay-end voltage relative to the circuit's calibrated reference
    phi: np.ndarray         # (nx, nx) state after one sample (psi[:, -1]: input → state after one sample)
    carrier_response: np.ndarray    # (nx,) complex: the states' phasor per unit input phasor at the
                                    # carrier, sampled (the discrete model's steady state)
    front_response: complex         # the same for the current arriving at the front head (0: no head)
    carrier_system: np.ndarray      # (2·nx, 2) the states at a sample and the next → the carrier's
                                    # phasor (re, im), by least squares (_carry_states_over)
    settle_frames: int = 0          # frames for every mode to fall below _SETTLED_SHARE (0: not yet known)
    padded: Optional[tuple] = None  # (step, ahead, entry) on a section's padded [states | frame input]


@dataclass(frozen=True)
class Calibration:
    """A track circuit's design levels (relay-end voltage / calibrated reference, docs/rail_line.md)."""
    length_m: float
    ballast_min_ohm_km: float
    ballast_max_ohm_km: float
    normal_level: float      # free circuit, minimum ballast, minimum supply (= pick-up by construction)
    shunt_level: float       # worst 0.06 Ω shunt over all nodes, maximum ballast, maximum supply
    shunt_node: int          # where that worst shunt is (0 relay end … S feed end)
    control_level: float     # worst broken rail over all segments, either ballast, maximum supply
    shunt_margin: float      # drop-out / shunt_level − 1 (required ≥ settings.shunt_margin)


class FrameCurrents:
    """A frame's per-sample currents of a section, computed only for the sections a coil sees
    (from each section's states at the frame start followed by the frame's code input)."""

    __slots__ = ("bank", "start")

    def __init__(self, bank: "TrackCircuitBank", start: np.ndarray):
        self.bank, self.start = bank, start

    def ahead(self, k: int, j: int) -> np.ndarray:
        """Rail current arriving from the feed at train j's first axle in section k (zero when
        its head was not in section k at the configuration tick)."""
        bank = self.bank
        row = bank._rows[k].get(j)
        if row is None:
            return bank._zeros
        if bank._parked_at[k] is not None:
            bank._wake_in_frame(k)
        return bank._active[k][1].padded[1][row] @ self.start[k]

    def entry(self, k: int) -> np.ndarray:
        bank = self.bank
        if bank._parked_at[k] is not None:
            bank._wake_in_frame(k)
        return bank._active[k][1].padded[2] @ self.start[k]


class TrackCircuitBank:
    """The line's track circuits: geometry, faults, calibration, network models and states, relays."""

    def __init__(self, line: Line, settings, trains: int, frame: int):
        s, c = settings, settings.circuit
        self.settings, self.line = s, line
        self.count, self.trains, self.frame = len(line.sections), trains, frame
        self.dt = 1.0 / s.fs_hz
        self.g_shunt = 1.0 / c.shunt_r_ohm
        leads = [(float(j["position_m"]), float(j.get("bond_lead_offset_m", 1.0))) for j in line.joints]
        offsets = {round(position, 6): offset for position, offset in leads}
        # each circuit's ballast: the line file's per-section minimum unless the `ballast` parameter overrides all
        self.circuits = [TrackCircuit(sec.start_m, sec.end_m, offsets.get(round(sec.end_m, 6), 1.0),
                                      replace(c, ballast_ohm_km=c.ballast_ohm_km if c.ballast_ohm_km > 0
                                              else float(sec.ballast_ohm_km)))
                         for sec in line.sections]
        self.ballast_max_ohm_km = float(getattr(line, "max_ballast_ohm_km", 50.0))
        # (bond lead before, joint, bond lead beyond) of every insulated joint
        self.joint_zones = [(position - offset, position, position + offset) for position, offset in leads]
        self.starts = np.array([sec.start_m for sec in line.sections])
        self.ends = np.array([sec.end_m for sec in line.sections])
        self._ends_ext = np.append(self.ends, -np.inf)
        self._starts_list = self.starts.tolist()
        self.ends_list = self.ends.tolist()
        self.feed_list = [float(circuit.feed_m) for circuit in self.circuits]
        if s.carrier_hz:          # the parameter overrides the line file's carriers: the same rule holds
            check_carrier_under_traction(s.carrier_hz, line.electrification, "parameter carrier")
        # a code of several tones (ALSU, ``tone_band_hz``): the rails follow the √f law across the
        # band (TrackCircuit.network), the phasor tables stand at its geometric centre
        self.band_hz = tuple(s.tone_band_hz) if s.tone_band_hz[1] > 0 else None
        centre = float(np.sqrt(s.tone_band_hz[0] * s.tone_band_hz[1])) if self.band_hz else 0.0
        self.carriers = np.array([s.carrier_hz or centre or sec.carrier_hz for sec in line.sections], dtype=float)
        # train detection works at the track circuit's own frequency (the line file's): a digital
        # cab-signal carrier (174.38 / 175 Hz) is superimposed on it and never feeds the relay
        self.track_frequencies = np.array([sec.carrier_hz for sec in line.sections], dtype=float)
        self._spacing_list = [float(circuit.nodes_m[1] - circuit.nodes_m[0]) for circuit in self.circuits]
        self._nodes_m = [np.ascontiguousarray(circuit.nodes_m, dtype=float) for circuit in self.circuits]
        self._segments_list = [circuit.segments for circuit in self.circuits]
        self._train_lengths = [float(length) for length in s.train_length_m]
        # positions where a train's head or tail changes section or clipping to the feed
        self._edges = sorted(set(self._starts_list + self.ends_list + self.feed_list))
        self._fault_inputs = None
        self._relay_levels = np.ones(self.count)
        self._relays_settled = False
        self.faults = [Faults() for _ in range(self.count)]
        self.broken_rail_m = -1.0
        self._families: Dict[Tuple[int, Faults], Tuple[ShuntFamily, Dict[str, int]]] = {}
        self._phasor_families: Dict[Tuple[int, Faults], PhasorFamily] = {}
        self._phasors: Dict[Tuple[int, Faults], Tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._zeros = np.zeros(frame)
        # per section: (position, amplitude table, node amplitude, scale) of a standing front train
        self._standing_scale: List[Optional[tuple]] = [None] * self.count
        self.calibration = self._calibrate()
        # sections of one design (the same circuit relative to its start, carrier and calibration)
        # share their network models: a train passing one meets the same configurations again
        designs = [(circuit.segments, float(circuit.feed_m - circuit.start_m), circuit.params,
                    float(self.carriers[k]), float(self.track_frequencies[k]), float(self._reference[k]))
                   for k, circuit in enumerate(self.circuits)]
        shared = {design: OrderedDict() for design in designs}
        self._models: List[OrderedDict] = [shared[design] for design in designs]
        self._cache_size = [_CACHE_SIZE * designs.count(design) for design in designs]
        # sections advanced every frame (the others parked: their states at the start of frame
        # _parked_at[k] in _parked, caught up from the inputs' history when needed again)
        self._parked_at: List[Optional[int]] = [None] * self.count
        self._refresh_faults()
        size = self._size = max(self._model(k, _NO_TRAIN).phi_n.shape[0] for k in range(self.count))
        # per section and frame: its states at the frame start (padded to one size) followed by
        # the frame's code input, so one product [Φᴺ | Ψ]·[x; u] advances it and one gives the
        # currents a coil sees; the two arrays alternate frame by frame
        self._frame_start = np.zeros((self.count, size + frame))
        self._frame_end = np.zeros((self.count, size + frame))
        self._step = np.zeros((self.count, size, size + frame))     # [Φᴺ | Ψ] per section, padded
        self._frame_index = 0
        self._live = list(range(self.count))
        self._wanted = set(range(self.count))
        self._review_parking = False
        self._parked = np.zeros((self.count, size))
        # a catch-up within a frame reads its slowest mode's frames and the frame itself
        history = 1 + max(self._settle_frames(self._model(k, _NO_TRAIN)) for k in range(self.count))
        self._history = np.zeros((min(history, _HISTORY_FLOATS // (self.count * frame)), self.count, frame))
        self._lookahead_m = max(self._spacing_list) + s.coil_offset_m + s.coil_length_m + 1.0
        self.relay_up = np.ones(self.count, dtype=bool)     # replaced when a relay moves, never changed in place
        self._relay_timer = np.zeros(self.count)
        self._carry_over: List[Tuple[int, _Model, _Model]] = []
        self._handover = [(1.0, 0.0)] * self.count

    # ---- geometry ---------------------------------------------------------------------------
    def section_of(self, x):
        k = np.searchsorted(self.starts, x, side="right") - 1
        return np.where(x < self._ends_ext[k], k, -1)      # k = −1 reads −inf: outside

    def section_at(self, x: float) -> int:
        k = bisect.bisect_right(self._starts_list, x) - 1
        return k if k >= 0 and x < self.ends_list[k] else -1

    def node_at(self, k: int, x: float) -> int:
        """Network node of section k nearest to x (clipped to the circuit: beyond the feed leads
        the rails carry no signal current, so a wheelset there shunts at the feed node)."""
        return min(max(round((min(x, self.feed_list[k]) - self._starts_list[k]) / self._spacing_list[k]), 0),
                   self._segments_list[k])

    # ---- calibration ------------------------------------------------------------------------
    def _design_levels(self, circuit: TrackCircuit, carrier_hz: float, ballast_min: float, ballast_max: float):
        """Relay-end voltages per unit feed at the carrier: (free circuit at the minimum ballast;
        the worst 0.06 Ω shunt over all nodes at the maximum ballast and its node; the worst
        broken rail over all segments at either ballast)."""
        omega, g = 2 * np.pi * carrier_hz, self.g_shunt
        worst_control = 0.0
        for ballast in (ballast_min, ballast_max):
            net = circuit.network(None, Faults(ballast), 1.0, carrier_hz)
            family = PhasorFamily(net, omega, [1.0])
            relay = net.node_index["n0"]
            nodes = np.array([net.node_index[f"n{i}"] for i in range(circuit.segments + 1)])
            broken = family.with_branch_opened(np.arange(circuit.segments), OPEN_OHM, relay)
            worst_control = max(worst_control, float(np.abs(broken).max()))
            if ballast == ballast_min:
                normal = abs(family.free[relay])
            else:
                # one shunt at each node in turn: Sherman–Morrison on Z
                z = family.impedance
                at_node = family.free[nodes] / (1.0 + g * z[nodes, nodes])
                shunted = np.abs(family.free[relay] - g * z[relay, nodes] * at_node)
                worst_node = int(np.argmax(shunted))
                worst_shunt = float(shunted[worst_node])
        return normal, worst_shunt, worst_node, worst_control

    def _levels(self, circuit: TrackCircuit, carrier_hz: float) -> Tuple[Calibration, float]:
        """Calibrate one circuit (docs/rail_line.md, relay calibration): the reference is set so that
        the free circuit at the minimum ballast and minimum supply reads exactly the pick-up
        level; the shunt and control modes are then read at the maximum supply."""
        s = self.settings
        tol = s.supply_tolerance
        ballast_min = circuit.params.ballast_ohm_km
        normal, shunt, node, control = self._design_levels(circuit, carrier_hz, ballast_min, self.ballast_max_ohm_km)
        reference = (1.0 - tol) * normal / s.relay_pick_up * (1.0 - 1e-9)   # 1e-9: picks up despite rounding
        shunt_level = (1.0 + tol) * shunt / reference
        control_level = (1.0 + tol) * control / reference
        return Calibration(float(circuit.feed_m - circuit.start_m), ballast_min, self.ballast_max_ohm_km,
                           float((1.0 - tol) * normal / reference), float(shunt_level), node, float(control_level),
                           float(s.relay_drop_out / max(shunt_level, control_level) - 1.0)), float(reference)

    def _calibrates(self, calibration: Calibration) -> bool:
        return calibration.shunt_margin >= self.settings.shunt_margin - 1e-12

    def _calibrate(self) -> List[Calibration]:
        """Each circuit's reference voltage (self._reference) from the three design regimes
        (docs/sources.md#track-circuits-and-rail-impedance, row 8), or the line refused naming the
        circuit and the longest circuit that would calibrate."""
        s = self.settings
        table, references, known = [], [], {}
        for k, (circuit, section) in enumerate(zip(self.circuits, self.line.sections)):
            if circuit.params.ballast_ohm_km > self.ballast_max_ohm_km:
                raise FmuInputError(f"{self.line.path}: field block_sections[{k}].ballast_ohm_km: "
                                    f"{circuit.params.ballast_ohm_km:g} Ω·km is above the line's max_ballast_ohm_km "
                                    f"{self.ballast_max_ohm_km:g}")
            key = (circuit.feed_m - circuit.start_m, circuit.params, float(self.track_frequencies[k]))
            if key not in known:                 # sections of one design share their calibration
                known[key] = self._levels(circuit, self.track_frequencies[k])
            calibration, reference = known[key]
            if not self._calibrates(calibration):
                longest = self.longest_calibratable_m(k)
                raise FmuInputError(
                    f"{self.line.path}: field block_sections[{k}]: track circuit '{section.name}' "
                    f"({calibration.length_m:.0f} m feed to relay) cannot be calibrated for ballast "
                    f"{calibration.ballast_min_ohm_km:g}–{calibration.ballast_max_ohm_km:g} Ω·km and "
                    f"±{100 * s.supply_tolerance:g} % supply: a 0.06 Ω shunt leaves the relay at "
                    f"{calibration.shunt_level:.3f} of its reference, drop-out {s.relay_drop_out:g} needs a margin of "
                    f"{100 * s.shunt_margin:g} %; the longest circuit that calibrates is {longest:.0f} m")
            table.append(calibration)
            references.append(reference)
        self._reference = np.array(references)
        return table

    def longest_calibratable_m(self, k: int) -> float:
        """The longest circuit (feed leads to relay end) with section k's equipment and ballast
        range that meets the normal and shunt modes with the required margin (bisection, 1 m)."""
        circuit = self.circuits[k]
        offset = circuit.end_m - circuit.feed_m

        def ok(length_m):
            trial = TrackCircuit(0.0, length_m + offset, offset, circuit.params)
            return self._calibrates(self._levels(trial, self.track_frequencies[k])[0])
        lo, hi = 1.0, max(circuit.feed_m - circuit.start_m, 1.0)
        if ok(hi):
            while ok(2 * hi) and hi < 1e5:
                lo, hi = 2 * hi, 2 * hi
            hi = 2 * hi
        elif not ok(lo):
            return 0.0
        while hi - lo > 1.0:
            middle = 0.5 * (lo + hi)
            lo, hi = (middle, hi) if ok(middle) else (lo, middle)
        return lo

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
        for k, parked_at in enumerate(self._parked_at):
            if parked_at is not None:                # caught up under the models it was parked with
                self._wake(k)
        self._effective_faults = [
            Faults(f.ballast_ohm_km, self.broken_rail_m if self.starts[k] <= self.broken_rail_m < self.ends[k] else -1.0,
                   f.feed_open) for k, f in enumerate(self.faults)]
        self._active = [None] * self.count          # models and relay levels follow the new faults
        self._configs: List[Optional[Config]] = [None] * self.count    # every section re-activates
        self._rows: List[Dict[int, int]] = [{} for _ in range(self.count)]
        self._node_bounds = [(0.0, 0.0)] * self.trains

    # ---- models -----------------------------------------------------------------------------
    def _model(self, k: int, config: Config) -> _Model:
        faults = self._effective_faults[k]
        key = (config, self._fault_key(k, faults))
        cache = self._models[k]
        if key in cache:
            cache.move_to_end(key)
            return cache[key]
        family_key = (k, faults)
        if family_key not in self._families:
            net = self.circuits[k].network(None, faults, self.settings.transformer_ratio, self.carriers[k], self.band_hz)
            self._families[family_key] = (ShuntFamily(net, self.g_shunt), net.node_index)
        family, node_index = self._families[family_key]
        shunts, heads = config
        system = family.state_space([node_index[f"n{node}"] for node in shunts])
        phi, gamma = discretise(system, self.dt)
        n = self.frame
        nx = phi.shape[0]
        segments = self.circuits[k].segments
        # output rows: the current arriving from the feed at each head (−segment current ahead of
        # its node; at the feed node, what the feed delivers: source − bond winding), then the
        # entry-end current (−segment 0)
        rows = np.zeros((len(heads) + 1, nx))
        direct = np.zeros(len(heads) + 1)
        for h, node in enumerate(heads):
            if node < segments:
                rows[h, node] = -1.0
            elif not faults.feed_open:
                g_feed, feed = 1.0 / self.settings.circuit.feed_r_ohm, node_index[f"n{segments}"]
                rows[h] = -g_feed * system.node_from_state[feed]
                rows[h, segments + 1] -= 1.0                 # the feed bond winding's branch
                direct[h] = g_feed * (self.settings.transformer_ratio - system.node_from_input[feed, 0])
        rows[-1, 0] = -1.0
        out_o = np.empty((n, len(rows), nx))
        markov = np.empty((n, len(rows)))       # C·Φ^k·Γ
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
        # outputs of all samples at once: (H, N, nx) and (H, N, N) per head, (N, nx), (N, N) entry
        rotation = np.exp(2j * np.pi * self.carriers[k] * self.dt)
        response = np.linalg.solve(rotation * np.eye(nx) - phi, gamma[:, 0].astype(complex))
        ahead_response = rows[:-1] @ response + direct[:-1]
        rotated = response * rotation
        carrier_system = np.concatenate([np.stack([response.real, -response.imag], 1),
                                         np.stack([rotated.real, -rotated.imag], 1)])
        model = _Model(np.linalg.matrix_power(phi, n), psi,
                       np.ascontiguousarray(out_o[:, :-1].transpose(1, 0, 2)),
                       np.ascontiguousarray(out_t[:, :-1].transpose(1, 0, 2)),
                       np.ascontiguousarray(out_o[:, -1]), np.ascontiguousarray(out_t[:, -1]),
                       self.relay_level(k, shunts), phi, response,
                       complex(ahead_response[0]) if heads else 0j, carrier_system)
        cache[key] = model
        if len(cache) > self._cache_size[k]:
            cache.popitem(last=False)
        return model

    def _fault_key(self, k: int, faults: Faults) -> tuple:
        """What of section k's faults its network depends on, relative to the section (its
        ballast, the segment a broken rail opens, an open feed), so sections of one design
        share models under the same faults (TrackCircuit.network)."""
        circuit, broken = self.circuits[k], -1
        if faults.broken_rail_m >= 0:
            nodes = circuit.nodes_m
            broken = next((i for i in range(circuit.segments) if nodes[i] <= faults.broken_rail_m < nodes[i + 1]), -1)
        return circuit.ballast(faults), broken, faults.feed_open

    def _phasor_family(self, k: int, faults: Faults) -> PhasorFamily:
        key = (k, faults)
        if key not in self._phasor_families:
            self._phasor_families[key] = PhasorFamily(self.circuits[k].network(None, faults, 1.0,
                                                                               self.track_frequencies[k]),
                                                      2 * np.pi * self.track_frequencies[k], [1.0])
        return self._phasor_families[key]

    def _phasor_table(self, k: int, faults: Optional[Faults] = None) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For ONE wheelset shunt at each node of section k (the current faults unless given; unit
        feed, phasor at the carrier): |shunt current|, its log, and |relay-end voltage|; the last
        relay entry is the circuit without a shunt. The shape of the amplitude between nodes
        (``scale``) and the ALS-mode regime (one normative shunt) use it."""
        faults = self._effective_faults[k] if faults is None else faults
        key = (k, faults)
        if key not in self._phasors:
            circuit, g_sh = self.circuits[k], self.g_shunt
            net = circuit.network(None, faults, 1.0, self.carriers[k])
            nodes = [net.node_index[f"n{node}"] for node in range(circuit.segments + 1)]
            at_node, at_relay, free_relay = net.phasor_with_shunt(2 * np.pi * self.carriers[k], [1.0], g_sh,
                                                                  net.node_index["n0"])
            amplitude = np.maximum(np.abs(at_node[nodes]) * g_sh, 1e-12)
            relay = np.append(np.abs(at_relay[nodes]), abs(free_relay))    # last: no shunt
            self._phasors[key] = (amplitude, np.log(amplitude), relay)
        return self._phasors[key]

    def relay_level(self, k: int, shunts: Sequence[int] = (), faults: Optional[Faults] = None,
                    supply: float = 1.0) -> float:
        """Relay-end voltage of section k with a 0.06 Ω shunt at each node in ``shunts`` under the
        current faults unless given, at ``supply`` × the nominal feed, relative to the circuit's
        calibrated reference (pick-up and drop-out are levels of this)."""
        faults = self._effective_faults[k] if faults is None else faults
        family = self._phasor_family(k, faults)
        return supply * abs(family.with_shunts(list(shunts), self.g_shunt, 0)) / self._reference[k]

    def scale(self, k: int, head: np.ndarray, j: int, times: np.ndarray, standing_at: Optional[float] = None):
        """Code-current amplitude at the exact wheelset position over the one at the model's node,
        for the train whose head is the section's front-most shunt (1 for any other train).
        The shape between nodes is the one-shunt table's; a whole train's shunts make the
        amplitude at the next node differ from it by a few per cent, and that difference is
        spread over ``SHUNT_BLEND_S`` after the head moves on to the next node. A train
        standing at ``standing_at`` over the frame gets the frame before's values again when
        nothing else changed (the same computation on the same positions)."""
        _, _, log_amplitude, at_node, front = self._active[k]
        if j != front:
            return 1.0
        kept = self._standing_scale[k]
        if standing_at is not None and kept is not None and kept[0] == standing_at and kept[1] is log_amplitude \
                and kept[2] == at_node and kept[3].size == head.size:
            value = kept[3]
        else:
            value = np.exp(_interp(head, self._nodes_m[k], log_amplitude) - at_node)
            self._standing_scale[k] = (standing_at, log_amplitude, at_node, value) if standing_at is not None else None
        gain, since = self._handover[k]
        if gain != 1.0 and times[0] - since < SHUNT_BLEND_S:
            blend = 1.0 - (times - since) / SHUNT_BLEND_S
            value = value * (1.0 + (gain - 1.0) * np.minimum(np.maximum(blend, 0.0, out=blend), 1.0, out=blend))
        return value

    @property
    def states(self) -> np.ndarray:
        """Every section's states at the start of the coming frame (a view, padded)."""
        return self._frame_start[:, :self._size]

    # ---- the trains' shunts -----------------------------------------------------------------
    def follow_shunts(self, heads: List[float], tick_s: float = 0.0) -> None:
        """Every train's wheelsets (heads at the configuration tick ``tick_s``) as shunts,
        activating the models of the sections whose configuration changed."""
        for head, (lo, hi) in zip(heads, self._node_bounds):
            if not lo < head < hi:
                break
        else:
            return                         # every head between the same two nodes as before
        configs, rows = self._configuration(heads)
        for k, config in enumerate(configs):
            if config != self._configs[k]:
                self._rows[k] = rows[k]
                self._activate(k, config, rows[k], tick_s)
        self._configs = configs
        # advanced every frame: the sections with a wheelset, and those a coil may reach before
        # the next configuration change (the head moves less than a node spacing till then)
        wanted = {k for k, (shunts, _) in enumerate(configs) if shunts}
        for head in heads:
            first = bisect.bisect_right(self.ends_list, head)
            last = bisect.bisect_right(self._starts_list, head + self._lookahead_m)
            wanted.update(range(first, last))
        self._wanted = wanted
        self._review_parking = True

    def _configuration(self, heads: List[float]):
        """Per section: (its shunt nodes, the head nodes of the trains whose head is in it, front
        first) and which row each such train reads; per train the open interval of head
        positions over which its contribution is constant (self._node_bounds)."""
        shunts = [set() for _ in range(self.count)]
        in_section: List[List[Tuple[int, int]]] = [[] for _ in range(self.count)]
        bounds = []
        for j, (head, length) in enumerate(zip(heads, self._train_lengths)):
            tail = head - length
            # sections with start ≤ head and end > tail (sorted, disjoint)
            last = bisect.bisect_right(self._starts_list, head) - 1
            for k in range(bisect.bisect_right(self.ends_list, tail), last + 1):
                front = self.node_at(k, head)
                shunts[k].update(range(self.node_at(k, max(tail, self._starts_list[k])), front + 1))
                if k == last and head < self.ends_list[k]:
                    in_section[k].append((front, j))
            head_lo, head_hi = self._interval(head)
            tail_lo, tail_hi = self._interval(tail)
            bounds.append((max(head_lo, tail_lo + length), min(head_hi, tail_hi + length)))
        self._node_bounds = bounds
        configs, rows = [], []
        for k in range(self.count):
            order = sorted(in_section[k], reverse=True)
            configs.append((tuple(sorted(shunts[k])), tuple(node for node, _ in order)))
            rows.append({j: h for h, (_, j) in enumerate(order)})
        return configs, rows

    def _interval(self, x: float) -> Tuple[float, float]:
        """Open interval around a head or tail position x over which its section, its clipping
        to the feed and its nearest node do not change."""
        edges = self._edges
        i = bisect.bisect_right(edges, x)
        lo, hi = (edges[i - 1] if i > 0 else -math.inf), (edges[i] if i < len(edges) else math.inf)
        k = self.section_at(x)
        if 0 <= k and x < self.feed_list[k]:
            start, spacing = self._starts_list[k], self._spacing_list[k]
            middle = round((x - start) / spacing)
            lo, hi = max(lo, start + (middle - 0.5) * spacing), min(hi, start + (middle + 0.5) * spacing)
        return lo, hi

    def _activate(self, k: int, config: Config, rows: Dict[int, int], tick_s: float) -> None:
        model = self._model(k, config)
        if self._parked_at[k] is not None:         # caught up under the model it was parked with
            self._wake(k)
        previous = self._active[k]
        self._handover[k] = (1.0, 0.0)
        # (one carrier only: the states of a code of several tones carry over as they are)
        if previous is not None and previous[1].phi.shape == model.phi.shape and previous[1] is not model \
                and self.band_hz is None:
            self._carry_over.append((k, previous[1], model))
        log_amplitude = self._phasor_table(k)[1]
        shunts, heads = config
        # the train whose head is the front-most shunt gets the continuous amplitude (scale)
        front = next((j for j, h in rows.items() if h == 0), -1) if heads and heads[0] == shunts[-1] else -1
        self._active[k] = (config, model, log_amplitude, log_amplitude[heads[0]] if front >= 0 else 0.0, front)
        if previous is not None and front >= 0 and previous[4] == front and previous[1] is not model:
            # the front train's steady amplitude just before and just after, at the same place
            before = abs(previous[1].front_response) * math.exp(-previous[3])
            after = abs(model.front_response) * math.exp(-self._active[k][3])
            if before > 0.0 and after > 0.0:     # an opened feed carries no code to hand over
                self._handover[k] = (before / after, tick_s)
        size = model.phi_n.shape[0]
        if model.padded is None:
            model.padded = self._padded(model)
        self._step[k] = model.padded[0]
        self.states[k, size:] = 0.0       # a branch the new network lacks (feed opened) carries nothing
        self._relay_levels[k] = model.relay_level
        self._relays_settled = False

    # ---- a frame ----------------------------------------------------------------------------
    def start(self, heads: List[float]) -> None:
        """The state at t = 0 with the trains at ``heads``: the relays stand as the trains'
        shunts leave them, with no pick-up or drop-out delay (up only at or above pick-up:
        the restrictive reading of a relay whose history is unknown)."""
        self.follow_shunts(heads)
        self.relay_up = self._relay_levels >= self.settings.relay_pick_up
        self._relay_timer[:] = 0.0
        self._relays_settled = False

    def _padded(self, model: _Model) -> tuple:
        """The model's matrices on a section's padded [states | frame input] row: the step
        [Φᴺ | Ψ] (size, size + N), the currents at the heads (H, N, size + N) and at the entry
        end (N, size + N); a state the model lacks has zero columns and a zero row."""
        size, nx = self._size, model.phi_n.shape[0]
        step = np.zeros((size, size + self.frame))
        step[:nx, :nx], step[:nx, size:] = model.phi_n, model.psi
        ahead = np.zeros((model.ahead_o.shape[0], self.frame, size + self.frame))
        ahead[..., :nx], ahead[..., size:] = model.ahead_o, model.ahead_t
        entry = np.zeros((self.frame, size + self.frame))
        entry[:, :nx], entry[:, size:] = model.entry_o, model.entry_t
        return step, ahead, entry

    def _settle_frames(self, model: _Model) -> int:
        """Frames after which whatever a section's states held has decayed below
        _SETTLED_SHARE (its network's slowest mode over a frame)."""
        if not model.settle_frames:
            radius = float(np.abs(np.linalg.eigvals(model.phi_n)).max())
            model.settle_frames = 1 if radius < 1e-300 else 1 << 62 if radius >= 1.0 \
                else math.ceil(math.log(_SETTLED_SHARE) / math.log(radius))
        return model.settle_frames

    def advance(self, u: np.ndarray, n: int) -> FrameCurrents:
        """The states over a frame of code input ``u`` (K, n) of the sections a train or a coil
        may need (the others parked, caught up when needed), and the relays; the frame's
        currents, computed on demand from the states it started from."""
        if self._carry_over:
            self._carry_states_over(u)
        start, end, size = self._frame_start, self._frame_end, self._size
        if len(self._live) < self.count:
            self._history[self._frame_index % len(self._history)] = u
        if 2 * len(self._live) > self.count:       # most sections: one stacked product
            start[:, size:] = u
            np.matmul(self._step, start[..., None], out=end[:, :size, None])
        else:
            step = self._step
            for k in self._live:
                start[k, size:] = u[k]
                np.matmul(step[k], start[k], out=end[k, :size])
        self._frame_index += 1
        if self._review_parking:
            self._park()
        self._frame_start, self._frame_end = end, start
        if not self._relays_settled:
            self._update_relays(n * self.dt)
        return FrameCurrents(self, start)

    def _park(self) -> None:
        """Stop advancing the live sections no train or coil needs (after this frame's step),
        when their history would be long enough to catch them up."""
        self._review_parking = False
        keep = []
        for k in self._live:
            model = self._active[k][1]
            if k in self._wanted or self._settle_frames(model) >= len(self._history):
                keep.append(k)
            else:
                self._parked[k] = self._frame_end[k, :self._size]
                self._parked_at[k] = self._frame_index
        self._live = keep

    def _caught_up(self, k: int, until: int) -> np.ndarray:
        """A parked section's states at the start of frame ``until``: its parked states stepped
        through the code input of the frames since, or only of the last frames its slowest mode
        needs to forget where it started (the difference is below rounding)."""
        size, history = self._size, self._history
        first = max(self._parked_at[k], until - self._settle_frames(self._active[k][1]))
        row, following = np.empty(size + self.frame), np.empty(size)
        row[:size] = self._parked[k]
        step = self._step[k]
        for index in range(first, until):
            row[size:] = history[index % len(history), k]
            np.matmul(step, row, out=following)
            row[:size] = following
        self._parked_at[k] = None
        self._wanted.add(k)
        self._live = sorted(self._live + [k])
        return row[:size]

    def _wake(self, k: int) -> None:
        """Before a frame's step: a parked section caught up, advanced from this frame on."""
        self.states[k] = self._caught_up(k, self._frame_index)

    def _wake_in_frame(self, k: int) -> None:
        """After a frame's step, when a coil reads a parked section: caught up to the frame
        start, then stepped over the frame (the history holds the frame's input)."""
        size, start = self._size, self._frame_end          # the arrays have alternated
        start[k, :size] = self._caught_up(k, self._frame_index - 1)
        start[k, size:] = self._history[(self._frame_index - 1) % len(self._history), k]
        np.matmul(self._step[k], start[k], out=self._frame_start[k, :size])

    def _carry_states_over(self, u: np.ndarray) -> None:
        """A wheelset shunt moved to the next node (the train's lumped shunts step by up to 50 m):
        the branch currents' steady state at the carrier is replaced by the new network's, with the
        carrier's amplitude and phase read from the old states and their next sample. Carrying the old states over unchanged would start a transient
        of the network's time constants (≈ 10 ms), a step of a few per cent in the current under
        the coils at every node: an EMF spike a moving train does not make."""
        for k, old, new in self._carry_over:
            if self._active[k] is None or self._active[k][1] is not new:
                continue
            nx = new.phi.shape[0]
            state = self.states[k, :nx]
            # x[n] = Re(h·p), x[n+1] = Re(h·p·e^{jωΔ}): the carrier's phasor p by least squares
            # (h: the old model's carrier response; its system matrix is built with the model)
            following = old.phi @ state + old.psi[:, -1] * u[k, 0]
            (p_re, p_im), *_ = np.linalg.lstsq(old.carrier_system, np.concatenate([state, following]), rcond=None)
            carrier = p_re + 1j * p_im
            # only the carrier's steady state is swapped: what else the states hold (the decaying
            # response to a code edge) carries over as it is
            self.states[k, :nx] += ((new.carrier_response - old.carrier_response) * carrier).real
        self._carry_over.clear()

    def _update_relays(self, step_s: float) -> None:
        s = self.settings
        levels = self._relay_levels
        wants_up = np.where(self.relay_up, levels > s.relay_drop_out, levels >= s.relay_pick_up)
        changing = wants_up != self.relay_up
        if not any_true(changing):
            self._relay_timer[:] = 0.0
            self._relays_settled = True              # nothing to do until a level changes
            return
        self._relay_timer = np.where(changing, self._relay_timer + step_s, 0.0)
        delay = np.where(wants_up, s.relay_pick_up_delay_s, s.relay_drop_out_delay_s)
        done = changing & (self._relay_timer >= delay - 1e-12)
        if any_true(done):
            self.relay_up = np.where(done, wants_up, self.relay_up)
            self._relay_timer[done] = 0.0

    # ---- studies ------------------------------------------------------------------------------
    def minimum_code_current(self, k: int, ballast_ohm_km: float) -> float:
        """ALS mode: the smallest code current (A rms) under one normative shunt (the first
        wheelset, the standard's regime) over all positions in section k, for the nominal code
        amplitude 4 V × transformer ratio."""
        amplitude = self._phasor_table(k, Faults(ballast_ohm_km, -1.0, False))[0]
        return float(amplitude.min() * 4.0 * self.settings.transformer_ratio / np.sqrt(2.0))
