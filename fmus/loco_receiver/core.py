"""Locomotive ALSN receiver: coil EMF frame → band-pass → gain control → envelope → impulse
relay → decoder (alsn_decoder.py, with the display hold and rule below; no FMI here).

Signal chain, vectorised over the frame with carried state (so any frame length gives the
same result, docs/loco_receiver.md#signal-chain-corepy-filterspy):

1. **Band-pass** at the carrier (filters.py), second-order sections (sosfilt's routine) with carried state.
2. **Gain control** on the in-band signal (docs/sources.md#interference-at-insulated-joints: the receiver is overloaded up to 10× by
   the code current at the feed end of a section and recovers in 0.6–1.5 s after the joint; an
   out-of-band interferer must not desensitise it, so the level is taken after the band-pass).
   Instant attack, slow release in the log domain: G[n] = min(G_req[n], G[n−1] + r·Δt) with
   G_req = 20·log10(limit/|x|) above the limit, 0 dB below. Solved for a whole frame as a
   running minimum (G[n] = (n+1)·c + min(G_prev, cummin(G_req[m] − (m+1)·c))), no per-sample
   loop. About 1 s recovery for the paper's 3.5 V → 0.28 V step with the defaults
   (docs/loco_receiver.md).
3. **Envelope**: full-wave rectification, 2nd-order low-pass, × π/2 (peak-equivalent).
4. **Impulse relay** with pick-up and drop-out thresholds (hysteresis), vectorised by
   forward-filling the last decided state.
5. **Decoder** (firmware kpt.h rules, docs/sources.md#alsn-decoder-rules): edges of the relay are events; an
   interval longer than 0.35 s ends a cycle; the number of short intervals gives З (2), Ж (1),
   КЖ (0, period doubled); the period classifies KPT-5 (1.47–1.73 s) or KPT-7 (1.73–1.99 s),
   other lengths are invalid (counted in ``errors``). Added plausibility (our choice, against
   pulses split by noise into a more permissive count): every pulse must last 0.17–0.50 s and
   every short interval at least 0.06 s, else the cycle is invalid. No relay edge for 2 s, or
   no valid cycle for 2 s (kpt.h's later "incorrect after 2000 ms"): the decoder has lost the
   code and starts afresh.

Display hold (the locomotive equipment's inertia, docs/loco_receiver.md#display-hold-equipment-inertia):
the indication shown, with ``code_valid``, holds through a loss of code shorter than
``inertia`` (5.5 s, docs/sources.md#receiver-inertia-and-latencies): it falls to the no-code
indication (white, or red after red-yellow) when no relay edge came for ``inertia`` (a loss),
or no cycle of the code shown or a more permissive one for ``inertia`` + one cycle (pulses
without a valid cycle: after a loss the decoder needs a whole cycle, and a short loss at the
wrong cam phase costs three KPT-7 cycles, 5.6 s), or — restrictive news — 2 s after the last
such cycle once two valid cycles of a more restrictive code that cannot be shown yet have
come (valid restrictive cycles must not keep an old code alive: an old code outlives a
restrictive change by at most one cycle + 2 s, within the stated latency). A restrictive code
that can be shown replaces the held one at once (the display rule below).

Display rule (fail-safe, our choice, docs/loco_receiver.md): a code no more permissive than
the one shown — or, after a loss of code, than the last one shown — is shown after one valid
*clean* cycle — its pulses, and the pulse that ends it, within a factor 2.5 of each other in
level (a cycle that straddles an insulated joint mixes two track circuits' codes and levels);
a cycle without a short interval (КЖ) also needs the pulse just before it within that factor
and must not have started after a gap longer than any code's long interval (after a joint or
lost pulses it may begin mid-pattern: a З's last pulse and long interval read as КЖ). A cycle
with a short interval and a valid period began at its pattern's first pulse (begun at a later
one it is shorter than any period window), so a gap or a joint before it does not matter —
anything else only after two identical consecutive valid cycles (kpt.h's rule). Only a cold
start (no code seen yet) takes any code after one cycle, which keeps the acquisition within
two cycles + 0.5 s from any cam phase.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from fmus.dsp.filter_design import SampleSosFilter, SosFilter, sos_frame

from fmus.signalling import alsn
from fmus.signalling import aspects as sig
from fmus.train_categories import TRAIN_CATEGORIES
from fmus.errors import FmuInputError
from fmus.loco_receiver import filters
from fmus.loco_receiver.alsn_decoder import RELAY_MARGIN, AlsnDecoder
from fmus.reductions import largest, smallest
from fmus.sizes import DEFAULT_SAMPLE_RATE_HZ
from fmus.units import MPS_PER_KMH

LEVEL_RELEASE_S = 1.0
# the carrier step simulated for the pick-up delay (s): longer than any chain's delay
COLD_START_PROBE_S = 0.5
# display hold of a digital receiver whose `inertia` is 0: none [U] (docs/loco_receiver.md). The
# sources give no inertia for the digital equipment, and a receiver cannot tell a joint's dropout
# from the next section's code: a hold bridging FIRE_DQPSK's re-acquisition at joints showed the
# previous section's command after the train had entered a more restrictive one, up to 0.3 s
# beyond the stated latency (a wrong-side indication); without a hold the display shows no code
# while it re-acquires, which is restrictive
DIGITAL_DEFAULT_HOLD_S = 0.0


def pick_up_delay_s(band_pass: SosFilter, envelope_lp: SosFilter, carrier_hz: float, fs_hz: float,
                    pick_up_v: float) -> float:
    """How long the chain takes from a carrier switched on at the coil to the relay's pick-up
    (s), for a code of RELAY_MARGIN × pick-up (a weaker one is marginal, and takes longer):
    the band-pass's rise at the carrier and the envelope low-pass's, simulated once on a
    carrier step (the later of two carrier phases)."""
    amplitude_v = RELAY_MARGIN * pick_up_v
    t = np.arange(int(round(COLD_START_PROBE_S * fs_hz))) / fs_hz
    delays = []
    for phase_rad in (0.0, np.pi / 2.0):
        band, _ = sos_frame(band_pass.sos, amplitude_v * np.sin(2.0 * np.pi * carrier_hz * t + phase_rad),
                            band_pass.initial_state())
        envelope, _ = sos_frame(envelope_lp.sos, np.abs(band), envelope_lp.initial_state())
        above = np.flatnonzero(envelope * (np.pi / 2.0) > pick_up_v)
        delays.append(t[above[0]] if above.size else COLD_START_PROBE_S)
    return float(max(delays))


def cold_start_off_s(pick_up_delay: float) -> float:
    """The relay off since reception began for longer than this is the tail of a long interval
    (docs/loco_receiver.md, display rule): the longest off stretch a cold start can see
    anywhere else is the tail of a pulse too short to raise the relay (shorter than the
    pick-up delay: a longer one is the carrier step itself up to its end), the short interval
    after it (0.12 s + drift) and the next pulse's pick-up delay."""
    return alsn.SHORT_INTERVAL_S * (1.0 + alsn.TIMING_DRIFT) + 2.0 * pick_up_delay


def resolve_inertia_s(inertia_s: float, digital: bool) -> float:
    """A receiver's display hold (s): its `inertia` parameter, or for 0 the default of its kind
    (the ALSN equipment's inertia; DIGITAL_DEFAULT_HOLD_S)."""
    if inertia_s > 0:
        return inertia_s
    return DIGITAL_DEFAULT_HOLD_S if digital else alsn.EQUIPMENT_INERTIA_S


# the digital receiver's redundant channels (2-out-of-3); every receiver reports one code per channel
CHANNELS = 3


@dataclass
class ReceiverSettings:
    carrier_hz: float = 0.0                # 0: filters.ALSN_DEFAULT_CARRIER_HZ
    fs_hz: float = DEFAULT_SAMPLE_RATE_HZ
    train_category: str = "passenger"
    v_max_mps: float = 0.0                 # 0: the category's maximum (aspects.CATEGORY_MAX_KMH)
    filter_order: int = 3
    filter_bandwidth_hz: float = 0.0       # 0: 0.4 × carrier
    agc_limit_v: float = 0.5               # input amplitude above which the gain is reduced
    agc_recovery_db_per_s: float = 10.0
    pick_up_v: float = 0.12                # relay picks up above this envelope (input-referred)
    drop_out_v: float = 0.08
    inertia_s: float = 0.0                 # 0: the equipment's (resolve_inertia_s); the longest code loss the display bridges


@dataclass
class ReceiverOutputs:
    aspect: int = sig.WHITE
    code: int = alsn.NO_CODE               # last decoded cycle (0: none or invalid)
    code_valid: bool = False
    v_permitted_mps: float = 0.0
    v_target_mps: float = 0.0
    free_blocks: int = 0
    level_v: float = 0.0                   # carrier amplitude at the coil (input-referred envelope)
    errors: int = 0                        # invalid cycles
    decoded_codes: int = 0                 # valid cycles decoded
    transmitter: int = 0                   # 5 or 7 (KPT type of the last valid cycle), 0 none
    joints: int = 0                        # KPT type changes (a new track circuit, kpt.h)
    relay: bool = False
    # the digital receiver's per-channel commands (raw ids, 0 none) and messages of the other
    # track discarded; an ALSN receiver has neither and reports zeros
    channel_codes: np.ndarray = field(default_factory=lambda: np.zeros(CHANNELS, dtype=np.int64))
    foreign: int = 0
    # TVM430's word shown: its target distance (m from the entry of the word's block), gradient
    # (‰, + uphill) and the carrier it came from (Hz); 0 for every other system and no word
    target_distance_m: float = 0.0
    gradient_permille: float = 0.0
    word_carrier_hz: float = 0.0


class LocoReceiverCore:
    def __init__(self, frame: int, settings: ReceiverSettings):
        s = settings
        carrier_hz, bandwidth, order = filters.band_pass_design(s)
        alsn.check_carrier_and_rate(carrier_hz, s.fs_hz, "parameter ")
        if s.train_category not in TRAIN_CATEGORIES:
            raise FmuInputError(f"parameter train_category: {s.train_category!r} is not one of "
                                f"{', '.join(TRAIN_CATEGORIES)}")
        if not 1 <= s.filter_order <= 8:
            raise FmuInputError(f"parameter filter_order: {s.filter_order} (1..8)")
        for name, value in (("agc_limit", s.agc_limit_v), ("agc_recovery", s.agc_recovery_db_per_s),
                            ("pick_up", s.pick_up_v), ("drop_out", s.drop_out_v)):
            if not value > 0:
                raise FmuInputError(f"parameter {name}: must be positive, got {value}")
        if s.inertia_s < 0:
            raise FmuInputError(f"parameter inertia: must not be negative, got {s.inertia_s}")
        if s.drop_out_v >= s.pick_up_v:
            raise FmuInputError(f"parameter drop_out: {s.drop_out_v} V must be below pick_up {s.pick_up_v} V")
        if bandwidth >= 2 * carrier_hz:
            raise FmuInputError(f"parameter filter_bandwidth: {bandwidth:g} Hz must be below twice the carrier")
        self.settings = s
        self.carrier_hz = carrier_hz
        self.frame = frame
        self.dt = 1.0 / s.fs_hz
        self.band_pass = filters.band_pass(carrier_hz, bandwidth, order, s.fs_hz)
        self.envelope_lp = filters.envelope_low_pass(filters.default_envelope_corner(carrier_hz), s.fs_hz)
        self._bp_state = self.band_pass.initial_state()
        self._env_state = self.envelope_lp.initial_state()
        # a build with one sample per frame filters in floats (the same samples as sosfilt)
        self._sample_filters = (SampleSosFilter(self.band_pass.sos),
                                SampleSosFilter(self.envelope_lp.sos)) if frame == 1 else None
        self._gain_db = 0.0
        self._ramp = (np.arange(frame) + 1) * (s.agc_recovery_db_per_s * self.dt)
        self._index = np.arange(frame)
        self._level_step = float(np.exp(-self.dt / LEVEL_RELEASE_S))
        self._level_growth = self._level_step ** -np.arange(frame, dtype=float)   # d^-m
        self._held = 0.0
        self.out = ReceiverOutputs()
        self.decoder = AlsnDecoder(
            s, short_min_s=alsn.short_interval_min_s(filters.default_envelope_corner(carrier_hz)),
            cold_start_off_s=cold_start_off_s(pick_up_delay_s(self.band_pass, self.envelope_lp, carrier_hz,
                                                              s.fs_hz, s.pick_up_v)),
            inertia_s=resolve_inertia_s(s.inertia_s, digital=False),
            v_max_mps=s.v_max_mps if s.v_max_mps > 0 else sig.CATEGORY_MAX_KMH[s.train_category] * MPS_PER_KMH,
            out=self.out)

    @property
    def inertia_s(self) -> float:
        """The display hold in force (s): the `inertia` parameter, or the equipment's."""
        return self.decoder.inertia_s

    # ---- signal chain -------------------------------------------------------------------------
    def _gain_control(self, x: np.ndarray):
        """(gain-controlled signal, linear gain per sample or a scalar when constant, |x| when
        the signal is x itself, else None)."""
        s = self.settings
        magnitude = np.abs(x)
        peak = largest(magnitude)
        if peak <= s.agc_limit_v:
            if self._gain_db >= 0.0:
                return x, 1.0, magnitude                    # the usual case: no overload, full gain
            gain_db = np.minimum(self._gain_db + self._ramp[:x.size], 0.0)   # recovering
        else:
            # agc_limit_v > 0 (checked when the core is made): the log of a positive ratio never warns
            required = np.where(magnitude > s.agc_limit_v,
                                20.0 * np.log10(s.agc_limit_v / np.maximum(magnitude, 1e-30)), 0.0)
            ramp = self._ramp[:x.size]
            gain_db = ramp + np.minimum(self._gain_db, np.minimum.accumulate(required - ramp))
        self._gain_db = float(gain_db[-1])
        gain = 10.0 ** (gain_db / 20.0)
        return x * gain, gain, None

    def _level(self, input_envelope: np.ndarray) -> float:
        """Peak-hold of the input-referred envelope with a 1 s exponential release, so the level
        reads the code amplitude, not the instant value: held = d^(N−1)·max(prev·d, max(e[m]·d^−m))."""
        n = input_envelope.size
        d = self._level_step
        self._held = d ** (n - 1) * max(self._held * d, largest(input_envelope * self._level_growth[:n]))
        return self._held

    def _relay_states(self, envelope: np.ndarray, relay_up: bool):
        """(relay state per sample or None when it stays as it is (``relay_up``) for the whole
        frame, the envelope's maximum)."""
        s = self.settings
        low, high = smallest(envelope), largest(envelope)
        if relay_up:
            if low >= s.drop_out_v:
                return None, high
        elif high <= s.pick_up_v:
            return None, high
        decided = np.where(envelope > s.pick_up_v, 1, np.where(envelope < s.drop_out_v, 0, -1))
        where = np.where(decided >= 0, self._index[:envelope.size], -1)
        last = np.maximum.accumulate(where)
        return np.where(last >= 0, decided[np.maximum(last, 0)] == 1, relay_up), high

    def step(self, t: float, e_coil: np.ndarray, channel_faults=None) -> ReceiverOutputs:
        """One frame of coil EMF. ``channel_faults`` is the digital receiver's per-channel fault
        input (digital_receiver.py); the ALSN receiver is one channel without it, so it is ignored."""
        s = self.settings
        decoder = self.decoder
        if decoder.started_s is None:
            decoder.started_s = t
        x = np.asarray(e_coil, dtype=float)
        if self._sample_filters is not None:
            if x.size != 1:
                raise ValueError(f"LocoReceiverCore built for one sample per frame stepped with {x.size}")
            return self._step_sample(t, x.item(0))
        band, self._bp_state = sos_frame(self.band_pass.sos, x, self._bp_state)
        scaled, gain, magnitude = self._gain_control(band)
        envelope, self._env_state = sos_frame(self.envelope_lp.sos, np.abs(scaled) if magnitude is None else magnitude,
                                              self._env_state)
        envelope *= np.pi / 2.0
        # the relay compares the gain-controlled envelope; thresholds are input-referred at 0 dB
        relay, drive_max = self._relay_states(envelope, decoder.relay)
        constant_gain = isinstance(gain, float)
        level = envelope / gain if not constant_gain else envelope   # input-referred: comparable across gains
        if relay is not None and (relay[0] != decoder.relay or not (relay[0] == relay).all()):
            changes = np.flatnonzero(relay != np.concatenate([[decoder.relay], relay[:-1]]))
            first = round(t * s.fs_hz)
            starts = np.concatenate([[0], changes]) if changes[0] > 0 else changes
            peaks = np.maximum.reduceat(level, starts)
            drives = np.maximum.reduceat(envelope, starts)
            segment = 0 if changes[0] > 0 else -1            # peaks[segment] = the stretch before an edge
            for n in changes:
                if segment >= 0 and decoder.relay:
                    decoder.pulse_peak = max(decoder.pulse_peak, float(peaks[segment]))
                    decoder.pulse_drive = max(decoder.pulse_drive, float(drives[segment]))
                decoder.edge((first + n) * self.dt, bool(relay[n]))
                decoder.relay = bool(relay[n])
                segment += 1
            if decoder.relay:
                decoder.pulse_peak = max(decoder.pulse_peak, float(peaks[segment]))
                decoder.pulse_drive = max(decoder.pulse_drive, float(drives[segment]))
        elif decoder.relay:
            decoder.pulse_peak = max(decoder.pulse_peak, drive_max / gain if constant_gain else largest(level))
            decoder.pulse_drive = max(decoder.pulse_drive, drive_max)
        if decoder.pending is not None:
            decoder.settle_pending(t + x.size * self.dt)
        decoder.watchdog(t + x.size * self.dt)
        out = self.out
        out.level_v = self._level(level)
        out.relay = decoder.relay
        return out

    def _step_sample(self, t: float, e_coil_v: float) -> ReceiverOutputs:
        """``step`` for a build with one sample per frame, in Python floats: the frame path's
        operations on its one sample, without two dozen numpy calls on one-element arrays."""
        s = self.settings
        decoder = self.decoder
        band_pass, envelope_lp = self._sample_filters
        band = band_pass(e_coil_v)
        magnitude = abs(band)
        if magnitude <= s.agc_limit_v and self._gain_db >= 0.0:
            gain = 1.0                                  # the usual case: no overload, full gain
            envelope = envelope_lp(magnitude) * (np.pi / 2.0)
            level = envelope
        else:                                           # as _gain_control, on one sample
            ramp = self._ramp.item(0)
            if magnitude <= s.agc_limit_v:
                self._gain_db = min(self._gain_db + ramp, 0.0)       # recovering
            else:
                required = 20.0 * math.log10(s.agc_limit_v / max(magnitude, 1e-30))
                self._gain_db = ramp + min(self._gain_db, required - ramp)
            gain = 10.0 ** (self._gain_db / 20.0)
            envelope = envelope_lp(abs(band * gain)) * (np.pi / 2.0)
            level = envelope / gain
        relay = decoder.relay
        if relay:
            if envelope < s.drop_out_v:
                relay = envelope > s.pick_up_v
        elif envelope > s.pick_up_v:
            relay = True
        if relay != decoder.relay:
            decoder.edge(round(t * s.fs_hz) * self.dt, relay)
            decoder.relay = relay
        if relay:
            decoder.pulse_peak = max(decoder.pulse_peak, level)
            decoder.pulse_drive = max(decoder.pulse_drive, envelope)
        end_s = t + self.dt
        if decoder.pending is not None:
            decoder.settle_pending(end_s)
        decoder.watchdog(end_s)
        self._held = max(self._held * self._level_step, level)     # _level of one sample
        out = self.out
        out.level_v = self._held
        out.relay = relay
        return out
