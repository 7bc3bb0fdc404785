"""Locomotive receiver for TVM-430: coil EMF → the track's two carriers, each mixed to complex
baseband, low-passed and decimated → FM discriminator → the 27 tones by least squares over a
sliding window → the word, its check and its reading → display (no FMI here;
docs/loco_receiver.md#tvm-430; the word, tones and modulation: fmus/signalling/tvm430.py).

* **Carriers, which carrier, display**: the front end and the fail-safe display both TVM
  receivers share (fmus/loco_receiver/um71.py): the track's two carriers to complex baseband,
  low-passed, decimated, FM discriminator; the carrier decoded only above the squelch and
  DOMINANCE_DB above the other.
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

from dataclasses import dataclass
from functools import lru_cache
from typing import Optional

import numpy as np

from fmus.loco_receiver.core import ReceiverOutputs
from fmus.loco_receiver.um71 import (BASEBAND_RATE_HZ, BASEBAND_RISE_S, CONFIRMATIONS, DOMINANCE_DB,  # noqa: F401
                                     IMAGE_GUARD_HZ, LOW_PASS_CORNER_HZ, LOW_PASS_ORDER, SQUELCH_V,
                                     WEAKEST_CARRIER_V, FailSafeDisplay, Um71FrontEnd, low_pass_design)
from fmus.loco_receiver.um71 import Um71ReceiverSettings
from fmus.signalling import aspects as sig
from fmus.signalling import tvm430
# the decoder rules' times (fmus/signalling/tvm430.py), importable from here as before
from fmus.signalling.tvm430 import HOLD_S, HOP_S, STATED_DECODE_S, STATED_LATENCY_S, WINDOW_S  # noqa: F401

PRESENT_FRACTION = 0.65           # a tone's fitted amplitude / DEVIATION_HZ_PER_TONE above: present
ABSENT_FRACTION = 0.35            # below: absent; between: no word


class Tvm430ReceiverSettings(Um71ReceiverSettings):
    """TVM-430's receiver settings: the UM71 receivers' (``inertia`` 0: HOLD_S, ``codes_file``
    empty: the shipped word tables)."""


def resolve_inertia_s(inertia_s: float) -> float:
    return inertia_s if inertia_s > 0 else HOLD_S


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
        self.front = Um71FrontEnd(settings, tvm430.NAME, WINDOW_S, HOP_S)
        self.carriers_hz = self.front.carriers_hz
        self.tvm = tvm if tvm is not None else tvm430.system(settings.codes_file or None)
        self.settings, self.frame = settings, frame
        self.rate_hz, self.window = self.front.rate_hz, self.front.window
        self.fit = tone_fit(self.window, self.rate_hz)
        self.hold_s = resolve_inertia_s(settings.inertia_s)
        self.display = FailSafeDisplay(self.hold_s)
        self._shown_reading: Optional[tvm430.Reading] = None
        self.last_decision: Optional[Decision] = None
        self.out = ReceiverOutputs()
        self._publish(0.0)

    def step(self, t: float, e_coil: np.ndarray, channel_faults=None) -> ReceiverOutputs:
        """One frame of coil EMF (``channel_faults`` is the digital receiver's input: ignored)."""
        self._publish(self.front.feed(t, e_coil, self._decide))
        return self.out

    # ---- decisions ----------------------------------------------------------------------------
    def read_window(self, time_s: float) -> Decision:
        """The word the current window gives (module docstring: which carrier, tones)."""
        best = self.front.carrier_to_decode()
        if best is None:
            return Decision(time_s, 0.0, None, tvm430.NO_WORD)
        coefficients = self.fit @ self.front.offset_hz[best]
        cos_sin = coefficients[1:].reshape(2, tvm430.TONE_COUNT)
        amplitudes = np.hypot(cos_sin[0], cos_sin[1]) / tvm430.DEVIATION_HZ_PER_TONE
        carrier = float(self.carriers_hz[best])
        if ((amplitudes > ABSENT_FRACTION) & (amplitudes < PRESENT_FRACTION)).any():
            return Decision(time_s, carrier, amplitudes, tvm430.NO_WORD)
        word = tvm430.word_of_bits(amplitudes >= PRESENT_FRACTION)
        if self.tvm.reading(word) is None:
            word = tvm430.NO_WORD
        return Decision(time_s, carrier, amplitudes, word)

    def _decide(self, time_s: float) -> None:
        decision = self.read_window(time_s)
        self.last_decision = decision
        out = self.out
        if decision.word == tvm430.NO_WORD:
            key = None
            if decision.carrier_hz:
                out.errors += 1
        else:
            key = (decision.word, decision.carrier_hz)
            out.decoded_codes += 1
        # tvm430's partial order (words on different carriers: never comparable)
        if self.display.decide(key, time_s, self.tvm.at_most):
            self._shown_reading = self.tvm.reading(key[0])

    def _publish(self, level_v: float) -> None:
        out = self.out
        out.level_v = level_v
        out.relay = level_v >= self.settings.squelch_v
        shown = self.display.shown
        if shown is None:
            out.aspect, out.code, out.code_valid, out.free_blocks = sig.RED, tvm430.NO_WORD, False, 0
            out.v_permitted_mps = out.v_target_mps = 0.0
            out.target_distance_m = out.gradient_permille = out.word_carrier_hz = 0.0
            return
        word, carrier = shown
        read = self._shown_reading
        out.aspect, out.code, out.code_valid, out.free_blocks = read.aspect, word, True, read.free_blocks
        out.v_permitted_mps, out.v_target_mps = read.step_kmh / 3.6, read.next_kmh / 3.6
        out.target_distance_m, out.gradient_permille = read.target_distance_m, read.gradient_permille
        out.word_carrier_hz = carrier
