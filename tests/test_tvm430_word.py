"""TVM-430's word (fmus/signalling/tvm430.py): its check, its tables, the block rules' words and
the carrier's modulation phase. docs/wayside_coder.md#tvm-430."""
import itertools
import json

import numpy as np
import pytest

from fmus.errors import FmuInputError
from fmus.signalling import tvm430


def every_sendable_word(table):
    for address in table.addresses:
        for speed in table.speed_codes:
            for distance in range(table.distance_codes):
                for gradient in range(16):
                    yield tvm430.assemble(address, speed, distance, gradient)


def test_the_check_has_distance_four_over_the_27_bits():
    # every non-zero error pattern of weight ≤ 3 changes the check: the code is linear (up to the
    # xor), so the words that pass differ from each other in at least 4 bits
    data = np.arange(1 << tvm430.DATA_BITS, dtype=np.int64)
    generator_rows = np.array([(1 << i << 6) | (tvm430.check_bits(1 << i) ^ tvm430.check_bits(0))
                               for i in range(tvm430.DATA_BITS)], dtype=np.int64)
    codewords = np.zeros(data.size, dtype=np.int64)
    for i, row in enumerate(generator_rows):
        codewords ^= np.where((data >> i) & 1, row, 0)
    weights = np.zeros(data.size, dtype=np.int64)
    for bit in range(tvm430.WORD_BITS):
        weights += (codewords >> bit) & 1
    assert weights[1:].min() == 4


def test_no_single_double_or_triple_error_of_a_sent_word_is_read():
    tvm = tvm430.system()
    words = list(every_sendable_word(tvm.table))
    assert len(words) == len(tvm.table.addresses) * len(tvm.table.speed_codes) * tvm.table.distance_codes * 16
    flips = [sum(1 << b for b in bits) for r in (1, 2, 3) for bits in itertools.combinations(range(27), r)]
    for word in words[::37]:
        assert tvm.reading(word) is not None
        assert not any(tvm430.check_passes(word ^ flip) for flip in flips)


def test_all_zero_and_all_one_words_fail():
    assert not tvm430.check_passes(0)
    assert not tvm430.check_passes((1 << 27) - 1)
    assert tvm430.system().reading(0) is None


def test_a_word_reads_back_its_fields():
    tvm = tvm430.system()
    table = tvm.table
    word = tvm430.assemble(table.addresses[1], table.speed_code(270.0, 230.0), table.distance_code(4610.0),
                           table.gradient_code(-11.0))
    read = tvm.reading(word)
    assert (read.step_kmh, read.next_kmh, read.control_kmh) == (270.0, 230.0, 285.0)
    assert read.target_distance_m == 4500.0            # rounded down: never announced farther
    assert read.gradient_permille == -12.0             # rounded to the more falling value
    assert not read.no_target


def test_an_address_not_accepted_or_an_unused_speed_code_reads_as_no_word():
    tvm = tvm430.system()
    other = next(a for a in range(1, 8) if a not in tvm.table.addresses)
    assert tvm.reading(tvm430.assemble(other, 17, 3, 5)) is None
    unused = next(c for c in range(1, 256) if c not in tvm.table.speed_codes)
    assert tvm.reading(tvm430.assemble(tvm.table.addresses[0], unused, 3, 5)) is None


def test_the_modulation_phase_is_the_integral_of_the_frequency_deviation():
    word = tvm430.assemble(5, 34, 20, 9)
    t = np.arange(0, 4.0, 1e-4)
    phase = tvm430.bits_of(word) @ tvm430.modulation_phase_terms(t)
    derivative_hz = np.gradient(phase, t)[1:-1] / (2 * np.pi)       # central differences inside
    assert np.allclose(derivative_hz, tvm430.frequency_deviation(word, t)[1:-1], atol=2e-4)
    full = tvm430.frequency_deviation((1 << 27) - 1, np.arange(0, 12.5, 1e-3))
    assert np.abs(full).max() < 7.1 * tvm430.DEVIATION_HZ_PER_TONE


def hsl_like_line(tmp_path, limit_kmh=300):
    from fmus.data.loader import load_line
    blocks = [{"name": f"B{k}", "start_m": 1500.0 * k, "end_m": 1500.0 * (k + 1), "signal": f"S{k}",
               "transmitter": "KPT-5", "carrier_hz": 75, "ballast_ohm_km": 2.0} for k in range(12)]
    doc = {"name": "tvm", "length_m": 18000.0, "electrification": {"system": "AC25000"},
           "block_sections": blocks, "stations": [{"name": "end", "stop_m": 17200.0}],
           "gradients": [{"start_m": 0, "permille": 0}, {"start_m": 6000, "permille": -25}, {"start_m": 7000, "permille": 5}],
           "curves": [], "speed_limits": [{"start_m": 0, "passenger_kmh": 160, "freight_kmh": 90,
                                           "high_speed_kmh": limit_kmh}]}
    path = tmp_path / "line.json"
    path.write_text(json.dumps(doc))
    return load_line(path)


def test_the_block_rules_step_down_300_270_230_170_0_towards_an_occupied_block(tmp_path):
    line = hsl_like_line(tmp_path)
    tvm = tvm430.system()
    words = tvm430.BlockWords(line, tvm)
    # a train in block 8: blocks 0…7 behind it see 8…1 blocks ahead before it, minus the buffer
    free = np.array([7 - b for b in range(8)])
    readings = [tvm.reading(words.word(b, int(free[b]))) for b in range(8)]
    assert [(r.step_kmh, r.next_kmh) for r in readings[2:]] == [
        (300, 300), (300, 270), (270, 230), (230, 170), (170, 0), (0, 0)]
    # the target is the entry of the buffer block 7, counted from each block's entry
    assert readings[6].target_distance_m == 1500.0 and readings[5].target_distance_m == 3000.0
    assert readings[3].target_distance_m == 6000.0
    # the steepest fall over the way to the target, rounded to the table's more falling value
    assert readings[3].gradient_permille == -25.0 and readings[6].gradient_permille == 3.0      # 5 ‰ rounded down


def test_the_last_station_is_a_target_of_zero(tmp_path):
    line = hsl_like_line(tmp_path)
    tvm = tvm430.system()
    words = tvm430.BlockWords(line, tvm)
    last = tvm.reading(words.word(11, 1 << 20))
    assert (last.step_kmh, last.next_kmh, last.target_distance_m) == (170, 0, 500.0)     # 17200 − 16500, floor 250
    assert (tvm.reading(words.word(10, 1 << 20)).step_kmh) == 230


def test_a_limit_below_the_lowest_step_is_refused(tmp_path):
    with pytest.raises(FmuInputError, match="speed_limits: 160 km/h at 0 m is below .* lowest step 170"):
        tvm430.BlockWords(hsl_like_line(tmp_path, limit_kmh=160), tvm430.system())


@pytest.mark.parametrize("edit, message", [
    (lambda d: d.update(addresses=[0]), "field addresses"),
    (lambda d: d["speed_codes"].update({"0": [300, 300]}), "field speed_codes.0"),
    (lambda d: d["speed_codes"].update({"99": [170, 230]}), "field speed_codes.99"),
    (lambda d: d.update(gradient_permille=[0] * 16), "field gradient_permille"),
    (lambda d: d.update(distance_codes=65), "field distance_codes"),
    (lambda d: d.update(steps_kmh=[300, 270, 10]), "field steps_kmh"),
])
def test_a_bad_code_table_names_its_field(tmp_path, edit, message):
    doc = json.loads(tvm430.CODES_FILE.read_text())
    edit(doc)
    path = tmp_path / "codes.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(FmuInputError, match=message):
        tvm430.load_codes(path)


def test_a_pair_the_block_rules_never_send_is_refused_and_free_blocks_read_from_the_rules(tmp_path):
    # 230/0 (a stop one block ahead from 230 km/h) is sent by no wayside: a table listing it is
    # refused, so no receiver shows a word no wayside sends; it read as green 5 free blocks before
    doc = json.loads(tvm430.CODES_FILE.read_text())
    doc["speed_codes"]["204"] = [230, 0]
    path = tmp_path / "codes.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(FmuInputError, match="field speed_codes.204: 230/0 km/h is a pair the block rules never send"):
        tvm430.system(str(path))
    tvm = tvm430.system()
    table = tvm.table
    sent = {}
    for m, pair in enumerate(tvm.pair_of_blocks):
        sent.setdefault(pair, m)
    # a pair a line's limit makes (270/270: 300/270 capped at 270, four blocks before the target)
    # reports the fewest free blocks the block rules send it with; the uncapped pairs their own
    for (step, following), blocks in {(270.0, 270.0): 4, (300.0, 230.0): 4, (170.0, 170.0): 2,
                                      (230.0, 170.0): 2, (170.0, 0.0): 1, (0.0, 0.0): 0}.items():
        word = tvm430.assemble(table.addresses[0], table.speed_code(step, following), 8, 9)
        assert tvm.reading(word).free_blocks == blocks, (step, following)
    assert set(table.speed_codes.values()) == set(tvm.blocks_of_pair)
