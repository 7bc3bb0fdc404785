"""π/4-DQPSK at a low carrier (the thesis' 175 Hz, 15 Bd; docs/sources.md#fire-code-and-pi4-dqpsk): modulation,
I/Q correlation (integrate and dump over each symbol) and differential decision, vectorised
over whole messages. Symbol boundaries fall at t = k/baud, not on whole samples (4000/15 is
not an integer): each sample belongs to the symbol its time falls in.

Gray mapping of dibits to phase increments: 00 → +π/4, 01 → +3π/4, 11 → −3π/4, 10 → −π/4.
The receiver's decision uses only the phase difference of consecutive symbols, so an unknown
carrier phase does not matter.

Theory for the tests (Proakis, differentially detected π/4-DQPSK with Gray coding):
P_b = Q₁(a, b) − ½·I₀(a·b)·exp(−(a² + b²)/2), a² = 2γ_b(1 − 1/√2), b² = 2γ_b(1 + 1/√2).
"""
from __future__ import annotations

import numpy as np
import scipy        # scipy.stats (0.6 s to import) loads at its first use: SciPy loads submodules lazily

INCREMENTS = {0b00: np.pi / 4, 0b01: 3 * np.pi / 4, 0b11: -3 * np.pi / 4, 0b10: -np.pi / 4}
INCREMENT_OF_DIBIT = np.array([INCREMENTS[d] for d in range(4)])
# decision: quadrant of the phase difference → dibit
_DIBIT_OF_QUADRANT = {0: 0b00, 1: 0b01, 2: 0b11, 3: 0b10}      # quadrants 0..3 from 0 rad counter-clockwise


def symbol_index(n_samples: int, fs_hz: float, baud: float, first_sample: int = 0) -> np.ndarray:
    """Symbol number of each sample (sample time (first + n)/fs)."""
    return np.floor((first_sample + np.arange(n_samples)) * baud / fs_hz + 1e-9).astype(np.int64)


def modulate(dibits, fs_hz: float, carrier_hz: float, baud: float, amplitude: float = 1.0,
             start_phase: float = 0.0) -> np.ndarray:
    """Samples of the reference symbol followed by one symbol per dibit."""
    return modulate_increments(INCREMENT_OF_DIBIT[np.asarray(dibits)], fs_hz, carrier_hz, baud, amplitude, start_phase)


def modulate_increments(increments, fs_hz: float, carrier_hz: float, baud: float, amplitude: float = 1.0,
                        start_phase: float = 0.0) -> np.ndarray:
    """Samples of a reference symbol followed by one symbol per phase increment (rad)."""
    phase = start_phase + np.concatenate([[0.0], np.cumsum(increments)])
    count = int(np.ceil(phase.size * fs_hz / baud - 1e-9))
    symbol = np.minimum(symbol_index(count, fs_hz, baud), phase.size - 1)
    t = np.arange(count) / fs_hz
    return amplitude * np.cos(2 * np.pi * carrier_hz * t + phase[symbol])


def correlate(samples: np.ndarray, fs_hz: float, carrier_hz: float, baud: float, first_sample: int = 0) -> np.ndarray:
    """Complex I/Q correlation of each whole symbol (integrate and dump)."""
    n = samples.size
    t = (first_sample + np.arange(n)) / fs_hz
    symbol = symbol_index(n, fs_hz, baud, first_sample)
    symbol -= symbol[0]
    mixed = samples * np.exp(-2j * np.pi * carrier_hz * t)
    return np.bincount(symbol, weights=mixed.real) + 1j * np.bincount(symbol, weights=mixed.imag)


def decide(symbols: np.ndarray) -> np.ndarray:
    """Dibits from the phase differences of consecutive symbols."""
    difference = np.angle(symbols[1:] * np.conj(symbols[:-1]))
    quadrant = np.floor(np.mod(difference, 2 * np.pi) / (np.pi / 2)).astype(np.int64) % 4
    return np.array([_DIBIT_OF_QUADRANT[q] for q in range(4)])[quadrant]


def bits_of(dibits: np.ndarray) -> np.ndarray:
    dibits = np.asarray(dibits)
    return np.stack([(dibits >> 1) & 1, dibits & 1], axis=-1).reshape(-1)


def theory_ber(ebn0_db):
    gamma = 10 ** (np.asarray(ebn0_db, dtype=float) / 10)
    a2 = 2 * gamma * (1 - 1 / np.sqrt(2))
    b2 = 2 * gamma * (1 + 1 / np.sqrt(2))
    marcum_q1 = scipy.stats.ncx2.sf(b2, 2, a2)
    return marcum_q1 - 0.5 * scipy.special.i0e(np.sqrt(a2 * b2)) * np.exp(np.sqrt(a2 * b2) - (a2 + b2) / 2)
