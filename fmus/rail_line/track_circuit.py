"""One coded track circuit (block section) as a network of components (network.py).

Layout along the section, running direction left → right (docs/sources.md#track-circuits-and-rail-impedance: the code is fed
at the signal end ahead of the train, the track relay sits at the entry end):

    entry joint            relay end                                   feed end      exit joint
        |── relay leads (n0) ─[rail segment]─ n1 ─ … ─ n(S−1) ─[rail segment]─ nS ── dead end ──|
            relay R, bond                                              source, bond

* rail segments: series R–L of the rail loop (two rails) and half the ballast conductance at
  each end node (π sections of at most ``segment_m``);
* feed end at ``bond_lead_offset`` before the exit joint: the code source (u_tx × transformer
  ratio behind the feed resistance) and the impedance bond's signal winding (R–L to the other
  rail); the rails between the bond leads and the joint carry no signal current (docs/sources.md#interference-at-insulated-joints:
  ≈ 1 m null zone);
* relay end at the entry joint: the track relay (a resistance referred to the rails) and the
  bond winding;
* wheelsets: a 0.06 Ω conductance at each node a train covers (the network model,
  circuit_bank.py; axle_chain.py puts each at its axle for the amplitudes);
* faults: broken rail (the segment containing it opens), ballast override, bond disconnected
  or feed failed (no source at the feed end).

Also the uniform-line two-port (ABCD) solution used to validate the network (docs/sources.md#track-circuits-and-rail-impedance).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence, Tuple

import numpy as np

from fmus.rail_line.network import Conductance, Network, NortonSource, RLBranch, RLCBranch

OPEN_OHM = 1e9
# a UM71 circuit's equipment at the rails, in place of the feed_r and relay_r of the ALSN circuits:
# the transmitter behind its matching transformer (nearer a current source, so a wheelset on its
# zone does not take the whole level at maximum ballast) and the receiver's input [U]; with them
# a 1500 m circuit calibrates at 1–50 Ω·km at 1700 and 2300 Hz (docs/rail_line.md)
UM71_TRANSMITTER_R_OHM = 5.0
UM71_RECEIVER_R_OHM = 20.0


@dataclass(frozen=True)
class SeparationZone:
    """The tuned electrical separation zone at each end of an audio-frequency (TVM) track circuit
    without insulated joints (docs/rail_line.md, separation zones): two tuned units across the
    rails ``length_m`` apart, each a series L–C resonant at the OTHER side's carrier (a short for
    it); the rails between them and the far unit make the near one a parallel resonance at its
    own carrier (a high impedance: its transmitter's or receiver's level is not shorted). The
    unit of the higher carrier has a capacitor in parallel (a series L–C is inductive above its
    resonance and could not resonate with the zone's rails). Values are designed from the rails'
    impedance at the two carriers [U: our design, docs/sources.md#tvm-430-track-circuits]."""
    own_hz: float                     # the section's carrier
    other_hz: float                   # the carrier on the other side of the zone (the track's pair)
    length_m: float = 26.0            # between the two tuned units [U]
    unit_q: float = 30.0              # quality factor of the tuned units' inductors [U]
    capacitor_q: float = 200.0        # of the parallel capacitor [U]
    capacitor_lead_h: float = 1e-6    # the parallel capacitor's lead inductance [U]


def _tuned_units(zone: SeparationZone, params: "CircuitParameters"):
    """The zone's two tuned units as series branches (r Ω, l H, c F): (the lower carrier's unit,
    the higher carrier's unit) each a list of branches across the rails; lossless design, the
    losses added from the quality factors."""
    low, high = sorted((zone.own_hz, zone.other_hz))
    w_low, w_high = 2 * np.pi * low, 2 * np.pi * high
    km = zone.length_m / 1000.0
    l_rails_low = rail_impedance(params, low)[1] * km
    l_rails_high = rail_impedance(params, high)[1] * km
    # the lower unit: series resonance at the higher carrier, its capacitive reactance at the lower
    # one cancelling the zone's rails (the far unit shorts the lower carrier): ωL_u(ω_H²/ω² − 1) = ωL_z
    l_low = l_rails_low / ((w_high / w_low) ** 2 - 1.0)
    c_low = 1.0 / (w_high ** 2 * l_low)
    # the higher unit: the same inductor, series resonance at the lower carrier; in parallel a
    # capacitor whose susceptance at the higher carrier cancels the series branch's and the rails'
    l_high = l_low
    c_high = 1.0 / (w_low ** 2 * l_high)
    x_series = w_high * l_high - 1.0 / (w_high * c_high)
    susceptance = 1.0 / x_series + 1.0 / (w_high * l_rails_high)
    c_parallel = 1.0 / (w_high * (1.0 / susceptance + w_high * zone.capacitor_lead_h))
    lower = [(w_high * l_low / zone.unit_q, l_low, c_low)]
    higher = [(w_low * l_high / zone.unit_q, l_high, c_high),
              (1.0 / (w_high * c_parallel) / zone.capacitor_q, zone.capacitor_lead_h, c_parallel)]
    return (lower, higher) if zone.own_hz < zone.other_hz else (higher, lower)


def _series_impedance(branch, omega: float) -> complex:
    r, l, c = branch
    return complex(r, omega * l - 1.0 / (omega * c))


@dataclass(frozen=True)
class CircuitParameters:
    rail_r_ohm_per_km: float = 0.52        # rail loop at rail_reference_hz: the worked example
    rail_l_h_per_km: float = 1.18e-3       # (docs/sources.md#track-circuits-and-rail-impedance) [S]
    rail_reference_hz: float = 165.0       # the worked example's frequency, from its X and L [D]
    rail_internal_l_h_per_km: float = 0.177e-3   # the rails' internal inductance there [S]
    ballast_ohm_km: float = 0.0            # minimum (wet) ballast; 0: each section's from the line file (the
                                           # shipped lines: 1 Ω·km, the normative minimum [S])
    feed_r_ohm: float = 0.5                # track transformer + limiting resistor, at the rails [U]
    relay_r_ohm: float = 4.0               # relay end equipment at the rails [U]
    bond_r_ohm: float = 0.05               # impedance bond signal winding [U]
    bond_l_h: float = 0.02                 # (|Z| ≈ 6.3 Ω at 50 Hz) [U]
    shunt_r_ohm: float = 0.06              # normative train shunt [S]
    segment_m: float = 50.0
    zone: Optional[SeparationZone] = None  # a TVM circuit: both ends in tuned separation zones
                                           # (instead of the bonds); None: insulated joints


def near_unit_admittance(params: CircuitParameters, frequency_hz: float) -> complex:
    """The admittance of a UM71 circuit's own tuned unit at either end (the zone's near unit)."""
    omega = 2 * np.pi * frequency_hz
    return sum(1.0 / _series_impedance(b, omega) for b in _tuned_units(params.zone, params)[0])


def end_admittance(params: CircuitParameters, ballast_ohm_km: float, frequency_hz: float) -> complex:
    """What terminates either end of a circuit across the rails besides its relay or source, at
    ``frequency_hz``: the impedance bond's signal winding at an insulated joint, or the tuned
    separation zone (its near unit in parallel with the zone's rails leading to the far unit,
    which sits on the zone's ballast)."""
    omega = 2 * np.pi * frequency_hz
    zone = params.zone
    if zone is None:
        return 1.0 / complex(params.bond_r_ohm, omega * params.bond_l_h)
    near, far = _tuned_units(zone, params)
    r, l = rail_impedance(params, frequency_hz)
    km = zone.length_m / 1000.0
    far_admittance = km / ballast_ohm_km + sum(1.0 / _series_impedance(b, omega) for b in far)
    return (sum(1.0 / _series_impedance(b, omega) for b in near)
            + 1.0 / (complex(r * km, omega * l * km) + 1.0 / far_admittance))


@dataclass(frozen=True)
class Faults:
    ballast_ohm_km: float = 0.0            # 0: the circuit's own (minimum) ballast
    broken_rail_m: float = -1.0            # absolute position, < 0: none
    feed_open: bool = False                # bond disconnected or feed failed: no code source


def rail_impedance(params: CircuitParameters, frequency_hz: Optional[float]) -> tuple:
    """(R Ω/km, L H/km) of the rail loop at ``frequency_hz`` (None: the reference values).
    Skin effect in the steel rails (docs/rail_line.md, rail impedance per frequency): the
    internal impedance grows as √f with equal resistance and reactance, so
    R(f) = R₀ − X_int0 + X_int0·√(f/f₀) and L(f) = L₀ − L_int0 + L_int0·√(f₀/f), X_int0 = 2πf₀·L_int0;
    the rest of R₀ (bonds, joints) and of L₀ (the loop's external inductance) do not depend on f."""
    if frequency_hz is None or frequency_hz <= 0:
        return params.rail_r_ohm_per_km, params.rail_l_h_per_km
    ratio = np.sqrt(frequency_hz / params.rail_reference_hz)
    x_internal = 2 * np.pi * params.rail_reference_hz * params.rail_internal_l_h_per_km
    r = params.rail_r_ohm_per_km + x_internal * (ratio - 1.0)
    l = params.rail_l_h_per_km + params.rail_internal_l_h_per_km * (1.0 / ratio - 1.0)
    return float(r), float(l)


def skin_effect_ladder(params: CircuitParameters, band_hz: Tuple[float, float]) -> Tuple[float, float, float, float]:
    """A network whose impedance follows rail_impedance's √f law across ``band_hz`` at every
    frequency at once, for a code of several tones (ALSU): per km, a series R–L and one parallel
    R‖L, (r_series Ω, l_series H, r_parallel Ω, l_parallel H). The law is
    Z(f) = R₀ − X_int0 + jωL_ext + (1 + j)·X_int0·√(f/f₀) (the internal part ∝ √(jω), a
    fractional order no finite network has); the R‖L with its corner at the band's geometric
    centre and the series R–L are fitted to it by non-negative least squares (passive parts),
    relative error weighted, over the band widened by 10 % each side: within 0.4 % of the
    law's whole impedance at the six ALSU tones, 0.8 % over 110–400 Hz (tests/test_alsu.py)."""
    from scipy.optimize import nnls

    low, high = band_hz
    f0, l_int0 = params.rail_reference_hz, params.rail_internal_l_h_per_km
    x_int0 = 2 * np.pi * f0 * l_int0
    f = np.geomspace(0.9 * low, 1.1 * high, 64)
    w = 2 * np.pi * f
    internal = (1 + 1j) * x_int0 * np.sqrt(f / f0)
    corner = 2 * np.pi * np.sqrt(low * high)
    columns = np.array([np.ones_like(w) + 0j, 1j * w, (1j * w / corner) / (1 + 1j * w / corner)]).T
    weight = 1.0 / np.abs(internal)
    matrix = np.vstack([(columns * weight[:, None]).real, (columns * weight[:, None]).imag])
    (r_extra, l_extra, r_parallel), _ = nnls(matrix, np.concatenate([(internal * weight).real, (internal * weight).imag]))
    r_series = params.rail_r_ohm_per_km - x_int0 + r_extra
    l_series = params.rail_l_h_per_km - l_int0 + l_extra
    return float(r_series), float(l_series), float(r_parallel), float(r_parallel / corner)


def two_port(z_per_km: complex, y_per_km: complex, length_km: float) -> np.ndarray:
    """ABCD matrix of a uniform line: [[cosh γl, Zc sinh γl], [sinh γl / Zc, cosh γl]]."""
    gamma = np.sqrt(z_per_km * y_per_km)
    zc = np.sqrt(z_per_km / y_per_km)
    return np.array([[np.cosh(gamma * length_km), zc * np.sinh(gamma * length_km)],
                     [np.sinh(gamma * length_km) / zc, np.cosh(gamma * length_km)]])


class TrackCircuit:
    def __init__(self, start_m: float, end_m: float, lead_offset_m: float, params: CircuitParameters):
        self.start_m, self.end_m = start_m, end_m
        self.feed_m = end_m - lead_offset_m
        self.params = params
        count = max(int(np.ceil((self.feed_m - start_m) / params.segment_m)), 1)
        self.nodes_m = np.linspace(start_m, self.feed_m, count + 1)
        self.segments = count

    def ballast(self, faults: Faults) -> float:
        return faults.ballast_ohm_km if faults.ballast_ohm_km > 0 else self.params.ballast_ohm_km

    def network(self, shunt_node: Optional[int], faults: Faults = Faults(), transformer_ratio: float = 1.0,
                frequency_hz: Optional[float] = None, band_hz: Optional[Tuple[float, float]] = None) -> Network:
        """Input 0 is the code voltage u_tx (× the transformer ratio at the rails); the rails'
        R and L at ``frequency_hz`` (rail_impedance), or, with ``band_hz`` (low, high), the
        √f law across that band (skin_effect_ladder: each segment's R–L in series with an R‖L
        behind an inner node ``m<k>``; the R‖L branches come after every other branch, so
        branch k is still segment k's current, and the bonds' follow the segments')."""
        p = self.params
        ladder = skin_effect_ladder(p, band_hz) if band_hz else None
        rail_r, rail_l = (ladder[0], ladder[1]) if ladder else rail_impedance(p, frequency_hz)
        net = Network(inputs=1)
        length_km = (self.feed_m - self.start_m) / 1000.0 / self.segments
        g_half = 0.5 * length_km / self.ballast(faults)
        for k in range(self.segments):
            a, b = f"n{k}", f"n{k + 1}"
            r = rail_r * length_km
            if 0 <= faults.broken_rail_m and self.nodes_m[k] <= faults.broken_rail_m < self.nodes_m[k + 1]:
                r = OPEN_OHM
            net.add(RLBranch(a, f"m{k}" if ladder else b, r, rail_l * length_km),
                    Conductance(a, "0", g_half), Conductance(b, "0", g_half))
            if ladder:
                net.add(Conductance(f"m{k}", b, 1.0 / (ladder[2] * length_km)))
        feed, relay = f"n{self.segments}", "n0"
        first = len(net.branches)
        self._terminate(net, relay, "relay_zone", faults, frequency_hz, rail_r, rail_l)
        net.add(Conductance(relay, "0", 1.0 / p.relay_r_ohm))
        # the branches leaving the feed node other than the rails (the feed's current into the rails
        # is the source's less theirs: network_models.py)
        before_feed = len(net.branches)
        self._terminate(net, feed, "feed_zone", faults, frequency_hz, rail_r, rail_l)
        net.feed_branches = [k for k in range(before_feed, len(net.branches)) if net.branches[k][0] == net.node(feed)]
        net.end_branches = list(range(first, len(net.branches)))
        if not faults.feed_open:
            net.add(NortonSource(feed, "0", 1.0 / p.feed_r_ohm, 0, transformer_ratio))
        else:
            net.add(Conductance(feed, "0", 1.0 / OPEN_OHM))
        if shunt_node is not None:
            net.add(Conductance(f"n{shunt_node}", "0", 1.0 / p.shunt_r_ohm))
        if ladder:
            for k in range(self.segments):
                net.add(RLBranch(f"m{k}", f"n{k + 1}", 0.0, ladder[3] * length_km))
        return net

    def _terminate(self, net: Network, node: str, name: str, faults: Faults, frequency_hz: Optional[float],
                   rail_r: float, rail_l: float) -> None:
        """The end network across the rails at ``node`` (end_admittance, as branches): the bond
        winding, or the separation zone: the near tuned unit, the zone's rails (the section's
        rail R and L) to an inner node on the zone's ballast, the far tuned unit there."""
        p = self.params
        if p.zone is None:
            net.add(RLBranch(node, "0", p.bond_r_ohm, p.bond_l_h))
            return
        near, far = _tuned_units(p.zone, p)
        km = p.zone.length_m / 1000.0
        inner = f"{name}_far"
        net.add(*(RLCBranch(node, "0", r, l, c) for r, l, c in near))
        net.add(RLBranch(node, inner, rail_r * km, rail_l * km), Conductance(inner, "0", km / self.ballast(faults)))
        net.add(*(RLCBranch(inner, "0", r, l, c) for r, l, c in far))


def cascade_shunt_current(circuit: TrackCircuit, x_m: float, train_length_m: float = 0.0,
                          carrier_hz: float = 50.0, wheelsets_m: Optional[Sequence[float]] = None) -> float:
    """The code current (amplitude per volt of source) reaching a standing train's first axle,
    by a cascade of two-ports, the sourced worked example's method (docs/rail_line.md#validation):
    source ‖ bond at the feed, the line to the first axle, the train's wheelsets each behind the
    line to the previous, down to the relay end (relay ‖ bond). The wheelsets: at ``wheelsets_m``
    (distances behind the first axle, the rolling-stock file's) where given, else the lumped
    train of the network model: one at the first axle and one at every network node it covers
    (its tail snapped to the nearest node). Independent of the rail line's solutions: the
    reference they are checked against."""
    params = circuit.params
    w = 2.0 * np.pi * carrier_hz
    rail_r, rail_l = rail_impedance(params, carrier_hz)
    z, y = rail_r + 1j * w * rail_l, 1.0 / params.ballast_ohm_km
    z_bond = params.bond_r_ohm + 1j * w * params.bond_l_h

    def through(length_m, z_end):
        abcd = two_port(z, y, length_m / 1000.0)
        return (abcd[0, 0] * z_end + abcd[0, 1]) / (abcd[1, 0] * z_end + abcd[1, 1])
    if wheelsets_m is None:
        spacing = circuit.nodes_m[1] - circuit.nodes_m[0]
        head_node = round((x_m - circuit.start_m) / spacing)
        tail_node = round((max(x_m - train_length_m, circuit.start_m) - circuit.start_m) / spacing)
        axles = [circuit.nodes_m[i] for i in range(tail_node, head_node)] + [x_m]
    else:
        axles = sorted(x_m - float(offset) for offset in wheelsets_m if x_m - float(offset) >= circuit.start_m)
    z_load, previous = 1.0 / (1.0 / params.relay_r_ohm + 1.0 / z_bond), circuit.start_m
    for position in axles:
        z_load = 1.0 / (1.0 / params.shunt_r_ohm + 1.0 / through(position - previous, z_load))
        previous = position
    ahead = two_port(z, y, (circuit.feed_m - x_m) / 1000.0)
    z_in = (ahead[0, 0] * z_load + ahead[0, 1]) / (ahead[1, 0] * z_load + ahead[1, 1])
    z_feed = 1.0 / (1.0 / z_in + 1.0 / z_bond)
    v_feed = z_feed / (params.feed_r_ohm + z_feed)
    return float(abs(v_feed / (ahead[0, 0] + ahead[0, 1] / z_load) / z_load))
