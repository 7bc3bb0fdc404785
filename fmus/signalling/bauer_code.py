"""The 8-bit, 16-word, distance-4 code of ALS-EN's subchannels (docs/sources.md#als-en).

The product literature calls it a "modified Bauer code"; no public source gives its
construction. We use the code with exactly those parameters that Russian coding texts call
Bauer's code: the extended Hamming (8,4) code (Reed–Muller RM(1,3)) — 4 information bits,
3 Hamming check bits and an overall parity bit, d_min = 4 (single errors correctable, double
errors detected). The receiver uses it for detection only, like the Fire code of the thesis'
system: a word at distance ≥ 1 from every code word is discarded.

Bit order: d1 d2 d3 d4 p1 p2 p3 p0, MSB first, with p1 = d1⊕d2⊕d4, p2 = d1⊕d3⊕d4,
p3 = d2⊕d3⊕d4 and p0 the parity of the other seven bits.
"""
from __future__ import annotations

import numpy as np


def encode(info: int) -> int:
    if not 0 <= info < 16:
        raise ValueError(f"information word {info} does not fit in 4 bits")
    d1, d2, d3, d4 = (info >> 3) & 1, (info >> 2) & 1, (info >> 1) & 1, info & 1
    p1, p2, p3 = d1 ^ d2 ^ d4, d1 ^ d3 ^ d4, d2 ^ d3 ^ d4
    seven = (info << 3) | (p1 << 2) | (p2 << 1) | p3
    return (seven << 1) | (bin(seven).count("1") & 1)


CODEWORDS = np.array([encode(i) for i in range(16)], dtype=np.int64)
_INFO_OF = np.full(256, -1, dtype=np.int64)
_INFO_OF[CODEWORDS] = np.arange(16)


def decode(words) -> np.ndarray:
    """Information word of each 8-bit word, −1 where it is not a code word (discarded)."""
    return _INFO_OF[np.asarray(words, dtype=np.int64) & 0xFF]
