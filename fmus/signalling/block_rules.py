"""Block rules of the automatic block: from the occupancy of the track circuits, the aspect of
each block signal and the code each track circuit may carry (no FMI here).

One function, :func:`block_codes`, used by the ALSN coder, the digital coder and the run's
verdict against the track (orchestrator/verdicts/verdict.py), so that what the coders send and
what the verdict allows are one rule (docs/wayside_coder.md#block-rules).

* A **block** is the run of track circuits from one block signal to the next: circuits whose
  line entry names no signal (``"signal": ""``) belong to the block of the circuits after them,
  up to the circuit with the exit signal (the line's ``block_of_section``).
* A block is **occupied** when any of its track circuits is (a failed circuit, e.g. a broken
  rail, drops its relay and counts as occupied).
* The **exit signal** of a block shows red when the next block is occupied, yellow when the
  one after is, yellow-green (4-aspect block) when the third is, else green. Beyond the last
  modelled circuit the line is taken as free.
* A **track circuit's code** follows its block's exit signal (red → КЖ, yellow → Ж, green and
  yellow-green → З) — unless a track circuit further on in the same block is occupied: then
  it carries **no code**. In coded automatic block the code of a circuit without its own
  signal is relayed through the front contacts of the track relay of the circuit ahead, so a
  dropped relay ahead cuts it. The sources in docs/sources.md do not state this relaying; we
  take the restrictive reading [U]: nothing permissive may reach a train behind an occupied or
  failed circuit; without code the cab shows white, as on track not equipped
  (docs/sources.md#alsn-carriers-and-aspects #3). docs/wayside_coder.md#block-rules.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fmus.signalling import alsn
from fmus.signalling import aspects as sig

SIGNAL_DARK, SIGNAL_RED, SIGNAL_YELLOW, SIGNAL_YELLOW_GREEN, SIGNAL_GREEN = 0, 1, 2, 3, 4
#: a block signal's aspects; dark: no signal at the section's exit (a track circuit inside a block)
SIGNAL_NAMES = {SIGNAL_DARK: "no signal", SIGNAL_RED: "red", SIGNAL_YELLOW: "yellow",
                SIGNAL_YELLOW_GREEN: "yellow-green", SIGNAL_GREEN: "green"}
NO_CODE_FREE_BLOCKS = -1        # free_blocks of a circuit whose code is cut
LINE_FREE_BLOCKS = 1 << 20      # "no occupied block ahead within the modelled line"
#: ALSN code keyed for the exit signal's aspect (yellow-green as З [U]: docs/wayside_coder.md)
ALSN_CODE_OF_SIGNAL = np.array([alsn.NO_CODE, sig.RED_YELLOW, sig.YELLOW, sig.GREEN, sig.GREEN])


@dataclass(frozen=True)
class BlockCodes:
    """Per track circuit (arrays of the circuit count)."""

    signal: np.ndarray        # aspect of the exit signal of the circuit's block (SIGNAL_*)
    free_blocks: np.ndarray   # free blocks ahead of the circuit's own block; NO_CODE_FREE_BLOCKS when cut
    coded: np.ndarray         # False: an occupied circuit further on in the same block cuts the code
    alsn_code: np.ndarray     # the ALSN code the circuit may carry (alsn.NO_CODE when cut)


def block_codes(occupied, block_of, block_aspects: int = 3) -> BlockCodes:
    """The block rules (module docstring) for ``occupied`` (bool per track circuit) on a line
    whose circuit k belongs to block ``block_of[k]`` (non-decreasing, from 0)."""
    occ = np.asarray(occupied, dtype=bool)
    block_of = np.asarray(block_of, dtype=np.int64)
    count = occ.size
    blocks = int(block_of[-1]) + 1 if count else 0
    block_occupied = np.zeros(blocks + 1, dtype=bool)            # + one free block beyond the line
    np.logical_or.at(block_occupied, block_of, occ)
    # first occupied block at or after each block; counted from the next block for a circuit
    index = np.where(block_occupied, np.arange(blocks + 1), LINE_FREE_BLOCKS)
    next_occupied_block = np.minimum.accumulate(index[::-1])[::-1]
    blocks_ahead = next_occupied_block[np.minimum(block_of + 1, blocks)] - block_of   # 1: the next block
    # first occupied circuit strictly ahead of each circuit: cut when it lies in the same block
    circuit_index = np.where(np.append(occ, False), np.arange(count + 1), count)
    next_occupied_circuit = np.minimum.accumulate(circuit_index[::-1])[::-1][1:]
    coded = ~((next_occupied_circuit < count)
              & (block_of[np.minimum(next_occupied_circuit, count - 1)] == block_of))
    signal = np.full(count, SIGNAL_GREEN, dtype=np.int64)
    signal[blocks_ahead == 1] = SIGNAL_RED
    signal[blocks_ahead == 2] = SIGNAL_YELLOW
    if block_aspects == 4:
        signal[blocks_ahead == 3] = SIGNAL_YELLOW_GREEN
    free_blocks = np.where(coded, np.minimum(blocks_ahead - 1, LINE_FREE_BLOCKS), NO_CODE_FREE_BLOCKS)
    alsn_code = np.where(coded, ALSN_CODE_OF_SIGNAL[signal], alsn.NO_CODE)
    return BlockCodes(signal, free_blocks, coded, alsn_code)
