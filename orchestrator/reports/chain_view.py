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
from orchestrator.verdicts.verdict import system_object, transmitted_indication

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
#: share of the rail line's reference current is drawn as not arriving: a train ahead shunts it,
#: a rail is broken or a feed open. The reference is the 95th percentile of that windowed current
#: over every train on the rail line while its coils are on a circuit — relative, because a UM71
#: circuit's 0.2 A is a KPT circuit's 3 A, and over all trains, because a train shunted for most
#: of a run has no current of its own to compare with. Measured over whole runs, the lowest
#: windowed current under which the receiver held a valid code: 0.92 % of the reference on
#: tvm430 (a long UM71 circuit's far end), 3.8 % alsu, 7.4 % als_en, 13.8 % free_run; under the
#: code its leader shunts, following's follower had 10⁻⁶ %.
NO_CURRENT_SHARE = 0.005
REFERENCE_PERCENTILE = 95.0
#: appended to the label of a code sent that does not arrive (drawn hatched)
NOT_ARRIVING = " ✕"
#: the label of a circuit whose code_tx the run did not record (--record)
NOT_RECORDED = "not recorded"
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
    hatched: bool = False          # a code sent whose current does not reach the first axle


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
    step = row_step_s(time_s)
    described: Dict[tuple, tuple] = {}
    segments = []
    for first, end in runs(keys):
        key = tuple(np.atleast_1d(keys[first]).tolist())
        if key not in described:
            described[key] = describe(key)
        t1 = float(time_s[end]) if end < len(time_s) else float(time_s[-1]) + step
        segments.append(Segment(float(time_s[first]), t1, *described[key]))
    return segments


def row_step_s(time_s: np.ndarray) -> float:
    """The output interval of a run's rows (s); a run of one row is drawn 0.1 s wide."""
    return float(time_s[1] - time_s[0]) if len(time_s) > 1 else 0.1


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


class ChainReader:
    """How one receiver's system reads codes: what a code sent means, a decoded code, an
    indication shown — as (label, colour, detail)."""

    def __init__(self, cab: cab_systems.CabSystem, parameters: Mapping[str, object], top_kmh: float):
        self.cab, self.top_kmh = cab, top_kmh
        self.category = str(parameters.get("train_category", "passenger"))
        self.system = system_object(cab, parameters)
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

    def sent(self, key: tuple) -> tuple:
        """``key``: (coil section, raw code_tx of that section — -1: not recorded —, whether its
        current reaches the first axle) — section 0: the coils on no circuit. Returns (label,
        colour, detail, hatched)."""
        section, raw, arrives = int(key[0]), int(key[1]), bool(key[2]) if len(key) > 2 else True
        if section <= 0:
            return "off the circuits", NO_CODE_COLOUR, "the coils are over no track circuit of the line", False
        if raw < 0:
            return NOT_RECORDED, NO_CODE_COLOUR, f"circuit {section}: its code_tx was not recorded (--record)", False
        read = self._of_code(raw)
        if read is None:
            return "no code", NO_CODE_COLOUR, f"circuit {section}: no code sent (code_tx {raw})", False
        aspect, permitted, target, free, code = read
        label = _indication_label(self.cab, aspect, code, permitted, target, free)
        detail = f"circuit {section}: sent code_tx {raw} = " + self._detail(aspect, code, permitted, target, free)
        if not arrives:
            return (label + NOT_ARRIVING, _colour(self.cab, aspect, permitted, self.top_kmh),
                    detail + "; no code current at the first axle (a train ahead in the circuit shunts it, or a "
                    "broken rail or an open feed stops it)", True)
        return label, _colour(self.cab, aspect, permitted, self.top_kmh), detail, False

    def decoded(self, key: tuple) -> Tuple[str, str, str]:
        """``key``: (code_valid, code)."""
        valid, code = bool(key[0]), int(key[1])
        read = self._of_code(code) if valid else None
        if read is None:
            return "none", NO_CODE_COLOUR, f"no valid code decoded (code {code})"
        aspect, permitted, target, free, code = read
        name = _indication_label(self.cab, aspect, code, permitted, target, free)
        return (name, _colour(self.cab, aspect, permitted, self.top_kmh),
                "decoded " + self._detail(aspect, code, permitted, target, free))

    def shown(self, key: tuple) -> Tuple[str, str, str]:
        """``key``: (code_valid, aspect, code, permitted km/h, target km/h, free blocks)."""
        valid, aspect, code, permitted, target, free = (bool(key[0]), int(key[1]), int(key[2]), float(key[3]),
                                                        float(key[4]), int(key[5]))
        if not valid and self.cab.family != cab_systems.NUMERIC:
            # the system's own no-code state: its aspect (red, or white), in words, not ALSN's letters
            return ("no code", ASPECT_COLOURS[sig.RED] if aspect == sig.RED else NO_CODE_COLOUR,
                    f"no valid code: the receiver shows {sig.ASPECT_NAMES.get(aspect, aspect)}, "
                    f"permitted {permitted:.0f} km/h")
        return (_indication_label(self.cab, aspect, code, permitted, target, free),
                _colour(self.cab, aspect, permitted, self.top_kmh), "shown " + self._detail(aspect, code, permitted,
                                                                                           target, free))

    def _detail(self, aspect: int, code: int, permitted_kmh: float, target_kmh: float, free_blocks: int) -> str:
        """What hovering says of a code: the system's own fields (a TVM step has no aspect or
        free blocks of its own to speak of: its step, next step and the code)."""
        if self.cab.speed_steps:
            return f"code {code}: step {permitted_kmh:.0f} km/h, next step {target_kmh:.0f} km/h"
        return (f"code {code}, aspect {sig.ASPECT_NAMES.get(int(aspect), aspect)}, permitted {permitted_kmh:.0f} km/h, "
                f"target {target_kmh:.0f} km/h, free blocks {free_blocks}")


def _column(results: Mapping[str, np.ndarray], name: str, length: int, default: float = 0.0) -> np.ndarray:
    return results[name] if name in results else np.full(length, default)


class NoChain(Exception):
    """Why a receiver's chain cannot be drawn from what the run recorded (said on the page)."""


def _indexed(results: Mapping[str, np.ndarray], prefix: str) -> Dict[int, np.ndarray]:
    """``prefix[k]`` columns by k (``coder.code_tx[3]`` → 3), whichever of them were recorded."""
    found = {}
    for name, values in results.items():
        if name.startswith(prefix + "[") and name.endswith("]") and name[len(prefix) + 1:-1].isdigit():
            found[int(name[len(prefix) + 1:-1])] = values
    return found


def train_chain(results: Mapping[str, np.ndarray], receiver: Mapping[str, object], components: Mapping[str, dict],
                ato: Optional[str], events: Sequence[dict] = (), top_kmh: float = 0.0,
                reference_a: Optional[float] = None) -> TrainChain:
    """The chain view of one receiver (a summary.json ``receivers`` entry); :class:`NoChain` with
    the reason when the run did not record what it needs. ``top_kmh``: the line's top speed (the
    top of TVM's step colours, one for every train); ``reference_a``: the rail line's reference
    code current (:func:`reference_current`)."""
    name, train = str(receiver["receiver"]), str(receiver["train"])
    rail, coder, slot = receiver.get("rail"), receiver.get("coder"), receiver.get("slot")
    if rail is None or coder is None or slot is None:
        raise NoChain(f"receiver {name}: the run's summary.json does not name its rail line and coder "
                      "(a run of an earlier railcosim: run it again)")
    time_s = results["time"]
    n = len(time_s)
    coil = f"{rail}.coil_section[{slot}]"
    missing = [c for c in (coil, f"{name}.aspect") if c not in results]
    codes_sent = _indexed(results, f"{coder}.code_tx")
    if n == 0:
        raise NoChain(f"receiver {name}: the run recorded no rows")
    if missing or not codes_sent:
        raise NoChain(f"receiver {name}: the run did not record {', '.join(missing) or coder + '.code_tx'} "
                      "(recorded with --record: record them too, or run without it)")
    parameters = components.get(name, {}).get("parameters", {})
    try:    # the summary names the system; the parameters give its category and code table
        cab = cab_systems.lookup(str(receiver["system"])) if receiver.get("system") else \
            cab_systems.of_parameters(parameters)
        reader = ChainReader(cab, parameters, top_kmh=top_kmh)
    except (FmuInputError, OSError, ValueError) as error:
        raise NoChain(f"receiver {name}: {error}") from None

    section = results[coil].astype(int)
    circuits = max(codes_sent)
    code_tx = np.full((n, circuits + 1), -1, dtype=np.int64)          # -1: that circuit not recorded
    for k, values in codes_sent.items():
        code_tx[:, k] = values.astype(np.int64)
    inside = (section >= 1) & (section <= circuits)
    sent_raw = np.where(inside, code_tx[np.arange(n), np.clip(section, 0, circuits)], 0)
    sending = inside & (sent_raw > 0)
    arrives = code_arrives(time_s, _column(results, f"{rail}.i_axle[{slot}]", n, np.nan), sending, reference_a)
    sent_keys = np.column_stack((np.where(inside, section, 0), sent_raw, np.where(sending, arrives, 1)))
    valid = _column(results, f"{name}.code_valid", n, 1.0).astype(int)
    code = _column(results, f"{name}.code", n).astype(np.int64)
    aspect = results[f"{name}.aspect"].astype(int)
    permitted = _column(results, f"{name}.v_permitted", n) * KMH_PER_MPS
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
                                      _column(results, f"{rail}.off_line[{slot}]", n), chain.latency_s,
                                      jointless=cab.transmitter == cab_systems.UM71)
    chain.episodes = episodes(receiver, events)
    return chain


def _windowed_peak(time_s: np.ndarray, current_a: np.ndarray) -> np.ndarray:
    from scipy.ndimage import maximum_filter1d

    rows = max(1, int(round(CURRENT_WINDOW_S / row_step_s(time_s))))
    return maximum_filter1d(np.abs(current_a), size=rows)


def reference_current(results: Mapping[str, np.ndarray], rail: str) -> Optional[float]:
    """The rail line's reference code current (A): the :data:`REFERENCE_PERCENTILE` of the
    windowed current under every train's first axle while its coils are on a circuit; None
    when the run recorded none."""
    time_s = results["time"]
    pooled = [_windowed_peak(time_s, current)[_column(results, f"{rail}.coil_section[{k}]", len(time_s)) > 0]
              for k, current in _indexed(results, f"{rail}.i_axle").items()]
    pooled = [p for p in pooled if len(p)]
    if not pooled or len(time_s) < 2:
        return None
    reference = float(np.percentile(np.concatenate(pooled), REFERENCE_PERCENTILE))
    return reference if reference > 0 else None


def code_arrives(time_s: np.ndarray, i_axle_a: np.ndarray, sent: np.ndarray,
                 reference_a: Optional[float]) -> np.ndarray:
    """Per row, 1 where the code current under the train's first axle is there (its maximum over
    :data:`CURRENT_WINDOW_S` at least :data:`NO_CURRENT_SHARE` of ``reference_a``), 0 where it
    is not; 1 throughout when the run did not record the current or gives no reference."""
    if reference_a is None or not np.isfinite(i_axle_a).all() or not sent.any() or len(time_s) < 2:
        return np.ones(len(time_s), dtype=int)
    return (_windowed_peak(time_s, i_axle_a) >= NO_CURRENT_SHARE * reference_a).astype(int)


def explain_errors(time_s: np.ndarray, errors: np.ndarray, sent_keys: np.ndarray, off_line: np.ndarray,
                   latency_s: float, jointless: bool = False) -> List[ReceiverError]:
    """Each increment of ``errors`` with its likely cause, looked for in what happened under the
    coils within the stated latency (+ :data:`CAUSE_MARGIN_S`) before it, or
    :data:`CAUSE_AHEAD_S` after it: the coils crossing from one circuit into the next (an
    insulated joint; ``jointless``: a UM71 circuits' tuned zone), no code sent or none reaching
    the first axle, the train off the line, the code sent changing, the receiver still
    acquiring after the start — else the code was steady and the error is the channel's
    (interference, noise, a weak signal). The coils' first entry onto the line (from no
    circuit) is acquisition, not a crossing."""
    increments = np.flatnonzero(np.diff(errors) > 0) + 1
    window_s = latency_s + CAUSE_MARGIN_S
    circuit = sent_keys[:, 0]
    crossed = np.flatnonzero((np.diff(circuit) != 0) & (circuit[:-1] > 0) & (circuit[1:] > 0)) + 1
    section_changes = time_s[crossed]
    code_changes = time_s[np.flatnonzero(np.diff(sent_keys[:, 1]) != 0) + 1]
    on_line = np.flatnonzero(circuit > 0)
    start_s = float(time_s[on_line[0]]) if len(on_line) else float(time_s[0])
    boundary = ("a UM71 electrical joint: in its tuned zone both circuits' carriers are heard" if jointless
                else "an insulated joint: the code cycle in progress was cut")
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
        elif sent_keys.shape[1] > 2 and not sent_keys[row, 2] and raw > 0:
            found.append(ReceiverError(t, count, "no code", f"circuit {section}'s code current does not reach the "
                                       "first axle (shunted by a train ahead, a broken rail or an open feed)"))
        elif last_section is not None and t - last_section <= window_s:
            found.append(ReceiverError(t, count, "section change",
                                       f"the coils entered circuit {section} at {last_section:.1f} s ({boundary})"))
        elif next_section is not None and next_section - t <= CAUSE_AHEAD_S:
            entered = int(circuit[int(np.searchsorted(time_s, next_section))])
            found.append(ReceiverError(t, count, "section change",
                                       f"the coils were {next_section - t:.1f} s from circuit {entered} (entered at "
                                       f"{next_section:.1f} s; {boundary})"))
        elif raw == 0:
            found.append(ReceiverError(t, count, "no code", f"no code sent in circuit {section}"
                                       + (f" (since {last_code:.1f} s)" if last_code is not None else "")))
        elif t - start_s <= window_s:
            found.append(ReceiverError(t, count, "acquisition", "the receiver was acquiring the code after the start"))
        elif last_code is not None and t - last_code <= window_s:
            found.append(ReceiverError(t, count, "code change", f"the code sent changed at {last_code:.1f} s"))
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
            value = event.get("value")
            found.append(Episode(float(event.get("t", 0.0)), "event",
                                 f"scenario: {event.get('action', 'set')} {event.get('model')}.{event.get('variable')}"
                                 + (f" = {value}" if value is not None else "")))
    return sorted(found, key=lambda e: e.t_s)


def chains(results: Mapping[str, np.ndarray], summary: Mapping[str, object], components: Mapping[str, dict],
           top_kmh: float = 0.0) -> Tuple[List[TrainChain], List[str]]:
    """The chain view of every judged receiver of a run, in summary order, and why any could not
    be drawn. ``top_kmh``: the line's top speed (0: the highest permitted speed any receiver
    showed)."""
    atos = {t["name"]: t.get("ato") for t in summary.get("trains", [])}
    events = summary.get("scenario", {}).get("events_applied", []) if summary.get("scenario") else []
    if top_kmh <= 0:
        top_kmh = max((float(np.max(v, initial=0.0)) * KMH_PER_MPS for k, v in results.items()
                       if k.endswith(".v_permitted")), default=0.0)
    references = {r.get("rail"): reference_current(results, r["rail"]) for r in summary.get("receivers", [])
                  if r.get("rail") and "time" in results}
    found, reasons = [], []
    for receiver in summary.get("receivers", []):
        try:
            found.append(train_chain(results, receiver, components, atos.get(receiver.get("train")), events,
                                     top_kmh, references.get(receiver.get("rail"))))
        except NoChain as why:
            reasons.append(str(why))
    return found, reasons


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
