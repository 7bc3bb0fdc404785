"""The running path through a railML topology and places along it: the micro netElements with
their lengths (:func:`net_elements`), the ways a train can run through them and the one chosen
as the line (:func:`choose_path`: most stations, then most block signals facing the train, then
the longest, then main tracks), and :class:`Locator`, which turns railML's spot and linear
locations into positions along that path (docs/railml.md#the-running-path).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Dict, Iterable, List, Optional, Sequence, Tuple

from fmus.data.loader import SCHEMAS
from orchestrator.errors import UserError
from orchestrator.railml.document import (SIGNAL_FUNCTIONS_CLOSING_A_BLOCK, VERSION_OF_NS, Document, shown_value,
                                          signal_kind, station_elements)

#: a netElement's ``length`` and the length its positioning gives may differ by this much (m)
#: plus LENGTH_TOLERANCE_SHARE of the length (rounding in the source data)
LENGTH_TOLERANCE_M = 1.0
LENGTH_TOLERANCE_SHARE = 1e-3
#: candidate paths enumerated through a topology before the import gives up (a large station
#: layout without a --line-id)
MAX_PATHS = 20000
#: the longest line the import makes (m): a line file's longest (its schema's length_m maximum)
MAX_LINE_M = float(json.loads((SCHEMAS / "line.schema.json").read_text(encoding="utf-8"))
                   ["properties"]["length_m"]["maximum"])
#: intrinsic coordinates: a place along a netElement, 0 at its start, 1 at its end
INTRINSIC = dict(minimum=0.0, maximum=1.0, what=" (0 at the netElement's start, 1 at its end)")
#: units of linear positioning systems → metres
UNIT_M = {"m": 1.0, "km": 1000.0, "mm": 0.001}


def clean_position(position: float):
    """A position computed from lengths, rounded off float noise (1 µm) and made an int when whole."""
    rounded = round(position, 6)
    return int(rounded) if float(rounded).is_integer() and not isinstance(position, float) else rounded


# ---- topology -----------------------------------------------------------------------------------
@dataclass
class NetElement:
    id: str
    element: object
    length: float
    #: (intrinsic coordinate, measure in m, positioning system) of each linear coordinate
    measures: List[Tuple[float, float, str]]


def _positioning_units(doc: Document) -> Dict[str, float]:
    units = {}
    for system in doc.findall(doc.root, "common", "positioning", "linearPositioningSystems",
                              "linearPositioningSystem"):
        unit = (system.get("units") or "m").strip().lower()
        if unit not in UNIT_M:
            doc.fail(system, f"units={system.get('units')!r}: expected m, km or mm")
        units[system.get("id")] = UNIT_M[unit]
    return units


def net_elements(doc: Document, notes: List[str]) -> Dict[str, NetElement]:
    """The micro-level netElements (those that are not collections of others) with their lengths."""
    topology = doc.find(doc.root, "infrastructure", "topology")
    if topology is None:
        raise UserError(f"{doc.path}: railML {VERSION_OF_NS[doc.ns]} without infrastructure/topology: "
                        "no track to run on")
    units = _positioning_units(doc)
    track_lengths = _track_lengths(doc)
    elements, by_geometry = {}, []
    for element in doc.findall(topology, "netElements", "netElement"):
        if doc.findall(element, "elementCollectionUnordered") or doc.findall(element, "elementCollectionOrdered"):
            continue                      # a macro element: a group of micro ones
        ident = element.get("id")
        measures, points = _coordinates(doc, element, units)
        stated = doc.float_attr(element, "length")
        from_positions = _length_from_measures(measures)
        if stated is not None and stated <= 0:
            doc.fail(element, f"length {stated:g} m: a track needs a positive length")
        if stated is not None and from_positions is not None:
            if abs(stated - from_positions) > LENGTH_TOLERANCE_M + LENGTH_TOLERANCE_SHARE * stated:
                doc.fail(element, f"length {stated:g} m disagrees with its positioning: its linear coordinates "
                                  f"span {from_positions:g} m")
        length = stated if stated is not None else from_positions
        if length is None and ident in track_lengths:
            length = track_lengths[ident]
        if length is None and len(points) >= 2:
            points.sort()
            length = sum(math.dist(a[1:], b[1:]) for a, b in zip(points[:-1], points[1:]))
            by_geometry.append(ident)
        if length is None or length <= 0:
            doc.fail(element, "no length: give it a length attribute, linear coordinates at both ends, or a "
                              "track with a length")
        if length > MAX_LINE_M:
            doc.fail(element, f"length {length:g} m: longer than the longest line railcosim runs "
                              f"({MAX_LINE_M / 1000:g} km)")
        elements[ident] = NetElement(ident, element, length, measures)
    if by_geometry:
        notes.append(f"lengths of netElements {', '.join(by_geometry)} taken from their geometric coordinates "
                     "(read as metres)")
    if not elements:
        raise UserError(f"{doc.path}: infrastructure/topology has no netElement")
    return elements


def _coordinates(doc: Document, element, units: Dict[str, float]):
    """A netElement's linear coordinates [(intrinsic, measure in m, positioning system)] and its
    geometric ones [(intrinsic, x, y)]."""
    measures, points = [], []
    for system in doc.findall(element, "associatedPositioningSystem"):
        for coordinate in doc.findall(system, "intrinsicCoordinate"):
            intrinsic = doc.float_attr(coordinate, "intrinsicCoord", required=True, **INTRINSIC)
            for linear in doc.findall(coordinate, "linearCoordinate"):
                reference = linear.get("positioningSystemRef") or system.get("positioningSystemRef") or ""
                measure = doc.float_attr(linear, "measure", required=True)
                measures.append((float(intrinsic), measure * units.get(reference, 1.0), reference))
            for geometric in doc.findall(coordinate, "geometricCoordinate"):
                x, y = doc.float_attr(geometric, "x"), doc.float_attr(geometric, "y")
                if x is not None and y is not None:
                    points.append((float(intrinsic), float(x), float(y)))
    return measures, points


def _length_from_measures(measures) -> Optional[float]:
    by_system: Dict[str, List[Tuple[float, float]]] = {}
    for intrinsic, measure, system in measures:
        by_system.setdefault(system, []).append((intrinsic, measure))
    for points in by_system.values():
        points.sort()
        if len(points) >= 2 and points[-1][0] > points[0][0]:
            # the measures at the two ends, extrapolated if the coordinates stop short of 0 or 1
            (i0, m0), (i1, m1) = points[0], points[-1]
            return abs(m1 - m0) / (i1 - i0)
    return None


def _track_lengths(doc: Document) -> Dict[str, float]:
    """netElement → length of a <track> laid on that one netElement alone."""
    lengths = {}
    for track in doc.findall(doc.root, "infrastructure", "functionalInfrastructure", "tracks", "track"):
        pieces = [a for location in doc.findall(track, "linearLocation")
                  for a in doc.findall(location, "associatedNetElement")]
        length = doc.find(track, "length")
        if len(pieces) == 1 and length is not None and not any(
                pieces[0].get(k) for k in ("posBegin", "posEnd", "intrinsicCoordBegin", "intrinsicCoordEnd")):
            value = doc.float_attr(length, "value")
            if value:
                lengths[pieces[0].get("netElementRef")] = value
    return lengths


def macro_members(doc: Document) -> Dict[str, List[str]]:
    """A macro netElement → the micro netElements it collects (recursively)."""
    topology = doc.find(doc.root, "infrastructure", "topology")
    direct = {}
    for element in doc.findall(topology, "netElements", "netElement"):
        parts = [part.get("ref") for tag in ("elementCollectionUnordered", "elementCollectionOrdered")
                 for collection in doc.findall(element, tag) for part in doc.findall(collection, "elementPart")]
        if parts:
            direct[element.get("id")] = parts

    def expand(ident, seen=()):
        if ident not in direct or ident in seen:
            return [ident]
        return [m for part in direct[ident] for m in expand(part, seen + (ident,))]

    return {ident: expand(ident) for ident in direct}


#: a step of the running path: the netElement and whether it is run from intrinsic 0 to 1
@dataclass
class _Step:
    id: str
    forward: bool
    offset: float           # position of its start along the path (m)
    length: float


class RunningPath:
    """The running path: netElements in running order with their positions along the line."""

    def __init__(self, steps: List[_Step]):
        self.steps = steps
        self.by_id = {s.id: s for s in steps}
        self.length = steps[-1].offset + steps[-1].length

    def at(self, ident: str, pos_m: float) -> Optional[float]:
        """The path position of ``pos_m`` metres from intrinsic 0 of netElement ``ident``."""
        step = self.by_id.get(ident)
        if step is None:
            return None
        pos_m = min(max(pos_m, 0.0), step.length)
        return step.offset + (pos_m if step.forward else step.length - pos_m)

    def faces_running(self, ident: str, direction: Optional[str]) -> bool:
        """Whether an applicationDirection on netElement ``ident`` includes the running direction."""
        step = self.by_id.get(ident)
        if step is None or direction in (None, "both"):
            return True
        return (direction == "normal") == step.forward


def _relations(doc: Document, elements: Dict[str, NetElement]):
    """(element, end) → [(element, end)] a train may pass to (navigability)."""
    topology = doc.find(doc.root, "infrastructure", "topology")
    links: Dict[Tuple[str, int], List[Tuple[str, int]]] = {}
    for relation in doc.findall(topology, "netRelations", "netRelation"):
        a, b = doc.find(relation, "elementA"), doc.find(relation, "elementB")
        if a is None or b is None:
            doc.fail(relation, "needs elementA and elementB")
        a_id, b_id = a.get("ref"), b.get("ref")
        for ident in (a_id, b_id):
            if ident not in elements and ident not in doc.by_id:
                doc.fail(relation, f"refers to netElement {ident!r}, which the file does not have")
        if a_id not in elements or b_id not in elements:
            continue                                  # a relation between macro elements
        navigability = relation.get("navigability", "Both")
        ends = {name: relation.get(name, default).strip() for name, default in (("positionOnA", "1"),
                                                                                  ("positionOnB", "0"))}
        for name, value in ends.items():
            if value not in ("0", "1"):
                doc.fail(relation, f"attribute {name}={shown_value(value)}: must be 0 or 1 (the netElement's start "
                                   "or end)")
        end_a, end_b = int(ends["positionOnA"]), int(ends["positionOnB"])
        if navigability in ("Both", "AB"):
            links.setdefault((a_id, end_a), []).append((b_id, end_b))
        if navigability in ("Both", "BA"):
            links.setdefault((b_id, end_b), []).append((a_id, end_a))
    return links


def _candidate_paths(doc: Document, elements: Dict[str, NetElement], allowed: Iterable[str], links) -> List[list]:
    """Every simple path from a track end to a track end through ``allowed`` netElements, as
    [(netElement, forward)] (a path and its reverse both: the running direction is chosen)."""
    allowed = set(allowed)

    def onward(ident, exit_end):
        return [(n, e) for n, e in links.get((ident, exit_end), []) if n in allowed]

    # where a train can start: an end nothing leads into (a buffer stop, an open end, the edge
    # of the chosen line)
    enters = {(n, e) for key, targets in links.items() if key[0] in allowed for n, e in targets if n in allowed}
    starts = [(ident, end) for ident in sorted(allowed) for end in (0, 1) if (ident, end) not in enters]
    if not starts:       # a closed loop: start anywhere
        starts = [(sorted(allowed)[0], 0)]
    paths, visited_steps = [], 0
    stack = [([(ident, end == 0)], {ident}) for ident, end in starts]
    while stack:
        path, seen = stack.pop()
        visited_steps += 1
        ident, forward = path[-1]
        nexts = [(n, e) for n, e in onward(ident, 1 if forward else 0) if n not in seen]
        if not nexts:
            paths.append(path)
        for n, e in nexts:
            stack.append((path + [(n, e == 0)], seen | {n}))
        if len(paths) > MAX_PATHS or visited_steps > 50 * MAX_PATHS:
            raise UserError(f"{doc.path}: the topology has more than {MAX_PATHS} ways through it; name the "
                            "railML line to import with --line-id")
    return paths


def choose_path(doc: Document, elements, line_id: Optional[str], via: Sequence[str], notes: List[str]) -> RunningPath:
    links = _relations(doc, elements)
    macro = macro_members(doc)
    allowed = list(elements)
    if line_id is not None:
        lines = {line.get("id"): line for line in doc.findall(doc.root, "infrastructure", "functionalInfrastructure",
                                                                  "lines", "line")}
        if line_id not in lines:
            raise UserError(f"--line-id {line_id}: {doc.path} has no railML line of that id "
                            f"(its lines: {', '.join(sorted(lines)) or 'none'})")
        refs = [a.get("netElementRef") for location in doc.findall(lines[line_id], "linearLocation")
                for a in doc.findall(location, "associatedNetElement")]
        allowed = [m for ref in refs for m in macro.get(ref, [ref]) if m in elements]
        if not allowed:
            doc.fail(lines[line_id], "its linearLocation names no netElement of the topology")
    candidates = _candidate_paths(doc, elements, allowed, links)
    if via:
        unknown = [v for v in via if v not in elements]
        if unknown:
            raise UserError(f"--sidecar: via {unknown[0]!r}: {doc.path} has no micro netElement of that id")
        candidates = [c for c in candidates if set(via) <= {i for i, _ in c}]
        if not candidates:
            raise UserError(f"--sidecar: via {', '.join(via)}: no path through the topology passes them all "
                            "(check the netRelations' navigability)")
    scores = _PathScores(doc, elements, macro)
    best = max(candidates, key=lambda p: scores.score(p))
    offset, steps = 0, []
    for ident, forward in best:
        length = elements[ident].length
        steps.append(_Step(ident, forward, offset, length))
        offset = offset + length
    chosen = RunningPath(steps)
    if chosen.length > MAX_LINE_M:
        raise UserError(f"{doc.path}: the running path {' → '.join(s.id for s in steps)} is {chosen.length:g} m "
                        f"long: longer than the longest line railcosim runs ({MAX_LINE_M / 1000:g} km)")
    if len({frozenset(i for i, _ in c) for c in candidates}) > 1:
        notes.append(f"running path chosen among {len(candidates)} ways through the topology (most stations, "
                     "then most block signals facing the train, then the longest, then main tracks): "
                     + " → ".join(f"{s.id}{'' if s.forward else ' (reversed)'}" for s in steps)
                     + "; choose another with --line-id or the sidecar's via")
    return chosen


class _PathScores:
    """What makes a path the line to import: the stations and block signals it meets."""

    def __init__(self, doc: Document, elements, macro):
        self.doc, self.elements = doc, elements
        fi = doc.find(doc.root, "infrastructure", "functionalInfrastructure")
        self.station_refs = []   # per station: the netElements it stands on
        for op in station_elements(doc):
            refs = set()
            for spot in doc.findall(op, "spotLocation") + [a for loc in doc.findall(op, "linearLocation")
                                                          for a in doc.findall(loc, "associatedNetElement")]:
                ref = spot.get("netElementRef")
                refs.update(macro.get(ref, [ref]))
            self.station_refs.append(refs)
        self.signals = []        # (netElement, applicationDirection) of every main signal
        for signal in doc.findall(fi, "signalsIS", "signalIS"):
            if signal_kind(doc, signal) in SIGNAL_FUNCTIONS_CLOSING_A_BLOCK:
                for spot in doc.findall(signal, "spotLocation"):
                    self.signals.append((spot.get("netElementRef"), spot.get("applicationDirection")))
        self.main_tracks = set()
        for track in doc.findall(fi, "tracks", "track"):
            if track.get("type") == "mainTrack":
                for location in doc.findall(track, "linearLocation"):
                    self.main_tracks.update(a.get("netElementRef") for a in doc.findall(location, "associatedNetElement"))

    def score(self, path):
        idents = {ident for ident, _ in path}
        forward = dict(path)
        stations = sum(1 for refs in self.station_refs if refs & idents)
        facing = sum(1 for ident, direction in self.signals if ident in forward and (
            direction in (None, "both") or (direction == "normal") == forward[ident]))
        length = sum(self.elements[i].length for i in idents)
        main = sum(1 for i in idents if i in self.main_tracks)
        # last: run the netElements forward (the direction of increasing kilometres), then ids
        forward_steps = sum(1 for _, f in path if f)
        return stations, facing, round(length, 3), main, forward_steps, [(i, f) for i, f in path]


# ---- locations along the path ---------------------------------------------------------------------
class Locator:
    def __init__(self, doc: Document, path: RunningPath, elements: Dict[str, NetElement], macro):
        self.doc, self.path, self.elements, self.macro = doc, path, elements, macro
        # per positioning system: (measure at start, measure at end, path start, path end) of each step
        self.spans: Dict[str, List[Tuple[float, float, float, float]]] = {}
        for step in path.steps:
            by_system: Dict[str, List[Tuple[float, float]]] = {}
            for intrinsic, measure, system in elements[step.id].measures:
                by_system.setdefault(system, []).append((intrinsic, measure))
            for system, points in by_system.items():
                points.sort()
                if len(points) < 2 or points[-1][0] <= points[0][0]:
                    continue
                (i0, m0), (i1, m1) = points[0], points[-1]
                at0 = m0 - i0 * (m1 - m0) / (i1 - i0)
                at1 = at0 + (m1 - m0) / (i1 - i0)
                self.spans.setdefault(system, []).append((at0, at1, path.at(step.id, 0.0), path.at(step.id, step.length)))

    def _pos_on(self, ident: str, element, pos_name: str, intrinsic_name: str) -> Optional[float]:
        pos = self.doc.float_attr(element, pos_name)
        if pos is not None:
            length = self.elements[ident].length
            slack = LENGTH_TOLERANCE_M + LENGTH_TOLERANCE_SHARE * length
            if not -slack <= pos <= length + slack:
                self.doc.fail(element, f"attribute {pos_name}={pos:g} m is off netElement {ident!r}, which is "
                                       f"{length:g} m long")
            return self.path.at(ident, pos)
        intrinsic = self.doc.float_attr(element, intrinsic_name, **INTRINSIC)
        if intrinsic is not None:
            return self.path.at(ident, intrinsic * self.elements[ident].length)
        return None

    def measure(self, linear) -> Optional[float]:
        """A linearCoordinate's position on the path, through the path's positioning."""
        if linear is None:
            return None
        system = linear.get("positioningSystemRef") or ""
        value = self.doc.float_attr(linear, "measure", required=True)
        units = _positioning_units(self.doc)
        value = value * units.get(system, 1.0)
        for at0, at1, p0, p1 in self.spans.get(system, []):
            low, high = min(at0, at1), max(at0, at1)
            if low - 1e-6 <= value <= high + 1e-6 and at1 != at0:
                return p0 + (value - at0) / (at1 - at0) * (p1 - p0)
        return None

    def spot(self, spot) -> Optional[float]:
        """A spotLocation's position on the path, None off the path."""
        ref = spot.get("netElementRef")
        if ref in self.path.by_id:
            position = self._pos_on(ref, spot, "pos", "intrinsicCoord")
            if position is not None:
                return position
        elif ref in self.elements:
            return None           # on a track the path does not run on
        return self.measure(self.doc.find(spot, "linearCoordinate"))

    def spots(self, entity) -> List[Tuple[float, object]]:
        found = []
        for spot in self.doc.findall(entity, "spotLocation"):
            position = self.spot(spot)
            if position is not None:
                found.append((position, spot))
        return found

    def intervals(self, entity) -> List[Tuple[float, float, bool, bool]]:
        """The stretches of the path an entity's linearLocations cover: (start, end, whether it
        applies in the running direction, whether its netElement is run from intrinsic 0 to 1)."""
        stretches = []
        for location in self.doc.findall(entity, "linearLocation"):
            direction = location.get("applicationDirection")
            for piece in self.doc.findall(location, "associatedNetElement"):
                ref = piece.get("netElementRef")
                members = [m for m in self.macro.get(ref, [ref]) if m in self.path.by_id]
                begin = self.measure(self.doc.find(piece, "linearCoordinateBegin"))
                end = self.measure(self.doc.find(piece, "linearCoordinateEnd"))
                if ref in self.path.by_id:
                    length = self.elements[ref].length
                    b = self._pos_on(ref, piece, "posBegin", "intrinsicCoordBegin")
                    e = self._pos_on(ref, piece, "posEnd", "intrinsicCoordEnd")
                    begin = b if b is not None else (begin if begin is not None else self.path.at(ref, 0))
                    end = e if e is not None else (end if end is not None else self.path.at(ref, length))
                    piece_direction = direction
                    if direction in ("normal", "reverse") and piece.get("keepsOrientation") == "false":
                        piece_direction = "reverse" if direction == "normal" else "normal"
                    faces = self.path.faces_running(ref, piece_direction)
                    forward = self.path.by_id[ref].forward
                elif ref in self.elements:
                    continue          # a track the path does not run on
                elif begin is not None and end is not None:
                    faces, forward = True, end >= begin
                elif members:        # a macro element without coordinates: its members on the path
                    begin = min(self.path.by_id[m].offset for m in members)
                    end = max(self.path.by_id[m].offset + self.path.by_id[m].length for m in members)
                    faces, forward = True, True
                else:
                    continue
                start, stop = sorted((begin, end))
                if stop > start:
                    stretches.append((start, stop, faces, forward))
        return stretches
