"""TVM-300's ATP and ATO (docs/ato.md#tvm-300) on the shipped TVM-300 line.

The ATP/ATO cores are driven by synthetic receiver outputs: the cascade of the TVM-300 design
behind an occupied block (docs/ato.md#tvm-300: n free blocks ahead of a block → n ≥ 6 300/300,
5 → 300→270, 4 → 270→220, 3 → 220→160, 2 → 160→80, 1 → 80→0, a stop at the block's exit, and
0 → 0/0, the buffer section) on fmus/data/shipped/hsl_tvm300_line.json (21 blocks of 2000 m,
carriers alternating 1700 / 2300 Hz). The receiver is modelled only by when a code shows: the
previous block's code for a hold after each boundary (carrier matching places it), the TVM-430
receiver's stated latency standing in for TVM-300's.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from fmus.ato_controller.atp import EMERGENCY_INTERVENTION, NO_INTERVENTION, Atp
from fmus.ato_controller.atp_tvm430 import TVM_CONTROL_MARGIN_MPS
from fmus.ato_controller.core import (ATP_DECEL_SHARE, MODE_ATP_EMERGENCY, MODE_ATP_SERVICE, AtoCore, AtoSettings,
                                      judged_measurements)
from fmus.data.loader import load_line, load_rolling_stock, load_timetable
from fmus.loco_receiver.tvm430 import STATED_LATENCY_S
from fmus.signalling import aspects as sig
from fmus.signalling import tvm300
from fmus.signalling.cab_systems import AtoMode
from fmus.traction.brake_pipeline import brake_lead_s
from fmus.units import KMH_PER_MPS, MPS_PER_KMH
from harness.closed_loop import run_closed_loop

SHIPPED = Path(__file__).resolve().parents[1] / "fmus" / "data" / "shipped"
TGV = SHIPPED / "high_speed_tgv.json"
LINE = SHIPPED / "hsl_tvm300_line.json"
BLOCK_M = 2000.0
# (step, next step) in km/h by the free blocks n ahead of a block (n ≥ 6: 300/300)
CASCADE_KMH = {6: (300, 300), 5: (300, 270), 4: (270, 220), 3: (220, 160), 2: (160, 80), 1: (80, 0), 0: (0, 0)}
# the occupied block of the closing-up runs (0-based): the buffer section 34-36 km, the stop at 34 km
OCCUPIED = 18


class CascadeCodes:
    """The TVM-300 codes of the line's blocks with block ``occupied`` taken, as a receiver
    would show them: each block's code from the moment the head has been in it for ``hold_s``
    (before that the previous block's, which carrier matching places), none during ``lost``
    (t0, t1). Records what it showed."""

    def __init__(self, occupied: int, hold_s: float = STATED_LATENCY_S, lost=None):
        self.line = load_line(LINE)
        self.occupied, self.hold_s, self.lost = occupied, hold_s, lost
        self.block, self.previous, self.entered_s = None, None, 0.0
        self.shown = []                 # (t, x, step km/h, block of the code)

    def steps_kmh(self, k: int):
        return CASCADE_KMH[min(max(self.occupied - k - 1, 0), 6)]

    def code(self, k: int) -> dict:
        step, nxt = self.steps_kmh(k)
        aspect = sig.RED_YELLOW if step == 0 else (sig.YELLOW if nxt < step else sig.GREEN)
        return dict(aspect=aspect, code_valid=True, v_permitted=step * MPS_PER_KMH, v_target=nxt * MPS_PER_KMH,
                    word_carrier=self.line.sections[k].carrier_hz)

    def __call__(self, t: float, x: float) -> dict:
        k = min(int(x // BLOCK_M), len(self.line.sections) - 1)
        if k != self.block:
            self.previous = self.block
            self.block, self.entered_s = k, t
        shown = k if t - self.entered_s >= self.hold_s or self.previous is None else self.previous
        if self.lost is not None and self.lost[0] <= t < self.lost[1]:
            self.shown.append((t, x, 0.0, None))
            return dict(aspect=sig.WHITE, code_valid=False)
        code = self.code(shown)
        self.shown.append((t, x, code["v_permitted"] * KMH_PER_MPS, shown))
        return code


def _timetable(folder: Path, arrival_s: float, station: str = "Terminus") -> Path:
    path = folder / "tvm300_timetable.json"
    path.write_text(json.dumps({"train": "TGV", "stops": [{"station": "Origine", "departure_s": 10.0},
                                                          {"station": station, "arrival_s": arrival_s}]}))
    return path


def _atp(stock=None) -> Atp:
    stock = stock or load_rolling_stock(TGV)
    return Atp(load_line(LINE), "high_speed", stock.length_m, AtoMode.TVM300, ATP_DECEL_SHARE * stock.service_decel,
               STATED_LATENCY_S, emergency_decel_mps2=stock.emergency_decel, brake_lead_s=brake_lead_s(stock))


def _supervise(atp: Atp, t: float, x: float, v_kmh: float, code: dict):
    return atp.supervise(t, x, v_kmh * MPS_PER_KMH, code.get("aspect", sig.WHITE), code.get("code_valid", False),
                         code.get("v_permitted", 0.0), code.get("v_target", 0.0), 0,
                         word_carrier_hz=code.get("word_carrier", 0.0))


def _closing_up(tmp_path, **codes_kwargs):
    codes = CascadeCodes(OCCUPIED, **codes_kwargs)
    loop = run_closed_loop(900.0, 0.5, AtoSettings(cab_signal=AtoMode.TVM300, strategy="flat_out"),
                           line_file=LINE, stock_file=TGV, timetable_file=_timetable(tmp_path, 1000.0),
                           cab_signal=codes)
    return codes, loop


# ---- the ATP: steps, control levels, the step function -------------------------------------------

def test_the_trip_is_the_step_plus_15_until_the_exit_and_the_next_step_plus_15_after_it():
    codes = CascadeCodes(OCCUPIED)
    for k in range(OCCUPIED - 6, OCCUPIED):
        code = codes.code(k)
        step, nxt = codes.steps_kmh(k)
        inside = k * BLOCK_M + 1500.0
        for v_kmh, tripped in ((step + 14.0, False), (step + 16.0, True)):
            atp = _atp()
            result = _supervise(atp, 0.0, inside, v_kmh, code)
            assert (result.intervention == EMERGENCY_INTERVENTION) == tripped, (k, v_kmh)
            assert atp.trip_mps == pytest.approx((step + 15.0) * MPS_PER_KMH)
        if nxt == 0:
            continue          # past a stop's exit is a signal passed at danger (below)
        atp = _atp()
        _supervise(atp, 0.0, (k + 1) * BLOCK_M - 30.0, nxt, code)
        past = _supervise(atp, 0.5, (k + 1) * BLOCK_M + 10.0, nxt + 14.0, code)   # the old code still shown
        assert atp.trip_mps == pytest.approx((nxt + 15.0) * MPS_PER_KMH) and past.intervention != EMERGENCY_INTERVENTION
        assert _supervise(atp, 1.0, (k + 1) * BLOCK_M + 20.0, nxt + 16.0, code).intervention == EMERGENCY_INTERVENTION


def test_no_trip_curve_ahead_of_the_exit_only_the_service_curve_to_the_next_step():
    """In the 270→220 block, 100 m before its exit, at 265 km/h: far above the service curve to
    220 km/h (so the service brake is commanded), under the control level 285 km/h (no trip)."""
    codes = CascadeCodes(OCCUPIED)
    k = OCCUPIED - 5
    atp = _atp()
    result = _supervise(atp, 0.0, (k + 1) * BLOCK_M - 100.0, 265.0, codes.code(k))
    expected = math.sqrt((220 * MPS_PER_KMH) ** 2 + 2.0 * atp.decel * 100.0)
    assert result.permitted_mps == pytest.approx(expected)
    assert result.intervention != EMERGENCY_INTERVENTION and atp.trip_mps == pytest.approx(285 * MPS_PER_KMH)


def test_a_code_lost_at_speed_is_step_0_and_trips_at_once():
    codes = CascadeCodes(OCCUPIED + 3)
    atp = _atp()
    x = 10 * BLOCK_M + 100.0
    assert _supervise(atp, 0.0, x, 298.0, codes.code(10)).intervention == NO_INTERVENTION
    lost = _supervise(atp, 0.5, x + 41.0, 298.0, dict(aspect=sig.WHITE, code_valid=False))
    assert lost.intervention == EMERGENCY_INTERVENTION and lost.aspect == sig.RED_YELLOW
    assert atp.trip_mps == pytest.approx(TVM_CONTROL_MARGIN_MPS)
    # a code on a carrier of no block of ours (track 2's) is no code either
    foreign = _atp()
    _supervise(foreign, 0.0, x, 298.0, codes.code(10))
    assert _supervise(foreign, 0.5, x + 41.0, 298.0, {**codes.code(10), "word_carrier": 2000.0}).intervention \
        == EMERGENCY_INTERVENTION


def test_passing_the_buffer_entry_under_80_0_or_the_buffer_exit_under_0_0_is_a_spad():
    codes = CascadeCodes(OCCUPIED)
    for k in (OCCUPIED - 2, OCCUPIED - 1):          # the (80, 0) block, the buffer section (0, 0)
        atp = _atp()
        exit_m = (k + 1) * BLOCK_M
        _supervise(atp, 0.0, exit_m - 20.0, 10.0, codes.code(k))
        assert atp.signals_passed_at_danger == 0
        passed = _supervise(atp, 0.5, exit_m + 1.0, 10.0, codes.code(k))
        assert atp.signals_passed_at_danger == 1 and passed.intervention == EMERGENCY_INTERVENTION, k
    # the same exit under (160, 80) is no signal at danger
    atp = _atp()
    k = OCCUPIED - 3
    _supervise(atp, 0.0, (k + 1) * BLOCK_M - 20.0, 75.0, codes.code(k))
    _supervise(atp, 0.5, (k + 1) * BLOCK_M + 1.0, 75.0, codes.code(k))
    assert atp.signals_passed_at_danger == 0 and atp.emergency_brakings == 0


def test_the_ato_reads_the_code_and_the_carrier_and_an_impossible_one_fails_safe(tmp_path):
    assert judged_measurements(AtoMode.TVM300) == ("x", "v", "aspect", "v_permitted", "v_target", "word_carrier")
    stock, line = load_rolling_stock(TGV), load_line(LINE)
    timetable_file = _timetable(tmp_path, 1000.0)
    ato = AtoCore(line, stock, load_timetable(timetable_file, line), timetable_file, "high_speed",
                  AtoSettings(cab_signal=AtoMode.TVM300))
    out = ato.step(0.0, 0.5, 400.0, 0.0, sig.GREEN, True, 300 * MPS_PER_KMH, 300 * MPS_PER_KMH, 0,
                   word_carrier=math.nan)
    assert out.emergency_brake and ato.fault[0] == "word_carrier"


def test_a_standing_train_departs_only_on_a_valid_permissive_code(tmp_path):
    stock, line = load_rolling_stock(TGV), load_line(LINE)
    timetable_file = _timetable(tmp_path, 1000.0)
    codes = CascadeCodes(OCCUPIED)
    cases = ((codes.code(OCCUPIED - 1), False),                        # (0, 0): the buffer section
             ({**codes.code(0), "code_valid": False, "aspect": sig.WHITE}, False),
             ({**codes.code(0), "word_carrier": 2300.0}, False),        # the next block's carrier: not ours
             ({**codes.code(0), "v_permitted": 80 * MPS_PER_KMH, "v_target": 0.0, "aspect": sig.YELLOW}, True),
             (codes.code(0), True))
    for code, departs in cases:
        ato = AtoCore(line, stock, load_timetable(timetable_file, line), timetable_file, "high_speed",
                      AtoSettings(cab_signal=AtoMode.TVM300))
        for k in range(60):
            out = ato.step(0.5 * k, 0.5, 400.0, 0.0, **{"aspect": sig.WHITE, "code_valid": False, **code})
        assert (ato.phase == "running") == departs, code
        assert (out.departure_hold_s > 0.0) == (not departs)


# ---- the ATO and the train under the cascade ------------------------------------------------

def test_a_train_at_300_follows_the_cascade_block_by_block_and_stops_before_the_buffer(tmp_path):
    """A standing train in block 19 (36-38 km): the follower at speed sees 300→270, 270→220,
    220→160, 160→80, 80→0 block by block, each code only the receiver's latency after the block's
    entry, is at most the next step at each exit, stands before the buffer section's entry
    (34 km), never tripped, no service intervention, no signal passed at danger."""
    codes, loop = _closing_up(tmp_path)
    x, v, mode = loop.column("x"), loop.column("v"), loop.column("mode")
    stop_m = (OCCUPIED - 1) * BLOCK_M
    assert v[x < (OCCUPIED - 6) * BLOCK_M].max() >= 290.0 * MPS_PER_KMH       # it ran at 300 first
    steps = np.round([s for _, _, s, _ in codes.shown], 6)
    assert [s for k, s in enumerate(steps) if k == 0 or s != steps[k - 1]] == [300, 270, 220, 160, 80]
    for k in range(OCCUPIED - 6, OCCUPIED - 2):
        step, nxt = codes.steps_kmh(k)
        at_exit = v[np.searchsorted(x, (k + 1) * BLOCK_M)]
        assert at_exit <= nxt * MPS_PER_KMH, (k, at_exit * KMH_PER_MPS)
    assert stop_m - 100.0 < x[-1] < stop_m and v[-1] == 0.0
    assert not np.any(np.isin(mode, (MODE_ATP_SERVICE, MODE_ATP_EMERGENCY)))
    atp = loop.ato.atp
    assert atp.emergency_brakings == 0 and atp.signals_passed_at_danger == 0 and atp.interventions == 0


def test_an_ato_that_ignores_the_steps_is_tripped_and_stands_before_the_occupied_block(tmp_path):
    codes = CascadeCodes(OCCUPIED)
    loop = run_closed_loop(900.0, 0.5, AtoSettings(cab_signal=AtoMode.TVM300, strategy="flat_out"),
                           line_file=LINE, stock_file=TGV, timetable_file=_timetable(tmp_path, 1000.0),
                           cab_signal=codes,
                           before_step=lambda t, ato: setattr(ato, "_brake_for_targets", lambda *a: None))
    x, v, mode = loop.column("x"), loop.column("v"), loop.column("mode")
    assert np.any(np.isin(mode, (MODE_ATP_SERVICE, MODE_ATP_EMERGENCY)))
    assert x[-1] < OCCUPIED * BLOCK_M and v[-1] == 0.0


def test_a_code_lost_at_speed_brakes_the_train_to_a_stand(tmp_path):
    codes, loop = _closing_up(tmp_path, lost=(300.0, 10_000.0))
    t, v = loop.column("t"), loop.column("v")
    assert v[t == 299.5][0] > 270.0 * MPS_PER_KMH
    assert loop.column("mode")[t == 300.5][0] == MODE_ATP_EMERGENCY
    stood = t[(t > 300.0) & (v <= 1e-3)]
    assert stood.size and v[t >= stood[0]].max() <= 1e-3
    assert loop.ato.atp.emergency_brakings == 1 and loop.ato.atp.signals_passed_at_danger == 0


# ---- the planner foresees the cascade to the terminus ------------------------------------------

class FreeLineCodes(CascadeCodes):
    """The codes the block rules send with the whole line free (tvm300.BlockCoding): the
    cascade before the line's last station stop, shown as CascadeCodes shows its own."""

    def __init__(self, hold_s: float = STATED_LATENCY_S):
        super().__init__(0, hold_s)
        coding = tvm300.system().block_coding(self.line)
        circuits = len(self.line.sections)
        free = coding.codes_of(np.full(circuits, coding.open_blocks), np.ones(circuits, dtype=bool))
        readings = [coding.tvm.reading(int(code)) for code in free]
        self.pairs_kmh = [(r.step_kmh, r.next_kmh) for r in readings]

    def steps_kmh(self, k: int):
        return self.pairs_kmh[k]


def _programme_run(tmp_path, arrival_s: float):
    codes = FreeLineCodes()
    loop = run_closed_loop(arrival_s + 60.0, 0.5, AtoSettings(cab_signal=AtoMode.TVM300),
                           line_file=LINE, stock_file=TGV, timetable_file=_timetable(tmp_path, arrival_s),
                           cab_signal=codes)
    return codes, loop


def test_the_planned_profile_keeps_the_free_line_steps_to_the_terminus(tmp_path):
    """The planner plans the cascade the block rules send before the terminus on a free line
    (300→270 from 32 km … 80→0 from 40 km): every planned programme is at most each block's
    step inside it and its next step at its exit; the minimum running time is longer than on
    the line's limits alone (TVM-430's mode plans those)."""
    codes, timetable = FreeLineCodes(), _timetable(tmp_path, 1000.0)
    line, stock = codes.line, load_rolling_stock(TGV)
    plans = {mode: AtoCore(line, stock, load_timetable(timetable, line), timetable, "high_speed",
                           AtoSettings(cab_signal=mode)).plans[0] for mode in (AtoMode.TVM300, AtoMode.TVM430)}
    plan = plans[AtoMode.TVM300]
    assert [pair for pair in codes.pairs_kmh[16:21]] == [(300, 270), (270, 220), (220, 160), (160, 80), (80, 0)]
    for k, section in enumerate(line.sections):
        step, nxt = (v * MPS_PER_KMH for v in codes.pairs_kmh[k])
        inside = (plan.s >= section.start_m) & (plan.s < section.end_m)
        assert np.all(plan.family.v[:, inside] <= step + 1e-9), k
        if section.start_m < plan.end_m < section.end_m:
            continue                     # the stop point lies inside the block: it ends there
        at_exit = [np.interp(section.end_m, plan.s, v) for v in plan.family.v]
        assert max(at_exit) <= nxt, (k, max(at_exit) * KMH_PER_MPS)
    assert plan.minimum_time_s > plans[AtoMode.TVM430].minimum_time_s + 20.0


@pytest.mark.parametrize("slack_s, earliest_s", [(1.5, -3.0), (60.0, -AtoSettings().early_threshold_s)])
def test_the_ato_alone_on_a_free_line_is_not_late_under_the_cascade(tmp_path, slack_s, earliest_s):
    """Closed loop, the ATO under the free line's codes (``programme``), timetables of the
    minimum running time plus 1.5 s and plus 60 s: it arrives less than 2 s late (planned on
    the line's limits alone: 27 s and 21 s late), no ATP
    intervention. With 60 s the programme's MARECO coasting before the cascade, planned as held
    at its end speed on the falling gradient, runs faster in the loop: early, by less than the
    ATO's early threshold, from which it holds the programme speed (docs/ato.md#tvm-300)."""
    codes, timetable = FreeLineCodes(), _timetable(tmp_path, 1000.0)
    line, stock = codes.line, load_rolling_stock(TGV)
    minimum_s = AtoCore(line, stock, load_timetable(timetable, line), timetable, "high_speed",
                        AtoSettings(cab_signal=AtoMode.TVM300)).plans[0].minimum_time_s
    due_s = 10.0 + minimum_s + slack_s
    codes, loop = _programme_run(tmp_path, due_s)
    arrival = loop.ato.arrivals[0]
    assert earliest_s <= arrival["arrival_deviation_s"] < 2.0, arrival
    assert loop.ato.atp.interventions == 0 and loop.ato.atp.signals_passed_at_danger == 0
