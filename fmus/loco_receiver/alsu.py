"""Locomotive receiver for ALSU: coil EMF → six tone channels → level detection → "exactly two
tones" → minimum duration → display with a hold (no FMI here; docs/loco_receiver.md#alsu).

* **Channels.** One band-pass per tone, Butterworth, designed in python-control and run as
  second-order sections (fmus/dsp/filter_design.py): order and width follow from the tone plan
  (:func:`channel_design`). The tones are 50 Hz apart and the traction harmonics lie half-way,
  25 Hz from the tones on either side; a prototype of order 4 (8th-order band-pass, four
  sections) 10 Hz wide takes ±25 Hz down by 56 dB and ±50 Hz (the next tone) by 80 dB, and
  its envelope settles in about 0.2 s, a tenth of the 2 s an aspect change may take. The width
  is corrected for the Tustin map's compression at the tone (ω0T/sin ω0T: 6 % at 375 Hz), so
  every channel is 10 Hz wide at −3 dB.
* **Level detection.** Each channel's output full-wave rectified, a 2nd-order low-pass at half
  the channel width (its envelope's own bandwidth), × π/2 to read the peak; a tone is present
  above ``pick_up`` and absent below ``drop_out`` (hysteresis, per channel).
* **Exactly two tones.** Two present tones are a code (the code table's pair); none is a loss of
  code; one, three or more tones, or a reserved pair, are no code at all: the most restrictive
  indication, never a permissive one.
* **Minimum duration** (the thesis' remedy for a filter ringing after an impulse, which a
  threshold alone does not stop): a state is acted on only once it has lasted
  MIN_DURATION_S (0.5 s) — a code no more permissive than the one shown, or a garbled state
  (shown as no code) — or PERMISSIVE_DURATION_S (1.0 s) for a more permissive code, and for
  any code while none is shown (a cold start, after a loss). A channel rings for about 0.35 s
  (to 1 % of its peak) after an impulse, and a code change passes through one or three tones
  for up to 0.4 s as one tone fades and the next rises: both shorter than the minimum.
* **Hold** (the equipment's inertia): the display holds the code shown for ``inertia``
  (DISPLAY_HOLD_S, 1.0 s) after its two tones, or those of a more permissive code (the code
  sent may have become more permissive: it keeps the code shown alive until it is shown itself,
  as in ALSN), were last heard, whatever else is heard meanwhile — nothing (the ≈ 1 m null zone
  at a joint, bridged at any speed above 10 km/h), a garbled state or a more restrictive code
  not yet shown — and then shows no code (white; red after code 1). A
  loss thus reaches the cab within 1.0 s + the channels' decay, within the 2 s; and impulses
  that keep breaking a new, more restrictive code into pieces shorter than its minimum
  duration cannot keep the old code shown (the noise study found that without this rule).
* **Readings per category**: the code table's (fmus/signalling/alsu.py): `v_permitted`,
  `v_target`, `free_blocks`, the aspect; `code` is the code shown (0 none).

Everything runs on a whole frame (six sosfilt calls and one on the six envelopes, the
hysteresis by forward filling) and carries its state; decisions are taken at the sample a
state reached its duration, so any frame length gives the same outputs. A build with one
sample per frame filters in Python floats (SampleSosFilter, sosfilt's samples bit for bit).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional

import numpy as np
import scipy        # scipy.signal loads at its first use, a design (SciPy loads submodules lazily)

from fmus.dsp.filter_design import SampleSosFilter, SosFilter, sections, sos_frame
from fmus.errors import FmuInputError
from fmus.loco_receiver.core import ReceiverOutputs
from fmus.signalling import alsu
from fmus.signalling import aspects as sig
from fmus.signalling.digital_messages import check_category
from fmus.sizes import DEFAULT_SAMPLE_RATE_HZ

CHANNEL_ORDER = 4                  # Butterworth prototype order of each channel (a 8th-order band-pass)
CHANNEL_BANDWIDTH_HZ = 10.0        # −3 dB width of each channel
MIN_DURATION_S = 0.5               # a restrictive (or equal) code, or a garbled state, is acted on after this
PERMISSIVE_DURATION_S = 1.0        # a more permissive code, or any code while none is shown
DISPLAY_HOLD_S = alsu.EQUIPMENT_INERTIA_S   # no tone at all: the code shown holds this long [U]
_WEIGHTS = 1 << np.arange(alsu.TONE_COUNT)
_NONE, _GARBLED = 0, -1            # classification of a tone word besides a code number


@dataclass
class AlsuReceiverSettings:
    fs_hz: float = DEFAULT_SAMPLE_RATE_HZ
    train_category: str = "passenger"
    v_max_mps: float = 0.0                 # 0: the category's top under ALSU (alsu.CATEGORY_MAX_KMH)
    filter_bandwidth_hz: float = 0.0       # 0: CHANNEL_BANDWIDTH_HZ
    pick_up_v: float = 0.12                # a tone is present above this (coil EMF, peak)
    drop_out_v: float = 0.08               # ... and absent below this
    inertia_s: float = 0.0                 # 0: DISPLAY_HOLD_S
    codes_file: str = ""                   # empty: the shipped code table


def channel_design(tone_hz: float, fs_hz: float, bandwidth_hz: float = CHANNEL_BANDWIDTH_HZ,
                   order: int = CHANNEL_ORDER) -> SosFilter:
    """The band-pass of one tone channel: Butterworth of ``order`` about the tone, ``bandwidth``
    wide at −3 dB after discretisation (the analog width widened by ω0T/sin ω0T, which the
    pre-warped Tustin map takes back at the tone)."""
    theta = 2.0 * math.pi * tone_hz / fs_hz
    analog_width = bandwidth_hz * theta / math.sin(theta)
    zeros, poles, gain = scipy.signal.lp2bp_zpk(*scipy.signal.buttap(order), wo=1.0, bw=analog_width / tone_hz)
    return sections((zeros, poles, gain), 2.0 * math.pi * tone_hz, fs_hz, tone_hz)


def envelope_design(bandwidth_hz: float, fs_hz: float) -> SosFilter:
    """2nd-order Butterworth low-pass at half the channel width: what a channel passes of a
    tone's amplitude changes, no more."""
    corner = bandwidth_hz / 2.0
    return sections(scipy.signal.buttap(2), 2.0 * math.pi * corner, fs_hz, corner)


def resolve_inertia_s(inertia_s: float) -> float:
    return inertia_s if inertia_s > 0 else DISPLAY_HOLD_S


class AlsuReceiverCore:
    def __init__(self, frame: int, settings: AlsuReceiverSettings, table: Optional[alsu.CodeTable] = None):
        s = settings
        check_category(s.train_category)
        for name, value in (("pick_up", s.pick_up_v), ("drop_out", s.drop_out_v)):
            if not value > 0:
                raise FmuInputError(f"parameter {name}: must be positive, got {value}")
        if s.drop_out_v >= s.pick_up_v:
            raise FmuInputError(f"parameter drop_out: {s.drop_out_v} V must be below pick_up {s.pick_up_v} V")
        for name, value in (("filter_bandwidth", s.filter_bandwidth_hz), ("inertia", s.inertia_s)):
            if value < 0:
                raise FmuInputError(f"parameter {name}: must not be negative, got {value}")
        self.alsu = alsu.AlsuSystem(table) if table is not None else alsu.system(s.codes_file or None)
        tones = np.array(self.alsu.table.tones_hz)
        bandwidth = s.filter_bandwidth_hz or CHANNEL_BANDWIDTH_HZ
        spacing = float(np.min(np.diff(tones)))
        if bandwidth >= spacing:
            raise FmuInputError(f"parameter filter_bandwidth: {bandwidth:g} Hz must be below the tone spacing "
                                f"{spacing:g} Hz")
        if s.fs_hz < 8.0 * tones.max():
            raise FmuInputError(f"parameter fs: {s.fs_hz:g} Hz is below 8× the highest ALSU tone {tones.max():g} Hz")
        self.settings, self.frame = s, frame
        self.dt = 1.0 / s.fs_hz
        self.channels = [channel_design(float(f), s.fs_hz, bandwidth) for f in tones]
        self.envelope = envelope_design(bandwidth, s.fs_hz)
        self._channel_states = [c.initial_state() for c in self.channels]
        self._envelope_state = self.envelope.initial_state(alsu.TONE_COUNT)
        self._present = np.zeros(alsu.TONE_COUNT, dtype=bool)
        self._rows = np.arange(alsu.TONE_COUNT)[:, None]
        self._index = np.arange(frame)
        self._sample_filters = ([SampleSosFilter(c.sos) for c in self.channels],
                                [SampleSosFilter(self.envelope.sos) for _ in tones]) if frame == 1 else None
        self.hold_samples = round(resolve_inertia_s(s.inertia_s) * s.fs_hz)
        self.min_samples = round(MIN_DURATION_S * s.fs_hz)
        self.permissive_samples = round(PERMISSIVE_DURATION_S * s.fs_hz)
        # classification of every 6-bit tone word: a code number, _NONE or _GARBLED (one tone,
        # three or more, or a reserved pair); and the code number of every pair, reserved or not
        pairs = self.alsu.table.code_of_tones()
        self._class_of_word = np.full(1 << alsu.TONE_COUNT, _GARBLED, dtype=np.int64)
        self._class_of_word[0] = _NONE
        self._pair_of_word = np.zeros(1 << alsu.TONE_COUNT, dtype=np.int64)
        for a in range(alsu.TONE_COUNT):
            for b in range(a + 1, alsu.TONE_COUNT):
                word = (1 << a) | (1 << b)
                self._pair_of_word[word] = int(pairs[a, b])
                code = self.alsu.command_of_code(int(pairs[a, b]))
                if code is not None:
                    self._class_of_word[word] = code
        self.v_max_kmh = s.v_max_mps * 3.6 if s.v_max_mps > 0 else alsu.CATEGORY_MAX_KMH[s.train_category]
        self._word = 0
        self._class = _NONE
        self._since = 0                    # sample index the current classification began at
        self._acted = True                 # the current classification has been acted on (or needs nothing)
        self._shown: Optional[int] = None
        self._unheard_since: Optional[int] = None   # sample the code shown was last heard until
        self._last_shown: Optional[int] = None
        self._level = 0.0
        self._level_step = float(np.exp(-self.dt / 1.0))
        self._level_growth = self._level_step ** -np.arange(frame, dtype=float)      # d^−m
        self.out = ReceiverOutputs()
        self._publish()

    # ---- signal chain -------------------------------------------------------------------------
    def step(self, t: float, e_coil: np.ndarray, channel_faults=None) -> ReceiverOutputs:
        """One frame of coil EMF (``channel_faults`` is the digital receiver's input: ignored)."""
        s = self.settings
        first = round(t * s.fs_hz)
        x = np.asarray(e_coil, dtype=float)
        if self._sample_filters is not None:
            if x.size != 1:
                raise ValueError(f"AlsuReceiverCore built for one sample per frame stepped with {x.size}")
            return self._step_sample(first, x.item(0))
        n = x.size
        bands = np.empty((alsu.TONE_COUNT, n))
        for tone, channel in enumerate(self.channels):
            bands[tone], self._channel_states[tone] = sos_frame(channel.sos, x, self._channel_states[tone])
        envelope, self._envelope_state = sos_frame(self.envelope.sos, np.abs(bands), self._envelope_state)
        envelope *= np.pi / 2.0
        present = self._hysteresis(envelope)
        words = _WEIGHTS @ present if present is not None else None
        if words is None or (words == self._word).all():
            self._advance(first + n)
        else:
            changes = np.flatnonzero(words != np.concatenate([[self._word], words[:-1]]))
            for index in changes.tolist():
                self._advance(first + index)
                self._new_word(int(words[index]), first + index)
            self._advance(first + n)
        # peak-hold with a 1 s release, sample by sample: held = d^(n−1)·max(held·d, max(e[m]·d^−m))
        d = self._level_step
        self._level = d ** (n - 1) * max(self._level * d, float((envelope.max(axis=0) * self._level_growth[:n]).max()))
        self._publish()
        return self.out

    def _hysteresis(self, envelope: np.ndarray) -> Optional[np.ndarray]:
        """Per channel and sample, tone present (pick-up / drop-out); None when no channel
        changes over the frame."""
        s = self.settings
        high, low = envelope.max(axis=1), envelope.min(axis=1)
        if not (np.where(self._present, low < s.drop_out_v, high > s.pick_up_v)).any():
            return None
        decided = np.where(envelope > s.pick_up_v, 1, np.where(envelope < s.drop_out_v, 0, -1))
        where = np.where(decided >= 0, self._index[:envelope.shape[1]], -1)
        last = np.maximum.accumulate(where, axis=1)
        present = np.where(last >= 0, decided[self._rows, np.maximum(last, 0)] == 1, self._present[:, None])
        self._present = present[:, -1].copy()
        return present.astype(np.int64)

    def _step_sample(self, first: int, e_coil_v: float) -> ReceiverOutputs:
        """``step`` for one sample in Python floats: the frame path's operations on its sample."""
        s = self.settings
        channels, envelopes = self._sample_filters
        word, peak = 0, 0.0
        present = self._present
        for tone in range(alsu.TONE_COUNT):
            level = envelopes[tone](abs(channels[tone](e_coil_v))) * (np.pi / 2.0)
            peak = max(peak, level)
            if present[tone]:
                if level < s.drop_out_v:
                    present[tone] = level > s.pick_up_v
            elif level > s.pick_up_v:
                present[tone] = True
            word |= int(present[tone]) << tone
        if word != self._word:
            self._advance(first)
            self._new_word(word, first)
        self._advance(first + 1)
        self._level = max(self._level * self._level_step, peak)
        self._publish()
        return self.out

    # ---- decisions ----------------------------------------------------------------------------
    @property
    def pair_code(self) -> int:
        """Diagnostics: the code number of the two tones present now (reserved codes included),
        0 when not exactly two tones are present."""
        return int(self._pair_of_word[self._word])

    def _supports(self, kind: int) -> bool:
        """Whether hearing ``kind`` keeps the code shown alive: the code itself or a more
        permissive one (the code sent may have become more permissive; ALSN's rule too)."""
        return kind > 0 and self._shown is not None and (
            kind == self._shown or self.alsu.rank(kind) > self.alsu.rank(self._shown))

    def _new_word(self, word: int, at: int) -> None:
        self._word = word
        kind = int(self._class_of_word[word])
        if kind != self._class:
            if self._supports(kind):
                self._unheard_since = None
            elif self._shown is not None and (self._unheard_since is None or self._supports(self._class)):
                self._unheard_since = at        # nothing supports the code shown from here on
            self._class, self._since, self._acted = kind, at, False
            if kind > 0 and kind == self._shown:
                self._acted = True              # the code shown again: nothing to decide

    def _due(self) -> Optional[int]:
        """Sample index at which the current classification is acted on, None: nothing to do.
        A loss of every tone needs nothing here: the hold (_expiry) ends it."""
        if self._acted:
            return None
        kind = self._class
        if kind == _NONE:
            return None
        if kind == _GARBLED:
            return self._since + self.min_samples if self._shown is not None else None
        if self._shown is None or self.alsu.rank(kind) > self.alsu.rank(self._shown):
            return self._since + self.permissive_samples
        return self._since + self.min_samples

    def _expiry(self) -> Optional[int]:
        """Sample index at which the code shown has not been heard for the hold, whatever was
        heard meanwhile (none, garbled, or other codes too short to be shown: impulses that
        keep breaking a new code must not keep an old one alive)."""
        if self._shown is None or self._unheard_since is None:
            return None
        return self._unheard_since + self.hold_samples

    def _advance(self, until: int) -> None:
        """Act on what falls due before sample ``until``: the current classification's
        duration reached, or the code shown unheard for the hold."""
        out = self.out
        while True:
            due, expiry = self._due(), self._expiry()
            if expiry is not None and expiry < until and (due is None or expiry <= due):
                self._shown, self._unheard_since = None, None      # the hold is over: no code
                continue
            if due is None or due >= until:
                return
            self._acted = True
            kind = self._class
            if kind > 0:
                self._shown = self._last_shown = kind
                self._unheard_since = None
                out.decoded_codes += 1
            else:
                out.errors += 1
                self._shown, self._unheard_since = None, None

    def _publish(self) -> None:
        out, s = self.out, self.settings
        out.level_v = self._level
        out.relay = bool(self._word)
        if self._shown is None:
            stop = self._last_shown is not None and self.alsu.indication(self._last_shown, s.train_category).aspect \
                == sig.RED_YELLOW
            out.aspect = sig.RED if stop else sig.WHITE
            out.code, out.code_valid, out.free_blocks = 0, False, 0
            out.v_permitted_mps = out.v_target_mps = (20.0 if stop else 40.0) / 3.6
            return
        ind = self.alsu.indication(self._shown, s.train_category)
        ceiling = min(ind.permitted_kmh, self.v_max_kmh)
        out.aspect, out.code, out.code_valid, out.free_blocks = ind.aspect, ind.code, True, ind.free_blocks
        out.v_permitted_mps = ceiling / 3.6
        out.v_target_mps = min(ind.target_kmh, ceiling) / 3.6
