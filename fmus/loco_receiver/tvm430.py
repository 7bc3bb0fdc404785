"""Locomotive receiver for TVM-430: coil EMF → the track's two carriers, each mixed to complex
baseband, low-passed and decimated → FM discriminator → the 27 tones by least squares over a
sliding window → the word, its check and its reading → display (no FMI here;
docs/loco_receiver.md#tvm-430; the word, tones and modulation: fmus/signalling/tvm430.py).

* **Carriers.** The track's pair (``track`` 1: 1700 / 2300 Hz, 2: 2000 / 2600 Hz, alternating
  block by block). Each is mixed to complex baseband with the sample's absolute phase (so any
  frame length gives the same samples), low-passed by a Butterworth of order
  LOW_PASS_ORDER at LOW_PASS_CORNER_HZ (python-control, second-order sections with carried
  state, fmus/dsp/filter_design.py; the FM of a full word stays within ±25 Hz of the carrier,
  and the other track's carrier 300 Hz away is taken down by 62 dB) and kept every D-th
  sample (D = round(fs / BASEBAND_RATE_HZ), absolute sample index multiple of D: the same
  decimated samples for any frame length). The level of a carrier is the magnitude of its
  baseband (×2: the mixer halves it), its frequency offset the phase step between two
  decimated samples × rate / 2π (the discriminator ignores the amplitude).
* **Which carrier.** At each decision (every HOP_S) the carrier with the largest level over
  the hop is decoded only when it is above SQUELCH_V over the whole window
  and at least DOMINANCE_DB above every other carrier of the track: a neighbour's carrier
  leaking through a separation zone (at worst 0.081 of the own EMF, −22 dB,
  docs/rail_line.md#tvm-430-track-circuits) is 12 dB short of the margin and never decoded;
  where two are comparable (inside a separation zone) neither is.
* **Tones.** The 27 tones are 0.64 Hz apart, so they are resolved only over a window of at
  least 1/0.64 = 1.5625 s (WINDOW_S): a least-squares fit of a constant (the carrier's offset)
  and a cosine and a sine per tone to the window's frequency offset — one product with the
  fixed pseudo-inverse per decision, vectorised. A tone's amplitude in units of
  DEVIATION_HZ_PER_TONE is present above PRESENT_FRACTION, absent below ABSENT_FRACTION;
  any tone between (a window straddling a change, noise) gives no word. The word must pass
  its check and mean something (tvm430.Tvm430System.reading: address accepted, speed and
  distance codes used).
* **Display** (fail-safe, ours [U]): a word of the same block (carrier) that permits nothing
  more than the one shown (no field more permissive: step, next step, target distance,
  gradient; tvm430.Tvm430System.at_most) is shown at once; any other — more permissive in some
  field, or on the other carrier (a new block: its distance counts from another entry) — only
  once CONFIRMATIONS consecutive decisions gave it. The word shown holds while decisions give
  it or a word of its block that permits everything it does; when none has for the hold
  (``inertia``, 0: HOLD_S — it bridges a separation zone, where the new carrier's window
  still holds the old block's carrier), the display shows no word: step 0, aspect red,
  ``code`` 0, ``code_valid`` false. STATED_LATENCY_S bounds a loss of every valid word (lost
  carrier, failed check, unused field) to the restrictive display.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Optional, Tuple

import numpy as np
import scipy        # scipy.signal loads at its first use, a design (SciPy loads submodules lazily)

from fmus.dsp.filter_design import SosFilter, sections, sos_frame
from fmus.errors import FmuInputError
from fmus.loco_receiver.core import ReceiverOutputs
from fmus.signalling import aspects as sig
from fmus.signalling import tvm430
from fmus.signalling.tvm430 import (BASEBAND_RISE_S, HOLD_S, HOP_S, STATED_DECODE_S,  # noqa: F401 (the receiver's timing)
                                     STATED_LATENCY_S, WINDOW_S)
from fmus.sizes import DEFAULT_SAMPLE_RATE_HZ

BASEBAND_RATE_HZ = 200.0          # decimated rate: 10× the highest tone, ±100 Hz for the discriminator
LOW_PASS_ORDER = 4
LOW_PASS_CORNER_HZ = 50.0         # twice the FM's reach (±25 Hz), 300 Hz below the nearest other carrier
PRESENT_FRACTION = 0.65           # a tone's fitted amplitude / DEVIATION_HZ_PER_TONE above: present
ABSENT_FRACTION = 0.35            # below: absent; between: no word
DOMINANCE_DB = 10.0               # the decoded carrier is this far above every other of the track
CONFIRMATIONS = 2                 # consecutive decisions a non-restrictive change needs
#: a carrier below this (coil EMF, peak, V) is not decoded: a third of the weakest carrier the
#: rail line gives a train, 0.1 V 10 m into a 2300 Hz circuit at 1 Ω·km from the coder's 4 V
#: (docs/rail_line.md#tvm-430-track-circuits, "Levels"); a carrier that stops falls below it
#: within the low-pass's settling (a few ms)
SQUELCH_V = 0.03
WEAKEST_CARRIER_V = 0.1
#: the fs needed above the highest carrier: its image fs − f must stay out of the baseband
#: low-pass (more than its stop band, 5× the corner) — fs ≥ 2·(2600 + 250) = 5.7 kHz for track 2
IMAGE_GUARD_HZ = 5.0 * LOW_PASS_CORNER_HZ


@dataclass
class Tvm430ReceiverSettings:
    fs_hz: float = DEFAULT_SAMPLE_RATE_HZ
    track: int = 1                          # 1: carriers 1700 / 2300 Hz, 2: 2000 / 2600 Hz
    squelch_v: float = SQUELCH_V            # a carrier below this (coil EMF, peak) is not decoded
    inertia_s: float = 0.0                  # 0: HOLD_S
    codes_file: str = ""                    # empty: the shipped word tables


def resolve_inertia_s(inertia_s: float) -> float:
    return inertia_s if inertia_s > 0 else HOLD_S


@lru_cache(maxsize=8)
def low_pass_design(fs_hz: float) -> SosFilter:
    """The baseband low-pass of every carrier: Butterworth, LOW_PASS_ORDER, LOW_PASS_CORNER_HZ."""
    return sections(scipy.signal.buttap(LOW_PASS_ORDER), 2.0 * math.pi * LOW_PASS_CORNER_HZ, fs_hz, LOW_PASS_CORNER_HZ)


@lru_cache(maxsize=8)
def tone_fit(window: int, rate_hz: float) -> np.ndarray:
    """(1 + 2·27, window) pseudo-inverse of the window's model: a constant, then cos and sin of
    every tone, over ``window`` samples at ``rate_hz`` (the fit's time origin is the window's
    first sample: the receiver does not know the coder's tone phases). Shared, read-only: every
    receiver at one rate fits with the same matrix."""
    t = np.arange(window) / rate_hz
    angle = np.multiply.outer(t, 2.0 * np.pi * tvm430.TONES_HZ)
    model = np.hstack([np.ones((window, 1)), np.cos(angle), np.sin(angle)])
    fit = np.linalg.pinv(model)
    fit.flags.writeable = False
    return fit


@dataclass(frozen=True)
class Decision:
    """What one decision heard (diagnostics and tests)."""

    time_s: float
    carrier_hz: float          # 0: no carrier decoded
    amplitudes: Optional[np.ndarray]   # the 27 tones' fitted amplitudes / DEVIATION_HZ_PER_TONE
    word: int                  # the word read, 0: none (no carrier, a tone undecided, failed check or unused)


class Tvm430ReceiverCore:
    def __init__(self, frame: int, settings: Tvm430ReceiverSettings, tvm: Optional[tvm430.Tvm430System] = None):
        s = settings
        if s.track not in tvm430.TRACK_CARRIERS_HZ:
            raise FmuInputError(f"parameter track: {s.track} is not one of "
                                f"{', '.join(map(str, tvm430.TRACK_CARRIERS_HZ))} (TVM430's tracks)")
        if not s.squelch_v > 0:
            raise ValueError(f"Tvm430ReceiverSettings.squelch_v must be positive, got {s.squelch_v}")
        if s.inertia_s < 0:
            raise FmuInputError(f"parameter inertia: must not be negative, got {s.inertia_s}")
        self.carriers_hz = np.array(tvm430.TRACK_CARRIERS_HZ[s.track])
        needed = 2.0 * (self.carriers_hz.max() + IMAGE_GUARD_HZ)
        if s.fs_hz < needed:
            raise FmuInputError(f"parameter fs: {s.fs_hz:g} Hz is too low for TVM430's carriers up to "
                                f"{self.carriers_hz.max():g} Hz on track {s.track} (at least {needed:g} Hz)")
        self.tvm = tvm if tvm is not None else tvm430.system(s.codes_file or None)
        self.settings, self.frame = s, frame
        self.decimation = max(1, round(s.fs_hz / BASEBAND_RATE_HZ))
        self.rate_hz = s.fs_hz / self.decimation
        self.window = math.ceil(WINDOW_S * self.rate_hz - 1e-9)
        self.hop = max(1, round(HOP_S * self.rate_hz))
        self.fit = tone_fit(self.window, self.rate_hz)
        self.low_pass = low_pass_design(s.fs_hz)
        count = self.carriers_hz.size
        self._lp_state = self.low_pass.initial_state(2 * count)
        self._cycles_per_sample = self.carriers_hz / s.fs_hz
        # the last `window` decimated samples per carrier: frequency offset (Hz) and level (V)
        self._offset = np.zeros((count, self.window))
        self._level = np.zeros((count, self.window))
        self._previous: Optional[np.ndarray] = None      # last decimated baseband sample per carrier
        self._decimated = 0                                # decimated samples so far
        self.hold_s = resolve_inertia_s(s.inertia_s)
        self.dominance = 10.0 ** (DOMINANCE_DB / 20.0)
        self._shown: Optional[Tuple[int, float]] = None   # (word, carrier Hz)
        self._shown_reading: Optional[tvm430.Reading] = None
        self._supported_s = 0.0
        self._pending: Optional[Tuple[int, float]] = None
        self._pending_count = 0
        self.last_decision: Optional[Decision] = None
        self.out = ReceiverOutputs()
        self._publish(0.0)

    # ---- signal chain -------------------------------------------------------------------------
    def step(self, t: float, e_coil: np.ndarray, channel_faults=None) -> ReceiverOutputs:
        """One frame of coil EMF (``channel_faults`` is the digital receiver's input: ignored)."""
        s = self.settings
        first = round(t * s.fs_hz)
        x = np.asarray(e_coil, dtype=float)
        index = first + np.arange(x.size)
        # each carrier's phase from the absolute sample index, in cycles mod 1 (exact enough
        # after 10^9 samples: 10^-7 cycle)
        cycles = np.mod(np.multiply.outer(self._cycles_per_sample, index.astype(float)), 1.0)
        angle = 2.0 * np.pi * cycles
        count = self.carriers_hz.size
        mixed = np.empty((2 * count, x.size))
        mixed[0::2] = x * np.cos(angle)
        mixed[1::2] = x * -np.sin(angle)
        baseband, self._lp_state = sos_frame(self.low_pass.sos, mixed, self._lp_state)
        kept = np.arange((-first) % self.decimation, x.size, self.decimation)   # absolute index multiple of D
        if kept.size:
            z = 2.0 * (baseband[0::2, kept] + 1j * baseband[1::2, kept])
            before = z[:, :1] if self._previous is None else self._previous[:, None]
            steps = z * np.conj(np.concatenate([before, z[:, :-1]], axis=1))
            self._previous = z[:, -1].copy()
            self._take(np.angle(steps) * (self.rate_hz / (2.0 * np.pi)), np.abs(z), index[kept])
        self._publish(float(np.abs(self._previous).max()) if self._previous is not None else 0.0)
        return self.out

    def _take(self, offset_hz: np.ndarray, level_v: np.ndarray, sample_index: np.ndarray) -> None:
        """Append decimated samples; decide at every hop boundary among them (a frame holds
        at most one at the usual frame lengths: a loop over decisions, not samples)."""
        m = offset_hz.shape[1]
        numbers = self._decimated + np.arange(m)
        self._decimated += m
        decide_at = np.flatnonzero((numbers + 1) % self.hop == 0)
        start = 0
        for at in decide_at.tolist():
            self._append(offset_hz[:, start:at + 1], level_v[:, start:at + 1])
            start = at + 1
            if numbers[at] + 1 >= self.window:
                self._decide(float(sample_index[at]) / self.settings.fs_hz)
        self._append(offset_hz[:, start:], level_v[:, start:])

    def _append(self, offset_hz: np.ndarray, level_v: np.ndarray) -> None:
        m = offset_hz.shape[1]
        if not m:
            return
        if m >= self.window:
            self._offset[:] = offset_hz[:, -self.window:]
            self._level[:] = level_v[:, -self.window:]
            return
        self._offset[:, :-m] = self._offset[:, m:]
        self._offset[:, -m:] = offset_hz
        self._level[:, :-m] = self._level[:, m:]
        self._level[:, -m:] = level_v

    # ---- decisions ----------------------------------------------------------------------------
    def read_window(self, time_s: float) -> Decision:
        """The word the current window gives (module docstring: which carrier, tones)."""
        hop_levels = self._level[:, -self.hop:].mean(axis=1)
        best = int(np.argmax(hop_levels))
        others = np.delete(hop_levels, best)
        squelch = self.settings.squelch_v
        if self._level[best].min() < squelch or (others.size and hop_levels[best] < self.dominance * others.max()):
            return Decision(time_s, 0.0, None, tvm430.NO_WORD)
        coefficients = self.fit @ self._offset[best]
        cos_sin = coefficients[1:].reshape(2, tvm430.TONE_COUNT)
        amplitudes = np.hypot(cos_sin[0], cos_sin[1]) / tvm430.DEVIATION_HZ_PER_TONE
        carrier = float(self.carriers_hz[best])
        if ((amplitudes > ABSENT_FRACTION) & (amplitudes < PRESENT_FRACTION)).any():
            return Decision(time_s, carrier, amplitudes, tvm430.NO_WORD)
        word = tvm430.word_of_bits(amplitudes >= PRESENT_FRACTION)
        if self.tvm.reading(word) is None:
            word = tvm430.NO_WORD
        return Decision(time_s, carrier, amplitudes, word)

    def _at_most(self, key: Tuple[int, float], other: Tuple[int, float]) -> bool:
        """(word, carrier) ``key`` permits nothing ``other`` does not (tvm430's partial order);
        words on different carriers are of different blocks, whose distances count from
        different entries: never comparable."""
        return key[1] == other[1] and self.tvm.at_most(key[0], other[0])

    def _decide(self, time_s: float) -> None:
        decision = self.read_window(time_s)
        self.last_decision = decision
        out = self.out
        if decision.word == tvm430.NO_WORD:
            self._pending, self._pending_count = None, 0
            if decision.carrier_hz:
                out.errors += 1
        else:
            key = (decision.word, decision.carrier_hz)
            out.decoded_codes += 1
            if key == self._shown:
                self._supported_s = time_s
                self._pending, self._pending_count = None, 0
            elif self._shown is not None and self._at_most(key, self._shown):
                self._show(key, time_s)                          # permits nothing more: at once
            else:
                if self._shown is not None and self._at_most(self._shown, key):
                    self._supported_s = time_s                   # the shown permits nothing more: it stays
                self._pending_count = self._pending_count + 1 if key == self._pending else 1
                self._pending = key
                if self._pending_count >= CONFIRMATIONS:
                    self._show(key, time_s)
        if self._shown is not None and time_s - self._supported_s >= self.hold_s - 1e-9:
            self._shown = None                                   # nothing valid heard for the hold

    def _show(self, key: Tuple[int, float], time_s: float) -> None:
        self._shown, self._supported_s = key, time_s
        self._shown_reading = self.tvm.reading(key[0])
        self._pending, self._pending_count = None, 0

    def _publish(self, level_v: float) -> None:
        out = self.out
        out.level_v = level_v
        out.relay = level_v >= self.settings.squelch_v
        if self._shown is None:
            out.aspect, out.code, out.code_valid, out.free_blocks = sig.RED, tvm430.NO_WORD, False, 0
            out.v_permitted_mps = out.v_target_mps = 0.0
            out.target_distance_m = out.gradient_permille = out.word_carrier_hz = 0.0
            return
        word, carrier = self._shown
        read = self._shown_reading
        out.aspect, out.code, out.code_valid, out.free_blocks = read.aspect, word, True, read.free_blocks
        out.v_permitted_mps, out.v_target_mps = read.step_kmh / 3.6, read.next_kmh / 3.6
        out.target_distance_m, out.gradient_permille = read.target_distance_m, read.gradient_permille
        out.word_carrier_hz = carrier
