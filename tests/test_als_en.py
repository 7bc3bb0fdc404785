"""ALS-EN: the coset ("modified Bauer") word code, word alignment by the cyclic
synchronisation of subchannel 2, the message cycle, and what the receiver must never do
(symbol level with ideal timing; the whole chain is in test_digital.py)."""
import itertools

import numpy as np
import pytest

from fmus.signalling import als_en, bauer_code, dqpsk
from fmus.signalling import aspects as sig
from fmus.signalling.digital_messages import Acceptor, Message

FS = 4000.0
BAUD = als_en.SYSTEM.baud(als_en.CARRIER_HZ)
MESSAGE_S = als_en.MESSAGE_SYMBOLS / BAUD
CODE = set(int(c) for c in bauer_code.CODEWORDS)


def _samples(messages, phase=0.0, carrier=als_en.CARRIER_HZ, baud=BAUD):
    increments = np.concatenate([als_en.message_increments(m) for m in messages])
    return dqpsk.modulate_increments(increments, FS, carrier, baud, 1.0, phase)


def _receive(samples, track=1, carrier=als_en.CARRIER_HZ, baud=BAUD):
    framer, acceptor = als_en.AlsEnFramer(), Acceptor(als_en.SYSTEM, track, MESSAGE_S)
    accepted = []
    for k, z in enumerate(dqpsk.correlate(samples, FS, carrier, baud)):
        now = (k + 1) / baud
        for _, message, quality in framer.push(np.array([z])):
            acceptor.push(now, message, quality)
        acceptor.expire(now)
        accepted.append(acceptor.command)
    return acceptor, accepted


def test_the_coset_code_keeps_distance_4_and_makes_constant_words_invalid():
    for subchannel in (1, 2):
        words = [als_en.word(i, subchannel) for i in range(16)]
        distances = [bin(a ^ b).count("1") for a, b in itertools.combinations(words, 2)]
        assert min(distances) == 4
        # a steady tone gives constant dibits: all-zero or all-one words on each subchannel
        assert als_en.decode_word(0x00, subchannel) < 0 and als_en.decode_word(0xFF, subchannel) < 0
    assert als_en.MASK_1 not in CODE and als_en.MASK_2 not in CODE
    # a word of one subchannel is never a word of the other
    assert all(als_en.decode_word(als_en.word(i, 1), 2) < 0 for i in range(16))


def test_no_misaligned_offset_of_any_legal_stream_passes_the_alignment_test():
    """Exhaustive over subchannel-2 streams p=1 (any), p=0, p=1 (same parities), p=0 (any):
    a window offset by 1…7 bits never gives two consecutive valid words whose cycle continues."""
    w = lambda info: als_en.word(info, 2)
    for before, inside, after in itertools.product(range(8), range(8), range(8)):
        stream = [w(8 | before), w(inside), w(8 | inside), w(after)]
        bits = "".join(f"{x:08b}" for x in stream)
        for offset in range(1, 8):
            windows = [als_en.decode_word(int(bits[offset + 8 * i: offset + 8 * i + 8], 2), 2) for i in range(3)]
            for a, b in zip(windows, windows[1:]):
                assert not (a >= 0 and b >= 0 and als_en._continues(a, b)), (before, inside, after, offset)


@pytest.mark.parametrize("free_blocks", range(7))
@pytest.mark.parametrize("phase", [0.0, 2.1])
def test_every_plain_line_message_round_trips(free_blocks, phase):
    command = als_en.SYSTEM.command_for(free_blocks)
    acceptor, accepted = _receive(_samples([Message(command, 1, free_blocks % 2)] * 4, phase))
    assert acceptor.command == command and acceptor.rejected == 0
    assert accepted.index(command) <= 3 * als_en.MESSAGE_SYMBOLS + 1     # lock, two messages


def test_indications_follow_the_klub_register_and_the_block_rules():
    ind = [als_en.SYSTEM.indication(als_en.SYSTEM.command_for(n), "passenger") for n in range(7)]
    assert [i.code for i in ind] == [10, 11, 12, 13, 14, 15, 15]
    assert [i.aspect for i in ind] == [sig.RED_YELLOW, sig.YELLOW] + [sig.GREEN] * 5
    assert [i.free_blocks for i in ind] == list(range(7))
    assert ind[0].target_kmh == 0 and ind[1].target_kmh == 60 and ind[2].target_kmh == 160
    assert als_en.SYSTEM.indication(als_en.command_id(als_en.RED, 1), "freight").permitted_kmh == 20
    freight = als_en.SYSTEM.indication(als_en.SYSTEM.command_for(6), "freight")
    assert freight.permitted_kmh == 90 and freight.target_kmh == 90


@pytest.mark.parametrize("slip_symbols", [-3, -1, 1, 2, 5])
def test_a_slip_never_yields_another_message(slip_symbols):
    sent = Message(als_en.SYSTEM.command_for(2), 1, 0)
    samples = _samples([sent] * 10)
    per_symbol = FS / BAUD
    cut = int(round(37.4 * per_symbol))
    if slip_symbols > 0:
        slipped = np.concatenate([samples[:cut], samples[cut + int(round(slip_symbols * per_symbol)):]])
    else:
        slipped = np.concatenate([samples[:cut], samples[cut - int(round(-slip_symbols * per_symbol)):cut],
                                  samples[cut:]])
    acceptor, accepted = _receive(slipped)
    assert set(accepted) <= {None, sent.command}
    assert accepted[-1] == sent.command


@pytest.mark.parametrize("offset_hz", [0.0, BAUD / 4, BAUD / 2, 3.3])
def test_a_steady_tone_never_yields_a_message(offset_hz):
    t = np.arange(int(12 * FS)) / FS
    acceptor, accepted = _receive(np.cos(2 * np.pi * (als_en.CARRIER_HZ + offset_hz) * t + 0.4))
    assert set(accepted) == {None} and acceptor.accepted == 0


def test_the_adjacent_tracks_code_is_discarded():
    other_track = Message(als_en.SYSTEM.command_for(6), 0, 1)
    acceptor, accepted = _receive(_samples([other_track] * 5), track=1)
    assert set(accepted) == {None} and acceptor.foreign >= 3


@pytest.mark.parametrize("snr_db", [6.0, 0.0, -6.0, -12.0])
def test_noise_never_yields_a_wrong_message(snr_db):
    rng = np.random.default_rng(int(snr_db) + 70)
    free = rng.integers(0, 7, 25)
    sequence = [Message(als_en.SYSTEM.command_for(int(n)), 1, 0) for n in free for _ in range(2)]
    samples = _samples(sequence)
    sigma = np.sqrt(0.5 / 10 ** (snr_db / 10))
    acceptor, accepted = _receive(samples + sigma * rng.standard_normal(samples.size))
    sent = np.repeat([m.command for m in sequence], als_en.MESSAGE_SYMBOLS)
    for k, command in enumerate(accepted[:sent.size]):
        window = set(sent[max(0, k - 4 * als_en.MESSAGE_SYMBOLS):k + 1].tolist())
        assert command is None or command in window
