"""The thesis' Fire (12,6) code: its real properties, checked by enumeration."""
import itertools

import numpy as np
import pytest

from fmus.signalling import fire_code as fc


def _weight(word: int) -> int:
    return bin(word).count("1")


def test_generator_divides_x12_plus_1_so_the_code_is_cyclic():
    assert fc.remainder(1 << 12 | 1, bits=13) == 0
    for word in fc.CODEWORDS:
        rotated = ((int(word) << 1) | (int(word) >> 11)) & 0xFFF
        assert fc.is_codeword(rotated)


def test_systematic_words_match_the_thesis_digest():
    # docs/sources.md#fire-code-and-pi4-dqpsk: info 1 → 000001110111, info 15 → 001111001111
    assert format(fc.encode(1), "012b") == "000001110111"
    assert format(fc.encode(15), "012b") == "001111001111"
    assert all(fc.decode(fc.encode(i)) == i for i in range(64))


def test_minimum_distance_is_4_and_the_weight_distribution():
    weights = np.bincount([_weight(int(w)) for w in fc.CODEWORDS], minlength=13)
    assert weights[0] == 1 and weights[4] == 18 and weights[6] == 24 and weights[8] == 21
    assert weights.sum() == 64 and weights[1:4].sum() == 0      # d_min = 4, not the thesis' 5


def test_every_error_of_up_to_three_bits_is_detected():
    for word in fc.CODEWORDS:
        for count in (1, 2, 3):
            for positions in itertools.combinations(range(12), count):
                error = sum(1 << p for p in positions)
                assert not fc.is_codeword(int(word) ^ error)


@pytest.mark.parametrize("length", range(1, 7))
def test_every_burst_up_to_six_bits_is_detected_including_cyclic_bursts(length):
    for word in fc.CODEWORDS[::7]:
        for start in range(12):
            # bursts of this length: first and last bit set, anything between
            for middle in range(1 << max(length - 2, 0)):
                pattern = 1 if length == 1 else (1 << (length - 1)) | (middle << 1) | 1
                error = ((pattern << start) | (pattern >> (12 - start))) & 0xFFF
                assert not fc.is_codeword(int(word) ^ error)


def test_a_slip_of_one_dibit_in_a_repeated_word_decodes_another_valid_command():
    """Why the system needs frame synchronisation: the code is cyclic, so reading a repeated
    word one symbol (two bits) late gives a valid code word of another information word."""
    other = 0
    for info in range(1, 64):
        word = int(fc.encode(info))
        slipped = ((word << 2) | (word >> 10)) & 0xFFF
        assert fc.is_codeword(slipped)
        other += fc.decode(slipped) != info
    assert other == 63
