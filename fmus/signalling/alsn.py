"""ALSN numeric codes: the KPT-5/KPT-7 timing tables (fmus/signalling/alsn_codes.json) and the
decoder's classification windows, shared by the wayside coder and the locomotive receiver.

Codes are named by the aspect they give on the locomotive and carry its enumeration (docs/interfaces.md#locoreceiver-locoreceiverfmu):
З (Z) = 4 green, Ж (Zh) = 3 yellow, КЖ (KZh) = 2 red-yellow; 0 = no code.
"""
from __future__ import annotations

import math

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Dict, Tuple

import numpy as np

from fmus.signalling import aspects as sig
from fmus.errors import FmuInputError, non_finite_number

CODES_FILE = Path(__file__).resolve().parent / "alsn_codes.json"
CODE_NAMES = {"Z": sig.GREEN, "Zh": sig.YELLOW, "KZh": sig.RED_YELLOW}
NO_CODE = 0
SUPPORTED_CARRIERS_HZ = (25.0, 50.0, 75.0)
MIN_SAMPLES_PER_CARRIER_PERIOD = 8
# a transmitter's 4 V reaching the receiver's coil as 0.4 V: the bench coupling where the coder
# feeds the receiver without a rail line (the conformance vectors, the latency benches and their
# tests; docs/loco_receiver.md, Latencies) — a code well above pick-up and below overload
BENCH_COIL_COUPLING = 0.1

# decoder rules, firmware kpt.h (docs/sources.md#alsn-decoder-rules) [S]
LONG_INTERVAL_S = 0.35
#: a transmitter's code timings may drift by this share either way (its cam's speed)
TIMING_DRIFT = 0.05
LONG_INTERVAL_MAX_S = 1.0     # the longest code interval is 0.86 s (KPT-7 Ж) + 5 % drift: longer = pulses missed
KPT5_WINDOW_S = (1.47, 1.73)
KPT7_WINDOW_S = (1.73, 1.99)
CODE_TIMEOUT_S = 2.0
# the stated decoding latency of a restrictive change of code (docs/loco_receiver.md#latency-of-a-change):
# the ATP's default allowance after passing a signal, the run verdicts' wrong-side allowance
# (docs/scenarios.md#results-summaryjson) and the conformance bound use it. Measured at most
# 4.21 s over cam phases × noise seeds (benchmarks/receiver_change_latency.py): a З → Ж change
# met at a KPT-5 → KPT-7 joint, where the receiver's gain first recovers from the strong feed
# end behind the joint (about 0.5 s) and then needs up to two KPT-7 cycles (3.72 s); within a
# track circuit at most 3.3 s. + 0.15 s: what a feed end 1.5 dB stronger than the default
# line's adds to that recovery (10 dB/s), rounded up for phases between the measured ones
STATED_LATENCY_S = 4.5
# inertia of the locomotive ALSN equipment (docs/sources.md#receiver-inertia-and-latencies: 5.5 s,
# the joints paper; the thesis' "about 6 s" for an aspect change): the display holds the code
# shown through a loss of code shorter than this, counted from the last cycle supporting it
EQUIPMENT_INERTIA_S = 5.5
# plausibility of the parts of a cycle (our addition, docs/loco_receiver.md): the shortest code
# pulse is 0.22 s and the longest 0.44 s, the short intervals 0.12 s, all ±5 % drift, plus the
# smearing of the receiver filters
PULSE_S = (0.17, 0.50)
SHORT_INTERVAL_MIN_S = 0.06
SHORT_INTERVAL_S = 0.12        # the code's short interval (KPT-5 and KPT-7)


def short_interval_min_s(envelope_corner_hz: float) -> float:
    """Shortest relay gap still taken for a code interval: 0.06 s, less where the envelope
    filter is slow (at 25 Hz its 8 Hz corner shrinks a 0.12 s gap to ≈ 0.055 s; the relay
    needs about two envelope time constants to drop and two to pick up again)."""
    tau = 1.0 / (2.0 * math.pi * envelope_corner_hz)
    return min(SHORT_INTERVAL_MIN_S, SHORT_INTERVAL_S - 4.0 * tau)


@dataclass(frozen=True)
class Transmitter:
    name: str
    cycle_s: float
    pulses: Dict[int, np.ndarray]     # code → (P, 2) pulse [start, end) within the cam period, s


def load_transmitters(path=CODES_FILE) -> Dict[str, Transmitter]:
    path = Path(path)
    if not path.is_file():
        raise FmuInputError(f"{path}: file not found")
    try:
        doc = json.loads(path.read_bytes().decode("utf-8-sig"))
        table = doc["transmitters"]
    except UnicodeDecodeError as error:
        raise FmuInputError(f"{path}: not UTF-8 text (offset {error.start}); save the file as UTF-8") from None
    except RecursionError:
        raise FmuInputError(f"{path}: not a code table: nested too deeply") from None
    except (json.JSONDecodeError, KeyError, TypeError):
        raise FmuInputError(f"{path}: field transmitters: missing or not valid JSON") from None
    bad = non_finite_number(doc)
    if bad is not None:
        raise FmuInputError(f"{path}: field {bad[0]}: {bad[1]} is not a finite number")
    if not isinstance(table, dict) or not all(isinstance(spec, dict) for spec in table.values()):
        raise FmuInputError(f"{path}: field transmitters: expected an object of transmitter objects")
    result = {}
    for name, spec in table.items():
        where = f"transmitters.{name}"
        cycle = spec.get("cycle_s")
        if not isinstance(cycle, (int, float)) or cycle <= 0:
            raise FmuInputError(f"{path}: field {where}.cycle_s: must be a positive number of seconds")
        pulses = {}
        for code_name, code in CODE_NAMES.items():
            timings = spec.get("codes", {}).get(code_name)
            field = f"{where}.codes.{code_name}"
            if not isinstance(timings, list) or len(timings) % 2 or not timings:
                raise FmuInputError(f"{path}: field {field}: expected pulse, interval, ... pairs")
            if any(not isinstance(d, (int, float)) or d <= 0 for d in timings):
                raise FmuInputError(f"{path}: field {field}: every timing must be positive")
            if abs(sum(timings) - cycle) > 1e-6:
                raise FmuInputError(f"{path}: field {field}: timings sum to {sum(timings):.4f} s, "
                                    f"not the cycle {cycle} s")
            edges = np.concatenate([[0.0], np.cumsum(timings)])
            pulses[code] = np.stack([edges[0:-1:2], edges[1::2]], axis=1)
        result[name] = Transmitter(name, float(cycle), pulses)
    return result


def classify_cycle(short_intervals: int, cycle_s: float) -> Tuple[int, str]:
    """(code, transmitter) of one cycle by the kpt.h rules; (NO_CODE, "") when invalid."""
    if short_intervals > 2 or short_intervals < 0:        # < 0: marked implausible by the receiver
        return NO_CODE, ""
    period = cycle_s * 2.0 if short_intervals == 0 else cycle_s   # КЖ repeats twice per period
    if KPT5_WINDOW_S[0] < period < KPT5_WINDOW_S[1]:
        kind = "KPT-5"
    elif KPT7_WINDOW_S[0] <= period < KPT7_WINDOW_S[1]:
        kind = "KPT-7"
    else:
        return NO_CODE, ""
    return {2: sig.GREEN, 1: sig.YELLOW, 0: sig.RED_YELLOW}[short_intervals], kind


def check_carrier_and_rate(carrier_hz: float, fs_hz: float, where: str) -> None:
    if not any(abs(carrier_hz - c) < 1e-9 for c in SUPPORTED_CARRIERS_HZ):
        raise FmuInputError(f"{where}carrier: {carrier_hz:g} Hz is not an ALSN carrier "
                            f"({', '.join(f'{c:g}' for c in SUPPORTED_CARRIERS_HZ)} Hz)")
    if fs_hz < MIN_SAMPLES_PER_CARRIER_PERIOD * carrier_hz:
        raise FmuInputError(f"parameter fs: {fs_hz:g} Hz is below {MIN_SAMPLES_PER_CARRIER_PERIOD}× the "
                            f"carrier {carrier_hz:g} Hz")


def speeds_for(category: str, aspect: int, v_max_mps: float) -> Tuple[float, float, int]:
    """(v_permitted, v_target at the next signal, free_blocks) the receiver reports for an aspect."""
    ceiling, at_signal = sig.alsn_speeds_mps(category, aspect)
    permitted = v_max_mps if ceiling is None else min(ceiling, v_max_mps)
    if aspect == sig.RED:
        return permitted, 0.0, 0
    target = permitted if at_signal is None else at_signal
    free = {sig.GREEN: 2, sig.YELLOW: 1}.get(aspect, 0)
    return permitted, target, free
