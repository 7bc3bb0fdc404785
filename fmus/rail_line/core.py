"""Rail line plant: K coded track circuits, M trains, receiver coil EMF, traction interference,
track relays (no FMI here; docs/rail_line.md).

The core composes three parts, each with one job:

* circuit_bank.py — the track-circuit bank: a network model per section for its trains'
  wheelset shunts, the network states frame by frame, the track relays (occupancy), composed
  of geometry.py, calibration.py, network_models.py, parking.py and relays.py;
* coil_pickup.py — the coil pickup: the code current the coils see → coil EMF per train;
* traction_interference.py — the traction interference under the coils: the traction return
  current (lagged, with DC ripple or AC harmonics) times a coupling along the line, the rails'
  asymmetry per section passing from one section's to the next across each joint's bond-lead
  zone (or TVM separation zone), plus the bond leads' and jumper's trapezoid around each joint (with the coil pair's
  mismatch).

What stays here is the trains' motion: a new position update starts x(t) = x_k + v_k·(t − t_k),
and the gap between where the train was (and how fast it went) and where the update puts it
closes along a cubic over ``POSITION_BLEND_S`` (docs/rail_line.md, connecting a train): the coils'
position and speed never jump, not even when an extrapolated position is corrected at a slow step. It is sampled for the shunts every 10 ms of
simulated time and for the coils at every sample, whatever the frame length, so frames of any
length give the same result.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import List, Optional, Tuple

import numpy as np

from fmus.data.loader import DEFAULT_ROLLING_STOCK, Line, load_rolling_stock
from fmus.errors import FmuInputError
from fmus.rail_line.circuit_bank import TrackCircuitBank
from fmus.rail_line.coil_pickup import CoilPickup
from fmus.rail_line.track_circuit import CircuitParameters
from fmus.rail_line.traction_interference import TractionInterference
from fmus.sizes import DEFAULT_SAMPLE_RATE_HZ

CONFIG_TICK_S = 0.01
POSITION_BLEND_S = 0.25     # a position update's correction is spread over this time
POSITION_JUMP_M = 5.0       # a correction larger than this is a jump (a train placed), not blended
SPEED_JUMP_MPS = 2.0        # likewise for the speed (a train set going)
# the highest carrier per sample rate: the network's zero-order hold and the coil's backward
# difference lose 2 sin(πf/fs)/(2πf/fs) of the carrier's level, ≤ 10 % at fs/4
# (docs/rail_line.md#tvm-430-track-circuits, sample rate)
MAX_CARRIER_SHARE_OF_FS = 0.25


@dataclass
class RailSettings:
    fs_hz: float = DEFAULT_SAMPLE_RATE_HZ
    circuit: CircuitParameters = field(default_factory=CircuitParameters)
    transformer_ratio: float = 2.5        # u_tx → rails: 1.4 A rms at the entry of a 2.6 km section at 1 Ω·km
    coil_offset_m: float = 1.5            # ahead of the first wheelset [S docs/sources.md#code-current-and-receiver-coils]
    coil_gain_h: float = 4.5e-4           # EMF = M·di/dt: 0.28 V at 2 A peak, 50 Hz (the joints paper's weak level, docs/sources.md#interference-at-insulated-joints)
    coil_length_m: float = 0.3            # sensitivity length of the coil core [U]
    train_length_m: Tuple[float, ...] = (400.0, 400.0)
    # per train its wheelsets' distances behind the first one (m, ascending, 0 first: the
    # rolling-stock file's wheelset_offsets_m); empty: default_wheelsets of each train's length
    wheelset_offsets_m: Tuple[np.ndarray, ...] = ()
    asymmetry_range: Tuple[float, float] = (0.01, 0.05)
    coil_mismatch: float = 0.0            # the two coils' sensitivity difference / their mean (0: matched)
    seed: int = 1
    dc_ripple: Tuple[float, float] = (0.02, 0.01)       # 300 Hz, 600 Hz shares of the DC traction current [U]
    dc_even_harmonics: Tuple[float, float] = (0.005, 0.005)   # 100 Hz, 200 Hz shares (supply unbalance) [U]
    ac_harmonics: Tuple[float, float, float] = (0.10, 0.05, 0.025)    # 150, 250, 350 Hz shares on AC lines [U]
    traction_time_constant_s: float = 0.1               # traction circuit lag seen in the rails [U]
    relay_pick_up: float = 0.8            # share of the circuit's calibrated reference (docs/rail_line.md): the
    relay_drop_out: float = 0.5           # free circuit at minimum ballast and supply reads exactly relay_pick_up
    supply_tolerance: float = 0.1         # ± share of the nominal feed the calibration covers [U]
    shunt_margin: float = 0.02            # drop-out ≥ (1 + margin) × the worst shunt-mode level [U]
    relay_pick_up_delay_s: float = 1.0
    relay_drop_out_delay_s: float = 0.2
    carrier_hz: float = 0.0               # 0: each section's carrier from the line file (ALSN); else this
                                          # one (a digital system's 174.38 / 175 Hz) for the phasors
    tone_band_hz: Tuple[float, float] = (0.0, 0.0)   # a code of several tones (ALSU 125…375 Hz): the rails'
                                          # impedance follows the √f law across it; (0, 0): R and L at the carrier


@lru_cache(maxsize=1)
def _default_train_wheelsets() -> np.ndarray:
    return load_rolling_stock(DEFAULT_ROLLING_STOCK).wheelset_offsets_m


def default_wheelsets(length_m: float) -> np.ndarray:
    """The wheelsets of a train known only by its length: the bundled passenger train's
    (passenger_chs7.json), cut at that length or continued with its last coach's bogies every
    coach length."""
    offsets = _default_train_wheelsets()
    if length_m < offsets[-1]:
        return offsets[offsets <= length_m].copy()
    coach, period = offsets[-4:], offsets[-4] - offsets[-8]
    extra = [coach + period * n for n in range(1, int((length_m - offsets[-1]) // period) + 1)]
    return np.concatenate([offsets, *extra])


def _wheelsets_of(s: "RailSettings", trains: int) -> Tuple[np.ndarray, ...]:
    """Each train's wheelset offsets, checked against its length."""
    given = list(s.wheelset_offsets_m)
    if given and len(given) != trains:
        raise FmuInputError(f"wheelsets of {len(given)} trains given, {trains} expected")
    offsets = tuple(np.asarray(given[j], dtype=float) if given else default_wheelsets(s.train_length_m[j])
                    for j in range(trains))
    for j, (layout, length) in enumerate(zip(offsets, s.train_length_m)):
        if not (layout.size and layout[0] == 0.0 and np.all(np.diff(layout) >= 0.0)):
            raise FmuInputError(f"parameter rolling_stock_file[{j + 1}]: wheelsets must start at 0 m behind "
                                f"the first and go back from there")
        if layout[-1] > length + 1e-6:
            raise FmuInputError(f"parameter rolling_stock_file[{j + 1}]: its wheelsets reach {layout[-1]:g} m "
                                f"behind the first, beyond train_length[{j + 1}] = {length:g} m")
    return offsets


@dataclass
class RailOutputs:
    e_coil: np.ndarray
    occupied: np.ndarray
    i_axle: np.ndarray
    off_line: np.ndarray
    coil_section: np.ndarray      # (M,) 1-based section under each train's coil at the frame end, 0 none


class RailLineCore:
    def __init__(self, line: Line, sections: int, trains: int, frame: int, settings: RailSettings):
        s = settings
        if len(line.sections) > sections:
            raise FmuInputError(f"{line.path}: field block_sections: {len(line.sections)} sections, but this "
                                f"build models {sections}; rebuild with `railcosim build --sections {len(line.sections)}`")
        c = s.circuit
        for name, value in (("fs", s.fs_hz), ("transformer_ratio", s.transformer_ratio), ("coil_gain", s.coil_gain_h),
                            ("coil_length", s.coil_length_m), ("rail_r", c.rail_r_ohm_per_km), ("rail_l", c.rail_l_h_per_km),
                            ("feed_r", c.feed_r_ohm), ("relay_r", c.relay_r_ohm),
                            ("bond_l", c.bond_l_h), ("shunt_r", c.shunt_r_ohm), ("segment", c.segment_m),
                            ("traction_time_constant", s.traction_time_constant_s)):
            if not value > 0:
                raise FmuInputError(f"parameter {name}: must be positive, got {value}")
        if c.ballast_ohm_km < 0:
            raise FmuInputError(f"parameter ballast: {c.ballast_ohm_km:g} (0: each section's from the line file)")
        if not 0 <= s.supply_tolerance < 0.5:
            raise FmuInputError(f"parameter supply_tolerance: {s.supply_tolerance:g} (need 0 ≤ tolerance < 0.5)")
        if not s.shunt_margin >= 0:
            raise FmuInputError(f"parameter shunt_margin: {s.shunt_margin:g} (need ≥ 0)")
        if s.carrier_hz < 0 or s.carrier_hz > s.fs_hz * MAX_CARRIER_SHARE_OF_FS:
            raise FmuInputError(f"parameter carrier: {s.carrier_hz:g} Hz (0: the line file's; else up to fs/4)")
        for k, section in enumerate(line.sections):
            if section.carrier_hz > s.fs_hz * MAX_CARRIER_SHARE_OF_FS:
                raise FmuInputError(f"{line.path}: field block_sections[{k}].carrier_hz: {section.carrier_hz:g} Hz "
                                    f"needs fs ≥ {4 * section.carrier_hz:g} Hz (carriers up to fs/4), "
                                    f"parameter fs is {s.fs_hz:g} Hz")
        low, high = s.tone_band_hz
        if (low or high) and not 0 < low < high <= s.fs_hz / 4:
            raise FmuInputError(f"parameter tone_band_max: the tone band {low:g}…{high:g} Hz needs "
                                f"0 < tone_band_min < tone_band_max ≤ fs/4")
        if not 0 < s.relay_drop_out < s.relay_pick_up <= 1.0:
            raise FmuInputError("parameter relay_drop_out: must be positive and below relay_pick_up (≤ 1)")
        if len(s.train_length_m) != trains or min(s.train_length_m) <= 0:
            raise FmuInputError(f"parameter train_length: {trains} positive lengths expected")
        if not 0 <= s.coil_mismatch < 1:
            raise FmuInputError(f"parameter coil_mismatch: {s.coil_mismatch:g} (need 0 ≤ mismatch < 1)")
        lo, hi = s.asymmetry_range
        if not 0 <= lo <= hi < 1:
            raise FmuInputError("parameter asymmetry_min/asymmetry_max: need 0 ≤ min ≤ max < 1")
        s = replace(s, wheelset_offsets_m=_wheelsets_of(s, trains))
        self.line, self.settings = line, s
        self.count, self.sections, self.trains, self.frame = len(line.sections), sections, trains, frame
        self.dt = 1.0 / s.fs_hz
        self.bank = TrackCircuitBank(line, s, trains, frame, CONFIG_TICK_S)
        self.interference = TractionInterference(line, s, trains, frame, self.bank.geometry)
        self.pickup = CoilPickup(line.length_m, s, trains, self.bank, self.interference)
        self._index_f = np.arange(frame, dtype=float)
        self._times = np.empty(frame)
        self._blend_tau, self._blend_term = np.empty((2, frame))        # scratch of the position blend
        # (x_k, v_k, t_k, gap_k, speed_gap_k, c2, c3): head_at; c2, c3 the blend's τ², τ³ coefficients
        self._anchors: List[Optional[Tuple[float, ...]]] = [None] * trains
        self._heads = np.zeros((trains, frame))
        # per train: its position when it stands over the whole frame (every sample of its
        # row in _heads is that value), else None
        self.standing_at: List[Optional[float]] = [None] * trains
        self.out = RailOutputs(np.zeros((trains, frame)), np.zeros(sections, dtype=bool),
                               np.zeros(trains), np.zeros(trains, dtype=bool), np.zeros(trains, dtype=np.int64))
        self._occupancy_of: Optional[np.ndarray] = None     # the relay states ``out.occupied`` shows

    def bind_outputs(self, out: RailOutputs) -> None:
        """Write every frame's outputs into ``out``'s arrays (a host's port buffers, of the
        shapes ``self.out`` has) instead of the core's own: no copy per frame."""
        for name in ("e_coil", "occupied", "i_axle", "off_line", "coil_section"):
            mine, theirs = getattr(self.out, name), getattr(out, name)
            if theirs.shape != mine.shape:
                raise ValueError(f"bind_outputs: {name} has shape {theirs.shape}, the core's {mine.shape}")
            theirs[...] = mine
        self.out = out

    @property
    def circuits(self):
        return self.bank.geometry.circuits

    @property
    def asymmetry(self) -> np.ndarray:
        """Traction-current asymmetry per section (a study may overwrite it in place)."""
        return self.interference.asymmetry

    def set_faults(self, broken_rail_m: float, ballast_override: np.ndarray, feed_open: np.ndarray) -> None:
        self.bank.set_faults(broken_rail_m, ballast_override, feed_open)

    def step(self, t: float, u_tx: np.ndarray, x_head: np.ndarray, v: np.ndarray, i_traction: np.ndarray) -> RailOutputs:
        n = u_tx.shape[1] if u_tx.ndim == 2 else self.frame
        first = round(t * self.settings.fs_hz)
        times = self._times[:n]
        if n == 1:
            times[0] = first * self.dt                  # (0 + first)·dt, as below
        else:
            np.add(self._index_f[:n], first, out=times)
            times *= self.dt
        tick = math.floor(t / CONFIG_TICK_S + 1e-9) * CONFIG_TICK_S
        at_tick = []
        heads = self._heads
        positions, speeds = x_head.tolist(), v.tolist()
        for j in range(self.trains):
            self._update_anchor(j, t, positions[j], speeds[j])
            at_tick.append(self.head_at_time(j, tick))
            self._head_into(j, times, heads[j, :n])
        self.interference.new_frame(i_traction, n)
        self.bank.follow_shunts(at_tick, tick)        # every wheelset of every train shunts its section
        currents = self.bank.advance(u_tx[:self.count], n)
        out = self.out
        self.pickup.sense(first, times, heads[:, :n], currents, out, self.standing_at)
        relays = self.bank.relays
        if relays.up is not self._occupancy_of:      # a new array when a relay moves
            self._occupancy_of = relays.up
            out.occupied[:self.count] = ~self._occupancy_of
        return out

    def start(self, x_head: np.ndarray) -> RailOutputs:
        """The state at t = 0 from the trains' initial head positions: a train placed overlapping
        another is refused; the relays stand as the trains leave them (no delays), so
        ``occupied`` holds before the first step."""
        length = self.line.length_m
        spans = [(float(x_head[j]) - self.settings.train_length_m[j], float(x_head[j])) for j in range(self.trains)]
        on_line = [j for j, (tail, head) in enumerate(spans) if head >= 0.0 and tail <= length]
        for a in on_line:
            for b in on_line:
                if a < b and spans[a][0] < spans[b][1] and spans[b][0] < spans[a][1]:
                    raise FmuInputError(
                        f"input x_head[{b + 1}]: train {b + 1} (head {spans[b][1]:g} m, length "
                        f"{spans[b][1] - spans[b][0]:g} m) overlaps train {a + 1} (head {spans[a][1]:g} m, length "
                        f"{spans[a][1] - spans[a][0]:g} m) at initialisation")
        self.bank.start([float(x) for x in x_head[:self.trains]])
        self._occupancy_of = self.bank.relays.up
        self.out.occupied[:self.count] = ~self._occupancy_of
        return self.out

    def _update_anchor(self, j: int, t: float, x: float, v: float) -> None:
        """A new position update starts x(t) = x_k + v_k·(t − t_k); the gaps between the position
        and speed the previous update gives at t_k and (x_k, v_k) close along a cubic Hermite
        over POSITION_BLEND_S, so the head (and the coils) move with a continuous position and
        speed when an extrapolated input is corrected (a slow step of the traction unit). A gap
        above POSITION_JUMP_M or SPEED_JUMP_MPS is taken as it is (a train placed or set going)."""
        anchor = self._anchors[j]
        if anchor is not None and x == anchor[0] and v == anchor[1]:
            return
        gap = speed_gap = 0.0
        if anchor is not None:
            gap = self.head_at_time(j, t) - x
            speed_gap = self._speed_at_time(j, t) - v
            if abs(gap) > POSITION_JUMP_M or abs(speed_gap) > SPEED_JUMP_MPS \
                    or (abs(gap) < 1e-6 and abs(speed_gap) < 1e-6):      # a jump, or nothing to close
                gap = speed_gap = 0.0
        # gap·(2s³ − 3s² + 1) + speed_gap·B·(s³ − 2s² + s) with s = τ/B, as a polynomial in τ:
        # gap + speed_gap·τ + c2·τ² + c3·τ³
        blend = POSITION_BLEND_S
        c2 = -(3.0 * gap / blend + 2.0 * speed_gap) / blend
        c3 = (2.0 * gap / blend + speed_gap) / (blend * blend)
        self._anchors[j] = (x, v, t, gap, speed_gap, c2, c3)

    def head_at(self, j: int, times: np.ndarray) -> np.ndarray:
        """Train j's first-wheelset position at ``times`` (after its latest update)."""
        return self._head_into(j, times, np.empty(times.shape))

    def _head_into(self, j: int, times: np.ndarray, head: np.ndarray) -> np.ndarray:
        """``head_at`` written into ``head``: in place, so a frame allocates nothing; one sample
        (a build with N = 1) in floats. Inside the blend and after it, the operations and their
        order are those of head_at_time, so the two agree bit for bit (a frame reaching over
        the blend's end continues the polynomial instead: the same values to rounding)."""
        x_k, v_k, t_k, gap, speed_gap, c2, c3 = self._anchors[j]
        if v_k == 0.0 and not (gap or speed_gap) and x_k != 0.0:
            # a train standing (or parked off the line): x_k + 0·(t − t_k) is x_k
            head.fill(x_k)
            self.standing_at[j] = x_k
            return head
        self.standing_at[j] = None
        if head.size == 1:
            head[0] = self.head_at_time(j, float(times[0]))
            return head
        tau = np.subtract(times, t_k, out=head)
        if not (gap or speed_gap) or times[0] - t_k >= POSITION_BLEND_S:
            head *= v_k
            head += x_k
            return head
        # the polynomial x_k + gap + (v_k + speed_gap)·τ + c2·τ² + c3·τ³ by Horner, at τ itself
        # when the frame lies inside the blend (every frame when the master updates the position
        # each frame), else at τ clipped to [0, B] and continued at v_k beyond (the blend is
        # flat at both ends: the gap and its slope at 0, nothing at B)
        inside = times[0] >= t_k and times[-1] - t_k <= POSITION_BLEND_S
        at = tau if inside else np.minimum(np.maximum(tau, 0.0, out=self._blend_tau[:head.size]),
                                           POSITION_BLEND_S, out=self._blend_tau[:head.size])
        term = np.multiply(at, c3, out=self._blend_term[:head.size])
        term += c2
        term *= at
        term += v_k + speed_gap
        term *= at
        if inside:
            return np.add(term, x_k + gap, out=head)
        term += x_k + gap
        tau -= at
        tau *= v_k
        head += term
        return head

    def head_at_time(self, j: int, t: float) -> float:
        """``head_at`` at one time, in floats."""
        x_k, v_k, t_k, gap, speed_gap, c2, c3 = self._anchors[j]
        tau = t - t_k
        if not (gap or speed_gap) or tau >= POSITION_BLEND_S:
            return x_k + v_k * tau
        if tau >= 0.0:
            return ((tau * c3 + c2) * tau + (v_k + speed_gap)) * tau + (x_k + gap)
        return (x_k + gap) + v_k * tau

    def _speed_at_time(self, j: int, t: float) -> float:
        """The head's speed at one time: the blend polynomial's derivative at τ clipped to [0, B]."""
        _, v_k, t_k, _, speed_gap, c2, c3 = self._anchors[j]
        tau = min(max(t - t_k, 0.0), POSITION_BLEND_S)
        return v_k + speed_gap + (2.0 * c2 + 3.0 * c3 * tau) * tau

    # ---- studies ------------------------------------------------------------------------------
    def minimum_code_current(self, k: int, ballast_ohm_km: float) -> float:
        """ALS mode: the smallest code current (A rms) under the first wheelset over all positions
        in section k, for the nominal code amplitude 4 V × transformer ratio."""
        return self.bank.minimum_code_current(k, ballast_ohm_km)
