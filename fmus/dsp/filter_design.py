"""Analog filter prototypes (scipy.signal) as python-control transfer functions, discretised
with Tustin and pre-warping — shared by the receivers and the digital generator.

Prototypes are kept in normalised frequency and scaled inside :func:`discretise`: a 6th-order
band-pass in rad/s has coefficients up to 1e16 and an ill-conditioned state-space form.

**Second-order sections.** Every receiver filter is designed and run as a cascade of
second-order sections (:func:`sections`, :class:`SosFilter`): the analog prototype's poles
are taken in conjugate pairs, each pair with its share of the zeros and of the gain is one
python-control transfer function of order two, and each is discretised on its own with the
same pre-warped Tustin map (the bilinear map of a product is the product of the maps, so the
cascade is the discretised whole filter). A band-pass of order 8 as one transfer function
needs its denominator's coefficients to 16 digits and more: at 25 Hz and 4 kHz the sampled
poles sit within 0.04 of z = 1, and the polynomial's rounding moves them — 9 % off the exact
response at the carrier, 85 % at half of it (tests/test_filter_sections.py). As sections it
is exact to about 10⁻¹² of a long-double evaluation of the same prototype. The digital
generator's band-pass (fmus/wayside_coder/digital_generator.py) is a transmitter's, of order four, and
keeps the transfer-function form.

**Imported at the first design.** python-control (which loads matplotlib) and scipy.signal
take about a second to import together. They are imported when a filter is first designed,
so a process that designs none does not pay for them: the run verdicts, which read the
receivers' settings, and a run whose components have no filters (ato_only). See
docs/performance.md#start-up-of-a-run.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy        # scipy.signal loads at its first use (SciPy loads submodules lazily)

from fmus.library_shortcuts import linear_filter, sections_filter

if TYPE_CHECKING:       # imported at the first design, not on import (module docstring)
    import control


def filter_frame(b: np.ndarray, a: np.ndarray, x: np.ndarray, state: np.ndarray, axis: int = -1):
    """scipy.signal.lfilter(b, a, x, axis, zi=state) for one frame of a core's hot path: the
    same C routine (transposed direct form II) without lfilter's argument checks, which the
    cores satisfy by construction (float64 arrays, a[0] = 1, state shaped as lfilter wants);
    fmus/library_shortcuts.py."""
    return linear_filter(b, a, x, axis, state)


@dataclass(frozen=True)
class DiscreteFilter:
    """A discretised filter as one transfer function: b / a, a[0] = 1 (lfilter's layout)."""

    b: np.ndarray
    a: np.ndarray

    def initial_state(self) -> np.ndarray:
        return np.zeros(max(self.a.size, self.b.size) - 1)


@dataclass(frozen=True)
class SosFilter:
    """A filter as a cascade of second-order sections (scipy's ``sos`` layout: one row
    b0 b1 b2 1 a1 a2 per section), the analog prototype it discretises and the map used, so
    the exact response can be evaluated independently (:meth:`exact_response`)."""

    sos: np.ndarray                    # (S, 6)
    prototype_zpk: tuple               # zeros, poles, gain of Hn(s) in normalised frequency
    scale_rad_s: float                 # H(s) = Hn(s / scale)
    fs_hz: float
    prewarp_hz: float

    @property
    def order(self) -> int:
        """Order of the whole filter (its number of poles)."""
        return len(self.prototype_zpk[1])

    def initial_state(self, rows: int = 0) -> np.ndarray:
        """Zero state for sos_frame: (S, 2), or (rows, S, 2) for ``rows`` signals filtered together."""
        return np.zeros((rows, self.sos.shape[0], 2) if rows else (self.sos.shape[0], 2))

    def response(self, frequencies_hz) -> np.ndarray:
        """The discrete cascade's frequency response at these frequencies (float64)."""
        return scipy.signal.sosfreqz(self.sos, worN=np.asarray(frequencies_hz, dtype=float), fs=self.fs_hz)[1]

    def exact_response(self, frequencies_hz) -> np.ndarray:
        """The same response from the analog prototype in long double: the pre-warped Tustin map
        is z = e^{jωT} ↔ s = (2/T_w)·tan(ωT/2), T_w = 2·tan(ω_p·T/2)/ω_p, so the discrete filter
        at ω is the prototype at jΩ/scale, Ω = (2/T_w)·tan(ωT/2); a reference independent of
        how the coefficients were rounded."""
        ld = np.longdouble
        period = ld(1) / ld(self.fs_hz)
        warp = ld(2) * ld(np.pi) * ld(self.prewarp_hz)
        t_warp = ld(2) * np.tan(warp * period / ld(2)) / warp
        omega = ld(2) * ld(np.pi) * np.asarray(frequencies_hz, dtype=ld)
        s = (1j * (ld(2) / t_warp * np.tan(omega * period / ld(2))) / ld(self.scale_rad_s)).astype(np.clongdouble)
        zeros, poles, gain = self.prototype_zpk
        h = np.full(s.shape, np.clongdouble(gain))
        for zero in zeros:
            h = h * (s - np.clongdouble(zero))
        for pole in poles:
            h = h / (s - np.clongdouble(pole))
        return h


def _pole_pairs(poles: np.ndarray):
    """Poles grouped as conjugate pairs (and single real poles), the lowest Q first."""
    poles = np.asarray(poles, dtype=complex)
    upper = [p for p in poles if p.imag > 1e-12 * max(abs(p), 1.0)]
    real = sorted((p.real for p in poles if abs(p.imag) <= 1e-12 * max(abs(p), 1.0)), reverse=True)
    pairs = [(p, p.conjugate()) for p in sorted(upper, key=lambda p: abs(p) / max(-2.0 * p.real, 1e-300))]
    singles = [(complex(a), complex(b)) for a, b in zip(real[0::2], real[1::2])] + \
        ([(complex(real[-1]),)] if len(real) % 2 else [])
    return singles + pairs


def sections(prototype_zpk, scale_rad_s: float, fs_hz: float, prewarp_hz: float) -> SosFilter:
    """Second-order sections of H(s) = Hn(s/scale), Tustin pre-warped at ``prewarp_hz``:
    each conjugate pole pair of the prototype (``prototype_zpk``: zeros, poles, gain, e.g. from
    scipy.signal.buttap and lp2bp_zpk) with up to two of its zeros and an equal share of its
    gain is a python-control transfer function of order ≤ 2, discretised by
    ``control.sample_system(..., 'tustin', prewarp_frequency)`` in normalised frequency (as
    :func:`discretise`); the cascade is the whole filter (module docstring)."""
    import control              # at the first design, not on import (module docstring)
    zeros, poles, gain = (np.asarray(prototype_zpk[0], dtype=complex), np.asarray(prototype_zpk[1], dtype=complex),
                          float(np.real(prototype_zpk[2])))
    groups = _pole_pairs(poles)
    zeros = list(zeros)
    share = abs(gain) ** (1.0 / len(groups))
    rows = []
    for index, group in enumerate(groups):
        mine = [zeros.pop(0) for _ in range(min(len(group), len(zeros)))]
        num = np.real(np.poly(mine)) * (share if index else np.sign(gain) * share)
        den = np.real(np.poly(list(group)))
        discrete = control.sample_system(control.tf(num, den), scale_rad_s / fs_hz, method="tustin",
                                         prewarp_frequency=2 * np.pi * prewarp_hz / scale_rad_s)
        b = np.asarray(discrete.num[0][0], dtype=float)
        a = np.asarray(discrete.den[0][0], dtype=float)
        b, a = np.pad(b, (3 - b.size, 0)) / a[0], np.pad(a, (3 - a.size, 0)) / a[0]
        if a.size and len(group) == 1:          # a first-order section: b0 b1 0 / 1 a1 0
            b, a = np.append(b[1:], 0.0), np.append(a[1:], 0.0)
        rows.append(np.concatenate([b, a]))
    if zeros:
        raise ValueError("sections: more zeros than poles (an improper prototype)")
    return SosFilter(np.array(rows), (np.asarray(prototype_zpk[0], dtype=complex), poles, gain),
                     float(scale_rad_s), float(fs_hz), float(prewarp_hz))


def sos_frame(sos: np.ndarray, x: np.ndarray, state: np.ndarray):
    """scipy.signal.sosfilt(sos, x, zi=state) for one frame of a core's hot path (x: (N,) or
    (rows, N) filtered along its last axis, state (S, 2) or (rows, S, 2)): the same C
    routine without sosfilt's argument checks, which the cores satisfy by construction;
    fmus/library_shortcuts.py. Returns (y, new state); neither argument is changed."""
    return sections_filter(sos, x, state)


class SampleSosFilter:
    """sosfilt(sos) one sample at a time in Python floats, for a build with one sample per
    frame: the operations in the order of scipy's routine (transposed direct form II per
    section), so the samples are sosfilt's bit for bit (tests/test_filter_frame.py);
    ``state`` is its zi as a flat list [z0 of section 0, z1 of section 0, z0 of section 1, …]."""

    __slots__ = ("_rows", "state")

    def __init__(self, sos: np.ndarray):
        self._rows = [tuple(float(v) for v in (row[0], row[1], row[2], row[4], row[5])) for row in np.asarray(sos)]
        self.state = [0.0] * (2 * len(self._rows))

    def __call__(self, x: float) -> float:
        z = self.state
        i = 0
        for b0, b1, b2, a1, a2 in self._rows:
            y = b0 * x + z[i]
            z[i] = b1 * x - a1 * y + z[i + 1]
            z[i + 1] = b2 * x - a2 * y
            x = y
            i += 2
        return x


def discretise(normalised: control.TransferFunction, scale_rad_s: float, fs_hz: float,
                prewarp_hz: float) -> DiscreteFilter:
    """Tustin with pre-warping of H(s) = Hn(s/scale). The prototype is kept in normalised
    frequency (coefficients of order one; a 6th-order band-pass in rad/s has coefficients up
    to 1e16 and an ill-conditioned state-space form), and Tustin commutes with frequency
    scaling: sample Hn at Ts·scale with the pre-warp frequency divided by scale."""
    import control
    discrete = control.sample_system(normalised, scale_rad_s / fs_hz, method="tustin",
                                     prewarp_frequency=2 * np.pi * prewarp_hz / scale_rad_s)
    num = np.asarray(discrete.num[0][0], dtype=float)
    den = np.asarray(discrete.den[0][0], dtype=float)
    return DiscreteFilter(num / den[0], den / den[0])




def chebyshev_band_pass(centre_hz: float, bandwidth_hz: float, prototype_order: int, ripple_db: float,
                        fs_hz: float) -> DiscreteFilter:
    """Chebyshev type I band-pass of order 2·prototype_order, ripple band centre ± bandwidth/2
    (geometric centre), pre-warped at the centre."""
    import control
    zeros, poles, gain = scipy.signal.cheb1ap(prototype_order, ripple_db)
    b, a = scipy.signal.zpk2tf(zeros, poles, gain)
    b, a = scipy.signal.lp2bp(b, a, wo=1.0, bw=bandwidth_hz / centre_hz)
    return discretise(control.tf(b, a), 2 * np.pi * centre_hz, fs_hz, centre_hz)


def chebyshev_low_pass(corner_hz: float, order: int, ripple_db: float, fs_hz: float) -> SosFilter:
    """Chebyshev type I low-pass (ripple band up to the corner), pre-warped at the corner, as
    second-order sections (a receiver's anti-alias filter)."""
    return sections(scipy.signal.cheb1ap(order, ripple_db), 2 * np.pi * corner_hz, fs_hz, corner_hz)
