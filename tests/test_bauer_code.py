"""ALS-EN's subchannel word code: extended Hamming (8,4) ("Bauer code"), d = 4."""
import itertools

import numpy as np

from fmus.signalling import bauer_code as bc


def test_sixteen_words_with_minimum_distance_four():
    words = [int(w) for w in bc.CODEWORDS]
    assert len(set(words)) == 16
    distances = [bin(a ^ b).count("1") for a, b in itertools.combinations(words, 2)]
    assert min(distances) == 4
    weights = np.bincount([bin(w).count("1") for w in words], minlength=9)
    assert weights[0] == 1 and weights[4] == 14 and weights[8] == 1


def test_every_single_and_double_error_is_detected_and_words_round_trip():
    for info, word in enumerate(bc.CODEWORDS):
        assert bc.decode(word) == info
        for count in (1, 2, 3):
            for bits in itertools.combinations(range(8), count):
                assert bc.decode(int(word) ^ sum(1 << b for b in bits)) == -1
