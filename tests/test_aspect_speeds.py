"""The ALSN speed tables (fmus/signalling/aspects.py): each category's sourced values, the
supervised table apart from the ATO's driving band."""
import numpy as np
import pytest

from harness.closed_loop import red_signal_ahead, run_closed_loop
from fmus.ato_controller.atp import Atp
from fmus.data.loader import load_line
from fmus.signalling import aspects as sig

KMH = 1 / 3.6


@pytest.mark.parametrize("category, yellow_kmh", [("passenger", 80.0), ("freight", 50.0), ("high_speed", 80.0)])
def test_supervised_speeds_per_category_are_the_sourced_ones(category, yellow_kmh):
    table = sig.ALSN_SPEEDS_KMH[category]
    # yellow: the thesis' speed past a wayside yellow (80 passenger, 50 freight)
    assert table[sig.YELLOW] == (None, yellow_kmh)
    # red-yellow: a stop at the exit signal, not the ATO's 60 km/h band
    assert table[sig.RED_YELLOW] == (yellow_kmh, 0.0)
    assert table[sig.RED] == (20.0, None)          # thesis Table 2.1
    assert table[sig.WHITE] == (40.0, None)        # KLUB no_code_limit 41 km/h
    assert table[sig.GREEN] == (None, None)
    for aspect in table:
        assert ("supervised", category, aspect) in sig.SOURCES


@pytest.mark.parametrize("category, band_kmh", [("passenger", 60.0), ("freight", 50.0), ("high_speed", 60.0)])
def test_ato_driving_speeds_per_category_are_the_sourced_ones(category, band_kmh):
    # МИИТ (passenger): yellow → 60 km/h by the end of the block; КЖ → band 60…42, then stop
    assert sig.ALSN_DRIVING_KMH[category] == {sig.YELLOW: (None, band_kmh), sig.RED_YELLOW: (band_kmh, 0.0)}
    for aspect in sig.ALSN_DRIVING_KMH[category]:
        assert ("driving", category, aspect) in sig.SOURCES
        band, at_signal = sig.ALSN_DRIVING_KMH[category][aspect]
        ceiling, supervised_at_signal = sig.ALSN_SPEEDS_KMH[category][aspect]
        # the ATO drives below what the ATP supervises
        assert band is None or ceiling is None or band <= ceiling
        assert at_signal <= supervised_at_signal


def test_the_atp_does_not_cap_red_yellow_at_the_atos_band():
    atp = Atp(load_line(), "passenger", 388.0, "ALSN", 0.63, 4.22)
    r = atp.supervise(0.0, 4000.0, 20.0, sig.RED_YELLOW, True, 0, 0, 0)
    assert r.ceiling_mps == pytest.approx(80 * KMH)


def test_the_ato_drives_its_band_under_red_yellow_and_60_at_the_yellow_exit():
    result = run_closed_loop(1300.0, cab_signal=red_signal_ahead(load_line(), 15200.0, 900.0))
    x, v, aspect = result.column("x"), result.column("v"), result.column("aspect")
    under_ry = aspect == sig.RED_YELLOW
    assert under_ry.any() and v[under_ry].max() <= 60 * KMH + 0.05
    # traction–coast: the band is driven by coasting down from its top (МИИТ 60…42 km/h)
    assert (result.column("mode")[under_ry] == 2).any()
    assert sig.ALSN_BAND_BOTTOM_KMH["passenger"][sig.RED_YELLOW] == 42.0
    # at the yellow section's exit (12 800 m, signal Ч2) the ATO is down to its 60 km/h
    k = np.argmax(x >= 12800.0)
    assert v[k] <= 60 * KMH + 0.05
    assert result.ato.atp.interventions == 0
