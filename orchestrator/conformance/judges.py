"""Judges: each check of a vector turns the recorded outputs into one measured figure and holds
it to its bound (docs/contracts.md, "Behavioural conformance"). The kinds are shared by the roles;
what a role checks is data (the vector files), so a judge knows nothing of railways.

A trace holds, per recorded port, one row per step (``Trace.values[port]``: steps × elements)
and the time at the end of each step (``Trace.time_s``); frame ports are recorded sample by
sample (``Trace.samples``). Windows: ``from_s``/``to_s`` on the step-end time, and ``where``
(a list of {port, in | range}) on recorded values of the same step.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Dict, List, Mapping, Optional

import numpy as np
from scipy.ndimage import maximum_filter1d


@dataclass
class Trace:
    time_s: np.ndarray                                    # end of each step
    values: Dict[str, np.ndarray] = field(default_factory=dict)     # port → (steps, elements)
    samples: Dict[str, np.ndarray] = field(default_factory=dict)    # frame row → samples
    sample_time_s: Optional[np.ndarray] = None            # instant of each frame sample

    def column(self, port: str) -> np.ndarray:
        """A scalar port (or the one element of an array port) per step."""
        rows = self.values[port]
        return rows[:, 0] if rows.ndim == 2 else rows


@dataclass
class Verdict:
    vector: str
    check: str                 # the check's label
    measured: float
    bound: str                 # the bound as text ("≤ 4.22 s")
    unit: str
    passed: bool
    note: str = ""

    def as_dict(self) -> dict:
        measured = self.measured if np.isfinite(self.measured) else None
        return {"vector": self.vector, "check": self.check, "measured": measured, "bound": self.bound,
                "unit": self.unit, "passed": self.passed, "note": self.note}


def condition_mask(values: np.ndarray, condition: Mapping) -> np.ndarray:
    """Rows meeting {in: [...]}, {range: [lo, hi]} (either end null: open) on the first element."""
    x = values[:, 0] if values.ndim == 2 else values
    if "in" in condition:
        return np.isin(x, np.asarray(condition["in"], dtype=float))
    lo, hi = condition["range"]
    mask = np.ones(x.shape, dtype=bool)
    if lo is not None:
        mask &= x >= lo
    if hi is not None:
        mask &= x <= hi
    return mask


def window(trace: Trace, check: Mapping) -> np.ndarray:
    t = trace.time_s
    mask = (t >= check.get("from_s", -np.inf) - 1e-9) & (t <= check.get("to_s", np.inf) + 1e-9)
    for condition in check.get("where", ()):
        mask &= condition_mask(trace.values[condition["port"]], condition)
    return mask


def _all_conditions(trace: Trace, conditions: List[Mapping]) -> np.ndarray:
    mask = np.ones(trace.time_s.shape, dtype=bool)
    for condition in conditions:
        mask &= condition_mask(trace.values[condition["port"]], condition)
    return mask


def _fmt(x: float) -> str:
    return f"{x:.4g}"


def judge_latency(trace: Trace, check: Mapping):
    """Time from ``from_s`` until every condition holds at a step end; bound ``bound_s``."""
    start = check["from_s"]
    after = trace.time_s >= start - 1e-9
    hit = np.flatnonzero(after & _all_conditions(trace, check["until"]))
    measured = float(trace.time_s[hit[0]] - start) if hit.size else np.inf
    return measured, f"≤ {_fmt(check['bound_s'])}", "s", measured <= check["bound_s"]


def judge_holds(trace: Trace, check: Mapping):
    """Seconds in the window during which a condition does not hold; bound ``bound_s`` (0)."""
    mask = window(trace, check)
    bad = mask & ~_all_conditions(trace, check["conditions"])
    steps = np.diff(trace.time_s, prepend=0.0)
    measured = float(steps[bad].sum())
    return measured, f"≤ {_fmt(check['bound_s'])}", "s", measured <= check["bound_s"] + 1e-12


def judge_table(trace: Trace, check: Mapping):
    """Values of a port at given instants against the expected rows: mismatches, bound 0."""
    rows = trace.values[check["port"]]
    mismatches = 0
    for at_s, expected in zip(check["at_s"], check["expected"]):
        k = int(np.argmin(np.abs(trace.time_s - at_s)))
        mismatches += int(np.count_nonzero(rows[k, :len(expected)] != np.asarray(expected, dtype=float)))
    return float(mismatches), "= 0", "values", mismatches == 0


def judge_near(trace: Trace, check: Mapping):
    """A port at given instants (``at_s``), or a statistic of it in given windows (``windows``:
    [from, to] pairs; ``statistic`` max, or rms: the root of the mean square, which for a port
    that is itself an rms over each frame is the rms over the window whatever the frame size),
    against expected values: largest deviation, absolute or relative (``relative``: true);
    bound ``tolerance``."""
    column = trace.column(check["port"])
    expected = np.asarray(check["expected"], dtype=float)
    if "windows" in check:
        t = trace.time_s
        rms = check.get("statistic", "max") == "rms"
        inside = [column[(t > lo + 1e-9) & (t <= hi + 1e-9)] for lo, hi in check["windows"]]
        got = np.array([(np.sqrt(np.mean(x ** 2)) if rms else np.max(x)) if x.size else np.nan for x in inside])
    else:
        got = np.array([column[int(np.argmin(np.abs(trace.time_s - at)))] for at in check["at_s"]])
    deviation = np.abs(got - expected)
    if check.get("relative"):
        deviation = deviation / np.maximum(np.abs(expected), 1e-300)
    measured = float(deviation.max()) if np.all(np.isfinite(deviation)) else np.inf
    unit = "" if check.get("relative") else check.get("unit", "")
    return measured, f"≤ {_fmt(check['tolerance'])}", unit, measured <= check["tolerance"]


def judge_extreme(trace: Trace, check: Mapping):
    """The least (``min``) or greatest (``max``) value of a port in the window, minus
    ``offset`` (0), against ``at_least`` or ``at_most``."""
    mask = window(trace, check)
    column = trace.column(check["port"])[mask]
    if column.size == 0:
        return np.nan, "window not reached", check.get("unit", ""), False
    value = float(column.min() if check["extreme"] == "min" else column.max()) - check.get("offset", 0.0)
    if "at_least" in check:
        return value, f"≥ {_fmt(check['at_least'])}", check.get("unit", ""), value >= check["at_least"]
    return value, f"≤ {_fmt(check['at_most'])}", check.get("unit", ""), value <= check["at_most"]


def judge_when(trace: Trace, check: Mapping):
    """A port's value at the first step where the trigger holds, against ``expected`` ±
    ``tolerance``; the measured figure is the signed deviation."""
    hit = np.flatnonzero(_all_conditions(trace, check["trigger"]))
    bound = f"|·| ≤ {_fmt(check['tolerance'])}"
    if not hit.size:
        return np.nan, bound, check.get("unit", ""), False
    deviation = float(trace.column(check["port"])[hit[0]] - check["expected"])
    return deviation, bound, check.get("unit", ""), abs(deviation) <= check["tolerance"]


def keyed_runs(samples: np.ndarray, fs_hz: float, carrier_hz: float):
    """(on, off) run lengths in seconds of a keyed carrier: a sample is keyed when the carrier
    peaks above a tenth of the record's largest value within a twentieth of a carrier period of it. The
    first and last runs (cut by the record's ends) are left out."""
    peak = float(np.max(np.abs(samples))) if samples.size else 0.0
    if peak == 0.0:
        return np.zeros(0), np.zeros(0)
    width = max(3, int(round(0.1 * fs_hz / carrier_hz)))      # bridges the zero crossings only
    on = maximum_filter1d(np.abs(samples), size=width) > 0.1 * peak
    edges = np.flatnonzero(np.diff(on.astype(np.int8))) + 1
    bounds = np.concatenate(([0], edges, [on.size]))
    lengths = np.diff(bounds) / fs_hz
    states = on[bounds[:-1]]
    inner = slice(1, len(lengths) - 1)
    return lengths[inner][states[inner]], lengths[inner][~states[inner]]


def judge_code_timing(trace: Trace, check: Mapping):
    """Pulses and intervals of a keyed carrier (a frame output row) against a code's table:
    the largest relative deviation of any complete pulse or interval from the nearest table
    value of its kind; bound ``tolerance`` (a share). A record with no pulse, or a pulse count per cycle other
    than the table's, fails."""
    samples = trace.samples[check["port"]]
    times = trace.sample_time_s
    mask = times >= check.get("from_s", 0.0)
    pulses, intervals = keyed_runs(samples[mask], check["fs_hz"], check["carrier_hz"])
    table = np.asarray(check["pattern_s"], dtype=float)
    want_pulses, want_intervals = table[0::2], table[1::2]
    bound = f"≤ {_fmt(check['tolerance'])}"
    if pulses.size == 0 or intervals.size == 0:
        return np.inf, bound, "", False
    def worst(runs, table):   # relative deviation from the nearest table value
        nearest = table[np.abs(runs[:, None] - table[None, :]).argmin(axis=1)]
        return float((np.abs(runs - nearest) / nearest).max())

    deviation = max(worst(pulses, want_pulses), worst(intervals, want_intervals))
    record_s = float(mask.sum()) / check["fs_hz"]
    cycles = record_s / check["cycle_s"]
    per_cycle = (pulses.size + 1) / cycles   # runs cut at both ends: about one pulse fewer
    if abs(per_cycle - want_pulses.size) > 0.75:
        return float(per_cycle), f"= {want_pulses.size}", "pulses per cycle", False
    return float(deviation), bound, "", deviation <= check["tolerance"]


def judge_frame_peak(trace: Trace, check: Mapping):
    """The largest |sample| of a recorded frame row in the window, against ``at_least`` or
    ``at_most``."""
    times = trace.sample_time_s
    mask = (times >= check.get("from_s", -np.inf) - 1e-9) & (times < check.get("to_s", np.inf) - 1e-9)
    peak = float(np.max(np.abs(trace.samples[check["port"]][mask]), initial=0.0))
    unit = check.get("unit", "")
    if "at_least" in check:
        return peak, f"≥ {_fmt(check['at_least'])}", unit, peak >= check["at_least"]
    return peak, f"≤ {_fmt(check['at_most'])}", unit, peak <= check["at_most"]


def tone_amplitudes(samples: np.ndarray, fs_hz: float, frequencies_hz) -> np.ndarray:
    """Peak amplitude of each frequency in ``samples``, by least squares on sines and cosines
    of all the frequencies at once (exact for a sum of steady tones at those frequencies)."""
    t = np.arange(samples.size) / fs_hz
    w = 2.0 * np.pi * np.asarray(frequencies_hz, dtype=float)
    basis = np.hstack([np.sin(np.outer(t, w)), np.cos(np.outer(t, w))])
    coefficients, *_ = np.linalg.lstsq(basis, samples, rcond=None)
    return np.hypot(coefficients[:w.size], coefficients[w.size:])


def judge_tones(trace: Trace, check: Mapping):
    """Which tones a recorded frame row carries in the window (an ALSU code: two of six): every
    frequency in ``present`` at least ``at_least`` (peak), every other of ``frequencies_hz`` at
    most ``at_most``. The measured figure is the weakest tone present, or the strongest absent
    one when that is what fails."""
    times = trace.sample_time_s
    mask = (times >= check.get("from_s", -np.inf) - 1e-9) & (times < check.get("to_s", np.inf) - 1e-9)
    amplitudes = tone_amplitudes(trace.samples[check["port"]][mask], check["fs_hz"], check["frequencies_hz"])
    present = np.isin(np.asarray(check["frequencies_hz"], dtype=float), np.asarray(check["present"], dtype=float))
    unit = check.get("unit", "")
    absent = float(amplitudes[~present].max(initial=0.0))
    if absent > check["at_most"]:
        return absent, f"≤ {_fmt(check['at_most'])} (a tone not in the code)", unit, False
    weakest = float(amplitudes[present].min(initial=np.inf))
    return weakest, f"≥ {_fmt(check['at_least'])}", unit, weakest >= check["at_least"]


def frequency_offset_hz(samples: np.ndarray, fs_hz: float, carrier_hz: float) -> np.ndarray:
    """The instantaneous frequency of a frequency-modulated carrier minus the carrier, between
    consecutive samples (from the phase of the analytic signal of the whole row)."""
    from scipy.signal import hilbert

    phase = np.unwrap(np.angle(hilbert(samples)))
    return np.diff(phase) * fs_hz / (2.0 * np.pi) - carrier_hz


def _fm_window(trace: Trace, check: Mapping):
    """(offset Hz, its instants) of a recorded frame row in the check's window."""
    offset = frequency_offset_hz(trace.samples[check["port"]], check["fs_hz"], check["carrier_hz"])
    times = trace.sample_time_s[:-1] + 0.5 / check["fs_hz"]           # between samples n and n+1
    mask = (times >= check.get("from_s", -np.inf) - 1e-9) & (times < check.get("to_s", np.inf) - 1e-9)
    return offset[mask], times[mask]


def judge_fm_tones(trace: Trace, check: Mapping):
    """Which modulation tones a frequency-modulated carrier carries in the window (a TVM-430
    word: one tone per bit): the frequency deviation's amplitude at each of ``frequencies_hz``,
    by least squares on sines and cosines of all of them at once; every frequency in ``present``
    at least ``at_least`` (Hz of deviation), every other at most ``at_most``."""
    offset, times = _fm_window(trace, check)
    w = 2.0 * np.pi * np.asarray(check["frequencies_hz"], dtype=float)
    basis = np.hstack([np.sin(np.outer(times, w)), np.cos(np.outer(times, w)), np.ones((times.size, 1))])
    coefficients, *_ = np.linalg.lstsq(basis, offset, rcond=None)
    amplitudes = np.hypot(coefficients[:w.size], coefficients[w.size:2 * w.size])
    present = np.isin(np.asarray(check["frequencies_hz"], dtype=float), np.asarray(check["present"], dtype=float))
    unit = check.get("unit", "Hz")
    absent = float(amplitudes[~present].max(initial=0.0))
    if absent > check["at_most"]:
        return absent, f"≤ {_fmt(check['at_most'])} (a tone not in the word)", unit, False
    weakest = float(amplitudes[present].min(initial=np.inf))
    return weakest, f"≥ {_fmt(check['at_least'])}", unit, weakest >= check["at_least"]


def judge_frequency_excursion(trace: Trace, check: Mapping):
    """The largest |instantaneous frequency − carrier| of a frequency-modulated frame row in the
    window, at most ``at_most``: a phase step (a transmitter restarting its phase) shows as a
    frequency far off the carrier for one sample."""
    offset, _ = _fm_window(trace, check)
    largest = float(np.max(np.abs(offset), initial=0.0))
    return largest, f"≤ {_fmt(check['at_most'])}", check.get("unit", "Hz"), largest <= check["at_most"]


JUDGES: Dict[str, Callable] = {
    "latency": judge_latency, "holds": judge_holds, "table": judge_table, "near": judge_near,
    "extreme": judge_extreme, "when": judge_when, "code_timing": judge_code_timing,
    "frame_peak": judge_frame_peak, "tones": judge_tones, "fm_tones": judge_fm_tones,
    "frequency_excursion": judge_frequency_excursion,
}


def judge(vector: str, trace: Trace, check: Mapping) -> Verdict:
    measured, bound, unit, passed = JUDGES[check["kind"]](trace, check)
    return Verdict(vector, check["label"], measured, bound, unit, bool(passed), check.get("note", ""))


#: the kinds that read a recorded frame row (the vector's record_frames), not a port per step
FRAME_KINDS = ("code_timing", "frame_peak", "tones", "fm_tones", "frequency_excursion")


def ports_of(check: Mapping) -> List[str]:
    """The recorded ports a check reads."""
    if check["kind"] in FRAME_KINDS:
        return []                                  # frame rows: the vector's record_frames
    ports = [check["port"]] if "port" in check else []
    for key in ("until", "conditions", "trigger", "where"):
        ports += [condition["port"] for condition in check.get(key, ())]
    return ports
