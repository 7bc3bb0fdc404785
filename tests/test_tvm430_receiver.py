"""The TVM-430 loco receiver (docs/loco_receiver.md#tvm-430, fmus/loco_receiver/tvm430.py): its
track's carriers synthesised from fmus/signalling/tvm430.py's modulation (harness/tvm430_receiver.py)
at a coil EMF like the rail line's, with white noise, a neighbour's carrier leaking 20 dB down,
word changes, every single- and double-bit corrupted word, a lost carrier; and the FMU built
with `railcosim build` driven through fmpy. Decode times and cost: benchmarks/tvm430_decode.py."""
import copy
import itertools

import numpy as np
import pytest

from fmus.errors import FmuInputError
from fmus.loco_receiver import tvm430 as rx
from fmus.loco_receiver.tvm430 import Tvm430ReceiverCore, Tvm430ReceiverSettings
from fmus.signalling import aspects as sig
from fmus.signalling import cab_systems, tvm430
from harness.tvm430_receiver import TONE_PERIOD_S, fm_carrier, run, word
from orchestrator.sspgen import ComponentSpec, write_ssd
from tests.helpers import railcosim

TVM = tvm430.system()
GREEN = word(300, 300)                           # no target in range
YELLOW = word(230, 170, 2750.0, -6.0)            # two blocks before the target, falling 6 ‰
STOP = word(0, 0, 0.0, 0.0)
EMF_V = 0.3                                      # a carrier at the coil (peak)
WEAK_V = 0.1                                     # the weakest the rail line gives (10 m into a 2300 Hz circuit)
LEAK = 0.1                                       # a neighbour's carrier 20 dB down


def test_the_system_name_is_known():
    assert cab_systems.lookup("TVM430") is cab_systems.TVM430
    assert cab_systems.TVM430.transmitter == cab_systems.UM71 and cab_systems.ALSU.transmitter == cab_systems.KPT
    assert cab_systems.digital_system("TVM430") is None


def test_the_window_resolves_the_tones_and_the_fit_is_exact_on_a_clean_deviation():
    """The window is at least 1/0.64 s; on the discriminator's ideal output (tvm430's
    frequency_deviation) the fit returns every tone at 1 (present) or 0 (absent)."""
    for fs in (8000.0, 12000.0):
        core = Tvm430ReceiverCore(40, Tvm430ReceiverSettings(fs_hz=fs))
        assert core.window / core.rate_hz >= 1.0 / tvm430.TONE_SPACING_HZ
        t = 3.7 + np.arange(core.window) / core.rate_hz
        coefficients = core.fit @ tvm430.frequency_deviation(YELLOW, t)
        amplitudes = np.hypot(*coefficients[1:].reshape(2, -1))
        np.testing.assert_allclose(amplitudes, tvm430.bits_of(YELLOW), atol=1e-9)


@pytest.mark.parametrize("fs", [12000.0, 8000.0])
def test_a_word_is_shown_with_its_meaning_and_a_neighbours_permissive_word_never(fs):
    """The section's carrier (1700 Hz) with YELLOW, the next block's (2300 Hz) leaking 20 dB down
    with a more permissive GREEN, white noise: YELLOW shown with its step, target, gradient and
    carrier; GREEN never."""
    plan = [(0.0, {1700.0: (YELLOW, EMF_V), 2300.0: (GREEN, LEAK * EMF_V)})]
    record, _ = run(plan, 5.0, fs_hz=fs, noise_v=0.05)
    assert not (record.code == GREEN).any()
    assert set(record.code.tolist()) == {0, YELLOW}
    shown = record.t >= 2.0
    assert (record.code[shown] == YELLOW).all() and record.valid[shown].all()
    assert (record.aspect[shown] == sig.YELLOW).all() and (record.v_permitted_kmh[shown] == pytest.approx(230.0))
    assert (record.target_distance_m[shown] == 2750.0).all() and (record.gradient_permille[shown] == -6.0).all()
    assert (record.word_carrier_hz[shown] == 1700.0).all()


@pytest.mark.parametrize("fs", [10400.0, 16000.0, 11025.0])
def test_other_sample_rates_decode_the_same(fs):
    """Rates the rail line may choose, one whose decimation (fs/200) is not whole among them."""
    plan = [(0.0, {1700.0: (YELLOW, EMF_V), 2300.0: (GREEN, LEAK * EMF_V)})]
    record, core = run(plan, 3.0, fs_hz=fs, frame=400, noise_v=0.05)
    assert core.window / core.rate_hz >= rx.WINDOW_S
    assert set(record.code.tolist()) == {0, YELLOW} and record.code[-1] == YELLOW


def test_the_other_tracks_carrier_as_strong_as_ours_is_not_heard():
    """Track 2's receiver between its 2000 Hz carrier (YELLOW) and track 1's 2300 Hz at the same
    level with GREEN (the neighbour track's circuit under the coils, at its worst): YELLOW only."""
    plan = [(0.0, {2000.0: (YELLOW, EMF_V), 2300.0: (GREEN, EMF_V), 1700.0: (GREEN, EMF_V)})]
    record, _ = run(plan, 4.0, settings=Tvm430ReceiverSettings(fs_hz=12000.0, track=2), noise_v=0.03)
    assert set(record.code.tolist()) == {0, YELLOW} and record.code[-1] == YELLOW
    assert (record.word_carrier_hz[record.code == YELLOW] == 2000.0).all()


def test_a_weak_carrier_in_noise_decodes_and_never_shows_another_word():
    """The weakest EMF the rail line gives, noise 0.06 V rms over 6 kHz (1.4 dB per sample; 19 dB
    in the 100 Hz the baseband keeps), on track 2's 2600 Hz at 12 kHz: the word shown, nothing
    else."""
    plan = [(0.0, {2600.0: (YELLOW, WEAK_V), 2000.0: (GREEN, LEAK * WEAK_V)})]
    record, _ = run(plan, 12.0, noise_v=0.06, settings=Tvm430ReceiverSettings(fs_hz=12000.0, track=2))
    assert set(record.code.tolist()) <= {0, YELLOW}
    assert record.first(0.0, record.code == YELLOW) < 2.5
    assert record.valid[record.t >= 2.5].all()


@pytest.mark.parametrize("fs", [12000.0, 8000.0])
def test_a_restrictive_change_is_taken_at_once_and_a_permissive_one_after_two_decisions(fs):
    plan = [(0.0, {1700.0: (GREEN, EMF_V)}), (4.0, {1700.0: (YELLOW, EMF_V)}), (8.0, {1700.0: (GREEN, EMF_V)})]
    for seed in range(3):
        record, core = run(plan, 11.0, fs_hz=fs, noise_v=0.03, seed=seed, tone_offset_s=seed * TONE_PERIOD_S / 3)
        restrictive = record.first(4.0, record.code == YELLOW)
        permissive = record.first(8.0, record.code == GREEN)
        # the window must be (nearly) all new before the tones decide: at least 0.7 of it, at
        # most the window and a hop; the permissive change needs one hop more than its first decode
        assert 0.7 * rx.WINDOW_S <= restrictive <= rx.WINDOW_S + rx.HOP_S + 0.01
        assert 0.7 * rx.WINDOW_S <= permissive <= rx.WINDOW_S + 2 * rx.HOP_S + 0.01
        # the display goes from one word to the other, never through no word or a third word
        assert set(record.code[record.t >= 2.0].tolist()) == {GREEN, YELLOW}
        # restrictive: shown at the first decision that read it; permissive: one decision later
        assert record.first(4.0, record.decided == YELLOW) == restrictive
        assert permissive - record.first(8.0, record.decided == GREEN) == pytest.approx(rx.HOP_S, abs=1.01 * 40 / fs)


def test_at_a_block_boundary_the_display_goes_from_the_old_word_to_the_new_carriers_without_a_gap():
    """The coils pass from the 1700 Hz block into the 2300 Hz one, each leaking 20 dB into the
    other: the old word holds until the new one shows, with its carrier (the ATP finds the block
    by it), never the restrictive no-word indication on the way."""
    plan = [(0.0, {1700.0: (GREEN, EMF_V), 2300.0: (YELLOW, LEAK * EMF_V)}),
            (4.0, {1700.0: (GREEN, LEAK * EMF_V), 2300.0: (YELLOW, EMF_V)})]
    record, _ = run(plan, 8.0, noise_v=0.03)
    after = record.t >= 2.0
    assert record.valid[after].all()
    new = record.first(4.0, record.code == YELLOW)
    assert new <= rx.WINDOW_S + 2 * rx.HOP_S + 0.01
    assert (record.word_carrier_hz[record.code == YELLOW] == 2300.0).all()
    assert (record.word_carrier_hz[record.code == GREEN] == 1700.0).all()


@pytest.mark.parametrize("before_s", [0.1, 0.5, 1.0, 1.6])
@pytest.mark.parametrize("first, second", [(YELLOW, GREEN), (GREEN, YELLOW)])
def test_a_word_change_just_before_a_block_boundary_leaves_no_gap(before_s, first, second):
    """The word of the block the coils are leaving changes (a train ahead moved on) shortly
    before they cross into the next block: the windows straddling the change read no word,
    then the new block's carrier needs a whole window of its own. The hold bridges both, so
    the ATP, which trips on a lost word, sees the old word until the new block's shows (found
    in the shipped tvm430_following, where the follower was tripped 0.3 s short)."""
    third = word(270, 230, 4500.0, -12.0)
    plan = [(0.0, {1700.0: (first, EMF_V)}), (4.0 - before_s, {1700.0: (second, EMF_V)}),
            (4.0, {2300.0: (third, EMF_V)})]
    record, _ = run(plan, 9.0, noise_v=0.03)
    after = record.t >= 2.0
    assert record.valid[after].all()
    assert record.first(4.0, record.code == third) <= rx.WINDOW_S + 2 * rx.HOP_S + 0.01


class ScriptedReceiver(Tvm430ReceiverCore):
    """The display logic on scripted decisions: ``script(t)`` gives the word each decision reads
    on 1700 Hz (the signal processing is tested above)."""

    def __init__(self, script):
        super().__init__(120, Tvm430ReceiverSettings(fs_hz=12000.0))
        self.script = script

    def read_window(self, time_s):
        word_read = self.script(time_s)
        return rx.Decision(time_s, 1700.0 if word_read else 0.0, None, word_read)


def _displayed(script, seconds):
    core = ScriptedReceiver(script)
    shown = []
    for first in range(0, int(seconds * 12000), 120):
        out = core.step(first / 12000.0, np.zeros(120))
        shown.append(((first + 120) / 12000.0, out.code))
    return np.array(shown)


def test_a_word_permissive_in_one_field_never_keeps_a_shown_word_alive():
    """The stop word shown (0/0 at 0 m, but +15 ‰) and then, under noise, only single reads of a
    270/230 word at 4500 m on a level (0 ‰): neither permits everything the other does (the
    stop word's gradient is less falling), so the reads do not hold the stop word past its
    hold, and the display goes to no word (found by the TVM-430 noise study: the stop word held
    7 s, its gradient more permissive than the word sent)."""
    stop, new = word(0, 0, 0.0, 15.0), word(270, 230, 4500.0, 0.0)
    every_other = lambda t: new if round(t / rx.HOP_S) % 2 else tvm430.NO_WORD      # never two in a row
    shown = _displayed(lambda t: stop if t < 3.0 else every_other(t), 12.0)
    held = shown[shown[:, 1] == stop, 0]
    assert held.max() <= 3.0 + rx.HOLD_S + rx.HOP_S
    assert (shown[shown[:, 0] > 3.0 + rx.HOLD_S + rx.HOP_S, 1] == tvm430.NO_WORD).all()


def test_a_word_permissive_in_every_field_keeps_the_shown_word_alive():
    """230/170 at 2750 m falling 6 ‰ shown, then single reads of 270/230 at 4500 m on a level:
    the shown word permits nothing the new one does not, so it stays (safe) until the new word
    is confirmed."""
    new = word(270, 230, 4500.0, 0.0)
    every_other = lambda t: new if round(t / rx.HOP_S) % 2 else tvm430.NO_WORD
    shown = _displayed(lambda t: YELLOW if t < 3.0 else every_other(t), 12.0)
    assert (shown[shown[:, 0] > 2.0, 1] == YELLOW).all()


def test_the_same_word_on_the_other_carrier_is_a_new_block_and_waits_for_confirmation():
    plan = [(0.0, {1700.0: (YELLOW, EMF_V)}), (3.0, {2300.0: (YELLOW, EMF_V)})]
    record, _ = run(plan, 6.0)
    carrier = record.word_carrier_hz
    assert carrier[-1] == 2300.0 and (record.code[record.t > 2.0] == YELLOW).all()
    assert record.first(3.0, carrier == 2300.0) >= rx.WINDOW_S


@pytest.mark.parametrize("fs", [12000.0, 8000.0])
def test_a_lost_carrier_is_the_restrictive_indication_within_the_stated_latency(fs):
    plan = [(0.0, {1700.0: (GREEN, EMF_V)}), (4.0, {})]
    record, _ = run(plan, 8.0, fs_hz=fs, noise_v=0.03)
    lost = record.first(4.0, ~record.valid)
    assert lost <= rx.STATED_LATENCY_S
    assert lost >= rx.HOLD_S - rx.HOP_S                 # the hold bridges a separation zone
    after = record.t >= 4.0 + lost
    assert (record.code[after] == 0).all() and (record.aspect[after] == sig.RED).all()
    assert (record.v_permitted_kmh[after] == 0.0).all() and (record.word_carrier_hz[after] == 0.0).all()
    assert (record.target_distance_m[after] == 0.0).all()


def _corrupted(true_word):
    flips = [1 << k for k in range(tvm430.WORD_BITS)]
    return [true_word ^ a for a in flips] + [true_word ^ a ^ b for a, b in itertools.combinations(flips, 2)]


@pytest.mark.parametrize("true_word", [YELLOW, STOP], ids=["230-170", "stop"])
def test_every_single_and_double_bit_corruption_is_never_shown_and_ends_restrictive(true_word):
    """The true word shown, then the carrier carries the word with one or two bits flipped
    (27 + 351 cases): nothing but the true word is ever shown, and the display ends restrictive
    (no word) within the stated latency of the corruption's start."""
    fs, frame = 8000.0, 800                     # any frame length gives the same decisions
    # the true word shown: every case goes on from a copy of this receiver
    shown, receiver = run([(0.0, {1700.0: (true_word, EMF_V)})], 2.0, fs_hz=fs, frame=frame, noise_v=0.03)
    assert shown.code[-1] == true_word
    worst = 0.0
    for corrupted in _corrupted(true_word):
        plan = [(0.0, {1700.0: (true_word, EMF_V)}), (2.0, {1700.0: (corrupted, EMF_V)})]
        record, _ = run(plan, rx.STATED_LATENCY_S + 0.2, core=copy.deepcopy(receiver), start_s=2.0, noise_v=0.03,
                        seed=corrupted)
        assert set(record.code.tolist()) <= {0, true_word}, hex(corrupted)
        lost = record.first(2.0, ~record.valid)
        assert lost is not None and lost <= rx.STATED_LATENCY_S, hex(corrupted)
        assert not record.valid[-1]
        worst = max(worst, lost)
    assert worst > rx.HOLD_S                       # the hold counted from the last decision of the true word


def test_any_frame_length_gives_the_same_outputs():
    plan = [(0.0, {1700.0: (GREEN, EMF_V)}), (3.0, {1700.0: (YELLOW, EMF_V)}), (6.0, {})]
    records = [run(plan, 9.0, frame=frame, noise_v=0.05, seed=4)[0] for frame in (40, 600)]
    forty, long = records
    same_time = np.isin(np.round(forty.t * 12000.0), np.round(long.t * 12000.0))
    assert same_time.sum() == long.t.size
    for name in ("code", "valid", "aspect", "word_carrier_hz", "target_distance_m"):
        np.testing.assert_array_equal(getattr(forty, name)[same_time], getattr(long, name))


@pytest.mark.parametrize("settings, message", [
    (Tvm430ReceiverSettings(fs_hz=4000.0), "parameter fs: 4000 Hz is too low for TVM430's carriers up to 2300 Hz"),
    (Tvm430ReceiverSettings(fs_hz=8000.0, track=3), "parameter track: 3 is not one of 1, 2"),
    (Tvm430ReceiverSettings(fs_hz=8000.0, inertia_s=-1.0), "parameter inertia: must not be negative"),
])
def test_bad_settings_are_one_error_naming_the_parameter(settings, message):
    with pytest.raises(FmuInputError, match=message):
        Tvm430ReceiverCore(40, settings)


# ---- through the rail line --------------------------------------------------------------------------
def _decode(emf, fs=12000.0, frame=120):
    core = Tvm430ReceiverCore(frame, Tvm430ReceiverSettings(fs_hz=fs))
    shown = []
    for first in range(0, emf.size - frame + 1, frame):
        out = core.step(first / fs, emf[first:first + frame])
        shown.append((out.code, out.word_carrier_hz))
    return shown


@pytest.mark.parametrize("ballast", [0.0, 50.0], ids=["line-ballast", "50-ohm-km"])
@pytest.mark.parametrize("section", [0, 1], ids=["1700Hz", "2300Hz"])
def test_through_the_rail_line_where_the_code_is_weakest(section, ballast):
    """Coder core → the high-speed line's rail line at 12 kHz → receiver: the section under test
    sends YELLOW and every other a more permissive GREEN; a train standing with its first
    wheelset 10 m into the section (its weakest code: 0.1–0.2 V at the line's own ballast, its
    minimum, 1–1.5 Ω·km here; 0.7 V at 50 Ω·km): YELLOW with its carrier."""
    from fmus.data.loader import load_line
    from harness.tvm_line import HSL_LINE
    from harness.tvm430_receiver import rail_line_emf

    line = load_line(HSL_LINE)
    words = [GREEN] * len(line.sections)
    words[section] = YELLOW
    emf = rail_line_emf([(0.0, words)], line.sections[section].start_m + 10.0, 3.0, ballast_ohm_km=ballast)
    assert np.abs(emf).max() < (0.25 if not ballast else 1.0)      # the weak end indeed
    shown = _decode(emf)
    assert {code for code, _ in shown} == {0, YELLOW}
    assert shown[-1] == (YELLOW, float(line.sections[section].carrier_hz))


def test_every_speed_pair_through_the_rail_line_on_one_running_receiver():
    """The speed pairs of the tables in turn, 2.5 s each, on the 2300 Hz section 10 m in:
    each shown by the end of its slot (benchmarks/tvm430_decode.py adds every distance and
    gradient code and the 1700 Hz section), nothing else ever."""
    from fmus.data.loader import load_line
    from harness.tvm_line import HSL_LINE
    from harness.tvm430_receiver import rail_line_emf

    line = load_line(HSL_LINE)
    sent = [word(*pair, distance_m=2000.0) for pair in TVM.table.speed_codes.values()]
    schedule = [(2.5 * k, [GREEN] + [w] + [GREEN] * (len(line.sections) - 2)) for k, w in enumerate(sent)]
    shown = np.array([code for code, _ in _decode(rail_line_emf(schedule, line.sections[1].start_m + 10.0,
                                                                2.5 * len(sent)))])
    assert set(shown.tolist()) <= set(sent) | {0}
    assert [shown[250 * (k + 1) - 1] for k in range(len(sent))] == sent


@pytest.mark.parametrize("own, neighbour", [(1700.0, 2300.0), (2300.0, 1700.0)])
def test_the_neighbours_carrier_at_its_worst_leak_is_never_decoded(own, neighbour):
    """harness/tvm_line.py: the train 2.7 m before the separation zone at its section's exit,
    the neighbour's carrier through the zone at its worst (0.058–0.074 of the own EMF, at the
    line's maximum ballast beyond) with a more permissive word: the own word only."""
    from harness.tvm_line import FS, worst_leak_emf

    t = np.arange(300 * 120) / FS
    case = worst_leak_emf(fm_carrier(YELLOW, t, own, 4.0), fm_carrier(GREEN, t, neighbour, 4.0), own_hz=own)
    assert 0.05 < case.leak.emf_ratio < 0.1
    shown = _decode(case.emf)
    assert {code for code, _ in shown} == {0, YELLOW}
    assert shown[-1] == (YELLOW, own)


# ---- through the FMU ------------------------------------------------------------------------------
def test_the_built_fmu_decodes_a_word_and_reports_its_new_outputs(product_fmus):
    """LocoReceiver.fmu (railcosim build) through fmpy: system TVM430, fs 12 kHz, track 1; the
    carrier fed frame by frame into e_coil."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    path = str(product_fmus / "LocoReceiver.fmu")
    description = read_model_description(path)
    vr = {v.name: v.valueReference for v in description.modelVariables}
    frame = sum(1 for name in vr if name.startswith("e_coil["))
    fs, h = 12000.0, frame / 12000.0
    slave = FMU2Slave(guid=description.guid, unzipDirectory=extract(path), modelIdentifier="LocoReceiver",
                      instanceName="rx")
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.setString([vr["system"]], ["TVM430"])
    slave.setReal([vr["fs"]], [fs])
    slave.setInteger([vr["track"]], [1])
    slave.exitInitializationMode()
    inputs = [vr[f"e_coil[{n}]"] for n in range(1, frame + 1)]
    outputs = {}
    for k in range(int(3.0 / h)):
        t = (k * frame + np.arange(frame)) / fs
        slave.setReal(inputs, list(fm_carrier(YELLOW, t, 1700.0, EMF_V)))
        slave.doStep(k * h, h)
    for name in ("target_distance", "gradient", "word_carrier", "v_permitted", "v_target", "level"):
        outputs[name] = slave.getReal([vr[name]])[0]
    for name in ("code", "aspect", "free_blocks"):
        outputs[name] = slave.getInteger([vr[name]])[0]
    outputs["code_valid"] = slave.getBoolean([vr["code_valid"]])[0]
    slave.terminate()
    slave.freeInstance()
    assert outputs["code"] == YELLOW and outputs["code_valid"] and outputs["aspect"] == sig.YELLOW
    assert outputs["target_distance"] == 2750.0 and outputs["gradient"] == -6.0 and outputs["word_carrier"] == 1700.0
    assert outputs["v_permitted"] == pytest.approx(230 / 3.6) and outputs["v_target"] == pytest.approx(170 / 3.6)
    assert outputs["free_blocks"] == 2 and outputs["level"] == pytest.approx(EMF_V, rel=0.02)


@pytest.mark.parametrize("parameters, message", [
    ({"system": "TVM430"}, "parameter fs: 4000 Hz is too low for TVM430's carriers"),
    ({"system": "TVM430", "fs": 8000.0, "carrier": 1700.0}, "parameter carrier: 1700 Hz, but TVM430 listens"),
])
def test_a_bad_tvm430_receiver_parameter_is_one_error(tmp_path, product_fmus, parameters, message):
    step = 40 / parameters.get("fs", 4000.0)
    components = [ComponentSpec("rx", str(product_fmus / "LocoReceiver.fmu"), step, parameters)]
    write_ssd(tmp_path / "sys", "bad", components, [], stop_time=0.1)
    code, _, stderr = railcosim("run", tmp_path / "sys", "--output", tmp_path / "out", "--no-build")
    assert code == 2 and message in stderr and "Traceback" not in stderr, stderr


def test_the_stated_decode_time_holds_the_baseband_low_pass_rise():
    # a carrier at the weakest level starting anywhere in a hop: the decision showing its word
    # comes within the stated decode time (window + two decisions + the low-pass's rise; it
    # left the rise out: 1.8183 s against 1.8125 s), the output at the end of that frame
    from fmus.dsp.filter_design import sos_frame
    for fs_hz in (8000.0, 12000.0):
        low_pass = rx.low_pass_design(fs_hz)
        step, _ = sos_frame(low_pass.sos, np.ones(int(0.05 * fs_hz)), low_pass.initial_state())
        assert np.argmax(step >= rx.SQUELCH_V / rx.WEAKEST_CARRIER_V) / fs_hz <= rx.BASEBAND_RISE_S
    frame, fs_hz = 40, 12000.0
    # the worst lies where the window's first sample above the squelch is a decision's first
    # (0.055 s into a hop here): every 2.5 ms around it, and either end of the hop
    for start_s in 4.0 + np.concatenate([[0.0, 0.1], np.arange(0.04, 0.0701, 0.0025)]):
        record, _ = run([(0.0, {}), (start_s, {1700.0: (GREEN, rx.WEAKEST_CARRIER_V)})], 6.2, fs_hz=fs_hz, frame=frame)
        assert record.first(start_s - 1e-9, record.code == GREEN) <= rx.STATED_DECODE_S + frame / fs_hz, start_s
