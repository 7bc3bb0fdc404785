"""The ATO book's statistical capacity method (orchestrator/headway/statistical.py) against the
book's own worked arithmetic (docs/sources.md#headway-and-capacity)."""
import pytest

from orchestrator.headway import statistical


def test_the_books_worked_arithmetic():
    mean, rms, ato = 290.4, 77.6, 15.0
    assert statistical.exact_interval_s(mean, rms) == pytest.approx(212.8, abs=1e-9)
    assert round(100 * statistical.under_use(mean, rms), 1) == 26.7
    assert statistical.achievable_interval_s(mean, rms, ato) == pytest.approx(227.8, abs=1e-9)
    assert round(100 * statistical.capacity_gain(mean, rms, ato), 1) == 21.6
    # the interval the ATO gains: RMS − 15 s
    assert mean - statistical.achievable_interval_s(mean, rms, ato) == pytest.approx(62.6, abs=1e-9)


def test_rms_counts_deviations_without_sign():
    # intervals 5 s short and 5 s long of a 300 s schedule: RMS 5, mean unchanged
    assert statistical.rms_deviation_s([295.0, 305.0], 300.0) == pytest.approx(5.0)
    assert statistical.rms_deviation_s([310.0, 290.0, 300.0], [300.0, 300.0, 300.0]) == pytest.approx((200 / 3) ** 0.5)
    assessed = statistical.assess([295.0, 305.0], 300.0, 1.0)
    assert assessed.mean_interval_s == 300.0 and assessed.exact_interval_s == pytest.approx(295.0)
    assert assessed.capacity_gain == pytest.approx(4.0 / 300.0)
    with pytest.raises(ValueError):
        statistical.rms_deviation_s([], 300.0)
