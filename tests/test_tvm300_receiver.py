"""The TVM-300 loco receiver (docs/loco_receiver.md#tvm-300, fmus/loco_receiver/tvm300.py): every
used sub-frequency from the coder core through the high-speed line's rail line at its minimum
ballast and at 50 Ω·km; synthesised carriers (harness/tvm300_receiver.py) with noise, a
neighbour's carrier, none / two / an unused sub-frequency, code changes and a lost carrier.
Decode times and cost: benchmarks/tvm300_decode.py."""
import numpy as np
import pytest

from fmus.errors import FmuInputError
from fmus.loco_receiver import tvm300 as rx
from fmus.loco_receiver.tvm300 import Tvm300ReceiverCore, Tvm300ReceiverSettings
from fmus.signalling import aspects as sig
from fmus.signalling import tvm300
from harness.tvm300_receiver import code, rail_line_emf, run

TVM = tvm300.system()
GREEN = code(300, 300)
YELLOW = code(220, 160)
STOP = code(0, 0)
USED = sorted(tvm300.code_of_index(k) for k in TVM.table.pairs)
UNUSED = sorted(set(range(1, tvm300.SUB_FREQUENCY_COUNT + 1)) - set(USED))
EMF_V = 0.3
LEAK = 0.1


def test_the_window_resolves_the_sub_frequencies_and_the_fit_is_exact_on_a_clean_deviation():
    for fs in (8000.0, 12000.0):
        core = Tvm300ReceiverCore(40, Tvm300ReceiverSettings(fs_hz=fs))
        assert core.window / core.rate_hz >= 1.0 / tvm300.SUB_FREQUENCY_SPACING_HZ
        t = 2.3 + np.arange(core.window) / core.rate_hz
        for c in range(1, tvm300.SUB_FREQUENCY_COUNT + 1):
            coefficients = core.fit @ tvm300.frequency_deviation(c, t, phase_rad=0.7 * c)
            amplitudes = np.hypot(*coefficients[1:].reshape(2, -1)) / tvm300.DEVIATION_HZ
            np.testing.assert_allclose(amplitudes, np.eye(tvm300.SUB_FREQUENCY_COUNT)[c - 1], atol=1e-9)


# ---- through the rail line: the acceptance criterion ------------------------------------------
def _decode(emf, fs=12000.0, frame=120):
    core = Tvm300ReceiverCore(frame, Tvm300ReceiverSettings(fs_hz=fs))
    return np.array([core.step(first / fs, emf[first:first + frame]).code
                     for first in range(0, emf.size - frame + 1, frame)]), core


@pytest.mark.parametrize("ballast", [0.0, 50.0], ids=["line-minimum-ballast", "50-ohm-km"])
@pytest.mark.parametrize("section", [0, 1], ids=["1700Hz", "2300Hz"])
def test_every_used_sub_frequency_through_the_rail_line_is_decoded_to_its_code(section, ballast):
    """Coder core → the high-speed line's rail line at 12 kHz → receiver, a train standing 10 m
    into the section (its weakest code; the line's own ballast there is its minimum, 1 and
    1.5 Ω·km): the section sends every used code in turn, 1.5 s each, every other section the
    most permissive 300/300; each code shown by the end of its slot, nothing else ever."""
    from fmus.data.loader import load_line
    from harness.tvm_line import HSL_LINE

    line = load_line(HSL_LINE)
    slot_s = 1.5
    schedule = [(slot_s * k, [GREEN] * section + [c] + [GREEN] * (len(line.sections) - section - 1))
                for k, c in enumerate(USED)]
    emf = rail_line_emf(schedule, line.sections[section].start_m + 10.0, slot_s * len(USED), ballast_ohm_km=ballast)
    assert np.abs(emf).max() < (0.25 if not ballast else 1.0)         # the weak end indeed
    shown, core = _decode(emf)
    assert set(shown.tolist()) <= set(USED) | {0}
    frames = int(round(slot_s / 0.01))
    assert [int(shown[frames * (k + 1) - 1]) for k in range(len(USED))] == USED
    # nothing but the slot's code or the one before it (held until the new one shows)
    for k in range(1, len(USED)):
        assert set(shown[frames * k:frames * (k + 1)].tolist()) <= {USED[k - 1], USED[k]}, USED[k]
    assert core.out.word_carrier_hz == float(line.sections[section].carrier_hz)


# ---- synthesised carriers ------------------------------------------------------------------------
@pytest.mark.parametrize("fs", [12000.0, 8000.0])
def test_a_code_is_shown_with_its_meaning_and_a_neighbours_permissive_code_never(fs):
    plan = [(0.0, {1700.0: (YELLOW, EMF_V), 2300.0: (GREEN, LEAK * EMF_V)})]
    record, core = run(plan, 3.0, fs_hz=fs, noise_v=0.05)
    assert set(record.code.tolist()) == {0, YELLOW}
    shown = record.t >= rx.STATED_DECODE_S + 0.01
    assert (record.code[shown] == YELLOW).all() and record.valid[shown].all()
    assert (record.aspect[shown] == sig.YELLOW).all() and (record.v_permitted_kmh[shown] == pytest.approx(220.0))
    assert (record.word_carrier_hz[shown] == 1700.0).all()
    assert core.out.v_target_mps == pytest.approx(160 / 3.6) and core.out.free_blocks == 3


@pytest.mark.parametrize("case", ["none", "two-full", "two-half", "unused", "between"])
def test_none_two_or_an_unused_sub_frequency_is_no_code_never_a_more_permissive_one(case):
    """From the stop code shown: a bare carrier, two sub-frequencies at once (each at the full
    deviation, each at half), an unused one, one at half the deviation: no code is ever shown
    but the stop code, and the display ends restrictive (no code) within the stated latency."""
    sent = {"none": [(0, 1.0)], "two-full": [((GREEN, YELLOW), 1.0)], "two-half": [((GREEN, YELLOW), 0.5)],
            "unused": [(u, 1.0) for u in UNUSED], "between": [(GREEN, 0.5)]}[case]
    for codes, share in sent:
        plan = [(0.0, {1700.0: (STOP, EMF_V)}), (2.0, {1700.0: (codes, EMF_V, share)})]
        record, core = run(plan, 2.0 + rx.STATED_LATENCY_S + 0.3, noise_v=0.03)
        assert set(record.code.tolist()) <= {0, STOP}, codes
        assert record.code[record.t < 2.0][-1] == STOP
        lost = record.first(2.0, ~record.valid)
        assert lost is not None and lost <= rx.STATED_LATENCY_S, codes
        assert not record.valid[-1] and record.aspect[-1] == sig.RED and record.v_permitted_kmh[-1] == 0.0
        assert core.last_decision.code == tvm300.NO_CODE and core.last_decision.carrier_hz == 1700.0


@pytest.mark.parametrize("fs", [12000.0, 8000.0])
def test_a_restrictive_change_is_shown_within_the_decode_time_at_once_and_a_permissive_one_confirmed(fs):
    plan = [(0.0, {1700.0: (GREEN, EMF_V)}), (3.0, {1700.0: (YELLOW, EMF_V)}), (6.0, {1700.0: (GREEN, EMF_V)})]
    for seed in range(3):
        record, _ = run(plan, 8.0, fs_hz=fs, noise_v=0.03, seed=seed, phase_seed=seed)
        restrictive = record.first(3.0, record.code == YELLOW)
        permissive = record.first(6.0, record.code == GREEN)
        assert restrictive <= rx.STATED_DECODE_S - rx.HOP_S + 40 / fs
        assert permissive <= rx.STATED_DECODE_S + 40 / fs
        assert set(record.code[record.t >= 1.5].tolist()) == {GREEN, YELLOW}
        assert record.first(3.0, record.decided == YELLOW) == restrictive          # at the first decision reading it
        assert permissive - record.first(6.0, record.decided == GREEN) == pytest.approx(rx.HOP_S, abs=1.01 * 40 / fs)


def test_a_code_starting_from_cold_is_shown_within_the_stated_decode_time():
    for start_s in 1.0 + np.arange(0.0, rx.HOP_S, 0.0125):
        record, _ = run([(0.0, {}), (start_s, {1700.0: (GREEN, 0.1)})], start_s + 1.5)
        assert record.first(start_s - 1e-9, record.code == GREEN) <= rx.STATED_DECODE_S + 40 / 12000.0, start_s


@pytest.mark.parametrize("fs", [12000.0, 8000.0])
def test_a_lost_carrier_is_the_restrictive_indication_within_the_stated_latency(fs):
    plan = [(0.0, {1700.0: (GREEN, EMF_V)}), (3.0, {})]
    record, _ = run(plan, 3.0 + rx.STATED_LATENCY_S + 0.3, fs_hz=fs, noise_v=0.03)
    lost = record.first(3.0, ~record.valid)
    assert rx.HOLD_S - rx.HOP_S <= lost <= rx.STATED_LATENCY_S
    after = record.t >= 3.0 + lost
    assert (record.code[after] == 0).all() and (record.aspect[after] == sig.RED).all()
    assert (record.v_permitted_kmh[after] == 0.0).all() and (record.word_carrier_hz[after] == 0.0).all()


def test_at_a_block_boundary_the_display_goes_from_the_old_code_to_the_new_carriers_without_a_gap():
    plan = [(0.0, {1700.0: (GREEN, EMF_V), 2300.0: (YELLOW, LEAK * EMF_V)}),
            (3.0, {1700.0: (GREEN, LEAK * EMF_V), 2300.0: (YELLOW, EMF_V)})]
    record, _ = run(plan, 5.0, noise_v=0.03)
    assert record.valid[record.t >= 1.5].all()
    assert (record.word_carrier_hz[record.code == YELLOW] == 2300.0).all()
    assert record.first(3.0, record.code == YELLOW) <= rx.STATED_DECODE_S


def test_any_frame_length_gives_the_same_outputs():
    plan = [(0.0, {1700.0: (GREEN, EMF_V)}), (2.0, {1700.0: (YELLOW, EMF_V)}), (4.0, {})]
    forty, long = (run(plan, 6.0, frame=frame, noise_v=0.05, seed=4)[0] for frame in (40, 600))
    same_time = np.isin(np.round(forty.t * 12000.0), np.round(long.t * 12000.0))
    assert same_time.sum() == long.t.size
    for name in ("code", "valid", "aspect", "word_carrier_hz"):
        np.testing.assert_array_equal(getattr(forty, name)[same_time], getattr(long, name))


@pytest.mark.parametrize("settings, message", [
    (Tvm300ReceiverSettings(fs_hz=4000.0), "parameter fs: 4000 Hz is too low for TVM300's carriers up to 2300 Hz"),
    (Tvm300ReceiverSettings(fs_hz=8000.0, track=3), "parameter track: 3 is not one of 1, 2 \\(TVM300's tracks\\)"),
    (Tvm300ReceiverSettings(fs_hz=8000.0, inertia_s=-1.0), "parameter inertia: must not be negative"),
])
def test_bad_settings_are_one_error_naming_the_parameter(settings, message):
    with pytest.raises(FmuInputError, match=message):
        Tvm300ReceiverCore(40, settings)
