"""Electrical networks from components with pins, Modelica-style, solved by modified nodal
analysis (no FMI, no track-circuit knowledge here).

A network is nodes plus components; each component class stamps itself into the nodal
matrices. Three kinds cover the track circuit (a new component is one small class):

* ``Conductance(a, b, g)`` — resistor, ballast leakage, wheelset shunt, relay;
* ``RLBranch(a, b, r, l)`` — series R–L (rail segment, impedance-bond winding); its current
  a → b is a state;
* ``NortonSource(a, b, g, input, gain)`` — a voltage gain·u[input] behind an internal
  resistance 1/g;
* ``RLCBranch(a, b, r, l, c)`` — series R–L–C (a tuned unit of a separation zone, a capacitor
  with its lead inductance); its current a → b and its capacitor's voltage are states.

With node voltages v, branch currents i, the series capacitors' voltages w and inputs u:

    KCL:       G·v + Q·i = P·u            (Q[a,k] = +1, Q[b,k] = −1: branch k leaves a)
    branches:  L·di/dt = Qᵀ·v − R·i − S·w (S[k,c] = 1: capacitor c sits in branch k)
    capacitors: C·dw/dt = Sᵀ·i

so the node voltages are algebraic (there is a conductance to ground at every node) and, with
the states x = [i; w],

    dx/dt = A·x + B·u,  A = [[−L⁻¹(Qᵀ G⁻¹ Q + R), −L⁻¹S], [C⁻¹Sᵀ, 0]],  B = [[L⁻¹ Qᵀ G⁻¹ P], [0]],
    v = G⁻¹(P·u − Q·i).

The capacitors' voltages come after every branch current, so state k is still branch k's current.

``phasor_with_shunt`` solves the same equations at one frequency; ``discretise`` gives the exact
zero-order-hold model at the sample rate (scipy.linalg.expm of the augmented matrix).
Ground is the node named ``"0"``.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Dict, List, Sequence, Tuple

import numpy as np
from scipy.linalg import expm

GROUND = "0"


@dataclass(frozen=True)
class Conductance:
    a: str
    b: str
    g: float

    def stamp(self, net: "Network") -> None:
        net._conductance(self.a, self.b, self.g)


@dataclass(frozen=True)
class RLBranch:
    a: str
    b: str
    r: float
    l: float

    def stamp(self, net: "Network") -> None:
        net._branch(self.a, self.b, self.r, self.l)


@dataclass(frozen=True)
class RLCBranch:
    """Series R–L–C from a to b (C in farads > 0); a capacitor alone is given its lead
    inductance, since every branch's current is a state."""
    a: str
    b: str
    r: float
    l: float
    c: float

    def stamp(self, net: "Network") -> None:
        net._branch(self.a, self.b, self.r, self.l, self.c)


@dataclass(frozen=True)
class NortonSource:
    """Voltage gain·u[input] behind the internal resistance 1/g."""
    a: str
    b: str
    g: float
    input: int
    gain: float = 1.0

    def stamp(self, net: "Network") -> None:
        net._conductance(self.a, self.b, self.g)
        net._injection(self.a, self.b, self.g * self.gain, self.input)


@dataclass
class StateSpace:
    a: np.ndarray
    b: np.ndarray
    node_from_state: np.ndarray      # v = node_from_state @ x + node_from_input @ u (x = [i; w])
    node_from_input: np.ndarray


class Network:
    def __init__(self, inputs: int = 1):
        self.inputs = inputs
        self.node_index: Dict[str, int] = {}
        self._g: List[Tuple[int, int, float]] = []
        self._p: List[Tuple[int, int, float]] = []
        self.branches: List[Tuple[int, int, float, float, float]] = []   # (a, b, r, l, c; c = 0: none)

    def node(self, name: str) -> int:
        if name == GROUND:
            return -1
        return self.node_index.setdefault(name, len(self.node_index))

    def add(self, *components) -> "Network":
        for component in components:
            component.stamp(self)
        return self

    def _conductance(self, a: str, b: str, g: float) -> None:
        ia, ib = self.node(a), self.node(b)
        for i, j, value in ((ia, ia, g), (ib, ib, g), (ia, ib, -g), (ib, ia, -g)):
            if i >= 0 and j >= 0:
                self._g.append((i, j, value))

    def _injection(self, a: str, b: str, g: float, input_index: int) -> None:
        ia, ib = self.node(a), self.node(b)
        if ia >= 0:
            self._p.append((ia, input_index, g))
        if ib >= 0:
            self._p.append((ib, input_index, -g))

    def _branch(self, a: str, b: str, r: float, l: float, c: float = 0.0) -> None:
        self.branches.append((self.node(a), self.node(b), r, l, c))

    # ---- matrices -----------------------------------------------------------------------------
    def matrices(self):
        n, m = len(self.node_index), len(self.branches)
        g = np.zeros((n, n))
        for i, j, value in self._g:
            g[i, j] += value
        p = np.zeros((n, self.inputs))
        for i, k, value in self._p:
            p[i, k] += value
        q = np.zeros((n, m))
        for k, (a, b, *_) in enumerate(self.branches):
            if a >= 0:
                q[a, k] = 1.0
            if b >= 0:
                q[b, k] = -1.0
        r = np.array([b[2] for b in self.branches])
        l = np.array([b[3] for b in self.branches])
        c = np.array([b[4] for b in self.branches])
        return g, p, q, r, l, c

    def _admittance(self, omega: float):
        """(nodal admittance matrix Y at ω, injection P·u matrix P, Q, branch impedances z)."""
        g, p, q, r, l, c = self.matrices()
        z = r + 1j * omega * l
        with np.errstate(divide="ignore"):
            z = z + np.where(c > 0, 1.0 / (1j * omega * np.where(c > 0, c, 1.0)), 0.0)
        return g + (q / z) @ q.T, p, q, z

    def phasor_with_shunt(self, omega: float, u: np.ndarray, g: float, observe: int):
        """Node voltages when a conductance ``g`` to ground is added at one node, for every node
        in turn: (v_i with the shunt at node i, v_observe with the shunt at node i) as two
        arrays over i, and v_observe without any shunt. One inverse of the nodal admittance
        matrix and a rank-one (Sherman–Morrison) update per node, instead of a solve per node."""
        y, p, _, _ = self._admittance(omega)
        impedance = np.linalg.inv(y)                              # Z = Y⁻¹
        free = impedance @ (p @ np.asarray(u, dtype=complex))     # v without a shunt
        at_node = free / (1.0 + g * np.diagonal(impedance))
        at_observe = free[observe] - g * impedance[observe] * at_node
        return at_node, at_observe, free[observe]

    def state_space(self) -> StateSpace:
        g, p, q, r, l, c = self.matrices()
        return _state_space(q, r, l, c, np.linalg.solve(g, q), np.linalg.solve(g, p))


def _state_space(q, r, l, c, g_inv_q, g_inv_p) -> StateSpace:
    """dx/dt = A·x + B·u and the node voltages, from G⁻¹Q and G⁻¹P (module docstring); x is the
    branch currents followed by the series capacitors' voltages (none: x = i, as before)."""
    a = -(q.T @ g_inv_q + np.diag(r)) / l[:, None]
    b = (q.T @ g_inv_p) / l[:, None]
    node_from_state = -g_inv_q
    with_c = np.flatnonzero(c > 0)
    if with_c.size:
        m, n = len(r), with_c.size
        select = np.zeros((m, n))
        select[with_c, np.arange(n)] = 1.0
        a = np.block([[a, -select / l[:, None]], [select.T / c[with_c][:, None], np.zeros((n, n))]])
        b = np.vstack([b, np.zeros((n, b.shape[1]))])
        node_from_state = np.hstack([node_from_state, np.zeros((node_from_state.shape[0], n))])
    return StateSpace(a, b, node_from_state, g_inv_p)


class ShuntFamily:
    """State-space models of one network with a conductance ``g`` to ground added at any set of
    nodes (the wheelsets of the trains in a section): the free network's G⁻¹ once, then a
    rank-s (Woodbury) update for s shunt nodes instead of assembling and solving a new network:
    (G + g·E·Eᵀ)⁻¹ = G⁻¹ − G⁻¹E·(I/g + EᵀG⁻¹E)⁻¹·EᵀG⁻¹, E the shunt nodes' unit columns."""

    def __init__(self, net: Network, g: float):
        self.g = g
        g_matrix, p, self.q, self.r, self.l, self.c = net.matrices()
        self.g_inv = np.linalg.inv(g_matrix)
        self.g_inv_q = self.g_inv @ self.q
        self.g_inv_p = self.g_inv @ p

    def state_space(self, nodes: Sequence[int] = ()) -> StateSpace:
        """The model with a shunt at each node index in ``nodes`` (empty or None: no shunt; an
        int: one shunt)."""
        g_inv_q, g_inv_p = self.g_inv_q, self.g_inv_p
        if nodes is not None and not isinstance(nodes, (list, tuple, np.ndarray)):
            nodes = (nodes,)
        if nodes is not None and len(nodes):
            idx = np.asarray(nodes, dtype=np.intp)
            core = np.eye(idx.size) / self.g + self.g_inv[np.ix_(idx, idx)]
            g_inv_q = g_inv_q - self.g_inv[:, idx] @ np.linalg.solve(core, g_inv_q[idx])
            g_inv_p = g_inv_p - self.g_inv[:, idx] @ np.linalg.solve(core, g_inv_p[idx])
        return _state_space(self.q, self.r, self.l, self.c, g_inv_q, g_inv_p)


class PhasorFamily:
    """The same network at one angular frequency: Z = Y⁻¹ and the free node voltages once, then
    node voltages with any set of shunts (Woodbury), without a new solve of the whole network."""

    def __init__(self, net: Network, omega: float, u: Sequence[float]):
        y, p, _, self.z_branch = net._admittance(omega)
        self.impedance = np.linalg.inv(y)
        self.free = self.impedance @ (p @ np.asarray(u, dtype=complex))

    def with_shunts(self, nodes: Sequence[int], g: float) -> np.ndarray:
        """Every node's voltage with a conductance ``g`` to ground at each node in ``nodes``
        (the free voltages when there is none)."""
        if not len(nodes):
            return self.free
        core = np.eye(len(nodes)) / g + self.impedance[np.ix_(nodes, nodes)]
        return self.free - self.impedance[:, nodes] @ np.linalg.solve(core, self.free[nodes])


def discretise(system: StateSpace, step_s: float):
    """Exact zero-order-hold discretisation: x[n+1] = Φ·x[n] + Γ·u[n]."""
    n, m = system.b.shape
    augmented = np.zeros((n + m, n + m))
    augmented[:n, :n] = system.a * step_s
    augmented[:n, n:] = system.b * step_s
    exp = expm(augmented)
    return exp[:n, :n], exp[:n, n:]
