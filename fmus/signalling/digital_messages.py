"""What the digital cab-signal systems share (docs/digital_channels.md): the message
model, the interface a system implements (ALS-EN in als_en.py, the thesis' FIRE_DQPSK in
fire_dqpsk.py), and the receiver's acceptance rules. No FMI and no signal processing here.

A **message** carries a system command plus two parity bits the wayside adds for protection
(docs/sources.md#als-en, ALS-EN): the parity of the track (a code induced from the adjacent track of a
double-track line is discarded) and of the block section (a code leaking from the next section
across a failed insulated joint, or from under the tail of the train ahead, cannot make the
display more permissive while the own section's code is still being received).

What a decoded command means to the ATP (our reading of the sources, docs/digital_channels.md):

* ``free_blocks`` — free block sections ahead; when below :data:`FREE_BLOCKS_OPEN` the section
  after them is occupied, so the train must stop at the end of the last free one;
* ``permitted_kmh`` — the ceiling from now on (the category's maximum, or a release speed
  such as 20 km/h when moving on a red);
* ``target_kmh`` — the speed for passing the next signal (0: stop at it).
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import List, Optional, Tuple

import numpy as np

from fmus.signalling import aspects as sig
from fmus.train_categories import TRAIN_CATEGORIES
from fmus.errors import FmuInputError

FREE_BLOCKS_OPEN = 6          # "up to 6" (ALS-EN) / "≥ 6" (Table 2.1): no stop known beyond
TIMEOUT_MESSAGES, TIMEOUT_MARGIN_S = 2, 0.1        # acceptance timeout (Acceptor)
QUALITY_MIN = 0.25                                  # a clear message (Acceptor)
LATENCY_MESSAGES, LATENCY_MARGIN_S = 2, 0.2        # stated decoding latency (docs/scenarios.md#results-summaryjson)


def stated_latency_s(message_s: float) -> float:
    return LATENCY_MESSAGES * message_s + LATENCY_MARGIN_S


JOINT_BRIDGE_MIN_S = 3.0      # the shortest ATP bridging of a code dropout (atp_allowance_s)


def atp_allowance_s(message_s: float) -> float:
    """How long an ATP should bridge a loss of code with the last valid one (its
    ``decoding_latency``): the stated latency plus two messages, and at least
    JOINT_BRIDGE_MIN_S. At a joint the old command times out and the next section's code comes
    on another symbol clock: timing, frame lock and two identical messages (a command after a
    loss is never taken on one message, Acceptor). FIRE_DQPSK's dropouts at joints measured
    1.3–2.3 s at 100 km/h in the shipped system (ALS-EN's long messages bridge the joint
    without a dropout), hence 3.0 s for FIRE_DQPSK; ALS-EN 6.1 s."""
    return max(stated_latency_s(message_s) + 2 * message_s, JOINT_BRIDGE_MIN_S)


@dataclass(frozen=True)
class Message:
    command: int              # system command id
    track: int                # track parity 0/1
    block: int                # block-section parity 0/1


@dataclass(frozen=True)
class Indication:
    code: int                 # raw id reported on the `code` port
    aspect: int               # aspect enumeration, docs/interfaces.md#locoreceiver-locoreceiverfmu
    free_blocks: int
    permitted_kmh: float      # ceiling from now on
    target_kmh: float         # speed for passing the next signal


Decoded = Tuple[int, Optional[Message], float]   # (index of the symbol that completed it, message or None, quality)


class Framer(ABC):
    """Symbol correlations → decoded messages (None for a word discarded by the code check or
    a lost alignment), each with the index, among the pushed symbols, of the symbol that
    completed it, and its quality: the smallest decision margin of its symbols, normalised
    to 0 (on a decision boundary) … 1 (on the constellation point)."""

    @abstractmethod
    def push(self, symbols: np.ndarray) -> List[Decoded]:
        ...

    @abstractmethod
    def reset(self) -> None:
        """Forget the symbol history (the symbol timing was re-chosen)."""

    previous: Optional[complex] = None

    def _joined(self, symbols: np.ndarray):
        """(the last symbol of the previous push followed by these, pushed index of the symbol
        ending the first phase difference), or None when there is no difference yet."""
        first = 0 if self.previous is not None else 1
        if self.previous is not None:
            symbols = np.concatenate([[self.previous], symbols])
        if symbols.size:
            self.previous = symbols[-1]
        return (symbols, first) if symbols.size >= 2 else None


class DigitalSystem(ABC):
    name: str
    carrier_hz: float             # default carrier
    message_symbols: int          # symbols per message cycle
    decode_lag_symbols: int = 0   # symbols after a message's last one before it is decoded

    @abstractmethod
    def baud(self, carrier_hz: float) -> float:
        """Symbol rate at a carrier (ALS-EN: a fixed number of carrier cycles per symbol)."""

    @abstractmethod
    def increments(self, message: Message) -> np.ndarray:
        """Phase increment (rad) of each symbol of one message cycle."""

    @abstractmethod
    def command_for(self, free_blocks: int) -> int:
        """The command a plain-line automatic block sends with this many free sections ahead."""

    @abstractmethod
    def indication(self, command: int, category: str) -> Indication:
        ...

    @abstractmethod
    def commands(self) -> Tuple[int, ...]:
        ...

    @abstractmethod
    def framer(self, track_parity: int) -> Framer:
        ...

    def command_of_code(self, code: int) -> Optional[int]:
        """The command a raw code id (the coder's ``code_tx``) stands for, None for no code;
        where the id is ambiguous, the most permissive reading."""
        return code if code > 0 else None

    def rank(self, command: int) -> tuple:
        """Higher is more permissive: aspect, then free blocks, then the speeds."""
        ind = self.indication(command, "passenger")
        return sig.restrictiveness(ind.aspect), ind.free_blocks, ind.target_kmh, ind.permitted_kmh

    def check_command(self, command: int, where: str) -> None:
        if command not in self.commands():
            raise FmuInputError(f"{where}: command {command} is not one of the {self.name} commands "
                                f"({min(self.commands())}…{max(self.commands())})")

    def message_s(self, carrier_hz: float) -> float:
        return self.message_symbols / self.baud(carrier_hz)


def check_category(category: str) -> None:
    if category not in TRAIN_CATEGORIES:
        raise FmuInputError(f"parameter train_category: {category!r} is not one of "
                            f"{', '.join(TRAIN_CATEGORIES)}")


def check_modem_rate(system: DigitalSystem, carrier_hz: float, fs_hz: float, where: str = "parameter ") -> None:
    """The sample rate must carry the carrier (Nyquist with room for the receiver's 500 Hz
    anti-alias filter) and give every symbol enough samples for its correlation."""
    baud = system.baud(carrier_hz)
    if not 100.0 <= carrier_hz <= 400.0:
        raise FmuInputError(f"{where}carrier: {carrier_hz:g} Hz is outside the 100…400 Hz band of the "
                            f"{system.name} modem")
    if fs_hz < 4.0 * carrier_hz or fs_hz < 1000.0:
        raise FmuInputError(f"{where}fs: {fs_hz:g} Hz cannot carry a {carrier_hz:g} Hz {system.name} carrier "
                            f"(needs ≥ max(4 × carrier, 1000 Hz))")
    if fs_hz / baud < 16:
        raise FmuInputError(f"{where}fs: {fs_hz:g} Hz gives {fs_hz / baud:.1f} samples per {baud:g} Bd symbol "
                            f"(needs ≥ 16)")


class Acceptor:
    """The receiver's acceptance rules, common to both digital systems (our design, fail-safe):

    * a message from the other track is discarded (counted in ``foreign``);
    * a message no more permissive than the command in force takes effect at once (one
      message); anything more permissive, and anything while no command is in force (a cold
      start or after a loss of code), only after two identical consecutive messages. After a
      loss the last accepted command is no reference: the code sent may have become more
      restrictive while the messages were lost, and the impulse-noise study found single noise
      words "no more permissive than the last one" taken at once and shown above the code sent
      (6 events in 3·10⁵ messages, docs/noise_immunity.md), so they must be confirmed;
    * a more permissive message of the *other* block parity does not count while the command
      in force (of this parity) is still being confirmed: a code leaking from the next section
      across a failed joint, or from under the tail of the train ahead, cannot win while the
      own section's code is still there. At a real joint the old code stops, times out, and
      the new one is then taken after two identical messages. (Equal or more restrictive
      messages of the new section are taken at once, which is what a joint usually brings.)
    * only a *clear* message (every symbol decided at least a quarter of its decision margin
      away from a boundary: ``quality`` ≥ 0.25) may accept a more permissive command or
      confirm the command in force; a restrictive one is taken whatever its quality, but an
      unclear one keeps the replaced command's confirmation time (the impulse-noise study found
      a noise word, restrictive against the command in force but more permissive than the
      code just sent, restarting the timeout and shown past the stated latency). Noise
      passes the code check now and then (1 in 64 random words is a Fire word); the noise
      study found such words confirming an old command, or pairing into a permissive one, a
      few times per 10⁵ messages at −16 dB before this rule;
    * no confirming message of the command in force for two message periods + 0.1 s → no
      code (the ATP then applies its no-code rules). One lost message is bridged; and since a
      changed command is sent from the next message boundary on, an old command can never be
      shown for longer than the stated latency (docs/scenarios.md#results-summaryjson: two messages + 0.2 s) after the
      change, even when every message after it is lost.
    """

    def __init__(self, system: DigitalSystem, track_parity: int, message_s: float):
        self.system = system
        self.track = track_parity
        self.message_s = message_s
        self.timeout_s = TIMEOUT_MESSAGES * message_s + TIMEOUT_MARGIN_S
        self.command: Optional[int] = None       # in force
        self.block: Optional[int] = None
        self.last_command: Optional[int] = None  # last accepted, kept through a loss (no-code display)
        self.candidate: Optional[Message] = None
        self.confirmed_s = -np.inf
        self.accepted = 0
        self.rejected = 0
        self.foreign = 0

    def push(self, time_s: float, message: Optional[Message], quality: float = 1.0) -> None:
        """``quality``: the word's worst symbol decision margin, 0 (on a boundary) … 1 (on a
        constellation point)."""
        if message is None:
            self.rejected += 1
            self.candidate = None
            return
        if message.track != self.track:
            self.foreign += 1
            self.candidate = None
            return
        self.accepted += 1
        permissive = self.command is None or self.system.rank(message.command) > self.system.rank(self.command)
        clear = quality >= QUALITY_MIN
        if message.command == self.command and message.block == self.block:
            if clear:
                self.confirmed_s = time_s
        elif not permissive:
            # taken at once; an unclear word (possibly noise) does not restart the timeout: it
            # cannot keep anything shown longer than the command it replaces would have been
            self._take(message, time_s if clear else self.confirmed_s)
        elif clear and self.candidate == message and (self.command is None or message.block == self.block):
            self._take(message, time_s)
        self.candidate = message if clear else None

    def _take(self, message: Message, time_s: float) -> None:
        self.command, self.block, self.last_command = message.command, message.block, message.command
        self.confirmed_s = time_s

    def expire(self, now_s: float) -> None:
        if self.command is not None and now_s - self.confirmed_s > self.timeout_s:
            self.command = None
