"""TVM-430, the French high-speed cab signal: a 27-bit word per block, one very-low modulation
tone per bit on the block's audio-frequency carrier (docs/sources.md#tvm-430;
docs/wayside_coder.md#tvm-430, docs/loco_receiver.md#tvm-430). No FMI and no filtering here: the
word's layout and check, the field tables (fmus/signalling/tvm430_codes.json, replaceable with a
coder's or receiver's ``codes_file``), the tones and the carrier's modulation phase, what a word
means to the cab, and the block rules' word of every block.

* **Word** (bits 26…0) [S]: 26–24 network address, 23–16 speed, 15–10 distance to target, 9–6
  gradient, 5–0 error detection. The check is ours [U]: a CRC with the generator
  x⁶+x⁵+x³+x²+x+1 = (x+1)(x⁵+x²+1) over bits 26–6, xor :data:`CHECK_XOR` — minimum distance 4 over
  the 27 bits, so every single, double and triple bit error is detected
  (tests/test_tvm430_word.py counts it); the xor makes the all-zero word (a carrier without
  tones) and the all-one word fail.
* **Tones** [S]: bit k ↔ f_k = 0.88 + 0.64·k Hz (0.88…17.52 Hz); a tone present is a 1.
* **Modulation** [U: the sources say FM for the UM71 carriers, not how 27 tones share it]: the
  carrier's instantaneous frequency is f_c + DEVIATION_HZ_PER_TONE·Σ_{k present} cos(2π f_k t + φ_k)
  with Newman phases φ_k = πk²/27, so a full word peaks near ±7 Hz, within UM71's ±11 Hz shift.
  Its phase is the closed form 2π f_c t + Σ_k b_k·(Δ/f_k)·sin(2π f_k t + φ_k): a coder adds the
  bits' rows of :func:`modulation_phase_terms` (one matrix product per frame for every block).
* **Meaning** (our reading of the thesis' Fig. 1.5 [U]): the speed field is a pair (the cab's
  step, the next step) of 300 – 270 – 230 – 170 – 0 km/h, each supervised at its control level
  (step + 15 km/h: 315 / 285 / 245 / 185 / 15) [S: 315, 285, 185 on the figure]; the distance to
  target counts from the entry of the word's block, in 250 m steps rounded down; the gradient is
  the most falling one between the block's entry and the target, rounded down to the table.
* **Block rules** [U]: n free blocks ahead of a block before the first occupied one → the stop
  target is the entry of the last free block (the buffer section before the occupied block) —
  or the line's last station stop when nearer — and m, the blocks from here that begin before
  the target, gives the speed pair: m ≥ 5 300/300, 4 300/270, 3 270/230, 2 230/170, 1 170/0,
  0 0/0; each step capped by the line's limit. A train closing on another is slowed
  300 → 270 → 230 → 170 → 0 block by block.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

import numpy as np

from fmus.data.loader import read_json_file
from fmus.errors import FmuInputError
from fmus.signalling import aspects as sig
from fmus.signalling import um71
from fmus.signalling.digital_messages import Indication

NAME = "TVM430"
CODES_FILE = Path(__file__).resolve().parent / "tvm430_codes.json"
WORD_BITS = 27
TONE_COUNT = WORD_BITS
TONE_FIRST_HZ, TONE_SPACING_HZ = 0.88, 0.64
TONES_HZ = TONE_FIRST_HZ + TONE_SPACING_HZ * np.arange(TONE_COUNT)
#: Newman phases: the 27 tones' sum peaks near 7.06 instead of 27 (crest 1.92)
TONE_PHASES_RAD = np.pi * np.arange(TONE_COUNT) ** 2 / TONE_COUNT
DEVIATION_HZ_PER_TONE = 1.0
#: the fields: name → (lowest bit, width)
FIELDS = {"address": (24, 3), "speed": (16, 8), "distance": (10, 6), "gradient": (6, 4), "check": (0, 6)}
CHECK_GENERATOR = 0b1101111          # x⁶ + x⁵ + x³ + x² + x + 1
CHECK_XOR = 0b101101
DATA_BITS = WORD_BITS - FIELDS["check"][1]
#: carriers per track, alternating block by block [S] (the UM71 circuits', um71.py)
TRACK_CARRIERS_HZ = um71.TRACK_CARRIERS_HZ
CARRIERS_HZ = um71.CARRIERS_HZ
NO_WORD = 0
FREE_BLOCKS_OPEN = 6                 # the `free_blocks` reported for "no target in range"

# ---- the decoder rules (ours [U]; docs/loco_receiver.md#tvm-430): what the receiver
# (fmus/loco_receiver/tvm430.py) decides on and the times it states ---------------------------
#: the 27 tones are 0.64 Hz apart: 1.5625 s is the shortest window resolving them
WINDOW_S = 1.0 / TONE_SPACING_HZ
HOP_S = 0.125                     # one decision every 0.125 s
#: the hold (3.5 s), stated latency (5.19 s) and decode time (1.82 s), by the rule of
#: um71.decoder_times
#: measured: a lost carrier 3.5 s, every single- and double-bit corruption 4.4 s at worst
#: (tests/test_tvm430_receiver.py, benchmarks/tvm430_decode.py); a carrier starting anywhere in
#: a hop shown 1.69–1.818 s after at 0.1 V, a change 1.25–1.75 s (docs/loco_receiver.md#tvm-430)
HOLD_S, STATED_LATENCY_S, STATED_DECODE_S = um71.decoder_times(WINDOW_S, HOP_S)


def check_bits(data: int) -> int:
    """The 6 check bits of the 21 data bits (the word's bits 26–6, ``data`` right-aligned)."""
    register = 0
    for i in range(DATA_BITS - 1, -1, -1):
        feedback = ((data >> i) & 1) ^ ((register >> 5) & 1)
        register = (register << 1) & 0x3F
        if feedback:
            register ^= CHECK_GENERATOR & 0x3F
    return register ^ CHECK_XOR


def field(word: int, name: str) -> int:
    low, width = FIELDS[name]
    return (word >> low) & ((1 << width) - 1)


def assemble(address: int, speed: int, distance: int, gradient: int) -> int:
    """The 27-bit word with its check bits."""
    data = 0
    for name, value in (("address", address), ("speed", speed), ("distance", distance), ("gradient", gradient)):
        low, width = FIELDS[name]
        if not 0 <= value < (1 << width):
            raise ValueError(f"{name} field {value} does not fit {width} bits")
        data |= value << (low - FIELDS["check"][1])
    return (data << FIELDS["check"][1]) | check_bits(data)


def check_passes(word: int) -> bool:
    return 0 <= word < (1 << WORD_BITS) and check_bits(word >> FIELDS["check"][1]) == field(word, "check")


def bits_of(word: int) -> np.ndarray:
    """(27,) 0/1 floats: bit k of the word, k = 0 (tone 0.88 Hz) … 26."""
    return ((word >> np.arange(WORD_BITS)) & 1).astype(float)


def word_of_bits(bits: Sequence[int]) -> int:
    return int(sum(int(b) << k for k, b in enumerate(bits)))


def modulation_phase_terms(times_s: np.ndarray, out: Optional[np.ndarray] = None) -> np.ndarray:
    """(27, n) phase (rad) each tone adds to the carrier at ``times_s`` when its bit is 1:
    (Δ/f_k)·sin(2π f_k t + φ_k), the integral of 2π·Δ·cos(2π f_k t + φ_k)."""
    angle = np.multiply.outer(2 * np.pi * TONES_HZ, times_s, out=out)
    angle += TONE_PHASES_RAD[:, None]
    np.sin(angle, out=angle)
    angle *= (DEVIATION_HZ_PER_TONE / TONES_HZ)[:, None]
    return angle


def frequency_deviation(word: int, times_s: np.ndarray) -> np.ndarray:
    """The carrier's frequency offset (Hz) a word makes at ``times_s`` (what a discriminator
    should recover): Δ·Σ_{k present} cos(2π f_k t + φ_k)."""
    angle = np.multiply.outer(2 * np.pi * TONES_HZ, times_s) + TONE_PHASES_RAD[:, None]
    return DEVIATION_HZ_PER_TONE * (bits_of(word) @ np.cos(angle))


@dataclass(frozen=True)
class Reading:
    """What a word that passed its check means to the cab."""

    word: int
    step_kmh: float             # the cab's speed step now
    next_kmh: float             # the step announced for the next block
    control_kmh: float          # trip level of the step
    target_distance_m: float    # from the entry of the word's block to the target point
    no_target: bool             # the distance is the largest code: no target nearer
    gradient_permille: float    # most falling gradient up to the target, + uphill
    aspect: int
    free_blocks: int


@dataclass(frozen=True)
class CodeTable:
    path: Path
    addresses: Tuple[int, ...]
    steps_kmh: Tuple[float, ...]                      # fastest first
    control_margin_kmh: float
    speed_codes: Dict[int, Tuple[float, float]]      # field value → (step, next step)
    distance_step_m: float
    distance_codes: int
    gradient_permille: Tuple[float, ...]             # ascending, 16 values

    def speed_code(self, step_kmh: float, next_kmh: float) -> int:
        for code, pair in self.speed_codes.items():
            if pair == (step_kmh, next_kmh):
                return code
        raise FmuInputError(f"{self.path}: field speed_codes: no code for step {step_kmh:g} km/h with next "
                            f"{next_kmh:g} km/h, which the block rules send")

    def distance_code(self, distance_m: float) -> int:
        """Rounded down (a target never announced farther than it is); the largest code for
        that far or farther."""
        return int(min(max(np.floor(distance_m / self.distance_step_m + 1e-9), 0), self.distance_codes - 1))

    def gradient_code(self, permille: float) -> int:
        """The largest table value not above ``permille`` (the steepest value for a gradient
        steeper than the table)."""
        values = np.asarray(self.gradient_permille)
        return int(max(np.searchsorted(values, permille + 1e-9, side="right") - 1, 0))

    def control_kmh(self, step_kmh: float) -> float:
        return step_kmh + self.control_margin_kmh


def load_codes(path=CODES_FILE) -> CodeTable:
    """The word tables, every error one FmuInputError naming the file and the field."""
    path = Path(path)
    doc = read_json_file(path)

    def fail(name: str, message: str):
        raise FmuInputError(f"{path}: field {name}: {message}")

    if not isinstance(doc, dict):
        fail("(top level)", "expected an object with addresses, steps_kmh, speed_codes, …")
    addresses = doc.get("addresses")
    if not isinstance(addresses, list) or not addresses or any(
            not isinstance(a, int) or isinstance(a, bool) or not 0 < a < 8 for a in addresses):
        fail("addresses", "expected a list of network addresses 1…7 (3 bits, not 0)")
    steps, margin = um71.read_steps_and_margin(doc, fail)
    speed_doc = doc.get("speed_codes")
    if not isinstance(speed_doc, dict) or not speed_doc:
        fail("speed_codes", "missing or not an object")
    speed_codes = {}
    for key, pair in speed_doc.items():
        where = f"speed_codes.{key}"
        if not key.isdigit() or not 0 < int(key) < 256:
            fail(where, "field values are 1…255 (8 bits, not 0)")
        if not isinstance(pair, list) or len(pair) != 2 or any(v not in steps for v in pair) or pair[1] > pair[0]:
            fail(where, "expected [step km/h, next step km/h], both of steps_kmh, the next not above the step")
        speed_codes[int(key)] = (float(pair[0]), float(pair[1]))
    if len(set(speed_codes.values())) != len(speed_codes):
        fail("speed_codes", "two field values for the same pair of steps")
    step_m = doc.get("distance_step_m")
    if not um71.is_number(step_m) or step_m <= 0:
        fail("distance_step_m", "must be a length in m above 0")
    codes = doc.get("distance_codes")
    if not isinstance(codes, int) or isinstance(codes, bool) or not 2 <= codes <= 64:
        fail("distance_codes", "must be a whole number 2…64 (6 bits)")
    gradients = doc.get("gradient_permille")
    if not isinstance(gradients, list) or len(gradients) != 16 or any(not um71.is_number(g) for g in gradients) \
            or any(b <= a for a, b in zip(gradients, gradients[1:])):
        fail("gradient_permille", "expected 16 gradients in ‰, rising")
    return CodeTable(path, tuple(addresses), tuple(float(s) for s in steps), float(margin), speed_codes,
                     float(step_m), codes, tuple(float(g) for g in gradients))


class Tvm430System:
    """The word tables with what a word means to the cab and which of two is more restrictive."""

    name = NAME

    def __init__(self, table: Optional[CodeTable] = None):
        self.table = table or load_codes()
        # the speed pair of each m (blocks before the target): (0, 0), (170, 0) … (300, 270), and
        # last the pair of no target in range (300, 300)
        steps = self.table.steps_kmh
        last = len(steps) - 1
        self.pair_of_blocks = ([(0.0, 0.0)] + [(steps[last - m], steps[last - m + 1]) for m in range(1, last + 1)]
                               + [(steps[0], steps[0])])
        # every pair the block rules send on some line (BlockWords.word: a block's step capped by
        # its limit, the next step by the next block's) → the fewest blocks before the target
        # that give it: a receiver reports that many free blocks (the restrictive reading where
        # a cap makes two counts send the same pair)
        self.blocks_of_pair: Dict[Tuple[float, float], int] = {}
        caps = [c for c in steps if c > 0]
        for m, (step, following) in enumerate(self.pair_of_blocks):
            for cap in caps:
                for cap_next in caps:
                    pair = (min(step, cap), min(following, step, cap, cap_next))
                    self.blocks_of_pair[pair] = min(self.blocks_of_pair.get(pair, m), m)
        for code, pair in self.table.speed_codes.items():
            if pair not in self.blocks_of_pair:
                raise FmuInputError(f"{self.table.path}: field speed_codes.{code}: {pair[0]:g}/{pair[1]:g} km/h is a pair "
                                    "the block rules never send (a step falls to 0 only from the lowest step): "
                                    "a receiver must not show a word no wayside sends")

    def reading(self, word: int) -> Optional[Reading]:
        """The word's meaning, None for a word that fails its check, carries an address not
        accepted, or an unused field value."""
        if word == NO_WORD or not check_passes(word):
            return None
        t = self.table
        if field(word, "address") not in t.addresses:
            return None
        pair = t.speed_codes.get(field(word, "speed"))
        distance = field(word, "distance")
        if pair is None or distance >= t.distance_codes:
            return None
        step, following = pair
        no_target = distance == t.distance_codes - 1 and following == step
        if step == 0:
            aspect = sig.RED
        elif following < step:
            aspect = sig.YELLOW
        else:
            aspect = sig.GREEN
        blocks = FREE_BLOCKS_OPEN if no_target else self.blocks_before_target(step, following)
        return Reading(word, step, following, t.control_kmh(step), distance * t.distance_step_m, no_target,
                       t.gradient_permille[field(word, "gradient")], aspect, blocks)

    def command_of_code(self, code: int) -> Optional[int]:
        """The word a coder's raw ``code_tx`` stands for; None for no word or one a receiver
        cannot read (the verdicts' reading, as for the other systems)."""
        return None if self.reading(int(code)) is None else int(code)

    def indication(self, word: int, category: str) -> Indication:
        """The word as the other systems' indications (the same for every train category: TVM
        steps are the line's, for the high-speed trains it is built for)."""
        read = self.reading(word)
        return Indication(word, read.aspect, read.free_blocks, read.step_kmh, read.next_kmh)

    def blocks_before_target(self, step_kmh: float, next_kmh: float) -> int:
        """The fewest blocks before the target that make the block rules send this pair (the
        free blocks a receiver reports for a word with a target)."""
        return self.blocks_of_pair[(step_kmh, next_kmh)]

    def at_most(self, a: int, b: int) -> bool:
        """Whether word ``a`` (of the same block as ``b``) permits nothing that ``b`` does not: no
        field more permissive — step, next step, target distance, and the gradient (a less
        falling one lengthens no braking curve). A partial order: a nearer target on a less falling
        gradient can give a higher braking curve than a farther one on a steeper fall, so such
        words are not comparable (neither is at most the other). A word that is not read is at
        most anything."""
        read_a, read_b = self.reading(a), self.reading(b)
        if read_a is None:
            return True
        if read_b is None:
            return False
        return (read_a.step_kmh <= read_b.step_kmh and read_a.next_kmh <= read_b.next_kmh
                and read_a.target_distance_m <= read_b.target_distance_m
                and read_a.gradient_permille <= read_b.gradient_permille)

    def block_coding(self, line, block_aspects: int = 0) -> "BlockWords":
        """The block rules' word of every track circuit of ``line`` (the verdicts' and the
        headway's reading of what the coder sends; TVM has no block aspects setting)."""
        return BlockWords(line, self)

    def shows_beyond(self, word: int, shown) -> bool:
        """Whether the receiver outputs ``shown`` (``target_distance`` m, ``gradient`` ‰: the
        descriptor's judged outputs) permit more than ``word`` does in the fields the common
        checks leave out: a target farther (beyond 1 m of rounding) or a gradient less falling."""
        read = self.reading(word)
        return (float(shown["target_distance"]) > read.target_distance_m + 1.0
                or float(shown["gradient"]) > read.gradient_permille + 1e-6)


SYSTEM = None      # the shipped table's system, made on first use (system())


def system(table_path=None) -> Tvm430System:
    global SYSTEM
    if table_path:
        return Tvm430System(load_codes(table_path))
    if SYSTEM is None:
        SYSTEM = Tvm430System()
    return SYSTEM


class BlockWords:
    """The word of every track circuit from the block states and the line (module docstring):
    the coder sends it and the verdict judges against it, so the two are one rule."""

    def __init__(self, line, tvm: Tvm430System, address: Optional[int] = None):
        self.tvm, self.line = tvm, line
        table = tvm.table
        self.address = table.addresses[0] if address is None else address
        if self.address not in table.addresses:
            raise FmuInputError(f"parameter address: {self.address} is not one of {table.path.name}'s addresses "
                                f"{', '.join(map(str, table.addresses))}")
        self.block_of = np.asarray(line.block_of_section, dtype=np.int64)
        self.block_starts = np.array([start for start, _ in line.block_bounds])
        blocks = len(line.block_bounds)
        # the line's last station stop: a target of 0 for every block beginning before it
        self.final_stop_m = max(s.stop_m for s in line.stations) if line.stations else line.length_m
        self.blocks_to_final = np.array([int(np.count_nonzero(self.block_starts[b:] < self.final_stop_m - 1e-9))
                                         for b in range(blocks)])
        # each block's step cap from the line's limit (high-speed column) over the block
        caps = []
        for start, end in line.block_bounds:
            limit_kmh = min(line.speed_limit_mps(x, "high_speed") * 3.6 for x in self._limit_points(start, end))
            cap = max([s for s in table.steps_kmh if s <= limit_kmh + 1e-6], default=0.0)
            if cap == 0.0:
                raise FmuInputError(f"{line.path}: field speed_limits: {limit_kmh:g} km/h at {start:g} m is below "
                                    f"{table.path.name}'s lowest step {table.steps_kmh[-2]:g} km/h: TVM-430 cannot "
                                    "signal it (add a step to the word tables)")
            caps.append(cap)
        self.cap_kmh = np.array(caps)
        self._cache: Dict[Tuple[int, int], int] = {}

    def _limit_points(self, start: float, end: float) -> List[float]:
        line = self.line
        return [start] + [s for s in line.limit_starts if start < s < end]

    def _gradient_down_to(self, start: float, end: float) -> float:
        """The most falling gradient (‰, + uphill) over [start, end]."""
        line = self.line
        points = [start] + [s for s in line.gradient_starts if start < s < end]
        return min(line.gradient_at(x) for x in points)

    def word(self, block: int, free_blocks: int) -> int:
        """The word of a block with ``free_blocks`` free blocks ahead before an occupied one
        (block_rules.LINE_FREE_BLOCKS: none within the line)."""
        key = (block, int(min(free_blocks, FREE_BLOCKS_OPEN + 1)))
        cached = self._cache.get(key)
        if cached is not None:
            return cached
        table, pairs = self.tvm.table, self.tvm.pair_of_blocks
        start = float(self.block_starts[block])
        by_occupancy = key[1]
        if by_occupancy <= FREE_BLOCKS_OPEN and by_occupancy < self.blocks_to_final[block]:
            blocks_before = by_occupancy                     # the buffer block's entry
            target_m = float(self.block_starts[block + by_occupancy]) if by_occupancy else start
        else:
            blocks_before = int(self.blocks_to_final[block])
            target_m = self.final_stop_m if blocks_before else start
        step, following = pairs[min(blocks_before, len(pairs) - 1)]
        cap = self.cap_kmh[block]
        cap_next = self.cap_kmh[min(block + 1, len(self.cap_kmh) - 1)]
        step = min(step, cap)
        following = min(following, step, cap_next)
        no_target = blocks_before >= len(pairs) - 1
        distance = (table.distance_codes - 1) if no_target else table.distance_code(target_m - start)
        reach = start + max(distance * table.distance_step_m, float(self.line.block_bounds[block][1] - start))
        gradient = table.gradient_code(self._gradient_down_to(start, min(reach, self.line.length_m)))
        word = assemble(self.address, table.speed_code(step, following), distance, gradient)
        self._cache[key] = word
        return word

    def words(self, free_blocks: np.ndarray, coded: np.ndarray) -> np.ndarray:
        """The word of every track circuit (block_rules.BlockCodes' free_blocks and coded); a
        circuit whose code is cut sends the stop word (TVM's carrier never stops: it detects)."""
        out = np.empty(self.block_of.size, dtype=np.int64)
        for k, (block, free, ok) in enumerate(zip(self.block_of.tolist(), free_blocks.tolist(), coded.tolist())):
            out[k] = self.word(block, free if ok else 0)
        return out

    def codes(self, rules) -> np.ndarray:
        """The word of every track circuit under block_rules.BlockCodes ``rules`` (the verdicts'
        call, as alsu.BlockCoding.codes)."""
        return self.words(rules.free_blocks, rules.coded)
