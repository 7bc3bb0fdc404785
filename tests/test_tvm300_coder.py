"""TVM-300's wayside coder (fmus/wayside_coder/tvm300.py): the code of every block state comes
back out of each section's FM carrier demodulated here with plain numpy (instantaneous
frequency, least squares over the 18 sub-frequencies), the carrier and the sub-frequency keep
their phase through a code change, frames of any length give the same samples, faults and bad
parameters. docs/wayside_coder.md#tvm-300."""
import numpy as np
import pytest

from fmus.data.loader import load_line
from fmus.errors import FmuInputError
from fmus.signalling import tvm300
from fmus.signalling.block_rules import block_codes
from fmus.wayside_coder.core import CoderSettings
from fmus.wayside_coder.tvm300 import PEAK_DEVIATION_HZ, Tvm300CoderCore
from tests.test_tvm430_coder import BLOCKS, CARRIERS_HZ, FRAME, FS_HZ, instantaneous_frequency_hz, run, write_tvm_line


@pytest.fixture
def line(tmp_path):
    return load_line(write_tvm_line(tmp_path))


def sub_frequency_amplitudes(u, carriers_hz, first_sample, edge_s=0.1, fs_hz=FS_HZ):
    """(K, 18) each row's fitted amplitude (Hz) of every sub-frequency in its frequency offset
    (away from the record's edges), and the offsets themselves."""
    deviation = instantaneous_frequency_hz(u, fs_hz) - carriers_hz[:, None]
    n = np.arange(deviation.shape[1]) + first_sample + 0.5          # between samples n and n+1
    keep = slice(int(edge_s * fs_hz), deviation.shape[1] - int(edge_s * fs_hz))
    angle = 2 * np.pi * np.outer(n[keep] / fs_hz, tvm300.SUB_FREQUENCIES_HZ)
    basis = np.hstack([np.cos(angle), np.sin(angle), np.ones((angle.shape[0], 1))])
    coefficients, *_ = np.linalg.lstsq(basis, deviation[:, keep].T, rcond=None)
    return np.hypot(coefficients[:18], coefficients[18:36]).T, deviation


def demodulated_codes(u, carriers_hz, first_sample, fs_hz=FS_HZ):
    amplitude, _ = sub_frequency_amplitudes(u, carriers_hz, first_sample, fs_hz=fs_hz)
    for row in amplitude:         # exactly one sub-frequency, at the deviation; the others absent
        assert np.sort(row)[-1] == pytest.approx(tvm300.DEVIATION_HZ, rel=0.01) and np.sort(row)[-2] < 0.05, row
    return [tvm300.code_of_index(int(np.argmax(row))) for row in amplitude]


def occupancy(block):
    occupied = np.zeros(BLOCKS, dtype=bool)
    if block is not None:
        occupied[block] = True
    return occupied


def test_every_block_state_comes_back_as_the_block_rules_code_from_each_carrier(line):
    """A train in each block in turn (and the line clear): 1.5 s per state on one running coder,
    each section's code demodulated from its own carrier, and what the codes say by hand."""
    core = Tvm300CoderCore(line, BLOCKS, FRAME, CoderSettings(fs_hz=FS_HZ))
    coding = tvm300.BlockCoding(line, tvm300.system())
    states = [None] + list(range(BLOCKS))
    seconds = 1.5
    u = run(core, seconds * len(states), lambda t: occupancy(states[min(int(t / seconds), len(states) - 1)]))
    per_state = int(seconds * FS_HZ)
    pairs = {}
    for i, state in enumerate(states):
        expected = coding.codes(block_codes(occupancy(state), line.block_of_section)).tolist()
        assert demodulated_codes(u[:, i * per_state:(i + 1) * per_state], CARRIERS_HZ, i * per_state) == expected
        pairs[state] = [(r.step_kmh, r.next_kmh) for r in map(tvm300.system().reading, expected)]
    # a train in block 7: behind it the cascade 300/300 … 80/0, the buffer block 0/0
    assert pairs[7][:7] == [(300, 300), (300, 270), (270, 220), (220, 160), (160, 80), (80, 0), (0, 0)]
    # the line clear: the station at 11.8 km in block 7 is the stop of the last blocks
    assert pairs[None][-3:] == [(220, 160), (160, 80), (80, 0)]


def test_a_code_change_keeps_the_carriers_and_the_sub_frequencys_phase(line):
    """The train enters block 3 at 2 s: the codes of blocks 0…2 change. The frequency from
    sample to sample stays within carrier ± Δ and moves by no more than the modulation's own
    slope through the change (θ continues: no jump of frequency either); a coder whose phase
    restarts with the new code steps far outside."""
    change_s = 2.0
    core = Tvm300CoderCore(line, BLOCKS, FRAME, CoderSettings(fs_hz=FS_HZ))
    occupied_at = lambda t: occupancy(3 if t >= change_s else None)
    u = run(core, 2 * change_s, occupied_at)
    n0 = int(change_s * FS_HZ)
    before, after = demodulated_codes(u[:, :n0], CARRIERS_HZ, 0), demodulated_codes(u[:, n0:], CARRIERS_HZ, n0)
    changed = [k for k in range(BLOCKS) if before[k] != after[k]]
    assert changed == [0, 1, 2]
    around = slice(n0 - 600, n0 + 600)
    offset_hz = instantaneous_frequency_hz(u)[:, around] - CARRIERS_HZ[:, None]
    assert np.abs(offset_hz).max() <= PEAK_DEVIATION_HZ * 1.001
    # the largest slope of Δ·cos(2π·29 Hz·t) per sample, with room for the analytic signal's ripple
    slope_hz = 2 * np.pi * tvm300.SUB_FREQUENCIES_HZ[-1] * tvm300.DEVIATION_HZ / FS_HZ
    assert np.abs(np.diff(offset_hz, axis=1)).max() < 1.5 * slope_hz

    restarted = Tvm300CoderCore(line, BLOCKS, FRAME, CoderSettings(fs_hz=FS_HZ, seed=7))
    restarted.send(np.array(after))
    spliced = u.copy()
    spliced[:, n0:] = run(restarted, 2 * change_s, occupied_at)[:, n0:]
    jump_hz = instantaneous_frequency_hz(spliced)[changed][:, around] - CARRIERS_HZ[changed, None]
    assert np.abs(jump_hz).max(axis=1).min() > 3 * PEAK_DEVIATION_HZ


def test_the_instantaneous_frequency_is_the_carrier_plus_the_deviation_of_the_sub_frequency(line):
    """Each section's offset is Δ·cos(2π f_k t + θ₀) of its code's sub-frequency, sample by
    sample (to the analytic signal's accuracy), and the code sent is index + 1."""
    core = Tvm300CoderCore(line, BLOCKS, FRAME, CoderSettings(fs_hz=FS_HZ))
    core.send(np.arange(1, BLOCKS + 1) * 2)              # codes 2, 4 … 16: sub-frequencies 11.4 … 27.9 Hz
    u = run(core, 1.0, lambda t: occupancy(None))
    assert core.out.code_tx[:BLOCKS].tolist() == (np.arange(1, BLOCKS + 1) * 2).tolist()
    _, deviation = sub_frequency_amplitudes(u, CARRIERS_HZ, 0)
    middle = slice(2000, 10000)
    t = (np.arange(deviation.shape[1]) + 0.5)[middle] / FS_HZ
    for k in range(BLOCKS):
        f = tvm300.SUB_FREQUENCIES_HZ[2 * (k + 1) - 1]
        basis = np.stack([np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t)], axis=1)
        fit, *_ = np.linalg.lstsq(basis, deviation[k, middle], rcond=None)
        model = basis @ fit
        assert np.hypot(*fit) == pytest.approx(tvm300.DEVIATION_HZ, rel=1e-3)
        residual = deviation[k, middle] - model          # the FFT's analytic signal ripples a little
        assert np.sqrt(np.mean(residual ** 2)) < 0.01 * tvm300.DEVIATION_HZ, k
        assert np.abs(residual).max() < 0.03 * tvm300.DEVIATION_HZ, k


@pytest.mark.parametrize("frame", [1, 40, 250])
def test_frames_of_any_length_give_the_same_samples(line, frame):
    occupied_at = lambda t: occupancy(5 if t >= 0.5 else None)     # a change on a boundary of every frame length
    reference = run(Tvm300CoderCore(line, BLOCKS, FRAME, CoderSettings(fs_hz=FS_HZ)), 1.0, occupied_at)
    other = run(Tvm300CoderCore(line, BLOCKS, frame, CoderSettings(fs_hz=FS_HZ)), 1.0, occupied_at)
    assert np.abs(other - reference).max() < 1e-9


def test_outputs_code_signal_and_faults(line):
    core = Tvm300CoderCore(line, 10, FRAME, CoderSettings(fs_hz=FS_HZ, amplitude_v=2.5))
    out = core.step(0.0, occupancy(4))
    rules = block_codes(occupancy(4), line.block_of_section)
    assert out.code_tx[:BLOCKS].tolist() == tvm300.BlockCoding(line, tvm300.system()).codes(rules).tolist()
    assert out.code_tx[BLOCKS:].tolist() == [0, 0] and not out.u_tx[BLOCKS:].any()
    assert out.signal[:5].tolist() == [4, 4, 2, 1, 4]
    assert np.abs(out.u_tx[:BLOCKS]).max() == pytest.approx(2.5, rel=1e-3)
    out = core.step(FRAME / FS_HZ, occupancy(4), fault_main=True)
    assert out.status == 1 and out.u_tx[:BLOCKS].any() and out.code_tx[0] != 0
    out = core.step(2 * FRAME / FS_HZ, occupancy(4), fault_main=True, fault_reserve=True)
    assert out.status == 2 and not out.u_tx.any() and not out.code_tx.any()


@pytest.mark.parametrize("settings, message", [
    (dict(fs_hz=5000.0), "parameter fs: 5000 Hz cannot hold the carrier 2300 Hz \\+ 11 Hz deviation: TVM-300 needs"),
    (dict(carrier_hz=1700.0), "parameter carrier: 1700 Hz, but TVM-300 sends on each section"),
    (dict(coding="on_occupation"), "parameter coding: on_occupation, but a TVM-300 carrier"),
])
def test_bad_parameters_are_one_error(line, settings, message):
    with pytest.raises(FmuInputError, match=message):
        Tvm300CoderCore(line, BLOCKS, FRAME, CoderSettings(**{"fs_hz": FS_HZ, **settings}))
