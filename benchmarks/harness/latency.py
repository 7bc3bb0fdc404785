"""The ALSN receiver's latencies measured on the receiver core fed by the wayside coder core
(benchmarks.harness.channel): acquisition from a cold start, restrictive and permissive
changes of the code sent, and a loss of code → the no-code indication, per transmitter type
over cam phases (docs/loco_receiver.md, "Latencies"). Used by benchmarks/receiver_latencies.py
and tests/test_loco_receiver.py."""
from __future__ import annotations

from typing import Dict, Iterable, List, Tuple

import numpy as np

from benchmarks.harness.channel import CodeChannel
from benchmarks.harness.display import rank
from fmus.signalling import aspects as sig
from fmus.wayside_coder.core import CoderSettings

COUPLING = 0.1                         # 4 V transmitter → 0.4 V at the coil
SECTION = {"KPT-5": 0, "KPT-7": 1}     # the default line's sections 1 and 2
SETTLE_S = 12.0                        # the code before a change has been shown for a while
AFTER_S = 10.0
NO_CODE = (sig.WHITE, sig.RED)


def occupancy(code: int, section: int) -> np.ndarray:
    """Occupied sections that make the coder send ``code`` into ``section`` (3-aspect block)."""
    occupied = np.zeros(8, dtype=bool)
    if code == sig.YELLOW:
        occupied[section + 2] = True
    elif code == sig.RED_YELLOW:
        occupied[section + 1] = True
    return occupied


def _channel(kpt: str, phase: float, receiver=None) -> CodeChannel:
    return CodeChannel(SECTION[kpt], 40, COUPLING, coder=CoderSettings(seed=1), receiver=receiver,
                       cam_phase=phase)


def acquisition_s(kpt: str, code: int, phase: float) -> float:
    rows = _channel(kpt, phase).run(AFTER_S, occupancy(code, SECTION[kpt]))
    hit = np.flatnonzero((rows[:, 1] == code) & (rows[:, 2] == 1))
    return float(rows[hit[0], 0]) if hit.size else np.inf


def change_s(kpt: str, before: int, after: int, phase: float, receiver=None) -> float:
    """Time from the change of the code sent until the display shows ``after`` (a restrictive
    change: ``after`` or anything more restrictive)."""
    section = SECTION[kpt]
    schedule = lambda t: occupancy(before if t < SETTLE_S else after, section)
    rows = _channel(kpt, phase, receiver).run(SETTLE_S + AFTER_S, schedule)
    assert rows[rows[:, 0] <= SETTLE_S][-1, 1] == before, "the code before the change was not shown"
    late = rows[rows[:, 0] > SETTLE_S]
    if sig.restrictiveness(after) < sig.restrictiveness(before):
        hit = np.flatnonzero(rank(late[:, 1]) <= sig.restrictiveness(after))
    else:
        hit = np.flatnonzero((late[:, 1] == after) & (late[:, 2] == 1))
    return float(late[hit[0], 0] - SETTLE_S) if hit.size else np.inf


def loss_s(kpt: str, code: int, phase: float, gap_s: float = np.inf, receiver=None) -> Tuple[float, bool]:
    """A loss of the code's EMF from SETTLE_S for ``gap_s``: (time until the no-code
    indication, inf if never; whether the display stayed on ``code`` throughout otherwise)."""
    cut = lambda t, e: e * ((t < SETTLE_S) | (t >= SETTLE_S + gap_s))
    rows = _channel(kpt, phase, receiver).run(SETTLE_S + AFTER_S, occupancy(code, SECTION[kpt]), disturb=cut)
    late = rows[rows[:, 0] > SETTLE_S]
    hit = np.flatnonzero(np.isin(late[:, 1], NO_CODE) & (late[:, 2] == 0))
    return (float(late[hit[0], 0] - SETTLE_S) if hit.size else np.inf), bool(np.all(late[:, 1] == code))


RESTRICTIVE = ((sig.GREEN, sig.YELLOW), (sig.YELLOW, sig.RED_YELLOW), (sig.GREEN, sig.RED_YELLOW))
PERMISSIVE = ((sig.RED_YELLOW, sig.YELLOW), (sig.YELLOW, sig.GREEN), (sig.RED_YELLOW, sig.GREEN))
CODES = (sig.GREEN, sig.YELLOW, sig.RED_YELLOW)


def table(phases: Iterable[float], kpts=("KPT-5", "KPT-7")) -> List[Dict]:
    """One row per (what, transmitter): the least and the greatest latency over the phases."""
    phases = list(phases)
    rows = []

    def add(what, kpt, values):
        values = np.array(values, dtype=float)
        rows.append({"what": what, "kpt": kpt, "min_s": float(values.min()), "max_s": float(values.max())})

    name = sig.ASPECT_NAMES
    for kpt in kpts:
        for code in CODES:
            add(f"acquisition, {name[code]}", kpt, [acquisition_s(kpt, code, p) for p in phases])
        for before, after in RESTRICTIVE:
            add(f"restrictive {name[before]} → {name[after]}", kpt, [change_s(kpt, before, after, p) for p in phases])
        for before, after in PERMISSIVE:
            add(f"permissive {name[before]} → {name[after]}", kpt, [change_s(kpt, before, after, p) for p in phases])
        for code in CODES:
            add(f"loss, {name[code]} → {'red' if code == sig.RED_YELLOW else 'white'}", kpt,
                [loss_s(kpt, code, p)[0] for p in phases])
    return rows
