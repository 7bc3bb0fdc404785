"""The thesis' 16-command system on one track (seed 000 §8): commands → Fire (12,6) words →
π/4-DQPSK at 175 Hz, 15 Bd — plus the frame synchronisation the thesis leaves out (our design).

Frame synchronisation. The Fire code is cyclic, so a receiver that reads a repeated word one
symbol late decodes another *valid* command (tests/test_fire_code.py). Each frame therefore
starts with a **sync symbol whose phase increment is 0**, an increment the data never uses
(data increments are odd multiples of π/4). A frame is 7 symbols: sync + 6 data symbols
(12 bits), 0.467 s at 15 Bd. The receiver

* classifies each phase difference as sync (|Δφ| < π/8) or a data dibit (its quadrant);
* locks on when two sync symbols arrive exactly 7 symbols apart, and decodes only the 6 data
  symbols between consecutive syncs that keep that spacing; a sync out of place, or a missing
  one, drops the lock (a slip, a noise hit) and nothing is decoded until it locks again;
* discards words that fail the Fire check;
* accepts a command only after two identical consecutive decoded words (cf. ALSN's two cycles);
* drops it (no code) when no word has confirmed it for three frames (1.4 s): a held command
  can never outlive a change of the command sent by more than that.

A slip can thus never yield a rotated word, and a steady unmodulated tone (all increments 0:
sync symbols only, no data) never yields a command.

Commands: Table 2.1 of the thesis (16 rows, speeds passenger/freight as printed; unreadable
cells marked [U]). Information words: command n ↦ 6-bit word n (1…16); the code's d_min = 4
holds between any two command words.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import List, Optional

import numpy as np

from . import dqpsk, fire_code

CARRIER_HZ = 175.0
BAUD = 15.0
DATA_SYMBOLS = fire_code.N_BITS // 2
FRAME_SYMBOLS = DATA_SYMBOLS + 1
SYNC_TOLERANCE_RAD = np.pi / 8
TIMEOUT_FRAMES = 3            # command not confirmed for three frames (1.4 s): no code, restrictive


@dataclass(frozen=True)
class Command:
    number: int
    free_blocks: int
    aspect: str                  # cab signal
    permitted_kmh: tuple         # (high-speed, passenger, freight) where printed, else repeated
    controlled_kmh: tuple


# seed 000 Table 2.1 (OCR-damaged cells as read in the digest; [U] where the digest is unsure)
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


def frame_increments(command: int) -> np.ndarray:
    """Phase increments of one frame: the sync symbol (0) and the 6 dibits of the code word."""
    if command not in COMMANDS:
        raise ValueError(f"command {command} is not one of 1…{len(COMMANDS)}")
    bits = fire_code.to_bits(fire_code.encode(command))
    dibits = bits[0::2] * 2 + bits[1::2]
    return np.concatenate([[0.0], dqpsk.INCREMENT_OF_DIBIT[dibits]])


def transmit(commands: List[int], fs_hz: float, amplitude: float = 1.0, start_phase: float = 0.0,
             carrier_hz: float = CARRIER_HZ, baud: float = BAUD) -> np.ndarray:
    """Samples of consecutive frames, one per command (a reference symbol first)."""
    increments = np.concatenate([frame_increments(c) for c in commands])
    return dqpsk.modulate_increments(increments, fs_hz, carrier_hz, baud, amplitude, start_phase)


SYNC = -1


def classify(symbols: np.ndarray) -> np.ndarray:
    """Per phase difference: SYNC (−1) or the data dibit (0…3)."""
    difference = np.angle(symbols[1:] * np.conj(symbols[:-1]))
    data = dqpsk.decide(symbols)
    return np.where(np.abs(difference) < SYNC_TOLERANCE_RAD, SYNC, data)


class FrameReceiver:
    """Symbol-by-symbol framing, Fire check and two-identical-words acceptance."""

    def __init__(self):
        self.since_sync: Optional[int] = None     # symbols since the last sync, None: not locked
        self.locked = False
        self.data: List[int] = []
        self.previous_word: Optional[int] = None
        self.command: Optional[int] = None        # accepted command, None: none
        self.rejected = 0                         # words that failed the Fire check
        self.decoded = 0
        self.since_word = 0                       # symbols since the command in force was last confirmed

    def push(self, kinds) -> None:
        for kind in np.asarray(kinds):
            kind = int(kind)
            self.since_word += 1
            if self.since_word > TIMEOUT_FRAMES * FRAME_SYMBOLS:
                self.command = None                   # no confirmed word for too long: no code
            if kind == SYNC:
                if self.since_sync == FRAME_SYMBOLS:
                    if self.locked and len(self.data) == DATA_SYMBOLS:
                        self._word(self.data)
                    self.locked = True
                else:
                    self.locked = False               # sync out of place: a slip or a hit
                    self.previous_word = None
                self.since_sync = 1
                self.data = []
                continue
            if self.since_sync is None:
                continue
            self.since_sync += 1
            self.data.append(kind)
            if self.since_sync > FRAME_SYMBOLS:       # sync missing where it was due
                self.locked = False
                self.since_sync = None
                self.data = []
                self.previous_word = None

    def _word(self, dibits: List[int]) -> None:
        bits = []
        for d in dibits:
            bits += [(d >> 1) & 1, d & 1]
        info = int(fire_code.decode(fire_code.from_bits(bits)))
        if info < 0 or info not in COMMANDS:
            self.rejected += 1
            self.previous_word = None
            return
        self.decoded += 1
        if info == self.previous_word:
            self.command = info
        if info == self.command:
            self.since_word = 0                   # the command in force is confirmed
        self.previous_word = info
