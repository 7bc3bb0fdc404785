"""Locomotive receiver for TVM-300: coil EMF → the track's two carriers, each mixed to complex
baseband, low-passed and decimated → FM discriminator (the front end TVM-430 shares,
fmus/loco_receiver/um71.py) → which one of the 18 sub-frequencies is present, by least squares
over a sliding window → the code and its reading → display (no FMI here;
docs/loco_receiver.md#tvm-300; sub-frequencies, table and decoder times:
fmus/signalling/tvm300.py).

* **Sub-frequency.** The 18 sub-frequencies are 1.1 Hz apart, so they are resolved only over a
  window of at least 1/1.1 = 0.909 s (tvm300.WINDOW_S): a least-squares fit of a constant (the
  carrier's offset) and a cosine and a sine per sub-frequency to the window's frequency offset
  — one product with the fixed pseudo-inverse per decision. A sub-frequency's amplitude in
  units of DEVIATION_HZ is present above PRESENT_FRACTION, absent below ABSENT_FRACTION. A
  code is read only when exactly one is present and every other absent, and its index is used
  in the table; none, two, one between the fractions (a window straddling a change, noise), or
  an unused one give no code — never a more permissive one.
* **Display** (fail-safe, ours [U]; um71.FailSafeDisplay): a code of the same carrier that
  permits nothing more than the one shown (tvm300.Tvm300System.at_most: neither step higher)
  is shown at once; any other only after CONFIRMATIONS consecutive decisions; the code shown
  holds while decisions give it or a code that permits everything it does, and when none has
  for the hold (``inertia``, 0: HOLD_S), the display shows no code: step 0, aspect red, ``code``
  0, ``code_valid`` false. tvm300.STATED_LATENCY_S bounds a loss to the restrictive display,
  tvm300.STATED_DECODE_S a new code's decode.

Outputs: ``code`` = sub-frequency index + 1, ``v_permitted`` the step, ``v_target`` the next
step, ``free_blocks`` the fewest blocks before the stop that give the pair, ``aspect`` GREEN
(step = next > 0), YELLOW (next < step), RED (step 0), ``word_carrier_hz`` the carrier decoded.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from fmus.loco_receiver.um71 import Decision, Um71ReceiverCore, Um71ReceiverSettings, tone_window_fit  # noqa: F401 (Decision: read here)
from fmus.signalling import tvm300
from fmus.signalling.tvm300 import HOLD_S, HOP_S, STATED_DECODE_S, STATED_LATENCY_S, WINDOW_S  # noqa: F401

PRESENT_FRACTION = 0.65           # a sub-frequency's fitted amplitude / DEVIATION_HZ above: present
ABSENT_FRACTION = 0.35            # below: absent


class Tvm300ReceiverSettings(Um71ReceiverSettings):
    """TVM-300's receiver settings: the UM71 receivers' (``inertia`` 0: HOLD_S, ``codes_file``
    empty: the shipped code table)."""


def resolve_inertia_s(inertia_s: float) -> float:
    return inertia_s if inertia_s > 0 else HOLD_S


def sub_frequency_fit(window: int, rate_hz: float) -> np.ndarray:
    """The window's least-squares fit of the 18 sub-frequencies (um71.tone_window_fit)."""
    return tone_window_fit(window, rate_hz, tuple(tvm300.SUB_FREQUENCIES_HZ.tolist()))


class Tvm300ReceiverCore(Um71ReceiverCore):
    deviation_hz = tvm300.DEVIATION_HZ
    no_code = tvm300.NO_CODE

    def __init__(self, frame: int, settings: Um71ReceiverSettings, tvm: Optional[tvm300.Tvm300System] = None):
        super().__init__(frame, settings, tvm if tvm is not None else tvm300.system(settings.codes_file or None),
                         tvm300.NAME, WINDOW_S, HOP_S, sub_frequency_fit, resolve_inertia_s(settings.inertia_s))

    def code_of(self, amplitudes: np.ndarray) -> int:
        """The code of the one sub-frequency present, every other absent (module docstring); else none."""
        present = np.flatnonzero(amplitudes > PRESENT_FRACTION)
        if present.size != 1 or np.count_nonzero(amplitudes >= ABSENT_FRACTION) != 1:
            return tvm300.NO_CODE
        return tvm300.code_of_index(int(present[0]))
