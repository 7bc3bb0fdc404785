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

import control
import numpy as np
from scipy import signal

from fmus.dsp.filter_design import DiscreteFilter, discretise


def band_pass(carrier_hz: float, bandwidth_hz: float, order: int, fs_hz: float) -> DiscreteFilter:
    zeros, poles, gain = signal.buttap(order)
    b, a = signal.zpk2tf(zeros, poles, gain)
    w0 = 2 * np.pi * carrier_hz
    b, a = signal.lp2bp(b, a, wo=1.0, bw=bandwidth_hz / carrier_hz)
    return discretise(control.tf(b, a), w0, fs_hz, carrier_hz)


def envelope_low_pass(corner_hz: float, fs_hz: float, order: int = 2) -> DiscreteFilter:
    zeros, poles, gain = signal.buttap(order)
    b, a = signal.zpk2tf(zeros, poles, gain)
    return discretise(control.tf(b, a), 2 * np.pi * corner_hz, fs_hz, corner_hz)


def default_bandwidth(carrier_hz: float) -> float:
    return 0.4 * carrier_hz


def default_envelope_corner(carrier_hz: float) -> float:
    return min(12.0, carrier_hz / 3.0)
