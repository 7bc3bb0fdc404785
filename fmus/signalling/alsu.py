"""ALSU, the unified frequency cab signal: a code is two continuous tones out of six
(docs/sources.md#alsu; docs/wayside_coder.md#alsu, docs/loco_receiver.md#alsu). No FMI and
no signal processing here: the code table (fmus/signalling/alsu_codes.json, replaceable with a
coder's or receiver's ``codes_file``), what each code means per train category, and the block
rules' ALSU code of every track circuit.

* **Tones** f2…f7 = 125 … 375 Hz, 50 Hz apart: odd multiples of 25 Hz, between the even
  harmonics of 50 Hz that DC traction makes and the odd ones of AC traction [S]. Two of six
  give 15 codes; which pair is which code is not in the sources [U]: the table orders the pairs
  by the sum of their tone numbers, the restrictive codes on the low tones, which the rails
  carry best (the rails' impedance grows with frequency, docs/rail_line.md), so where a code is
  weak the permissive ones fade first.
* **Codes** rise with the permitted speed [S]. 3-aspect block sends 1 (red ahead), 6 (yellow
  ahead), 9 (clear); 4-aspect adds 4 (yellow ahead, pass it at 80 / 50 km/h) and sends 6 for a
  yellow-green; a diverging route set at a signal sends 3 / 5 / 7 (frogs 1/11, 1/18, 1/22: 50,
  80, 120 km/h) into its approach and 6 or 7 into the section before; a permanent restriction
  to 140 / 160 km/h beyond a clear signal sends 10 / 11 (gentle braking), a line cleared for
  180 / 200 km/h 12 / 13 [S]. Codes 2, 14 and 15 are reserved: never sent; a receiver takes
  them as no code.
* **Meaning** per train category (the freight and passenger decoders read one code
  differently [S]): a ceiling (None: the line's limit) and the speed for passing the next
  signal, the aspect to show and the free blocks to report, and the braking it asks for
  (``signal``: towards a signal ahead; ``restriction``: a permanent restriction, gentler [S]).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, List, Optional, Tuple

import numpy as np

from fmus.data.loader import read_json_file
from fmus.errors import FmuInputError
from fmus.signalling import aspects as sig
from fmus.train_categories import TRAIN_CATEGORIES
from fmus.signalling.block_rules import SIGNAL_GREEN, SIGNAL_RED, SIGNAL_YELLOW, SIGNAL_YELLOW_GREEN, BlockCodes
from fmus.signalling.digital_messages import Indication

NAME = "ALSU"
CODES_FILE = Path(__file__).resolve().parent / "alsu_codes.json"
NO_CODE = 0
TONE_COUNT = 6
CODE_COUNT = 15                     # pairs of six tones
#: the thesis' tone plan (docs/sources.md#alsu) [S]; a code table may move them
TONE_SPACING_HZ = 50.0
#: top speed of each category under ALSU: freight 100, passenger 160, high-speed 200 km/h [S]
CATEGORY_MAX_KMH = {"passenger": 160.0, "freight": 100.0, "high_speed": 200.0}
ASPECTS = {"red_yellow": sig.RED_YELLOW, "yellow": sig.YELLOW, "green": sig.GREEN}
BRAKINGS = ("restriction", "signal")       # at equal speeds, gentle braking first: the more restrictive
#: the ATP's supervision deceleration for a code's target, as a share of its own: braking for a
#: permanent restriction is gentler than towards a closed signal [S]; how much gentler [U]
BRAKING_SHARE = {"signal": 1.0, "restriction": 0.5}
#: the block's codes (module docstring) [S]
RED_CODE, YELLOW_CODE_3, YELLOW_CODE_4, YELLOW_GREEN_CODE, CLEAR_CODE = 1, 6, 4, 6, 9
RESTRICTION_CODES = ((140.0, 10), (160.0, 11))     # a permanent restriction beyond a clear signal
HIGH_SPEED_CODES = ((200.0, 13), (180.0, 12))      # the line cleared for these speeds
PRE_ROUTE_CODES = (6, 7)           # into the section before a diverging route's: 7 for a 120 km/h route, else 6 [S: "6 or 7"]
#: an aspect change reaches the cab within 2 s (thesis: three times less inertia than ALSN) [S]:
#: the stated latency the verdicts and the ATP use (docs/scenarios.md#results-summaryjson)
STATED_LATENCY_S = 2.0
#: the display holds the code shown through a loss of every tone this long (the receiver's
#: `inertia` default; the ATP's bridging after a signal) [U]: it bridges the ≈ 1 m null zone at
#: a joint from 10 km/h on, and a loss still reaches the cab within the 2 s
EQUIPMENT_INERTIA_S = 1.0
#: after passing a signal under a code, the most restrictive code the new section can carry:
#: behind a green-class code (free blocks ≥ 2) a yellow ahead (6), else a red ahead (1)
WORST_AFTER_CLEAR, WORST_AFTER_RESTRICTIVE = YELLOW_CODE_3, RED_CODE


@dataclass(frozen=True)
class Code:
    number: int
    tones: Tuple[int, int]                   # indices 0..5 of the tones, ascending
    reserved: bool
    aspect: int = sig.WHITE
    free_blocks: int = 0
    braking: str = "signal"
    speeds_kmh: Optional[Dict[str, Tuple[Optional[float], Optional[float]]]] = None
    route_frog: str = ""
    source: str = ""


@dataclass(frozen=True)
class CodeTable:
    path: Path
    tones_hz: Tuple[float, ...]              # f2..f7
    codes: Dict[int, Code]
    permissiveness: Dict[int, int]           # sent code → its place in the order, 0 the most restrictive

    def code_of_tones(self) -> np.ndarray:
        """(6, 6) code number of each tone pair (symmetric), 0 on the diagonal."""
        table = np.zeros((TONE_COUNT, TONE_COUNT), dtype=np.int64)
        for code in self.codes.values():
            a, b = code.tones
            table[a, b] = table[b, a] = code.number
        return table

    def route_code(self, frog: str) -> Optional[int]:
        return next((c.number for c in self.codes.values() if c.route_frog == frog and not c.reserved), None)


def load_codes(path=CODES_FILE) -> CodeTable:
    """The code table, every error one FmuInputError naming the file and the field."""
    path = Path(path)
    doc = read_json_file(path)

    def fail(field: str, message: str):
        raise FmuInputError(f"{path}: field {field}: {message}")
    if not isinstance(doc, dict):
        fail("(top level)", "expected an object with tones and codes")
    tones = doc.get("tones")
    if not isinstance(tones, dict) or len(tones) != TONE_COUNT:
        fail("tones", f"expected an object of {TONE_COUNT} named tone frequencies")
    names = list(tones)
    for name, value in tones.items():
        if not isinstance(value, (int, float)) or isinstance(value, bool) or value <= 0:
            fail(f"tones.{name}", "must be a positive frequency in Hz")
    frequencies = [float(tones[name]) for name in names]
    if any(b <= a for a, b in zip(frequencies, frequencies[1:])):
        fail("tones", "frequencies must rise from the first tone to the last")
    codes_doc = doc.get("codes")
    if not isinstance(codes_doc, dict):
        fail("codes", "missing or not an object")
    codes, seen = {}, {}
    for key, entry in codes_doc.items():
        where = f"codes.{key}"
        if not key.isdigit() or not 1 <= int(key) <= CODE_COUNT:
            fail(where, f"code numbers are 1…{CODE_COUNT}")
        if not isinstance(entry, dict):
            fail(where, "expected an object")
        pair = entry.get("tones")
        if not isinstance(pair, list) or len(pair) != 2 or any(t not in tones for t in pair) or pair[0] == pair[1]:
            fail(f"{where}.tones", f"expected two different tones of {', '.join(names)}")
        indices = tuple(sorted(names.index(t) for t in pair))
        if indices in seen:
            fail(f"{where}.tones", f"the same pair as code {seen[indices]}")
        seen[indices] = int(key)
        if entry.get("reserved", False):
            codes[int(key)] = Code(int(key), indices, True, source=str(entry.get("source", "")))
            continue
        aspect = entry.get("aspect")
        if aspect not in ASPECTS:
            fail(f"{where}.aspect", f"{aspect!r} is not one of {', '.join(ASPECTS)}")
        braking = entry.get("braking", "signal")
        if braking not in BRAKINGS:
            fail(f"{where}.braking", f"{braking!r} is not one of {', '.join(BRAKINGS)}")
        free = entry.get("free_blocks")
        if not isinstance(free, int) or isinstance(free, bool) or free < 0:
            fail(f"{where}.free_blocks", "must be a whole number ≥ 0")
        speeds = entry.get("speeds_kmh")
        if not isinstance(speeds, dict) or set(speeds) != set(TRAIN_CATEGORIES):
            fail(f"{where}.speeds_kmh", f"expected one entry per category ({', '.join(TRAIN_CATEGORIES)})")
        read = {}
        for category, pair_kmh in speeds.items():
            if not isinstance(pair_kmh, list) or len(pair_kmh) != 2 or any(
                    v is not None and (not isinstance(v, (int, float)) or isinstance(v, bool) or v < 0) for v in pair_kmh):
                fail(f"{where}.speeds_kmh.{category}", "expected [ceiling km/h or null, speed at the next signal km/h or null]")
            read[category] = tuple(None if v is None else float(v) for v in pair_kmh)
        frog = entry.get("route_frog", "")
        if not isinstance(frog, str):
            fail(f"{where}.route_frog", "must be a frog name such as \"1/11\"")
        codes[int(key)] = Code(int(key), indices, False, ASPECTS[aspect], free, braking, read, frog,
                               str(entry.get("source", "")))
    if len(codes) != CODE_COUNT:
        missing = sorted(set(range(1, CODE_COUNT + 1)) - set(codes))
        fail("codes", f"every code 1…{CODE_COUNT} needs an entry (missing {', '.join(map(str, missing))})")
    block_codes = (RED_CODE, YELLOW_CODE_3, YELLOW_CODE_4, YELLOW_GREEN_CODE, CLEAR_CODE)
    for number in block_codes + tuple(c for _, c in RESTRICTION_CODES + HIGH_SPEED_CODES) + PRE_ROUTE_CODES:
        if codes[number].reserved:
            fail(f"codes.{number}", "the block rules send this code: it cannot be reserved")
    order = _permissiveness(doc.get("permissiveness"), codes, fail)
    return CodeTable(path, tuple(frequencies), codes, order)


def _readings(code: Code) -> List[float]:
    """A code's readings compared for permissiveness: per category its permitted speed and its
    speed at the next signal (CATEGORY_MAX_KMH for the line's limit), its aspect and free blocks."""
    values = [float(sig.restrictiveness(code.aspect)), float(code.free_blocks)]
    for category in TRAIN_CATEGORIES:
        ceiling, at_signal = code.speeds_kmh[category]
        permitted = CATEGORY_MAX_KMH[category] if ceiling is None else min(ceiling, CATEGORY_MAX_KMH[category])
        values += [permitted, permitted if at_signal is None else min(at_signal, permitted)]
    return values


def _permissiveness(doc, codes: Dict[int, Code], fail) -> Dict[int, int]:
    """Each sent code's place in the table's ``permissiveness.order`` (0: the most restrictive),
    checked against the readings (the table's ``permissiveness.rule``)."""
    order = doc.get("order") if isinstance(doc, dict) else None
    sent = sorted(n for n, c in codes.items() if not c.reserved)
    if not isinstance(order, list) or not all(isinstance(g, list) and g for g in order) \
            or sorted(n for g in order for n in g if isinstance(n, int)) != sent:
        fail("permissiveness.order", "expected the codes a wayside sends (" + ", ".join(map(str, sent)) +
             "), each once, in groups from the most restrictive to the most permissive")
    place = {n: index for index, group in enumerate(order) for n in group}
    for a in sent:
        for b in sent:
            ra, rb = _readings(codes[a]), _readings(codes[b])
            steeper = BRAKINGS.index(codes[b].braking) - BRAKINGS.index(codes[a].braking)   # > 0: b brakes more steeply
            if place[a] == place[b] and (ra != rb or steeper):
                fail("permissiveness.order", f"codes {a} and {b} share a group but read differently")
            if place[a] < place[b] and (any(y < x for x, y in zip(ra, rb)) or (ra == rb and steeper <= 0)):
                fail("permissiveness.order", f"code {b} is listed as more permissive than code {a} but is not "
                                             "(speeds per category, then braking: permissiveness.rule)")
    return place


def all_pairs() -> List[Tuple[int, int]]:
    return list(itertools.combinations(range(TONE_COUNT), 2))


class AlsuSystem:
    """ALSU as the verdicts, the coder and the receiver see it: the code table and what a code
    means (the digital systems' Indication, so one judgement compares both)."""

    name = NAME

    def __init__(self, table: Optional[CodeTable] = None):
        self.table = table or load_codes()

    def codes(self) -> Tuple[int, ...]:
        """The codes a wayside may send (not reserved)."""
        return tuple(n for n, c in sorted(self.table.codes.items()) if not c.reserved)

    def command_of_code(self, code: int) -> Optional[int]:
        """The code a raw id stands for; None for no code and for a reserved one."""
        found = self.table.codes.get(int(code))
        return None if found is None or found.reserved else found.number

    def indication(self, code: int, category: str) -> Indication:
        entry = self.table.codes[int(code)]
        top = CATEGORY_MAX_KMH[category]
        ceiling, at_signal = entry.speeds_kmh[category]
        permitted = top if ceiling is None else min(ceiling, top)
        target = permitted if at_signal is None else min(at_signal, permitted)
        return Indication(entry.number, entry.aspect, entry.free_blocks, permitted, target)

    def braking(self, code: int) -> str:
        return self.table.codes[int(code)].braking

    def worst_next(self, code: int) -> int:
        """The most restrictive code the section beyond the signal may carry when the train
        passes it under ``code`` (the ATP assumes it until the new code is shown)."""
        return WORST_AFTER_CLEAR if self.table.codes[int(code)].free_blocks >= 2 else WORST_AFTER_RESTRICTIVE

    def rank(self, code: int) -> int:
        """Higher is more permissive: the code's place in the table's permissiveness order
        (alsu_codes.json ``permissiveness``; equal for codes that mean the same)."""
        return self.table.permissiveness[int(code)]

    def more_restrictive(self, a: int, b: int) -> int:
        return a if self.rank(a) <= self.rank(b) else b

    def block_coding(self, line, block_aspects: int) -> "BlockCoding":
        """The block rules' ALSU code of every track circuit of ``line`` (the verdicts' and the
        headway's reading of what the coder sends)."""
        return BlockCoding(line, block_aspects, self)


SYSTEM = None      # the shipped table's system, made on first use (system())


def system(table_path=None) -> AlsuSystem:
    """ALSU with the shipped code table, or with the table at ``table_path``."""
    global SYSTEM
    if table_path:
        return AlsuSystem(load_codes(table_path))
    if SYSTEM is None:
        SYSTEM = AlsuSystem()
    return SYSTEM


class BlockCoding:
    """The ALSU code of every track circuit from the block rules (block_rules.py) and the
    line: its exit signal's aspect (3- or 4-aspect block), a diverging route set at that signal
    (the line file's ``diverging_routes``) or at the next one, and a permanent restriction or a
    high-speed clearance beyond it (the line's limits). The coder sends it and the verdict
    judges against it, so the two are one rule."""

    def __init__(self, line, block_aspects: int, alsu: AlsuSystem):
        self.alsu, self.block_aspects = alsu, block_aspects
        self.block_of = np.asarray(line.block_of_section, dtype=np.int64)
        blocks = len(line.block_bounds)
        exits_m = [end for _, end in line.block_bounds]
        # the signal closing each block: the name on its last circuit
        exit_names = [""] * blocks
        for section, block in zip(line.sections, line.block_of_section):
            exit_names[block] = section.signal
        routes = {name: frog for name, frog in getattr(line, "diverging_routes", [])}
        self.route_code = np.zeros(blocks, dtype=np.int64)
        for block, name in enumerate(exit_names):
            if name and name in routes:
                code = alsu.table.route_code(routes[name])
                if code is None:
                    raise FmuInputError(f"{line.path}: field diverging_routes: frog {routes[name]!r} has no "
                                        f"route code in {alsu.table.path.name}")
                self.route_code[block] = code
        self.pre_route_code = np.zeros(blocks, dtype=np.int64)
        for block in range(blocks - 1):
            route = int(self.route_code[block + 1])
            if route:
                fast = alsu.indication(route, "passenger").target_kmh >= alsu.indication(PRE_ROUTE_CODES[1], "passenger").target_kmh
                self.pre_route_code[block] = PRE_ROUTE_CODES[1] if fast else PRE_ROUTE_CODES[0]
        self.clear_code = np.array([self._clear_code(line, exits_m, block) for block in range(blocks)], dtype=np.int64)

    @staticmethod
    def _clear_code(line, exits_m: List[float], block: int) -> int:
        """The code behind a clear signal: by the line's lowest limit (high-speed column) over
        the block beyond it — 12 / 13 where it is cleared for 180 / 200 km/h, 10 / 11 where it
        drops there to 140 / 160 km/h (a permanent restriction), else 9."""
        start = exits_m[block]
        end = exits_m[block + 1] if block + 1 < len(exits_m) else line.length_m
        limits = line.limits_mps["high_speed"]
        starts = line.limit_starts
        within = [v for s, v, following in zip(starts, limits, starts[1:] + [np.inf]) if following > start and s < end]
        ahead_kmh = min(within or [line.speed_limit_mps(start, "high_speed")]) * 3.6
        here_kmh = line.speed_limit_mps(max(start - 1e-6, 0.0), "high_speed") * 3.6
        for speed, code in HIGH_SPEED_CODES:
            if ahead_kmh >= speed - 1e-6:
                return code
        if ahead_kmh < here_kmh - 1e-6:
            for speed, code in RESTRICTION_CODES:
                if speed - 1e-6 <= ahead_kmh < speed + 20.0 - 1e-6:
                    return code
        return CLEAR_CODE

    def codes(self, rules: BlockCodes) -> np.ndarray:
        """The ALSU code of every circuit (NO_CODE where the block rules cut it)."""
        block = self.block_of
        signal = rules.signal
        yellow = YELLOW_CODE_4 if self.block_aspects == 4 else YELLOW_CODE_3
        code = np.select([signal == SIGNAL_RED, signal == SIGNAL_YELLOW, signal == SIGNAL_YELLOW_GREEN,
                          signal == SIGNAL_GREEN], [RED_CODE, yellow, YELLOW_GREEN_CODE, self.clear_code[block]],
                         CLEAR_CODE)
        limit = np.where(self.route_code[block] > 0, self.route_code[block], self.pre_route_code[block])
        for k in np.flatnonzero((limit > 0) & (signal != SIGNAL_RED)).tolist():
            code[k] = self.alsu.more_restrictive(int(code[k]), int(limit[k]))
        return np.where(rules.coded, code, NO_CODE)
