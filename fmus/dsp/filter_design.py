"""Analog filter prototypes (scipy.signal) as python-control transfer functions, discretised
with Tustin and pre-warping — shared by the receivers and the digital generator.

Prototypes are kept in normalised frequency and scaled inside :func:`discretise`: a 6th-order
band-pass in rad/s has coefficients up to 1e16 and an ill-conditioned state-space form.
"""
from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np
from scipy import signal

from fmus.library_shortcuts import linear_filter


def filter_frame(b: np.ndarray, a: np.ndarray, x: np.ndarray, state: np.ndarray, axis: int = -1):
    """scipy.signal.lfilter(b, a, x, axis, zi=state) for one frame of a core's hot path: the
    same C routine (transposed direct form II) without lfilter's argument checks, which the
    cores satisfy by construction (float64 arrays, a[0] = 1, state shaped as lfilter wants);
    fmus/library_shortcuts.py."""
    return linear_filter(b, a, x, axis, state)


class SampleFilter:
    """lfilter(b, a) one sample at a time in Python floats, for a build with one sample per
    frame: there a call of the C routine on a one-element array costs twice the arithmetic.
    Transposed direct form II with the operations in the order of scipy's routine, so the
    samples are lfilter's bit for bit (tests/test_filter_frame.py); ``state`` is its zi."""

    __slots__ = ("_b", "_a", "state", "_last")

    def __init__(self, b: np.ndarray, a: np.ndarray):
        if a[0] != 1.0:
            raise ValueError("SampleFilter: a[0] must be 1 (normalise the coefficients)")
        size = max(a.size, b.size)             # lfilter pads the shorter with zeros
        if size < 2:
            raise ValueError("SampleFilter: a filter of order 0 is a gain, not a filter")
        self._b = np.pad(np.asarray(b, dtype=float), (0, size - b.size)).tolist()
        self._a = np.pad(np.asarray(a, dtype=float), (0, size - a.size)).tolist()
        self.state = [0.0] * (size - 1)
        self._last = size - 2

    def __call__(self, x: float) -> float:
        z, b, a, last = self.state, self._b, self._a, self._last
        y = z[0] + b[0] * x
        for i in range(last):
            z[i] = z[i + 1] + x * b[i + 1] - y * a[i + 1]
        z[last] = x * b[last + 1] - y * a[last + 1]
        return y


@dataclass(frozen=True)
class DiscreteFilter:
    b: np.ndarray
    a: np.ndarray
    analog: control.TransferFunction
    discrete: control.TransferFunction

    def initial_state(self) -> np.ndarray:
        return np.zeros(max(self.a.size, self.b.size) - 1)


def discretise(normalised: control.TransferFunction, scale_rad_s: float, fs_hz: float,
                prewarp_hz: float) -> DiscreteFilter:
    """Tustin with pre-warping of H(s) = Hn(s/scale). The prototype is kept in normalised
    frequency (coefficients of order one; a 6th-order band-pass in rad/s has coefficients up
    to 1e16 and an ill-conditioned state-space form), and Tustin commutes with frequency
    scaling: sample Hn at Ts·scale with the pre-warp frequency divided by scale."""
    discrete = control.sample_system(normalised, scale_rad_s / fs_hz, method="tustin",
                                     prewarp_frequency=2 * np.pi * prewarp_hz / scale_rad_s)
    num = np.asarray(discrete.num[0][0], dtype=float)
    den = np.asarray(discrete.den[0][0], dtype=float)
    b, a = num / den[0], den / den[0]
    analog_num = np.asarray(normalised.num[0][0], dtype=float)
    analog_den = np.asarray(normalised.den[0][0], dtype=float)
    # the same filters in physical units, for plots and checks
    n = analog_den.size
    analog = control.tf(_rescale(analog_num, scale_rad_s, n), _rescale(analog_den, scale_rad_s, n))
    return DiscreteFilter(b, a, analog, control.tf(b, a, 1.0 / fs_hz))


def _rescale(coefficients: np.ndarray, scale: float, order_plus_one: int) -> np.ndarray:
    """Coefficients of P(s/scale)·scale^(order), highest power first, for H(s) = Hn(s/scale)."""
    n = order_plus_one - 1
    padded = np.concatenate([np.zeros(order_plus_one - coefficients.size), coefficients])
    powers = np.arange(n, -1, -1)                      # power of s of each coefficient
    return padded * scale ** (n - powers)




def chebyshev_band_pass(centre_hz: float, bandwidth_hz: float, prototype_order: int, ripple_db: float,
                        fs_hz: float) -> DiscreteFilter:
    """Chebyshev type I band-pass of order 2·prototype_order, ripple band centre ± bandwidth/2
    (geometric centre), pre-warped at the centre."""
    zeros, poles, gain = signal.cheb1ap(prototype_order, ripple_db)
    b, a = signal.zpk2tf(zeros, poles, gain)
    b, a = signal.lp2bp(b, a, wo=1.0, bw=bandwidth_hz / centre_hz)
    return discretise(control.tf(b, a), 2 * np.pi * centre_hz, fs_hz, centre_hz)


def chebyshev_low_pass(corner_hz: float, order: int, ripple_db: float, fs_hz: float) -> DiscreteFilter:
    """Chebyshev type I low-pass (ripple band up to the corner), pre-warped at the corner."""
    zeros, poles, gain = signal.cheb1ap(order, ripple_db)
    b, a = signal.zpk2tf(zeros, poles, gain)
    return discretise(control.tf(b, a), 2 * np.pi * corner_hz, fs_hz, corner_hz)
