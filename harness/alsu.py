"""The ALSU bench: the ALSU coder core → the rail line core (the six tones through the
track-circuit network, traction interference under the coils) → the ALSU receiver core, frame
by frame without FMI (docs/loco_receiver.md#alsu, docs/wayside_coder.md#alsu): for the tests,
benchmarks/alsu_acceptance.py and the noise study.

The coder's block logic is bypassed where a case needs a given code or tone set
(``AlsuCoderCore.send``); one train stands or runs on the line, its coils over the section
under test.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, List, Optional

import numpy as np

from fmus.data.loader import Line, load_line
from fmus.loco_receiver.alsu import AlsuReceiverCore, AlsuReceiverSettings
from fmus.rail_line.core import RailLineCore, RailSettings
from fmus.signalling import alsu
from fmus.sizes import DEFAULT_SAMPLE_RATE_HZ
from fmus.wayside_coder.alsu import AlsuCoderCore
from fmus.wayside_coder.core import CoderSettings

FS, N = DEFAULT_SAMPLE_RATE_HZ, 40
FRAME_S = N / FS
TONE_BAND_HZ = (125.0, 375.0)
# a train standing with its head this far into a section: the coils over its entry end, where
# the code current is weakest (the ALS regime, docs/rail_line.md)
ENTRY_HEAD_M = 10.0


@dataclass
class Record:
    """Per frame: end time, the code shown (0 none), code_valid, aspect, the receiver's
    pair code (two tones present: their code, reserved ones included), the code sent into the
    section under the coils."""
    t: List[float] = field(default_factory=list)
    shown: List[int] = field(default_factory=list)
    valid: List[bool] = field(default_factory=list)
    aspect: List[int] = field(default_factory=list)
    pair: List[int] = field(default_factory=list)
    sent: List[int] = field(default_factory=list)

    def arrays(self):
        return {name: np.array(getattr(self, name)) for name in ("t", "shown", "valid", "aspect", "pair", "sent")}


class AlsuBench:
    """One train on ``line`` (its head at ``head_m``, speed ``speed_mps``, traction current
    ``traction_a``), the coder on every section, the receiver on the train's coils."""

    def __init__(self, line: Optional[Line] = None, head_m: float = 2600.0 + ENTRY_HEAD_M, speed_mps: float = 0.0,
                 traction_a: float = 0.0, ballast_ohm_km: float = 0.0, seed: int = 1, coil_mismatch: float = 0.0,
                 receiver: Optional[AlsuReceiverSettings] = None, coder: Optional[CoderSettings] = None,
                 disturb: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]] = None,
                 asymmetry: Optional[float] = None, **rail_settings):
        self.line = line or load_line()
        k = len(self.line.sections)
        self.coder = AlsuCoderCore(self.line, k, N, coder or CoderSettings(seed=seed, block_aspects=4))
        self.rail = RailLineCore(self.line, k, 2, N, RailSettings(tone_band_hz=TONE_BAND_HZ, seed=seed,
                                                                  coil_mismatch=coil_mismatch, **rail_settings))
        if ballast_ohm_km:           # the ballast of every section, as the rail line's ballast_override input sets it
            self.rail.set_faults(-1.0, np.full(k, float(ballast_ohm_km)), np.zeros(k, dtype=bool))
        if asymmetry is not None:
            self.rail.asymmetry[:] = asymmetry
        self.receiver = AlsuReceiverCore(N, receiver or AlsuReceiverSettings())
        self.head_m, self.speed, self.traction_a = head_m, speed_mps, traction_a
        self.disturb = disturb
        self.frames = 0
        self.rail.start(np.array([head_m, -1000.0]))
        self.record = Record()

    @property
    def t(self) -> float:
        return self.frames * FRAME_S

    def head_at(self, t: float) -> float:
        return self.head_m + self.speed * t

    def run(self, seconds: float, keep: bool = True) -> Record:
        times = np.arange(N) / FS
        for _ in range(int(round(seconds / FRAME_S))):
            t = self.t
            sent = self.coder.step(t, self.rail.out.occupied)
            x = np.array([self.head_at(t), -1000.0])
            out = self.rail.step(t, sent.u_tx, x, np.array([self.speed, 0.0]), np.array([self.traction_a, 0.0]))
            e = out.e_coil[0]
            if self.disturb is not None:
                e = self.disturb(t + times, e)
            shown = self.receiver.step(t, e)
            self.frames += 1
            if keep:
                r = self.record
                section = int(out.coil_section[0])
                r.t.append(self.t)
                r.shown.append(shown.code)
                r.valid.append(shown.code_valid)
                r.aspect.append(shown.aspect)
                r.pair.append(self.receiver.pair_code)
                r.sent.append(int(sent.code_tx[section - 1]) if section > 0 else 0)
        return self.record

    def send_code(self, code: int) -> None:
        """Every section sends ``code`` (0: nothing)."""
        k = self.coder.count
        self.coder.send(np.tile(self.coder.tones_of(code), (k, 1)), np.full(k, code))

    def send_tones(self, flags) -> None:
        """Every section sends the tones flagged (six booleans: any number of them)."""
        k = self.coder.count
        self.coder.send(np.tile(np.asarray(flags, dtype=bool), (k, 1)), np.zeros(k, dtype=np.int64))


def first_time(record: Record, since_s: float, condition: np.ndarray) -> Optional[float]:
    """Seconds from ``since_s`` to the first frame end at or after it where ``condition`` holds."""
    t = np.array(record.t)
    hits = np.flatnonzero((t > since_s) & condition)
    return None if hits.size == 0 else float(t[hits[0]] - since_s)


@dataclass
class ToneSetOutcome:
    """What the display did after a set of tones replaced a code shown."""
    lost_s: Optional[float]     # time to the no-code indication (None: never within the watch)
    other_code: bool            # another code shown meanwhile (a wrong code)
    shown_again: bool           # a code shown again after the no-code indication
    aspect_at_end: int          # the aspect displayed when the watch ends


def tones_after_code(flags: List[int], code: int = 9, settle_s: float = 3.0, watch_s: float = 4.0) -> ToneSetOutcome:
    """Send ``code`` for ``settle_s``, then the tones ``flags`` (one 0/1 per tone f2…f7) for
    ``watch_s``: how the display reacted (the exactly-two-tones rule, docs/loco_receiver.md#alsu)."""
    bench = AlsuBench()
    bench.send_code(code)
    bench.run(settle_s)
    bench.send_tones(flags)
    start = bench.t
    record = bench.run(watch_s).arrays()
    after = record["t"] > start
    lost = first_time(bench.record, start, ~record["valid"])
    other = bool((record["valid"][after] & (record["shown"][after] != code)).any())
    again = lost is not None and bool(record["valid"][record["t"] > start + lost].any())
    return ToneSetOutcome(lost, other, again, int(record["aspect"][-1]))


def sendable_codes() -> List[int]:
    return list(alsu.system().codes())
