"""The block sections of a railML import (docs/railml.md#block-sections): the train detectors
and block signals on the running path, the path between consecutive detectors as the TVD section
both demarcate, each section's carrier, transmitter and ballast (the file's, the sidecar's or a
default, docs/railml.md#defaults), the tuned separation zones between UM71 circuits, and a long
section cut into track circuits that calibrate.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

from orchestrator.errors import UserError
from orchestrator.railml.document import (DEFAULTS, RC, SIGNAL_FUNCTIONS_CLOSING_A_BLOCK, Document,
                                          interlocking_assets, local_name, signal_kind)
from orchestrator.railml.topology import Locator, clean_position

#: a block signal belongs to the section whose end lies this far ahead of it at most (m): a
#: signal stands at, or a little before, the joint it protects
SIGNAL_TO_JOINT_M = 60.0
#: the longest coded track circuit the import makes (m): a longer TVD section (an axle-counter
#: section of kilometres) becomes several track circuits in one block. At the normative minimum
#: ballast (1 Ω·km) a 50 Hz track circuit calibrates up to about 2.7 km (the rail line says so at
#: initialisation, docs/rail_line.md); the shipped lines' longest is 2.6 km
MAX_TRACK_CIRCUIT_M = 2600.0
#: the carriers of coded ALSN track circuits and of audio-frequency TVM (UM71) ones, Hz, and the
#: transmitter of the latter (docs/interfaces.md#line-file-tvm-430-sections)
ALSN_CARRIERS_HZ = (25, 50, 75)
TVM_CARRIERS_HZ = (1700, 2000, 2300, 2600)
TVM_TRANSMITTER = "UM71"


@dataclass
class Detector:
    position: float
    id: str
    kind: str            # insulatedRailJoint, trackCircuit, axleCounter, … or bufferStop / pathEnd
    element: object
    #: a tuned separation zone between two UM71 circuits: its line-file entry (position_m, length_m)
    zone: Optional[dict] = None


def detectors(doc: Document, fi, locate: Locator, extras, notes):
    """Train detection elements on the path (sorted) and the insulated joints of the line file.
    A border marked ``rcs:separationZone`` (or named in the sidecar's zones) is a UM71
    separation zone: its :attr:`Detector.zone` is the line file's entry."""
    found: List[Detector] = []
    joints = []
    off_path = 0
    for element in doc.findall(fi, "trainDetectionElements", "trainDetectionElement"):
        spots = locate.spots(element)
        if not spots:
            off_path += 1
            continue
        kind = element.get("type") or element.get("detectionType") or "trackCircuit"
        position = clean_position(spots[0][0])
        found.append(Detector(position, element.get("id"), kind, element,
                              _zone(doc, element, kind, position, extras.get("zones", {}))))
        if kind == "insulatedRailJoint":
            joints.append(_joint(doc, element, position, extras))
    kinds = sorted({d.kind for d in found if d.zone is None} - {"insulatedRailJoint"})
    if kinds:
        notes.append(f"train detection of type {', '.join(kinds)} modelled as coded track-circuit borders "
                     "(ALSN codes run in the rails of track circuits); only insulatedRailJoint elements are "
                     "insulated joints")
    if off_path:
        notes.append(f"{off_path} trainDetectionElement(s) off the running path ignored")
    found.sort(key=lambda d: d.position)
    joints.sort(key=lambda j: j["position_m"])
    return found, joints


def _zone(doc: Document, element, kind: str, position, zone_extras: dict) -> Optional[dict]:
    """The separation zone's line-file entry of a detector the file or the sidecar marks as one."""
    if element.get(RC + "separationZone") not in ("true", "1") and element.get("id") not in zone_extras:
        return None
    if kind == "insulatedRailJoint":
        doc.fail(element, "an insulated rail joint marked a separation zone: a UM71 separation zone "
                          "is a jointless track-circuit border (type trackCircuit)")
    zone = {"position_m": position}
    length = zone_extras.get(element.get("id"), {}).get("length_m")
    if length is None and element.get(RC + "separationZoneLengthM") is not None:
        length = doc.float_attr(element, RC + "separationZoneLengthM")
    if length is not None:
        zone["length_m"] = length
    return zone


def _joint(doc: Document, element, position, extras) -> dict:
    """An insulated joint's line-file entry: its impedance bond and bond lead offset from our
    extension, the sidecar's for this joint overriding them, the sidecar's defaults filling in."""
    joint = {"position_m": position}
    if element.get(RC + "impedanceBond") is not None:
        joint["impedance_bond"] = element.get(RC + "impedanceBond") == "true"
    if element.get(RC + "bondLeadOffsetM") is not None:
        joint["bond_lead_offset_m"] = doc.float_attr(element, RC + "bondLeadOffsetM")
    own = extras.get("joints", {}).get(element.get("id"), {})
    defaults = extras.get("defaults", {})
    for key in ("impedance_bond", "bond_lead_offset_m"):
        value = own.get(key, defaults.get(key))
        if value is not None and (key not in joint or key in own):
            joint[key] = value
    return joint


@dataclass
class BlockSignal:
    """A block signal on the path, facing the train."""
    position: float
    name: str
    id: str


def block_signals(doc: Document, fi, locate: Locator, notes) -> List[BlockSignal]:
    """The signals on the path that close a block and face the train, sorted; the others noted."""
    signals, other_kinds, against, off_path = [], {}, 0, 0
    for element in doc.findall(fi, "signalsIS", "signalIS"):
        kind = signal_kind(doc, element)
        spots = locate.spots(element)
        if not spots:
            off_path += 1
            continue
        if kind not in SIGNAL_FUNCTIONS_CLOSING_A_BLOCK:
            label = kind or "speed or other (no train movement)"
            other_kinds[label] = other_kinds.get(label, 0) + 1
            continue
        position, spot = spots[0]
        if not locate.path.faces_running(spot.get("netElementRef"), spot.get("applicationDirection")):
            against += 1
            continue
        signals.append(BlockSignal(position, doc.name_of(element) or element.get("id"), element.get("id")))
    if other_kinds:
        notes.append("signals that close no block ignored: "
                     + ", ".join(f"{n} {k}" for k, n in sorted(other_kinds.items())))
    if against:
        notes.append(f"{against} block signal(s) for the other running direction ignored")
    if off_path:
        notes.append(f"{off_path} signal(s) off the running path ignored")
    signals.sort(key=lambda s: s.position)
    return signals


def _tvd_sections(doc: Document) -> List[object]:
    return [tvd for assets in interlocking_assets(doc) for tvd in doc.findall(assets, "tvdSections", "tvdSection")]


def _demarcation(doc: Document, tvds: List[object]) -> Tuple[Dict[str, List[object]], Dict[str, set]]:
    """The TVD section(s) each detector (or buffer stop) demarcates, and each TVD section's exit
    signals (the signalIS ids, a signalIL named by what it refers to)."""
    demarcates: Dict[str, List[object]] = {}
    exit_signals: Dict[str, set] = {}
    for tvd in tvds:
        for tag in ("hasDemarcatingTraindetector", "hasDemarcatingBufferstop"):
            for ref in doc.findall(tvd, tag):
                demarcates.setdefault(ref.get("ref"), []).append(tvd)
        exits = set()
        for ref in doc.findall(tvd, "hasExitSignal"):
            target = doc.by_id.get(ref.get("ref"))
            if target is not None and local_name(target) == "signalIL":
                refers = doc.find(target, "refersTo")
                exits.add(refers.get("ref") if refers is not None else ref.get("ref"))
            else:
                exits.add(ref.get("ref"))
        exit_signals[tvd.get("id")] = exits
    return demarcates, exit_signals


def _bounds(doc: Document, locate: Locator, detectors: List[Detector], signals: List[BlockSignal],
            notes) -> List[Detector]:
    """Where block sections begin and end along the path: the detectors (a joint at each block
    signal when the path has none), the buffer stops, and the path's ends where nothing else
    closes the first or the last stretch."""
    path_ = locate.path
    points = list(detectors)
    if not points:
        if not signals:
            raise UserError(f"{doc.path}: no train detection element and no block signal on the running path "
                            f"({' → '.join(s.id for s in path_.steps)}): no block section can be made")
        points = [Detector(clean_position(s.position), f"joint at signal {s.name}", "insulatedRailJoint", None)
                  for s in signals]
        notes.append("no train detection on the path: an insulated joint assumed at each block signal "
                     f"({', '.join(s.name for s in signals)})")
    buffer_stops = []
    for stop in doc.findall(doc.find(doc.root, "infrastructure", "functionalInfrastructure"), "bufferStops",
                            "bufferStop"):
        for position, _ in locate.spots(stop):
            buffer_stops.append(Detector(clean_position(position), stop.get("id"), "bufferStop", stop))
    bounds = sorted(points + buffer_stops, key=lambda d: d.position)
    if bounds[0].position > 1e-6:
        bounds.insert(0, Detector(0, "the path's start", "pathEnd", None))
    if bounds[-1].position < path_.length - 1e-6:
        bounds.append(Detector(clean_position(path_.length), "the path's end", "pathEnd", None))
    return bounds


@dataclass
class _Stretch:
    """The path between two consecutive bounds: the TVD section both demarcate (None in a file
    without TVD sections), its id and name, and the detector at its end."""
    tvd: Optional[object]
    ident: str
    name: str
    start_m: float
    end_m: float
    end: Detector


def _stretches(doc: Document, bounds: List[Detector], tvds: List[object], demarcates, notes) -> List[_Stretch]:
    """The stretches between consecutive bounds, each the TVD section its two bounds demarcate;
    a stretch no TVD section covers is refused, but for track beyond the first or last detector."""
    stretches, derived, open_ends = [], [], []
    for a, b in zip(bounds[:-1], bounds[1:]):
        if b.position - a.position < 1e-6:
            continue
        common = [t for t in demarcates.get(a.id, []) if t in demarcates.get(b.id, [])]
        tvd = common[0] if common else None
        if tvds and tvd is None:
            if a.kind == "pathEnd" or b.kind == "pathEnd":
                open_ends.append((a, b))    # track beyond the first or last detector: checked below
                continue
            _refuse_uncovered(doc, a, b, stretches, demarcates)
        if tvd is not None:
            ident = tvd.get("id")
            name = (doc.find(tvd, "designator").get("entry") if doc.find(tvd, "designator") is not None
                    else None) or ident
        else:
            ident = f"S{len(stretches) + 1}"
            name = str(len(stretches) + 1)
            derived.append(ident)
        stretches.append(_Stretch(tvd, ident, name, a.position, b.position, b))
    _check_open_ends(doc, open_ends, stretches, demarcates, notes)
    if derived and not tvds:
        notes.append("no tvdSections in the interlocking: block sections made between consecutive train "
                     f"detectors ({', '.join(derived)}; name them in the sidecar's sections)")
    if not stretches:
        raise UserError(f"{doc.path}: no block section on the running path")
    return stretches


def _refuse_uncovered(doc: Document, a: Detector, b: Detector, stretches: List[_Stretch], demarcates) -> None:
    """A stretch between two detectors that no TVD section covers: refused naming the TVD
    section left open there (one of the two detectors demarcates it, and it is not closed
    elsewhere on the path)."""
    made_so_far = {id(s.tvd) for s in stretches}
    owners = [t.get("id") for t in demarcates.get(a.id, []) + demarcates.get(b.id, [])
              if id(t) not in made_so_far] or [t.get("id") for t in demarcates.get(a.id, []) +
                                               demarcates.get(b.id, [])]
    where = f"between {a.id!r} ({a.position:g} m) and {b.id!r} ({b.position:g} m)"
    if not owners:
        raise UserError(f"{doc.path}: trainDetectionElement {a.id!r}: no tvdSection is demarcated by it "
                        f"and {b.id!r}: the stretch {where} has no block section")
    detectors_of = sorted(r.get("ref") for r in doc.findall(doc.by_id[owners[0]], "hasDemarcatingTraindetector"))
    raise UserError(f"{doc.path}: tvdSection {owners[0]!r}: no train detection at its end on the running path "
                    f"{where} (it is demarcated by {', '.join(detectors_of)})")


def _check_open_ends(doc: Document, open_ends, stretches: List[_Stretch], demarcates, notes) -> None:
    """Track beyond the first or the last detector: a note, unless a TVD section the detector
    demarcates is left without its other end (refused)."""
    made = {id(s.tvd) for s in stretches if s.tvd is not None}
    for a, b in open_ends:
        detector, end = (b, a) if a.kind == "pathEnd" else (a, b)
        unclosed = [t.get("id") for t in demarcates.get(detector.id, []) if id(t) not in made]
        if unclosed:
            raise UserError(f"{doc.path}: tvdSection {unclosed[0]!r}: no train detection at its end on the running "
                            f"path: it runs from {detector.id!r} ({detector.position:g} m) to {end.id} "
                            f"({end.position:g} m) with no detector there")
        notes.append(f"{end.position - detector.position if end is b else detector.position - end.position:g} m of "
                     f"track beyond {detector.id!r} ({detector.position:g} m) to {end.id} has no track circuit")


class _Assumed:
    """What a block section takes where neither the sidecar nor the file says (the sidecar's
    defaults, else the built-in ones), and how many sections took each: one note per kind."""

    def __init__(self, defaults: dict, electrification: str):
        self.carrier_hz = defaults.get("carrier_hz") or (DEFAULTS["carrier_hz_ac"] if electrification == "AC25000"
                                                         else DEFAULTS["carrier_hz_dc"])
        self.transmitter = defaults.get("transmitter", DEFAULTS["transmitter"])
        self.ballast_ohm_km = defaults.get("ballast_ohm_km", DEFAULTS["ballast_ohm_km"])
        self.counts = {"carrier": 0, "transmitter": 0, "ballast": 0}

    def notes(self) -> List[str]:
        values = {"carrier": f"{self.carrier_hz} Hz", "transmitter": self.transmitter,
                  "ballast": f"{self.ballast_ohm_km} Ω·km"}
        return [f"{what} of {count} block section(s) not in the file: {values[what]} assumed (docs/railml.md#defaults)"
                for what, count in self.counts.items() if count]


def block_sections(doc: Document, locate: Locator, detectors: List[Detector], signals: List[BlockSignal],
                   electrification: str, extras, notes, section_ids: Optional[List[str]] = None) -> List[dict]:
    """Block sections: the path between consecutive train detectors, each the TVD section that
    both demarcate (docs/railml.md#block-sections), with the block signal at its exit and its
    track circuit's transmitter, carrier and ballast. ``section_ids`` gets the id of each
    (the keys the sidecar's ``sections`` may use)."""
    tvds = _tvd_sections(doc)
    demarcates, exit_signals = _demarcation(doc, tvds)
    stretches = _stretches(doc, _bounds(doc, locate, detectors, signals, notes), tvds, demarcates, notes)
    if section_ids is not None:
        section_ids.extend(s.ident for s in stretches)
    section_extras = extras.get("sections", {})
    assumed = _Assumed(extras.get("defaults", {}), electrification)
    used = set()
    result = []
    for stretch in stretches:
        signal = _exit_signal(signals, used, stretch.end_m, exit_signals.get(stretch.ident, set()))
        entry = {"name": stretch.name, "start_m": stretch.start_m, "end_m": stretch.end_m,
                 "signal": signal.name if signal is not None else ""}
        own = section_extras.get(stretch.ident, {})
        circuit = _circuit(doc, stretch, own, result, assumed)
        if "name" in own:
            entry["name"] = own["name"]
        entry.update(circuit)
        result.append(entry)
    _check_separation_zones(doc, result, [s.ident for s in stretches], [s.end for s in stretches], detectors)
    result = _split_long(result, notes)
    unused = [s.name for s in signals if s.id not in used]
    if unused:
        notes.append(f"block signals not at a section's exit (more than {SIGNAL_TO_JOINT_M:g} m before its end) "
                     f"ignored: {', '.join(unused)}")
    notes.extend(assumed.notes())
    return result


def _exit_signal(signals: List[BlockSignal], used: set, end_m: float, exits: set) -> Optional[BlockSignal]:
    """The block signal at a section's exit: at most SIGNAL_TO_JOINT_M before its end and not
    taken by a section before; the last such, among those the TVD section names as its exit
    signals if any."""
    candidates = [s for s in signals
                  if s.id not in used and end_m - SIGNAL_TO_JOINT_M - 1e-6 <= s.position <= end_m + 1e-6]
    preferred = [s for s in candidates if s.id in exits] or candidates
    signal = preferred[-1] if preferred else None
    if signal is not None:
        used.add(signal.id)
    return signal


def _circuit(doc: Document, stretch: _Stretch, own: dict, before: List[dict], assumed: _Assumed) -> dict:
    """A section's track circuit: its transmitter, carrier and ballast, each the sidecar's for
    the section, else the TVD section's, else assumed (``before``: the sections made so far, for
    the alternating transmitters)."""
    tvd = stretch.tvd
    carrier = own.get("carrier_hz") or (doc.float_attr(tvd, "frequency") if tvd is not None else None)
    if carrier is None:
        carrier = assumed.carrier_hz
        assumed.counts["carrier"] += 1
    transmitter = own.get("transmitter") or (tvd.get(RC + "transmitter") if tvd is not None else None)
    if transmitter is None and carrier in TVM_CARRIERS_HZ:
        transmitter = TVM_TRANSMITTER      # only a UM71 circuit carries an audio frequency
    if transmitter is None:
        transmitter = assumed.transmitter
        assumed.counts["transmitter"] += 1
    if transmitter == "alternate":     # the other type than the section before (docs/wayside_coder.md)
        transmitter = "KPT-7" if before and before[-1]["transmitter"] == "KPT-5" else "KPT-5"
    ballast = own.get("ballast_ohm_km") or (doc.float_attr(tvd, RC + "ballastOhmKm") if tvd is not None else None)
    if ballast is None:
        ballast = assumed.ballast_ohm_km
        assumed.counts["ballast"] += 1
    if carrier not in ALSN_CARRIERS_HZ + TVM_CARRIERS_HZ:
        where = f"tvdSection {stretch.ident!r}" if tvd is not None else f"block section {stretch.ident}"
        raise UserError(f"{doc.path}: {where}: frequency {carrier:g} Hz is no ALSN carrier (25, 50 or 75 Hz) "
                        "nor a TVM one (1700, 2000, 2300 or 2600 Hz)")
    return {"transmitter": transmitter, "carrier_hz": int(carrier), "ballast_ohm_km": ballast}


def _check_separation_zones(doc: Document, sections: List[dict], idents: List[str], ends: List[Detector],
                            detectors: List[Detector]) -> None:
    """Two UM71 circuits meet at a tuned separation zone, and a zone stands nowhere else: a file
    that lacks one is refused naming the border (railML itself has no word for a zone: docs/
    railml.md#our-extension)."""
    between_tvm = set()
    for k in range(1, len(sections)):
        before, after, border = sections[k - 1], sections[k], ends[k - 1]
        if after["start_m"] != before["end_m"] or not before["transmitter"] == after["transmitter"] == TVM_TRANSMITTER:
            continue
        between_tvm.add(id(border))
        if border.zone is None:
            what = "an insulated rail joint" if border.kind == "insulatedRailJoint" else f"a {border.kind} border"
            doc.fail(border.element if border.element is not None else border.id,
                     f"{what} at {border.position:g} m between the TVM (UM71) sections {idents[k - 1]!r} and "
                     f"{idents[k]!r}: missing the tuned separation zone that goes there (UM71 circuits have no "
                     "insulated joints); mark a jointless border rcs:separationZone=\"true\" or name it in the "
                     "sidecar's zones")
    for detector in detectors:
        if detector.zone is not None and id(detector) not in between_tvm:
            doc.fail(detector.element, f"a separation zone at {detector.position:g} m, where no two TVM (UM71) "
                                       "sections meet: a zone goes only between two UM71 circuits")

def _split_long(sections: List[dict], notes) -> List[dict]:
    """Sections longer than MAX_TRACK_CIRCUIT_M as equal track circuits in one block: the signal
    at the last one's exit only, the transmitters alternating."""
    result = []
    for section in sections:
        length = section["end_m"] - section["start_m"]
        pieces = math.ceil(length / MAX_TRACK_CIRCUIT_M - 1e-9)
        # a UM71 circuit is not cut: its neighbours would need a zone and the other carrier (the
        # rail line says at initialisation whether it calibrates)
        if pieces <= 1 or section["transmitter"] == TVM_TRANSMITTER:
            result.append(section)
            continue
        bounds = [clean_position(section["start_m"] + length * k / pieces) for k in range(pieces)] + [section["end_m"]]
        for k in range(pieces):
            transmitter = section["transmitter"] if k == 0 else (
                "KPT-7" if result[-1]["transmitter"] == "KPT-5" else "KPT-5")
            result.append({**section, "name": f"{section['name']}/{k + 1}", "start_m": bounds[k],
                           "end_m": bounds[k + 1], "signal": section["signal"] if k == pieces - 1 else "",
                           "transmitter": transmitter})
        notes.append(f"block section {section['name']} ({length:g} m) made {pieces} coded track circuits of "
                     f"{length / pieces:g} m in one block (a track circuit calibrates up to about "
                     f"{MAX_TRACK_CIRCUIT_M / 1000:g} km, docs/rail_line.md)")
    return result
