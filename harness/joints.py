"""A train crossing an insulated joint, driven straight into the rail line core without FMI, and
the measures compared with the joints paper (docs/rail_line.md, traction interference at the
joints): for tests/test_rail_line_joints.py and benchmarks/rail_line_sources.py."""
from __future__ import annotations

import numpy as np
from scipy.signal import hilbert

from fmus.data.loader import load_line
from fmus.rail_line.core import RailLineCore, RailSettings
from fmus.rail_line.traction_interference import REFERENCE_TRACTION_A
from fmus.sizes import DEFAULT_SAMPLE_RATE_HZ

FS, N = DEFAULT_SAMPLE_RATE_HZ, 40                   # sample rate [Hz] and frame length [samples] of the runs
JOINT_M = 2600.0                     # the default lines' joint between sections 1 and 2
COIL_OFFSET_M = 1.5                  # the coils ahead of the first wheelset (RailSettings' default)


def cross_joint(speed_kmh, line=None, i_traction=REFERENCE_TRACTION_A, carrier_v=0.0, before_m=40.0,
                after_m=40.0, asymmetry=None, joint_m=JOINT_M, **settings):
    """A train crossing the joint at ``joint_m`` at constant speed (coil 1.5 m ahead of the head);
    a steady current established before (the traction lag settled). ``asymmetry`` overwrites
    every section's rail asymmetry (None: the seeded ones); ``settings`` go to RailSettings (DC
    ripple and harmonics off unless given). Returns (coil position per sample, t, EMF)."""
    settings.setdefault("dc_ripple", (0.0, 0.0))
    settings.setdefault("dc_even_harmonics", (0.0, 0.0))
    core = RailLineCore(line or load_line(), 8, 2, N, RailSettings(**settings))
    if asymmetry is not None:
        core.asymmetry[:] = asymmetry
    v = speed_kmh / 3.6
    x_start = joint_m - COIL_OFFSET_M - before_m
    settle_s = 1.0                               # standing still for the lag to settle
    seconds = settle_s + (before_m + after_m) / v
    emf, coil = [], []
    for k in range(int(round(seconds * FS / N))):
        t = k * N / FS
        times = t + np.arange(N) / FS
        head = x_start + v * np.clip(times - settle_s, 0.0, None)
        u = np.tile(carrier_v * np.sin(2 * np.pi * 50.0 * times), (8, 1))
        out = core.step(t, u, np.array([head[0], -1000.0]), np.array([v if t >= settle_s else 0.0, 0.0]),
                        np.array([i_traction, 0.0]))
        emf.append(out.e_coil[0].copy())
        coil.append(head + COIL_OFFSET_M)
    t = np.arange(len(emf) * N) / FS
    keep = t >= settle_s + 0.05
    return np.concatenate(coil)[keep], t[keep], np.concatenate(emf)[keep]


def pulse_lobes(t, emf):
    """(peak, half-amplitude width, time of the peak) of the positive and of the negative pulse."""
    result = []
    for sign in (1.0, -1.0):
        e = sign * emf
        i = int(np.argmax(e))
        above = e >= 0.5 * e[i]
        lo, hi = i, i
        while lo > 0 and above[lo - 1]:
            lo -= 1
        while hi < e.size - 1 and above[hi + 1]:
            hi += 1
        result.append((e[i], (hi - lo + 1) / FS, t[i]))
    return result


def burst_envelope(emf):
    """The 50 Hz envelope (magnitude of the analytic signal) and its largest value."""
    envelope = np.abs(hilbert(emf))
    return envelope, envelope.max()
