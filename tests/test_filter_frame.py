"""The cores' frame filter calls give the library's samples and state, frame after frame: the
receivers' second-order sections sosfilt's, the digital generator's transfer function lfilter's."""
import numpy as np
import pytest
from scipy.signal import lfilter, sosfilt

from fmus.dsp.filter_design import SampleSosFilter, chebyshev_band_pass, chebyshev_low_pass, filter_frame, sos_frame
from fmus.loco_receiver import filters


@pytest.mark.parametrize("rows", [0, 3])
def test_the_generator_filter_frame_by_frame_equals_lfilter_over_the_whole_signal(rows):
    design = chebyshev_band_pass(175.0, 58.3, 2, 0.5, 4000.0)
    rng = np.random.default_rng(5)
    x = rng.standard_normal((rows, 4000) if rows else 4000)
    order = design.a.size - 1
    state = np.zeros((rows, order) if rows else order)
    pieces = []
    for start in range(0, 4000, 40):
        y, state = filter_frame(design.b, design.a, x[..., start:start + 40], state)
        pieces.append(y)
    whole, final = lfilter(design.b, design.a, x, axis=-1, zi=np.zeros_like(state))
    np.testing.assert_array_equal(np.concatenate(pieces, axis=-1), whole)
    np.testing.assert_array_equal(state, final)


@pytest.mark.parametrize("design", [filters.band_pass(50.0, 20.0, 3, 4000.0), filters.envelope_low_pass(12.0, 4000.0),
                                    chebyshev_low_pass(500.0, 6, 1.0, 4000.0), filters.band_pass(125.0, 10.0, 4, 4000.0)],
                         ids=["alsn-band-pass", "envelope", "anti-alias", "alsu-channel"])
@pytest.mark.parametrize("rows", [0, 3])
def test_sections_frame_by_frame_equal_sosfilt_over_the_whole_signal(design, rows):
    rng = np.random.default_rng(5)
    x = rng.standard_normal((rows, 4000) if rows else 4000)
    state = design.initial_state(rows)
    pieces = []
    for start in range(0, 4000, 40):
        y, state = sos_frame(design.sos, x[..., start:start + 40], state)
        pieces.append(y)
    zi = np.zeros((design.sos.shape[0], rows, 2) if rows else (design.sos.shape[0], 2))
    whole, final = sosfilt(design.sos, x, axis=-1, zi=zi)
    np.testing.assert_array_equal(np.concatenate(pieces, axis=-1), whole)
    np.testing.assert_array_equal(state, np.moveaxis(final, 1, 0) if rows else final)


@pytest.mark.parametrize("design", [filters.band_pass(50.0, 20.0, 4, 4000.0), filters.band_pass(25.0, 10.0, 4, 4000.0),
                                    filters.envelope_low_pass(12.0, 4000.0)],
                         ids=["alsn-band-pass-50", "alsn-band-pass-25", "envelope"])
def test_sample_by_sample_sections_give_sosfilts_samples_bit_for_bit(design):
    """A build with one sample per frame filters in floats: the same samples as sosfilt."""
    x = np.random.default_rng(7).standard_normal(3000)
    one_at_a_time = SampleSosFilter(design.sos)
    samples = [one_at_a_time(value) for value in x.tolist()]
    whole, final = sosfilt(design.sos, x, zi=np.zeros((design.sos.shape[0], 2)))
    assert samples == whole.tolist()
    assert one_at_a_time.state == final.ravel().tolist()
