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

from typing import Optional

import numpy as np

from fmus.loco_receiver.core import ReceiverOutputs
from fmus.loco_receiver.um71 import (BASEBAND_RATE_HZ, BASEBAND_RISE_S, CONFIRMATIONS, DOMINANCE_DB,  # noqa: F401
                                     IMAGE_GUARD_HZ, LOW_PASS_CORNER_HZ, LOW_PASS_ORDER, SQUELCH_V,
                                     WEAKEST_CARRIER_V, FailSafeDisplay, Um71FrontEnd, low_pass_design)
from fmus.loco_receiver.um71 import Decision, Um71ReceiverCore, Um71ReceiverSettings, tone_window_fit  # noqa: F401 (Decision: read here)
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


def tone_fit(window: int, rate_hz: float) -> np.ndarray:
    """The window's least-squares fit of the 27 tones (um71.tone_window_fit)."""
    return tone_window_fit(window, rate_hz, tuple(tvm430.TONES_HZ.tolist()))


class Tvm430ReceiverCore(Um71ReceiverCore):
    deviation_hz = tvm430.DEVIATION_HZ_PER_TONE
    no_code = tvm430.NO_WORD

    def __init__(self, frame: int, settings: Tvm430ReceiverSettings, tvm: Optional[tvm430.Tvm430System] = None):
        super().__init__(frame, settings, tvm if tvm is not None else tvm430.system(settings.codes_file or None),
                         tvm430.NAME, WINDOW_S, HOP_S, tone_fit, resolve_inertia_s(settings.inertia_s))

    def code_of(self, amplitudes: np.ndarray) -> int:
        """The word of the 27 tones (module docstring); a tone between the fractions: no word."""
        if ((amplitudes > ABSENT_FRACTION) & (amplitudes < PRESENT_FRACTION)).any():
            return tvm430.NO_WORD
        return tvm430.word_of_bits(amplitudes >= PRESENT_FRACTION)

    def publish_extra(self, out: ReceiverOutputs, read: tvm430.Reading) -> None:
        out.target_distance_m, out.gradient_permille = read.target_distance_m, read.gradient_permille
