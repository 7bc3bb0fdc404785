"""ALSU, two of six tones, through the chain (docs/loco_receiver.md#alsu,
docs/wayside_coder.md#alsu): the code table and the block's codes, the coder's tones, the rails'
impedance at every tone, the receiver's rules, the bench (coder → rail line → receiver cores),
the ATP's reading, and the FMUs through the orchestrator. The full measurements are
benchmarks/alsu_acceptance.py."""
import json
from pathlib import Path

import numpy as np
import pytest

from harness.alsu import AlsuBench, first_time, tones_after_code
from fmus.data.loader import DATA, load_line
from fmus.errors import FmuInputError
from fmus.loco_receiver.alsu import AlsuReceiverCore, AlsuReceiverSettings, channel_design
from fmus.rail_line.track_circuit import CircuitParameters, rail_impedance, skin_effect_ladder
from fmus.signalling import alsu
from fmus.signalling import aspects as sig
from fmus.signalling.block_rules import block_codes
from fmus.wayside_coder.alsu import AlsuCoderCore
from fmus.wayside_coder.core import CoderSettings
from orchestrator.systems.chain import _shipped_json
from orchestrator.systems.shipped import alsu_line
from orchestrator.sspgen import ComponentSpec, ConnectionSpec, write_ssd
from tests.helpers import railcosim, read_csv

FS, N = 4000.0, 40
SYSTEM = alsu.system()
SSP = Path(__file__).resolve().parents[1] / "ssp"


# ---- the code table and the block's codes -------------------------------------------------------
def test_the_table_is_the_thesis_tone_plan_fifteen_pairs_and_its_code_meanings():
    table = SYSTEM.table
    assert table.tones_hz == (125.0, 175.0, 225.0, 275.0, 325.0, 375.0)
    assert sorted(c.tones for c in table.codes.values()) == alsu.all_pairs()
    # pairs ordered by the sum of their tone numbers: the restrictive codes on the low tones
    sums = [sum(table.codes[n].tones) for n in range(1, 16)]
    assert sums == sorted(sums)
    assert [n for n, c in table.codes.items() if c.reserved] == [2, 14, 15]
    read = {n: (SYSTEM.indication(n, "passenger").target_kmh, SYSTEM.indication(n, "freight").target_kmh)
            for n in SYSTEM.codes()}
    assert read[1] == (0.0, 0.0) and read[4] == (80.0, 50.0)                   # 4-aspect yellow
    assert read[3] == (50.0, 50.0) and read[5] == (80.0, 80.0) and read[7] == (120.0, 100.0)   # routes
    assert read[8] == read[9] == (160.0, 100.0) and read[10] == (140.0, 100.0) and read[11] == (160.0, 100.0)
    assert SYSTEM.indication(12, "high_speed").target_kmh == 180.0
    assert SYSTEM.indication(13, "high_speed").target_kmh == 200.0
    assert SYSTEM.braking(10) == SYSTEM.braking(11) == "restriction" and SYSTEM.braking(9) == "signal"
    # code numbers rise with the permitted speed (passenger readings)
    ranks = [SYSTEM.rank(n) for n in (1, 3, 4, 6, 7, 10, 9)]
    assert ranks == sorted(ranks)
    # the order is the table's (permissiveness): 10 (140 km/h) below 9 (160) though numbered
    # above it; 11 (160, gentle braking for a restriction) below 9 (160 towards a signal); 8 = 9
    assert SYSTEM.rank(10) < SYSTEM.rank(11) < SYSTEM.rank(9) == SYSTEM.rank(8) < SYSTEM.rank(12) < SYSTEM.rank(13)
    assert SYSTEM.more_restrictive(9, 10) == 10 and SYSTEM.more_restrictive(7, 10) == 7


def _table_with(tmp_path, change):
    doc = json.loads(alsu.CODES_FILE.read_text())
    change(doc)
    path = tmp_path / "codes.json"
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("change, message", [
    (lambda d: d["codes"]["9"].update(tones=["f4", "f4"]), "field codes.9.tones: expected two different tones"),
    (lambda d: d["codes"]["9"].update(tones=["f2", "f3"]), "field codes.9.tones: the same pair as code 1"),
    (lambda d: d["codes"].pop("13"), "field codes: every code 1…15 needs an entry (missing 13)"),
    (lambda d: d["codes"]["6"].update(reserved=True), "field codes.6: the block rules send this code"),
    (lambda d: d["tones"].update(f3=100), "field tones: frequencies must rise"),
    (lambda d: d["codes"]["4"]["speeds_kmh"].pop("freight"), "field codes.4.speeds_kmh: expected one entry per category"),
    (lambda d: d.pop("permissiveness"), "field permissiveness.order: expected the codes a wayside sends"),
    (lambda d: d["permissiveness"]["order"].remove([13]), "field permissiveness.order: expected the codes"),
    # code numbers are not the order: 10 permits 140 km/h, 9 160
    (lambda d: d["permissiveness"].update(order=[[1], [3], [4], [5], [6], [7], [11], [8, 9], [10], [12], [13]]),
     "field permissiveness.order: code 10 is listed as more permissive than code 8 but is not"),
    (lambda d: d["permissiveness"].update(order=[[1], [3], [4], [5], [6], [7], [10], [8, 9, 11], [12], [13]]),
     "field permissiveness.order: codes 8 and 11 share a group but read differently"),
])
def test_a_bad_code_table_is_one_error_naming_the_field(tmp_path, change, message):
    import re

    with pytest.raises(FmuInputError, match=re.escape(message)):
        alsu.load_codes(_table_with(tmp_path, change))


def _codes(line, occupied_sections, aspects):
    occupied = np.zeros(len(line.sections), dtype=bool)
    occupied[list(occupied_sections)] = True
    return alsu.BlockCoding(line, aspects, SYSTEM).codes(block_codes(occupied, line.block_of_section, aspects)).tolist()


def test_the_block_sends_1_6_9_on_3_aspect_and_adds_4_on_4_aspect():
    line = load_line()
    # a train in section 6 (index 5): red at its entry, yellow, then yellow-green (4-aspect)
    assert _codes(line, [5], 3) == [9, 9, 9, 6, 1, 9, 9, 9]
    assert _codes(line, [5], 4) == [9, 9, 6, 4, 1, 9, 9, 9]
    # no code behind an occupied circuit of the same block (the station throat line)
    from orchestrator.systems.shipped import THROAT_LINE
    throat = load_line_from(THROAT_LINE)
    assert _codes(throat, [4], 3)[3] == alsu.NO_CODE


def test_a_diverging_route_and_a_permanent_restriction_set_their_codes():
    line_doc = alsu_line(_shipped_json("default_line.json"))
    line = load_line_from(line_doc)
    free = _codes(line, [], 4)
    # route at signal 5 (exit of section 3): 5 into its approach, 6 into the section before;
    # the drop from 160 to 140 km/h at 12.8 km (exit of section 5): 10
    assert free == [9, 6, 5, 9, 10, 9, 9, 9]
    # a red beyond the route's signal: 1 wins; a yellow-green behind it: the route's code still limits
    assert _codes(line, [3], 4)[2] == 1 and _codes(line, [5], 4)[2] == 5


def test_a_route_with_a_signal_that_does_not_exist_is_refused(tmp_path):
    doc = _shipped_json("default_line.json")
    doc["diverging_routes"] = [{"signal": "X9", "frog": "1/18"}]
    path = tmp_path / "line.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(FmuInputError, match=r"line.json: field diverging_routes\[0\].signal: 'X9' is not the signal"):
        load_line(path)


def load_line_from(document):
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "line.json"
        path.write_text(json.dumps(document))
        return load_line(path)


# ---- coder ----------------------------------------------------------------------------------------
def test_the_coder_sends_two_continuous_tones_and_a_kept_tone_goes_on_without_a_phase_step():
    line = load_line()
    frames, one = AlsuCoderCore(line, 8, N, CoderSettings(block_aspects=4)), AlsuCoderCore(line, 8, 1, CoderSettings(block_aspects=4))
    occupied = np.zeros(8, dtype=bool)
    a, b = [], []
    for f in range(100):
        if f == 50:
            occupied[5] = True           # section 5's code 9 (f4 f5) turns 4 (f3 f4): f4 goes on
        t = f * N / FS
        a.append(frames.step(t, occupied).u_tx.copy())
        for i in range(N):
            b.append(one.step((f * N + i) / FS, occupied).u_tx.copy())
    u, u_one = np.concatenate(a, axis=1), np.concatenate(b, axis=1)
    np.testing.assert_array_equal(u, u_one)
    assert frames.out.code_tx[3] == 4
    # section 4 (index 3) before and after: the generators' sines at their own phases
    n = np.arange(u.shape[1])
    tones = np.array(SYSTEM.table.tones_hz)
    phase = np.random.default_rng(1).uniform(0.0, 2 * np.pi, (8, 6))[3]
    wave = 4.0 * np.sin(2 * np.pi * tones[:, None] * n / FS + phase[:, None])
    np.testing.assert_allclose(u[3, :2000], wave[2, :2000] + wave[3, :2000], atol=1e-9)
    np.testing.assert_allclose(u[3, 2000:], wave[1, 2000:] + wave[2, 2000:], atol=1e-9)


# ---- rail line ------------------------------------------------------------------------------------
def test_the_rails_follow_the_square_root_law_at_every_tone_at_once():
    params = CircuitParameters()
    r, l, r_parallel, l_parallel = skin_effect_ladder(params, (125.0, 375.0))
    for f in (125.0, 175.0, 225.0, 275.0, 325.0, 375.0):
        w = 2 * np.pi * f
        ladder = r + 1j * w * l + r_parallel * 1j * w * l_parallel / (r_parallel + 1j * w * l_parallel)
        law_r, law_l = rail_impedance(params, f)
        assert abs(ladder - (law_r + 1j * w * law_l)) / abs(law_r + 1j * w * law_l) < 0.005


def _wheelset_factors(frequency_hz, heads, k=1):
    """At each head of a passenger train in section k of the alsu line (its own ballast): the
    wheelset chain's current at the first axle over the network model's (lumped shunts, the
    tone band's ladder) at ``frequency_hz`` — the factor the rail line scales that model's
    current by."""
    from fmus.data.loader import DEFAULT_ROLLING_STOCK, load_rolling_stock
    from fmus.rail_line.core import RailLineCore, RailSettings
    from fmus.rail_line.track_circuit import Faults

    line = load_line(str(SSP / "alsu" / "resources" / "alsu_line.json"))
    stock = load_rolling_stock(str(DEFAULT_ROLLING_STOCK))
    settings = RailSettings(tone_band_hz=(125.0, 375.0), carrier_hz=frequency_hz, train_length_m=(stock.length_m,),
                            wheelset_offsets_m=(stock.wheelset_offsets_m,))
    bank = RailLineCore(line, len(line.sections), 1, 40, settings).bank
    factors = []
    for head in heads:
        configs, rows = bank.configuration([head])
        model = bank.models.model(k, configs[k], Faults())
        currents, _, _ = bank.wheelset_solution(k, [head], frequency_hz)
        factors.append(currents[0] / abs(model.head_responses[rows[k][0]]))
    return np.array(factors)


def test_the_wheelset_amplitude_solved_at_the_band_centre_fits_every_tone_within_four_percent():
    """A code of several tones takes the wheelset chain's amplitude factor at the band's centre
    for both its tones (docs/rail_line.md, open points): what that costs each tone."""
    heads = list(np.linspace(2620.0, 5194.0, 25))         # the 2.6 km section 2, every 107 m
    centre = _wheelset_factors(float(np.sqrt(125.0 * 375.0)), heads)
    for tone in SYSTEM.table.tones_hz:
        error = centre / _wheelset_factors(float(tone), heads) - 1.0
        assert np.abs(error).max() < 0.04, (tone, error)


# ---- receiver -------------------------------------------------------------------------------------
def test_every_channel_is_sections_centred_on_its_tone_and_deaf_between_the_tones():
    for tone in SYSTEM.table.tones_hz:
        channel = channel_design(tone, FS)
        gain = np.abs(channel.response([tone, tone - 5.0, tone + 5.0, tone - 25.0, tone + 25.0, tone - 50.0, tone + 50.0]))
        assert abs(gain[0] - 1.0) < 1e-9 and np.all(np.abs(gain[1:3] - 2 ** -0.5) < 0.05)
        assert np.all(20 * np.log10(gain[3:5]) < -50.0) and np.all(20 * np.log10(gain[5:]) < -70.0)


def _tones(code, t, amplitude=0.3):
    if not code:
        return np.zeros_like(t)
    a, b = SYSTEM.table.codes[code].tones
    f = SYSTEM.table.tones_hz
    return amplitude * (np.sin(2 * np.pi * f[a] * t + 0.4) + np.sin(2 * np.pi * f[b] * t + 2.0))


def test_the_receiver_gives_the_same_outputs_for_one_sample_and_forty_per_frame():
    plan = [(0.0, 9), (2.0, 6), (3.2, 0), (3.6, 6), (5.0, 1), (7.5, 0)]
    forty, one = AlsuReceiverCore(N, AlsuReceiverSettings()), AlsuReceiverCore(1, AlsuReceiverSettings())
    for f in range(int(10.0 * FS / N)):
        t = f * N / FS + np.arange(N) / FS
        code = [c for start, c in plan if start <= t[0]][-1]
        e = _tones(code, t)
        out = forty.step(f * N / FS, e)
        for i in range(N):
            one.step((f * N + i) / FS, e[i:i + 1])
        got = one.out
        assert (got.code, got.code_valid, got.aspect, got.decoded_codes, got.errors) == \
            (out.code, out.code_valid, out.aspect, out.decoded_codes, out.errors)
        assert got.v_target_mps == out.v_target_mps and got.level_v == pytest.approx(out.level_v, rel=1e-12)


# ---- the bench: coder → rail line → receiver -----------------------------------------------------
@pytest.fixture(scope="module")
def bench_min_ballast():
    return AlsuBench(ballast_ohm_km=1.0)


def test_every_code_decodes_where_the_code_is_weakest_at_the_minimum_ballast(bench_min_ballast):
    bench = bench_min_ballast
    for code in range(1, 16):
        bench.send_code(code)
        start = bench.t
        record = bench.run(1.5).arrays()
        assert first_time(bench.record, start, record["pair"] == code) < 0.3, code
        if code in SYSTEM.codes():
            assert record["shown"][-1] == code and record["valid"][-1], code
        else:                            # reserved: never shown, no code
            assert not record["valid"][-1]


def test_codes_decode_at_the_maximum_ballast():
    bench = AlsuBench(ballast_ohm_km=50.0)
    for code in (1, 9, 13, 15):
        bench.send_code(code)
        record = bench.run(1.5).arrays()
        assert record["pair"][-1] == code
        assert (record["shown"][-1] == code) == (code in SYSTEM.codes())


@pytest.mark.parametrize("flags", [[0] * 6, [0, 0, 0, 0, 1, 0], [0, 1, 1, 1, 0, 0]], ids=["none", "one", "three"])
def test_none_one_or_three_tones_give_no_code_never_another(flags):
    outcome = tones_after_code(flags, code=9, settle_s=1.5, watch_s=2.0)
    assert outcome.lost_s is not None and outcome.lost_s <= (1.3 if not any(flags) else 0.8)   # hold / minimum duration + decay
    assert not outcome.other_code
    assert not outcome.shown_again
    assert outcome.aspect_at_end == sig.WHITE


@pytest.mark.parametrize("old, new", [(9, 6), (6, 1), (9, 10), (1, 9), (4, 5), (9, 3)])
def test_an_aspect_change_reaches_the_cab_within_two_seconds(old, new):
    bench = AlsuBench(seed=3)
    bench.send_code(old)
    bench.run(1.5)
    bench.send_code(new)
    start = bench.t
    record = bench.run(2.0).arrays()
    took = first_time(bench.record, start, record["valid"] & (record["shown"] == new))
    assert took is not None and took <= alsu.STATED_LATENCY_S


@pytest.mark.parametrize("line_file, traction_a, speed_kmh", [("default_line.json", 2000.0, 160.0),
                                                                 ("default_line_ac.json", 300.0, 40.0)])
def test_no_false_code_from_a_joint_or_the_traction_harmonics(line_file, traction_a, speed_kmh):
    """Coils 5 % mismatched (the joints paper's 5 V DC pulses; AC its 14 V 50 Hz burst), with the
    DC 100/200/300 Hz or AC 150/250/350 Hz harmonics of the traction current."""
    for code in (0, 1):
        bench = AlsuBench(line=load_line(DATA / line_file), head_m=5200.0 - 40.0, speed_mps=speed_kmh / 3.6,
                          traction_a=traction_a, coil_mismatch=0.05)
        bench.send_code(code)
        record = bench.run(80.0 / (speed_kmh / 3.6) + 1.0).arrays()
        assert bench.head_at(bench.t) > 5200.0 + 10.0
        shown = set(record["shown"][record["valid"]].tolist())
        assert shown <= {code}


# ---- the ATP's reading ----------------------------------------------------------------------------
def test_the_atp_supervises_a_restriction_on_a_gentler_curve_and_a_red_ahead_on_the_normal_one():
    from fmus.ato_controller.atp import Atp

    line = load_line()
    atp = Atp(line, "passenger", 400.0, "ALSU", 0.6, alsu.STATED_LATENCY_S)
    x = 10500.0          # section 5, exit signal at 12.8 km
    restriction = atp.supervise(0.0, x, 40.0, sig.GREEN, True, 44.4, 38.9, 2, code=10)
    target = next(t for t in restriction.constraints.targets if t.position_m == 12800.0)
    assert target.speed_mps == pytest.approx(140 / 3.6) and target.braking_share == 0.5
    assert restriction.permitted_mps == pytest.approx(min(np.sqrt((140 / 3.6) ** 2 + 2 * 0.3 * 2300.0),
                                                          atp.static_limit(x)), rel=1e-6)
    red = Atp(line, "passenger", 400.0, "ALSU", 0.6, alsu.STATED_LATENCY_S)
    result = red.supervise(0.0, x, 20.0, sig.RED_YELLOW, True, 22.2, 0.0, 0, code=1)
    stop = next(t for t in result.constraints.targets if t.position_m == 12800.0)
    assert stop.speed_mps == 0.0 and stop.signal and stop.braking_share == 1.0
    # passing the signal under code 1 is a signal passed at danger
    red.supervise(1.0, 12801.0, 5.0, sig.RED_YELLOW, True, 22.2, 0.0, 0, code=1)
    assert red.signals_passed_at_danger == 1


def test_after_a_clear_signal_the_atp_assumes_a_yellow_ahead_until_the_new_code_shows():
    from fmus.ato_controller.atp import Atp

    atp = Atp(load_line(), "passenger", 400.0, "ALSU", 0.6, alsu.STATED_LATENCY_S)
    atp.supervise(0.0, 10300.0, 30.0, sig.GREEN, True, 44.4, 44.4, 2, code=9)
    result = atp.supervise(0.5, 10410.0, 30.0, sig.GREEN, True, 44.4, 44.4, 2, code=9)
    assumed = [t for t in result.constraints.targets if t.position_m == 12800.0]
    assert assumed and assumed[0].speed_mps == pytest.approx(SYSTEM.indication(6, "passenger").target_kmh / 3.6)


# ---- through the FMUs -----------------------------------------------------------------------------
def test_coder_and_receiver_fmus_run_alsu_through_the_orchestrator(tmp_path, product_fmus):
    components = [
        ComponentSpec("coder", str(product_fmus / "WaysideCoder.fmu"), 0.01, {"system": "ALSU", "block_aspects": 4}),
        ComponentSpec("rx", str(product_fmus / "LocoReceiver.fmu"), 0.01, {"system": "ALSU", "train_category": "freight"}),
    ]
    connections = [ConnectionSpec(f"coder.u_tx[1,{n}]", f"rx.e_coil[{n}]", factor=0.1) for n in range(1, N + 1)]
    write_ssd(tmp_path / "sys", "alsu_pair", components, connections, stop_time=2.0)
    code, _, stderr = railcosim("run", tmp_path / "sys", "--output", tmp_path / "out", "--no-build",
                                "--record", "rx.code", "--record", "rx.v_target", "--record", "coder.code_tx[1]")
    assert code == 0, stderr
    header, data = read_csv(tmp_path / "out" / "results.csv")
    last = dict(zip(header, data[-1]))
    assert last["coder.code_tx[1]"] == 9 and last["rx.code"] == 9
    assert last["rx.v_target"] == pytest.approx(100 / 3.6)


def test_a_run_reads_an_alsu_coders_codes_file_as_an_alsu_table(tmp_path, product_fmus):
    """The check of the data files before a run reads a codes_file by its component's system
    (it read every one as ALSN's transmitters, refusing a valid ALSU table)."""
    table = tmp_path / "my_alsu_codes.json"
    table.write_text(alsu.CODES_FILE.read_text(encoding="utf-8"), encoding="utf-8")
    components = [ComponentSpec("coder", str(product_fmus / "WaysideCoder.fmu"), 0.01,
                                {"system": "ALSU", "codes_file": str(table)})]
    write_ssd(tmp_path / "sys", "alsu_table", components, [], stop_time=0.1)
    code, _, stderr = railcosim("run", tmp_path / "sys", "--output", tmp_path / "out", "--no-build",
                                "--record", "coder.code_tx[1]")
    assert code == 0, stderr
    header, data = read_csv(tmp_path / "out" / "results.csv")
    assert data[-1, header.index("coder.code_tx[1]")] == 9


def test_an_alsu_receiver_with_a_carrier_is_one_error(tmp_path, product_fmus):
    components = [ComponentSpec("rx", str(product_fmus / "LocoReceiver.fmu"), 0.01, {"system": "ALSU", "carrier": 50.0})]
    write_ssd(tmp_path / "sys", "bad", components, [], stop_time=0.1)
    code, _, stderr = railcosim("run", tmp_path / "sys", "--output", tmp_path / "out", "--no-build")
    assert code == 2 and "parameter carrier: 50 Hz, but ALSU" in stderr and "Traceback" not in stderr


def test_the_ato_brakes_gently_for_a_permanent_restriction_and_harder_towards_a_signal(tmp_path):
    """Closed loop on the 160 km/h throat line, the code of section 3 scripted: code 10 (140 km/h
    at its exit signal, a permanent restriction) against code 7 (120 km/h, a route: a signal's
    braking). Both without an ATP intervention; the restriction's braking at most half the
    deceleration of the signal's."""
    from harness.closed_loop import run_closed_loop
    from fmus.ato_controller.core import AtoSettings
    from orchestrator.systems.shipped import THROAT_LINE, THROAT_TIMETABLE

    (tmp_path / "line.json").write_text(json.dumps(THROAT_LINE))
    (tmp_path / "timetable.json").write_text(json.dumps(THROAT_TIMETABLE))

    def cab(code_in_section_3):
        def shown(t, x):
            code = code_in_section_3 if 5200.0 <= x < 7600.0 else 9
            ind = SYSTEM.indication(code, "passenger")
            return ind.aspect, True, ind.permitted_kmh / 3.6, ind.target_kmh / 3.6, ind.free_blocks, False, code
        return shown
    hardest = {}
    for code in (10, 7):
        run = run_closed_loop(470.0, settings=AtoSettings(cab_signal="ALSU", decoding_latency_s=alsu.STATED_LATENCY_S),
                              line_file=tmp_path / "line.json", timetable_file=tmp_path / "timetable.json",
                              cab_signal=cab(code))
        x, v = run.column("x"), run.column("v")
        assert run.ato.atp.interventions == 0
        assert v[np.searchsorted(x, 7600.0)] <= SYSTEM.indication(code, "passenger").target_kmh / 3.6 + 0.1
        inside = (x > 5200.0) & (x < 7600.0)
        hardest[code] = -np.min(np.diff(v[inside])) / 0.5
    assert hardest[10] <= 0.5 * hardest[7]
