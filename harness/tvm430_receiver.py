"""The TVM-430 receiver on synthesised carriers: each carrier frequency-modulated by its word
exactly as fmus/signalling/tvm430.py defines it (phase 2π f_c t + bits·modulation_phase_terms),
plus white noise, fed to Tvm430ReceiverCore frame by frame (no FMI, no rail line): for
tests/test_tvm430_receiver.py and benchmarks/tvm430_decode.py (docs/loco_receiver.md#tvm-430).

A plan is a list of (start s, {carrier Hz: (word, coil EMF amplitude V)}): from its start
each listed carrier carries its word at its amplitude until the next entry; word 0 is a carrier
without tones (it fails the check). The tones' time origin can be moved (``tone_offset_s``): the
coder's tone phases at the instant of a change vary with it.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from fmus.loco_receiver.tvm430 import Tvm430ReceiverCore, Tvm430ReceiverSettings
from fmus.signalling import tvm430

Plan = Sequence[Tuple[float, Dict[float, Tuple[int, float]]]]
CHUNK_S = 0.5               # synthesis span: the tone matrix of 0.5 s at 12 kHz is 27 × 6000
#: the 27 tones' common period (0.88 and 0.64 Hz are multiples of 0.08 Hz): tone offsets beyond
#: it repeat
TONE_PERIOD_S = 12.5


def fm_carrier(word: int, times_s: np.ndarray, carrier_hz: float, amplitude_v: float,
               terms: Optional[np.ndarray] = None) -> np.ndarray:
    """The carrier at ``times_s`` frequency-modulated by ``word`` (``terms``: the tones' phase
    rows at those times, tvm430.modulation_phase_terms, when the caller has them)."""
    if terms is None:
        terms = tvm430.modulation_phase_terms(times_s)
    return amplitude_v * np.cos(2.0 * np.pi * carrier_hz * times_s + tvm430.bits_of(word) @ terms)


@dataclass
class Record:
    """Per frame (its end time): what the receiver outputs, and the word its latest decision
    read (0: none; diagnostics)."""

    t: np.ndarray
    code: np.ndarray
    valid: np.ndarray
    aspect: np.ndarray
    v_permitted_kmh: np.ndarray
    word_carrier_hz: np.ndarray
    target_distance_m: np.ndarray
    gradient_permille: np.ndarray
    decided: np.ndarray

    def first(self, after_s: float, condition: np.ndarray) -> Optional[float]:
        """Time after ``after_s`` of the first frame at or after it where ``condition`` holds
        (None: never)."""
        hits = np.flatnonzero((self.t >= after_s) & condition)
        return float(self.t[hits[0]] - after_s) if hits.size else None


def run(plan: Plan, duration_s: float, fs_hz: float = 12000.0, frame: int = 40, noise_v: float = 0.0,
        seed: int = 0, tone_offset_s: float = 0.0, settings: Optional[Tvm430ReceiverSettings] = None,
        core: Optional[Tvm430ReceiverCore] = None, start_s: float = 0.0) -> Tuple[Record, Tvm430ReceiverCore]:
    """Run a receiver (``core``, or a new one with ``settings`` at ``fs_hz``) through the plan
    from ``start_s`` (a core carried over from an earlier run goes on from there) for
    ``duration_s``."""
    if core is None:
        settings = settings or Tvm430ReceiverSettings(fs_hz=fs_hz)
        core = Tvm430ReceiverCore(frame, settings)
    fs_hz, frame = core.settings.fs_hz, core.frame
    rng = np.random.default_rng(seed)
    starts = [start for start, _ in plan]
    rows: List[tuple] = []
    chunk = max(frame, int(round(CHUNK_S * fs_hz / frame)) * frame)
    begin = int(round(start_s * fs_hz))
    total = begin + int(round(duration_s * fs_hz / frame)) * frame
    for first in range(begin, total, chunk):
        index = np.arange(first, min(first + chunk, total))
        t = index / fs_hz
        terms = _phase_terms(first, t.size, fs_hz, tone_offset_s)
        e = rng.normal(0.0, noise_v, t.size) if noise_v else np.zeros(t.size)
        entry = np.searchsorted(starts, t, side="right") - 1
        for k in np.unique(entry[entry >= 0]).tolist():
            span = entry == k
            for carrier_hz, (word, amplitude_v) in plan[k][1].items():
                e[span] += fm_carrier(word, t[span], carrier_hz, amplitude_v, terms[:, span])
        for at in range(0, t.size, frame):
            out = core.step(float(t[at]), e[at:at + frame])
            rows.append((float(t[at] + frame / fs_hz), out.code, out.code_valid, out.aspect, out.v_permitted_mps * 3.6,
                         out.word_carrier_hz, out.target_distance_m, out.gradient_permille,
                         core.last_decision.word if core.last_decision else 0))
    columns = list(zip(*rows))
    return Record(*(np.array(c) for c in columns)), core


def rail_line_emf(schedule: Sequence[Tuple[float, Sequence[int]]], head_m: float, seconds: float,
                  fs_hz: float = 12000.0, ballast_ohm_km: float = 0.0, coder_core=None) -> np.ndarray:
    """The coil EMF (V, per sample) of a train standing with its first wheelset at ``head_m`` on
    the high-speed line: the TVM-430 coder core (its default 4 V) → harness/tvm_line.py's rail
    line core, every section k sending ``words[k]`` of the schedule's latest (start s, words)
    on its line-file carrier (the coder's ``send``: the block rules bypassed, each change
    phase-continuous as in service). ``ballast_ohm_km``: every section's ballast, as the rail
    line's ballast_override input sets it (0: the line file's, its minimum). ``coder_core``: the
    coder core's class (Tvm430CoderCore; Tvm300CoderCore sends codes instead of words)."""
    from fmus.wayside_coder.core import CoderSettings
    from fmus.wayside_coder.tvm430 import Tvm430CoderCore
    from harness.tvm_line import tvm_rail_line

    rail = tvm_rail_line(fs_hz=fs_hz)
    count, n = len(rail.line.sections), rail.frame
    if ballast_ohm_km:
        rail.set_faults(-1.0, np.full(count, float(ballast_ohm_km)), np.zeros(count, dtype=bool))
    coder = (coder_core or Tvm430CoderCore)(rail.line, count, n, CoderSettings(fs_hz=fs_hz))
    clear = np.zeros(count, dtype=bool)
    rail.start(np.array([head_m]))
    frames = []
    starts = [start for start, _ in schedule]
    sending = None
    for first in range(0, int(round(seconds * fs_hz / n)) * n, n):
        entry = int(np.searchsorted(starts, first / fs_hz, side="right")) - 1
        if entry != sending:
            coder.send(np.asarray(schedule[entry][1]))
            sending = entry
        u = coder.step(first / fs_hz, clear).u_tx[:count]
        frames.append(rail.step(first / fs_hz, u, np.array([head_m]), np.zeros(1), np.zeros(1)).e_coil[0].copy())
    return np.concatenate(frames)


@lru_cache(maxsize=64)
def _phase_terms(first: int, count: int, fs_hz: float, tone_offset_s: float) -> np.ndarray:
    """The tones' phase rows of one chunk (cases that replay the same span share them)."""
    terms = tvm430.modulation_phase_terms((first + np.arange(count)) / fs_hz + tone_offset_s)
    terms.flags.writeable = False
    return terms


def word(step_kmh: float, next_kmh: float, distance_m: float = 7000.0, gradient_permille: float = 0.0,
         table: Optional[tvm430.Tvm430System] = None) -> int:
    """The word of a speed pair, target distance and gradient in the shipped tables."""
    tvm = table or tvm430.system()
    t = tvm.table
    return tvm430.assemble(t.addresses[0], t.speed_code(step_kmh, next_kmh), t.distance_code(distance_m),
                           t.gradient_code(gradient_permille))
