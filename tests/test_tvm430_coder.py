"""TVM-430's wayside coder (fmus/wayside_coder/tvm430.py): the word of every block state comes
back out of each section's FM carrier demodulated here with plain numpy, the carrier keeps its
phase through a word change, frames of any length give the same samples, bad parameters are one
error, and the WaysideCoder FMU runs it. docs/wayside_coder.md#tvm-430."""
import json

import numpy as np
import pytest

from fmus.data.loader import load_line
from fmus.errors import FmuInputError
from fmus.signalling import tvm430
from fmus.signalling.block_rules import block_codes
from fmus.wayside_coder.core import CoderSettings
from fmus.wayside_coder.tvm430 import PEAK_DEVIATION_HZ, Tvm430CoderCore
from orchestrator.sspgen import ComponentSpec, write_ssd
from tests.helpers import railcosim, read_csv

FS_HZ = 12000.0
FRAME = 120
BLOCKS = 8
CARRIERS_HZ = np.array([(1700.0, 2300.0)[b % 2] for b in range(BLOCKS)])


def write_tvm_line(folder, carriers=None, name="tvm_line.json"):
    """8 blocks of 1500 m, carriers alternating 1700 / 2300 Hz (track 1), a station at the end."""
    carriers = CARRIERS_HZ if carriers is None else carriers
    blocks = [{"name": f"B{b}", "start_m": 1500.0 * b, "end_m": 1500.0 * (b + 1), "signal": f"M{b}",
               "transmitter": "UM71", "carrier_hz": float(carriers[b]), "ballast_ohm_km": 2.0} for b in range(BLOCKS)]
    doc = {"name": "tvm test", "length_m": 1500.0 * BLOCKS, "electrification": {"system": "AC25000"},
           "block_sections": blocks, "separation_zones": [{"position_m": 1500.0 * b} for b in range(1, BLOCKS)], "stations": [{"name": "end", "stop_m": 11800.0}],
           "gradients": [{"start_m": 0, "permille": 0}, {"start_m": 4000, "permille": -12}],
           "curves": [], "speed_limits": [{"start_m": 0, "passenger_kmh": 160, "freight_kmh": 90,
                                           "high_speed_kmh": 300}]}
    path = folder / name
    path.write_text(json.dumps(doc))
    return path


@pytest.fixture
def line(tmp_path):
    return load_line(write_tvm_line(tmp_path))


def run(core, seconds, occupied_at):
    """The coder's output (K × samples) from t = 0, ``occupied_at(t)`` the occupancy per frame."""
    frames = int(round(seconds * FS_HZ / core.frame))
    out = np.empty((core.count, frames * core.frame))
    for f in range(frames):
        t = f * core.frame / FS_HZ
        out[:, f * core.frame:(f + 1) * core.frame] = core.step(t, occupied_at(t)).u_tx[:core.count]
    return out


def analytic(u):
    """The analytic signal of each row (one-sided spectrum), numpy only."""
    n = u.shape[-1]
    spectrum = np.fft.fft(u, axis=-1)
    weight = np.zeros(n)
    weight[0] = 1.0
    weight[1:(n + 1) // 2] = 2.0
    if n % 2 == 0:
        weight[n // 2] = 1.0
    return np.fft.ifft(spectrum * weight, axis=-1)


def instantaneous_frequency_hz(u, fs_hz=FS_HZ):
    """(K, samples − 1) the frequency of each row between consecutive samples."""
    return np.diff(np.unwrap(np.angle(analytic(u)), axis=-1), axis=-1) * fs_hz / (2 * np.pi)


def demodulated_words(u, carriers_hz, first_sample, edge_s=0.2, fs_hz=FS_HZ):
    """The word each row carries: its instantaneous frequency minus the carrier, fitted by least
    squares with a cosine and a sine of each of the 27 tones (away from the record's edges); a
    tone of amplitude above half the deviation per tone is a 1."""
    deviation = instantaneous_frequency_hz(u, fs_hz) - carriers_hz[:, None]
    n = np.arange(deviation.shape[1]) + first_sample + 0.5          # between samples n and n+1
    keep = slice(int(edge_s * fs_hz), deviation.shape[1] - int(edge_s * fs_hz))
    angle = 2 * np.pi * np.outer(n[keep] / fs_hz, tvm430.TONES_HZ)
    basis = np.hstack([np.cos(angle), np.sin(angle), np.ones((angle.shape[0], 1))])
    coefficients, *_ = np.linalg.lstsq(basis, deviation[:, keep].T, rcond=None)
    amplitude = np.hypot(coefficients[:27], coefficients[27:54])      # (27, K)
    assert np.all((amplitude < 0.1) | (np.abs(amplitude - tvm430.DEVIATION_HZ_PER_TONE) < 0.1)), amplitude
    return [tvm430.word_of_bits(amplitude[:, k] > 0.5 * tvm430.DEVIATION_HZ_PER_TONE) for k in range(u.shape[0])]


def test_every_block_state_comes_back_as_the_block_rules_word_from_each_carrier(line):
    """A train in each block in turn (and the line clear): 3 s per state on one running coder,
    each section's word demodulated from its own carrier."""
    core = Tvm430CoderCore(line, BLOCKS, FRAME, CoderSettings(fs_hz=FS_HZ))
    expected_words = tvm430.BlockWords(line, tvm430.system())
    states = [None] + list(range(BLOCKS))
    seconds = 3.0

    def occupancy(state):
        occupied = np.zeros(BLOCKS, dtype=bool)
        if state is not None:
            occupied[state] = True
        return occupied
    u = run(core, seconds * len(states), lambda t: occupancy(states[min(int(t / seconds), len(states) - 1)]))
    per_state = int(seconds * FS_HZ)
    shown = {}
    for i, state in enumerate(states):
        piece = u[:, i * per_state:(i + 1) * per_state]
        rules = block_codes(occupancy(state), line.block_of_section)
        expected = expected_words.words(rules.free_blocks, rules.coded).tolist()
        assert demodulated_words(piece, CARRIERS_HZ, i * per_state) == expected, state
        shown[state] = [tvm430.system().reading(w) for w in expected]
    # what the words say, by hand: a train in block 6 → behind it 300/300 … 170/0, the buffer 0/0
    behind = shown[6][:6]
    assert [(r.step_kmh, r.next_kmh) for r in behind] == [(300, 300), (300, 270), (270, 230), (230, 170),
                                                          (170, 0), (0, 0)]
    assert behind[4].target_distance_m == 1500.0 and behind[1].target_distance_m == 6000.0
    assert behind[1].gradient_permille == -12.0
    # the line clear: the station at 11.8 km is the target of the last blocks
    assert [(r.step_kmh, r.next_kmh) for r in shown[None][-3:]] == [(270, 230), (230, 170), (170, 0)]


def test_a_word_change_keeps_the_carriers_phase_and_changes_only_its_frequency(line):
    """The train enters block 3 at 3 s: the words of blocks 0…2 change. The frequency between
    consecutive samples stays within carrier ± the largest deviation through the change; a
    coder that restarted its phase with the new word would step by up to half a turn."""
    change_s = 3.0

    def occupied_at(t):
        occupied = np.zeros(BLOCKS, dtype=bool)
        occupied[3] = t >= change_s
        return occupied
    core = Tvm430CoderCore(line, BLOCKS, FRAME, CoderSettings(fs_hz=FS_HZ))
    u = run(core, 2 * change_s, occupied_at)
    n0 = int(change_s * FS_HZ)
    words_before = demodulated_words(u[:, :n0], CARRIERS_HZ, 0)
    words_after = demodulated_words(u[:, n0:], CARRIERS_HZ, n0)
    changed = [k for k in range(BLOCKS) if words_before[k] != words_after[k]]
    assert changed == [0, 1, 2]
    around = slice(n0 - 600, n0 + 600)                       # ±50 ms, far from the record's ends
    offset_hz = instantaneous_frequency_hz(u)[:, around] - CARRIERS_HZ[:, None]
    assert np.abs(offset_hz).max() <= PEAK_DEVIATION_HZ

    # the same check on a carrier whose phase restarts with the new word: it must fail
    restarted = Tvm430CoderCore(line, BLOCKS, FRAME, CoderSettings(fs_hz=FS_HZ))
    restarted.send(np.array(words_after))
    spliced = u.copy()
    spliced[:, n0:] = run(restarted, 2 * change_s, occupied_at)[:, n0:]
    jump_hz = instantaneous_frequency_hz(spliced)[changed][:, around] - CARRIERS_HZ[changed, None]
    assert np.abs(jump_hz).max(axis=1).min() > PEAK_DEVIATION_HZ


@pytest.mark.parametrize("frame", [1, 40, 250])
def test_frames_of_any_length_give_the_same_samples(line, frame):
    def occupied_at(t):
        occupied = np.zeros(BLOCKS, dtype=bool)
        occupied[5] = t >= 0.5                    # a word change on a boundary of every frame length
        return occupied
    reference = run(Tvm430CoderCore(line, BLOCKS, FRAME, CoderSettings(fs_hz=FS_HZ)), 1.0, occupied_at)
    other = run(Tvm430CoderCore(line, BLOCKS, frame, CoderSettings(fs_hz=FS_HZ)), 1.0, occupied_at)
    assert np.abs(other - reference).max() < 1e-9


def test_outputs_code_signal_and_faults(line):
    core = Tvm430CoderCore(line, 10, FRAME, CoderSettings(fs_hz=FS_HZ, amplitude_v=2.5))
    occupied = np.zeros(BLOCKS, dtype=bool)
    occupied[4] = True
    out = core.step(0.0, occupied)
    rules = block_codes(occupied, line.block_of_section)
    assert out.code_tx[:BLOCKS].tolist() == tvm430.BlockWords(line, tvm430.system()).words(
        rules.free_blocks, rules.coded).tolist()
    assert out.code_tx[BLOCKS:].tolist() == [0, 0] and not out.u_tx[BLOCKS:].any()     # ports beyond the line
    assert out.signal[:5].tolist() == [4, 4, 2, 1, 4]
    assert np.abs(out.u_tx[:BLOCKS]).max() == pytest.approx(2.5, rel=1e-3)
    out = core.step(FRAME / FS_HZ, occupied, fault_main=True)
    assert out.status == 1 and out.u_tx[:BLOCKS].any() and out.code_tx[0] != 0
    out = core.step(2 * FRAME / FS_HZ, occupied, fault_main=True, fault_reserve=True)
    assert out.status == 2 and not out.u_tx.any() and not out.code_tx.any()


def test_a_network_address_of_the_tables_is_sent(line):
    table = tvm430.system().table
    core = Tvm430CoderCore(line, BLOCKS, FRAME, CoderSettings(fs_hz=FS_HZ), address=table.addresses[1])
    out = core.step(0.0, np.zeros(BLOCKS, dtype=bool))
    assert {tvm430.field(int(w), "address") for w in out.code_tx} == {table.addresses[1]}


@pytest.mark.parametrize("change, message", [
    (dict(settings=dict(fs_hz=5000.0)), "parameter fs: 5000 Hz cannot hold the carrier 2300 Hz"),
    (dict(settings=dict(carrier_hz=1700.0)), "parameter carrier: 1700 Hz, but TVM-430 sends on each section"),
    (dict(settings=dict(coding="on_occupation")), "parameter coding: on_occupation, but a TVM-430 carrier"),
    (dict(address=3), "parameter address: 3 is not one of tvm430_codes.json's addresses 5, 6"),
])
def test_bad_parameters_are_one_error(tmp_path, change, message):
    line = load_line(write_tvm_line(tmp_path, change.get("carriers")))
    settings = CoderSettings(**{"fs_hz": FS_HZ, **change.get("settings", {})})
    with pytest.raises(FmuInputError, match=message):
        Tvm430CoderCore(line, BLOCKS, FRAME, settings, address=change.get("address"))


# ---- through the FMU ------------------------------------------------------------------------------
N = 40          # the product FMUs' frame
FMU_FS_HZ = 8000.0      # a 40-sample step at 12 kHz is no whole number of nanoseconds


def test_the_coder_fmu_sends_the_words_of_the_clear_line(tmp_path, product_fmus):
    line_path = write_tvm_line(tmp_path)
    parameters = {"system": "TVM430", "fs": FMU_FS_HZ, "line_file": str(line_path)}
    components = [ComponentSpec("coder", str(product_fmus / "WaysideCoder.fmu"), N / FMU_FS_HZ, parameters)]
    write_ssd(tmp_path / "sys", "tvm_coder", components, [], stop_time=3.0)
    records = [a for n in range(1, N + 1) for a in ("--record", f"coder.u_tx[2,{n}]")]
    code, _, stderr = railcosim("run", tmp_path / "sys", "--output", tmp_path / "out", "--no-build",
                                "--output-interval", N / FMU_FS_HZ, "--record", "coder.code_tx[2]",
                                "--record", "coder.status", *records)
    assert code == 0, stderr
    header, data = read_csv(tmp_path / "out" / "results.csv")
    column = {name: k for k, name in enumerate(header)}
    line = load_line(line_path)
    rules = block_codes(np.zeros(BLOCKS, dtype=bool), line.block_of_section)
    expected = int(tvm430.BlockWords(line, tvm430.system()).words(rules.free_blocks, rules.coded)[1])
    assert data[-1, column["coder.code_tx[2]"]] == expected and data[-1, column["coder.status"]] == 0
    # a row at time t holds the frame that ends at t: the rows after t = 0 are every frame in order
    assert np.allclose(np.diff(data[:, column["time"]]), N / FMU_FS_HZ)
    u = data[1:, [column[f"coder.u_tx[2,{n}]"] for n in range(1, N + 1)]].reshape(1, -1)
    assert demodulated_words(u, CARRIERS_HZ[1:2], 0, fs_hz=FMU_FS_HZ) == [expected]


def test_the_coder_fmu_refuses_a_sample_rate_too_low_for_the_carriers(tmp_path, product_fmus):
    parameters = {"system": "TVM430", "line_file": str(write_tvm_line(tmp_path))}       # fs 4 kHz by default
    components = [ComponentSpec("coder", str(product_fmus / "WaysideCoder.fmu"), 0.01, parameters)]
    write_ssd(tmp_path / "sys", "bad", components, [], stop_time=0.1)
    code, _, stderr = railcosim("run", tmp_path / "sys", "--output", tmp_path / "out", "--no-build")
    assert code == 2 and "parameter fs: 4000 Hz cannot hold the carrier 2300 Hz" in stderr
    assert "Traceback" not in stderr and len(stderr.strip().splitlines()) == 1, stderr


def test_the_coder_fmu_reads_its_word_tables_from_codes_file(tmp_path, product_fmus):
    """Through `railcosim run`: its check of the data files before the run reads a TVM430
    component's codes_file as word tables (not as ALSN's transmitters), and the FMU sends them."""
    tables = json.loads(tvm430.CODES_FILE.read_text(encoding="utf-8"))
    tables["addresses"] = [3]
    (tmp_path / "my_tables.json").write_text(json.dumps(tables))
    parameters = {"system": "TVM430", "fs": FMU_FS_HZ, "line_file": str(write_tvm_line(tmp_path)),
                  "codes_file": str(tmp_path / "my_tables.json")}
    components = [ComponentSpec("coder", str(product_fmus / "WaysideCoder.fmu"), N / FMU_FS_HZ, parameters)]
    write_ssd(tmp_path / "sys", "tvm_tables", components, [], stop_time=0.05)
    code, _, stderr = railcosim("run", tmp_path / "sys", "--output", tmp_path / "out", "--no-build",
                                "--output-interval", N / FMU_FS_HZ, "--record", "coder.code_tx[1]")
    assert code == 0, stderr
    header, data = read_csv(tmp_path / "out" / "results.csv")
    word = int(data[-1, header.index("coder.code_tx[1]")])
    assert tvm430.check_passes(word) and tvm430.field(word, "address") == 3
