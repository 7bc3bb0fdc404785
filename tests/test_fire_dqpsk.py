"""The thesis' 16-command system with our frame synchronisation: round trip, slips never
yield another command, a steady tone never yields one, noise never yields a wrong one
(symbol-level: ideal symbol timing; the whole chain is in test_digital.py)."""
import numpy as np
import pytest

from fmus.signalling import dqpsk
from fmus.signalling import fire_dqpsk as fd
from fmus.signalling.digital_messages import Acceptor

FS = 4000.0
FRAME_S = fd.FRAME_SYMBOLS / fd.BAUD


class _Receiver:
    """Framer + acceptance fed one symbol correlation at a time."""

    def __init__(self):
        self.framer = fd.FireFramer()
        self.acceptor = Acceptor(fd.SYSTEM, 1, FRAME_S)
        self.symbols = 0

    def push(self, symbol):
        self.symbols += 1
        now = self.symbols / fd.BAUD
        for _, message, quality in self.framer.push(np.array([symbol])):
            self.acceptor.push(now, message, quality)
        self.acceptor.expire(now)
        return self.acceptor.command


def _receive(samples):
    receiver = _Receiver()
    accepted = [receiver.push(z) for z in dqpsk.correlate(samples, FS, fd.CARRIER_HZ, fd.BAUD)]
    return receiver.acceptor, accepted


@pytest.mark.parametrize("command", [1, 2, 7, 11, 16])
def test_every_command_round_trips_after_two_identical_words(command):
    acceptor, accepted = _receive(fd.transmit([command] * 4, FS, 1.0, 0.3))
    assert acceptor.command == command and acceptor.rejected == 0
    first = next(i for i, c in enumerate(accepted) if c is not None)
    assert first <= 3 * fd.FRAME_SYMBOLS + 1                  # lock, then two words


@pytest.mark.parametrize("command", [3, 9, 14])
@pytest.mark.parametrize("slip_symbols", [-2, -1, 1, 2])
def test_a_slip_of_whole_symbols_never_yields_another_command(command, slip_symbols):
    samples = fd.transmit([command] * 16, FS)     # after the slip: relock, then two identical words
    per_symbol = FS / fd.BAUD
    cut = int(round(5.3 * fd.FRAME_SYMBOLS * per_symbol))
    if slip_symbols > 0:                                      # symbols lost
        slipped = np.concatenate([samples[:cut], samples[cut + int(round(slip_symbols * per_symbol)):]])
    else:                                                     # symbols repeated
        extra = samples[cut - int(round(-slip_symbols * per_symbol)):cut]
        slipped = np.concatenate([samples[:cut], extra, samples[cut:]])
    _, accepted = _receive(slipped)
    assert set(accepted) <= {None, command}
    assert accepted[-1] == command                            # locks again on the true frames


def test_without_the_sync_a_one_symbol_slip_reads_a_rotated_valid_word():
    """The reason for the sync symbol: framing by code validity alone decodes another command."""
    from fmus.signalling import fire_code

    word = fire_code.encode(11)
    rotated = ((word << 2) | (word >> 10)) & 0xFFF
    assert fire_code.is_codeword(rotated) and fire_code.decode(rotated) != 11


def test_a_steady_tone_never_yields_a_command():
    t = np.arange(int(10 * FS)) / FS
    acceptor, accepted = _receive(np.cos(2 * np.pi * fd.CARRIER_HZ * t + 0.4))
    assert set(accepted) == {None} and acceptor.accepted == 0


@pytest.mark.parametrize("snr_db", [6.0, 0.0, -3.0, -9.0, -15.0])
def test_noise_never_yields_a_wrong_command(snr_db):
    rng = np.random.default_rng(int(snr_db) + 50)
    commands = list(rng.integers(1, 17, 60))
    sequence = [c for c in commands for _ in range(3)]       # each command held for three frames
    samples = fd.transmit(sequence, FS, 1.0)
    sigma = np.sqrt(0.5 / 10 ** (snr_db / 10))                # SNR over the whole band (A²/2 / σ²)
    receiver = _Receiver()
    symbols = dqpsk.correlate(samples + sigma * rng.standard_normal(samples.size), FS, fd.CARRIER_HZ, fd.BAUD)
    sent = np.repeat(sequence, fd.FRAME_SYMBOLS)
    wrong = 0
    for k, z in enumerate(symbols[:sent.size]):
        command = receiver.push(z)
        # the accepted command may lag behind a change until the timeout, never be anything else
        window = sent[max(0, k - 4 * fd.FRAME_SYMBOLS):k + 1]
        if command is not None and command not in set(window):
            wrong += 1
    assert wrong == 0


def test_words_carry_the_track_and_block_parity():
    framer = fd.FireFramer()
    symbols = dqpsk.correlate(fd.transmit([9] * 4, FS, track=0, block=1), FS, fd.CARRIER_HZ, fd.BAUD)
    messages = [m for _, m, _ in framer.push(symbols)]
    assert messages and all(m.command == 9 and m.track == 0 and m.block == 1 for m in messages)


def test_unknown_command_is_refused():
    with pytest.raises(ValueError, match="command 17"):
        fd.frame_increments(17)
