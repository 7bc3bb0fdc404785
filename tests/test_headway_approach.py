"""The approach of a block (orchestrator/headway/approach.py): what each cab system shows behind
an occupied block and the ATP's permitted speed under it. No simulation: the coder rules, the
receivers' readings and the ATP's builders only — checked against the documented numbers, against
the real coder cores stepped with the same occupancy, and against Atp.supervise point by point."""
import json
import math

import numpy as np
import pytest

from fmus.ato_controller.atp import Atp
from fmus.ato_controller.supervision import dv_sbi_mps
from fmus.data.loader import DATA
from fmus.signalling import aspects as sig
from fmus.signalling.digital_messages import FREE_BLOCKS_OPEN
from fmus.units import STANDARD_GRAVITY_MPS2
from fmus.wayside_coder.alsu import AlsuCoderCore
from fmus.wayside_coder.core import CoderSettings, WaysideCoderCore
from fmus.wayside_coder.digital_generator import DigitalCoderCore
from fmus.wayside_coder.tvm430 import Tvm430CoderCore
from fmus.signalling import cab_systems
from orchestrator.systems.chain import cab_settings
from orchestrator.systems.shipped import TVM430_FS_HZ, TVM430_LINE, TVM430_STOCK
from orchestrator.errors import UserError
from orchestrator.headway.approach import (_dv_sbi_mps, approach_blocks, cab_setup, indications_behind,
                                           permitted_speed_mps)

KMH = 1 / 3.6
# documented numbers (docs/ato.md; fmus/signalling/aspects.py, alsu_codes.json, als_en.py, fire_dqpsk.py)
ATP_DECEL_SHARE = 0.7            # the ATP supervises at 0.7 × the stock's service deceleration
ALSN_YELLOW_AT_SIGNAL_KMH = 80   # passenger, supervised at the exit signal of a Ж block (the ATO drives to 60)
ALSN_RED_YELLOW_CEILING_KMH = 80
ALSU_CODE_6_AT_SIGNAL_KMH, ALSU_CODE_4_AT_SIGNAL_KMH, ALSU_CODE_1_CEILING_KMH = 100, 80, 80   # passenger
ALSU_PASSENGER_TOP_KMH = 160
DIGITAL_PASSENGER_TOP_KMH = 160
# speed at the block's exit signal by free blocks 0…5, passenger: ALS-EN's plain line (60 km/h on one
# free block, else 200 capped at the category's 160); Table 2.1's commands 2, 7, 12, 13, 14, 15
AT_SIGNAL_KMH = {"ALS-EN": (0, 60, 160, 160, 160, 160), "FIRE_DQPSK": (0, 100, 140, 160, 160, 160)}
TVM_CASCADE = ["300→270", "270→230", "230→170", "170→0", "0→0"]


def setup_for(system, block_aspects=3):
    ato = cab_settings(system)[3]
    if system == "TVM430":
        return cab_setup(system, block_aspects, TVM430_LINE, TVM430_STOCK, ato, {"train_category": "high_speed"})
    return cab_setup(system, block_aspects, None, None, ato)


def starts(setup):
    return [start for start, _ in setup.line.block_bounds]


def test_alsn_three_aspect_red_yellow_then_yellow_then_clear():
    setup = setup_for("ALSN")
    a = ATP_DECEL_SHARE * setup.stock.service_decel
    k = 5
    shown = indications_behind(setup, k)
    assert [i.label for i in shown] == ["З", "З", "З", "Ж", "КЖ"]
    assert [i.free_line for i in shown] == [True, True, True, False, False]
    assert approach_blocks(setup) == 2
    s = starts(setup)
    # КЖ in block k-1: ceiling 80 km/h, a stop at block k's start
    d = np.array([1e-9, 10.0, 100.0, 300.0, 1000.0])
    got = permitted_speed_mps(setup, k, s[k] - d)
    assert got == pytest.approx(np.minimum(ALSN_RED_YELLOW_CEILING_KMH * KMH, np.sqrt(2 * a * d)), rel=1e-9, abs=1e-6)
    assert got[0] == pytest.approx(0.0, abs=1e-3)
    # Ж in block k-2: 80 km/h at its exit (block k-1's start) on the supervision curve
    d = np.array([1e-9, 200.0, 1000.0, 2000.0])
    got = permitted_speed_mps(setup, k, s[k - 1] - d)
    assert got == pytest.approx(np.sqrt((ALSN_YELLOW_AT_SIGNAL_KMH * KMH) ** 2 + 2 * a * d), rel=1e-9)
    # further back unrestricted; in and beyond the occupied block, and off the line: NaN
    assert np.all(np.isinf(permitted_speed_mps(setup, k, np.linspace(0.0, s[k - 2] - 1.0, 50))))
    beyond = permitted_speed_mps(setup, k, [s[k], s[k] + 1.0, setup.line.length_m - 1.0, -5.0])
    assert np.all(np.isnan(beyond))


def test_alsn_four_aspect_sends_yellow_green_as_green():
    setup = setup_for("ALSN", block_aspects=4)
    assert [i.label for i in indications_behind(setup, 6)][-3:] == ["З", "Ж", "КЖ"]
    assert approach_blocks(setup) == 2


def test_alsu_four_aspect_codes_behind_an_occupied_block():
    setup = setup_for("ALSU", block_aspects=4)
    a = ATP_DECEL_SHARE * setup.stock.service_decel
    k = 6
    shown = indications_behind(setup, k)
    assert [i.label for i in shown[-3:]] == ["code 6", "code 4", "code 1"]
    assert [i.free_line for i in shown[-3:]] == [False, False, False]
    assert all(i.free_line for i in shown[:-3])
    assert approach_blocks(setup) == 3
    s = starts(setup)
    d = np.array([1e-9, 100.0, 1000.0, 2000.0])
    top = ALSU_PASSENGER_TOP_KMH * KMH
    for block, at_signal, ceiling in ((k - 3, ALSU_CODE_6_AT_SIGNAL_KMH, top), (k - 2, ALSU_CODE_4_AT_SIGNAL_KMH, top),
                                      (k - 1, 0.0, ALSU_CODE_1_CEILING_KMH * KMH)):
        expected = np.minimum(ceiling, np.sqrt((at_signal * KMH) ** 2 + 2 * a * d))
        assert permitted_speed_mps(setup, k, s[block + 1] - d) == pytest.approx(expected, rel=1e-9, abs=1e-6)


@pytest.mark.parametrize("system", ["ALS-EN", "FIRE_DQPSK"])
def test_digital_free_blocks_and_the_stop_at_the_occupied_block(system):
    setup = setup_for(system)
    a = ATP_DECEL_SHARE * setup.stock.service_decel
    k = len(setup.line.block_bounds) - 1
    shown = indications_behind(setup, k)
    assert [i.free_blocks for i in shown] == [6, 5, 4, 3, 2, 1, 0]
    assert [i.free_line for i in shown] == [True] + [False] * 6
    assert approach_blocks(setup) == FREE_BLOCKS_OPEN
    assert shown[-2].label == f"free 1, {AT_SIGNAL_KMH[system][1]} km/h"
    s = starts(setup)
    for block in range(1, k):
        x = np.linspace(s[block], s[block + 1] - 1e-6, 40)
        # free blocks < 6: a stop at the end of the last free one, i.e. at the occupied block's start,
        # and the indication's speed at the exit of its own block
        at_signal = AT_SIGNAL_KMH[system][k - 1 - block] * KMH
        expected = np.minimum.reduce([np.full(x.shape, DIGITAL_PASSENGER_TOP_KMH * KMH), np.sqrt(2 * a * (s[k] - x)),
                                      np.sqrt(at_signal ** 2 + 2 * a * (s[block + 1] - x))])
        assert permitted_speed_mps(setup, k, x) == pytest.approx(expected, rel=1e-9, abs=1e-6)


def test_tvm430_cascade_and_the_stop_at_the_buffer_section():
    setup = setup_for("TVM430")
    assert setup.category == "high_speed"
    k = 20
    shown = indications_behind(setup, k)
    assert [i.label for i in shown[-5:]] == TVM_CASCADE
    assert all(i.free_line for i in shown[:-5]) and not any(i.free_line for i in shown[-5:])
    assert approach_blocks(setup) == len(TVM_CASCADE)
    s = starts(setup)
    # the target point of every word in the cascade: the entry of the buffer block k-1
    for back, ind in zip(range(5, 0, -1), shown[-5:]):
        assert s[k - back] + ind.target_distance_m == pytest.approx(s[k - 1])
    # the buffer block: step 0 throughout
    assert np.all(permitted_speed_mps(setup, k, np.linspace(s[k - 1], s[k] - 1e-6, 30)) == 0.0)
    # 170→0 in block k-2: the service curve at the ATP's deceleration less the transmitted gradient's
    # pull, 0 at the buffer block's entry (the gradient is at or below the line's most falling one there)
    ind = shown[-2]
    assert ind.gradient_permille <= min(setup.line.gradient_at(x) for x in np.linspace(s[k - 2], s[k - 1], 50))
    a = ATP_DECEL_SHARE * setup.stock.service_decel + STANDARD_GRAVITY_MPS2 * min(ind.gradient_permille, 0.0) / 1000
    d = np.array([1e-9, 50.0, 500.0, 1499.0])
    got = permitted_speed_mps(setup, k, s[k - 1] - d)
    assert got == pytest.approx(np.minimum(170 * KMH, np.sqrt(2 * a * d)), rel=1e-9, abs=1e-6)
    assert got[0] == pytest.approx(0.0, abs=1e-3)


def test_tvm430_stop_curve_at_the_trains_own_speed():
    """Towards a stop the service curve stays 2·dV_sbi(v) under the trip curve: without a speed,
    the permitted speed is the curve a train running on it sees (a fixed point)."""
    setup = setup_for("TVM430")
    k = 20
    x = np.linspace(starts(setup)[k - 5], starts(setup)[k] - 1.0, 400)
    own = permitted_speed_mps(setup, k, x)
    assert permitted_speed_mps(setup, k, x, speed_mps=own) == pytest.approx(own, rel=1e-9)
    assert np.all(permitted_speed_mps(setup, k, x, speed_mps=0.0) >= own - 1e-12)
    v = np.array([0.0, 20.0, 30.0, 31.0, 50.0, 60.0, 80.0]) * 1.0
    assert _dv_sbi_mps(v) == pytest.approx([dv_sbi_mps(s) for s in v.tolist()], rel=1e-12)


SYSTEMS = [("ALSN", 3), ("ALSN", 4), ("ALSU", 3), ("ALSU", 4), ("ALS-EN", 3), ("FIRE_DQPSK", 3), ("TVM430", 3)]


def coder_for(setup):
    line = setup.line
    count = len(line.sections)
    system = setup.system
    if system == "TVM430":
        return Tvm430CoderCore(line, count, 1, CoderSettings(fs_hz=TVM430_FS_HZ, block_aspects=setup.block_aspects))
    settings = CoderSettings(block_aspects=setup.block_aspects)
    if system == "ALSU":
        return AlsuCoderCore(line, count, 1, settings)
    digital = cab_systems.digital_system(system)
    if digital is None:
        return WaysideCoderCore(line, count, 1, settings)
    return DigitalCoderCore(digital, line, count, 8, settings)


def sent_by(core):
    """What a coder core sends per circuit after one step: its code_tx, and a digital coder's
    commands too (ALS-EN's code_tx reads five and six free blocks alike)."""
    code_tx = core.out.code_tx.copy()
    if isinstance(core, DigitalCoderCore):
        return code_tx, [message.command for message in core.pending]
    return code_tx, code_tx.tolist()


@pytest.mark.parametrize("system, block_aspects", SYSTEMS)
def test_indications_are_what_the_coder_core_sends(system, block_aspects):
    setup = setup_for(system, block_aspects)
    line = setup.line
    block_of = np.array(line.block_of_section)
    core = coder_for(setup)
    core.step(0.0, np.zeros(len(line.sections), dtype=bool))
    _, free_line = sent_by(core)
    for k in range(len(line.block_bounds)):
        core = coder_for(setup)          # a fresh core: its first frame sends the codes of now
        core.step(0.0, block_of == k)
        code_tx, sent = sent_by(core)
        shown = indications_behind(setup, k)
        for circuit, block in enumerate(block_of.tolist()):
            if block < k:
                assert code_tx[circuit] == shown[block].code, (system, k, circuit)
                assert (sent[circuit] == free_line[circuit]) == shown[block].free_line, (system, k, circuit)
                if isinstance(core, DigitalCoderCore):
                    read = core.system.indication(sent[circuit], setup.receiver_category)
                    assert (read.free_blocks, min(read.target_kmh, read.permitted_kmh)) == \
                        (shown[block].free_blocks, pytest.approx(shown[block].v_target_mps * 3.6))


def fresh_atp(setup):
    """An ATP as the setup's, with the line's limits and restrictions lifted (the permitted speed
    of approach.py leaves them out)."""
    atp = setup.atp
    fresh = Atp(setup.line, setup.category, setup.stock.length_m, atp.mode, atp.decel, atp.latency_s,
                emergency_decel_mps2=atp.emergency_decel, brake_lead_s=atp.brake_lead_s)
    fresh.limits = [math.inf] * len(fresh.limits)
    fresh.restrictions.of_line = ()
    return fresh


def supervised_mps(setup, k, head, speed):
    """Atp.supervise's permitted speed with the head at ``head`` moving at ``speed``, under the
    indication of the track circuit holding it (block ``k`` occupied), on a fresh ATP."""
    line = setup.line
    circuit = next(c for c, sec in enumerate(line.sections) if sec.start_m <= head < sec.end_m)
    ind = indications_behind(setup, k)[line.block_of_section[circuit]]
    return fresh_atp(setup).supervise(
        0.0, head, speed, ind.aspect, True, ind.v_permitted_mps, ind.v_target_mps, ind.free_blocks, ind.code,
        ind.target_distance_m, ind.gradient_permille, line.sections[circuit].carrier_hz).permitted_mps


def restricted_heads(setup, k, per_circuit=7):
    """Head positions in every track circuit behind block k whose indication is not the free-line one."""
    line = setup.line
    shown = indications_behind(setup, k)
    heads = [np.linspace(sec.start_m, sec.end_m - 1e-3, per_circuit)
             for sec, block in zip(line.sections, line.block_of_section) if block < k and not shown[block].free_line]
    return np.concatenate(heads)


@pytest.mark.parametrize("system, block_aspects", SYSTEMS)
def test_permitted_speed_is_the_atps_own(system, block_aspects):
    """At a standstill (v = 0) Atp.supervise's permitted speed under each block's indication is
    what approach.py computes, wherever the indication is not the free-line one."""
    setup = setup_for(system, block_aspects)
    k = len(setup.line.block_bounds) - 1 if system != "TVM430" else 20
    heads = restricted_heads(setup, k)
    assert heads.size >= 7
    ours = permitted_speed_mps(setup, k, heads, speed_mps=0.0)
    theirs = [supervised_mps(setup, k, head, 0.0) for head in heads.tolist()]
    assert ours == pytest.approx(theirs, rel=1e-12, abs=1e-9)


def test_tvm430_stop_curve_under_the_trip_curve_of_a_slow_brake(tmp_path):
    """A brake acting after 30 s (and the ATP supervising at 1.1 m/s²) brings TVM-430's trip curve
    towards a stop down to the service curve: the service curve is held 2·dV_sbi(v) under it, at
    the train's own speed, as Atp.supervise holds it."""
    stock = json.loads((DATA / TVM430_STOCK).read_text())
    stock["pneumatic_brake"]["delay_s"] = 30.0
    (tmp_path / "slow.json").write_text(json.dumps(stock))
    setup = cab_setup("TVM430", 3, TVM430_LINE, str(tmp_path / "slow.json"),
                      {**cab_settings("TVM430")[3], "atp_decel": 1.1}, {"train_category": "high_speed"})
    k = 20
    heads = restricted_heads(setup, k, per_circuit=25)
    own = permitted_speed_mps(setup, k, heads)
    assert np.any(permitted_speed_mps(setup, k, heads, speed_mps=0.0) > own + 0.1)     # the hold binds
    assert own == pytest.approx([supervised_mps(setup, k, h, v) for h, v in zip(heads.tolist(), own.tolist())],
                                rel=1e-9, abs=1e-9)
    assert permitted_speed_mps(setup, k, heads, speed_mps=0.0) == pytest.approx(
        [supervised_mps(setup, k, h, 0.0) for h in heads.tolist()], rel=1e-12, abs=1e-9)


def test_bad_input_is_one_clear_line():
    with pytest.raises(UserError, match="parameter system: 'ALS_EN'"):
        cab_setup("ALS_EN")
    with pytest.raises(UserError, match="parameter cab_signal: 'ALSN'.*TVM430"):
        cab_setup("TVM430", 3, TVM430_LINE, TVM430_STOCK, {"cab_signal": "ALSN"})
    with pytest.raises(UserError, match="parameter block_aspects: 5"):
        cab_setup("ALSN", 5)
    setup = setup_for("ALSN")
    with pytest.raises(UserError, match="occupied block 8: .* has blocks 0…7"):
        indications_behind(setup, 8)
    assert sig.GREEN in {i.aspect for i in indications_behind(setup, 7)}
