"""Rail line: interference at insulated joints against the joints paper's table of effects
(docs/sources.md#interference-at-insulated-joints; docs/rail_line.md, traction interference at
the joints). One test per row the paper quantifies, each within ±10 %."""
import numpy as np
import pytest

from harness.joints import FS, JOINT_M, N, burst_envelope, cross_joint, pulse_lobes
from fmus.data.loader import load_line
from fmus.rail_line.core import RailLineCore, RailSettings


def test_dc_traction_two_opposite_pulses_as_in_the_paper():
    """Table row 6 at 80 km/h: two pulses of opposite polarity, each 0.059 s wide at half
    amplitude, the spectrum's envelope largest at 5 Hz with the energy below 20 Hz, the
    largest EMF 0.925 V (matched coils, the reference traction current, the same rail
    asymmetry on both sides)."""
    _, t, emf = cross_joint(80.0, asymmetry=0.03)
    (up, up_width, up_t), (down, down_width, down_t) = pulse_lobes(t, emf)
    assert max(up, down) == pytest.approx(0.925, rel=0.10)
    assert min(up, down) > 0.9 * max(up, down)                 # a pair, one of each polarity
    assert abs(up_t - down_t) < 0.2
    assert up_width == pytest.approx(0.059, rel=0.10)
    assert down_width == pytest.approx(0.059, rel=0.10)
    spectrum = np.abs(np.fft.rfft(emf, 1 << 16))
    f = np.fft.rfftfreq(1 << 16, 1.0 / FS)
    assert f[np.argmax(spectrum)] == pytest.approx(5.0, rel=0.10)
    energy = spectrum ** 2
    assert energy[f <= 20.0].sum() > 0.9 * energy.sum()


def test_coil_pair_mismatch_of_5_percent_gives_5_v():
    """Table row 6: with 5 % asymmetry of the coils the EMF reaches 5 V."""
    _, t, emf = cross_joint(80.0, asymmetry=0.03, coil_mismatch=0.05)
    assert np.abs(emf).max() == pytest.approx(5.0, rel=0.10)
    _, _, matched = cross_joint(80.0, asymmetry=0.03, coil_mismatch=0.0)
    assert np.abs(matched).max() < 0.2 * np.abs(emf).max()


@pytest.mark.parametrize("speed_kmh", [40.0, 160.0])
def test_dc_pulses_depend_on_speed(speed_kmh):
    """Table row 6: the pulses depend on speed — the motion over the bond leads' field makes
    them: amplitude ∝ v, width ∝ 1/v."""
    _, t, emf = cross_joint(speed_kmh, asymmetry=0.03)
    (up, width, _), _ = pulse_lobes(t, emf)
    assert up == pytest.approx(0.925 * speed_kmh / 80.0, rel=0.10)
    assert width == pytest.approx(0.059 * 80.0 / speed_kmh, rel=0.10)


def test_every_joint_gives_two_opposite_pulses_with_the_default_asymmetries():
    """With the seeded per-section asymmetries (1–5 %, either sign) every joint still gives a
    pair of opposite pulses: the bond leads' field dominates the rails' asymmetry step."""
    line = load_line()
    core = RailLineCore(line, 8, 2, N, RailSettings())
    asymmetry = core.asymmetry.copy()
    for joint in [j["position_m"] for j in line.joints][1:]:
        k = int(np.searchsorted([s.end_m for s in line.sections], joint))
        _, t, emf = cross_joint(80.0, asymmetry=None, before_m=10.0, after_m=10.0, joint_m=joint)
        (up, _, _), (down, _, _) = pulse_lobes(t, emf)
        assert min(up, down) > 0.5 * max(up, down), (joint, asymmetry[k - 1:k + 1], up, down)


def test_ac_traction_additive_50_hz_pulses_independent_of_speed():
    """Table row 5: AC traction gives additive 50 Hz pulses at the joint, their amplitude
    independent of speed, their duration set by speed (the zone's length over v)."""
    line = load_line(str(__import__("fmus.data.loader", fromlist=["x"]).DEFAULT_LINE).replace(
        "default_line.json", "default_line_ac.json"))
    peaks, lengths = {}, {}
    for speed in (40.0, 80.0, 160.0):
        coil, t, emf = cross_joint(speed, line=line, i_traction=300.0, asymmetry=0.03)
        envelope, peak = burst_envelope(emf)
        # away from the joint: only the rails' asymmetry; at the joint: the burst on top
        away = envelope[(np.abs(coil - JOINT_M) > 10.0) & (np.abs(coil - JOINT_M) < 30.0)].max()
        assert peak > 3.0 * away
        spectrum = np.abs(np.fft.rfft(emf * np.hanning(emf.size), 1 << 16))
        f = np.fft.rfftfreq(1 << 16, 1.0 / FS)
        assert f[np.argmax(spectrum)] == pytest.approx(50.0, abs=2.0)
        burst = envelope - away
        wide = burst > 0.5 * burst.max()
        peaks[speed], lengths[speed] = peak, wide.sum() / FS * speed / 3.6
    assert peaks[40.0] == pytest.approx(peaks[80.0], rel=0.10)
    assert peaks[160.0] == pytest.approx(peaks[80.0], rel=0.10)
    # the same length of track at every speed: duration ∝ 1/v
    assert lengths[40.0] == pytest.approx(lengths[80.0], rel=0.10)
    assert lengths[160.0] == pytest.approx(lengths[80.0], rel=0.10)


def test_null_zone_of_1_m_and_weak_zone_of_1_5_m():
    """Table rows 1 and 2: no signal current over ≈ 1 m from the feed-end bond leads to the
    joint; then ≈ 1.5 m of the next circuit's weak, unshunted current until the first wheelset
    crosses (the coils 1.5 m ahead of it). Measured from the code current's envelope at the coil
    (the integrated EMF) at walking pace, where a 50 Hz envelope resolves centimetres."""
    from scipy.signal import hilbert
    gain = RailSettings().coil_gain_h
    coil, t, emf = cross_joint(5.0, i_traction=0.0, carrier_v=4.0, before_m=5.0, after_m=5.0)
    current = np.cumsum(emf) / (FS * gain)
    current -= np.convolve(current, np.ones(80) / 80, mode="same")
    envelope = np.abs(hilbert(current))
    x = coil - JOINT_M
    strong = envelope[(x > -3.0) & (x < -2.0)].mean()          # the feed end of the section left
    weak = envelope[(x > 0.4) & (x < 1.1)].mean()              # the next section, not shunted yet
    shunted = envelope[(x > 2.0) & (x < 3.0)].mean()           # the next section, shunted
    assert strong > 5 * shunted > 5 * weak
    null_start = x[np.argmax((x > -2.0) & (envelope < 0.5 * strong))]       # half-way down
    inside = x[np.argmax((x > null_start) & (envelope < 0.5 * weak))]
    null_end = x[np.argmax((x > inside) & (envelope > 0.5 * weak))]          # half-way up
    weak_end = x[np.argmax((x > null_end) & (envelope > 0.5 * (weak + shunted)))]
    assert null_end - null_start == pytest.approx(1.0, rel=0.10)
    assert weak_end - null_end == pytest.approx(1.5, rel=0.10)


def test_a_line_file_listing_its_joints_out_of_order_couples_the_same(tmp_path):
    """The interference around each joint does not depend on the order the line file lists the
    joints in (the joint search needs them sorted)."""
    import json
    from fmus.data.loader import DEFAULT_LINE

    document = json.loads(DEFAULT_LINE.read_text())
    document["insulated_joints"] = document["insulated_joints"][::-1]
    reversed_line = tmp_path / "reversed_joints.json"
    reversed_line.write_text(json.dumps(document))
    x = np.linspace(0.0, load_line().length_m, 200_001)
    couplings = [RailLineCore(load_line(path), 8, 2, N, RailSettings()).interference.coupling(x)
                 for path in (DEFAULT_LINE, reversed_line)]
    np.testing.assert_array_equal(couplings[0], couplings[1])
