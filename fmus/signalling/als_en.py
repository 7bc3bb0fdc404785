"""ALS-EN (АЛС-ЕН): double relative phase modulation on one ≈175 Hz carrier with two
subchannels of 8-bit, distance-4 words (docs/sources.md#als-en; docs/sources.md#als-en). No FMI here.

Modem. Each symbol carries a dibit: one bit of subchannel 1 and one of subchannel 2 (the "0°
and 90° channels"), as a phase increment with Gray mapping 00 → 0, 01 → π/2, 11 → π,
10 → 3π/2 (the open receiver code's table, docs/sources.md#als-en). A symbol lasts 16 carrier
cycles (10.9 Bd at 174.38 Hz; the sources' 174.38 / 174.89 / 175 Hz all give ≈ 10.9 Bd, the
thesis' 10.9 bit/s per subchannel). Words are sent MSB first, both subchannels aligned.

Word code ("modified Bauer code"): the extended Hamming (8,4) code of bauer_code.py (d = 4),
**modified by a fixed coset mask per subchannel** (our construction; the product literature
names the code but does not define it): a subchannel's words are c ⊕ m with m not a code
word. Why: the plain code contains 00000000 and 11111111, which any steady tone (constant
phase increment, hence constant dibits) would produce; a coset leaves both invalid. The two
masks also differ by a non-code word, so a subchannel-1 word never reads as a subchannel-2
word. Distance 4 is kept (a coset has the code's distances).

Message cycle (our layout of the sources' contents, docs/digital_channels.md): two words.

* subchannel 2, every word: cycle position p (bit 3; 0: subchannel 1 carries the indication,
  1: the speed), track parity (bit 2), block-section parity (bit 1), route (bit 0; 0 straight
  / main, sent as 0). This is the cyclic synchronisation and the adjacent-track / adjacent-
  section protection of docs/sources.md#als-en.
* subchannel 1, word p = 0: the indication: 0 red (in an occupied section), 1 КЖ (approach to
  a closed signal), 2 БМ (flashing white, passing a signal at danger), 3…8 = 1…6 free blocks;
  9…15 unused (discarded).
* subchannel 1, word p = 1: the speed for passing the next signal, 16 steps over 0–200 km/h
  (:data:`SPEEDS_KMH`; the sources give the count and range, not the steps [U]).

Word alignment. Nothing but the code marks word boundaries. The receiver locks at a bit offset
only when two consecutive words there are valid on both subchannels and their cycle positions
alternate (p = 0 then p = 1 with the same parities, or p = 1 then p = 0); it stays locked while
every word is valid and the cycle keeps alternating. tests/test_als_en.py shows by enumeration
over every legal word stream that no misaligned offset passes that test, so a slip never
yields another message.

Plain-line automatic block (wayside), by free blocks n: n = 0 → КЖ with speed 0; n = 1 → 1
free block, 60 km/h at the next signal (ALSN's yellow rule, signalling.py); n ≥ 2 → n free
blocks (≤ 6), 200 km/h. Reported `code`: the KLUB register number (docs/sources.md#als-en):
9 red, 10 КЖ, 11…15 one…five (or more) free blocks, 5 flashing white.
"""
from __future__ import annotations

from collections import deque
from typing import List, Optional, Tuple

import numpy as np

from fmus.signalling import bauer_code
from fmus.signalling import aspects as sig
from fmus.signalling.digital_messages import Decoded, DigitalSystem, Framer, Indication, Message

CARRIER_HZ = 174.38
CYCLES_PER_SYMBOL = 16
WORD_BITS = 8
MESSAGE_SYMBOLS = 2 * WORD_BITS
MASK_1, MASK_2 = 0x35, 0x5C
SPEEDS_KMH = (0, 15, 20, 25, 40, 50, 60, 70, 80, 90, 100, 120, 140, 160, 180, 200)
RED, RED_YELLOW, WHITE_FLASHING = 0, 1, 2
FIRST_FREE = 3                       # indication 3 + n − 1: n free blocks
LAST_INDICATION = FIRST_FREE + 5
INCREMENT_OF_DIBIT = np.array([0.0, np.pi / 2, 3 * np.pi / 2, np.pi])   # 00, 01, 10, 11 (Gray)
_DIBIT_OF_QUADRANT = np.array([0b00, 0b01, 0b11, 0b10])


def word(info: int, subchannel: int) -> int:
    return bauer_code.encode(info) ^ (MASK_1 if subchannel == 1 else MASK_2)


def _table(mask: int) -> np.ndarray:
    table = np.full(256, -1, dtype=np.int64)
    table[bauer_code.CODEWORDS ^ mask] = np.arange(16)
    return table


_INFO_1, _INFO_2 = _table(MASK_1), _table(MASK_2)


def decode_word(value: int, subchannel: int) -> int:
    """Information nibble of an 8-bit word, −1 if it is not a word of that subchannel."""
    return int((_INFO_1 if subchannel == 1 else _INFO_2)[value & 0xFF])


def sync_info(position: int, track: int, block: int, route: int = 0) -> int:
    return (position & 1) << 3 | (track & 1) << 2 | (block & 1) << 1 | (route & 1)


def command_id(indication: int, speed_index: int) -> int:
    """Our command number, 1…144 (0 is left for "none" on the ports)."""
    return 1 + indication * 16 + speed_index


def command_fields(command: int) -> Tuple[int, int]:
    """(indication, speed index) of a command number."""
    return divmod(command - 1, 16)


def speed_index(kmh: float) -> int:
    return int(np.argmin(np.abs(np.asarray(SPEEDS_KMH) - kmh)))


def message_words(message: Message) -> Tuple[Tuple[int, int], Tuple[int, int]]:
    """((subchannel-1 word, subchannel-2 word) for p = 0, the same for p = 1)."""
    indication, speed = command_fields(message.command)
    return ((word(indication, 1), word(sync_info(0, message.track, message.block), 2)),
            (word(speed, 1), word(sync_info(1, message.track, message.block), 2)))


def message_increments(message: Message) -> np.ndarray:
    increments = []
    for first, second in message_words(message):
        for k in range(WORD_BITS - 1, -1, -1):
            increments.append(INCREMENT_OF_DIBIT[((first >> k) & 1) << 1 | ((second >> k) & 1)])
    return np.array(increments)


def margins_of(symbols: np.ndarray) -> np.ndarray:
    """Decision margin of each phase difference: 1 on a multiple of π/2, 0 half-way between."""
    difference = np.angle(symbols[1:] * np.conj(symbols[:-1]))
    return 1.0 - np.abs(np.mod(difference + np.pi / 4, np.pi / 2) - np.pi / 4) / (np.pi / 4)


def dibits_of(symbols: np.ndarray) -> np.ndarray:
    """Dibit of each phase difference of consecutive symbols (nearest multiple of π/2)."""
    difference = np.angle(symbols[1:] * np.conj(symbols[:-1]))
    quadrant = np.round(np.mod(difference, 2 * np.pi) / (np.pi / 2)).astype(np.int64) % 4
    return _DIBIT_OF_QUADRANT[quadrant]


class AlsEnFramer(Framer):
    """Bit streams of both subchannels → word alignment → messages (module docstring)."""

    def __init__(self):
        self.reset()

    def reset(self) -> None:
        self.previous: Optional[complex] = None
        self.register_1 = self.register_2 = 0       # the last 16 bits of each subchannel
        self.bits = 0
        self.locked = False
        self.boundary = 0                           # bit count mod 8 at which words end
        self.last: Optional[Tuple[int, int]] = None  # (indication or speed, sync info) of the last word
        self.margins = deque(maxlen=MESSAGE_SYMBOLS)  # decision margins of the last message's symbols

    def push(self, symbols: np.ndarray) -> List[Decoded]:
        joined = self._joined(symbols)
        if joined is None:
            return []
        symbols, first = joined
        messages: List[Decoded] = []
        margins = margins_of(symbols).tolist()
        for index, (dibit, margin) in enumerate(zip(dibits_of(symbols).tolist(), margins), start=first):
            self.register_1 = (self.register_1 << 1 | dibit >> 1) & 0xFFFF
            self.register_2 = (self.register_2 << 1 | dibit & 1) & 0xFFFF
            self.margins.append(margin)
            self.bits += 1
            if self.locked:
                if self.bits % WORD_BITS == self.boundary:
                    messages += [(index, m, min(self.margins)) for m in self._word(self.register_1 & 0xFF,
                                                                                   self.register_2 & 0xFF)]
            elif self.bits >= 2 * WORD_BITS and self._aligned():
                self.locked, self.boundary = True, self.bits % WORD_BITS
                self.last = (decode_word(self.register_1 >> 8, 1), decode_word(self.register_2 >> 8, 2))
                messages += [(index, m, min(self.margins)) for m in self._word(self.register_1 & 0xFF,
                                                                               self.register_2 & 0xFF)]
        return messages

    def _aligned(self) -> bool:
        infos = [decode_word(self.register_1 >> 8, 1), decode_word(self.register_1 & 0xFF, 1),
                 decode_word(self.register_2 >> 8, 2), decode_word(self.register_2 & 0xFF, 2)]
        return min(infos) >= 0 and _continues(infos[2], infos[3])

    def _word(self, value_1: int, value_2: int) -> List[Optional[Message]]:
        info_1, info_2 = decode_word(value_1, 1), decode_word(value_2, 2)
        last, self.last = self.last, None
        if info_2 < 0 or (last is not None and not _continues(last[1], info_2)):
            self.locked = False                     # alignment lost (a slip or a hit)
            return [None]
        if info_1 < 0:
            return [None]
        self.last = (info_1, info_2)
        if info_2 >> 3 == 1 and last is not None:
            indication = last[0]
            if indication > LAST_INDICATION:
                return [None]
            return [Message(command_id(indication, info_1), info_2 >> 2 & 1, info_2 >> 1 & 1)]
        return []


def _continues(first: int, second: int) -> bool:
    """Subchannel-2 words that may follow each other: the cycle position alternates, and within
    a message (p = 0 → p = 1) the parities and route stay."""
    if first >> 3 == second >> 3:
        return False
    return first >> 3 == 1 or (first & 7) == (second & 7)


class AlsEn(DigitalSystem):
    name = "ALS-EN"
    carrier_hz = CARRIER_HZ
    message_symbols = MESSAGE_SYMBOLS

    def baud(self, carrier_hz: float) -> float:
        return carrier_hz / CYCLES_PER_SYMBOL

    def increments(self, message: Message) -> np.ndarray:
        return message_increments(message)

    def command_for(self, free_blocks: int) -> int:
        n = min(max(free_blocks, 0), LAST_INDICATION - FIRST_FREE + 1)
        if n == 0:
            return command_id(RED_YELLOW, speed_index(0))
        return command_id(FIRST_FREE + n - 1, speed_index(60 if n == 1 else 200))

    def commands(self) -> Tuple[int, ...]:
        return tuple(command_id(i, s) for i in range(LAST_INDICATION + 1) for s in range(16))

    def command_of_code(self, code: int) -> Optional[int]:
        """KLUB register → command; register 15 is "five or more" free blocks, read as six."""
        if code <= 0:
            return None
        top = len(SPEEDS_KMH) - 1
        if code == 9:
            return command_id(RED, top)
        if code == 5:
            return command_id(WHITE_FLASHING, top)
        return self.command_for(0 if code == 10 else (6 if code == 15 else code - 10))

    def indication(self, command: int, category: str) -> Indication:
        indication, speed = command_fields(command)
        ceiling = sig.CATEGORY_MAX_KMH[category]
        if indication == RED:
            return Indication(9, sig.RED, 0, 20.0, min(SPEEDS_KMH[speed], 20.0))
        if indication == RED_YELLOW:
            return Indication(10, sig.RED_YELLOW, 0, ceiling, 0.0)
        if indication == WHITE_FLASHING:
            return Indication(5, sig.WHITE, 0, 20.0, min(SPEEDS_KMH[speed], 20.0))
        free = indication - FIRST_FREE + 1
        return Indication(10 + min(free, 5), sig.YELLOW if free == 1 else sig.GREEN, free, ceiling,
                          min(float(SPEEDS_KMH[speed]), ceiling))

    def framer(self, track_parity: int) -> Framer:
        return AlsEnFramer()


SYSTEM = AlsEn()
