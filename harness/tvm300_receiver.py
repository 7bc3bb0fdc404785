"""The TVM-300 receiver on synthesised carriers: each carrier frequency-modulated by the
sub-frequencies of its code as fmus/signalling/tvm300.py defines them (phase 2π f_c t +
Σ (Δ/f_k)·sin(2π f_k t + φ_k)), plus white noise, fed to Tvm300ReceiverCore frame by frame (no
FMI, no rail line); and through the rail line, the coder core's carriers
(harness/tvm430_receiver.rail_line_emf with Tvm300CoderCore). For tests/test_tvm300_receiver.py
and benchmarks/tvm300_decode.py (docs/loco_receiver.md#tvm-300).

A plan is a list of (start s, {carrier Hz: (codes, coil EMF amplitude V[, deviation share])}):
from its start each listed carrier carries its code — or a tuple of codes at once (a faulty
coder), each at ``deviation share`` × Δ (1 by default) — until the next entry; code 0 is a
bare carrier. Each sub-frequency starts at the phase ``phase_seed`` draws for it (the same for
the whole run: a change of code is not phase-continuous here; the coder core's is).
"""
from __future__ import annotations

from typing import Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from fmus.loco_receiver.tvm300 import Tvm300ReceiverCore, Tvm300ReceiverSettings
from fmus.signalling import tvm300
from harness.tvm430_receiver import Record
from harness.tvm430_receiver import rail_line_emf as _rail_line_emf

Codes = Union[int, Tuple[int, ...]]
Plan = Sequence[Tuple[float, Dict[float, tuple]]]
CHUNK_S = 0.5


def fm_carrier(codes: Codes, times_s: np.ndarray, carrier_hz: float, amplitude_v: float, share: float = 1.0,
               phases_rad: Optional[np.ndarray] = None) -> np.ndarray:
    """The carrier at ``times_s`` frequency-modulated by the sub-frequency of each code (0: none)."""
    codes = (codes,) if isinstance(codes, (int, np.integer)) else tuple(codes)
    phases = np.zeros(tvm300.SUB_FREQUENCY_COUNT) if phases_rad is None else phases_rad
    phase = 2.0 * np.pi * carrier_hz * times_s
    for code in codes:
        if code:
            k = tvm300.index_of_code(code)
            f = tvm300.SUB_FREQUENCIES_HZ[k]
            phase = phase + share * tvm300.DEVIATION_HZ / f * np.sin(2.0 * np.pi * f * times_s + phases[k])
    return amplitude_v * np.cos(phase)


def run(plan: Plan, duration_s: float, fs_hz: float = 12000.0, frame: int = 40, noise_v: float = 0.0,
        seed: int = 0, phase_seed: int = 0, settings: Optional[Tvm300ReceiverSettings] = None,
        core: Optional[Tvm300ReceiverCore] = None, start_s: float = 0.0) -> Tuple[Record, Tvm300ReceiverCore]:
    """Run a receiver (``core``, or a new one with ``settings`` at ``fs_hz``) through the plan
    from ``start_s`` for ``duration_s``."""
    if core is None:
        core = Tvm300ReceiverCore(frame, settings or Tvm300ReceiverSettings(fs_hz=fs_hz))
    fs_hz, frame = core.settings.fs_hz, core.frame
    rng = np.random.default_rng(seed)
    phases = np.random.default_rng(phase_seed).uniform(0.0, 2.0 * np.pi, tvm300.SUB_FREQUENCY_COUNT)
    starts = [start for start, _ in plan]
    rows: List[tuple] = []
    chunk = max(frame, int(round(CHUNK_S * fs_hz / frame)) * frame)
    begin = int(round(start_s * fs_hz))
    total = begin + int(round(duration_s * fs_hz / frame)) * frame
    for first in range(begin, total, chunk):
        t = np.arange(first, min(first + chunk, total)) / fs_hz
        e = rng.normal(0.0, noise_v, t.size) if noise_v else np.zeros(t.size)
        entry = np.searchsorted(starts, t, side="right") - 1
        for k in np.unique(entry[entry >= 0]).tolist():
            span = entry == k
            for carrier_hz, sent in plan[k][1].items():
                codes, amplitude_v = sent[0], sent[1]
                share = sent[2] if len(sent) > 2 else 1.0
                e[span] += fm_carrier(codes, t[span], carrier_hz, amplitude_v, share, phases)
        for at in range(0, t.size, frame):
            out = core.step(float(t[at]), e[at:at + frame])
            rows.append((float(t[at] + frame / fs_hz), out.code, out.code_valid, out.aspect, out.v_permitted_mps * 3.6,
                         out.word_carrier_hz, out.target_distance_m, out.gradient_permille,
                         core.last_decision.code if core.last_decision else 0))
    return Record(*(np.array(c) for c in zip(*rows))), core


def rail_line_emf(schedule: Sequence[Tuple[float, Sequence[int]]], head_m: float, seconds: float,
                  fs_hz: float = 12000.0, ballast_ohm_km: float = 0.0) -> np.ndarray:
    """The coil EMF (V, per sample) of a train standing with its first wheelset at ``head_m`` on
    the high-speed line (harness/tvm_line.py), the TVM-300 coder core (its default 4 V) sending
    on every section k ``codes[k]`` of the schedule's latest (start s, codes), each change
    phase-continuous; ``ballast_ohm_km`` every section's ballast (0: the line file's, its
    minimum)."""
    from fmus.wayside_coder.tvm300 import Tvm300CoderCore
    return _rail_line_emf(schedule, head_m, seconds, fs_hz, ballast_ohm_km, coder_core=Tvm300CoderCore)


def code(step_kmh: float, next_kmh: float, tvm: Optional[tvm300.Tvm300System] = None) -> int:
    """The code of a speed pair in the shipped table."""
    found = (tvm or tvm300.system()).table.code_of_pair(float(step_kmh), float(next_kmh))
    if found is None:
        raise ValueError(f"no code for {step_kmh:g}/{next_kmh:g} km/h")
    return found
