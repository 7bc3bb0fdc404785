"""Receiver filter design: analog prototypes in python-control, discretised with Tustin and
pre-warping at the carrier, as second-order sections (fmus/dsp/filter_design.py ``sections``;
docs/loco_receiver.md has the Bode plot and group delay).

* Band-pass at the carrier: a Butterworth low-pass prototype of ``order`` (scipy.signal.buttap)
  transformed to a band-pass of width B around f0 (lp2bp_zpk), each conjugate pole pair a
  python-control transfer function of order two, each discretised with
  ``control.sample_system(..., 'tustin', prewarp_frequency=2π·f0)`` so the centre frequency
  is exact at fs. Default order 3 (a 6th-order band-pass, three sections) and B = 0.4·f0:
  20 Hz at 50 Hz passes the code sidebands (the shortest interval, 0.12 s, needs about
  ±8 Hz) and takes 100 Hz (DC traction ripple's even harmonic) down by about 40 dB; at 25 Hz
  (10 Hz wide) it takes the 50 Hz of AC traction down by about 34 dB.
* Envelope low-pass after full-wave rectification: 2nd-order Butterworth at min(12 Hz, f0/3),
  same discretisation, pre-warped at its corner (one section).
* The digital receivers' band-pass (digital_receiver.py): the same design, prototype order 2 (a
  4th-order band-pass), 10/3 of the symbol rate wide.

:func:`receiver_band_pass` is the band-pass a receiver with given settings uses; the cores and
the run report (``railcosim report``) both design it through :func:`band_pass_design`.
"""
from __future__ import annotations

from typing import Tuple

import numpy as np
import scipy        # scipy.signal loads at its first use, a design (SciPy loads submodules lazily)

from fmus.dsp.filter_design import SosFilter, sections

ALSN_DEFAULT_CARRIER_HZ = 50.0        # an ALSN receiver's carrier when its settings say 0
DIGITAL_BAND_PASS_ORDER = 2
DIGITAL_BANDWIDTH_PER_BAUD = 10.0 / 3.0


def band_pass(carrier_hz: float, bandwidth_hz: float, order: int, fs_hz: float) -> SosFilter:
    """Butterworth band-pass of order 2·``order``, −3 dB width ``bandwidth_hz`` around the
    carrier (geometric centre), as ``order`` second-order sections."""
    zeros, poles, gain = scipy.signal.lp2bp_zpk(*scipy.signal.buttap(order), wo=1.0, bw=bandwidth_hz / carrier_hz)
    return sections((zeros, poles, gain), 2 * np.pi * carrier_hz, fs_hz, carrier_hz)


def envelope_low_pass(corner_hz: float, fs_hz: float, order: int = 2) -> SosFilter:
    return sections(scipy.signal.buttap(order), 2 * np.pi * corner_hz, fs_hz, corner_hz)


def default_bandwidth(carrier_hz: float) -> float:
    return 0.4 * carrier_hz


def default_envelope_corner(carrier_hz: float) -> float:
    return min(12.0, carrier_hz / 3.0)


def band_pass_design(settings, system=None) -> Tuple[float, float, int]:
    """(carrier, bandwidth, prototype order) of a receiver's band-pass, zeros in the settings
    resolved to their defaults: an ALSN receiver (``system`` None, core.ReceiverSettings) or a
    digital system's (digital.DigitalReceiverSettings)."""
    if system is None:
        carrier_hz = settings.carrier_hz or ALSN_DEFAULT_CARRIER_HZ
        bandwidth_hz = settings.filter_bandwidth_hz if settings.filter_bandwidth_hz > 0 else default_bandwidth(carrier_hz)
        return carrier_hz, bandwidth_hz, settings.filter_order
    carrier_hz = settings.carrier_hz if settings.carrier_hz > 0 else system.carrier_hz
    bandwidth_hz = settings.filter_bandwidth_hz or DIGITAL_BANDWIDTH_PER_BAUD * system.baud(carrier_hz)
    return carrier_hz, bandwidth_hz, DIGITAL_BAND_PASS_ORDER


def receiver_band_pass(settings, system=None) -> SosFilter:
    """The band-pass of a receiver with these settings (see :func:`band_pass_design`)."""
    carrier_hz, bandwidth_hz, order = band_pass_design(settings, system)
    return band_pass(carrier_hz, bandwidth_hz, order, settings.fs_hz)
