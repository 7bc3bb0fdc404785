"""TVM-430's rail line: UM71 track circuits without insulated joints, ended by tuned separation
zones (docs/rail_line.md#tvm-430-track-circuits): the line file's rules, the zones' selectivity,
detection by every wheelset, the neighbour's carrier leaking through a zone, the rails at the
carriers, the sample-rate rule, the shipped high-speed line."""
import json

import numpy as np
import pytest

from helpers import railcosim

from fmus.data.loader import DATA, load_line
from fmus.errors import FmuInputError
from fmus.rail_line.core import RailLineCore, RailSettings, default_wheelsets
from fmus.rail_line.network import ShuntFamily, discretise
from fmus.rail_line.separation_leak import NEAREST_HEAD_BEFORE_ZONE_M, leak_at, worst_leak
from fmus.rail_line.track_circuit import (CircuitParameters, Faults, SeparationZone, TrackCircuit, end_admittance,
                                          rail_impedance)

HSL = DATA / "hsl_tvm430_line.json"
FS = 12000.0
TRAIN_M = 200.0


def _document():
    return json.loads(HSL.read_text(encoding="utf-8"))


def _refused(tmp_path, document, *fragments):
    path = tmp_path / "line.json"
    path.write_text(json.dumps(document), encoding="utf-8")
    with pytest.raises(FmuInputError) as error:
        load_line(path)
    message = str(error.value)
    assert "\n" not in message
    for fragment in fragments:
        assert fragment in message, message


def _core(line, trains=1, fs=FS):
    wheels = default_wheelsets(TRAIN_M)
    return RailLineCore(line, len(line.sections), trains, int(fs * 0.01),
                        RailSettings(fs_hz=fs, train_length_m=(TRAIN_M,) * trains, wheelset_offsets_m=(wheels,) * trains))


# ---- the line file --------------------------------------------------------------------------
def test_a_um71_section_needs_a_tvm_carrier_and_a_kpt_an_alsn_one(tmp_path):
    document = _document()
    document["block_sections"][3]["carrier_hz"] = 75
    _refused(tmp_path, document, "line.json", "block_sections[3].carrier_hz", "75 Hz", "UM71")
    document = _document()
    document["block_sections"][3]["transmitter"] = "KPT-5"
    _refused(tmp_path, document, "block_sections[3].carrier_hz", "2300 Hz", "KPT-5")


def test_adjacent_tvm_sections_alternate_their_tracks_two_carriers(tmp_path):
    document = _document()
    document["block_sections"][5]["carrier_hz"] = 1700       # after section 5's 1700 Hz
    _refused(tmp_path, document, "block_sections[5].carrier_hz", "1700 Hz again", "alternate")
    document = _document()
    document["block_sections"][5]["carrier_hz"] = 2600       # track 2's carrier on a track 1 line
    _refused(tmp_path, document, "block_sections[5].carrier_hz", "track 2", "1700/2300")


def test_a_separation_zone_at_every_tvm_boundary_and_nowhere_else(tmp_path):
    document = _document()
    del document["separation_zones"][6]                      # the zone at 10500 m
    _refused(tmp_path, document, "separation_zones", "no separation zone at 10500 m", "'7'", "'8'")
    document = _document()
    document["separation_zones"].append({"position_m": 700})
    _refused(tmp_path, document, "separation_zones[27].position_m", "700 m is not a boundary")
    document = _document()
    document["insulated_joints"] = [{"position_m": 3000, "impedance_bond": True}]
    _refused(tmp_path, document, "insulated_joints", "3000 m", "a separation zone goes there")


def test_tvm_and_alsn_sections_meet_only_at_an_insulated_joint(tmp_path):
    document = _document()
    document["block_sections"][27].update(transmitter="KPT-5", carrier_hz=75)
    document["separation_zones"] = document["separation_zones"][:-1]
    _refused(tmp_path, document, "insulated_joints", "'27' and '28' meet at 40500 m without an insulated joint")
    document["insulated_joints"] = [{"position_m": 40500, "impedance_bond": True}]
    line = load_line(_write(tmp_path, document))
    assert [s.transmitter for s in line.sections[-2:]] == ["UM71", "KPT-5"]
    document["separation_zones"].append({"position_m": 40500})
    _refused(tmp_path, document, "separation_zones[26].position_m", "TVM and ALSN sections meet")


def _write(tmp_path, document):
    path = tmp_path / "line.json"
    path.write_text(json.dumps(document), encoding="utf-8")
    return path


def test_a_bad_tvm_line_file_is_one_line_and_exit_2_through_the_cli(tmp_path, product_fmus):
    document = _document()
    document["block_sections"][2]["carrier_hz"] = 2300
    bad = _write(tmp_path, document)
    code, _, stderr = railcosim("run", "ato_only", "--no-build", "--output", tmp_path / "out",
                                "--set", f"train.line_file={bad}", "--set", f"ato.line_file={bad}")
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert code == 2 and len(lines) == 1 and "Traceback" not in stderr, stderr
    assert "line.json" in lines[0] and "block_sections[2].carrier_hz" in lines[0], lines[0]


# ---- the rails and the zones ------------------------------------------------------------------
@pytest.mark.parametrize("carrier", [1700.0, 2000.0, 2300.0, 2600.0])
def test_rail_impedance_at_the_carriers_follows_the_square_root_law(carrier):
    """The internal part (what the law adds to the 165 Hz anchor's external R and L) has equal
    resistance and reactance, growing as √f; the loop reactance at 2.3 kHz ≈ 15 Ω/km."""
    p = CircuitParameters()
    r, l = rail_impedance(p, carrier)
    x_int0 = 2 * np.pi * p.rail_reference_hz * p.rail_internal_l_h_per_km
    r_internal = r - (p.rail_r_ohm_per_km - x_int0)
    x_internal = 2 * np.pi * carrier * (l - (p.rail_l_h_per_km - p.rail_internal_l_h_per_km))
    assert r_internal == pytest.approx(x_internal, rel=1e-12)
    assert r_internal == pytest.approx(x_int0 * np.sqrt(carrier / p.rail_reference_hz), rel=1e-12)
    assert 10.0 < 2 * np.pi * carrier * l < 18.0 and 0.9 < r < 1.1


@pytest.mark.parametrize("own, other", [(1700.0, 2300.0), (2300.0, 1700.0), (2000.0, 2600.0), (2600.0, 2000.0)])
@pytest.mark.parametrize("ballast", [1.0, 50.0])
def test_the_zone_is_high_at_its_own_carrier_and_shorts_the_neighbours(own, other, ballast):
    p = CircuitParameters(ballast_ohm_km=ballast, zone=SeparationZone(own, other))
    at_own, at_other = abs(1 / end_admittance(p, ballast, own)), abs(1 / end_admittance(p, ballast, other))
    assert at_own > 1.0 and at_other < 0.02
    assert at_own / at_other > 100.0                          # ≥ 40 dB between the two carriers
    # the parallel resonance sits at the own carrier: |Z| is lower 50 Hz either side
    assert abs(1 / end_admittance(p, ballast, own - 50)) < at_own > abs(1 / end_admittance(p, ballast, own + 50))


@pytest.mark.parametrize("carrier", [1700.0, 2300.0])
def test_the_state_space_with_tuned_units_meets_the_phasor_solution(carrier):
    """The capacitors' voltages as states: the continuous model's steady state at the carrier is
    the nodal phasor solution's, and the exact ZOH model's is it times the hold's
    (1 − e^{−jωT})/(jωT) ever closer as the step shrinks."""
    other = 4000.0 - carrier
    circuit = TrackCircuit(0.0, 1500.0, 1.0, CircuitParameters(ballast_ohm_km=1.0, zone=SeparationZone(carrier, other)))
    net = circuit.network(None, Faults(), 2.5, carrier)
    family = ShuntFamily(net, 1.0 / 0.06)
    system = family.state_space([net.node_index["n10"]])
    capacitors = sum(1 for branch in net.branches if branch[4] > 0)
    assert capacitors == 6 and system.a.shape[0] == len(net.branches) + capacitors
    w = 2 * np.pi * carrier
    states = np.linalg.solve(1j * w * np.eye(system.a.shape[0]) - system.a, system.b[:, 0])
    voltages = system.node_from_state @ states + system.node_from_input[:, 0]
    y, p_matrix, _, _ = net._admittance(w)
    y[net.node_index["n10"], net.node_index["n10"]] += 1.0 / 0.06
    phasor = np.linalg.solve(y, p_matrix[:, 0].astype(complex))
    assert np.allclose(voltages, phasor, rtol=1e-9, atol=1e-12)
    errors = []
    for fs in (12000.0, 48000.0, 480000.0):
        phi, gamma = discretise(system, 1.0 / fs)
        rotation = np.exp(1j * w / fs)
        discrete = np.linalg.solve(rotation * np.eye(phi.shape[0]) - phi, gamma[:, 0])
        hold = (1 - np.exp(-1j * w / fs)) / (1j * w / fs)
        errors.append(abs(discrete[10] / (states[10] * hold) - 1))       # segment 10's current
    assert errors[0] < 0.02 and errors[2] < errors[1] < errors[0] and errors[2] < 1e-4


# ---- detection --------------------------------------------------------------------------------
def test_every_section_of_the_high_speed_line_calibrates_at_its_ballast_range():
    line = load_line(HSL)
    core = _core(line)
    table = core.bank.calibration.table
    assert {c.ballast_min_ohm_km for c in table} >= {1.0} and {c.ballast_max_ohm_km for c in table} == {50.0}
    assert min(c.shunt_margin for c in table) >= core.settings.shunt_margin


@pytest.mark.parametrize("k", [0, 1])
def test_one_wheelset_anywhere_drops_the_relay_at_either_ballast(k):
    """The calibration's shunt mode at every node, both ends of the ballast range, the maximum
    supply: a single 0.06 Ω wheelset leaves the receiver below drop-out."""
    core = _core(load_line(HSL))
    bank, s = core.bank, core.settings
    for ballast in (bank.calibration.table[k].ballast_min_ohm_km, 50.0):
        levels = [bank.relay_level(k, [node], Faults(ballast), 1.0 + s.supply_tolerance)
                  for node in range(core.circuits[k].segments + 1)]
        assert max(levels) < s.relay_drop_out
        assert bank.relay_level(k, [], Faults(ballast), 1.0 - s.supply_tolerance) >= s.relay_pick_up * (1 - 1e-6)


def _run(core, line, seconds, heads, speeds):
    carriers = np.array([s.carrier_hz for s in line.sections])
    n, t = core.frame, 0.0
    emf = []
    for _ in range(int(round(seconds / 0.01))):
        times = t + np.arange(n) / FS
        out = core.step(t, np.sin(2 * np.pi * carriers[:, None] * times), heads + speeds * t, speeds,
                        np.zeros(len(heads)))
        emf.append(out.e_coil.copy())
        t += n / FS
    return out, np.concatenate(emf, axis=1)


@pytest.mark.parametrize("k", [1, 2])
def test_a_train_with_only_its_last_wheelset_in_a_section_occupies_it(k):
    line = load_line(HSL)
    end = line.sections[k].end_m
    span = float(default_wheelsets(TRAIN_M)[-1])
    core = _core(line)
    core.start(np.array([end + span - 2.0]))                 # the last wheelset 2 m before the zone
    out, _ = _run(core, line, 1.5, np.array([end + span - 2.0]), np.zeros(1))
    assert out.occupied[k] and out.occupied[k + 1] and not out.occupied[k - 1] and not out.occupied[k + 2]
    core = _core(line)
    core.start(np.array([end + span + 2.0]))                 # cleared by 2 m
    out, _ = _run(core, line, 1.5, np.array([end + span + 2.0]), np.zeros(1))
    assert not out.occupied[k] and out.occupied[k + 1]


def test_a_train_at_300_kmh_occupies_each_block_it_enters_and_frees_it_behind():
    line = load_line(HSL)
    core = _core(line)
    v = 300 / 3.6
    start = 1400.0
    core.start(np.array([start]))
    carriers = np.array([s.carrier_hz for s in line.sections])
    t, n = 0.0, core.frame
    entered, freed = {}, {}
    span = float(default_wheelsets(TRAIN_M)[-1])
    while t < 60.0:
        times = t + np.arange(n) / FS
        out = core.step(t, np.sin(2 * np.pi * carriers[:, None] * times), np.array([start + v * t]), np.array([v]),
                        np.zeros(1))
        t += n / FS
        for k in range(1, 4):
            if out.occupied[k] and k not in entered:
                entered[k] = t
            if k in entered and not out.occupied[k] and k not in freed:
                freed[k] = t
    for k in range(1, 4):
        head_in = (line.sections[k].start_m - start) / v
        tail_out = (line.sections[k].end_m + span - start) / v
        assert head_in <= entered[k] <= head_in + core.settings.relay_drop_out_delay_s + 0.03
        assert tail_out + core.settings.relay_pick_up_delay_s <= freed[k] <= tail_out + core.settings.relay_pick_up_delay_s + 0.03


def test_the_coil_emf_at_the_carrier_is_the_two_port_current_times_m_omega_less_the_backward_difference():
    """The sample-rate figures (docs/rail_line.md#sample-rate-of-the-tvm-chain): the network's
    zero-order hold is scaled to the two-port amplitude, so what the EMF loses at the carrier is
    the backward difference's 2 sin(ωT/2)/(ωT)."""
    line = load_line(HSL)
    k, head = 1, 1500.0 + 700.0
    core = _core(line)
    core.start(np.array([head]))
    _, emf = _run(core, line, 0.4, np.array([head]), np.zeros(1))
    tail = emf[0, -int(0.1 * FS):]
    times = (np.arange(tail.size) + emf.shape[1] - tail.size) / FS
    w = 2 * np.pi * 2300.0
    (c, s), *_ = np.linalg.lstsq(np.stack([np.cos(w * times), np.sin(w * times)], 1), tail, rcond=None)
    current = core.bank.wheelset_solution(k, [head])[0][0]
    droop = 2 * np.sin(w / FS / 2) / (w / FS)
    assert np.hypot(c, s) == pytest.approx(core.settings.coil_gain_h * w * current * droop, rel=1e-3)


def test_the_rail_line_refuses_a_carrier_above_a_quarter_of_fs():
    line = load_line(HSL)
    with pytest.raises(FmuInputError, match=r"block_sections\[1\]\.carrier_hz: 2300 Hz needs fs ≥ 9200 Hz"):
        _core(line, fs=8000.0)
    assert _core(line, fs=9200.0).count == 28


# ---- the neighbour's carrier through the zone -----------------------------------------------------
def test_the_neighbours_carrier_under_the_coils_is_bounded_at_its_worst():
    """Worst over the head's position, both ballasts, both orders of the carriers: the
    neighbour's EMF is at most a tenth of the own one (−20 dB; measured 0.077 on track 1, 0.081
    on track 2), and a real leak (above 1 %). 50 m back from the zone it is below 1 %."""
    wheels = default_wheelsets(TRAIN_M)
    for pair in ((1700.0, 2300.0), (2000.0, 2600.0)):
        worst = worst_leak(wheels, pair_hz=pair)
        assert 0.01 < worst.emf_ratio < 0.10, worst
        assert worst.head_before_zone_m == pytest.approx(NEAREST_HEAD_BEFORE_ZONE_M) and worst.ballast_neighbour_ohm_km == 50.0
        for own, other in (pair, pair[::-1]):
            assert leak_at(50.0, own, other, 1.0, 50.0, wheels).emf_ratio < 0.01


# ---- the shipped line -----------------------------------------------------------------------------
def test_the_shipped_high_speed_line():
    line = load_line(HSL)
    assert line.length_m >= 40000.0 and line.electrification == "AC25000"
    assert len(line.sections) >= 27
    assert all(s.transmitter == "UM71" and s.end_m - s.start_m == 1500.0 for s in line.sections)
    assert [s.carrier_hz for s in line.sections] == [1700, 2300] * 14
    assert sorted(line.separation_zones) == [s.start_m for s in line.sections[1:]]
    assert max(map(abs, line.gradient_permille)) == 35.0
    limits = line.limits_mps["high_speed"]
    assert max(limits) == pytest.approx(300 / 3.6) and limits[-1] < 300 / 3.6
    assert line.stations[-1].stop_m > line.sections[-1].start_m


def test_the_worst_leak_emf_carries_both_carriers_at_the_leaks_ratio():
    """harness/tvm_line.py: what a receiver test decodes. With plain sines at the two carriers
    the EMF's neighbour / own amplitude is the leak's EMF ratio (less the backward difference's
    loss, slightly more at the higher carrier)."""
    from harness.tvm_line import FS as TVM_FS, worst_leak_emf

    t = np.arange(int(0.4 * TVM_FS)) / TVM_FS
    case = worst_leak_emf(np.sin(2 * np.pi * 1700 * t), np.sin(2 * np.pi * 2300 * t))
    assert case.section == 0 and case.head_m == pytest.approx(1500.0 - NEAREST_HEAD_BEFORE_ZONE_M)
    tail = slice(int(0.2 * TVM_FS), None)

    def amplitude(signal, f):
        basis = np.stack([np.cos(2 * np.pi * f * t[tail]), np.sin(2 * np.pi * f * t[tail])], 1)
        return float(np.hypot(*np.linalg.lstsq(basis, signal[tail], rcond=None)[0]))
    own, neighbour = amplitude(case.emf, 1700.0), amplitude(case.emf, 2300.0)
    assert amplitude(case.own_emf, 2300.0) < 1e-6 * own
    droop = [2 * np.sin(np.pi * f / TVM_FS) / (2 * np.pi * f / TVM_FS) for f in (1700.0, 2300.0)]
    assert neighbour / own == pytest.approx(case.leak.emf_ratio * droop[1] / droop[0], rel=2e-3)
    assert 0.05 < neighbour / own < 0.1


def test_the_traction_interference_passes_a_separation_zone_without_a_spike():
    """No insulated joint: the rails' asymmetry passes from one section's to the next across the
    zone's 26 m, so the 50 Hz traction EMF under the coils grows or falls there, it does not
    jump (a step of the asymmetry at the boundary would be an EMF spike of tens of volts)."""
    line = load_line(HSL)
    core = _core(line)
    v, start = 300 / 3.6, 1400.0
    core.start(np.array([start]))
    n, t, emf = core.frame, 0.0, []
    silent = np.zeros((len(line.sections), n))
    while t < 3.0:
        emf.append(core.step(t, silent, np.array([start + v * t]), np.array([v]), np.array([300.0])).e_coil[0].copy())
        t += n / FS
    emf = np.abs(np.concatenate(emf))
    coil = start + v * np.arange(emf.size) / FS + core.settings.coil_offset_m
    steady = (coil > 1400.0) & ((coil < 1480.0) | (coil > 1520.0)) & (np.arange(emf.size) > 0.5 * FS)
    crossing = (coil >= 1480.0) & (coil <= 1520.0)
    assert emf[steady].max() > 1.0                             # the 50 Hz interference is there
    assert emf[crossing].max() <= 1.01 * emf[steady].max()


@pytest.mark.parametrize("own, other", [(1700.0, 2300.0), (2300.0, 1700.0)])
@pytest.mark.parametrize("ballasts", [(1.0, 50.0), (1.0, 1.0), (50.0, 50.0)])
def test_the_leaks_two_port_solution_meets_the_two_circuits_joined_in_one_network(own, other, ballasts):
    """The two circuits and the zone between them as one nodal network (network.py, 50 m π
    sections; B's transmitter on, A's silent, one wheelset at a node of A): the neighbour's
    current arriving at it is the two-port chains' (separation_leak.leak_at) within 1 %."""
    from fmus.rail_line.network import Conductance, NortonSource, RLBranch
    from fmus.rail_line.separation_leak import _params

    ballast_a, ballast_b = ballasts
    p_a, p_b = (_params(own, other, ballast_a, 26.0, CircuitParameters()),
                _params(other, own, ballast_b, 26.0, CircuitParameters()))
    a, b = TrackCircuit(0.0, 1500.0, 1.0, p_a), TrackCircuit(0.0, 1500.0, 1.0, p_b)
    for node in (20, 29):
        net = a.network(node, Faults(), 2.5, other)          # A's exit zone ends at "feed_zone_far": B's entry
        net.inputs = 2
        r, l = rail_impedance(p_b, other)
        km = (b.feed_m - b.start_m) / 1000.0 / b.segments
        names = ["feed_zone_far"] + [f"b{k}" for k in range(1, b.segments + 1)]
        for k in range(b.segments):
            net.add(RLBranch(names[k], names[k + 1], r * km, l * km),
                    Conductance(names[k], "0", 0.5 * km / ballast_b), Conductance(names[k + 1], "0", 0.5 * km / ballast_b))
        net.add(Conductance(names[0], "0", 1.0 / p_b.relay_r_ohm))
        b._terminate(net, names[-1], "b_exit", Faults(ballast_b), other, r, l)
        net.add(NortonSource(names[-1], "0", 1.0 / p_b.feed_r_ohm, 1, 2.5))
        y, p, _, z = net._admittance(2 * np.pi * other)
        v = np.linalg.solve(y, p @ np.array([0.0, 1.0], dtype=complex))
        nodal = abs((v[net.node_index[f"n{node}"]] - v[net.node_index[f"n{node + 1}"]]) / z[node])
        chain = leak_at(1500.0 - float(a.nodes_m[node]), own, other, ballast_a, ballast_b, [0.0]).neighbour_current_a
        assert nodal == pytest.approx(chain, rel=0.01)
