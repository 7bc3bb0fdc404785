"""The front end and the display rules both TVM receivers share (fmus/loco_receiver/tvm430.py,
tvm300.py; docs/loco_receiver.md#tvm-430, #tvm-300): the track's two UM71 carriers
(fmus/signalling/um71.py) from the coil EMF to a frequency offset and a level per decimated
sample over a sliding window, which carrier a decision decodes, and the fail-safe display of
what the decisions read. No FMI here; what a window means (the 27 tones of a word, the one
sub-frequency of a code) is each system's.

* **Carriers.** The track's pair (``track`` 1: 1700 / 2300 Hz, 2: 2000 / 2600 Hz, alternating
  block by block). Each is mixed to complex baseband with the sample's absolute phase (so any
  frame length gives the same samples), low-passed by a Butterworth of order
  LOW_PASS_ORDER at LOW_PASS_CORNER_HZ (python-control, second-order sections with carried
  state, fmus/dsp/filter_design.py; the FM of a full TVM-430 word stays within ±25 Hz of the
  carrier, a TVM-300 code's within ±40 Hz (Carson: 2·(11 + 29) Hz wide), and the other
  track's carrier 300 Hz away is taken down by 62 dB) and kept every D-th sample
  (D = round(fs / BASEBAND_RATE_HZ), absolute sample index multiple of D: the same decimated
  samples for any frame length). The level of a carrier is the magnitude of its baseband (×2:
  the mixer halves it), its frequency offset the phase step between two decimated samples ×
  rate / 2π (the discriminator ignores the amplitude).
* **Which carrier.** At each decision (every hop of the system's rules) the carrier with the
  largest level over the hop is decoded only when it is above SQUELCH_V over the whole window
  and at least DOMINANCE_DB above every other carrier of the track: a neighbour's carrier
  leaking through a separation zone (at worst 0.081 of the own EMF, −22 dB,
  docs/rail_line.md#tvm-430-track-circuits) is 12 dB short of the margin and never decoded;
  where two are comparable (inside a separation zone) neither is.
* **Display** (fail-safe, ours [U]): a code of the same block (carrier) that permits nothing
  more than the one shown (the system's ``at_most``) is shown at once; any other — more
  permissive in some respect, or on the other carrier (a new block) — only once CONFIRMATIONS
  consecutive decisions gave it. The code shown holds while decisions give it or a code of its
  block that permits everything it does; when none has for the hold, the display shows no
  code.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import lru_cache
from typing import Callable, Optional, Tuple

import numpy as np
import scipy        # scipy.signal loads at its first use, a design (SciPy loads submodules lazily)

from fmus.dsp.filter_design import SosFilter, sections, sos_frame
from fmus.errors import FmuInputError
from fmus.loco_receiver.core import ReceiverOutputs
from fmus.signalling import aspects as sig
from fmus.signalling import um71
from fmus.sizes import DEFAULT_SAMPLE_RATE_HZ

BASEBAND_RATE_HZ = 200.0          # decimated rate: ±100 Hz for the discriminator, ~7× TVM-300's highest sub-frequency
LOW_PASS_ORDER = 4
LOW_PASS_CORNER_HZ = 50.0         # above the FM's reach (±25 Hz TVM-430, ±40 Hz TVM-300), 250 Hz below the other carrier
DOMINANCE_DB = 10.0               # the decoded carrier is this far above every other of the track
CONFIRMATIONS = 2                 # consecutive decisions a non-restrictive change needs
#: a carrier below this (coil EMF, peak, V) is not decoded: a third of the weakest carrier the
#: rail line gives a train, 0.1 V 10 m into a 2300 Hz circuit at 1 Ω·km from the coder's 4 V
#: (docs/rail_line.md#tvm-430-track-circuits, "Levels"); a carrier that stops falls below it
#: within the low-pass's settling (a few ms)
SQUELCH_V = 0.03
WEAKEST_CARRIER_V = 0.1
#: the baseband low-pass's rise (s), stated with the systems' decoder rules (signalling/um71.py)
BASEBAND_RISE_S = um71.BASEBAND_RISE_S
#: the fs needed above the highest carrier: its image fs − f must stay out of the baseband
#: low-pass (more than its stop band, 5× the corner) — fs ≥ 2·(2600 + 250) = 5.7 kHz for track 2
IMAGE_GUARD_HZ = 5.0 * LOW_PASS_CORNER_HZ


@dataclass
class Um71ReceiverSettings:
    """A TVM receiver's settings (TVM-430's and TVM-300's alike: Tvm430ReceiverSettings,
    Tvm300ReceiverSettings)."""

    fs_hz: float = DEFAULT_SAMPLE_RATE_HZ
    track: int = 1                          # 1: carriers 1700 / 2300 Hz, 2: 2000 / 2600 Hz
    squelch_v: float = SQUELCH_V            # a carrier below this (coil EMF, peak) is not decoded
    inertia_s: float = 0.0                  # 0: the system's HOLD_S
    codes_file: str = ""                    # empty: the shipped tables


@lru_cache(maxsize=8)
def low_pass_design(fs_hz: float) -> SosFilter:
    """The baseband low-pass of every carrier: Butterworth, LOW_PASS_ORDER, LOW_PASS_CORNER_HZ."""
    return sections(scipy.signal.buttap(LOW_PASS_ORDER), 2.0 * math.pi * LOW_PASS_CORNER_HZ, fs_hz, LOW_PASS_CORNER_HZ)


def check_settings(s: Um71ReceiverSettings, system_name: str) -> np.ndarray:
    """The track's carriers (Hz); a track, squelch, inertia or sample rate a TVM receiver
    cannot take is an input error naming the parameter."""
    if s.track not in um71.TRACK_CARRIERS_HZ:
        raise FmuInputError(f"parameter track: {s.track} is not one of "
                            f"{', '.join(map(str, um71.TRACK_CARRIERS_HZ))} ({system_name}'s tracks)")
    if not s.squelch_v > 0:
        raise ValueError(f"{type(s).__name__}.squelch_v must be positive, got {s.squelch_v}")
    if s.inertia_s < 0:
        raise FmuInputError(f"parameter inertia: must not be negative, got {s.inertia_s}")
    carriers = np.array(um71.TRACK_CARRIERS_HZ[s.track])
    needed = 2.0 * (carriers.max() + IMAGE_GUARD_HZ)
    if s.fs_hz < needed:
        raise FmuInputError(f"parameter fs: {s.fs_hz:g} Hz is too low for {system_name}'s carriers up to "
                            f"{carriers.max():g} Hz on track {s.track} (at least {needed:g} Hz)")
    return carriers


class Um71FrontEnd:
    """Coil EMF → each carrier's frequency offset (Hz) and level (V) per decimated sample, the
    last ``window_s`` of them kept (``offset_hz``, ``level_v``: carriers × window), and a call of
    ``decide(time_s)`` at every hop boundary once the window is full."""

    def __init__(self, settings: Um71ReceiverSettings, system_name: str, window_s: float, hop_s: float):
        s = settings
        self.carriers_hz = check_settings(s, system_name)
        self.settings = s
        self.decimation = max(1, round(s.fs_hz / BASEBAND_RATE_HZ))
        self.rate_hz = s.fs_hz / self.decimation
        self.window = math.ceil(window_s * self.rate_hz - 1e-9)
        self.hop = max(1, round(hop_s * self.rate_hz))
        self.low_pass = low_pass_design(s.fs_hz)
        count = self.carriers_hz.size
        self._lp_state = self.low_pass.initial_state(2 * count)
        self._cycles_per_sample = self.carriers_hz / s.fs_hz
        self.offset_hz = np.zeros((count, self.window))
        self.level_v = np.zeros((count, self.window))
        self._previous: Optional[np.ndarray] = None      # last decimated baseband sample per carrier
        self._decimated = 0                                # decimated samples so far
        self.dominance = 10.0 ** (DOMINANCE_DB / 20.0)

    def feed(self, t: float, e_coil: np.ndarray, decide: Callable[[float], None]) -> float:
        """One frame of coil EMF from ``t``; the largest carrier level at its end (V)."""
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
            self._take(np.angle(steps) * (self.rate_hz / (2.0 * np.pi)), np.abs(z), index[kept], decide)
        return float(np.abs(self._previous).max()) if self._previous is not None else 0.0

    def _take(self, offset_hz: np.ndarray, level_v: np.ndarray, sample_index: np.ndarray,
              decide: Callable[[float], None]) -> None:
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
                decide(float(sample_index[at]) / self.settings.fs_hz)
        self._append(offset_hz[:, start:], level_v[:, start:])

    def _append(self, offset_hz: np.ndarray, level_v: np.ndarray) -> None:
        m = offset_hz.shape[1]
        if not m:
            return
        if m >= self.window:
            self.offset_hz[:] = offset_hz[:, -self.window:]
            self.level_v[:] = level_v[:, -self.window:]
            return
        self.offset_hz[:, :-m] = self.offset_hz[:, m:]
        self.offset_hz[:, -m:] = offset_hz
        self.level_v[:, :-m] = self.level_v[:, m:]
        self.level_v[:, -m:] = level_v

    def carrier_to_decode(self) -> Optional[int]:
        """The index of the carrier this window decodes (module docstring), None: none."""
        hop_levels = self.level_v[:, -self.hop:].mean(axis=1)
        best = int(np.argmax(hop_levels))
        others = np.delete(hop_levels, best)
        if self.level_v[best].min() < self.settings.squelch_v or (
                others.size and hop_levels[best] < self.dominance * others.max()):
            return None
        return best


Key = Tuple[int, float]          # (code or word, carrier Hz)


class FailSafeDisplay:
    """The display rules (module docstring) on the decisions' (code, carrier) reads; ``shown``
    the key shown, None: no code."""

    def __init__(self, hold_s: float):
        self.hold_s = hold_s
        self.shown: Optional[Key] = None
        self._supported_s = 0.0
        self._pending: Optional[Key] = None
        self._pending_count = 0

    def decide(self, key: Optional[Key], time_s: float, at_most: Callable[[int, int], bool]) -> bool:
        """One decision's read (None: no code); ``at_most(a, b)``: code ``a`` permits nothing code
        ``b`` does not (the system's order, both of one block). Whether a new key is shown."""
        def below(a: Key, b: Key) -> bool:            # other carriers: other blocks, never comparable
            return a[1] == b[1] and at_most(a[0], b[0])
        changed = False
        if key is None:
            self._pending, self._pending_count = None, 0
        elif key == self.shown:
            self._supported_s = time_s
            self._pending, self._pending_count = None, 0
        elif self.shown is not None and below(key, self.shown):
            changed = self._show(key, time_s)                    # permits nothing more: at once
        else:
            if self.shown is not None and below(self.shown, key):
                self._supported_s = time_s                       # the shown permits nothing more: it stays
            self._pending_count = self._pending_count + 1 if key == self._pending else 1
            self._pending = key
            if self._pending_count >= CONFIRMATIONS:
                changed = self._show(key, time_s)
        if self.shown is not None and time_s - self._supported_s >= self.hold_s - 1e-9:
            self.shown = None                                    # nothing valid heard for the hold
        return changed

    def _show(self, key: Key, time_s: float) -> bool:
        self.shown, self._supported_s = key, time_s
        self._pending, self._pending_count = None, 0
        return True


@lru_cache(maxsize=16)
def tone_window_fit(window: int, rate_hz: float, tones_hz: Tuple[float, ...]) -> np.ndarray:
    """(1 + 2·len(tones), window) pseudo-inverse of a window's model of the frequency offset: a
    constant, then the cos and the sin of every tone, over ``window`` samples at ``rate_hz`` (the
    fit's time origin is the window's first sample: the receiver does not know the coder's
    phases). Shared, read-only: every receiver of a system at one rate fits with one matrix."""
    t = np.arange(window) / rate_hz
    angle = np.multiply.outer(t, 2.0 * np.pi * np.asarray(tones_hz))
    fit = np.linalg.pinv(np.hstack([np.ones((window, 1)), np.cos(angle), np.sin(angle)]))
    fit.flags.writeable = False
    return fit


@dataclass(frozen=True)
class Decision:
    """What one decision heard (diagnostics and tests)."""

    time_s: float
    carrier_hz: float                  # 0: no carrier decoded
    amplitudes: Optional[np.ndarray]   # each tone's or sub-frequency's fitted amplitude / its deviation
    code: int                          # the word or code read, 0: none

    @property
    def word(self) -> int:             # TVM-430's name for it
        return self.code


class Um71ReceiverCore(ABC):
    """What both TVM receivers do around their own reading of a window (``code_of``): the front
    end, the fit of the window's frequency offset (``fit``, a pseudo-inverse whose rows after the
    first are the cosines then the sines of the system's tones), the decision, the fail-safe
    display and the outputs. A subclass sets ``deviation_hz`` (a tone's amplitude unit) and may
    add outputs of its own in ``publish_extra``."""

    deviation_hz = 1.0
    no_code = 0

    def __init__(self, frame: int, settings: Um71ReceiverSettings, tvm, system_name: str, window_s: float,
                 hop_s: float, fit_of, hold_s: float):
        self.front = Um71FrontEnd(settings, system_name, window_s, hop_s)
        self.carriers_hz = self.front.carriers_hz
        self.tvm = tvm
        self.settings, self.frame = settings, frame
        self.rate_hz, self.window = self.front.rate_hz, self.front.window
        self.fit = fit_of(self.window, self.rate_hz)
        self.hold_s = hold_s
        self.display = FailSafeDisplay(self.hold_s)
        self._shown_reading = None
        self.last_decision: Optional[Decision] = None
        self.out = ReceiverOutputs()
        self._publish(0.0)

    def step(self, t: float, e_coil: np.ndarray, channel_faults=None) -> ReceiverOutputs:
        """One frame of coil EMF (``channel_faults`` is the digital receiver's input: ignored)."""
        self._publish(self.front.feed(t, e_coil, self._decide))
        return self.out

    @abstractmethod
    def code_of(self, amplitudes: np.ndarray) -> int:
        """The word or code the fitted amplitudes give, ``no_code`` for none (each system its own)."""

    def publish_extra(self, out: ReceiverOutputs, read) -> None:
        """Outputs of the system's own for a reading shown (none by default)."""

    def read_window(self, time_s: float) -> Decision:
        """What the current window gives (the system's module docstring): the carrier decoded,
        the tones' amplitudes, the code — one the system does not read is none."""
        best = self.front.carrier_to_decode()
        if best is None:
            return Decision(time_s, 0.0, None, self.no_code)
        coefficients = self.fit @ self.front.offset_hz[best]
        cos_sin = coefficients[1:].reshape(2, -1)
        amplitudes = np.hypot(cos_sin[0], cos_sin[1]) / self.deviation_hz
        code = self.code_of(amplitudes)
        if code != self.no_code and self.tvm.reading(code) is None:
            code = self.no_code
        return Decision(time_s, float(self.carriers_hz[best]), amplitudes, code)

    def _decide(self, time_s: float) -> None:
        decision = self.read_window(time_s)
        self.last_decision = decision
        out = self.out
        if decision.code == self.no_code:
            key = None
            if decision.carrier_hz:
                out.errors += 1
        else:
            key = (decision.code, decision.carrier_hz)
            out.decoded_codes += 1
        # the system's partial order (codes on different carriers: never comparable)
        if self.display.decide(key, time_s, self.tvm.at_most):
            self._shown_reading = self.tvm.reading(key[0])

    def _publish(self, level_v: float) -> None:
        out = self.out
        out.level_v = level_v
        out.relay = level_v >= self.settings.squelch_v
        shown = self.display.shown
        if shown is None:
            out.aspect, out.code, out.code_valid, out.free_blocks = sig.RED, self.no_code, False, 0
            out.v_permitted_mps = out.v_target_mps = 0.0
            out.target_distance_m = out.gradient_permille = out.word_carrier_hz = 0.0
            return
        code, carrier = shown
        read = self._shown_reading
        out.aspect, out.code, out.code_valid, out.free_blocks = read.aspect, code, True, read.free_blocks
        out.v_permitted_mps, out.v_target_mps = read.step_kmh / 3.6, read.next_kmh / 3.6
        self.publish_extra(out, read)
        out.word_carrier_hz = carrier
