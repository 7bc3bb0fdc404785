"""The shortcuts into numpy's and scipy's C routines (fmus/library_shortcuts.py) give the answers
of the public functions they stand for, on the inputs the cores pass them."""
import numpy as np
import pytest
from scipy.signal import butter, lfilter, sosfilt

from fmus import library_shortcuts as shortcuts


def test_the_shortcuts_this_numpy_and_scipy_offer_are_taken():
    """Every shortcut is taken on the versions this project installs (a layout change shows
    here, not as a silent slow-down)."""
    assert shortcuts.in_use() == {"count_nonzero": True, "interp": True, "linear_filter": True,
                                  "sections_filter": True}


@pytest.mark.parametrize("size", [0, 1, 40, 320])
def test_count_nonzero_is_np_count_nonzero(size):
    rng = np.random.default_rng(size)
    for share in (0.0, 0.3, 1.0):
        flags = rng.random(size) < share
        assert shortcuts.count_nonzero(flags) == np.count_nonzero(flags)


def test_interp_is_np_interp_inside_beyond_and_at_the_nodes():
    rng = np.random.default_rng(3)
    xp = np.cumsum(rng.uniform(1.0, 50.0, 30))
    fp = np.log(rng.uniform(0.1, 2.0, 30))
    x = np.concatenate([rng.uniform(xp[0] - 100.0, xp[-1] + 100.0, 400), xp])
    np.testing.assert_array_equal(shortcuts.interp(x, xp, fp), np.interp(x, xp, fp))


@pytest.mark.parametrize("rows", [0, 3])
def test_linear_filter_is_lfilter_with_state(rows):
    b, a = butter(4, [0.01, 0.05], btype="band")
    rng = np.random.default_rng(rows)
    x = rng.standard_normal((rows, 400) if rows else 400)
    zi = rng.standard_normal((rows, a.size - 1) if rows else a.size - 1)
    y, zf = shortcuts.linear_filter(b, a, x, -1, zi.copy())
    y_public, zf_public = lfilter(b, a, x, axis=-1, zi=zi.copy())
    np.testing.assert_array_equal(y, y_public)
    np.testing.assert_array_equal(zf, zf_public)


@pytest.mark.parametrize("rows", [0, 3])
def test_sections_filter_is_sosfilt_with_state_and_leaves_its_arguments(rows):
    sos = butter(4, [0.01, 0.05], btype="band", output="sos")
    rng = np.random.default_rng(rows)
    x = rng.standard_normal((rows, 400) if rows else 400)
    zi = rng.standard_normal((rows, sos.shape[0], 2) if rows else (sos.shape[0], 2))
    x_before, zi_before = x.copy(), zi.copy()
    y, zf = shortcuts.sections_filter(sos, x, zi)
    public_zi = np.moveaxis(zi, 1, 0) if rows else zi
    y_public, zf_public = sosfilt(sos, x, axis=-1, zi=public_zi)
    np.testing.assert_array_equal(y, y_public)
    np.testing.assert_array_equal(zf, np.moveaxis(zf_public, 0, 1) if rows else zf_public)
    np.testing.assert_array_equal(x, x_before)
    np.testing.assert_array_equal(zi, zi_before)
