"""Receiver filter design: analog prototypes in python-control, discretised with Tustin and
pre-warping at the carrier (docs/loco_receiver.md has the Bode plot and group delay).

* Band-pass at the carrier: a Butterworth low-pass prototype of ``order`` (scipy.signal.buttap)
  transformed to a band-pass of width B around f0 (lp2bp), as a python-control transfer
  function, then ``control.sample_system(..., 'tustin', prewarp_frequency=2π·f0)`` so the
  centre frequency is exact at fs. Default order 3 (a 6th-order band-pass) and B = 0.4·f0:
  20 Hz at 50 Hz passes the code sidebands (the shortest interval, 0.12 s, needs about
  ±8 Hz) and takes 100 Hz (DC traction ripple's even harmonic) down by about 40 dB; at 25 Hz
  (10 Hz wide) it takes the 50 Hz of AC traction down by about 34 dB.
* Envelope low-pass after full-wave rectification: 2nd-order Butterworth at min(12 Hz, f0/3),
  same discretisation, pre-warped at its corner.
"""
from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np
from scipy import signal


@dataclass(frozen=True)
class DiscreteFilter:
    b: np.ndarray
    a: np.ndarray
    analog: control.TransferFunction
    discrete: control.TransferFunction

    def initial_state(self) -> np.ndarray:
        return np.zeros(max(self.a.size, self.b.size) - 1)


def _discretise(normalised: control.TransferFunction, scale_rad_s: float, fs_hz: float,
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


def band_pass(carrier_hz: float, bandwidth_hz: float, order: int, fs_hz: float) -> DiscreteFilter:
    zeros, poles, gain = signal.buttap(order)
    b, a = signal.zpk2tf(zeros, poles, gain)
    w0 = 2 * np.pi * carrier_hz
    b, a = signal.lp2bp(b, a, wo=1.0, bw=bandwidth_hz / carrier_hz)
    return _discretise(control.tf(b, a), w0, fs_hz, carrier_hz)


def envelope_low_pass(corner_hz: float, fs_hz: float, order: int = 2) -> DiscreteFilter:
    zeros, poles, gain = signal.buttap(order)
    b, a = signal.zpk2tf(zeros, poles, gain)
    return _discretise(control.tf(b, a), 2 * np.pi * corner_hz, fs_hz, corner_hz)


def default_bandwidth(carrier_hz: float) -> float:
    return 0.4 * carrier_hz


def default_envelope_corner(carrier_hz: float) -> float:
    return min(12.0, carrier_hz / 3.0)
