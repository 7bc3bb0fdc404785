"""TVM-430's ATP and ATO (docs/ato.md#tvm-430) and the high-speed set that runs them.

The ATP/ATO cores are driven by synthetic receiver outputs: the words the block rules of the
TVM-430 design give (docs/ato.md#tvm-430: n free blocks ahead → 300/300, 300→270, 270→230,
230→170, 170→0, step 0 in the buffer section), on a short synthetic high-speed line of 1500 m
blocks whose carriers alternate 1700 / 2300 Hz. The receiver is modelled only by when a word
shows: the previous block's word for a hold after each boundary (carrier matching places it).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from fmus.ato_controller.atp import EMERGENCY_INTERVENTION, NO_INTERVENTION, SERVICE_INTERVENTION, Atp
from fmus.ato_controller.atp_tvm430 import TVM_CONTROL_MARGIN_MPS
from fmus.ato_controller.core import AtoCore, AtoSettings, MODE_ATP_EMERGENCY, MODE_ATP_SERVICE
from fmus.data.loader import load_line, load_rolling_stock, load_timetable
from fmus.signalling import aspects as sig
from fmus.traction.core import TractionCore
from fmus.units import KMH_PER_MPS, MPS_PER_KMH
from harness.closed_loop import run_closed_loop

SHIPPED = Path(__file__).resolve().parents[1] / "fmus" / "data" / "shipped"
TGV = SHIPPED / "high_speed_tgv.json"
BLOCK_M = 1500.0
BLOCKS = 30
CARRIERS_HZ = (1700.0, 2300.0)
# (step, next step) in km/h by the free blocks n ahead of a block (n ≥ 5: 300/300)
STEPS_KMH = {5: (300, 300), 4: (300, 270), 3: (270, 230), 2: (230, 170), 1: (170, 0), 0: (0, 0)}
NO_TARGET_M = 9450.0            # what a 300/300 word carries as its distance: "no target"
FALLING_PERMILLE = -8.0


def _high_speed_line(folder: Path, end_station_block: int = BLOCKS - 1,
                     falling_permille: float = FALLING_PERMILLE, limit_kmh: float = 300.0) -> Path:
    """30 blocks of 1500 m, carriers alternating, level then a −8 ‰ fall from 24 km, the line
    limit 300 km/h for high-speed trains; stations A (400 m) and Z at the entry of block
    ``end_station_block`` (the block beyond the stop point is its buffer section)."""
    blocks = [{"name": f"B{k}", "start_m": k * BLOCK_M, "end_m": (k + 1) * BLOCK_M, "signal": f"R{k}",
               "transmitter": "UM71", "carrier_hz": CARRIERS_HZ[k % 2], "ballast_ohm_km": 2.0}
              for k in range(BLOCKS)]
    line = {"name": "synthetic high-speed line", "length_m": BLOCKS * BLOCK_M,
            "electrification": {"system": "AC25000"}, "block_sections": blocks,
            "separation_zones": [{"position_m": k * BLOCK_M} for k in range(1, BLOCKS)],
            "stations": [{"name": "A", "stop_m": 400.0}, {"name": "Z", "stop_m": end_station_block * BLOCK_M}],
            "gradients": [{"start_m": 0.0, "permille": 0.0}, {"start_m": 24000.0, "permille": falling_permille}],
            "curves": [],
            "speed_limits": [{"start_m": 0.0, "passenger_kmh": 160, "freight_kmh": 100, "high_speed_kmh": limit_kmh}]}
    path = folder / "high_speed_line.json"
    path.write_text(json.dumps(line))
    return path


def _timetable(folder: Path, arrival_s: float) -> Path:
    path = folder / "high_speed_timetable.json"
    path.write_text(json.dumps({"train": "TGV", "stops": [{"station": "A", "departure_s": 10.0},
                                                          {"station": "Z", "arrival_s": arrival_s}]}))
    return path


class BlockWords:
    """The TVM-430 words of a line's blocks with block ``occupied`` taken (a standing train, or
    the virtual block beyond the line's end), as a receiver would show them: each block's word
    from the moment the head has been in it for ``hold_s`` (before that the previous block's,
    which carrier matching places), none during ``lost`` (t0, t1). Records what it showed."""

    def __init__(self, line_file: Path, occupied: int, hold_s: float = 1.0, lost=None):
        self.line = load_line(line_file)
        self.occupied, self.hold_s, self.lost = occupied, hold_s, lost
        self.block, self.previous, self.entered_s = None, None, 0.0
        self.shown = []                 # (t, x, step km/h, block of the word)

    def word(self, k: int) -> dict:
        n = self.occupied - k - 1
        step, nxt = STEPS_KMH[min(n, 5)]
        target_m = (self.occupied - 1) * BLOCK_M              # entry of the buffer section
        start = k * BLOCK_M
        falling = min(min(self.line.gradient_at(x) for x in np.arange(start, max(target_m, start + 1.0), 50.0)), 0.0)
        aspect = sig.RED_YELLOW if step == 0 else (sig.YELLOW if nxt < step else sig.GREEN)
        return dict(aspect=aspect, code_valid=True, v_permitted=step * MPS_PER_KMH, v_target=nxt * MPS_PER_KMH,
                    target_distance=NO_TARGET_M if n >= 5 else target_m - start, gradient=falling,
                    word_carrier=self.line.sections[k].carrier_hz)

    def __call__(self, t: float, x: float) -> dict:
        k = min(int(x // BLOCK_M), BLOCKS - 1)
        if k != self.block:
            self.previous = self.block
            self.block, self.entered_s = k, t
        shown = k if t - self.entered_s >= self.hold_s or self.previous is None else self.previous
        if self.lost is not None and self.lost[0] <= t < self.lost[1]:
            self.shown.append((t, x, 0.0, None))
            return dict(aspect=sig.WHITE, code_valid=False)
        word = self.word(shown)
        self.shown.append((t, x, word["v_permitted"] * KMH_PER_MPS, shown))
        return word


def _atp(line_file: Path, stock=None) -> Atp:
    stock = stock or load_rolling_stock(TGV)
    return Atp(load_line(line_file), "high_speed", stock.length_m, "TVM430", 0.7 * stock.service_decel, 2.0,
               emergency_decel_mps2=stock.emergency_decel, brake_lead_s=stock.brake_delay_s + 0.5 * stock.brake_time_constant_s)


# ---- the high-speed set ------------------------------------------------------------------------

def test_the_set_has_26_wheelsets_with_the_trailers_on_shared_bogies():
    stock = load_rolling_stock(TGV)
    offsets = stock.wheelset_offsets_m
    assert len(offsets) == 2 * 4 + 9 * 2 and stock.category == "high_speed"
    assert stock.mass_kg == pytest.approx(413.6e3)
    # the trailer rake: a Jacobs bogie every 18.7 m, joint to joint, its two axles 3.0 m apart
    trailer_bogies = offsets[4:22].reshape(9, 2).mean(axis=1)
    assert np.diff(trailer_bogies) == pytest.approx([18.7] * 8)
    assert np.diff(offsets[4:22].reshape(9, 2), axis=1).ravel() == pytest.approx([3.0] * 9)
    assert offsets[-1] < stock.length_m == pytest.approx(200.19)


def test_a_bogie_count_the_axles_do_not_divide_onto_is_refused(tmp_path):
    from fmus.errors import FmuInputError
    doc = json.loads(TGV.read_text())
    doc["units"][1]["axles"] = 16
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(FmuInputError, match=r"field units\[1\]\.axles: 16 axles do not divide onto 9 bogies"):
        load_rolling_stock(path)


def test_the_set_balances_above_300_km_h_on_the_level_and_reaches_it(tmp_path):
    line_file = _high_speed_line(tmp_path)
    stock, line = load_rolling_stock(TGV), load_line(line_file)
    core = TractionCore(stock, line, x0_m=400.0)
    speeds = np.arange(1.0, 300.0 * MPS_PER_KMH + 1e-9, 0.5)
    surplus = np.array([core.max_traction_force(v) - core.main_resistance(v) for v in speeds])
    assert np.all(surplus > 0.0)                                 # balance speed ≥ 300 km/h
    assert core.main_resistance(300 * MPS_PER_KMH) == pytest.approx(63.9e3, rel=0.01)
    for k in range(4 * 600):                                     # full traction on the level, 600 s
        out = core.step(0.25 * k, 0.25, 1.0)
        if out.v_mps >= 300 * MPS_PER_KMH:
            break
    assert out.v_mps >= 300 * MPS_PER_KMH and out.x_m < 24000.0  # reached on the level part


# ---- ATP: steps, control levels, curves --------------------------------------------------------

def test_the_trip_is_the_control_level_fifteen_above_each_step(tmp_path):
    atp_file = _high_speed_line(tmp_path)
    words = BlockWords(atp_file, occupied=BLOCKS)
    word = words.word(3)                                   # 300/300
    for step_kmh in (300, 270, 230, 170, 0):
        for v_kmh, tripped in ((step_kmh + 14.0, False), (step_kmh + 16.0, True)):
            atp = _atp(atp_file)
            result = atp.supervise(0.0, 3 * BLOCK_M + 10.0, v_kmh * MPS_PER_KMH, word["aspect"], True,
                                   step_kmh * MPS_PER_KMH, step_kmh * MPS_PER_KMH, 0,
                                   target_distance_m=NO_TARGET_M, word_carrier_hz=word["word_carrier"])
            assert (result.intervention == EMERGENCY_INTERVENTION) == tripped, (step_kmh, v_kmh)
            assert atp.trip_mps == pytest.approx((step_kmh + 15.0) * MPS_PER_KMH)


def test_a_train_above_the_trip_curve_trips_below_the_control_level(tmp_path):
    """A word announcing a stop 1000 m into the next block (its buffer section ends 2500 m
    ahead): at 295 km/h, under the control level of 315 km/h, the train is above the trip
    curve — an emergency braking after the brake's lead would not stand by the buffer's end —
    and is tripped; at 270 km/h it is not (a service intervention: above the service curve)."""
    line_file = _high_speed_line(tmp_path)
    stock = load_rolling_stock(TGV)
    lead = stock.brake_delay_s + 0.5 * stock.brake_time_constant_s
    x = 5 * BLOCK_M + 200.0
    carrier = CARRIERS_HZ[1]
    for v_kmh, expected in ((295.0, EMERGENCY_INTERVENTION), (270.0, SERVICE_INTERVENTION)):
        v = v_kmh * MPS_PER_KMH
        atp = _atp(line_file, stock)
        result = atp.supervise(0.0, x, v, sig.YELLOW, True, 300 * MPS_PER_KMH, 270 * MPS_PER_KMH, 0,
                               target_distance_m=BLOCK_M + 1000.0, word_carrier_hz=carrier)
        stands_by_m = v * lead + v * v / (2 * stock.emergency_decel)
        assert result.intervention == expected, v_kmh
        assert (stands_by_m > 7 * BLOCK_M - x) == (expected == EMERGENCY_INTERVENTION)
        assert atp.trip_mps < 300 * MPS_PER_KMH


def test_the_trip_curve_lies_above_the_service_curve_and_ends_at_the_buffer_end(tmp_path):
    """Towards a stop 4 blocks ahead, every 10 m: service curve + dV_sbi stays under the trip
    curve, and both fall to the stop; the service curve is 0 at the target point, the trip
    curve stops an emergency braking (after the brake's lead) by the buffer section's end."""
    line_file = _high_speed_line(tmp_path)
    stock = load_rolling_stock(TGV)
    words = BlockWords(line_file, occupied=10)
    target_m, buffer_end_m = 9 * BLOCK_M, 10 * BLOCK_M
    lead = stock.brake_delay_s + 0.5 * stock.brake_time_constant_s
    for k in range(5, 10):
        word = words.word(k)
        for x in np.arange(k * BLOCK_M, min((k + 1) * BLOCK_M, target_m), 10.0):
            atp = _atp(line_file, stock)
            result = atp.supervise(0.0, x, 1.0, word["aspect"], True, word["v_permitted"], word["v_target"], 0,
                                   target_distance_m=word["target_distance"], word_carrier_hz=word["word_carrier"])
            trip = atp.trip_mps
            assert result.permitted_mps + 5.5 * MPS_PER_KMH <= trip + 1e-9, x
            # an emergency braking begun on the trip curve stands before the buffer section's end
            assert trip * lead + trip ** 2 / (2 * stock.emergency_decel) <= buffer_end_m - x + 1e-6
            if x + 10.0 >= target_m:
                assert result.permitted_mps < 15.0 * MPS_PER_KMH


def test_a_falling_gradient_lowers_the_curve_at_the_same_distance(tmp_path):
    line_file = _high_speed_line(tmp_path)
    words = BlockWords(line_file, occupied=10)
    word = words.word(6)
    permitted = {}
    for gradient in (0.0, -10.0, 10.0):
        atp = _atp(line_file)
        permitted[gradient] = atp.supervise(0.0, 6 * BLOCK_M + 700.0, 1.0, word["aspect"], True, word["v_permitted"],
                                            word["v_target"], 0, target_distance_m=word["target_distance"],
                                            gradient_permille=gradient, word_carrier_hz=word["word_carrier"]).permitted_mps
    assert permitted[-10.0] < permitted[0.0] == permitted[10.0]     # uphill is not credited


def test_a_word_still_from_the_previous_block_puts_the_target_where_it_belongs(tmp_path):
    """Just past the boundary into block 6 the receiver still shows block 5's word (its carrier):
    the target is block 5's start + its distance, the same point block 6's word gives; a word on
    neither carrier (track 2's) is no word of ours: the ATP acts as on a lost word."""
    line_file = _high_speed_line(tmp_path)
    words = BlockWords(line_file, occupied=10)
    x = 6 * BLOCK_M + 20.0
    v = 250.0 * MPS_PER_KMH
    stops = {}
    for k in (5, 6):
        word = words.word(k)
        atp = _atp(line_file)
        result = atp.supervise(0.0, x, v, word["aspect"], True, word["v_permitted"], word["v_target"], 0,
                               target_distance_m=word["target_distance"], word_carrier_hz=word["word_carrier"])
        assert atp.tvm.word_block(x, word["word_carrier"]) == k
        stops[k] = [tg.position_m for tg in result.constraints.targets if tg.signal]
        assert result.intervention == NO_INTERVENTION
    assert stops[5] == stops[6] == [9 * BLOCK_M]
    # block 5's word read as if it were block 6's (no carrier matching) would move the target a block on
    assert 6 * BLOCK_M + words.word(5)["target_distance"] == 10 * BLOCK_M
    # block 5's next step (270) is now behind the head: it is the ceiling
    word = words.word(5)
    atp = _atp(line_file)
    result = atp.supervise(0.0, x, v, word["aspect"], True, word["v_permitted"], word["v_target"], 0,
                           target_distance_m=word["target_distance"], word_carrier_hz=word["word_carrier"])
    assert result.permitted_mps == pytest.approx(270.0 * MPS_PER_KMH)
    foreign = _atp(line_file)
    foreign.supervise(0.0, x - 100.0, v, sig.GREEN, True, 300 * MPS_PER_KMH, 300 * MPS_PER_KMH, 0,
                      target_distance_m=NO_TARGET_M, word_carrier_hz=CARRIERS_HZ[1])
    result = foreign.supervise(0.5, x, v, word["aspect"], True, word["v_permitted"], word["v_target"], 0,
                               target_distance_m=word["target_distance"], word_carrier_hz=2000.0)
    assert foreign.tvm.word_block(x, 2000.0) is None and result.intervention == EMERGENCY_INTERVENTION


def test_a_lost_word_at_speed_is_step_0_and_applies_the_emergency_brake(tmp_path):
    line_file = _high_speed_line(tmp_path)
    words = BlockWords(line_file, occupied=BLOCKS)
    atp = _atp(line_file)
    word = words.word(12)
    v = 298.0 * MPS_PER_KMH
    assert atp.supervise(0.0, 12 * BLOCK_M + 100.0, v, word["aspect"], True, word["v_permitted"],
                         word["v_target"], 0, target_distance_m=word["target_distance"],
                         word_carrier_hz=word["word_carrier"]).intervention == NO_INTERVENTION
    lost = atp.supervise(0.5, 12 * BLOCK_M + 141.0, v, sig.WHITE, False, 0.0, 0.0, 0)
    assert lost.intervention == EMERGENCY_INTERVENTION
    assert atp.trip_mps == pytest.approx(TVM_CONTROL_MARGIN_MPS) and lost.aspect == sig.RED_YELLOW


def test_the_ato_and_train_brake_to_a_stand_on_a_lost_word(tmp_path):
    line_file = _high_speed_line(tmp_path)
    words = BlockWords(line_file, occupied=BLOCKS, lost=(400.0, 10_000.0))
    loop = run_closed_loop(600.0, 0.5, AtoSettings(cab_signal="TVM430", strategy="flat_out"),
                           line_file=line_file, stock_file=TGV, timetable_file=_timetable(tmp_path, 1000.0),
                           cab_signal=words)
    t, v = loop.column("t"), loop.column("v")
    assert v[t == 399.5][0] > 250.0 * MPS_PER_KMH
    assert loop.column("mode")[t == 400.5][0] == MODE_ATP_EMERGENCY
    stood = t[(t > 400.0) & (v <= 1e-3)]
    assert stood.size and v[t >= stood[0]].max() <= 1e-3          # stands and stays standing
    assert loop.ato.atp.emergency_brakings == 1 and loop.ato.atp.signals_passed_at_danger == 0


# ---- ATO + traction on the steps ---------------------------------------------------------------

def _steps_shown(words: BlockWords) -> np.ndarray:
    """The step shown at each ATO step (km/h; the loop asks once per step)."""
    return np.round([step for _, _, step, _ in words.shown], 6)


def test_a_train_at_300_closing_on_an_occupied_block_slows_by_the_steps_and_stops_short(tmp_path):
    """A standing train in block 24: the follower at 300 km/h sees 300→270→230→170→0 block by
    block, slows and stands before the target point (the buffer section's entry, 23 × 1500 m),
    never above the control level of the step shown, without an ATP intervention."""
    line_file = _high_speed_line(tmp_path)
    occupied = 24
    words = BlockWords(line_file, occupied=occupied)
    loop = run_closed_loop(900.0, 0.5, AtoSettings(cab_signal="TVM430", strategy="flat_out"),
                           line_file=line_file, stock_file=TGV, timetable_file=_timetable(tmp_path, 1000.0),
                           cab_signal=words)
    x, v, mode = loop.column("x"), loop.column("v"), loop.column("mode")
    target_m = (occupied - 1) * BLOCK_M
    steps = _steps_shown(words)
    assert v.max() >= 295.0 * MPS_PER_KMH                          # it ran at 300 first
    assert np.all(v <= steps * MPS_PER_KMH + TVM_CONTROL_MARGIN_MPS)
    # the steps seen on the way in, in order
    seen = [s for k, s in enumerate(steps) if k == 0 or s != steps[k - 1]]
    assert seen == [300, 270, 230, 170]                    # it stood before the buffer section (step 0)
    assert x[-1] < target_m and x[-1] > target_m - 100.0 and v[-1] == 0.0
    assert not np.any(np.isin(mode, (MODE_ATP_SERVICE, MODE_ATP_EMERGENCY)))
    assert loop.ato.atp.signals_passed_at_danger == 0 and loop.ato.atp.emergency_brakings == 0
    # at each block entry the train is no faster than the step it enters with
    for k in range(occupied - 5, occupied - 1):
        entering = v[np.searchsorted(x, k * BLOCK_M)]
        assert entering <= STEPS_KMH[occupied - k - 1][0] * MPS_PER_KMH + 1e-6, k


def test_closing_down_a_25_permille_fall_the_ato_keeps_under_the_atp_curves(tmp_path):
    """The same approach at 230 km/h down a 25 ‰ fall: the ATP's curves lose g·25/1000 = 0.25
    m/s² of their 0.7 m/s² to the transmitted gradient; the ATO's planned curve (0.6 m/s²) gives
    up as much, so it brakes early enough and the ATP never intervenes (a curve planned for level
    track crosses the ATP's and the service brake is applied again and again). At 300 km/h no
    ATO could: 4 blocks from the target the ATP's curve on such a fall is already below it."""
    line_file = _high_speed_line(tmp_path, falling_permille=-25.0, limit_kmh=230.0)
    occupied = 24
    words = BlockWords(line_file, occupied=occupied)
    loop = run_closed_loop(900.0, 0.5, AtoSettings(cab_signal="TVM430", strategy="flat_out"),
                           line_file=line_file, stock_file=TGV, timetable_file=_timetable(tmp_path, 1000.0),
                           cab_signal=words)
    x, v, mode = loop.column("x"), loop.column("v"), loop.column("mode")
    assert x[-1] < (occupied - 1) * BLOCK_M and v[-1] == 0.0
    assert not np.any(np.isin(mode, (MODE_ATP_SERVICE, MODE_ATP_EMERGENCY)))


def test_when_the_block_ahead_clears_the_standing_train_moves_on_to_the_end_station(tmp_path):
    line_file = _high_speed_line(tmp_path)
    words = BlockWords(line_file, occupied=24)

    def leader_leaves(t, ato):
        if t >= 700.0:
            words.occupied = BLOCKS

    loop = run_closed_loop(1300.0, 0.5, AtoSettings(cab_signal="TVM430", strategy="flat_out"),
                           line_file=line_file, stock_file=TGV, timetable_file=_timetable(tmp_path, 1000.0),
                           cab_signal=words, before_step=leader_leaves)
    t, x, v = loop.column("t"), loop.column("x"), loop.column("v")
    assert v[t == 699.5][0] == 0.0 and x[t == 699.5][0] < 23 * BLOCK_M          # stood before the target
    assert [a["station"] for a in loop.ato.arrivals] == ["Z"]
    assert abs(loop.ato.arrivals[0]["stop_error_m"]) < 1.0
    assert loop.ato.atp.interventions == 0 and loop.ato.atp.signals_passed_at_danger == 0


def test_a_train_too_fast_for_the_steps_is_tripped_before_the_target(tmp_path):
    """An ATO that does not brake for the steps (a driver ignoring them): the ATP's service
    intervention, then if need be its trip, stop the train before the buffer section's end."""
    line_file = _high_speed_line(tmp_path)
    occupied = 24
    words = BlockWords(line_file, occupied=occupied)
    settings = AtoSettings(cab_signal="TVM430", strategy="flat_out")
    loop = run_closed_loop(900.0, 0.5, settings, line_file=line_file, stock_file=TGV,
                           timetable_file=_timetable(tmp_path, 1000.0), cab_signal=words,
                           before_step=lambda t, ato: setattr(ato, "_brake_for_targets", lambda *a: None))
    x, v, mode = loop.column("x"), loop.column("v"), loop.column("mode")
    assert np.any(np.isin(mode, (MODE_ATP_SERVICE, MODE_ATP_EMERGENCY)))
    assert x[-1] < occupied * BLOCK_M and v[-1] == 0.0


def test_the_train_runs_the_line_at_300_and_stops_at_the_end_station_within_the_band(tmp_path):
    line_file = _high_speed_line(tmp_path)
    words = BlockWords(line_file, occupied=BLOCKS)           # the station Z: entry of the last block
    settings = AtoSettings(cab_signal="TVM430", strategy="flat_out")
    loop = run_closed_loop(900.0, 0.5, settings, line_file=line_file, stock_file=TGV,
                           timetable_file=_timetable(tmp_path, 800.0), cab_signal=words)
    x, v, mode = loop.column("x"), loop.column("v"), loop.column("mode")
    cruising = v[(x > 16000.0) & (x < 24000.0)]
    assert cruising.min() >= 290.0 * MPS_PER_KMH and cruising.max() <= 300.0 * MPS_PER_KMH
    assert len(loop.ato.arrivals) == 1
    arrival = loop.ato.arrivals[0]
    assert arrival["station"] == "Z" and abs(arrival["stop_error_m"]) <= settings.stop_window_m
    assert abs(arrival["stop_error_m"]) < 1.0
    assert loop.ato.atp.signals_passed_at_danger == 0 and loop.ato.atp.interventions == 0
    assert not np.any(np.isin(mode, (MODE_ATP_SERVICE, MODE_ATP_EMERGENCY)))


def test_an_impossible_tvm_input_applies_the_emergency_brake(tmp_path):
    line_file = _high_speed_line(tmp_path)
    stock, line = load_rolling_stock(TGV), load_line(line_file)
    timetable_file = _timetable(tmp_path, 1000.0)
    ato = AtoCore(line, stock, load_timetable(timetable_file, line), timetable_file, "high_speed",
                  AtoSettings(cab_signal="TVM430"))
    out = ato.step(0.0, 0.5, 400.0, 0.0, sig.GREEN, True, 300 * MPS_PER_KMH, 300 * MPS_PER_KMH, 0,
                   target_distance=math.nan, word_carrier=1700.0)
    assert out.emergency_brake and ato.fault[0] == "target_distance"


def test_a_standing_train_departs_only_on_a_valid_word_with_a_step_above_0(tmp_path):
    line_file = _high_speed_line(tmp_path)
    stock, line = load_rolling_stock(TGV), load_line(line_file)
    timetable_file = _timetable(tmp_path, 1000.0)
    words = BlockWords(line_file, occupied=1)                 # block 0 is a buffer section: step 0
    for occupied, departs in ((1, False), (BLOCKS, True)):
        words.occupied = occupied
        ato = AtoCore(line, stock, load_timetable(timetable_file, line), timetable_file, "high_speed",
                      AtoSettings(cab_signal="TVM430"))
        for k in range(60):
            out = ato.step(0.5 * k, 0.5, 400.0, 0.0, **words.word(0))
        assert (out.command > 0.0) == departs, occupied


@pytest.mark.parametrize("carrier_hz, departs", [(50.0, True), (75.0, False)])
def test_the_fmu_reads_the_word_on_its_new_inputs(tmp_path, product_fmus, carrier_hz, departs):
    """ato_only with cab_signal = TVM430 and the receiver's word set by scenario events: a 160 km/h
    step on the default line's 50 Hz carrier lets the train depart at 60 s, and the word's loss at
    120 s trips it; a word on a carrier of no block (75 Hz) is no word: the train never departs."""
    from helpers import railcosim

    word = {"code_valid": True, "aspect": sig.GREEN, "v_permitted": 160 * MPS_PER_KMH,
            "v_target": 160 * MPS_PER_KMH, "target_distance": NO_TARGET_M, "gradient": -2.0,
            "word_carrier": carrier_hz}
    events = [{"time": 0.0, "model": "ato", "variable": name, "action": "set", "value": value}
              for name, value in word.items()]
    events.append({"time": 120.0, "model": "ato", "variable": "code_valid", "action": "set", "value": False})
    scenario = tmp_path / "words.json"
    scenario.write_text(json.dumps({"events": events}))
    out = tmp_path / "run"
    code, _, stderr = railcosim("run", "ato_only", "--output", out, "--no-build", "--stop-time", "180",
                                "--scenario", scenario, "--set", "ato.cab_signal=TVM430")
    assert code == 0, stderr
    (train,) = json.loads((out / "summary.json").read_text())["trains"]
    assert train["emergency_brakings"] == (1 if departs else 0)
    assert (train["departure_hold_s"] > 100.0) == (not departs)
