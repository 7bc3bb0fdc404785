"""The thesis' 16-command system on one track (docs/sources.md#fire-code-and-pi4-dqpsk): commands → Fire (12,6) words →
π/4-DQPSK at 175 Hz, 15 Bd — plus the frame synchronisation the thesis leaves out (our design).

Frame synchronisation. The Fire code is cyclic, so a receiver that reads a repeated word one
symbol late decodes another *valid* command (tests/test_fire_code.py). Each frame therefore
starts with a **sync symbol whose phase increment is 0**, an increment the data never uses
(data increments are odd multiples of π/4). A frame is 7 symbols: sync + 6 data symbols
(12 bits), 0.467 s at 15 Bd. The receiver

* takes a phase difference as a sync when |Δφ| < π/8 (the boundary half-way to the nearest
  data increment), else as the data dibit of its quadrant;
* locks on when two syncs arrive exactly 7 symbols apart; then keeps the frame positions
  (flywheel): the 6 symbols after a sync are data whatever they look like, and a word is
  decoded only when the syncs before *and* after it were both seen where due. A sync missed
  where due loses the words on both sides of it; two in a row drop the lock (a slip or a
  long hit), and nothing is decoded until it locks again. (A first version dropped the lock
  at any sync out of place: the noise study showed it lost 70 % of the messages at an
  Eb/N0 of 8 dB, because the sync lies only π/4 from the data increments);
* discards words that fail the Fire check (reported as ``None``); what is accepted, and when,
  is the common rule of digital.Acceptor.

A slip can thus never yield a rotated word, and a steady unmodulated tone (all increments 0:
sync symbols only, no data) never yields a command.

Commands: Table 2.1 of the thesis (16 rows, speeds high-speed/passenger/freight as printed;
unreadable cells marked [U]). Information word (6 bits, the thesis leaves the map to us):
command − 1 in the low 4 bits, the track parity in bit 4 and the block-section parity in bit 5
(the thesis has no protection against adjacent tracks and sections; ALS-EN has, docs/sources.md#als-en —
we use the two spare bits for it). The code's d_min = 4 holds between any two words.

What a command means to the ATP (docs/digital_channels.md): the cab signal, the free blocks,
and Table 2.1's *permissible* speed of the train's category as the speed for passing the next
signal (0 with no free block: stop there); the ceiling is the category's top speed of the
table (cmd 16), or 20 km/h on commands 1 and 3 (moving on a red / flashing white). Our plain-
line automatic block sends, by free blocks 0…6: 2 (КЖ), 7, 12, 13, 14, 15, 16.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional, Tuple

import numpy as np

from fmus.signalling import dqpsk, fire_code
from fmus.signalling import aspects as sig
from fmus.signalling.digital_messages import Decoded, DigitalSystem, Framer, Indication, Message

CARRIER_HZ = 175.0
BAUD = 15.0
DATA_SYMBOLS = fire_code.N_BITS // 2
FRAME_SYMBOLS = DATA_SYMBOLS + 1
SYNC_TOLERANCE_RAD = np.pi / 8
LOCK_MISSES = 2               # syncs missed in a row before the lock is dropped


@dataclass(frozen=True)
class Command:
    number: int
    free_blocks: int
    aspect: str                  # cab signal
    permitted_kmh: tuple         # (high-speed, passenger, freight) where printed, else repeated
    controlled_kmh: tuple


# the ALS thesis' Table 2.1, docs/sources.md#fire-code-and-pi4-dqpsk (OCR-damaged cells as read in the digest; [U] where the digest is unsure)
COMMANDS = {c.number: c for c in (
    Command(1, 0, "red", (20, 20, 20), (0, 0, 0)),
    Command(2, 0, "red-yellow", (20, 20, 20), (0, 0, 0)),
    Command(3, 0, "white-flashing", (20, 20, 20), (0, 0, 0)),
    Command(4, 1, "yellow", (35, 35, 35), (20, 20, 20)),
    Command(5, 1, "yellow", (55, 55, 55), (40, 40, 40)),
    Command(6, 2, "yellow", (55, 55, 55), (40, 40, 40)),
    Command(7, 1, "yellow", (100, 100, 80), (80, 80, 60)),
    Command(8, 2, "yellow", (100, 100, 80), (80, 80, 60)),
    Command(9, 2, "yellow", (100, 100, 80), (80, 80, 60)),
    Command(10, 3, "yellow", (120, 120, 90), (100, 100, 70)),
    Command(11, 3, "green", (140, 140, 100), (120, 120, 90)),
    Command(12, 2, "green", (140, 140, 100), (120, 120, 90)),
    Command(13, 3, "green", (160, 160, 100), (140, 140, 90)),
    Command(14, 4, "green", (240, 160, 100), (220, 140, 90)),
    Command(15, 5, "green", (260, 160, 100), (240, 140, 90)),
    Command(16, 6, "green", (280, 160, 100), (260, 140, 90)),
)}


_ASPECT = {"red": sig.RED, "red-yellow": sig.RED_YELLOW, "white-flashing": sig.WHITE,
           "yellow": sig.YELLOW, "green": sig.GREEN}
_CATEGORY_COLUMN = {"high_speed": 0, "passenger": 1, "freight": 2}
COMMAND_OF_FREE_BLOCKS = (2, 7, 12, 13, 14, 15, 16)
RELEASE_COMMANDS = (1, 3)          # moving on a red or a flashing white: 20 km/h from now on


def info_word(command: int, track: int, block: int) -> int:
    if command not in COMMANDS:
        raise ValueError(f"command {command} is not one of 1…{len(COMMANDS)}")
    return (command - 1) | (track & 1) << 4 | (block & 1) << 5


def frame_increments(command: int, track: int = 1, block: int = 0) -> np.ndarray:
    """Phase increments of one frame: the sync symbol (0) and the 6 dibits of the code word."""
    bits = fire_code.to_bits(fire_code.encode(info_word(command, track, block)))
    dibits = bits[0::2] * 2 + bits[1::2]
    return np.concatenate([[0.0], dqpsk.INCREMENT_OF_DIBIT[dibits]])


def transmit(commands: List[int], fs_hz: float, amplitude: float = 1.0, start_phase: float = 0.0,
             carrier_hz: float = CARRIER_HZ, baud: float = BAUD, track: int = 1, block: int = 0) -> np.ndarray:
    """Samples of consecutive frames, one per command (a reference symbol first)."""
    increments = np.concatenate([frame_increments(c, track, block) for c in commands])
    return dqpsk.modulate_increments(increments, fs_hz, carrier_hz, baud, amplitude, start_phase)


class FireFramer(Framer):
    """Frame synchronisation on the sync symbol, then the Fire check (module docstring)."""

    def __init__(self):
        self.reset()

    def reset(self) -> None:
        self.previous: Optional[complex] = None
        self.since_sync: Optional[int] = None     # acquisition: symbols since the last sync seen
        self.locked = False
        self.position = 0                         # locked: symbols since the expected sync
        self.leading_sync = False                 # locked: the sync opening this frame was seen
        self.misses = 0
        self.data: List[int] = []
        self.quality = 1.0

    def push(self, symbols: np.ndarray) -> List[Decoded]:
        joined = self._joined(symbols)
        if joined is None:
            return []
        symbols, first = joined
        difference = np.abs(np.angle(symbols[1:] * np.conj(symbols[:-1])))
        syncs = (difference < SYNC_TOLERANCE_RAD).tolist()
        dibits = dqpsk.decide(symbols).tolist()
        # decision margins, 0 on a boundary … 1 on the point: a sync against ±π/8, data
        # (odd multiples of π/4) against the nearest multiple of π/2
        sync_margin = (1.0 - difference / SYNC_TOLERANCE_RAD).tolist()
        data_margin = (np.abs(np.mod(difference, np.pi / 2) - np.pi / 4) / (np.pi / 4))
        data_margin = (1.0 - data_margin).tolist()
        messages: List[Decoded] = []
        for index, (sync, dibit) in enumerate(zip(syncs, dibits), start=first):
            if self.locked:
                self._locked(index, sync, dibit, messages, sync_margin[index - first], data_margin[index - first])
            elif sync:
                if self.since_sync == FRAME_SYMBOLS:      # two syncs a frame apart: locked
                    self.locked, self.position, self.leading_sync, self.misses = True, 0, True, 0
                    self.data = []
                self.since_sync = 1
            elif self.since_sync is not None:
                self.since_sync += 1
        return messages

    def _locked(self, index: int, sync: bool, dibit: int, messages: List[Decoded], sync_margin: float,
                data_margin: float) -> None:
        """Flywheel: data positions are decided as data whatever they look like; a word is
        decoded only between two syncs both seen where expected, so a slip, which puts data
        where a sync is due, can never yield a rotated word."""
        self.position += 1
        if self.position < FRAME_SYMBOLS:
            self.data.append(dibit)
            self.quality = min(self.quality, data_margin)
            return
        self.position = 0
        if sync:
            if self.leading_sync and len(self.data) == DATA_SYMBOLS:
                messages.append((index, self._word(self.data), min(self.quality, sync_margin)))
            self.leading_sync, self.misses = True, 0
        else:
            messages.append((index, None, 0.0))       # no sync where due: this word is lost
            self.leading_sync = False
            self.misses += 1
            if self.misses >= LOCK_MISSES:
                self.locked, self.since_sync = False, None
        self.data = []
        self.quality = sync_margin                    # the word's margins start with its leading sync

    @staticmethod
    def _word(dibits: List[int]) -> Optional[Message]:
        word = 0
        for d in dibits:
            word = word << 2 | d
        info = int(fire_code.decode(word))
        if info < 0 or (info & 0xF) + 1 not in COMMANDS:
            return None
        return Message((info & 0xF) + 1, info >> 4 & 1, info >> 5 & 1)


class FireDqpsk(DigitalSystem):
    name = "FIRE_DQPSK"
    carrier_hz = CARRIER_HZ
    message_symbols = FRAME_SYMBOLS
    decode_lag_symbols = 1          # a word is taken when the next frame's sync confirms the spacing

    def baud(self, carrier_hz: float) -> float:
        return BAUD

    def increments(self, message: Message) -> np.ndarray:
        return frame_increments(message.command, message.track, message.block)

    def command_for(self, free_blocks: int) -> int:
        return COMMAND_OF_FREE_BLOCKS[min(max(free_blocks, 0), len(COMMAND_OF_FREE_BLOCKS) - 1)]

    def commands(self) -> Tuple[int, ...]:
        return tuple(COMMANDS)

    def indication(self, command: int, category: str) -> Indication:
        c = COMMANDS[command]
        column = _CATEGORY_COLUMN[category]
        ceiling = 20.0 if command in RELEASE_COMMANDS else float(COMMANDS[16].permitted_kmh[column])
        target = 0.0 if c.free_blocks == 0 else float(c.permitted_kmh[column])
        return Indication(command, _ASPECT[c.aspect], c.free_blocks, ceiling, target)

    def framer(self, track_parity: int) -> Framer:
        return FireFramer()


SYSTEM = FireDqpsk()
