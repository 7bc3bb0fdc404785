"""Traction against the sources: effort at a catenary voltage other than nominal, the
locomotive's idle resistance when coasting (the ATO book's coasting example), and the line
file's carrier checked against the traction system (docs/traction.md)."""
import json

import numpy as np
import pytest

from fmus.data.loader import DATA, DEFAULT_LINE, load_line, load_rolling_stock
from fmus.errors import FmuInputError
from fmus.traction.core import EffortCurve, TractionCore
from helpers import ComponentSpec, railcosim, write_ssd

KMH = 1 / 3.6
STOCKS = ["passenger_chs7.json", "freight_vl80.json", "emu_er2.json"]


def _line(tmp_path, template=DEFAULT_LINE, name="line", **changes):
    doc = json.loads(template.read_text())
    doc.update(changes)
    path = tmp_path / f"{name}.json"
    path.write_text(json.dumps(doc, ensure_ascii=False))
    return path


def _flat(tmp_path, grade=0.0, ac=False):
    template = DATA / "default_line_ac.json" if ac else DEFAULT_LINE
    return load_line(_line(tmp_path, template, f"grade{grade}", gradients=[{"start_m": 0, "permille": grade}],
                           curves=[]))


# ---- effort and catenary voltage ---------------------------------------------------------------
@pytest.mark.parametrize("stock_file", STOCKS)
def test_at_the_rated_voltage_the_effort_is_the_table(stock_file):
    stock = load_rolling_stock(DATA / stock_file)
    speeds = np.linspace(0.0, stock.effort_speeds[-1] * 1.1, 400)
    for ratio in (1.0, 1.0 + 1e-9):                # the scaled path at U → U_n meets the table
        curve = EffortCurve(stock.effort_speeds, stock.effort_forces, ratio)
        assert np.allclose([curve(v) for v in speeds], np.interp(speeds, stock.effort_speeds, stock.effort_forces),
                           rtol=0, atol=1e-3)     # N


@pytest.mark.parametrize("stock_file, natural_kmh, limit_kmh", [
    ("passenger_chs7.json", (80, 100, 140), (10, 40, 60)),     # 6160 kW from 70 km/h
    ("freight_vl80.json", (70, 80, 90), (10, 30, 50)),         # 6520 kW from 60 km/h (AC)
])
@pytest.mark.parametrize("ratio", [0.95, 1.05])
def test_the_natural_characteristic_scales_with_voltage_and_the_start_limit_does_not(stock_file, natural_kmh,
                                                                                      limit_kmh, ratio):
    """Series motors: at a given current (effort) the speed is proportional to the voltage, so on
    the constant-power part the power is proportional to it; the start (current, adhesion)
    limit is the same at every voltage."""
    stock = load_rolling_stock(DATA / stock_file)
    curve = EffortCurve(stock.effort_speeds, stock.effort_forces, ratio)
    for v in np.array(natural_kmh) * KMH:
        nominal = np.interp(v, stock.effort_speeds, stock.effort_forces)
        assert curve(v) == pytest.approx(ratio * nominal, rel=0.01)
        assert curve(v) == pytest.approx(np.interp(v / ratio, stock.effort_speeds, stock.effort_forces), rel=1e-9)
    for v in np.array(limit_kmh) * KMH:
        assert curve(v) == np.interp(v, stock.effort_speeds, stock.effort_forces)


def test_a_table_without_a_constant_power_end_does_not_depend_on_voltage():
    speeds, forces = [0.0, 10.0, 30.0], [300e3, 250e3, 200e3]
    curve = EffortCurve(speeds, forces, 0.9)
    assert [curve(v) for v in (0.0, 5.0, 20.0, 30.0)] == [300e3, 275e3, 225e3, 200e3]


@pytest.mark.parametrize("ac", [False, True])
def test_a_low_catenary_voltage_slows_the_run_up_and_raises_the_current(tmp_path, ac):
    """The pantograph_voltage parameter reaches the effort: full traction from rest on a level
    line at 95 % and 105 % of the rated voltage."""
    stock = load_rolling_stock(DATA / ("freight_vl80.json" if ac else "passenger_chs7.json"))
    line = _flat(tmp_path, ac=ac)
    rated = 25000.0 if ac else 3000.0
    target = (70 if ac else 110) * KMH                     # well into the constant-power part
    times, currents = {}, {}
    for ratio in (0.95, 1.0, 1.05):
        core = TractionCore(stock, line, x0_m=1200.0, pantograph_voltage_v=ratio * rated)
        t = 0.0
        while core.v < target:
            out = core.step(t, 1.0, 1.0)
            t += 1.0
            assert t < 1200
        times[ratio], currents[ratio] = t, out.i_traction_a
    assert times[0.95] > times[1.0] > times[1.05]
    assert times[0.95] >= 1.02 * times[1.0]
    assert currents[0.95] > currents[1.0]


# ---- coasting: the locomotive's idle resistance ------------------------------------------------
#: the grade at which our passenger train (ЧС7 + 14 coaches) coasts from 80 to 75 km/h in the
#: ATO book's 390 m (docs/traction.md#coasting-and-the-books-example)
BOOK_COAST_GRADE_PERMILLE = 4.82


def _coast_80_to_75(core, step_s=0.05):
    """Distance and time from 80 to 75 km/h with the controller at zero (coasting)."""
    t, x0 = 0.0, core.x
    while core.v > 75 * KMH:
        before = (t, core.x, core.v)
        core.step(t, step_s, 0.0)
        t += step_s
    t_b, x_b, v_b = before
    share = (v_b - 75 * KMH) / (v_b - core.v)
    return x_b + share * (core.x - x_b) - x0, t_b + share * step_s


def test_the_books_coasting_example_at_its_implied_grade(tmp_path):
    """ATO book §3 (Fig. 14): coasting 80 → 75 km/h takes 390 m and 18.2 s. With the idle
    formula our train needs +4.82 ‰ for the 390 m; with the traction formula it would coast
    about 2 % further."""
    core = TractionCore(load_rolling_stock(), _flat(tmp_path, BOOK_COAST_GRADE_PERMILLE), x0_m=2000.0,
                        v0_mps=80 * KMH)
    distance, duration = _coast_80_to_75(core)
    assert distance == pytest.approx(390.0, abs=2.0)
    assert duration == pytest.approx(18.2, abs=0.25)


def test_coasting_uses_the_idle_formula_and_traction_the_traction_formula(tmp_path):
    stock = load_rolling_stock()
    core = TractionCore(stock, _flat(tmp_path), x0_m=2000.0, v0_mps=80 * KMH)
    v = 80 * KMH
    # ПТР, ЧС7 (172 t of 984 t): idle 2.4 + 0.011V + 0.00035V², traction 1.9 + 0.01V + 0.0003V²
    loco_share = 172 / 984
    idle_excess = loco_share * ((2.4 + 0.011 * 80 + 0.00035 * 80 ** 2) - (1.9 + 0.01 * 80 + 0.0003 * 80 ** 2))
    assert (core.coasting_resistance(v) - core.main_resistance(v)) / core.weight_kn == pytest.approx(idle_excess)
    coasting = core.step(0.0, 0.1, 0.0)
    assert coasting.a_mps2 == pytest.approx(-core.coasting_resistance(coasting.v_mps) / core.m_eff, rel=1e-9)
    pulling = core.step(0.1, 0.1, 0.5)
    expected = (0.5 * core.max_traction_force(pulling.v_mps) - core.main_resistance(pulling.v_mps)) / core.m_eff
    assert pulling.a_mps2 == pytest.approx(expected, rel=1e-9)


def test_a_stock_file_without_idle_resistance_uses_its_resistance_in_every_mode(tmp_path):
    emu = load_rolling_stock(DATA / "emu_er2.json")
    core = TractionCore(emu, _flat(tmp_path))
    assert core.coasting_resistance(20.0) == core.main_resistance(20.0)


# ---- ALSN 50 Hz under 50 Hz AC traction --------------------------------------------------------
def _ac_line_with_50_hz(tmp_path):
    doc = json.loads((DATA / "default_line_ac.json").read_text())
    doc["block_sections"][3]["carrier_hz"] = 50
    path = tmp_path / "ac_50hz.json"
    path.write_text(json.dumps(doc, ensure_ascii=False))
    return path


def test_a_50_hz_carrier_on_an_ac_line_is_refused(tmp_path):
    path = _ac_line_with_50_hz(tmp_path)
    with pytest.raises(FmuInputError) as error:
        load_line(path)
    assert str(path) in str(error.value) and "field block_sections[3].carrier_hz" in str(error.value)
    # the same carrier on the DC line, and 25/75 Hz on the AC line, are accepted
    load_line(DEFAULT_LINE)
    load_line(DATA / "default_line_ac.json")


def test_a_50_hz_carrier_on_an_ac_line_ends_the_run_with_one_line(tmp_path, product_fmus):
    line = _ac_line_with_50_hz(tmp_path)
    folder = tmp_path / "ac50"
    write_ssd(folder, "ac50", [
        ComponentSpec("train", str(product_fmus / "Traction.fmu"), 0.5,
                      {"line_file": str(line), "rolling_stock_file": str(DATA / "freight_vl80.json"), "x0": 1000.0}),
    ], [], stop_time=5.0)
    code, _, stderr = railcosim("run", folder, "--no-build", "--output", tmp_path / "o")
    assert code == 2 and len(stderr.strip().splitlines()) == 1 and "Traceback" not in stderr
    assert "block_sections[3].carrier_hz" in stderr and "ac_50hz.json" in stderr


def test_the_rail_lines_carrier_parameter_is_held_to_the_same_rule():
    """The rail line's `carrier` parameter overrides the line file's carriers: 50 Hz on an AC
    line is refused there too, naming the parameter."""
    from fmus.rail_line.core import RailLineCore, RailSettings

    line = load_line(DATA / "default_line_ac.json")
    with pytest.raises(FmuInputError, match="parameter carrier: a 50 Hz ALSN carrier cannot be used under 50 Hz AC"):
        RailLineCore(line, 8, 2, 40, RailSettings(carrier_hz=50.0))
    RailLineCore(line, 8, 2, 40, RailSettings(carrier_hz=75.0))
