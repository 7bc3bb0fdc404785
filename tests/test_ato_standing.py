"""A train standing before a stop target (a signal at danger) holds its brake until the target
moves, then departs: ATO + traction cores in closed loop (no FMI), an hour of standing."""
import numpy as np

from harness.closed_loop import red_signal_ahead, run_closed_loop
from fmus.ato_controller.core import MODE_TRACTION, AtoCore, AtoSettings
from fmus.data.loader import DEFAULT_LINE, DEFAULT_ROLLING_STOCK, DEFAULT_TIMETABLE, load_line, load_rolling_stock, load_timetable
from fmus.signalling import aspects as sig
from fmus.traction.core import TractionCore
from fmus.units import MPS_PER_KMH

RED_SIGNAL_M = 15200.0        # signal 9 of the default line
HOUR_S = 3600.0


def _standing(x, v):
    """Indices from the first standstill in the section before the red signal onwards."""
    first = np.nonzero((x > RED_SIGNAL_M - 2400.0) & (x < RED_SIGNAL_M) & (v <= 1e-3))[0][0]
    return first


def test_alsn_standing_an_hour_before_a_red_signal_holds_the_brake_then_departs():
    clear_s = 900.0 + HOUR_S + 100.0
    result = run_closed_loop(clear_s + 600.0, cab_signal=red_signal_ahead(load_line(), RED_SIGNAL_M, clear_s))
    t, x, v, command = (result.column(n) for n in ("t", "x", "v", "command"))
    first = _standing(x, v)
    held = (t >= t[first]) & (t < clear_s)
    assert t[held][-1] - t[held][0] >= HOUR_S
    # no traction at all while the signal stays at danger, and the train does not creep
    assert np.all(command[held] < 0.0)
    assert np.ptp(x[held]) < 0.01
    assert RED_SIGNAL_M - x[first] >= 25.0
    atp = result.ato.atp
    assert atp.signals_passed_at_danger == 0 and atp.interventions == 0
    # the target moves (the signal clears): the train departs at once and reaches C
    after = t >= clear_s
    starts = np.nonzero(after & (result.column("mode") == MODE_TRACTION))[0]
    assert starts.size and t[starts[0]] - clear_s <= 1.0
    assert [a["station"] for a in result.ato.arrivals] == ["B", "C"]


def _digital_loop(stop_time_s: float, clear_s: float, step_s: float = 0.5):
    """The same with a digital cab signal: in the section before the signal the code says no
    free block ahead (a stop at its exit), one free block in the section before that (60 km/h at
    its exit), everywhere else six free blocks at 160 km/h."""
    line = load_line(DEFAULT_LINE)
    stock = load_rolling_stock(DEFAULT_ROLLING_STOCK)
    timetable = load_timetable(DEFAULT_TIMETABLE, line)
    ato = AtoCore(line, stock, timetable, DEFAULT_TIMETABLE, stock.category, AtoSettings(cab_signal="digital"))
    train = TractionCore(stock, line, x0_m=timetable[0].stop_m)
    k = [s.end_m for s in line.sections].index(RED_SIGNAL_M)
    closed = (line.sections[k].start_m, RED_SIGNAL_M)
    warned = (line.sections[k - 1].start_m, closed[0])
    rows = []
    state = train.out
    for n in range(int(round(stop_time_s / step_s))):
        t = n * step_s
        if t < clear_s and closed[0] <= state.x_m < closed[1]:
            code = (sig.RED_YELLOW, True, 60.0 * MPS_PER_KMH, 0.0, 0)
        elif t < clear_s and warned[0] <= state.x_m < warned[1]:
            code = (sig.YELLOW, True, 160.0 * MPS_PER_KMH, 60.0 * MPS_PER_KMH, 1)
        else:
            code = (sig.GREEN, True, 160.0 * MPS_PER_KMH, 160.0 * MPS_PER_KMH, 6)
        out = ato.step(t, step_s, state.x_m, state.v_mps, *code)
        rows.append((t, state.x_m, state.v_mps, out.command))
        state = train.step(t, step_s, out.command, out.emergency_brake)
    return ato, np.array(rows)


def test_digital_standing_an_hour_before_a_stop_holds_the_brake_then_departs():
    clear_s = 900.0 + HOUR_S + 100.0
    ato, rows = _digital_loop(clear_s + 120.0, clear_s)
    t, x, v, command = rows.T
    first = _standing(x, v)
    held = (t >= t[first]) & (t < clear_s)
    assert t[held][-1] - t[held][0] >= HOUR_S
    assert np.all(command[held] < 0.0)
    assert np.ptp(x[held]) < 0.01
    assert ato.atp.signals_passed_at_danger == 0 and ato.atp.interventions == 0
    assert x[-1] > RED_SIGNAL_M + 100.0        # departed once the code cleared
