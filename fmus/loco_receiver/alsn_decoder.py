"""The ALSN decoder and display of the locomotive receiver: the impulse relay's edges → code
cycles → the indication shown (core.py's module docstring: step 5, the display hold and the
display rule; docs/loco_receiver.md).

The signal chain (core.py) owns the filters and the relay's thresholds; it tells the decoder
each relay edge (:meth:`AlsnDecoder.edge`), raises the running pulse's levels
(``pulse_peak``: input-referred, ``pulse_drive``: the relay's own input) while the relay is up,
and at the end of every frame lets it settle a pending cycle and run the watchdog. The decoder
writes the indication into the receiver's output record it is given.
"""
from __future__ import annotations

from typing import Optional

from fmus.signalling import alsn
from fmus.signalling import aspects as sig

# a cycle whose pulses differ in level by more than this straddles an insulated joint (the
# feed end of one section against the entry end of the next, ≈ 10× apart, docs/sources.md#interference-at-insulated-joints)
LEVEL_SPREAD = 2.5
# a pulse whose relay input peaked below this × pick-up while the code itself (input-referred)
# was above it was marginal through the reduced gain: its cycle is not decoded
RELAY_MARGIN = 1.5
# how long into the pulse after a cycle its level is awaited (the envelope settles in ~30 ms)
PENDING_S = 0.05


class AlsnDecoder:
    """Decoder and display state of one ALSN receiver (its settings: train category, pick-up;
    ``short_min_s``: the shortest interval that is a code interval; ``cold_start_off_s``: see
    core.cold_start_off_s; ``inertia_s``: the display hold; ``v_max_mps``: the train's
    maximum speed; ``out``: the receiver's output record, written here)."""

    def __init__(self, settings, short_min_s: float, cold_start_off_s: float, inertia_s: float,
                 v_max_mps: float, out):
        self.settings = settings
        self._short_min_s = short_min_s
        self.cold_start_off_s = cold_start_off_s
        self.inertia_s = inertia_s
        self.v_max = v_max_mps
        self.out = out
        self.relay = False                              # the impulse relay: up or down
        self.started_s: Optional[float] = None          # when reception began (the first frame)
        self.pulse_peak = 0.0                           # the running pulse's input-referred peak
        self.pulse_drive = 0.0                          # peak of the relay's own (gain-controlled) input
        self.pending = None                             # (code, decide at, lowest, highest level)
        self._last_edge_s: Optional[float] = None
        self._last_rise_s: Optional[float] = None
        self._last_fall_s: Optional[float] = None
        self._cycle_start_s: Optional[float] = None
        self._short = 0
        self._implausible = False
        self._cycle_peaks = []
        self._after_gap = False
        self._boundary_peak: Optional[float] = None
        self._previous_cycle = alsn.NO_CODE
        self._previous_level = 0.0                       # pulse level of the previous valid cycle
        self._last_shown: Optional[int] = None          # last valid code shown, kept through a loss
        self._last_valid_s: Optional[float] = None
        self._supported_s: Optional[float] = None   # last cycle no more restrictive than the code shown
        self._contradictions = 0        # valid more restrictive cycles since then (not shown yet)
        self._publish_speeds()

    def edge(self, time_s: float, rising: bool) -> None:
        self._last_edge_s = time_s
        if not rising:
            self._last_fall_s = time_s
            self._cycle_peaks.append(self.pulse_peak)
            marginal = RELAY_MARGIN * self.settings.pick_up_v
            if self.pulse_drive < marginal <= self.pulse_peak:
                # the code is strong enough but the gain, still reduced after a strong feed end,
                # left the relay only just moving: its neighbours may have been lost, so the
                # cycle may under-count — never decode it (113 km/h past a joint: З read as КЖ).
                # A code that is itself weak is the relay's ordinary business.
                self._implausible = True
            self.pulse_peak = 0.0
            if self._last_rise_s is not None and not (alsn.PULSE_S[0] <= time_s - self._last_rise_s <= alsn.PULSE_S[1]):
                self._implausible = True          # a pulse split by noise, or carrier without keying
            self.pulse_drive = 0.0
            return
        if self._last_fall_s is None and self.started_s is not None \
                and time_s - self.started_s > self.cold_start_off_s:
            # relay off since reception began, for longer than a short interval can reach the
            # relay after a pulse's tail (cold_start_off_s): the tail of a long interval, so
            # this rise starts a cycle (saves one cycle of latency on a cold start; a cycle
            # begun mid-pattern could only under-count short intervals, but then showed З as
            # КЖ and made З wait two more cycles)
            self._cycle_start_s = time_s
            self._short = 0
            self._implausible = False
            self._cycle_peaks = []
        elif self._last_fall_s is not None:
            interval = time_s - self._last_fall_s
            if interval > alsn.LONG_INTERVAL_S:
                if self._cycle_start_s is not None:
                    self._cycle(-1 if self._implausible else self._short, time_s - self._cycle_start_s, time_s)
                self._cycle_start_s = time_s
                self._short = 0
                self._implausible = False
                # the level of the pulse before the boundary: a cycle whose pulses jump from it
                # (≈ 10× at a joint) began in another track circuit, possibly mid-pattern
                self._boundary_peak = self._cycle_peaks[-1] if self._cycle_peaks else None
                self._cycle_peaks = []
                # longer than any code's long interval: pulses were missed (a joint, the gain
                # recovering), so the cycle now starting may begin mid-pattern
                self._after_gap = interval > alsn.LONG_INTERVAL_MAX_S
            else:
                self._short += 1
                if interval < self._short_min_s:
                    self._implausible = True      # a dropout inside a pulse, not a code interval
        self._last_rise_s = time_s

    def _cycle(self, short_intervals: int, length_s: float, time_s: float) -> None:
        out = self.out
        code, kind = alsn.classify_cycle(short_intervals, length_s)
        out.code = code
        if code == alsn.NO_CODE:
            out.errors += 1
            self._previous_cycle = alsn.NO_CODE
            return
        out.decoded_codes += 1
        transmitter = 5 if kind == "KPT-5" else 7
        previous_transmitter = out.transmitter
        if out.transmitter and transmitter != out.transmitter:
            out.joints += 1
        out.transmitter = transmitter
        self._last_valid_s = time_s
        if out.code_valid and sig.restrictiveness(code) >= sig.restrictiveness(out.aspect):
            self._supported_s = time_s        # a cycle no more restrictive than the code shown
            self._contradictions = 0
        elif out.code_valid and not self._after_gap:
            # (a cycle begun after a gap may start mid-pattern and under-count: not news)
            self._contradictions += 1
        # compare with what is shown, or after a loss of code with the last code shown (as the
        # ATP does): only a cold start, with no code seen yet, takes a code after one cycle
        reference = out.aspect if out.code_valid else self._last_shown
        peaks = self._cycle_peaks
        # A cycle with a short interval and a valid period began at its pattern's first pulse:
        # begun at a later one it lacks at least the first pulse and interval (0.47 s) and is
        # shorter than any period window (KPT-7 З, the longest, 1.36 s, 1.43 s with 5 % drift,
        # against 1.47 s; tests/test_alsn.py). So it is whole however it began — after a gap, or
        # after the pulse of another track circuit at a joint — and only its own pulses (and the
        # one that ends it) must agree in level. Only a cycle without a short interval (КЖ) may
        # be a mid-pattern remnant (a З's last pulse and long interval): it keeps both rules.
        # Waiting for a second cycle after every joint would make a restrictive change met at a
        # joint up to 5.2 s late (docs/loco_receiver.md#latency-of-a-change).
        whole = short_intervals >= 1
        levels = peaks + ([self._boundary_peak] if self._boundary_peak is not None and not whole else [])
        clean = bool(peaks) and max(levels) <= LEVEL_SPREAD * max(min(levels), 1e-12) and (whole or not self._after_gap)
        # two identical cycles confirm each other only from the same track circuit: the same
        # transmitter type and levels within the spread (at 113 km/h a З cut by a joint read as
        # КЖ, and the next section's first, partly missed З read as КЖ too)
        level = max(peaks) if peaks else 0.0
        same_circuit = transmitter == previous_transmitter and self._previous_level > 0 and \
            max(level, self._previous_level) <= LEVEL_SPREAD * max(min(level, self._previous_level), 1e-12)
        confirmed = code == self._previous_cycle and same_circuit
        self._previous_level = level
        self.pending = None
        if confirmed:
            self._show(code)
        elif clean and (reference is None or sig.restrictiveness(code) <= sig.restrictiveness(reference)):
            # one cycle is enough, unless the pulse that ended it is from another track circuit
            # (the coils crossed a joint and the dropout passed for the long interval): decide
            # once that pulse's level is known
            self.pending = (code, time_s + PENDING_S, min(levels), max(levels))
        self._previous_cycle = code

    def _show(self, code: int) -> None:
        out = self.out
        if not (out.code_valid and out.aspect == code):
            self._supported_s = self._last_valid_s
            self._contradictions = 0
        out.aspect = code
        out.code_valid = True
        self._last_shown = code
        self._publish_speeds()

    def settle_pending(self, now_s: float) -> None:
        code, due, low, high = self.pending
        if self.relay and now_s < due:
            return
        level = self.pulse_peak if self.relay else (self._cycle_peaks[0] if self._cycle_peaks else 0.0)
        self.pending = None
        if max(high, level) <= LEVEL_SPREAD * max(min(low, level), 1e-12):
            self._show(code)

    def watchdog(self, now_s: float) -> None:
        out = self.out
        quiet = now_s - (self._last_edge_s if self._last_edge_s is not None else self.started_s)
        stale = now_s - (self._last_valid_s if self._last_valid_s is not None else self.started_s)
        # the decoder loses the code after 2 s without an edge or a valid cycle (kpt.h) and
        # starts afresh; the display holds what it shows (the equipment's inertia) until no
        # cycle has supported it for `inertia` — then no code: white, or red after red-yellow
        lost = quiet > alsn.CODE_TIMEOUT_S or stale > alsn.CODE_TIMEOUT_S
        if lost:
            self.pending = None
            if quiet > alsn.CODE_TIMEOUT_S:
                self._cycle_start_s = None
                self._short = 0
            self._previous_cycle = alsn.NO_CODE
        unsupported_s = now_s - self._supported_s if self._supported_s is not None else 0.0
        # the hold: no pulse for `inertia` (a loss of code), or pulses without a cycle of the
        # code shown for `inertia` + one cycle (after a loss the decoder needs a whole cycle:
        # at the wrong cam phase a short loss costs three KPT-7 cycles, 5.6 s, from the last
        # one); and valid cycles of a more restrictive code that cannot be shown yet (not
        # clean, not confirmed; two of them, as one may be cut by a joint) end it 2 s after
        # the last supporting cycle: without this an impulse-noise study run showed З for
        # 3.4 s after the code sent had turned КЖ (beyond the stated latency)
        cycle_s = (alsn.KPT5_WINDOW_S if out.transmitter == 5 else alsn.KPT7_WINDOW_S)[1]
        expired = quiet > self.inertia_s or unsupported_s > self.inertia_s + cycle_s \
            or (self._contradictions >= 2 and unsupported_s > alsn.CODE_TIMEOUT_S)
        # a clean cycle no more permissive than the code shown waits (PENDING_S at most) for the
        # level of the pulse that ends it: the code shown holds until that is settled, so the
        # display goes from the old code to the new one without white between (after a joint,
        # two restrictive cycles end the hold just as the second one is pending)
        if out.code_valid and expired and self.pending is None:
            out.aspect = sig.RED if out.aspect == sig.RED_YELLOW else sig.WHITE
            out.code_valid = False
            self._contradictions = 0
            self._publish_speeds()

    def _publish_speeds(self) -> None:
        out = self.out
        out.v_permitted_mps, out.v_target_mps, out.free_blocks = alsn.speeds_for(
            self.settings.train_category, out.aspect, self.v_max)
