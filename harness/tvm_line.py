"""TVM-430's rail line for benches and tests (docs/rail_line.md#tvm-430-track-circuits): the
high-speed line's rail line core at the TVM sample rate, and the coil EMF where the neighbour's
carrier leaks most through a separation zone, for a receiver test to decode.

The own carrier comes from the rail line core (the section's network, a train standing with its
first wheelset ``NEAREST_HEAD_BEFORE_ZONE_M`` before the zone at the section's exit, the
section's minimum ballast); the neighbour's is added at its current per volt there from
fmus/rail_line/separation_leak.py (the section ahead at the line's maximum ballast: the worst
case), through the same backward difference the rail line takes for the EMF. The neighbour's
current is its u_tx times a real gain: its phase, a constant delay of an FM carrier, is not
modelled, nor the zone's shaping of it across the word's band.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from fmus.data.loader import DATA, Line, load_line
from fmus.rail_line.core import RailLineCore, RailSettings, default_wheelsets
from fmus.rail_line.separation_leak import NEAREST_HEAD_BEFORE_ZONE_M, Leak, leak_at

HSL_LINE = DATA / "hsl_tvm430_line.json"
FS = 12000.0                 # the TVM chain's sample rate (docs/rail_line.md#tvm-430-track-circuits)
FRAME_S = 0.01
TRAIN_M = 200.0


def tvm_rail_line(line: Optional[Line] = None, trains: int = 1, fs_hz: float = FS, train_length_m: float = TRAIN_M,
                  wheelsets_m: Optional[Sequence[float]] = None) -> RailLineCore:
    """The rail line core on the high-speed line (or ``line``), 10 ms frames."""
    line = line or load_line(HSL_LINE)
    wheels = np.asarray(wheelsets_m if wheelsets_m is not None else default_wheelsets(train_length_m), dtype=float)
    settings = RailSettings(fs_hz=fs_hz, train_length_m=(train_length_m,) * trains, wheelset_offsets_m=(wheels,) * trains)
    return RailLineCore(line, len(line.sections), trains, int(round(fs_hz * FRAME_S)), settings)


@dataclass
class LeakEmf:
    emf: np.ndarray           # the coil EMF, V, per sample: the own carrier and the neighbour's leak
    own_emf: np.ndarray       # the own carrier's part alone
    leak: Leak                # the leak there (separation_leak.leak_at)
    section: int              # the own section (0-based) on the line
    head_m: float             # the train's first wheelset


def worst_leak_emf(u_own: np.ndarray, u_neighbour: np.ndarray, own_hz: float = 1700.0, fs_hz: float = FS,
                   line: Optional[Line] = None, train_length_m: float = TRAIN_M,
                   wheelsets_m: Optional[Sequence[float]] = None) -> LeakEmf:
    """The coil EMF of a train standing at the leak's worst place before the exit zone of the
    line's first section with carrier ``own_hz`` (the next section's carrier is the
    neighbour's), for the code waveforms ``u_own`` (that section's u_tx) and ``u_neighbour``
    (the next section's), V, sampled at ``fs_hz``, a whole number of 10 ms frames."""
    line = line or load_line(HSL_LINE)
    k = next(i for i, s in enumerate(line.sections[:-1]) if float(s.carrier_hz) == own_hz)
    own, ahead = line.sections[k], line.sections[k + 1]
    core = tvm_rail_line(line, 1, fs_hz, train_length_m, wheelsets_m)
    wheels = core.settings.wheelset_offsets_m[0]
    head = own.end_m - NEAREST_HEAD_BEFORE_ZONE_M
    leak = leak_at(NEAREST_HEAD_BEFORE_ZONE_M, own_hz, float(ahead.carrier_hz), float(own.ballast_ohm_km),
                   line.max_ballast_ohm_km, wheels, length_m=own.end_m - own.start_m,
                   neighbour_length_m=ahead.end_m - ahead.start_m, transformer_ratio=core.settings.transformer_ratio)
    u_own, u_neighbour = np.asarray(u_own, dtype=float), np.asarray(u_neighbour, dtype=float)
    n = core.frame
    if u_own.shape != u_neighbour.shape or u_own.ndim != 1 or u_own.size % n:
        raise ValueError(f"u_own and u_neighbour: two arrays of one length, a multiple of {n} samples")
    core.start(np.array([head]))
    u = np.zeros((len(line.sections), n))
    frames = []
    for f in range(u_own.size // n):
        u[k] = u_own[f * n:(f + 1) * n]
        frames.append(core.step(f * n / fs_hz, u, np.array([head]), np.zeros(1), np.zeros(1)).e_coil[0].copy())
    own_emf = np.concatenate(frames)
    current = leak.neighbour_current_a * u_neighbour
    neighbour_emf = core.settings.coil_gain_h * fs_hz * np.diff(current, prepend=current[0])
    return LeakEmf(own_emf + neighbour_emf, own_emf, leak, k, head)
