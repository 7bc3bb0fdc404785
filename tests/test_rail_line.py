"""Rail line: the network against the two-port equations, track-relay regimes, ALS mode, coil
EMF through joints, traction interference, faults, frame invariance, the FMU in the chain."""
import numpy as np
import pytest
from scipy.signal import hilbert

from fmus.data.loader import load_line
from fmus.errors import FmuInputError
from fmus.rail_line.core import RailLineCore, RailSettings
from fmus.rail_line.track_circuit import CircuitParameters, Faults, cascade_shunt_current, rail_impedance, two_port
from helpers import ComponentSpec, ConnectionSpec, railcosim, read_csv, write_ssd

FS, N = 4000.0, 40
W50 = 2 * np.pi * 50.0


def test_worked_example_two_port_is_reproduced():
    """docs/sources.md#track-circuits-and-rail-impedance: z = 0.52 + j1.224 Ω/km, r_и = 1 Ω·km, l = 0.3 km."""
    abcd = two_port(0.52 + 1.224j, 1.0, 0.3)
    assert abcd[0, 0] == pytest.approx(1.023 + 0.055j, abs=1e-3)
    assert abcd[0, 1] == pytest.approx(0.151 + 0.373j, abs=1.5e-3)
    assert abcd[1, 0] == pytest.approx(0.302 + 0.006j, abs=1e-3)
    assert np.linalg.det(abcd) == pytest.approx(1.0)


def _steady_carrier_core(line=None, **settings):
    core = RailLineCore(line or load_line(), 8, 2, N, RailSettings(**settings))
    return core


def _run(core, seconds, x_of_t, v, u_amplitude=1.0, i_traction=0.0, sections=None):
    """Continuous carrier into every section (or ``sections``); returns (t, e_coil of train 1, i_axle)."""
    emf, axle = [], []
    for k in range(int(round(seconds * FS / N))):
        t = k * N / FS
        times = t + np.arange(N) / FS
        u = np.zeros((8, N))
        for s in (sections if sections is not None else range(8)):
            u[s] = u_amplitude * np.sin(W50 * times)
        out = core.step(t, u, np.array([x_of_t(t), -1000.0]), np.array([v, 0.0]), np.array([i_traction, 0.0]))
        emf.append(out.e_coil[0].copy())
        axle.append(out.i_axle[0])
    return np.arange(len(emf) * N) / FS, np.concatenate(emf), np.array(axle)


@pytest.mark.parametrize("x_m", [7850.0, 8600.0, 9137.0, 9900.0, 10350.0])
def test_code_current_under_the_first_axle_matches_the_two_port_solution(x_m):
    core = _steady_carrier_core(transformer_ratio=1.0)
    _, _, axle = _run(core, 0.6, lambda t: x_m, 0.0, sections=[3])
    measured = axle[-20:].mean() * np.sqrt(2.0)          # rms over whole periods → amplitude
    expected = cascade_shunt_current(core.circuits[3], x_m, wheelsets_m=core.settings.wheelset_offsets_m[0])
    assert measured == pytest.approx(expected, rel=0.01)


def test_code_current_is_continuous_as_the_train_moves():
    core = _steady_carrier_core(transformer_ratio=1.0)
    positions = np.linspace(8000.0, 8200.0, 41)
    currents = []
    for x in positions:
        _, _, axle = _run(core, 0.1, lambda t, x=x: x, 0.0, sections=[3])
        currents.append(axle[-5:].mean())
    steps = np.abs(np.diff(currents)) / np.mean(currents)
    assert steps.max() < 0.01                            # no jumps at the 50 m model nodes


def _relay_levels(ballast, node=None, broken=-1.0, supply=1.0):
    core = _steady_carrier_core()
    k = 3
    faults = Faults(ballast, broken, False)
    return core.bank.relay_level(k, () if node is None else (node,), faults, supply)


def test_normal_mode_relay_picks_up_at_minimum_ballast():
    settings = RailSettings()
    assert _relay_levels(1.0, supply=1.0 - settings.supply_tolerance) >= settings.relay_pick_up


def test_shunt_mode_relay_drops_with_a_normative_shunt_anywhere_at_maximum_ballast():
    settings = RailSettings()
    circuit = _steady_carrier_core().circuits[3]
    for node in range(0, circuit.segments + 1):
        level = _relay_levels(50.0, node, supply=1.0 + settings.supply_tolerance)
        assert level * (1 + settings.shunt_margin) < settings.relay_drop_out, node


def test_control_mode_relay_drops_on_a_broken_rail():
    settings = RailSettings()
    for position in (7900.0, 9000.0, 10300.0):
        assert _relay_levels(1.0, None, position, supply=1.0 + settings.supply_tolerance) < settings.relay_drop_out


def test_occupancy_follows_the_train_with_relay_delays():
    core = _steady_carrier_core()
    occupied = []
    for k in range(int(3.0 * FS / N)):
        t = k * N / FS
        x = 5000.0 if t < 1.0 else -1000.0
        out = core.step(t, np.zeros((8, N)), np.array([x, -1000.0]), np.zeros(2), np.zeros(2))
        occupied.append(out.occupied[:3].copy())
    occupied = np.array(occupied)
    t_end = (np.arange(len(occupied)) + 1) * N / FS
    # section 2 (2600..5200) and its neighbour under the 400 m train: drop after 0.2 s
    assert occupied[t_end > 0.25][0].tolist() == [False, True, False]
    # cleared at 1.0 s: picks up after the 1.0 s pick-up delay
    assert occupied[(t_end > 1.05) & (t_end < 1.95), 1].all()
    assert not occupied[t_end > 2.1, 1].any()


def test_rail_impedance_reproduces_the_worked_example_and_grows_with_sqrt_f():
    """docs/rail_line.md, rail impedance per frequency: the worked example at its own frequency,
    the internal part ∝ √f (equal R and X) elsewhere."""
    params = CircuitParameters()
    r, l = rail_impedance(params, params.rail_reference_hz)
    assert complex(r, 2 * np.pi * params.rail_reference_hz * l) == pytest.approx(0.520 + 1.224j, abs=2e-3)
    x_int0 = 2 * np.pi * params.rail_reference_hz * params.rail_internal_l_h_per_km
    for f in (25.0, 50.0, 75.0, 175.0):
        r, l = rail_impedance(params, f)
        internal = complex(r - (0.52 - x_int0), 2 * np.pi * f * (l - (1.18e-3 - params.rail_internal_l_h_per_km)))
        assert internal == pytest.approx(complex(x_int0, x_int0) * np.sqrt(f / params.rail_reference_hz), rel=1e-9)
    assert rail_impedance(params, 25.0)[0] < rail_impedance(params, 50.0)[0] < rail_impedance(params, 175.0)[0]


@pytest.mark.parametrize("line_name, carrier_hz, norm_a", [("default_line_ac.json", 25.0, 1.4),
                                                           ("default_line.json", 50.0, 1.4),
                                                           ("default_line.json", 75.0, 1.2)])
def test_als_mode_code_current_per_carrier(line_name, carrier_hz, norm_a):
    """ALS mode per ALSN carrier with the rails' impedance at that carrier: the smallest code
    current under the first wheelset, over all positions and sections, at the normative minimum
    ballast (1 Ω·km) and above, meets the minimum code current."""
    from fmus.data.loader import DEFAULT_LINE
    line = load_line(str(DEFAULT_LINE).replace("default_line.json", line_name))
    core = RailLineCore(line, 8, 2, N, RailSettings(carrier_hz=carrier_hz))
    assert core.bank.geometry.carriers[0] == carrier_hz
    for ballast in (1.0, 2.5, 50.0):
        assert min(core.minimum_code_current(k, ballast) for k in range(8)) >= norm_a, ballast


def test_als_mode_minimum_code_current_per_section():
    core = _steady_carrier_core()
    table = {b: [core.minimum_code_current(k, b) for k in range(8)] for b in (1.0, 2.0, 5.0, 20.0, 50.0)}
    # the design point: the longest sections at the normative minimum ballast get ≈ 1.4 A rms
    assert 1.3 <= min(table[1.0]) <= 1.6
    for ballast, currents in table.items():
        assert min(currents) >= 1.2, ballast


def _envelope_of_current(emf, gain):
    current = np.cumsum(emf) / (FS * gain)
    current -= np.convolve(current, np.ones(80) / 80, mode="same")     # remove the integration offset
    return np.abs(hilbert(current))


@pytest.mark.parametrize("speed_kmh", [80.0, 160.0])
def test_joint_crossing_null_and_weak_zones_scale_with_speed(speed_kmh):
    v = speed_kmh / 3.6
    joint = 2600.0
    core = _steady_carrier_core()
    start = joint - 1.5 - 20.0
    t, emf, _ = _run(core, 40.0 / v, lambda t: start + v * t, v)
    env = _envelope_of_current(emf, core.settings.coil_gain_h)
    coil = start + v * t + core.settings.coil_offset_m
    strong = np.median(env[(coil > joint - 10) & (coil < joint - 3)])
    weak = np.median(env[(coil > joint + 4) & (coil < joint + 10)])
    assert strong > 5 * weak                     # feed end of one section vs entry end of the next
    # quiet: well below the weak zone's level (the unshunted entry end: ≈ 0.19 of the shunted
    # level beyond, the rail current at the joint as the wheelset chain gives it)
    quiet = (coil > joint - 3) & (coil < joint + 4) & (env < 0.15 * weak)
    null_m = quiet.sum() / FS * v
    # the ≈ 1 m null zone (docs/sources.md#interference-at-insulated-joints), smeared by the coil and by the envelope (one carrier period)
    assert 0.5 <= null_m <= 1.5


def test_frame_length_does_not_change_the_coil_emf():
    # a train running under traction current (its position updated every 0.5 s) and one
    # standing in another section: a build with one sample per frame (its own float path)
    # gives the 10 ms frames' EMF and axle current
    line = load_line()
    results = {}
    v = 100 / 3.6
    for frame in (1, 40):
        core = RailLineCore(line, 8, 2, frame, RailSettings())
        emf, axle = [], []
        for k in range(int(1.2 * FS / frame)):
            t = k * frame / FS
            times = t + np.arange(frame) / FS
            u = np.tile(np.where(np.sin(2 * np.pi * 0.9 * times) > 0, 4.0, 0.0) * np.sin(W50 * times), (8, 1))
            x = 2580.0 + v * np.floor(t / 0.5) * 0.5
            out = core.step(t, u, np.array([x, 4200.0]), np.array([v, 0.0]), np.array([500.0, 0.0]))
            emf.append(out.e_coil.copy())
            axle.append(out.i_axle.copy())          # the rms of the frame's samples
        results[frame] = np.concatenate(emf, axis=1), np.array(axle)
    (emf_1, axle_1), (emf_40, axle_40) = results[1], results[40]
    assert np.abs(emf_40).max(axis=1).min() > 0.01           # both coils see code
    np.testing.assert_allclose(emf_1, emf_40, rtol=1e-9, atol=1e-12)
    rms_of_40 = np.sqrt(np.mean(axle_1.reshape(-1, 40, 2) ** 2, axis=1))
    np.testing.assert_allclose(rms_of_40, axle_40, rtol=1e-9, atol=1e-12)


def _keyed_run(core, seconds, x0_m, v_mps, ballast_at=None):
    """Keyed code in every section, the train from x0_m at v_mps; ``ballast_at`` (t0, t1, k):
    section k's ballast overridden to 3 Ω·km from t0 to t1. Returns (e_coil, i_axle, occupied)."""
    emf, axle, occupied, parked = [], [], [], set()
    for frame in range(int(round(seconds * FS / N))):
        t = frame * N / FS
        times = t + np.arange(N) / FS
        ballast = np.zeros(8)
        if ballast_at is not None and ballast_at[0] <= t < ballast_at[1]:
            ballast[ballast_at[2]] = 3.0
        core.set_faults(-1.0, ballast, np.zeros(8, dtype=bool))
        u = np.where(np.sin(2 * np.pi * 0.9 * times + 2.0 * np.arange(8)[:, None]) > 0, 4.0, 0.0) * np.sin(W50 * times)
        out = core.step(t, u, np.array([x0_m + v_mps * t, -1000.0]), np.array([v_mps, 0.0]), np.zeros(2))
        emf.append(out.e_coil[0].copy())
        axle.append(out.i_axle[0])
        occupied.append(out.occupied.copy())
        parked.update(k for k, at in enumerate(core.bank.parking.parked_at) if at is not None)
    return np.concatenate(emf), np.array(axle), np.array(occupied), parked


def test_sections_without_a_train_parked_and_caught_up_give_the_same_currents(monkeypatch):
    """A section no train or coil needs is not advanced; when a train or a coil needs it again
    (here section 2 after 6 s, and every parked section when a fault changes), it is caught up
    from its code input's history: the coil sees what it sees when every section advances
    every frame (docs/rail_line.md, performance)."""
    line = load_line()
    parked_core = RailLineCore(line, 8, 2, N, RailSettings())
    from fmus.rail_line import parking
    monkeypatch.setattr(parking, "HISTORY_FLOATS", 0)       # no history: nothing parked
    live_core = RailLineCore(line, 8, 2, N, RailSettings())
    run = dict(seconds=9.0, x0_m=2300.0, v_mps=40.0, ballast_at=(3.0, 4.5, 5))
    emf, axle, occupied, parked = _keyed_run(parked_core, **run)
    emf_live, axle_live, occupied_live, never = _keyed_run(live_core, **run)
    assert not never and {1, 5, 7} <= parked
    assert emf.std() > 0.05 and axle[-1] > 0.5                       # the coil over section 2's code
    assert np.allclose(emf, emf_live, rtol=0.0, atol=1e-12 * np.abs(emf_live).max())
    assert np.allclose(axle, axle_live, rtol=1e-12, atol=0.0)
    assert (occupied == occupied_live).all()


def test_sections_of_one_design_share_their_network_models_with_the_same_results(monkeypatch):
    """Sections alike relative to their start (the default line's first four) share their
    network models: a train entering section 2 meets the configurations it had at the start of
    section 1 again, and gets the very same numbers as with a model made per section."""
    from fmus.rail_line import network_models

    made = []
    discretise = network_models.discretise
    monkeypatch.setattr(network_models, "discretise", lambda *args: made.append(1) or discretise(*args))
    run = dict(seconds=6.0, x0_m=2450.0, v_mps=50.0)

    def models_made(per_section):
        if per_section:
            fault_key = network_models.NetworkModels.fault_key
            monkeypatch.setattr(network_models.NetworkModels, "fault_key",
                                lambda models, k, faults: (k, fault_key(models, k, faults)))
        made.clear()
        core = RailLineCore(load_line(), 8, 2, N, RailSettings())
        core.step(0.0, np.zeros((8, N)), np.array([-1000.0, -1000.0]), np.zeros(2), np.zeros(2))
        for head_m in range(0, 450, 10):        # section 1's first configurations (section 2's after 2600 m)
            core.bank.follow_shunts([float(head_m), -1000.0])
        made.clear()
        return _keyed_run(core, **run), len(made)

    (emf, axle, occupied, _), shared = models_made(per_section=False)
    (emf_own, axle_own, occupied_own, _), own = models_made(per_section=True)
    assert own - shared >= 3, (shared, own)       # section 2 (index 1) made nothing new
    assert np.array_equal(emf, emf_own) and np.array_equal(axle, axle_own) and (occupied == occupied_own).all()


def test_bad_parameters_are_named_and_off_line_trains_reported(tmp_path):
    with pytest.raises(FmuInputError, match="parameter coil_gain"):
        RailLineCore(load_line(), 8, 2, N, RailSettings(coil_gain_h=0.0))
    with pytest.raises(FmuInputError, match="parameter relay_drop_out"):
        RailLineCore(load_line(), 8, 2, N, RailSettings(relay_drop_out=0.9))
    with pytest.raises(FmuInputError, match="rebuild with `railcosim build --sections 8`"):
        RailLineCore(load_line(), 4, 2, N, RailSettings())
    core = _steady_carrier_core()
    out = core.step(0.0, np.zeros((8, N)), np.array([25000.0, -5.0]), np.zeros(2), np.zeros(2))
    assert out.off_line.tolist() == [True, True] and not out.e_coil.any()


# ---- the FMUs in the signal chain -----------------------------------------------------------------
def test_coder_rail_line_receiver_chain_decodes_under_a_moving_train(tmp_path, product_fmus):
    """Coder → rail line → receiver through the orchestrator; the train is a scripted position
    (TestSchedule is a step function, so the rail line's own extrapolation x + v·t moves it)."""
    fmus = product_fmus
    k, n = 8, N
    components = [
        ComponentSpec("coder", str(fmus / "WaysideCoder.fmu"), 0.01),
        ComponentSpec("rail", str(fmus / "RailLine.fmu"), 0.01),
        ComponentSpec("rx", str(fmus / "LocoReceiver.fmu"), 0.01),
    ]
    connections = [ConnectionSpec(f"coder.u_tx[{a},{b}]", f"rail.u_tx[{a},{b}]") for a in range(1, k + 1) for b in range(1, n + 1)]
    connections += [ConnectionSpec(f"rail.occupied[{a}]", f"coder.occupied[{a}]") for a in range(1, k + 1)]
    connections += [ConnectionSpec(f"rail.e_coil[1,{b}]", f"rx.e_coil[{b}]") for b in range(1, n + 1)]
    folder = tmp_path / "chain"
    write_ssd(folder, "chain", components, connections, stop_time=8.0)
    code, _, stderr = railcosim("run", folder, "--output", tmp_path / "out", "--no-build",
                                "--set", "rail.x_head[1]=1500", "--set", "rail.v[1]=22.2",
                                "--record", "rx.aspect", "--record", "rx.code_valid",
                                "--record", "rail.occupied[1]", "--record", "coder.code_tx[1]")
    assert code == 0, stderr
    header, data = read_csv(tmp_path / "out" / "results.csv")
    last = dict(zip(header, data[-1]))
    assert last["rail.occupied[1]"] == 1 and last["coder.code_tx[1]"] == 4
    assert last["rx.aspect"] == 4 and last["rx.code_valid"] == 1


def test_faults_injected_as_inputs_drop_the_relay_and_the_code():
    core = _steady_carrier_core()
    free = np.zeros(8)
    no_feed = np.zeros(8, dtype=bool)

    def settle(broken=-1.0, ballast=free, feed_open=no_feed, x=-1000.0):
        core.set_faults(broken, ballast, feed_open)
        _, _, axle = _run(core, 3.0, lambda t: x, 0.0, sections=range(8))   # bond L/R ≈ 0.4 s: let it settle
        return core.out.occupied[:8].copy(), axle[-10:].mean()

    occupied, _ = settle()
    assert not occupied.any()
    occupied, _ = settle(broken=9000.0)                       # broken rail in section 4
    assert occupied.tolist() == [False, False, False, True, False, False, False, False]
    wet = free.copy()
    wet[5] = 0.4                                               # section 6 ballast well below the design 1 Ω·km
    occupied, _ = settle(ballast=wet)
    assert occupied[5] and occupied.sum() == 1                 # right-side failure: shows occupied
    _, coded = settle(x=9000.0)
    feed = no_feed.copy()
    feed[3] = True                                             # bond disconnected / transmitter failed in section 4
    occupied, cut = settle(feed_open=feed, x=9000.0)
    assert occupied[3] and coded > 0.5 and cut < 0.01 * coded


def test_ac_traction_adds_50_hz_and_odd_harmonics_at_the_coil():
    import json
    from fmus.data.loader import DATA

    line = load_line(DATA / "default_line_ac.json")
    core = RailLineCore(line, 8, 2, N, RailSettings())
    core.asymmetry[:] = 0.02
    _, emf, _ = _run(core, 1.0, lambda t: 5000.0, 0.0, u_amplitude=0.0, i_traction=300.0)
    spectrum = np.abs(np.fft.rfft(emf[int(0.5 * FS):]))
    freqs = np.fft.rfftfreq(emf[int(0.5 * FS):].size, 1 / FS)
    peak = {f: spectrum[np.argmin(np.abs(freqs - f))] for f in (50, 100, 150, 250)}
    assert peak[50] > 5 * peak[100] and peak[150] > 5 * peak[100] and peak[250] > 5 * peak[100]
    # EMF amplitude at 50 Hz = M·ω·a·I·√2
    expected = core.settings.coil_gain_h * 2 * np.pi * 50 * 0.02 * 300 * np.sqrt(2)
    assert 2 * peak[50] / (emf.size - int(0.5 * FS)) == pytest.approx(expected, rel=0.05)
    assert json.loads((DATA / "default_line_ac.json").read_text())["electrification"]["system"] == "AC25000"


def test_a_feed_opening_under_a_moving_train_leaves_the_coil_emf_finite():
    """An open feed (bond disconnected, transmitter failed) in the section a moving train is in:
    the network without a feed carries no code to hand over as the shunt moves from node to
    node, and the coil EMF stays a number (the `faults` system opens a feed at speed)."""
    core = _steady_carrier_core()
    _run(core, 1.0, lambda t: 9000.0 + 20.0 * t, 20.0)        # coded, moving, in section 4
    feed = np.zeros(8, dtype=bool)
    feed[3] = True
    core.set_faults(-1.0, np.zeros(8), feed)
    _, emf, axle = _run(core, 6.0, lambda t: 9020.0 + 20.0 * t, 20.0)   # 120 m: several node changes
    assert np.isfinite(emf).all() and np.isfinite(axle).all()
    assert np.abs(axle[-20:]).max() < 0.01
