"""π/4-DQPSK modem of the thesis' system (175 Hz, 15 Bd): round trip and bit error rate in
white noise against differential-detection theory."""
import numpy as np
import pytest

from fmus.signalling import dqpsk

FS, FC, BAUD = 4000.0, 175.0, 15.0


def test_round_trip_without_noise_at_any_carrier_phase():
    rng = np.random.default_rng(2)
    dibits = rng.integers(0, 4, 300)
    for phase in (0.0, 1.0, 2.5):
        samples = dqpsk.modulate(dibits, FS, FC, BAUD, 1.0, phase)
        decided = dqpsk.decide(dqpsk.correlate(samples, FS, FC, BAUD))
        assert np.array_equal(decided[:dibits.size], dibits)


def test_a_word_takes_0_4_s():
    """12 bits = 6 symbols at 15 Bd (docs/sources.md#fire-code-and-pi4-dqpsk), plus the reference symbol."""
    samples = dqpsk.modulate(np.zeros(6, dtype=int), FS, FC, BAUD)
    assert samples.size == pytest.approx(7 / BAUD * FS, abs=1)


@pytest.mark.parametrize("ebn0_db", [4.0, 6.0, 8.0])
def test_bit_error_rate_is_within_1_db_of_theory(ebn0_db):
    rng = np.random.default_rng(int(ebn0_db))
    dibits = rng.integers(0, 4, 8000)
    samples = dqpsk.modulate(dibits, FS, FC, BAUD, 1.0)
    eb = (FS / BAUD) / 4.0                       # A²/2 per sample × samples per symbol / 2 bits
    sigma = np.sqrt(eb / (2 * 10 ** (ebn0_db / 10)))   # N0 = 2σ² for real samples
    received = samples + sigma * rng.standard_normal(samples.size)
    decided = dqpsk.decide(dqpsk.correlate(received, FS, FC, BAUD))[:dibits.size]
    ber = np.mean(dqpsk.bits_of(decided) != dqpsk.bits_of(dibits))
    assert dqpsk.theory_ber(ebn0_db + 1.0) < ber < dqpsk.theory_ber(ebn0_db - 1.0)
