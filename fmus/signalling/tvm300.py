"""TVM-300, the first French high-speed cab signal: one low modulation sub-frequency at a time on
the block's UM71 carrier, the sub-frequency giving a speed code (docs/sources.md#tvm-300;
docs/wayside_coder.md#tvm-300, docs/loco_receiver.md#tvm-300). No FMI and no filtering here: the
sub-frequencies and the carrier's modulation, the code table (fmus/signalling/tvm300_codes.json,
replaceable with a coder's or receiver's ``codes_file``), what a code means to the cab, the
block rules' code of every block, and the decoder rules' times.

* **Sub-frequencies** [S: 18 over 10.3…29 Hz, one active at a time, 14 used; D: equally spaced]:
  f_k = 10.3 + 1.1·k Hz, k = 0…17. The code sent and shown is k + 1 (1…18), 0 no code.
* **Modulation** [U: the sources say FM, not the shift or the waveform]: the carrier's
  instantaneous frequency is f_c + DEVIATION_HZ·cos θ(t), θ the active sub-frequency's phase,
  θ' = 2π f_k; a coder changes f_k without a jump of θ or of the carrier's phase
  (fmus/wayside_coder/tvm300.py). DEVIATION_HZ = 11 Hz, the shift TVM-430's modulation is sized
  to stay within (docs/wayside_coder.md#tvm-430).
* **Meaning** [U]: a code is a pair (the step in force to the block's end, the step to be
  reached at its end: the next block's) of the table's steps 300 – 270 – 220 – 160 – 80 – 0 km/h,
  each supervised at step + control_margin_kmh (15 km/h, TVM-430's control level).
* **Block rules** [U], the cascade: m free blocks ahead of a block before the first occupied
  one (block_rules' free_blocks) — or the blocks to the line's last station stop when fewer —
  gives 0 → 0/0 (the buffer block), 1 → 80/0, 2 → 160/80, 3 → 220/160, 4 → 270/220,
  5 → 300/270, 6 or more → 300/300; each step capped by the line's limit over the block (the
  largest step not above it), the next by the step and the next block's cap. A circuit whose
  code is cut sends 0/0 (the carrier never stops: it detects). A pair the table has no
  sub-frequency for is refused when the line is read (FmuInputError naming line, block, pair).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np

from fmus.data.loader import read_json_file
from fmus.errors import FmuInputError
from fmus.signalling import aspects as sig
from fmus.signalling import um71
from fmus.signalling.digital_messages import Indication

NAME = "TVM300"
CODES_FILE = Path(__file__).resolve().parent / "tvm300_codes.json"
SUB_FREQUENCY_COUNT = 18
SUB_FREQUENCY_FIRST_HZ, SUB_FREQUENCY_LAST_HZ = 10.3, 29.0
SUB_FREQUENCY_SPACING_HZ = (SUB_FREQUENCY_LAST_HZ - SUB_FREQUENCY_FIRST_HZ) / (SUB_FREQUENCY_COUNT - 1)   # 1.1 Hz
SUB_FREQUENCIES_HZ = SUB_FREQUENCY_FIRST_HZ + SUB_FREQUENCY_SPACING_HZ * np.arange(SUB_FREQUENCY_COUNT)
#: the carrier's peak frequency deviation (Hz) [U]
DEVIATION_HZ = 11.0
TRACK_CARRIERS_HZ = um71.TRACK_CARRIERS_HZ
CARRIERS_HZ = um71.CARRIERS_HZ
NO_CODE = 0

# ---- the decoder rules (ours [U]; docs/loco_receiver.md#tvm-300): what the receiver
# (fmus/loco_receiver/tvm300.py) decides on and the times it states ---------------------------
#: the sub-frequencies are 1.1 Hz apart: 0.909 s is the shortest window resolving them
WINDOW_S = 1.0 / SUB_FREQUENCY_SPACING_HZ
HOP_S = 0.1                        # one decision every 0.1 s
#: the hold (2.12 s), stated latency (3.13 s) and decode time (1.12 s), by the rule of
#: um71.decoder_times
HOLD_S, STATED_LATENCY_S, STATED_DECODE_S = um71.decoder_times(WINDOW_S, HOP_S)


def code_of_index(index: int) -> int:
    return int(index) + 1


def index_of_code(code: int) -> int:
    return int(code) - 1


def frequency_deviation(code: int, times_s: np.ndarray, phase_rad: float = 0.0) -> np.ndarray:
    """The carrier's frequency offset (Hz) a code makes at ``times_s`` (what a discriminator
    should recover): Δ·cos(2π f_k t + phase); 0 for no code (a bare carrier)."""
    times_s = np.asarray(times_s, dtype=float)
    if code == NO_CODE:
        return np.zeros_like(times_s)
    return DEVIATION_HZ * np.cos(2.0 * np.pi * SUB_FREQUENCIES_HZ[index_of_code(code)] * times_s + phase_rad)


@dataclass(frozen=True)
class Reading:
    """What a used code means to the cab."""

    code: int
    step_kmh: float             # the step in force to the block's end
    next_kmh: float             # the step to be reached at the block's end
    control_kmh: float          # trip level of the step
    aspect: int
    free_blocks: int            # the fewest blocks before the stop that give the pair


@dataclass(frozen=True)
class CodeTable:
    path: Path
    steps_kmh: Tuple[float, ...]                      # fastest first, ending at 0
    control_margin_kmh: float
    pairs: Dict[int, Tuple[float, float]]             # sub-frequency index → (step, next step)

    def code_of_pair(self, step_kmh: float, next_kmh: float) -> Optional[int]:
        """The code (index + 1) of a pair, None: no sub-frequency for it."""
        for index, pair in self.pairs.items():
            if pair == (step_kmh, next_kmh):
                return code_of_index(index)
        return None

    def control_kmh(self, step_kmh: float) -> float:
        return step_kmh + self.control_margin_kmh


def load_codes(path=CODES_FILE) -> CodeTable:
    """The code table, every error one FmuInputError naming the file and the field."""
    path = Path(path)
    doc = read_json_file(path)

    def fail(name: str, message: str):
        raise FmuInputError(f"{path}: field {name}: {message}")

    if not isinstance(doc, dict):
        fail("(top level)", "expected an object with steps_kmh, control_margin_kmh, sub_frequency_codes")
    steps, margin = um71.read_steps_and_margin(doc, fail)
    codes_doc = doc.get("sub_frequency_codes")
    if not isinstance(codes_doc, dict) or not codes_doc:
        fail("sub_frequency_codes", "missing or not an object")
    pairs: Dict[int, Tuple[float, float]] = {}
    for key, pair in codes_doc.items():
        where = f"sub_frequency_codes.{key}"
        if not key.isdigit() or not 0 <= int(key) < SUB_FREQUENCY_COUNT:
            fail(where, f"sub-frequency indices are 0…{SUB_FREQUENCY_COUNT - 1} "
                        f"({SUB_FREQUENCY_FIRST_HZ:g} + {SUB_FREQUENCY_SPACING_HZ:g}·k Hz)")
        if not isinstance(pair, list) or len(pair) != 2 or any(not um71.is_number(v) or v not in steps for v in pair) \
                or pair[1] > pair[0]:
            fail(where, "expected [step km/h, next step km/h], both of steps_kmh, the next not above the step")
        pairs[int(key)] = (float(pair[0]), float(pair[1]))
    if len(set(pairs.values())) != len(pairs):
        fail("sub_frequency_codes", "two sub-frequencies for the same pair of steps")
    if (0.0, 0.0) not in pairs.values():
        fail("sub_frequency_codes", "no sub-frequency for 0/0, the stop code a circuit whose code is cut sends")
    return CodeTable(path, tuple(float(s) for s in steps), float(margin), dict(sorted(pairs.items())))


class Tvm300System:
    """The code table with what a code means to the cab and which of two is more restrictive."""

    name = NAME

    def __init__(self, table: Optional[CodeTable] = None):
        self.table = table or load_codes()
        steps = self.table.steps_kmh
        last = len(steps) - 1
        # the pair of each m (free blocks before the stop): (0, 0), (80, 0) … (300, 270), and
        # last the pair of no stop in range (300, 300)
        self.pair_of_blocks: List[Tuple[float, float]] = (
            [(0.0, 0.0)] + [(steps[last - m], steps[last - m + 1]) for m in range(1, last + 1)]
            + [(steps[0], steps[0])])
        # every pair the block rules send on some line (a step capped by its block's limit, the
        # next by the next block's) → the fewest m that give it: a receiver reports that many
        # free blocks (the restrictive reading where a cap makes two counts send one pair)
        self.blocks_of_pair: Dict[Tuple[float, float], int] = {}
        caps = [c for c in steps if c > 0]
        for m, (step, following) in enumerate(self.pair_of_blocks):
            for cap in caps:
                for cap_next in caps:
                    pair = (min(step, cap), min(following, step, cap, cap_next))
                    self.blocks_of_pair[pair] = min(self.blocks_of_pair.get(pair, m), m)
        for index, pair in self.table.pairs.items():
            if pair not in self.blocks_of_pair:
                raise FmuInputError(f"{self.table.path}: field sub_frequency_codes.{index}: {pair[0]:g}/{pair[1]:g} km/h "
                                    "is a pair the block rules never send (a step falls to 0 only from the lowest "
                                    "step): a receiver must not show a code no wayside sends")
        self._readings: Dict[int, Reading] = {}
        for index, (step, following) in self.table.pairs.items():
            aspect = sig.RED if step == 0 else (sig.YELLOW if following < step else sig.GREEN)
            code = code_of_index(index)
            self._readings[code] = Reading(code, step, following, self.table.control_kmh(step), aspect,
                                           self.blocks_of_pair[(step, following)])

    def reading(self, code: int) -> Optional[Reading]:
        """The code's meaning, None for no code or an unused sub-frequency."""
        return self._readings.get(int(code))

    def command_of_code(self, code: int) -> Optional[int]:
        """The code a coder's raw ``code_tx`` stands for; None for no code or one a receiver
        cannot read (the verdicts' reading, as for the other systems)."""
        return None if self.reading(int(code)) is None else int(code)

    def indication(self, code: int, category: str) -> Indication:
        """The code as the other systems' indications (the same for every train category)."""
        read = self._readings[int(code)]
        return Indication(int(code), read.aspect, read.free_blocks, read.step_kmh, read.next_kmh)

    def blocks_before_target(self, step_kmh: float, next_kmh: float) -> int:
        """The fewest free blocks before the stop that make the block rules send this pair."""
        return self.blocks_of_pair[(step_kmh, next_kmh)]

    def at_most(self, a: int, b: int) -> bool:
        """Whether code ``a`` permits nothing that ``b`` does not: neither its step nor its next
        step higher (a partial order: 300/220 and 270/270 are not comparable). A code that is not
        read is at most anything."""
        read_a, read_b = self.reading(a), self.reading(b)
        if read_a is None:
            return True
        if read_b is None:
            return False
        return read_a.step_kmh <= read_b.step_kmh and read_a.next_kmh <= read_b.next_kmh

    def block_coding(self, line, block_aspects: int = 0) -> "BlockCoding":
        """The block rules' code of every track circuit of ``line`` (the verdicts' and the
        headway's reading of what the coder sends; TVM has no block aspects setting)."""
        return BlockCoding(line, self)


SYSTEM = None      # the shipped table's system, made on first use (system())


def system(table_path=None) -> Tvm300System:
    global SYSTEM
    if table_path:
        return Tvm300System(load_codes(table_path))
    if SYSTEM is None:
        SYSTEM = Tvm300System()
    return SYSTEM


class BlockCoding:
    """The code of every track circuit from the block states and the line (module docstring):
    the coder sends it and the verdict judges against it, so the two are one rule. Every code
    any block can need is worked out here, so a line the table cannot signal is refused at
    once."""

    def __init__(self, line, tvm: Tvm300System):
        self.tvm, self.line = tvm, line
        table = tvm.table
        pairs = tvm.pair_of_blocks
        self.open_blocks = len(pairs) - 1                # m from which on: no stop in range
        self.block_of = np.asarray(line.block_of_section, dtype=np.int64)
        starts = np.array([start for start, _ in line.block_bounds])
        blocks = len(line.block_bounds)
        # the line's last station stop: the stop of every block beginning before it
        final_stop_m = max(s.stop_m for s in line.stations) if line.stations else line.length_m
        blocks_to_final = [int(np.count_nonzero(starts[b:] < final_stop_m - 1e-9)) for b in range(blocks)]
        caps = []
        for start, end in line.block_bounds:
            points = [start] + [s for s in line.limit_starts if start < s < end]
            limit_kmh = min(line.speed_limit_mps(x, "high_speed") * 3.6 for x in points)
            cap = max([s for s in table.steps_kmh if s <= limit_kmh + 1e-6], default=0.0)
            if cap == 0.0:
                raise FmuInputError(f"{line.path}: field speed_limits: {limit_kmh:g} km/h at {start:g} m is below "
                                    f"{table.path.name}'s lowest step {table.steps_kmh[-2]:g} km/h: TVM-300 cannot "
                                    "signal it (add a step to the code table)")
            caps.append(cap)
        # code[b, m]: block b with m free blocks ahead (m = open_blocks: none in range)
        self.code = np.zeros((blocks, self.open_blocks + 1), dtype=np.int64)
        for b, (start, end) in enumerate(line.block_bounds):
            cap, cap_next = caps[b], caps[min(b + 1, blocks - 1)]
            for m in range(self.open_blocks + 1):
                step, following = pairs[min(m, blocks_to_final[b], self.open_blocks)]
                step = min(step, cap)
                following = min(following, step, cap_next)
                code = table.code_of_pair(step, following)
                if code is None:
                    raise FmuInputError(f"{line.path}: block {b + 1} ({start:g}–{end:g} m): the block rules send "
                                        f"{step:g}/{following:g} km/h there, which has no sub-frequency in "
                                        f"{table.path.name} (field sub_frequency_codes)")
                self.code[b, m] = code

    def codes_of(self, free_blocks: np.ndarray, coded: np.ndarray) -> np.ndarray:
        """The code of every track circuit (block_rules.BlockCodes' free_blocks and coded); a
        circuit whose code is cut sends the stop code 0/0."""
        m = np.where(coded, np.clip(free_blocks, 0, self.open_blocks), 0)
        return self.code[self.block_of, m]

    def codes(self, rules) -> np.ndarray:
        """The code of every track circuit under block_rules.BlockCodes ``rules`` (the verdicts'
        call, as tvm430.BlockWords.codes)."""
        return self.codes_of(rules.free_blocks, rules.coded)
