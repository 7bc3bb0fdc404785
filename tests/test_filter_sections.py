"""Every receiver filter runs as second-order sections, exact against a long-double evaluation
of the same analog prototype and pre-warped Tustin map (fmus/dsp/filter_design.py)."""
import numpy as np
import pytest
from scipy import signal

from fmus.dsp.filter_design import SosFilter, chebyshev_low_pass, sections
from fmus.loco_receiver import filters
from fmus.loco_receiver.core import LocoReceiverCore, ReceiverSettings
from fmus.loco_receiver.digital_receiver import DigitalReceiverCore, DigitalReceiverSettings
from fmus.signalling import als_en, fire_dqpsk

FS = 4000.0


def _receiver_filters():
    """Every filter the receiver cores build, by name."""
    found = {}
    for carrier in (25.0, 50.0, 75.0):
        core = LocoReceiverCore(40, ReceiverSettings(carrier_hz=carrier))
        found[f"ALSN {carrier:g} Hz band-pass"] = core.band_pass
        found[f"ALSN {carrier:g} Hz envelope"] = core.envelope_lp
    for system in (als_en.SYSTEM, fire_dqpsk.SYSTEM):
        core = DigitalReceiverCore(system, 40, DigitalReceiverSettings())
        found[f"{system.name} anti-alias"] = core.anti_alias
        found[f"{system.name} band-pass"] = core.band_pass
    return found


@pytest.mark.parametrize("name", sorted(_receiver_filters()))
def test_every_receiver_filter_is_second_order_sections_exact_to_a_long_double_reference(name):
    design = _receiver_filters()[name]
    assert isinstance(design, SosFilter) and design.sos.shape[1] == 6
    top = min(FS / 2 * 0.95, 4 * design.prewarp_hz + 600.0)
    freqs = np.linspace(1.0, top, 400)
    exact = design.exact_response(freqs).astype(complex)
    error = np.abs(design.response(freqs) - exact)
    # relative where the filter passes, absolute (against its peak) where it stops
    assert np.max(error / np.maximum(np.abs(exact), 1e-6)) < 1e-9


def test_the_8th_order_25_hz_band_pass_as_one_transfer_function_is_far_off_and_as_sections_exact():
    """The reason for sections: the same prototype discretised as one polynomial ratio loses the
    response to the rounding of its coefficients (9 % at the carrier, more below it)."""
    design = filters.band_pass(25.0, 10.0, 4, FS)
    freqs = np.array([12.5, 25.0, 50.0])
    exact = design.exact_response(freqs).astype(complex)
    b, a = signal.sos2tf(design.sos)
    _, as_polynomial = signal.freqz(b, a, worN=freqs, fs=FS)
    assert abs(as_polynomial[1] - exact[1]) / abs(exact[1]) > 1e-3
    assert np.max(np.abs(design.response(freqs) - exact) / np.abs(exact)) < 1e-10


def test_sections_keep_the_prototypes_gain_and_centre():
    for carrier, bandwidth, order in ((25.0, 10.0, 3), (50.0, 20.0, 3), (75.0, 30.0, 3)):
        design = filters.band_pass(carrier, bandwidth, order, FS)
        assert design.order == 2 * order and design.sos.shape[0] == order
        assert abs(abs(design.response([carrier])[0]) - 1.0) < 1e-9
        # the −3 dB edges of an analog band-pass about its geometric centre (the Tustin map,
        # exact at the carrier, narrows the band by ω0T/sin(ω0T): 0.2 % at 75 Hz)
        edges = np.sqrt(carrier ** 2 + (bandwidth / 2) ** 2) + np.array([-0.5, 0.5]) * bandwidth
        half_power = np.abs(design.response(edges))
        assert np.all(np.abs(half_power - 2 ** -0.5) < 0.01)
    low = chebyshev_low_pass(500.0, 6, 1.0, FS)
    assert abs(20 * np.log10(abs(low.response([500.0])[0])) + 1.0) < 1e-6


def test_an_odd_order_prototype_gets_a_first_order_section():
    design = sections(signal.buttap(3), 2 * np.pi * 20.0, FS, 20.0)
    assert design.sos.shape == (2, 6)
    freqs = np.linspace(1.0, 200.0, 50)
    exact = design.exact_response(freqs).astype(complex)
    assert np.max(np.abs(design.response(freqs) - exact) / np.abs(exact)) < 1e-10
