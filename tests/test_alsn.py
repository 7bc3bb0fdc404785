"""ALSN channel: wayside coder and locomotive receiver (cores), and both FMUs coupled through
the orchestrator. The coil EMF here is the transmitter voltage scaled by a coupling factor
(the rail line is a separate unit)."""
import json

import numpy as np
import pytest

from fmus.signalling import alsn
from fmus.signalling import aspects as sig
from fmus.data.loader import DATA, load_line
from fmus.errors import FmuInputError
from harness.channel import CodeChannel, white_noise_and_hum
from fmus.loco_receiver.core import LocoReceiverCore, ReceiverSettings
from fmus.signalling.alsn import BENCH_COIL_COUPLING, EQUIPMENT_INERTIA_S
from fmus.wayside_coder.core import (SIGNAL_GREEN, SIGNAL_RED, SIGNAL_YELLOW, SIGNAL_YELLOW_GREEN, STATUS_FAILED,
                                     STATUS_PARTIAL, CoderSettings, WaysideCoderCore)
from helpers import ComponentSpec, ConnectionSpec, railcosim, read_csv, write_ssd

FS, N = 4000.0, 40
KPT = {0: 1.60, 1: 1.86}  # section 0 carries KPT-5, section 1 KPT-7 on the default line


def _occupied(*sections):
    occ = np.zeros(8, dtype=bool)
    occ[list(sections)] = True
    return occ


CODE_OCCUPANCY = {  # code sent into section k when ... is occupied
    sig.GREEN: lambda k: _occupied(),
    sig.YELLOW: lambda k: _occupied(k + 2),
    sig.RED_YELLOW: lambda k: _occupied(k + 1),
}


def Chain(section=0, timing_scale=1.0, cam_phase=None, frame=N, receiver=None, seed=1):
    return CodeChannel(section, frame, BENCH_COIL_COUPLING, coder=CoderSettings(timing_scale=timing_scale, seed=seed),
                       receiver=receiver, cam_phase=cam_phase)


def _first_shown(rows, aspect):
    hit = np.flatnonzero((rows[:, 1] == aspect) & (rows[:, 2] == 1))
    return rows[hit[0], 0] if hit.size else np.inf


# ---- decoding latency ---------------------------------------------------------------------------
@pytest.mark.parametrize("section", [0, 1], ids=["KPT-5", "KPT-7"])
@pytest.mark.parametrize("code", [sig.GREEN, sig.YELLOW, sig.RED_YELLOW], ids=["Z", "Zh", "KZh"])
@pytest.mark.parametrize("drift", [0.95, 1.05])
def test_every_code_decodes_within_two_cycles_and_half_a_second_from_any_phase(section, code, drift):
    bound = 2 * KPT[section] * drift + 0.5
    for phase in np.linspace(0.0, 1.0, 12, endpoint=False):
        chain = Chain(section, timing_scale=drift, cam_phase=phase)
        rows = chain.run(bound + 0.1, CODE_OCCUPANCY[code](section))
        assert rows[-1, 3] == code
        assert _first_shown(rows, code) <= bound, f"phase {phase:.2f}"


def test_transitions_green_yellow_red_yellow_in_order():
    chain = Chain(0)
    schedule = lambda t: _occupied() if t < 6.0 else (_occupied(2) if t < 12.0 else _occupied(1))
    rows = chain.run(18.0, schedule)
    shown = [int(a) for i, a in enumerate(rows[:, 1]) if i == 0 or a != rows[i - 1, 1]]
    assert shown == [sig.WHITE, sig.GREEN, sig.YELLOW, sig.RED_YELLOW]
    assert _first_shown(rows, sig.YELLOW) <= 6.0 + 2 * 1.6 + 0.5
    assert _first_shown(rows, sig.RED_YELLOW) <= 12.0 + 2 * 1.6 + 0.5


@pytest.mark.parametrize("code, after_loss", [(sig.GREEN, sig.WHITE), (sig.YELLOW, sig.WHITE),
                                              (sig.RED_YELLOW, sig.RED)])
def test_code_loss_is_held_for_the_equipment_inertia_then_white_or_red_after_red_yellow(code, after_loss):
    chain = Chain(0)
    cut = lambda t, e: e * (t < 8.0)
    rows = chain.run(16.0, CODE_OCCUPANCY[code](0), disturb=cut)
    before = rows[(rows[:, 0] > 7.0) & (rows[:, 0] <= 8.0)]
    assert np.all(before[:, 1] == code)
    inertia = EQUIPMENT_INERTIA_S
    lost = rows[rows[:, 0] >= 8.0 + inertia + 0.2]                 # + the envelope's decay to drop-out
    assert np.all(lost[:, 1] == after_loss) and not lost[:, 2].any()
    # held (and valid) until then: the last cycle supporting it ended at most one cycle before the cut
    held = rows[(rows[:, 0] > 8.0) & (rows[:, 0] < 8.0 + inertia - KPT[0])]
    assert np.all(held[:, 1] == code) and held[:, 2].all()


def test_an_unconfirmed_more_restrictive_code_does_not_keep_the_old_code_shown():
    # З (KPT-5), then from 10 s КЖ whose pulses alternate 0.5 / 0.18 V (impulse-hit levels): its
    # cycles decode but are neither clean nor confirmed, so КЖ is not shown — and they must not
    # keep З alive: З goes within one cycle + 2 s of the change (it stayed for good before)
    tx = alsn.load_transmitters()["KPT-5"]
    t = np.arange(int(20.0 * FS)) / FS
    key = np.zeros(t.size)
    level = np.zeros(t.size)
    change_s = 10.0
    for code, begin, end in ((sig.GREEN, 0.0, change_s), (sig.RED_YELLOW, change_s, 20.0)):
        cycle = tx.cycle_s / (2 if code == sig.RED_YELLOW else 1)
        pulses = tx.pulses[code][:1] if code == sig.RED_YELLOW else tx.pulses[code]
        for index, start in enumerate(np.arange(begin, end, cycle)):
            for on, off in pulses:
                inside = (t >= start + on) & (t < min(start + off, end))
                key[inside] = 1.0
                level[inside] = 0.5 if code == sig.GREEN or index % 2 == 0 else 0.18
    emf = level * key * np.sin(2 * np.pi * 50.0 * t)
    receiver = LocoReceiverCore(N, ReceiverSettings())
    shown = []
    for first in range(0, t.size, N):
        out = receiver.step(first / FS, emf[first:first + N])
        shown.append((t[first] + N / FS, out.aspect))
    shown = np.array(shown)
    assert np.all(shown[(shown[:, 0] > 7.0) & (shown[:, 0] <= change_s), 1] == sig.GREEN)
    assert receiver.out.decoded_codes > 10
    late = shown[shown[:, 0] > change_s + tx.cycle_s + alsn.CODE_TIMEOUT_S + 0.3]
    assert late.size and not np.any(late[:, 1] == sig.GREEN)
    assert alsn.STATED_LATENCY_S > tx.cycle_s + alsn.CODE_TIMEOUT_S + 0.3


def test_a_cycle_begun_after_its_first_pulse_never_has_a_valid_period_and_a_short_interval():
    """The receiver takes a valid cycle with a short interval as whole even right after a joint
    or a gap (docs/loco_receiver.md, display rule): begun at any later pulse of its pattern (the
    pulses before it missed), a cycle of any code of either transmitter, at ±5 % drift, is
    invalid if it still has a short interval; without one (КЖ) it may be valid."""
    mid_pattern = []
    for tx in alsn.load_transmitters().values():
        for code, pulses in tx.pulses.items():
            gaps = pulses[1:, 0] - pulses[:-1, 1]                  # the intervals between its pulses
            for first in range(1, len(pulses)):                    # the pulse the cycle begins at
                shorts = int(np.sum(gaps[first:] < alsn.LONG_INTERVAL_S))
                for drift in (0.95, 1.0, 1.05):
                    decoded, _ = alsn.classify_cycle(shorts, (tx.cycle_s - pulses[first, 0]) * drift)
                    mid_pattern.append((tx.name, code, first, shorts, drift, decoded))
    with_short = [m for m in mid_pattern if m[3] >= 1]
    assert with_short and all(m[5] == alsn.NO_CODE for m in with_short), with_short
    # the reason КЖ-like cycles keep the stricter rule: a З's last pulse and long interval
    assert any(m[3] == 0 and m[5] == sig.RED_YELLOW and m[1] == sig.GREEN for m in mid_pattern)


# ---- noise immunity -----------------------------------------------------------------------------
def _wrong_side_seconds(rows, latency_s):
    """Time the receiver showed a more permissive aspect than sent, beyond the decoding latency
    after each change of the code sent."""
    changes = rows[np.flatnonzero(np.diff(rows[:, 3])) + 1, 0]
    wrong = 0.0
    for t, shown, valid, sent in rows:
        if np.any((changes <= t) & (t < changes + latency_s)) or t < latency_s:
            continue
        if sig.restrictiveness(int(shown)) > sig.restrictiveness(int(sent)):
            wrong += N / FS
    return wrong


def _disturbance(snr_db, harmonics_v, seed):
    return white_noise_and_hum(snr_db, 4.0 * BENCH_COIL_COUPLING, harmonics_v, seed)


# traction harmonics on a DC line, relative to the 0.4 V code: 100 Hz (rectifier even harmonic,
# 2×), 150 Hz (2×), 300 Hz (6-pulse ripple, 5×); a 50 Hz interferer is in-band for a 50 Hz
# carrier and is tested against the 25 Hz carrier below
DC_HARMONICS = {100.0: 0.8, 150.0: 0.8, 300.0: 2.0}


@pytest.mark.parametrize("snr_db", [10.0, 0.0, -6.0, -12.0])
@pytest.mark.parametrize("code", [sig.GREEN, sig.YELLOW, sig.RED_YELLOW], ids=["Z", "Zh", "KZh"])
def test_noise_and_traction_harmonics_never_give_a_more_permissive_aspect(snr_db, code):
    latency = 2 * 1.6 + 0.5
    schedule = lambda t: CODE_OCCUPANCY[code](0) if t < 15.0 else CODE_OCCUPANCY[sig.RED_YELLOW](0)
    rows = Chain(0, seed=int(snr_db) + 100).run(30.0, schedule, disturb=_disturbance(snr_db, DC_HARMONICS, seed=code))
    assert _wrong_side_seconds(rows, latency) == 0.0


def test_harmonics_alone_at_stated_levels_do_not_disturb_decoding():
    rows = Chain(0).run(20.0, _occupied(), disturb=_disturbance(60.0, DC_HARMONICS, seed=3))
    assert _first_shown(rows, sig.GREEN) < 4.0 and np.all(rows[rows[:, 0] > 4.0, 1] == sig.GREEN)


def test_ac_traction_50_hz_does_not_disturb_a_25_hz_receiver(tmp_path):
    doc = json.loads((DATA / "default_line_ac.json").read_text())
    chain = CodeChannel(0, N, BENCH_COIL_COUPLING, line=load_line(DATA / "default_line_ac.json"),
                        receiver=ReceiverSettings(carrier_hz=25.0))
    rows = chain.run(20.0, _occupied(), disturb=_disturbance(60.0, {50.0: 0.8, 150.0: 0.8}, seed=4))
    assert doc["block_sections"][0]["carrier_hz"] == 25
    assert _first_shown(rows, sig.GREEN) < 2 * 1.6 + 0.5 and np.all(rows[rows[:, 0] > 4.0, 1] == sig.GREEN)


def test_a_25_hz_code_is_not_decoded_by_a_50_hz_receiver():
    chain = CodeChannel(0, N, BENCH_COIL_COUPLING, coder=CoderSettings(carrier_hz=25.0))
    rows = chain.run(10.0, _occupied())
    assert not rows[:, 2].any()


# ---- receiver details ---------------------------------------------------------------------------
def test_recovery_after_a_ten_fold_overload_takes_0_6_to_1_5_s():
    """The joints paper (docs/sources.md#interference-at-insulated-joints): at the feed end the coil sees 3.5 V; past the joint 0.28 V; the receiver's
    sensitivity takes 0.6–1.5 s to recover."""
    receiver = LocoReceiverCore(N, ReceiverSettings())
    t = np.arange(int(4.0 * FS)) / FS
    carrier = np.sin(2 * np.pi * 50.0 * t)
    e = np.where(t < 2.0, 3.5, 0.28) * carrier
    relay = []
    for k in range(t.size // N):
        relay.append(receiver.step(k * N / FS, e[k * N:(k + 1) * N]).relay)
    relay = np.array(relay)
    frame_end = (np.arange(relay.size) + 1) * N / FS
    dropped = np.flatnonzero((frame_end > 2.0) & ~relay)[0]
    recovered = frame_end[dropped + np.argmax(relay[dropped:])]
    assert relay[dropped:].any()
    assert 0.6 <= recovered - 2.0 <= 1.5


def test_results_do_not_depend_on_the_frame_length():
    occupancy = lambda t: _occupied() if t < 4.0 else _occupied(1)
    emf, states = {}, {}
    for frame in (1, 40):
        chain = Chain(1, frame=frame, cam_phase=0.3)
        rows, emf[frame] = chain.run(8.0, occupancy, keep_emf=True)
        every_10ms = rows[(np.arange(len(rows)) + 1) * frame % 40 == 0]
        out = chain.receiver.out
        states[frame] = (every_10ms[:, 1:].tolist(), out.decoded_codes, out.errors, round(out.level_v, 9))
    assert np.array_equal(emf[1], emf[40])
    assert states[1] == states[40]


def test_overload_recovery_and_loss_decode_the_same_sample_by_sample():
    # the gain control at work (a coil EMF 30× the usual, 6 V: twelve times its limit), its
    # recovery, a code loss beyond the inertia and the code back: a build with one sample per
    # frame (which filters and decides in floats) shows what the 10 ms frames show, when they
    # show it, with the same level
    gain = lambda t: np.where(t < 4.0, 1.0, np.where(t < 8.0, 30.0, np.where((t >= 10.0) & (t < 17.0), 0.0, 1.0)))
    disturb = lambda t, e: e * gain(t)
    shown = {}
    for frame in (1, 40):
        chain = Chain(1, frame=frame, cam_phase=0.55, receiver=ReceiverSettings())
        rows, levels = [], []
        for _ in range(int(22.0 * FS / 40)):       # 10 ms at a time, the receiver's state read after each
            rows.append(chain.run(0.01, CODE_OCCUPANCY[sig.YELLOW](1), disturb=disturb)[-1])
            levels.append(chain.receiver.out.level_v)
        out = chain.receiver.out
        shown[frame] = (np.array(rows), np.array(levels), out.decoded_codes, out.errors, out.joints)
    (rows_1, levels_1, *counts_1), (rows_40, levels_40, *counts_40) = shown[1], shown[40]
    assert np.array_equal(rows_1[:, 1:], rows_40[:, 1:]) and counts_1 == counts_40
    np.testing.assert_allclose(levels_1, levels_40, rtol=1e-9, atol=1e-12)
    # the overload was seen, the code was lost (beyond the 5.5 s inertia) and shown again
    assert levels_40.max() > 3.0 and not rows_40[1600:1700, 2].any() and rows_40[-1, 1] == sig.YELLOW


def test_receiver_reports_speeds_per_category_and_transmitter_type():
    chain = Chain(1, receiver=ReceiverSettings(train_category="freight"))
    chain.run(6.0, _occupied(3))   # section 1 sees Ж
    out = chain.receiver.out
    assert (out.aspect, out.transmitter, out.free_blocks) == (sig.YELLOW, 7, 1)
    assert out.v_target_mps == pytest.approx(50 / 3.6) and out.v_permitted_mps == pytest.approx(90 / 3.6)


# ---- coder ----------------------------------------------------------------------------------
def test_block_logic_three_and_four_aspects():
    line = load_line()
    three = WaysideCoderCore(line, 8, N, CoderSettings())
    four = WaysideCoderCore(line, 8, N, CoderSettings(block_aspects=4))
    occ = _occupied(5)
    assert three.block_signals(occ)[:5].tolist() == [SIGNAL_GREEN] * 3 + [SIGNAL_YELLOW, SIGNAL_RED]
    assert four.block_signals(occ)[:5].tolist() == [SIGNAL_GREEN] * 2 + [SIGNAL_YELLOW_GREEN, SIGNAL_YELLOW, SIGNAL_RED]
    out = three.step(0.0, occ)
    assert out.code_tx[:5].tolist() == [sig.GREEN] * 3 + [sig.YELLOW, sig.RED_YELLOW]


def test_track_circuits_without_signals_are_coded_as_one_block():
    """A station throat: sections 4-6 of the joints_at_speed line form one block (signals only
    at its ends). Occupancy anywhere in it closes the signal before it; its track circuits carry
    the code of the block's exit signal, except behind the occupied circuit (no code: the block
    rules, tests/test_block_rules.py), and show no signal of their own."""
    from orchestrator.systems.shipped import SSP_ROOT

    line = load_line(SSP_ROOT / "joints_at_speed" / "resources" / "throat_line.json")
    assert line.block_of_section == [0, 1, 2, 3, 3, 3, 4, 5]
    coder = WaysideCoderCore(line, 8, N, CoderSettings())
    occ = np.zeros(8, dtype=bool)
    occ[4] = True                                              # the middle circuit of the throat
    out = coder.step(0.0, occ)
    assert out.code_tx[:6].tolist() == [sig.GREEN, sig.YELLOW, sig.RED_YELLOW, alsn.NO_CODE, sig.GREEN, sig.GREEN]
    assert out.signal[3:6].tolist() == [0, 0, SIGNAL_GREEN]    # dark inside the throat


def test_coding_on_occupation_after_the_switch_on_delay():
    coder = WaysideCoderCore(load_line(), 8, N, CoderSettings(coding="on_occupation", switch_on_delay_s=0.5))
    assert coder.step(0.0, _occupied(2)).code_tx[2] == alsn.NO_CODE
    assert coder.step(0.4, _occupied(2)).code_tx[2] == alsn.NO_CODE
    out = coder.step(0.5, _occupied(2))
    assert out.code_tx[2] == sig.GREEN and out.code_tx[1] == alsn.NO_CODE
    assert np.abs(out.u_tx[1]).max() == 0.0


def test_transmitter_faults_reserve_then_no_code():
    coder = WaysideCoderCore(load_line(), 8, N, CoderSettings())
    assert coder.step(0.0, _occupied(), fault_main=True).status == STATUS_PARTIAL
    assert coder.out.code_tx[0] == sig.GREEN
    out = coder.step(0.01, _occupied(), fault_main=True, fault_reserve=True)
    assert out.status == STATUS_FAILED and not out.code_tx.any() and not out.u_tx.any()


@pytest.mark.parametrize("t0", [0.0, 9999.99, 123456.78])
def test_the_transmitted_code_is_the_keyed_carrier_after_long_runs(t0):
    # the coder reads a section's periodic output from a table: it must stay the code table's
    # keyed carrier at any time, every section, every code
    line = load_line()
    coder = WaysideCoderCore(line, 8, N, CoderSettings())
    transmitters = alsn.load_transmitters()
    for occupied in (_occupied(), _occupied(3), _occupied(5, 6)):
        for frame in range(60):
            t = t0 + frame * N / FS
            out = coder.step(t, occupied)
            times = (round(t * FS) + np.arange(N)) / FS
            for k, section in enumerate(line.sections):
                tx = transmitters[section.transmitter]
                phase = np.mod(times + coder.cam_offset_s[k], tx.cycle_s)
                pulses = tx.pulses.get(int(out.code_tx[k]), np.zeros((0, 2)))
                keyed = ((phase[:, None] >= pulses[:, 0]) & (phase[:, None] < pulses[:, 1])).any(axis=1)
                near_edge = (np.abs(phase[:, None] - pulses.ravel()) < 1e-6).any(axis=1)
                expected = 4.0 * keyed * np.sin(2 * np.pi * section.carrier_hz * times)
                np.testing.assert_allclose(out.u_tx[k][~near_edge], expected[~near_edge], atol=1e-6)


def test_unsynchronised_transmitters_have_different_cam_phases():
    coder = WaysideCoderCore(load_line(), 8, N, CoderSettings(seed=7))
    assert np.unique(np.round(coder.cam_offset_s / coder.cycle_s, 6)).size == 8
    again = WaysideCoderCore(load_line(), 8, N, CoderSettings(seed=7))
    assert np.array_equal(coder.cam_offset_s, again.cam_offset_s)


# ---- bad input ------------------------------------------------------------------------------
def test_bad_carrier_rate_and_timings_are_named(tmp_path):
    with pytest.raises(FmuInputError, match="parameter carrier: 60 Hz"):
        LocoReceiverCore(N, ReceiverSettings(carrier_hz=60.0))
    with pytest.raises(FmuInputError, match="parameter fs: 300 Hz is below 8"):
        LocoReceiverCore(N, ReceiverSettings(fs_hz=300.0))
    with pytest.raises(FmuInputError, match="parameter fs"):
        WaysideCoderCore(load_line(), 8, N, CoderSettings(fs_hz=300.0))
    doc = json.loads(alsn.CODES_FILE.read_text())
    doc["transmitters"]["KPT-7"]["codes"]["Zh"][1] = -0.12
    bad = tmp_path / "codes.json"
    bad.write_text(json.dumps(doc))
    with pytest.raises(FmuInputError, match=r"codes.json: field transmitters.KPT-7.codes.Zh: every timing must be positive"):
        alsn.load_transmitters(bad)
    line = json.loads((DATA / "default_line.json").read_text())
    line["block_sections"][3]["carrier_hz"] = 60
    path = tmp_path / "line.json"
    path.write_text(json.dumps(line))
    with pytest.raises(FmuInputError, match=r"line.json: field block_sections\[3\].carrier_hz: 60 is not one of"):
        load_line(path)
    with pytest.raises(FmuInputError, match="parameter carrier: 60 Hz"):
        WaysideCoderCore(load_line(), 8, N, CoderSettings(carrier_hz=60.0))


# ---- the FMUs through the orchestrator -----------------------------------------------------------
def _coder_receiver_system(folder, fmu_dir, section=1, extra_receiver=None):
    components = [
        ComponentSpec("coder", str(fmu_dir / "WaysideCoder.fmu"), 0.01),
        ComponentSpec("rx", str(fmu_dir / "LocoReceiver.fmu"), 0.01, dict(extra_receiver or {})),
    ]
    connections = [ConnectionSpec(f"coder.u_tx[{section + 1},{n}]", f"rx.e_coil[{n}]", factor=BENCH_COIL_COUPLING)
                   for n in range(1, N + 1)]
    return write_ssd(folder, "alsn_pair", components, connections, stop_time=6.0)


def test_coder_and_receiver_fmus_decode_through_the_orchestrator(tmp_path, product_fmus):
    _coder_receiver_system(tmp_path / "sys", product_fmus)
    code, _, stderr = railcosim("run", tmp_path / "sys", "--output", tmp_path / "out", "--no-build",
                                "--record", "rx.aspect", "--record", "rx.code_valid", "--record", "coder.code_tx[2]")
    assert code == 0, stderr
    header, data = read_csv(tmp_path / "out" / "results.csv")
    last = dict(zip(header, data[-1]))
    assert last["coder.code_tx[2]"] == sig.GREEN
    assert last["rx.aspect"] == sig.GREEN and last["rx.code_valid"] == 1


def test_receiver_fmu_rejects_an_unsupported_carrier(tmp_path, product_fmus):
    _coder_receiver_system(tmp_path / "sys", product_fmus, extra_receiver={"carrier": 60.0})
    code, _, stderr = railcosim("run", tmp_path / "sys", "--output", tmp_path / "out", "--no-build")
    assert code == 2 and "parameter carrier: 60 Hz" in stderr and "Traceback" not in stderr
