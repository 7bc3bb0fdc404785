"""The signal chain of a finished run over time, per train, in its cab system's own terms: the
code sent in the track circuit under the train's coils, the code its receiver decoded, the
indication it showed, and each receiver "error" with its likely cause. Pure analysis of the
files a run writes (results.csv, summary.json, metadata.json); ``report.html`` draws it
(orchestrator/reports/interactive.py).

Every label comes from the one registry of cab systems (fmus/signalling/cab_systems.py): the
descriptor's ``label`` for an indication (ALSN's З/Ж/КЖ/К/Б, ALSU's code numbers, TVM's
steps ``270→230``, the digital commands' free blocks and target), its system object for what a
code sent means (``transmitted_indication``, as the verdicts read it).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from fmus.errors import FmuInputError
from fmus.signalling import aspects as sig
from fmus.signalling import cab_systems
from fmus.units import KMH_PER_MPS, MPS_PER_KMH
from orchestrator.verdicts.verdict import _data_file, transmitted_indication

#: an aspect's colour (ALSN, ALSU and the digital systems are drawn by their aspect)
ASPECT_COLOURS = {sig.WHITE: "#d0d0d0", sig.RED: "#d62728", sig.RED_YELLOW: "#ff7f0e",
                  sig.YELLOW: "#ffd700", sig.GREEN: "#2ca02c"}
NO_CODE_COLOUR = "#f4f4f4"
#: speed steps (TVM) are drawn from red (0) through orange and yellow to green (the line's top step)
STEP_COLOURS = ("#d62728", "#ff7f0e", "#ffd700", "#9acd32", "#2ca02c")
#: an error counted this long after a change under the coils is put down to that change, on top
#: of the system's stated latency (a decoding cycle begun before the change ends after it)
CAUSE_MARGIN_S = 1.0
#: the code current under the first axle is taken over this window (s): a KPT code is pulsed, so
#: one recorded instant may fall between two pulses
CURRENT_WINDOW_S = 2.0
#: a code sent whose current under the first axle (its maximum over the window) is below this
#: share of the run's median is drawn as not arriving: a train ahead shunts it, a rail is broken
#: or a feed open — relative, because a UM71 circuit's 0.2 A is a KPT circuit's 3 A
NO_CURRENT_SHARE = 0.05
#: appended to the label of a code sent that does not arrive (drawn hatched)
NOT_ARRIVING = " ✕"
#: an error this long before the coils enter the next circuit is put down to the boundary: over a
#: jointless circuits' tuned zone (UM71) both carriers are heard before the nominal boundary
CAUSE_AHEAD_S = 1.0


@dataclass
class Segment:
    """A stretch of time with one value: [t0, t1) s, its label, its colour, what hovering says."""

    t0_s: float
    t1_s: float
    label: str
    colour: str
    detail: str


@dataclass
class ReceiverError:
    """One increment of a receiver's ``errors`` count and the likely cause."""

    t_s: float
    count: int                     # errors counted at this output instant
    cause: str                     # "section change", "code change", "no code", "acquisition", "steady code"
    explanation: str


@dataclass
class Episode:
    """A wrong-side or unsafe indication the verdicts counted, or a scenario event (a fault)."""

    t_s: float
    kind: str                      # "wrong-side", "unsafe", "event"
    text: str


@dataclass
class TrainChain:
    train: str
    receiver: str
    ato: Optional[str]
    cab: cab_systems.CabSystem
    sent: List[Segment]
    decoded: List[Segment]
    shown: List[Segment]
    errors: List[ReceiverError]
    episodes: List[Episode] = field(default_factory=list)
    latency_s: float = 0.0
    rail: str = "rail"
    slot: int = 1                  # the train's index on the rail line (its coil EMF is e_coil[slot])


def runs(values: np.ndarray) -> List[Tuple[int, int]]:
    """(first row, row after the last) of each run of equal values (rows of a 2-D array)."""
    values = np.asarray(values)
    if not len(values):
        return []
    changed = np.any(values[1:] != values[:-1], axis=tuple(range(1, values.ndim))) if values.ndim > 1 \
        else values[1:] != values[:-1]
    starts = np.concatenate(([0], np.flatnonzero(changed) + 1))
    return list(zip(starts.tolist(), np.concatenate((starts[1:], [len(values)])).tolist()))


def _segments(time_s: np.ndarray, keys: np.ndarray, describe) -> List[Segment]:
    """Segments of equal ``keys`` rows, each described once per distinct key (``describe(key)``
    → (label, colour, detail)): the labels are looked up per run, never per sample."""
    step = float(time_s[1] - time_s[0]) if len(time_s) > 1 else 0.0
    described: Dict[tuple, Tuple[str, str, str]] = {}
    segments = []
    for first, end in runs(keys):
        key = tuple(np.atleast_1d(keys[first]).tolist())
        if key not in described:
            described[key] = describe(key)
        label, colour, detail = described[key]
        t1 = float(time_s[end]) if end < len(time_s) else float(time_s[-1]) + step
        segments.append(Segment(float(time_s[first]), t1, label, colour, detail))
    return segments


def step_colour(permitted_kmh: float, top_kmh: float) -> str:
    if top_kmh <= 0 or permitted_kmh <= 0:
        return STEP_COLOURS[0]
    return STEP_COLOURS[min(len(STEP_COLOURS) - 1, 1 + int((len(STEP_COLOURS) - 2) * permitted_kmh / top_kmh + 1e-9))]


def _colour(cab: cab_systems.CabSystem, aspect: int, permitted_kmh: float, top_kmh: float) -> str:
    if cab.speed_steps:
        return step_colour(permitted_kmh, top_kmh)
    return ASPECT_COLOURS.get(int(aspect), NO_CODE_COLOUR)


def _indication_label(cab: cab_systems.CabSystem, aspect: int, code: int, permitted_kmh: float,
                      target_kmh: float, free_blocks: int) -> str:
    return cab.label({"aspect": aspect, "code": code, "v_permitted": permitted_kmh * MPS_PER_KMH,
                      "v_target": target_kmh * MPS_PER_KMH, "free_blocks": free_blocks})


def _detail(aspect: int, code: int, permitted_kmh: float, target_kmh: float, free_blocks: int) -> str:
    return (f"code {code}, aspect {sig.ASPECT_NAMES.get(int(aspect), aspect)}, permitted {permitted_kmh:.0f} km/h, "
            f"target {target_kmh:.0f} km/h, free blocks {free_blocks}")


class ChainReader:
    """How one receiver's system reads codes: what a code sent means, a decoded code, an
    indication shown — as (label, colour, detail)."""

    def __init__(self, cab: cab_systems.CabSystem, parameters: Mapping[str, object], top_kmh: float):
        self.cab, self.top_kmh = cab, top_kmh
        self.category = str(parameters.get("train_category", "passenger"))
        table = parameters.get("codes_file")
        self.system = cab.system(str(_data_file(table, cab.codes_file)) if table and cab.codes_file else None)
        self.v_max_mps = float(parameters.get("v_max", 0.0) or 0.0)

    def _of_code(self, code: int) -> Optional[Tuple[int, float, float, int, int]]:
        """(aspect, permitted km/h, target km/h, free blocks, code) of a code as the coder sends
        it and the receiver reports it (``code_tx``, ``code``: one numbering); None: no code."""
        if self.cab.family == cab_systems.NUMERIC:
            if code == 0:
                return None
            out = self.cab.receiver_outputs(None, code, self.category, self.v_max_mps, 0.0)
            return (int(out["aspect"]), out["v_permitted"] * KMH_PER_MPS, out["v_target"] * KMH_PER_MPS,
                    int(out["free_blocks"]), int(out["code"]))
        try:
            ind = transmitted_indication(self.system, code, self.category)
        except (KeyError, ValueError, IndexError, FmuInputError):
            return None
        return None if ind is None else (ind.aspect, ind.permitted_kmh, ind.target_kmh, ind.free_blocks, ind.code)

    def sent(self, key: tuple) -> Tuple[str, str, str]:
        """``key``: (coil section, raw code_tx of that section, whether its current reaches the
        first axle) — section 0: the coils on no circuit."""
        label, colour, detail = self._sent(int(key[0]), int(key[1]))
        if len(key) > 2 and not key[2] and label not in ("off the circuits", "no code"):
            return (label + NOT_ARRIVING, colour, detail + "; no code current at the first axle (a train ahead in the "
                    "circuit shunts it, or a broken rail or an open feed stops it)")
        return label, colour, detail

    def _sent(self, section: int, raw: int) -> Tuple[str, str, str]:
        if section <= 0:
            return "off the circuits", NO_CODE_COLOUR, "the coils are over no track circuit of the line"
        read = self._of_code(raw)
        if read is None:
            return "no code", NO_CODE_COLOUR, f"circuit {section}: no code sent (code_tx {raw})"
        aspect, permitted, target, free, code = read
        return (_indication_label(self.cab, aspect, code, permitted, target, free), _colour(self.cab, aspect, permitted, self.top_kmh),
                f"circuit {section}: sent code_tx {raw} = " + _detail(aspect, code, permitted, target, free))

    def decoded(self, key: tuple) -> Tuple[str, str, str]:
        """``key``: (code_valid, code)."""
        valid, code = bool(key[0]), int(key[1])
        read = self._of_code(code) if valid else None
        if read is None:
            return "none", NO_CODE_COLOUR, f"no valid code decoded (code {code})"
        aspect, permitted, target, free, code = read
        name = _indication_label(self.cab, aspect, code, permitted, target, free)
        return name, _colour(self.cab, aspect, permitted, self.top_kmh), "decoded " + _detail(aspect, code, permitted, target, free)

    def shown(self, key: tuple) -> Tuple[str, str, str]:
        """``key``: (code_valid, aspect, code, permitted km/h, target km/h, free blocks)."""
        valid, aspect, code, permitted, target, free = (bool(key[0]), int(key[1]), int(key[2]), float(key[3]),
                                                        float(key[4]), int(key[5]))
        if not valid and self.cab.family != cab_systems.NUMERIC:
            letter = cab_systems.ALSN_LETTERS.get(aspect, "?")
            return (f"no code ({letter})", _colour(self.cab, aspect, 0.0, self.top_kmh) if aspect == sig.RED else NO_CODE_COLOUR,
                    f"no valid code: the receiver shows {sig.ASPECT_NAMES.get(aspect, aspect)}")
        return (_indication_label(self.cab, aspect, code, permitted, target, free),
                _colour(self.cab, aspect, permitted, self.top_kmh), "shown " + _detail(aspect, code, permitted, target, free))


def _column(results: Mapping[str, np.ndarray], name: str, length: int, default: float = 0.0) -> np.ndarray:
    return results[name] if name in results else np.full(length, default)


def train_chain(results: Mapping[str, np.ndarray], receiver: Mapping[str, object], components: Mapping[str, dict],
                ato: Optional[str], events: Sequence[dict] = ()) -> Optional[TrainChain]:
    """The chain view of one receiver (a summary.json ``receivers`` entry); None when the run
    did not record what it needs (the receiver's outputs, the coil section, the codes sent)."""
    name, train = str(receiver["receiver"]), str(receiver["train"])
    rail, coder, slot = receiver.get("rail"), receiver.get("coder"), receiver.get("slot")
    if rail is None or coder is None or slot is None:
        return None                                  # a run from before summary.json named them
    time_s = results["time"]
    n = len(time_s)
    coil = f"{rail}.coil_section[{slot}]"
    sections = sorted((k for k in results if k.startswith(f"{coder}.code_tx[")), key=lambda k: int(k.split("[")[1][:-1]))
    if n == 0 or coil not in results or not sections or f"{name}.aspect" not in results:
        return None
    parameters = components.get(name, {}).get("parameters", {})
    try:
        cab = cab_systems.of_parameters(parameters)
    except FmuInputError:
        return None
    permitted = _column(results, f"{name}.v_permitted", n) * KMH_PER_MPS
    reader = ChainReader(cab, parameters, top_kmh=float(np.max(permitted, initial=0.0)))

    section = results[coil].astype(int)
    code_tx = np.column_stack([results[k] for k in sections]).astype(int)
    inside = (section >= 1) & (section <= len(sections))
    sent_raw = np.where(inside, code_tx[np.arange(n), np.clip(section - 1, 0, len(sections) - 1)], 0)
    arrives = code_arrives(time_s, _column(results, f"{rail}.i_axle[{slot}]", n, np.nan), inside & (sent_raw != 0))
    sent_keys = np.column_stack((np.where(inside, section, 0), sent_raw, arrives))
    valid = _column(results, f"{name}.code_valid", n, 1.0).astype(int)
    code = _column(results, f"{name}.code", n).astype(int)
    aspect = results[f"{name}.aspect"].astype(int)
    # ALSN's display is its aspect: a code decoded afresh under a held aspect does not change it
    shown_code = aspect if cab.family == cab_systems.NUMERIC else code
    shown_keys = np.column_stack((valid, aspect, shown_code, np.round(permitted, 1),
                                  np.round(_column(results, f"{name}.v_target", n) * KMH_PER_MPS, 1),
                                  _column(results, f"{name}.free_blocks", n).astype(int)))
    chain = TrainChain(train=train, receiver=name, ato=ato, cab=cab,
                       sent=_segments(time_s, sent_keys, reader.sent),
                       decoded=_segments(time_s, np.column_stack((valid, code)), reader.decoded),
                       shown=_segments(time_s, shown_keys, reader.shown),
                       errors=[], latency_s=float(receiver.get("latency_s", cab.latency_s(parameters))),
                       rail=str(rail), slot=int(slot))
    if f"{name}.errors" in results:
        chain.errors = explain_errors(time_s, results[f"{name}.errors"], sent_keys,
                                      _column(results, f"{rail}.off_line[{slot}]", n), chain.latency_s)
    chain.episodes = episodes(receiver, events)
    return chain


def code_arrives(time_s: np.ndarray, i_axle_a: np.ndarray, sent: np.ndarray) -> np.ndarray:
    """Per row, 1 where the code current under the train's first axle is there (its maximum over
    :data:`CURRENT_WINDOW_S` at least :data:`NO_CURRENT_SHARE` of the median over the rows a code
    is sent), 0 where it is not; 1 throughout when the run did not record the current."""
    from scipy.ndimage import maximum_filter1d

    if not np.isfinite(i_axle_a).all() or not sent.any() or len(time_s) < 2:
        return np.ones(len(time_s), dtype=int)
    rows = max(1, int(round(CURRENT_WINDOW_S / float(time_s[1] - time_s[0]))))
    peak = maximum_filter1d(np.abs(i_axle_a), size=rows)
    return (peak >= NO_CURRENT_SHARE * float(np.median(peak[sent]))).astype(int)


def explain_errors(time_s: np.ndarray, errors: np.ndarray, sent_keys: np.ndarray, off_line: np.ndarray,
                   latency_s: float) -> List[ReceiverError]:
    """Each increment of ``errors`` with its likely cause, looked for in what happened under the
    coils within the stated latency (+ :data:`CAUSE_MARGIN_S`) before it: the coils crossing
    into another circuit (a joint), the code sent changing, no code sent or the train off the
    line, the receiver still acquiring after the start — else the code was steady and the
    error is the channel's (interference, noise, a weak signal)."""
    increments = np.flatnonzero(np.diff(errors) > 0) + 1
    window_s = latency_s + CAUSE_MARGIN_S
    section_changes = time_s[np.flatnonzero(np.diff(sent_keys[:, 0]) != 0) + 1]
    code_changes = time_s[np.flatnonzero(np.diff(sent_keys[:, 1]) != 0) + 1]
    found = []
    for row in increments.tolist():
        t = float(time_s[row])
        count = int(errors[row] - errors[row - 1])
        last_section = _last_before(section_changes, t)
        next_section = _first_after(section_changes, t)
        last_code = _last_before(code_changes, t)
        section, raw = int(sent_keys[row, 0]), int(sent_keys[row, 1])
        if off_line[row] > 0.5 or section <= 0:
            found.append(ReceiverError(t, count, "no code", "the train is off the coded circuits"))
        elif sent_keys.shape[1] > 2 and not sent_keys[row, 2] and raw != 0:
            found.append(ReceiverError(t, count, "no code", f"circuit {section}'s code current does not reach the "
                                       "first axle (shunted by a train ahead, a broken rail or an open feed)"))
        elif last_section is not None and t - last_section <= window_s:
            found.append(ReceiverError(t, count, "section change",
                                       f"the coils entered circuit {section} at {last_section:.1f} s (a joint: "
                                       f"the code cycle in progress was cut)"))
        elif next_section is not None and next_section - t <= CAUSE_AHEAD_S:
            entered = int(sent_keys[int(np.searchsorted(time_s, next_section)), 0])
            found.append(ReceiverError(t, count, "section change",
                                       f"the coils were {next_section - t:.1f} s from circuit {entered} (entered at "
                                       f"{next_section:.1f} s): over the boundary both circuits' currents are heard"))
        elif raw == 0:
            found.append(ReceiverError(t, count, "no code", f"no code sent in circuit {section}"
                                       + (f" (since {last_code:.1f} s)" if last_code is not None else "")))
        elif last_code is not None and t - last_code <= window_s:
            found.append(ReceiverError(t, count, "code change", f"the code sent changed at {last_code:.1f} s"))
        elif t - float(time_s[0]) <= window_s:
            found.append(ReceiverError(t, count, "acquisition", "the receiver was acquiring the code after the start"))
        else:
            found.append(ReceiverError(t, count, "steady code",
                                       "the code sent was steady: interference or noise at the receiver"))
    return found


def _first_after(times: np.ndarray, t: float) -> Optional[float]:
    k = int(np.searchsorted(times, t, side="right"))
    return float(times[k]) if k < len(times) else None


def _last_before(times: np.ndarray, t: float) -> Optional[float]:
    k = int(np.searchsorted(times, t, side="right"))
    return float(times[k - 1]) if k else None


def episodes(receiver: Mapping[str, object], events: Sequence[dict]) -> List[Episode]:
    """The verdicts' wrong-side and unsafe episodes of this receiver, and the scenario's events
    (faults and their repairs, a signaller's commands) on the components of its chain."""
    found = [Episode(float(e["t"]), "wrong-side", f"wrong-side failure: circuit {e.get('section')}, "
                     f"code sent {e.get('code_sent')}") for e in receiver.get("wrong_side_events", [])]
    found += [Episode(float(e["t"]), "unsafe", f"unsafe indication: circuit {e.get('section')}, "
                      f"{e.get('free_blocks_allowed')} free blocks allowed, aspect shown "
                      f"{sig.ASPECT_NAMES.get(e.get('aspect_shown'), e.get('aspect_shown'))}")
              for e in receiver.get("unsafe_events", [])]
    chain = {receiver.get("receiver"), receiver.get("rail"), receiver.get("coder"), receiver.get("train")}
    for event in events:
        if event.get("model") in chain:
            found.append(Episode(float(event.get("t", 0.0)), "event",
                                 f"scenario: {event.get('action', 'set')} {event.get('model')}.{event.get('variable')}"
                                 + (f" = {event['value']}" if "value" in event else "")))
    return sorted(found, key=lambda e: e.t_s)


def chains(results: Mapping[str, np.ndarray], summary: Mapping[str, object],
           components: Mapping[str, dict]) -> List[TrainChain]:
    """The chain view of every judged receiver of a run, in summary order."""
    atos = {t["name"]: t.get("ato") for t in summary.get("trains", [])}
    events = summary.get("scenario", {}).get("events_applied", []) if summary.get("scenario") else []
    found = []
    for receiver in summary.get("receivers", []):
        chain = train_chain(results, receiver, components, atos.get(receiver.get("train")), events)
        if chain is not None:
            found.append(chain)
    return found


def occupancy(results: Mapping[str, np.ndarray], rail: str) -> Dict[int, List[Tuple[float, float]]]:
    """Circuit k (1-based) → the [t0, t1) s it was occupied, from the rail line's ``occupied[k]``."""
    time_s = results["time"]
    step = float(time_s[1] - time_s[0]) if len(time_s) > 1 else 0.0
    found: Dict[int, List[Tuple[float, float]]] = {}
    prefix = f"{rail}.occupied["
    for name in results:
        if not name.startswith(prefix):
            continue
        k = int(name[len(prefix):-1])
        values = results[name] > 0.5
        spans = [(float(time_s[a]), float(time_s[b]) if b < len(time_s) else float(time_s[-1]) + step)
                 for a, b in runs(values) if values[a]]
        if spans:
            found[k] = spans
    return found
