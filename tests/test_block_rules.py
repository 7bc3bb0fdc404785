"""Block rules (fmus/signalling/block_rules.py) and the coders that apply them: a
track circuit behind an occupied circuit of the same block carries no code."""
import itertools

import numpy as np
import pytest

from fmus.data.loader import load_line
from fmus.signalling import alsn, cab_systems
from fmus.signalling import aspects as sig
from fmus.signalling.block_rules import NO_CODE_FREE_BLOCKS, SIGNAL_GREEN, SIGNAL_RED, SIGNAL_YELLOW, block_codes
from fmus.wayside_coder.core import CoderSettings, WaysideCoderCore
from fmus.wayside_coder.digital_generator import DigitalCoderCore
from orchestrator.systems.shipped import SSP_ROOT

N = 40
THROAT = SSP_ROOT / "joints_at_speed" / "resources" / "throat_line.json"


def _throat():
    line = load_line(THROAT)
    assert line.block_of_section == [0, 1, 2, 3, 3, 3, 4, 5]    # circuits "4", "5", "6" form block 3
    return line


def _reference(occupied, block_of, block_aspects=3):
    """The rules written out circuit by circuit: (free blocks ahead or -1 when cut, ALSN code)."""
    blocks = max(block_of) + 1
    block_occ = [any(o for o, b in zip(occupied, block_of) if b == k) for k in range(blocks)]
    result = []
    for k, b in enumerate(block_of):
        if any(occupied[j] for j in range(k + 1, len(block_of)) if block_of[j] == b):
            result.append((-1, alsn.NO_CODE))
            continue
        ahead = next((n for n in range(b + 1, blocks) if block_occ[n]), None)
        free = None if ahead is None else ahead - b - 1
        if free == 0:
            code = sig.RED_YELLOW
        elif free == 1:
            code = sig.YELLOW
        else:
            code = sig.GREEN
        result.append((free, code))
    return result


def test_block_rules_match_the_rules_written_out_for_every_occupancy_of_the_throat_line():
    block_of = _throat().block_of_section
    for pattern in itertools.product((False, True), repeat=len(block_of)):
        rules = block_codes(np.array(pattern), block_of)
        for k, (free, code) in enumerate(_reference(pattern, block_of)):
            assert rules.alsn_code[k] == code, (pattern, k)
            if free is not None:
                assert rules.free_blocks[k] == free, (pattern, k)
            else:
                assert rules.free_blocks[k] > 100, (pattern, k)


def test_a_circuit_behind_an_occupied_circuit_of_its_block_is_cut_and_the_exit_signal_is_not():
    block_of = _throat().block_of_section
    occ = np.zeros(8, dtype=bool)
    occ[[3, 5]] = True              # the train in circuit "4", a broken rail in circuit "6"
    rules = block_codes(occ, block_of)
    assert rules.coded.tolist() == [True, True, True, False, False, True, True, True]
    assert rules.alsn_code[3:6].tolist() == [alsn.NO_CODE, alsn.NO_CODE, sig.GREEN]
    assert rules.free_blocks[3] == NO_CODE_FREE_BLOCKS
    assert rules.signal[:3].tolist() == [SIGNAL_GREEN, SIGNAL_YELLOW, SIGNAL_RED]


def _occupancies_with_an_occupied_circuit_ahead_in_the_block(block_of):
    """Every occupancy of the line, with the circuits that have an occupied circuit further on
    in their own block."""
    for pattern in itertools.product((False, True), repeat=len(block_of)):
        behind = [k for k, b in enumerate(block_of)
                  if any(pattern[j] for j in range(k + 1, len(block_of)) if block_of[j] == b)]
        if behind:
            yield np.array(pattern), behind


def test_the_alsn_coder_never_sends_green_or_yellow_behind_an_occupied_circuit_of_the_same_block():
    line = _throat()
    for aspects in (3, 4):
        coder = WaysideCoderCore(line, 8, N, CoderSettings(block_aspects=aspects))
        for occ, behind in _occupancies_with_an_occupied_circuit_ahead_in_the_block(line.block_of_section):
            codes = coder.step(0.0, occ).code_tx
            assert all(codes[k] == alsn.NO_CODE for k in behind), (occ, behind, codes[:8])


@pytest.mark.parametrize("name", ["ALS-EN", "FIRE_DQPSK"])
def test_the_digital_coder_sends_nothing_behind_an_occupied_circuit_of_the_same_block(name):
    line = _throat()
    system = cab_systems.digital_system(name)
    coder = DigitalCoderCore(system, line, 8, N, CoderSettings())
    t = 0.0
    for occ, behind in _occupancies_with_an_occupied_circuit_ahead_in_the_block(line.block_of_section):
        out = coder.step(t, occ)
        t += N / coder.settings.fs_hz
        assert all(out.code_tx[k] == 0 for k in behind), (occ, behind, out.code_tx[:8])
    # the circuit itself stays silent for as long as the circuit ahead is occupied
    occ = np.zeros(8, dtype=bool)
    occ[[3, 5]] = True
    for _ in range(200):                        # 2 s: the generator's filter has rung down
        out = coder.step(t, occ)
        t += N / coder.settings.fs_hz
    assert out.code_tx[3] == 0 and np.abs(out.u_tx[3]).max() < 1e-3 * coder.settings.amplitude_v
    assert out.code_tx[5] != 0 and np.abs(out.u_tx[5]).max() > 0.5 * coder.settings.amplitude_v
