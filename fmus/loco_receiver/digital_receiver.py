"""Locomotive receiver for the digital systems (ALS-EN, FIRE_DQPSK): coil EMF → amplitude
limiter → anti-alias low-pass → band-pass → symbol timing and I/Q correlation → differential
decision → framing and code check → acceptance → three channels voted 2-out-of-3 (
docs/sources.md#digital-generator-receiver-and-redundancy; no FMI here).

* **Front end.** Back-to-back zener limiter at ±`limiter` V (docs/sources.md#digital-generator-receiver-and-redundancy: КС133А), the
  6th-order Chebyshev low-pass at 500 Hz (1 dB ripple; the thesis' anti-alias filter, an
  analog design in python-control discretised with Tustin), then a digital band-pass at the
  carrier (Butterworth, 4th order, 10/3 of the symbol rate wide); both as second-order sections.
* **Symbol timing and correlation.** The transmitter's symbol clock is unknown. The baseband
  signal x·e^(−jωt) is integrated over one symbol (integrate-and-dump, running sums from a
  carried cumulative sum) at 8 candidate instants per symbol; each candidate keeps a running
  mean of |Z|² relative to the signal level over about 16 symbols (one observation counts at
  most twice the level, so an impulse cannot steer it; a level jump of 4× — a joint, the next
  track circuit's code on another symbol clock — restarts the search from the next symbol),
  and the receiver samples at the best one (after the first symbols, switching only when
  another is > 0.3 dB better: a window that straddles a phase jump loses energy, so the
  best instant is the symbol end, filter delays included). A re-choice by up to two
  candidates (¼ symbol) keeps the symbol count; a larger jump restarts the framing.
* **Squelch.** Symbols whose amplitude is below `min_level` are not decided (the framing
  restarts), so a dead channel shows no code rather than noise decisions.
* **Decision, framing, code check**: the system's framer (als_en.py, fire_dqpsk.py);
  **acceptance**: digital.Acceptor (track parity, one message towards restrictive, two
  identical towards permissive, block-parity rule, timeout after two lost messages).
* **2-out-of-3.** The three channels are identical hardware on the same coil signal, so they
  decode the same messages: the chain runs once and its result feeds every channel (exact,
  not an approximation). Per-channel faults (`channel_fault[i]`) act on a channel's output:
  1 failed and excluded by its self-test; 2 stuck at the most permissive command (a dangerous
  undetected fault); 3 silent without being detected. The command in force is one that two
  counted channels agree on, else none (redundancy.vote_2oo3).

Outputs follow the ALSN receiver's record (core.ReceiverOutputs): ``code`` is the system's
raw id (FIRE: command 1–16; ALS-EN: KLUB register 9–15), ``errors`` counts discarded words,
``decoded_codes`` accepted own-track messages, ``joints`` changes of block parity (sections
entered), ``relay`` carrier present (above the squelch).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Tuple

import cmath
import math

import numpy as np

from fmus.signalling import redundancy
from fmus.signalling import aspects as sig
from fmus.signalling.digital_messages import Acceptor, DigitalSystem, check_category, check_modem_rate
from fmus.dsp.filter_design import chebyshev_low_pass, sos_frame
from fmus.errors import FmuInputError
from fmus.loco_receiver import filters
from fmus.loco_receiver.core import CHANNELS, ReceiverOutputs, resolve_inertia_s
from fmus.sizes import DEFAULT_SAMPLE_RATE_HZ

ANTI_ALIAS_HZ, ANTI_ALIAS_ORDER, ANTI_ALIAS_RIPPLE_DB = 500.0, 6, 1.0
TIMING_CANDIDATES = 8
TIMING_AVERAGE = 1.0 / 16.0         # weight of a new |Z|² in a candidate's running mean
TIMING_SWITCH = 10 ** 0.03          # another candidate must be 0.3 dB better (a ¼-symbol error costs ~1 dB)
TIMING_DRIFT = 2                    # a re-choice by up to this many candidates keeps the symbol count
LEVEL_FAST, LEVEL_SLOW = 1.0 / 8.0, 1.0 / 32.0   # level averages over about one and four symbols
LEVEL_JUMP = 4.0                    # their ratio beyond this: a new signal, search the timing afresh
_NO_SYMBOLS = np.zeros(0, dtype=complex)
CHANNEL_OK, CHANNEL_FAILED, CHANNEL_STUCK_PERMISSIVE, CHANNEL_SILENT = 0, 1, 2, 3


@dataclass
class DigitalReceiverSettings:
    fs_hz: float = DEFAULT_SAMPLE_RATE_HZ
    carrier_hz: float = 0.0          # 0: the system's default
    train_category: str = "passenger"
    v_max_mps: float = 0.0           # 0: the system's speed for the category
    track_parity: int = 1
    limiter_v: float = 4.0           # 0: no limiter
    min_level_v: float = 0.1         # squelch, V at the coil: the ALSN relay's pick-up level (docs/digital_channels.md)
    filter_bandwidth_hz: float = 0.0  # 0: 10/3 × the symbol rate
    inertia_s: float = 0.0           # display hold, s; 0: none (core.DIGITAL_DEFAULT_HOLD_S, [U])


class SymbolClock:
    """Integrate-and-dump correlation at the best of several candidate symbol instants."""

    def __init__(self, fs_hz: float, carrier_hz: float, baud: float, frame: int):
        self.samples_per_symbol = fs_hz / baud
        self.window = int(round(self.samples_per_symbol))
        self.spacing = self.samples_per_symbol / TIMING_CANDIDATES
        self.omega = 2 * np.pi * carrier_hz / fs_hz
        self.oscillator = np.exp(-1j * self.omega * np.arange(frame))
        # running sum of the baseband signal per sample, in a ring long enough for one window
        # behind the oldest sample of a frame
        self.ring = np.zeros(self.window + 1 + frame, dtype=complex)
        self._steps = np.arange(frame)
        self.next_instant = TIMING_CANDIDATES                      # first instant with a full window
        self.metric = [0.0] * TIMING_CANDIDATES
        self.observed = 0
        self.level_fast = self.level_slow = 0.0
        self.chosen = 0
        self.last_taken = -TIMING_CANDIDATES

    def push(self, x: np.ndarray, first: int) -> Tuple[np.ndarray, list, bool]:
        """(correlations at the chosen instants in this frame, the sample index each ends at,
        True if the timing was re-chosen after them)."""
        n, ring, size = x.size, self.ring, self.ring.size
        rotation = cmath.exp(-1j * self.omega * first)
        running = ring[(first - 1) % size] + np.cumsum(x * self.oscillator[:n] * rotation)
        start = first % size
        if start + n <= size:
            ring[start:start + n] = running
        else:
            ring[(first + self._steps[:n]) % size] = running
        last = first + n - 1
        symbols, ends, retimed = [], [], False
        instant, spacing, window = self.next_instant, self.spacing, self.window
        while math.floor(instant * spacing) <= last:
            end = math.floor(instant * spacing)
            z = ring[end % size] - ring[(end - window) % size]
            power = z.real * z.real + z.imag * z.imag
            c = instant % TIMING_CANDIDATES
            metric = self.metric
            # the signal level over about one symbol, and over four: a jump (a joint: the next
            # track circuit's code, 10× weaker and on another symbol clock) restarts the search
            self.level_fast += LEVEL_FAST * (power - self.level_fast)
            self.level_slow += LEVEL_SLOW * (power - self.level_slow)
            if not 1.0 / LEVEL_JUMP < self.level_fast / max(self.level_slow, 1e-30) < LEVEL_JUMP:
                self.level_slow = self.level_fast
                self.observed = 0
            # candidates compare relative powers, each capped at twice the level, so neither a
            # level change nor an impulse can steer the choice
            relative = min(power / max(self.level_fast, 1e-30), 2.0)
            # a plain mean over the first symbols after a (re)start, a running mean after that
            weight = max(TIMING_AVERAGE, TIMING_CANDIDATES / (TIMING_CANDIDATES + self.observed))
            metric[c] += weight * (relative - metric[c])
            self.observed += 1
            # a small re-choice of timing keeps the symbol count: an instant less than ¾ symbol
            # after the last one taken belongs to the same symbol
            if c == self.chosen and instant - self.last_taken >= TIMING_CANDIDATES - TIMING_DRIFT:
                symbols.append(z)
                ends.append(end)
                self.last_taken = instant
            instant += 1
        if instant == self.next_instant:
            return _NO_SYMBOLS, ends, False
        self.next_instant = instant
        best = max(range(TIMING_CANDIDATES), key=self.metric.__getitem__)
        if self.metric[best] > TIMING_SWITCH * self.metric[self.chosen] or self.observed <= 2 * TIMING_CANDIDATES:
            step = (best - self.chosen) % TIMING_CANDIDATES
            retimed = min(step, TIMING_CANDIDATES - step) > TIMING_DRIFT   # a jump, not a drift
            self.chosen = best
        return np.array(symbols, dtype=complex), ends, retimed

    def amplitude(self, symbols: np.ndarray) -> np.ndarray:
        """Carrier amplitude (V) of a correlation over one whole symbol."""
        return 2.0 * np.abs(symbols) / self.window


@dataclass
class ChannelState:
    fault: int = CHANNEL_OK
    command: Optional[int] = None


class DigitalReceiverCore:
    def __init__(self, system: DigitalSystem, frame: int, settings: DigitalReceiverSettings):
        s = settings
        check_category(s.train_category)
        self.carrier_hz, bandwidth, order = filters.band_pass_design(s, system)
        check_modem_rate(system, self.carrier_hz, s.fs_hz)
        if s.track_parity not in (0, 1):
            raise FmuInputError(f"parameter track_parity: {s.track_parity} (0 even track, 1 odd track)")
        for name, value in (("limiter", s.limiter_v), ("min_level", s.min_level_v),
                            ("filter_bandwidth", s.filter_bandwidth_hz), ("inertia", s.inertia_s)):
            if value < 0:
                raise FmuInputError(f"parameter {name}: must not be negative, got {value}")
        self.system, self.settings, self.frame = system, s, frame
        self.baud = system.baud(self.carrier_hz)
        if bandwidth >= 2 * self.carrier_hz:
            raise FmuInputError(f"parameter filter_bandwidth: {bandwidth:g} Hz must be below twice the carrier")
        self.anti_alias = chebyshev_low_pass(ANTI_ALIAS_HZ, ANTI_ALIAS_ORDER, ANTI_ALIAS_RIPPLE_DB, s.fs_hz)
        self.band_pass = filters.band_pass(self.carrier_hz, bandwidth, order, s.fs_hz)
        self._aa_state = self.anti_alias.initial_state()
        self._bp_state = self.band_pass.initial_state()
        self.clock = SymbolClock(s.fs_hz, self.carrier_hz, self.baud, frame)
        self.framer = system.framer(s.track_parity)
        self.message_s = system.message_s(self.carrier_hz)
        self.acceptor = Acceptor(system, s.track_parity, self.message_s)
        # the display holds the command shown through a loss of code (docs/loco_receiver.md)
        self.inertia_s = resolve_inertia_s(s.inertia_s, digital=True)
        self._held: Optional[int] = None             # command displayed (in force or held)
        self._held_support_s = -np.inf               # last message confirming it
        self.channels = [ChannelState() for _ in range(CHANNELS)]
        self.most_permissive = max(system.commands(), key=system.rank)
        self._level = 0.0
        self._block: Optional[int] = None
        self._indications = {}
        self._voted_for = None
        self._vote_result: Optional[int] = None
        self.out = ReceiverOutputs()
        self.channel_codes = self.out.channel_codes
        self._publish(None)

    def step(self, t: float, e_coil: np.ndarray, channel_faults=(0, 0, 0)) -> ReceiverOutputs:
        """One frame of coil EMF; ``channel_faults[i]`` is channel i's fault (CHANNEL_OK …)."""
        s = self.settings
        first = round(t * s.fs_hz)
        x = np.asarray(e_coil, dtype=float)
        if s.limiter_v > 0:
            x = np.clip(x, -s.limiter_v, s.limiter_v)
        x, self._aa_state = sos_frame(self.anti_alias.sos, x, self._aa_state)
        x, self._bp_state = sos_frame(self.band_pass.sos, x, self._bp_state)
        symbols, ends, retimed = self.clock.push(x, first)
        if symbols.size:
            amplitude = self.clock.amplitude(symbols)
            self._level = float(amplitude[-1])
            if (amplitude < s.min_level_v).any():
                self.framer.reset()                      # squelched: no decisions on noise
                keep = np.flatnonzero(amplitude < s.min_level_v)[-1] + 1
                symbols, ends = symbols[keep:], ends[keep:]
            for index, message, quality in self.framer.push(symbols):
                decided_s = (ends[index] + 1) / s.fs_hz   # when its last symbol was integrated
                self.acceptor.expire(decided_s)
                self._restrict_held(message)
                self.acceptor.push(decided_s, message, quality)
        if retimed:
            self.framer.reset()
        now_s = (first + x.size) / s.fs_hz
        self.acceptor.expire(now_s)
        self._publish(self._hold(self._vote(channel_faults), now_s))
        return self.out

    def _restrict_held(self, message) -> None:
        """While the display holds a command through a loss, a message of this track more
        restrictive than it is shown at once (the acceptance rules would wait for two)."""
        if self.inertia_s > 0 and self.acceptor.command is None and self._held is not None and message is not None \
                and message.track == self.settings.track_parity \
                and self.system.rank(message.command) < self.system.rank(self._held):
            self._held = message.command

    def _hold(self, command: Optional[int], now_s: float) -> Optional[int]:
        """The command displayed: the one voted, else — when the code was lost, not when the
        channels disagree — the last one displayed while the loss is shorter than the inertia
        (counted from the last message confirming it), else none."""
        if command is not None:
            self._held = command
            self._held_support_s = self.acceptor.confirmed_s if command == self.acceptor.command else now_s
            return command
        if self.acceptor.command is not None:
            # the code is there but the channels do not agree (faults): no hold, no code
            self._held = None
            return None
        if self._held is not None and self.inertia_s > 0 and now_s - self._held_support_s <= self.inertia_s:
            return self._held
        return None

    def _indication(self, command: int):
        found = self._indications.get(command)
        if found is None:
            found = self._indications[command] = self.system.indication(command, self.settings.train_category)
        return found

    def _vote(self, faults) -> Optional[int]:
        command = self.acceptor.command
        key = (command, int(faults[0]), int(faults[1]), int(faults[2]))
        if key == self._voted_for:
            return self._vote_result
        self._voted_for = key
        for index, channel in enumerate(self.channels):
            channel.fault = int(faults[index])
            channel.command = {CHANNEL_OK: command, CHANNEL_FAILED: None, CHANNEL_SILENT: None,
                               CHANNEL_STUCK_PERMISSIVE: self.most_permissive}.get(channel.fault, None)
            self.channel_codes[index] = 0 if channel.command is None else self._indication(channel.command).code
        healthy = [c.fault != CHANNEL_FAILED for c in self.channels]
        self._vote_result = redundancy.vote_2oo3([c.command for c in self.channels], healthy)
        return self._vote_result

    def _publish(self, command: Optional[int]) -> None:
        s, out, acceptor = self.settings, self.out, self.acceptor
        out.level_v = self._level
        out.relay = self._level >= s.min_level_v
        out.errors = acceptor.rejected
        out.decoded_codes = acceptor.accepted
        out.foreign = acceptor.foreign
        if acceptor.block is not None and acceptor.block != self._block:
            if self._block is not None:
                out.joints += 1
            self._block = acceptor.block
        if command is None:
            last = self._held if self._held is not None else acceptor.last_command
            stop = last is not None and self._indication(last).aspect in (sig.RED_YELLOW, sig.RED)
            out.aspect = sig.RED if stop else sig.WHITE
            out.code, out.code_valid, out.free_blocks = 0, False, 0
            out.v_permitted_mps = out.v_target_mps = (20.0 if stop else 40.0) / 3.6
            return
        ind = self._indication(command)
        ceiling = ind.permitted_kmh / 3.6
        if s.v_max_mps > 0:
            ceiling = min(ceiling, s.v_max_mps)
        out.aspect, out.code, out.code_valid, out.free_blocks = ind.aspect, ind.code, True, ind.free_blocks
        out.v_permitted_mps = ceiling
        out.v_target_mps = min(ind.target_kmh / 3.6, ceiling)
