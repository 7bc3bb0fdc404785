"""Rail line: the coil EMF has no discontinuity where the trains' inputs are corrected at the
traction unit's slow steps (extrapolated position, speed and traction current) or where a
train's lumped wheelset shunts move on to the next network node (docs/rail_line.md, connecting
a train)."""
import numpy as np

from fmus.data.loader import load_line
from fmus.rail_line.core import RailLineCore, RailSettings

FS, N = 4000.0, 40
SLOW_S = 0.5                      # the traction unit's step


def _extrapolated(f, t):
    """What a linear rate transition delivers at t: f extrapolated from its values at the last
    two slow steps (the traction unit publishes its state at the end of each step)."""
    t1 = np.floor(t / SLOW_S + 1e-9) * SLOW_S
    t0 = t1 - SLOW_S
    return f(t1) + (f(t1) - f(t0)) / SLOW_S * (t - t1)


def _carrier_residual(emf: np.ndarray, carrier_hz: float) -> np.ndarray:
    """e[n] − 2cos(ωΔ)·e[n−1] + e[n−2]: zero for a sinusoid of the carrier, ≈ the step for a
    jump of the EMF (slow amplitude changes leave ≈ 10⁻⁵ of the amplitude)."""
    c = 2 * np.cos(2 * np.pi * carrier_hz / FS)
    return emf[2:] - c * emf[1:-1] + emf[:-2]


def _run(x_of_t, v_of_t, seconds, t0=0.0, i_of_t=None, settings=None):
    core = RailLineCore(load_line(), 8, 2, N, RailSettings(**(settings or {})))
    i_of_t = i_of_t or (lambda t: 0.0)
    emf = []
    for k in range(int(round(seconds * FS / N))):
        t = t0 + k * N / FS
        times = t + np.arange(N) / FS
        u = np.tile(np.sin(2 * np.pi * 50.0 * times), (8, 1))        # a steady carrier everywhere
        x, v, i = (_extrapolated(f, t) for f in (x_of_t, v_of_t, i_of_t))
        out = core.step(t, u, np.array([x, -1000.0]), np.array([v, 0.0]), np.array([i, 0.0]))
        emf.append(out.e_coil[0].copy())
    return t0 + np.arange(len(emf) * N) / FS, np.concatenate(emf)


def test_coil_emf_is_continuous_at_slow_steps_and_node_changes():
    # accelerating at 0.6 m/s² from 15 m/s in section 4: 60 slow steps, ≈ 20 network nodes
    x0, v0, acc = 8100.0, 15.0, 0.6
    x_of_t = lambda t: x0 + v0 * t + 0.5 * acc * t * t
    v_of_t = lambda t: v0 + acc * t
    t, emf = _run(x_of_t, v_of_t, 30.0)
    settled = t[2:] > 1.0                                   # after the network's start-up
    residual = np.abs(_carrier_residual(emf, 50.0))[settled]
    amplitude = np.abs(emf[2:][settled]).max()
    assert amplitude > 0.1
    # at the slow-step boundaries and everywhere else: no step above 0.1 % of the EMF
    # (before the fix: 3–4 % at every node the shunts moved to, and the position jumped by up to 9 cm)
    assert residual.max() < 1e-3 * amplitude, (residual.max() / amplitude, t[2:][settled][residual.argmax()])
