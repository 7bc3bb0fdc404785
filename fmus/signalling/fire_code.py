"""The thesis' Fire (12,6) code (docs/sources.md#fire-code-and-pi4-dqpsk): g(x) = (x² + x + 1)(x⁴ + 1) = x⁶+x⁵+x⁴+x²+x+1.

Systematic, MSB first: a 12-bit word is the 6 information bits (x¹¹…x⁶) followed by the
remainder of info·x⁶ divided by g(x) (x⁵…x⁰). The receiver only *detects* errors (a word whose
remainder is not zero is discarded), as the thesis' receiver algorithm does.

Properties (verified by enumeration in tests/test_fire_code.py, against the thesis' claims):
d_min = 4 (the thesis says 5), weight distribution A0 = 1, A4 = 18, A6 = 24, A8 = 21; every
burst of length ≤ 6 is detected. The code is cyclic, so every rotation of a code word is a code
word: word framing cannot come from code validity alone.
"""
from __future__ import annotations

import numpy as np

GENERATOR = 0b1110111          # x⁶+x⁵+x⁴+x²+x+1
N_BITS, K_BITS = 12, 6
CHECK_BITS = N_BITS - K_BITS


def remainder(word: int, bits: int = N_BITS) -> int:
    """word (``bits`` long, MSB = highest power) modulo g(x) over GF(2)."""
    for shift in range(bits - 1, CHECK_BITS - 1, -1):
        if word >> shift & 1:
            word ^= GENERATOR << (shift - CHECK_BITS)
    return word


def encode(info: int) -> int:
    if not 0 <= info < 1 << K_BITS:
        raise ValueError(f"information word {info} does not fit in {K_BITS} bits")
    shifted = info << CHECK_BITS
    return shifted | remainder(shifted)


# every code word, indexed by its information word, and the validity of all 4096 words
CODEWORDS = np.array([encode(i) for i in range(1 << K_BITS)], dtype=np.int64)
_VALID = np.zeros(1 << N_BITS, dtype=bool)
_VALID[CODEWORDS] = True
_INFO_OF = np.full(1 << N_BITS, -1, dtype=np.int64)
_INFO_OF[CODEWORDS] = np.arange(1 << K_BITS)


def is_codeword(words) -> np.ndarray:
    """Vectorised check (zero syndrome) of 12-bit words."""
    return _VALID[np.asarray(words, dtype=np.int64) & ((1 << N_BITS) - 1)]


def decode(words) -> np.ndarray:
    """Information word of each 12-bit word, −1 where the word is not a code word (discarded)."""
    return _INFO_OF[np.asarray(words, dtype=np.int64) & ((1 << N_BITS) - 1)]


def to_bits(word: int, bits: int = N_BITS) -> np.ndarray:
    return np.array([(word >> (bits - 1 - k)) & 1 for k in range(bits)], dtype=np.int8)
