"""TVM-300's code table and block rules (fmus/signalling/tvm300.py, tvm300_codes.json): every
error in a table one line naming the file and the field, the cascade pairs behind a train, the
caps of the line's limits, the lines the table cannot signal refused, the neighbours of every
sub-frequency, and what a code means to the cab. docs/wayside_coder.md#tvm-300."""
import json

import numpy as np
import pytest

from fmus.data.loader import load_line
from fmus.errors import FmuInputError
from fmus.signalling import aspects as sig
from fmus.signalling import tvm300
from fmus.signalling.block_rules import block_codes
from tests.test_tvm430_coder import write_tvm_line

TVM = tvm300.system()


def _table(tmp_path, change):
    doc = json.loads(tvm300.CODES_FILE.read_text(encoding="utf-8"))
    change(doc)
    path = tmp_path / "codes.json"
    path.write_text(json.dumps(doc))
    return path


@pytest.mark.parametrize("change, message", [
    (lambda d: d.update(steps_kmh=[300, 270, 270, 0]), "field steps_kmh: expected speeds in km/h falling"),
    (lambda d: d.update(steps_kmh=[300, 80]), "field steps_kmh: expected speeds in km/h falling from the fastest step to 0"),
    (lambda d: d.update(control_margin_kmh=0), "field control_margin_kmh: must be a speed in km/h above 0"),
    (lambda d: d.pop("sub_frequency_codes"), "field sub_frequency_codes: missing or not an object"),
    (lambda d: d["sub_frequency_codes"].update({"18": [80, 80]}), r"field sub_frequency_codes.18: sub-frequency indices are 0…17"),
    (lambda d: d["sub_frequency_codes"].update({"1": [230, 160]}), r"field sub_frequency_codes.1: expected \[step km/h, next"),
    (lambda d: d["sub_frequency_codes"].update({"1": [160, 220]}), r"field sub_frequency_codes.1: expected \[step km/h, next"),
    (lambda d: d["sub_frequency_codes"].update({"1": [300, 300]}), "field sub_frequency_codes: two sub-frequencies for the same pair"),
    (lambda d: d["sub_frequency_codes"].pop("0"), "field sub_frequency_codes: no sub-frequency for 0/0"),
    (lambda d: d["sub_frequency_codes"].update({"1": [300, 0]}), "field sub_frequency_codes.1: 300/0 km/h is a pair the block rules never send"),
])
def test_every_table_error_is_one_line_naming_the_file_and_the_field(tmp_path, change, message):
    path = _table(tmp_path, change)
    with pytest.raises(FmuInputError, match=message) as raised:
        tvm300.system(path)
    assert str(path) in str(raised.value) and "\n" not in str(raised.value)


def test_the_shipped_table_uses_14_of_18_sub_frequencies_and_its_neighbours_are_comparable():
    """The eleven cascade and steady pairs and three capped ones, four unused; any two used
    neighbours (1.1 Hz apart, the likeliest confusion) are comparable — one permits everything
    the other does, so a confusion is a plain step up or down, never faster in one respect and
    slower in another — and the stop code and 80/0 have no used neighbour at all."""
    pairs = TVM.table.pairs
    assert len(pairs) == 14 and set(range(18)) - set(pairs) == {1, 3, 9, 13}
    cascade = {(300, 300), (270, 270), (220, 220), (160, 160), (80, 80), (300, 270), (270, 220), (220, 160),
               (160, 80), (80, 0), (0, 0)}
    assert cascade <= set(pairs.values()) and set(pairs.values()) - cascade == {(300, 220), (270, 160), (220, 80)}
    for k in range(17):
        if k in pairs and k + 1 in pairs:
            a, b = tvm300.code_of_index(k), tvm300.code_of_index(k + 1)
            assert TVM.at_most(a, b) or TVM.at_most(b, a), (pairs[k], pairs[k + 1])
    for pair in ((0.0, 0.0), (80.0, 0.0)):
        k = tvm300.index_of_code(TVM.table.code_of_pair(*pair))
        assert not {k - 1, k + 1} & set(pairs), pair


def test_what_a_code_means_to_the_cab():
    read = TVM.reading(tvm300.code_of_index(7))                  # 220/160
    assert (read.step_kmh, read.next_kmh, read.control_kmh, read.aspect, read.free_blocks) == (220, 160, 235,
                                                                                                sig.YELLOW, 3)
    assert TVM.reading(tvm300.code_of_index(17)).aspect == sig.GREEN and TVM.reading(18).free_blocks == 6
    assert TVM.reading(1).aspect == sig.RED and TVM.reading(1).free_blocks == 0
    assert TVM.reading(2) is None and TVM.reading(0) is None and TVM.command_of_code(2) is None
    assert TVM.blocks_before_target(160.0, 160.0) == 3           # the fewest m giving it (220/160 capped at 160)
    assert TVM.at_most(1, 18) and not TVM.at_most(18, 1) and TVM.at_most(2, 1)
    assert not TVM.at_most(code := TVM.table.code_of_pair(300.0, 220.0), 17) and not TVM.at_most(17, code)
    indication = TVM.indication(18, "high_speed")
    assert (indication.code, indication.aspect, indication.permitted_kmh, indication.target_kmh) == (18, sig.GREEN,
                                                                                                     300, 300)


def _pairs(line, occupied_block=None, cut=False):
    occupied = np.zeros(len(line.sections), dtype=bool)
    if occupied_block is not None:
        occupied[occupied_block] = True
    rules = block_codes(occupied, line.block_of_section)
    codes = tvm300.BlockCoding(line, TVM).codes(rules)
    return [(TVM.reading(c).step_kmh, TVM.reading(c).next_kmh) for c in codes]


def test_the_cascade_behind_a_train_and_the_last_stations_stop(tmp_path):
    line = load_line(write_tvm_line(tmp_path))
    assert _pairs(line, 7)[:7] == [(300, 300), (300, 270), (270, 220), (220, 160), (160, 80), (80, 0), (0, 0)]
    assert _pairs(line, 2)[:2] == [(80, 0), (0, 0)] and _pairs(line, 2)[3:6] == [(300, 270), (270, 220), (220, 160)]
    assert _pairs(line)[-3:] == [(220, 160), (160, 80), (80, 0)]          # the station at 11.8 km in block 8


def _line_with_limits(tmp_path, limits):
    path = write_tvm_line(tmp_path)
    doc = json.loads(path.read_text())
    doc["speed_limits"] = [{"start_m": start, "passenger_kmh": 160, "freight_kmh": 90, "high_speed_kmh": v}
                           for start, v in limits]
    path.write_text(json.dumps(doc))
    return path


def test_each_step_is_capped_by_the_lines_limit_over_its_block(tmp_path):
    """300 km/h, then 270 from block 4, 230 (cap 220) from block 5, 170 (cap 160) from block 7,
    the line clear to the station at 11.8 km: the caps, and the next step capped by the next
    block's."""
    line = load_line(_line_with_limits(tmp_path, [(0, 300), (4500, 270), (6000, 230), (9000, 170)]))
    assert _pairs(line) == [(300, 300), (300, 300), (300, 270), (270, 220), (220, 220), (220, 160), (160, 80),
                            (80, 0)]


@pytest.mark.parametrize("limits, message", [
    ([(0, 300), (6000, 170)], r"block 4 \(4500–6000 m\): the block rules send 300/160 km/h there, which has no "
                              "sub-frequency in tvm300_codes.json"),
    ([(0, 300), (3000, 60)], "field speed_limits: 60 km/h at 3000 m is below tvm300_codes.json's lowest step 80"),
])
def test_a_line_the_table_cannot_signal_is_refused_naming_the_line_the_block_and_the_pair(tmp_path, limits, message):
    path = _line_with_limits(tmp_path, limits)
    with pytest.raises(FmuInputError, match=message) as raised:
        tvm300.BlockCoding(load_line(path), TVM)
    assert str(path) in str(raised.value)
