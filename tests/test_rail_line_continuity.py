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


def _run_traction(seconds, x_of_t, v_of_t, i_of_t):
    """No code: the coil EMF is the traction interference alone (DC, no ripple)."""
    core = RailLineCore(load_line(), 8, 2, N, RailSettings(dc_ripple=(0.0, 0.0), dc_even_harmonics=(0.0, 0.0)))
    core.asymmetry[:] = 0.03
    emf = []
    for k in range(int(round(seconds * FS / N))):
        t = k * N / FS
        x, v, i = (_extrapolated(f, t) for f in (x_of_t, v_of_t, i_of_t))
        out = core.step(t, np.zeros((8, N)), np.array([x, -1000.0]), np.array([v, 0.0]), np.array([i, 0.0]))
        emf.append(out.e_coil[0].copy())
    return np.arange(len(emf) * N) / FS, np.concatenate(emf)


def test_coil_emf_has_no_step_at_slow_steps_through_a_joint():
    """An accelerating train crosses a joint under DC traction with its position, speed and
    current extrapolated between the traction unit's 0.5 s steps: the EMF pulse pair is smooth —
    no sample-to-sample step at a slow-step boundary or a frame boundary larger than the pulse's
    own largest one (before: the corrected position jumped by up to 15 cm at each slow step and
    by millimetres at every frame, a spike of volts in the bond leads' field; a correction
    spread linearly over 10 ms still stepped the speed, and the EMF, by 70 %)."""
    x0, v0, acc = 2600.0 - 1.5 - 30.0, 20.0, 0.6          # the coils reach the joint after ≈ 1.5 s
    x_of_t = lambda t: x0 + v0 * t + 0.5 * acc * t * t
    v_of_t = lambda t: v0 + acc * t
    i_of_t = lambda t: 800.0 + 200.0 * t + 40.0 * t * t   # the traction current rising
    t, emf = _run_traction(3.0, x_of_t, v_of_t, i_of_t)
    pulse = (t > 0.6)
    step = np.abs(np.diff(emf))[pulse[1:]]
    assert np.abs(emf[pulse]).max() > 0.5                  # the pair is there
    # the pair's own steepest change: each of the coil's five sensitivity points turning a
    # corner of the leads' field in one sample, a fifth of the peak; a position step of 1 cm in
    # the field adds ≈ peak × 0.01 m / 1.31 m × (1.31 m / v) · fs ≈ peak · 1.9 on its own
    flank = np.abs(emf[pulse]).max() / 5.0
    assert step.max() < 1.05 * flank, (step.max(), flank, t[1:][pulse[1:]][step.argmax()])
    boundaries = [round(b * FS) for b in np.arange(1.0, 3.0, 0.5)]
    for b in boundaries:
        around = np.abs(np.diff(emf[b - 3:b + 4]))
        assert around.max() < 1.05 * flank


def test_coil_emf_is_continuous_at_slow_steps_with_a_steady_carrier():
    """A steady 50 Hz carrier, the train accelerating in mid-section: at every slow-step
    boundary the EMF is a sinusoid without a step (the node changes of the lumped shunts are
    excluded: docs/rail_line.md, simplifications)."""
    x0, v0, acc = 8100.0, 15.0, 0.6
    x_of_t = lambda t: x0 + v0 * t + 0.5 * acc * t * t
    v_of_t = lambda t: v0 + acc * t
    t, emf = _run(x_of_t, v_of_t, 12.0)
    residual = np.abs(_carrier_residual(emf, 50.0))
    amplitude = np.abs(emf[t > 1.0]).max()
    worst = []
    for b in np.arange(1.5, 12.0, 0.5):
        i = round(b * FS)
        worst.append(residual[i - 4:i + 4].max() / amplitude)
    # most slow steps fall clear of a node change: there the EMF has no step at all
    assert np.median(worst) < 1e-4, worst
