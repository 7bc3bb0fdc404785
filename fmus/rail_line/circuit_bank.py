"""The track-circuit bank: the line's K coded track circuits under the trains' wheelsets, their
network states frame by frame, and the track relays (no FMI here; docs/rail_line.md).

Two solutions of each section work together:

* the network model (network_models.py): the section's network with a 0.06 Ω shunt at every
  node a train covers (nodes ≤ 50 m apart), as a state-space model discretised exactly at fs;
  its states (the rail segments' currents) advance frame by frame and carry over when a train
  moves to the next node. It gives the waveform of the code current: its carrier, its code
  edges and the network's transients;
* the wheelset chain (axle_chain.py): the same track circuit at the carrier with every wheelset
  at its axle position, solved at a configuration tick (every 10 ms of simulated time) for the
  sections a train has moved a metre in since their last solution (SOLVE_STEP_M), come to rest
  in, or whose configuration or faults changed. It gives the amplitudes: the current arriving
  at each train's first axle, the entry-end current and the relay-end voltage.

The current a train's coils see is the network model's current arriving at its head node from
the feed (a branch current: a state), scaled so that its amplitude at the carrier is the chain's
at its solution, and in between following the one-shunt amplitude table along the track, so
it varies continuously with position. A train
behind another one in the same circuit gets what the front train's wheelsets leave, as the chain
says. The relays read the chain's relay-end voltage at the track circuit's own frequency. The
rail line core takes the configuration every 10 ms of simulated time, whatever the frame length,
so frames of any length give the same result.

The bank composes its parts, one concern each:

* geometry.py — where the sections, their feed points, nodes and joints lie;
* calibration.py — each relay's reference from the design regimes, the relay-end levels;
* network_models.py — the network model per configuration, cached and shared by design;
* axle_chain.py — the wheelset chain of a section at one frequency, and wheelset_amplitudes.py —
  its solutions: the trains' amplitude factors, the entry-end current's, the relay levels;
* parking.py — sections no train or coil needs are not advanced, and caught up when needed;
* relays.py — the track relays: levels against pick-up / drop-out with delays → occupancy.
"""
from __future__ import annotations

import bisect
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from fmus.data.loader import Line
from fmus.rail_line.calibration import RelayCalibration
from fmus.rail_line.geometry import LineGeometry
from fmus.rail_line.network_models import NO_TRAIN, Config, NetworkModel, NetworkModels
from fmus.rail_line.parking import Parking, settle_frames
from fmus.rail_line.relays import TrackRelays
from fmus.rail_line.track_circuit import Faults
from fmus.rail_line.wheelset_amplitudes import WheelsetAmplitudes




# the wheelsets are solved again once a train has moved this far since its last solution (or
# comes to rest): in between, its amplitude follows the one-shunt table along the track, which
# the chain's shape differs from by < 10⁻³ over a metre (docs/rail_line.md, simplifications)
SOLVE_STEP_M = 1.0


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
        if bank.parking.parked_at[k] is not None:
            bank._wake_in_frame(k)
        return bank._active[k][1].padded[1][row] @ self.start[k]

    def entry(self, k: int) -> np.ndarray:
        bank = self.bank
        if bank.parking.parked_at[k] is not None:
            bank._wake_in_frame(k)
        return (bank._active[k][1].padded[2] @ self.start[k]) * bank.amplitudes.entry_factor[k]


class TrackCircuitBank:
    """The line's track circuits: their geometry, faults, relay calibration, network models and
    states, parking, relays."""

    def __init__(self, line: Line, settings, trains: int, frame: int, tick_s: float = 0.01):
        s = settings
        self.settings = s
        self.geometry = geometry = LineGeometry(line, s)
        self.count, self.trains, self.frame = geometry.count, trains, frame
        self.dt = 1.0 / s.fs_hz
        self.calibration = RelayCalibration(line, geometry, s)
        self.models = NetworkModels(geometry, self.calibration, s, frame)
        self._fault_inputs = None
        self.faults = [Faults() for _ in range(self.count)]
        self.broken_rail_m = -1.0
        self._train_lengths = [float(length) for length in s.train_length_m]
        self._zeros = np.zeros(frame)
        # the trains' amplitudes: the wheelset chains and their factors; the heads at the last tick
        self.amplitudes = WheelsetAmplitudes(geometry, self.calibration, s, tick_s)
        self._tick_heads: Optional[List[float]] = None
        self._solved_heads: Optional[List[float]] = None    # each train's head at its last solution
        self._tick_s: Optional[float] = None
        size = self._size = self.models.size
        # per section and frame: its states at the frame start (padded to one size) followed by
        # the frame's code input, so one product [Φᴺ | Ψ]·[x; u] advances it and one gives the
        # currents a coil sees; the two arrays alternate frame by frame
        self._frame_start = np.zeros((self.count, size + frame))
        self._frame_end = np.zeros((self.count, size + frame))
        self._step = np.zeros((self.count, size, size + frame))     # [Φᴺ | Ψ] per section, padded
        self._frame_index = 0
        # sections advanced every frame (the others parked, caught up from the inputs' history
        # when needed); a catch-up within a frame reads its slowest mode's frames and the frame itself
        free = [self.models.model(k, NO_TRAIN, Faults()) for k in range(self.count)]
        self.parking = Parking(self.count, frame, size, self._step, 1 + max(settle_frames(m) for m in free))
        self.relays = TrackRelays(self.count, s)
        self._refresh_faults()
        self._lookahead_m = max(geometry.spacing_list) + s.coil_offset_m + s.coil_length_m + 1.0
        self._carry_over: List[Tuple[int, NetworkModel, NetworkModel]] = []

    # ---- relay calibration --------------------------------------------------------------------
    def relay_level(self, k: int, shunts: Sequence[int] = (), faults: Optional[Faults] = None,
                    supply: float = 1.0) -> float:
        """Relay-end voltage of section k with a 0.06 Ω shunt at each node in ``shunts`` under the
        current faults unless given, at ``supply`` × the nominal feed, relative to the circuit's
        calibrated reference (pick-up and drop-out are levels of this)."""
        faults = self._effective_faults[k] if faults is None else faults
        return self.calibration.relay_level(k, shunts, faults, supply)

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
        for k, parked_at in enumerate(self.parking.parked_at):
            if parked_at is not None:                # caught up under the models it was parked with
                self._wake(k)
        starts, ends = self.geometry.starts, self.geometry.ends
        self._effective_faults = [
            Faults(f.ballast_ohm_km, self.broken_rail_m if starts[k] <= self.broken_rail_m < ends[k] else -1.0,
                   f.feed_open) for k, f in enumerate(self.faults)]
        self._active = [None] * self.count          # models and relay levels follow the new faults
        self._configs: List[Optional[Config]] = [None] * self.count    # every section re-activates
        self._rows: List[Dict[int, int]] = [{} for _ in range(self.count)]
        self._node_bounds = [(0.0, 0.0)] * self.trains
        self._tick_heads = self._solved_heads = None   # every section's chain solved again
        self.amplitudes.reset(self._effective_faults)

    @property
    def states(self) -> np.ndarray:
        """Every section's states at the start of the coming frame (a view, padded)."""
        return self._frame_start[:, :self._size]

    # ---- the trains' shunts -----------------------------------------------------------------
    def follow_shunts(self, heads: List[float], tick_s: float = 0.0) -> None:
        """Every train's wheelsets (heads at the configuration tick ``tick_s``) as shunts:
        the models of the sections whose configuration changed activated, the wheelset chain
        solved again for the sections a train has moved SOLVE_STEP_M in since its last solution
        (or come to rest in)."""
        if tick_s == self._tick_s and heads == self._tick_heads:
            return                         # this tick's, taken already (frames shorter than a tick)
        previous, self._tick_heads, self._tick_s = self._tick_heads, list(heads), tick_s
        moving = heads != previous
        amplitudes = self.amplitudes
        if not moving and heads == self._solved_heads:       # nothing moved, nothing left to solve
            if amplitudes.passing:
                amplitudes.settle(tick_s, ())
            return
        changed = set()
        if moving:
            for head, (lo, hi) in zip(heads, self._node_bounds):
                if not lo < head < hi:
                    changed = self._follow_nodes(heads, tick_s)
                    break
        geometry = self.geometry
        if self._solved_heads is None:     # the first tick, or faults changed: every section
            touched = set(range(self.count))
            self._solved_heads = list(heads)
        else:
            touched = changed
            solved = self._solved_heads
            for j, head in enumerate(heads):
                last = solved[j]
                # a metre on since its last solution, or at rest elsewhere: the sections under its
                # wheelsets then and now
                if head != last and (abs(head - last) >= SOLVE_STEP_M or head == previous[j]):
                    lo, hi = min(head, last) - amplitudes.spans[j], max(head, last)
                    touched.update(range(bisect.bisect_right(geometry.ends_list, lo),
                                         bisect.bisect_right(geometry.starts_list, hi)))
                    solved[j] = head
        if amplitudes.passing:
            amplitudes.settle(tick_s, touched)
        relays = self.relays
        for k in sorted(touched):
            level = amplitudes.solve(k, heads, tick_s, self._rows[k], self._active[k][1])
            relays.levels[k] = level
            if relays.settled and relays.would_move(k, level):
                relays.settled = False     # a relay starts to pick up or drop out

    def _follow_nodes(self, heads: List[float], tick_s: float) -> set:
        """The configurations from the heads; the sections whose configuration changed
        activated (returned)."""
        configs, rows = self.configuration(heads)
        changed = set()
        for k, config in enumerate(configs):
            if config != self._configs[k]:
                self._rows[k] = rows[k]
                self._activate(k, config)
                changed.add(k)
        self._configs = configs
        # advanced every frame: the sections with a wheelset, and those a coil may reach before
        # the next configuration change (the head moves less than a node spacing till then)
        wanted = {k for k, (shunts, _) in enumerate(configs) if shunts}
        geometry = self.geometry
        for head in heads:
            first = bisect.bisect_right(geometry.ends_list, head)
            last = bisect.bisect_right(geometry.starts_list, head + self._lookahead_m)
            wanted.update(range(first, last))
        self.parking.wanted = wanted
        self.parking.review = True
        return changed

    def configuration(self, heads: List[float]):
        """Per section: (its shunt nodes, the head nodes of the trains whose head is in it, front
        first) and which row each such train reads; per train the open interval of head
        positions over which its contribution is constant (self._node_bounds)."""
        geometry = self.geometry
        starts, ends = geometry.starts_list, geometry.ends_list
        shunts = [set() for _ in range(self.count)]
        in_section: List[List[Tuple[int, int]]] = [[] for _ in range(self.count)]
        bounds = []
        for j, (head, length) in enumerate(zip(heads, self._train_lengths)):
            tail = head - length
            # sections with start ≤ head and end > tail (sorted, disjoint)
            last = bisect.bisect_right(starts, head) - 1
            for k in range(bisect.bisect_right(ends, tail), last + 1):
                front = geometry.node_at(k, head)
                shunts[k].update(range(geometry.node_at(k, max(tail, starts[k])), front + 1))
                if k == last and head < ends[k]:
                    in_section[k].append((front, j))
            head_lo, head_hi = geometry.interval(head)
            tail_lo, tail_hi = geometry.interval(tail)
            bounds.append((max(head_lo, tail_lo + length), min(head_hi, tail_hi + length)))
        self._node_bounds = bounds
        configs, rows = [], []
        for k in range(self.count):
            order = sorted(in_section[k], reverse=True)
            configs.append((tuple(sorted(shunts[k])), tuple(node for node, _ in order)))
            rows.append({j: h for h, (_, j) in enumerate(order)})
        return configs, rows

    def _activate(self, k: int, config: Config) -> None:
        model = self.models.model(k, config, self._effective_faults[k])
        if self.parking.parked_at[k] is not None:         # caught up under the model it was parked with
            self._wake(k)
        previous = self._active[k]
        # (one carrier only: the states of a code of several tones carry over as they are)
        if previous is not None and previous[1].phi.shape == model.phi.shape and previous[1] is not model \
                and self.geometry.band_hz is None:
            self._carry_over.append((k, previous[1], model))
        self.amplitudes.one_shunt(k, self.models.one_shunt_table(k, self._effective_faults[k])[1])
        self._active[k] = (config, model)
        size = model.phi_n.shape[0]
        if model.padded is None:
            model.padded = self.models.padded(model)
        self._step[k] = model.padded[0]
        self.states[k, size:] = 0.0       # a branch the new network lacks (feed opened) carries nothing

    # ---- a frame ----------------------------------------------------------------------------
    def start(self, heads: List[float]) -> None:
        """The state at t = 0 with the trains at ``heads``: the relays stand as the trains'
        shunts leave them, with no pick-up or drop-out delay (up only at or above pick-up:
        the restrictive reading of a relay whose history is unknown)."""
        self.follow_shunts(heads)
        self.relays.stand()

    def advance(self, u: np.ndarray, n: int) -> FrameCurrents:
        """The states over a frame of code input ``u`` (K, n) of the sections a train or a coil
        may need (the others parked, caught up when needed), and the relays; the frame's
        currents, computed on demand from the states it started from."""
        if self._carry_over:
            self._carry_states_over(u)
        start, end, size = self._frame_start, self._frame_end, self._size
        parking = self.parking
        live = parking.live
        if len(live) < self.count:
            history = parking.history
            history[self._frame_index % len(history)] = u
        if 2 * len(live) > self.count:       # most sections: one stacked product
            start[:, size:] = u
            np.matmul(self._step, start[..., None], out=end[:, :size, None])
        else:
            step = self._step
            for k in live:
                start[k, size:] = u[k]
                np.matmul(step[k], start[k], out=end[k, :size])
        self._frame_index += 1
        if parking.review:
            active = self._active
            parking.park(end, self._frame_index, lambda k: settle_frames(active[k][1]))
        self._frame_start, self._frame_end = end, start
        relays = self.relays
        if not relays.settled:
            relays.update(n * self.dt)
        return FrameCurrents(self, start)

    def _wake(self, k: int) -> None:
        """Before a frame's step: a parked section caught up, advanced from this frame on."""
        self.states[k] = self.parking.caught_up(k, self._frame_index, settle_frames(self._active[k][1]))

    def _wake_in_frame(self, k: int) -> None:
        """After a frame's step, when a coil reads a parked section: caught up to the frame
        start, then stepped over the frame (the history holds the frame's input)."""
        size, start, parking = self._size, self._frame_end, self.parking       # the arrays have alternated
        start[k, :size] = parking.caught_up(k, self._frame_index - 1, settle_frames(self._active[k][1]))
        start[k, size:] = parking.history[(self._frame_index - 1) % len(parking.history), k]
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

    # ---- studies ------------------------------------------------------------------------------
    def wheelset_solution(self, k: int, heads: List[float], frequency_hz: Optional[float] = None):
        """Section k with every train's wheelsets at their axles (heads at ``heads``, the
        current faults), solved by the wheelset chain at ``frequency_hz`` (default the
        section's carrier), per volt of code input: ({train: the current arriving at its first
        axle, A} for the trains whose head is in the section, the entry-end current, A, and the
        relay-end voltage, V) — the amplitudes the rail line gives its outputs and relays."""
        geometry = self.geometry
        frequency = float(geometry.carriers[k]) if frequency_hz is None else float(frequency_hz)
        chain = self.amplitudes.chain(k, frequency)
        trains = [j for j, head in enumerate(heads) if geometry.starts_list[k] <= head < geometry.ends_list[k]]
        currents, entry, relay = chain.solve(self.amplitudes.wheelset_runs(k, chain, heads), [heads[j] for j in trains])
        return dict(zip(trains, currents)), entry, relay

    def minimum_code_current(self, k: int, ballast_ohm_km: float) -> float:
        """ALS mode: the smallest code current (A rms) under one normative shunt (the first
        wheelset, the standard's regime) over all positions in section k, for the nominal code
        amplitude 4 V × transformer ratio."""
        amplitude = self.models.one_shunt_table(k, Faults(ballast_ohm_km, -1.0, False))[0]
        return float(amplitude.min() * 4.0 * self.settings.transformer_ratio / np.sqrt(2.0))
