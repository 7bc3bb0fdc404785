"""The track circuits' network models (no FMI here; docs/rail_line.md): per section and
configuration (the wheelset shunts' nodes, the train heads' nodes, the faults) the state-space
model of its network, discretised exactly at fs for a frame, with the outputs the coils read;
cached, and shared by the sections of one design. Also each section's one-shunt phasor table
at its carrier (the amplitude's shape between nodes, the ALS-mode regime).

A section's network with every shunt of every train in it is the free network's state space
with a Woodbury update (network.py ShuntFamily), discretised for a zero-order hold.
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

import numpy as np

from fmus.rail_line.calibration import RelayCalibration
from fmus.rail_line.geometry import LineGeometry
from fmus.rail_line.network import ShuntFamily, discretise
from fmus.rail_line.track_circuit import Faults

CACHE_SIZE = 64          # network models kept per section (shared by the sections of one design)
# a section's configuration: (shunt nodes, sorted; head nodes, one per train head in it, front first)
Config = Tuple[Tuple[int, ...], Tuple[int, ...]]
NO_TRAIN: Config = ((), ())


@dataclass
class NetworkModel:
    phi_n: np.ndarray       # (nx, nx) state after a frame
    psi: np.ndarray         # (nx, N) input → state after a frame
    ahead_o: np.ndarray     # (H, N, nx) state at the frame start → current arriving at head h, per sample
    ahead_t: np.ndarray     # (H, N, N) inputs of the frame → the same
    entry_o: np.ndarray     # (N, nx) the same for the entry-end current
    entry_t: np.ndarray     # (N, N)
    phi: np.ndarray         # (nx, nx) state after one sample (psi[:, -1]: input → state after one sample)
    carrier_response: np.ndarray    # (nx,) complex: the states' phasor per unit input phasor at the
                                    # carrier, sampled (the discrete model's steady state)
    head_responses: np.ndarray      # (H,) complex: the same for the current arriving at each head
    entry_response: complex         # the same for the entry-end current
    carrier_system: np.ndarray      # (2·nx, 2) the states at a sample and the next → the carrier's
                                    # phasor (re, im), by least squares (TrackCircuitBank._carry_states_over)
    settle_frames: int = 0          # frames for every mode to fall below parking.SETTLED_SHARE (0: not yet known)
    padded: Optional[tuple] = None  # (step, ahead, entry) on a section's padded [states | frame input]


class NetworkModels:
    """Every section's network models, made on demand and cached per (configuration, faults
    relative to the section); ``size`` is the most states any section's free network has (the
    padded size of the bank's state rows)."""

    def __init__(self, geometry: LineGeometry, calibration: RelayCalibration, settings, frame: int):
        self.geometry, self.calibration, self.settings, self.frame = geometry, calibration, settings, frame
        self.dt = 1.0 / settings.fs_hz
        self.g_shunt = 1.0 / settings.circuit.shunt_r_ohm
        self._families: Dict[Tuple[int, Faults], Tuple[ShuntFamily, Dict[str, int]]] = {}
        self._phasors: Dict[Tuple[int, Faults], Tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        # sections of one design (the same circuit relative to its start, carrier and calibration)
        # share their network models: a train passing one meets the same configurations again
        designs = [(circuit.segments, float(circuit.feed_m - circuit.start_m), circuit.params,
                    float(geometry.carriers[k]), float(geometry.track_frequencies[k]),
                    float(calibration.reference[k]))
                   for k, circuit in enumerate(geometry.circuits)]
        shared = {design: OrderedDict() for design in designs}
        self._models: List[OrderedDict] = [shared[design] for design in designs]
        self._cache_size = [CACHE_SIZE * designs.count(design) for design in designs]
        self.size = max(self.model(k, NO_TRAIN, Faults()).phi_n.shape[0] for k in range(geometry.count))

    def model(self, k: int, config: Config, faults: Faults) -> NetworkModel:
        """Section k's model with the wheelset shunts and heads of ``config`` under ``faults``
        (the section's own: a broken rail elsewhere is -1)."""
        key = (config, self.fault_key(k, faults))
        cache = self._models[k]
        if key in cache:
            cache.move_to_end(key)
            return cache[key]
        circuit = self.geometry.circuits[k]
        carrier = self.geometry.carriers[k]
        family_key = (k, faults)
        if family_key not in self._families:
            net = circuit.network(None, faults, self.settings.transformer_ratio, carrier, self.geometry.band_hz)
            self._families[family_key] = (ShuntFamily(net, self.g_shunt), net.node_index, net.feed_branches)
        family, node_index, feed_branches = self._families[family_key]
        shunts, heads = config
        system = family.state_space([node_index[f"n{node}"] for node in shunts])
        phi, gamma = discretise(system, self.dt)
        n = self.frame
        nx = phi.shape[0]
        segments = circuit.segments
        # output rows: the current arriving from the feed at each head (−segment current ahead of
        # its node; at the feed node, what the feed delivers: source − bond winding or zone), then the
        # entry-end current (−segment 0)
        rows = np.zeros((len(heads) + 1, nx))
        direct = np.zeros(len(heads) + 1)
        for h, node in enumerate(heads):
            if node < segments:
                rows[h, node] = -1.0
            elif not faults.feed_open:
                g_feed, feed = 1.0 / circuit.params.feed_r_ohm, node_index[f"n{segments}"]
                rows[h] = -g_feed * system.node_from_state[feed]
                rows[h, feed_branches] -= 1.0                # the feed bond winding's (or zone's) branches
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
        rotation = np.exp(2j * np.pi * carrier * self.dt)
        response = np.linalg.solve(rotation * np.eye(nx) - phi, gamma[:, 0].astype(complex))
        row_responses = rows @ response + direct
        rotated = response * rotation
        carrier_system = np.concatenate([np.stack([response.real, -response.imag], 1),
                                         np.stack([rotated.real, -rotated.imag], 1)])
        model = NetworkModel(np.linalg.matrix_power(phi, n), psi,
                             np.ascontiguousarray(out_o[:, :-1].transpose(1, 0, 2)),
                             np.ascontiguousarray(out_t[:, :-1].transpose(1, 0, 2)),
                             np.ascontiguousarray(out_o[:, -1]), np.ascontiguousarray(out_t[:, -1]),
                             phi, response, row_responses[:-1], complex(row_responses[-1]), carrier_system)
        cache[key] = model
        if len(cache) > self._cache_size[k]:
            cache.popitem(last=False)
        return model

    def fault_key(self, k: int, faults: Faults) -> tuple:
        """What of section k's faults its network depends on, relative to the section (its
        ballast, the segment a broken rail opens, an open feed), so sections of one design
        share models under the same faults (TrackCircuit.network)."""
        circuit, broken = self.geometry.circuits[k], -1
        if faults.broken_rail_m >= 0:
            nodes = circuit.nodes_m
            broken = next((i for i in range(circuit.segments) if nodes[i] <= faults.broken_rail_m < nodes[i + 1]), -1)
        return circuit.ballast(faults), broken, faults.feed_open

    def padded(self, model: NetworkModel) -> tuple:
        """The model's matrices on a section's padded [states | frame input] row: the step
        [Φᴺ | Ψ] (size, size + N), the currents at the heads (H, N, size + N) and at the entry
        end (N, size + N); a state the model lacks has zero columns and a zero row."""
        size, nx = self.size, model.phi_n.shape[0]
        step = np.zeros((size, size + self.frame))
        step[:nx, :nx], step[:nx, size:] = model.phi_n, model.psi
        ahead = np.zeros((model.ahead_o.shape[0], self.frame, size + self.frame))
        ahead[..., :nx], ahead[..., size:] = model.ahead_o, model.ahead_t
        entry = np.zeros((self.frame, size + self.frame))
        entry[:, :nx], entry[:, size:] = model.entry_o, model.entry_t
        return step, ahead, entry

    def one_shunt_table(self, k: int, faults: Faults) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """For ONE wheelset shunt at each node of section k under ``faults`` (unit feed, phasor
        at the carrier): |shunt current|, its log, and |relay-end voltage|; the last relay entry
        is the circuit without a shunt. The shape of the amplitude between nodes
        (TrackCircuitBank.scale) and the ALS-mode regime (one normative shunt) use it."""
        key = (k, faults)
        if key not in self._phasors:
            circuit, g_sh, carrier = self.geometry.circuits[k], self.g_shunt, self.geometry.carriers[k]
            net = circuit.network(None, faults, 1.0, carrier)
            nodes = [net.node_index[f"n{node}"] for node in range(circuit.segments + 1)]
            at_node, at_relay, free_relay = net.phasor_with_shunt(2 * np.pi * carrier, [1.0], g_sh,
                                                                  net.node_index["n0"])
            amplitude = np.maximum(np.abs(at_node[nodes]) * g_sh, 1e-12)
            relay = np.append(np.abs(at_relay[nodes]), abs(free_relay))    # last: no shunt
            self._phasors[key] = (amplitude, np.log(amplitude), relay)
        return self._phasors[key]
