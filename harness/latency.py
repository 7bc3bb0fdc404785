"""The ALSN receiver's latencies measured on the receiver core fed by the wayside coder core
(harness.channel): acquisition from a cold start, restrictive and permissive
changes of the code sent, and a loss of code → the no-code indication, per transmitter type
over cam phases (docs/loco_receiver.md, "Latencies"); and a change of code at an insulated
joint, the coder → rail line → receiver cores with a train crossing the joint behind a standing
one (``joint_change_s``). Used by benchmarks/receiver_latencies.py,
benchmarks/receiver_change_latency.py and tests/test_loco_receiver.py."""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Dict, Iterable, List, Optional, Tuple

import numpy as np

from harness.channel import CodeChannel, Disturbance, white_noise_and_hum
from harness.display import rank
from fmus.data.loader import load_line
from fmus.signalling.alsn import BENCH_COIL_COUPLING
from fmus.loco_receiver.core import LocoReceiverCore, ReceiverSettings
from fmus.rail_line.core import RailLineCore, RailSettings
from fmus.rail_line.traction_interference import REFERENCE_TRACTION_A
from fmus.signalling import aspects as sig
from fmus.sizes import DEFAULT_SAMPLE_RATE_HZ
from fmus.wayside_coder.core import CoderSettings, WaysideCoderCore

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


def _channel(kpt: str, phase: float, receiver=None, carrier_hz: float = 0.0) -> CodeChannel:
    """Coder section of ``kpt`` into a receiver; ``carrier_hz`` both ends' carrier (0: the
    line's, 50 Hz; a ``receiver``'s settings then keep their own)."""
    if receiver is None and carrier_hz:
        receiver = ReceiverSettings(carrier_hz=carrier_hz)
    return CodeChannel(SECTION[kpt], 40, BENCH_COIL_COUPLING, coder=CoderSettings(seed=1, carrier_hz=carrier_hz),
                       receiver=receiver, cam_phase=phase)


def acquisition_s(kpt: str, code: int, phase: float, carrier_hz: float = 0.0) -> float:
    rows = _channel(kpt, phase, carrier_hz=carrier_hz).run(AFTER_S, occupancy(code, SECTION[kpt]))
    hit = np.flatnonzero((rows[:, 1] == code) & (rows[:, 2] == 1))
    return float(rows[hit[0], 0]) if hit.size else np.inf


COLD_FRAME = 400            # 0.1 s frames for cold starts: the receiver's results do not depend on it


def cold_starts(kpt: str, code: int, carrier_hz: float, step_s: float = 0.01, seconds: float = AFTER_S):
    """Cold starts every ``step_s`` of the cam's cycle: the coder's EMF of ``code`` computed
    once, a new receiver started at each offset into it. (start offsets s, time until ``code``
    is shown (inf: never), the most permissive aspect shown meanwhile by rank
    (aspects.restrictiveness)) as arrays; times are frame ends, so up to 0.1 s late."""
    channel = _channel(kpt, 0.0, carrier_hz=carrier_hz)
    cycle_s = float(channel.coder.cycle_s[SECTION[kpt]])
    _, emf = channel.run(cycle_s + seconds + 0.1, occupancy(code, SECTION[kpt]), keep_emf=True)
    fs = channel.fs
    starts = np.arange(0.0, cycle_s, step_s)
    settings = channel.receiver.settings
    frames = int(round(seconds * fs / COLD_FRAME))
    shown_s, most = np.full(starts.size, np.inf), np.zeros(starts.size, dtype=int)
    for i, start_s in enumerate(starts):
        first = int(round(start_s * fs))
        receiver = LocoReceiverCore(COLD_FRAME, settings)
        for k in range(frames):
            out = receiver.step(k * COLD_FRAME / fs, emf[first + k * COLD_FRAME:first + (k + 1) * COLD_FRAME])
            most[i] = max(most[i], sig.restrictiveness(out.aspect) if out.code_valid else 0)
            if out.code_valid and out.aspect == code and shown_s[i] == np.inf:
                shown_s[i] = (k + 1) * COLD_FRAME / fs
    return starts, shown_s, most


def change_s(kpt: str, before: int, after: int, phase: float, receiver=None,
             disturb: Optional[Disturbance] = None, carrier_hz: float = 0.0) -> float:
    """Time from the change of the code sent until the display shows ``after`` (a restrictive
    change: ``after`` or anything more restrictive); ``disturb`` adds to the coil EMF."""
    section = SECTION[kpt]
    schedule = lambda t: occupancy(before if t < SETTLE_S else after, section)
    rows = _channel(kpt, phase, receiver, carrier_hz).run(SETTLE_S + AFTER_S, schedule, disturb=disturb)
    assert rows[rows[:, 0] <= SETTLE_S][-1, 1] == before, "the code before the change was not shown"
    late = rows[rows[:, 0] > SETTLE_S]
    if sig.restrictiveness(after) < sig.restrictiveness(before):
        hit = np.flatnonzero(rank(late[:, 1]) <= sig.restrictiveness(after))
    else:
        hit = np.flatnonzero((late[:, 1] == after) & (late[:, 2] == 1))
    return float(late[hit[0], 0] - SETTLE_S) if hit.size else np.inf


def loss_s(kpt: str, code: int, phase: float, gap_s: float = np.inf, receiver=None,
           carrier_hz: float = 0.0) -> Tuple[float, bool]:
    """A loss of the code's EMF from SETTLE_S for ``gap_s``: (time until the no-code
    indication, inf if never; whether the display stayed on ``code`` throughout otherwise)."""
    cut = lambda t, e: e * ((t < SETTLE_S) | (t >= SETTLE_S + gap_s))
    rows = _channel(kpt, phase, receiver, carrier_hz).run(SETTLE_S + AFTER_S, occupancy(code, SECTION[kpt]), disturb=cut)
    late = rows[rows[:, 0] > SETTLE_S]
    hit = np.flatnonzero(np.isin(late[:, 1], NO_CODE) & (late[:, 2] == 0))
    return (float(late[hit[0], 0] - SETTLE_S) if hit.size else np.inf), bool(np.all(late[:, 1] == code))


RESTRICTIVE = ((sig.GREEN, sig.YELLOW), (sig.YELLOW, sig.RED_YELLOW), (sig.GREEN, sig.RED_YELLOW))
PERMISSIVE = ((sig.RED_YELLOW, sig.YELLOW), (sig.YELLOW, sig.GREEN), (sig.RED_YELLOW, sig.GREEN))
CODES = (sig.GREEN, sig.YELLOW, sig.RED_YELLOW)


def table(phases: Iterable[float], kpts=("KPT-5", "KPT-7"), carrier_hz: float = 0.0) -> List[Dict]:
    """One row per (what, transmitter): the least and the greatest latency over the phases, at
    ``carrier_hz`` (0: the line's, 50 Hz)."""
    phases = list(phases)
    rows = []

    def add(what, kpt, values):
        values = np.array(values, dtype=float)
        rows.append({"what": what, "kpt": kpt, "min_s": float(values.min()), "max_s": float(values.max())})

    name = sig.ASPECT_NAMES
    for kpt in kpts:
        for code in CODES:
            add(f"acquisition, {name[code]}", kpt, [acquisition_s(kpt, code, p, carrier_hz) for p in phases])
        for before, after in RESTRICTIVE:
            add(f"restrictive {name[before]} → {name[after]}", kpt, [change_s(kpt, before, after, p, carrier_hz=carrier_hz) for p in phases])
        for before, after in PERMISSIVE:
            add(f"permissive {name[before]} → {name[after]}", kpt, [change_s(kpt, before, after, p, carrier_hz=carrier_hz) for p in phases])
        for code in CODES:
            add(f"loss, {name[code]} → {'red' if code == sig.RED_YELLOW else 'white'}", kpt,
                [loss_s(kpt, code, p, carrier_hz=carrier_hz)[0] for p in phases])
    return rows


# ---- a change of code at an insulated joint -----------------------------------------------------
FS_HZ, FRAME = DEFAULT_SAMPLE_RATE_HZ, 40
WEAK_CODE_V = 0.28          # the code at a section's entry end past a joint (joints paper, docs/sources.md#interference-at-insulated-joints)
NOISE_SNR_DB = 10.0         # white noise over the whole band against WEAK_CODE_V (30 dB in the filter band)
CROSS_S = 7.0               # the coils cross the joint: the code behind it shown for 3 s before (acquired within 3.82 s)
JOINT_AFTER_S = 7.0         # longer than any latency measured; a change not shown by then is inf


@dataclass(frozen=True)
class JointCase:
    joint_m: float          # the insulated joint on the default line
    before: int             # the section behind it (0-based)
    after: int              # the section past it


#: the default line's sections alternate KPT-5 (odd) and KPT-7 (even)
JOINT_CASES = {"KPT-7 → KPT-5": JointCase(5200.0, 1, 2), "KPT-5 → KPT-7": JointCase(7800.0, 2, 3)}
_default_line = lru_cache(maxsize=1)(load_line)      # validated once: a third of a crossing's time


def joint_crossing(case: str, phase: float, old_phase: float, seed: int, speed_kmh: float = 80.0,
                   snr_db: Optional[float] = NOISE_SNR_DB, traction_a: float = REFERENCE_TRACTION_A,
                   standing: Optional[int] = 2):
    """A train crossing the joint of ``JOINT_CASES[case]`` at CROSS_S: (frame end times, aspect
    shown, code sent under the coils). It runs at ``speed_kmh`` drawing ``traction_a`` (the rail
    line's traction interference, the rails' asymmetry drawn from ``seed``); white noise from
    ``seed`` at ``snr_db`` against the weak code at the entry end (None: none). ``phase`` /
    ``old_phase``: where the cams of the section past / behind the joint stand in their cycle
    (0–1) when the coils cross it. ``standing``: a train stands that many circuits ahead of the
    one past the joint — 2: З → Ж, 1: Ж → КЖ — or None: the line is clear (З → З)."""
    spec = JOINT_CASES[case]
    line = _default_line()
    sections = len(line.sections)
    rail = RailLineCore(line, sections, 2, FRAME, RailSettings(fs_hz=FS_HZ, seed=seed))
    coder = WaysideCoderCore(line, sections, FRAME, CoderSettings(fs_hz=FS_HZ, seed=seed))
    receiver = LocoReceiverCore(FRAME, ReceiverSettings(fs_hz=FS_HZ))
    for section, at in ((spec.before, old_phase), (spec.after, phase)):
        cycle = coder.cycle_s[section]
        coder.cam_offset_s[section] = (at * cycle - CROSS_S) % cycle
    if standing is None:
        standing_m = -1000.0                        # off the line
    else:
        ahead = line.sections[spec.after + standing]
        standing_m = (ahead.start_m + ahead.end_m) / 2.0 + rail.settings.train_length_m[1] / 2.0
    v = speed_kmh / 3.6
    start_m = spec.joint_m - rail.settings.coil_offset_m - v * CROSS_S      # the coils reach the joint at CROSS_S
    noise = white_noise_and_hum(snr_db, WEAK_CODE_V, {}, seed) if snr_db is not None else None
    occupied = rail.start(np.array([start_m, standing_m])).occupied.copy()
    speeds, currents = np.array([v, 0.0]), np.array([traction_a, 0.0])
    offsets = np.arange(FRAME) / FS_HZ
    frames = int(round((CROSS_S + JOINT_AFTER_S) * FS_HZ / FRAME))
    shown, sent = np.zeros(frames, dtype=int), np.zeros(frames, dtype=int)
    for k in range(frames):
        t = k * FRAME / FS_HZ
        coded = coder.step(t, occupied)
        rail_out = rail.step(t, coded.u_tx, np.array([start_m + v * t, standing_m]), speeds, currents)
        occupied = rail_out.occupied.copy()
        e = rail_out.e_coil[0] if noise is None else noise(t + offsets, rail_out.e_coil[0])
        shown[k] = receiver.step(t, e).aspect
        section = int(rail_out.coil_section[0])
        sent[k] = coded.code_tx[section - 1] if section > 0 else sig.WHITE
        past = (k + 1) * FRAME / FS_HZ > CROSS_S
        assert section - 1 == (spec.after if past else spec.before), "the coils not where they were placed"
    return (np.arange(frames) + 1) * FRAME / FS_HZ, shown, sent


#: the restrictive changes met at a joint: (code behind, code past it) → how many circuits ahead
#: of the one past the joint a train stands
JOINT_CHANGES = {(sig.GREEN, sig.YELLOW): 2, (sig.YELLOW, sig.RED_YELLOW): 1}


def joint_change_s(case: str, phase: float, old_phase: float, seed: int,
                   change: Tuple[int, int] = (sig.GREEN, sig.YELLOW), **crossing) -> float:
    """Time from the coils crossing the joint of ``JOINT_CASES[case]`` with the code ``change``
    (behind, past it: З → Ж or Ж → КЖ, JOINT_CHANGES) until the display shows the code past it or
    anything more restrictive; ``crossing``: ``joint_crossing``'s options. inf when not shown
    within JOINT_AFTER_S."""
    t_end, shown, sent = joint_crossing(case, phase, old_phase, seed, standing=JOINT_CHANGES[change], **crossing)
    past = t_end > CROSS_S
    behind, ahead = change
    assert sent[~past][-1] == behind and sent[past][0] == ahead and shown[~past][-1] == behind, \
        "not the change meant"
    hit = np.flatnonzero(past & (rank(shown) <= sig.restrictiveness(ahead)))
    return float(t_end[hit[0]] - CROSS_S) if hit.size else np.inf
