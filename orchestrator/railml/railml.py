"""railML 3.1 / 3.2 infrastructure in and out of railcosim's line file (docs/railml.md).

* :func:`import_railml` reads a railML 3 file (and an optional sidecar, docs/railml.md#the-sidecar)
  into a line-file document (fmus/data/schemas/line.schema.json): the running path through the
  topology, in running order with its length, and along it the block sections (the
  interlocking's TVD sections between their demarcating train detectors), the block signals at
  their exits, the insulated joints, stations, gradients, curves, speed limits, temporary
  restrictions and the electrification. What it does not read, and every default it assumed,
  is listed in :attr:`RailmlImport.notes` (the CLI prints them as one warning block).
* :func:`export_railml` writes a line-file document as railML 3.2 infrastructure plus our
  extension namespace :data:`EXTENSION_NS`; ``import_railml(export_railml(line))`` gives the
  line document back (tests/test_railml.py runs it for every shipped line).
* :func:`validate_railml` checks a file against the railML XSD in a folder the user has (the
  railML schemas are not redistributable: docs/railml.md#validation).

Bad input is a :class:`~orchestrator.errors.UserError` of one line naming the file and the
railML element's ``id``. Data conversion on the host side only: no FMU needs railML, so this
lives in orchestrator/railml, not in the ``fmus`` package every FMU bundles
(docs/architecture.md).
"""
from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, Iterable, List, Optional, Sequence, Tuple

from lxml import etree

from fmus.data.loader import MAX_JSON_DEPTH, SCHEMAS, json_nesting_depth, read_json_file
from fmus.errors import FmuInputError
from orchestrator.errors import UserError

RAILML_NS = {"3.1": "https://www.railml.org/schemas/3.1", "3.2": "https://www.railml.org/schemas/3.2"}
VERSION_OF_NS = {ns: version for version, ns in RAILML_NS.items()}
#: our extension namespace: what railML has no place for (docs/railml.md#our-extension)
EXTENSION_NS = "urn:railcosim:railml:1"
SCHEMA_DIR = Path(__file__).resolve().parent / "schema"
EXTENSION_XSD = SCHEMA_DIR / "railcosim_extension.xsd"
DUBLIN_CORE_XSD = SCHEMA_DIR / "dublin_core_stand_in.xsd"
SIDECAR_SCHEMA = "railml_sidecar.schema.json"
RC = "{%s}" % EXTENSION_NS

#: a netElement's ``length`` and the length its positioning gives may differ by this much (m)
#: plus LENGTH_TOLERANCE_SHARE of the length (rounding in the source data)
LENGTH_TOLERANCE_M = 1.0
LENGTH_TOLERANCE_SHARE = 1e-3
#: a block signal belongs to the section whose end lies this far ahead of it at most (m): a
#: signal stands at, or a little before, the joint it protects
SIGNAL_TO_JOINT_M = 60.0
#: the longest coded track circuit the import makes (m): a longer TVD section (an axle-counter
#: section of kilometres) becomes several track circuits in one block. At the normative minimum
#: ballast (1 Ω·km) a 50 Hz track circuit calibrates up to about 2.7 km (the rail line says so at
#: initialisation, docs/rail_line.md); the shipped lines' longest is 2.6 km
MAX_TRACK_CIRCUIT_M = 2600.0
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

#: built-in defaults (docs/railml.md#defaults): the shipped lines' values
DEFAULTS = {
    "carrier_hz_dc": 50, "carrier_hz_ac": 25,       # 50 Hz cannot be used under 50 Hz AC traction
    "transmitter": "alternate",                      # KPT-5, KPT-7, KPT-5, … as the shipped lines
    "ballast_ohm_km": 1.0,                           # the normative minimum (docs/rail_line.md)
    "speed_kmh": 80.0,                               # where no speed section and no line maxSpeed
    "freight_speed_kmh": None,                       # None: the passenger speed, at most 200
}
#: the carriers of coded ALSN track circuits and of audio-frequency TVM (UM71) ones, Hz, and the
#: transmitter of the latter (docs/interfaces.md#line-file-tvm-430-sections)
ALSN_CARRIERS_HZ = (25, 50, 75)
TVM_CARRIERS_HZ = (1700, 2000, 2300, 2600)
TVM_TRANSMITTER = "UM71"
SIGNAL_FUNCTIONS_CLOSING_A_BLOCK = {"main", "block", "exit", "entry", "intermediate", "intermediateStop",
                                    "junction", "combined"}
STATION_TYPES = {"station", "stoppingPoint", "halt"}


@dataclass
class RailmlImport:
    """A line document, where it came from, and what was ignored or assumed."""
    document: dict
    version: str
    path_ids: List[str]
    notes: List[str] = field(default_factory=list)


# ---- small helpers --------------------------------------------------------------------------------
#: a decimal literal as xs:double writes one (Python's float() also reads "1_000", "١٢" and " 1 ")
_DECIMAL = re.compile(r"[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?")
_NOT_FINITE = {"inf", "+inf", "-inf", "nan", "infinity", "+infinity", "-infinity"}
#: no number the import reads comes near this in any unit railML uses (a position on a 10 000 km
#: line in millimetres is 10¹⁰): larger is a fault in the file, refused before any arithmetic
MAX_MAGNITUDE = 1e12
#: the railML elements the import names and links by their id (railML requires one on each)
IDENTIFIED = {"netElement", "netRelation", "linearPositioningSystem", "electrificationSystem", "speedProfile",
              "track", "line", "operationalPoint", "platform", "signalIS", "signalIL", "trainDetectionElement",
              "tvdSection", "bufferStop", "speedSection", "electrificationSection", "gradientCurve",
              "horizontalCurve"}
#: attributes that refer to an element by its id besides ``ref`` and those ending in ``Ref``
#: (xs:IDREF: railML resolves every one within the file)
REFERENCE_ATTRIBUTES = {"belongsToParent"}


def _number(text: Optional[str]):
    """An int for an integer literal ("2600"), else a float ("2600.0", "1e3"); None for None;
    ValueError for anything but a decimal literal. Keeping ints as ints lets a line file go
    through railML and back unchanged."""
    if text is None:
        return None
    text = text.strip()
    if re.fullmatch(r"[+-]?[0-9]+", text) and len(text) <= 4000:     # int() refuses more than 4300 digits
        return int(text)
    if text.lower() in _NOT_FINITE:
        return float(text)
    if not _DECIMAL.fullmatch(text):
        raise ValueError(text)
    return float(text)


def _shown(value: str) -> str:
    """An attribute's value for a message: a 4000-digit number is not repeated in full."""
    return repr(value) if len(value) <= 40 else f"{value[:20]!r}… ({len(value)} characters)"


def _attribute(name: str) -> str:
    """An attribute's name as the file writes it (our extension's with its rcs: prefix)."""
    return "rcs:" + name[len(RC):] if name.startswith(RC) else name


def _text(value) -> str:
    """The railML literal of a line-file number (an int stays an int)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    return repr(float(value))


def _clean(position: float):
    """A position computed from lengths, rounded off float noise (1 µm) and made an int when whole."""
    rounded = round(position, 6)
    return int(rounded) if float(rounded).is_integer() and not isinstance(position, float) else rounded


def _local(element) -> str:
    return etree.QName(element).localname if isinstance(element.tag, str) else ""


class _Doc:
    """The parsed file: namespaced look-ups and one-line errors naming the element. Every id is
    unique, every element the import links has one, and every reference names an element of
    the file (:meth:`_check_ids`), before anything is read."""

    def __init__(self, path: Path, root, ns: str):
        self.path, self.root, self.ns = path, root, ns
        self.by_id: Dict[str, object] = {}
        self._check_ids()

    def _check_ids(self) -> None:
        elements = [e for e in self.root.iter() if isinstance(e.tag, str)]
        for element in elements:
            ident = element.get("id")
            if not ident and _local(element) in IDENTIFIED and etree.QName(element).namespace == self.ns:
                self.fail(element, f"attribute id {'empty' if ident == '' else 'missing'} (the import names and "
                                   f"links every {_local(element)} by its id)")
            if ident is None:
                continue
            first = self.by_id.setdefault(ident, element)
            if first is not element:
                self.fail(element, f"id {ident!r} is also the id of the {_local(first)} at line {first.sourceline} "
                                   "(railML ids are unique in a file)")
        for element in elements:
            for name, value in element.attrib.items():
                local = _attribute(name).rpartition(":")[2]
                if (local == "ref" or local.endswith("Ref") or local in REFERENCE_ATTRIBUTES) and \
                        value not in self.by_id:
                    owner = element if element.get("id") is not None else next(
                        (e for e in element.iterancestors() if e.get("id")), element)
                    what = f"attribute {_attribute(name)}={_shown(value)}" if owner is element else \
                        f"<{_local(element)} {_attribute(name)}={_shown(value)}> at line {element.sourceline}"
                    self.fail(owner, f"{what} names no element of the file (railML refers by id within the file)")

    def q(self, tag: str) -> str:
        return "{%s}%s" % (self.ns, tag)

    def path_of(self, *tags: str) -> str:
        return "/".join(f"r:{t}" for t in tags)

    def find(self, element, *tags):
        return element.find(self.path_of(*tags), {"r": self.ns}) if element is not None else None

    def findall(self, element, *tags) -> list:
        return element.findall(self.path_of(*tags), {"r": self.ns}) if element is not None else []

    def fail(self, element_or_id, message: str):
        ident = element_or_id if isinstance(element_or_id, str) else element_or_id.get("id")
        tag = "" if isinstance(element_or_id, str) else _local(element_or_id)
        what = f"{tag} {ident!r}" if tag and ident else (f"element {ident!r}" if ident else tag)
        line = "" if isinstance(element_or_id, str) else f" (line {element_or_id.sourceline})"
        raise UserError(f"{self.path}: {what}{line}: {message}")

    def float_attr(self, element, name: str, required: bool = False, minimum: Optional[float] = None,
                   maximum: Optional[float] = None, what: str = ""):
        """Attribute ``name`` of ``element`` as a number (None when absent and not ``required``):
        a decimal literal, finite, within ±MAX_MAGNITUDE and [``minimum``, ``maximum``]
        (``what`` says why), else one line naming the element and the attribute."""
        value = element.get(name)
        shown = f"attribute {_attribute(name)}"
        if value is None:
            if required:
                self.fail(element, f"{shown} missing")
            return None
        try:
            number = _number(value)
        except ValueError:
            self.fail(element, f"{shown}={_shown(value)} is not a number")
        if isinstance(number, float) and not math.isfinite(number) and value.strip().lower() in _NOT_FINITE:
            self.fail(element, f"{shown}={_shown(value)} is not a finite number")
        if not abs(number) <= MAX_MAGNITUDE:      # (float() reads 1e400 as inf)       # (an int of 4000 digits would not even convert to float)
            self.fail(element, f"{shown}={_shown(value)} is beyond ±{MAX_MAGNITUDE:g}: no railway "
                               "quantity is that large")
        if (minimum is not None and number < minimum) or (maximum is not None and number > maximum):
            bounds = f"from {minimum:g} to {maximum:g}" if minimum is not None and maximum is not None else (
                f"at least {minimum:g}" if minimum is not None else f"at most {maximum:g}")
            self.fail(element, f"{shown}={_shown(value)}: must be {bounds}{what}")
        return number

    def name_of(self, element) -> Optional[str]:
        """An entity's human name: its first <name name=…>, else its designator's entry."""
        name = self.find(element, "name")
        if name is not None and name.get("name"):
            return name.get("name")
        designator = self.find(element, "designator")
        if designator is not None and designator.get("entry"):
            return designator.get("entry")
        return None


def _parse(path: Path) -> _Doc:
    path = Path(path)
    if not path.is_file():
        raise UserError(f"{path}: file not found")
    parser = etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=False, remove_comments=True)
    try:
        root = etree.parse(str(path), parser).getroot()
    except etree.XMLSyntaxError as error:
        raise UserError(f"{path}: not railML 3: not an XML document ({error.msg}, line {error.lineno})") from None
    except OSError as error:
        raise UserError(f"{path}: cannot be read ({error})") from None
    qname = etree.QName(root)
    if qname.localname != "railML" or qname.namespace not in VERSION_OF_NS:
        found = f"<{qname.localname}> in namespace {qname.namespace}" if qname.namespace else f"<{qname.localname}>"
        hint = " (railML 2: convert it to railML 3 first)" if qname.localname.lower() == "railml" else ""
        raise UserError(f"{path}: not railML 3: its root element is {found}; expected <railML> in "
                        f"{RAILML_NS['3.1']} or {RAILML_NS['3.2']}{hint}")
    return _Doc(path, root, qname.namespace)


# ---- topology -----------------------------------------------------------------------------------
@dataclass
class _NetElement:
    id: str
    element: object
    length: float
    #: (intrinsic coordinate, measure in m, positioning system) of each linear coordinate
    measures: List[Tuple[float, float, str]]


def _positioning_units(doc: _Doc) -> Dict[str, float]:
    units = {}
    for system in doc.findall(doc.root, "common", "positioning", "linearPositioningSystems",
                              "linearPositioningSystem"):
        unit = (system.get("units") or "m").strip().lower()
        if unit not in UNIT_M:
            doc.fail(system, f"units={system.get('units')!r}: expected m, km or mm")
        units[system.get("id")] = UNIT_M[unit]
    return units


def _net_elements(doc: _Doc, notes: List[str]) -> Dict[str, _NetElement]:
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
        elements[ident] = _NetElement(ident, element, length, measures)
    if by_geometry:
        notes.append(f"lengths of netElements {', '.join(by_geometry)} taken from their geometric coordinates "
                     "(read as metres)")
    if not elements:
        raise UserError(f"{doc.path}: infrastructure/topology has no netElement")
    return elements


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


def _track_lengths(doc: _Doc) -> Dict[str, float]:
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


def _macro_members(doc: _Doc) -> Dict[str, List[str]]:
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


class _Path:
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


def _relations(doc: _Doc, elements: Dict[str, _NetElement]):
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
                doc.fail(relation, f"attribute {name}={_shown(value)}: must be 0 or 1 (the netElement's start "
                                   "or end)")
        end_a, end_b = int(ends["positionOnA"]), int(ends["positionOnB"])
        if navigability in ("Both", "AB"):
            links.setdefault((a_id, end_a), []).append((b_id, end_b))
        if navigability in ("Both", "BA"):
            links.setdefault((b_id, end_b), []).append((a_id, end_a))
    return links


def _candidate_paths(doc: _Doc, elements: Dict[str, _NetElement], allowed: Iterable[str], links) -> List[list]:
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


def _choose_path(doc: _Doc, elements, line_id: Optional[str], via: Sequence[str], notes: List[str]) -> _Path:
    links = _relations(doc, elements)
    macro = _macro_members(doc)
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
    chosen = _Path(steps)
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

    def __init__(self, doc: _Doc, elements, macro):
        self.doc, self.elements = doc, elements
        fi = doc.find(doc.root, "infrastructure", "functionalInfrastructure")
        self.station_refs = []   # per station: the netElements it stands on
        for op in _stations_elements(doc):
            refs = set()
            for spot in doc.findall(op, "spotLocation") + [a for loc in doc.findall(op, "linearLocation")
                                                          for a in doc.findall(loc, "associatedNetElement")]:
                ref = spot.get("netElementRef")
                refs.update(macro.get(ref, [ref]))
            self.station_refs.append(refs)
        self.signals = []        # (netElement, applicationDirection) of every main signal
        for signal in doc.findall(fi, "signalsIS", "signalIS"):
            if _signal_kind(doc, signal) in SIGNAL_FUNCTIONS_CLOSING_A_BLOCK:
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
class _Locator:
    def __init__(self, doc: _Doc, path: _Path, elements: Dict[str, _NetElement], macro):
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


# ---- functional infrastructure ----------------------------------------------------------------------
def _signal_kind(doc: _Doc, signal) -> Optional[str]:
    """'main', 'distant', … of a signalIS: its signalIL's function, else its isTrainMovementSignal's
    type (railML 3.2), else 'main' for a train movement signal; None for other signals (speed
    boards, mileposts)."""
    function = _signal_functions(doc).get(signal.get("id"))
    if function:
        return function
    movement = doc.find(signal, "isTrainMovementSignal")
    if movement is not None:
        return movement.get("type") or movement.get("function") or "main"
    if not any(_local(child).startswith("is") and _local(child).endswith("Signal") or _local(child) in (
            "isMilepost", "isStopPost") for child in signal):
        return "main"          # no function given at all: taken as a main signal (docs/railml.md#defaults)
    return None


def _signal_functions(doc: _Doc) -> Dict[str, str]:
    cache = getattr(doc, "_signal_functions", None)
    if cache is None:
        cache = {}
        for assets in _interlocking_assets(doc):
            for signal_il in doc.findall(assets, "signalsIL", "signalIL"):
                refers = doc.find(signal_il, "refersTo")
                if refers is not None and signal_il.get("function"):
                    cache[refers.get("ref")] = signal_il.get("function")
        doc._signal_functions = cache
    return cache


def _interlocking_assets(doc: _Doc) -> list:
    """railML 3.1's interlocking/assetsForIL, or 3.2's interlocking/assetsForInterlockings/
    assetsForInterlocking (either is read from either version: files in the wild mix them)."""
    interlocking = doc.find(doc.root, "interlocking")
    return doc.findall(interlocking, "assetsForIL") + doc.findall(interlocking, "assetsForInterlockings",
                                                                     "assetsForInterlocking")


def _stations_elements(doc: _Doc) -> list:
    fi = doc.find(doc.root, "infrastructure", "functionalInfrastructure")
    stations = []
    for op in doc.findall(fi, "operationalPoints", "operationalPoint"):
        types = {o.get("operationalType") for o in doc.findall(op, "opOperations", "opOperation")}
        if not types or types & STATION_TYPES:
            stations.append(op)
    return stations


@dataclass
class _Detector:
    position: float
    id: str
    kind: str            # insulatedRailJoint, trackCircuit, axleCounter, … or bufferStop / pathEnd
    element: object
    #: a tuned separation zone between two UM71 circuits: its line-file entry (position_m, length_m)
    zone: Optional[dict] = None


def import_railml(path, line_id: Optional[str] = None, sidecar=None) -> RailmlImport:
    """Read railML 3.1 or 3.2 infrastructure into a line document (module docstring)."""
    doc = _parse(Path(path))
    notes: List[str] = []
    version = VERSION_OF_NS[doc.ns]
    stated_version = doc.root.get("version")
    if stated_version and stated_version != version:
        notes.append(f"<railML version={stated_version!r}> in the railML {version} namespace: read as {version}")
    extras = _load_sidecar(sidecar)
    if extras.get("line_id") and line_id is None:
        line_id = extras["line_id"]
    elements = _net_elements(doc, notes)
    path_ = _choose_path(doc, elements, line_id, extras.get("via", []), notes)
    macro = _macro_members(doc)
    locate = _Locator(doc, path_, elements, macro)
    fi = doc.find(doc.root, "infrastructure", "functionalInfrastructure")
    ours = EXTENSION_NS in {ns for element in doc.root.iter() if isinstance(element.tag, str)
                            for ns in element.nsmap.values()}
    length = _clean(path_.length)

    line_element = None
    if line_id is not None:
        line_element = doc.by_id.get(line_id)
    else:       # the railML line the path runs on (the first whose netElements hold the path)
        on_path = set(path_.by_id)
        line_element = next((line for line in doc.findall(fi, "lines", "line") if on_path <= {
            m for location in doc.findall(line, "linearLocation") for a in doc.findall(location, "associatedNetElement")
            for m in macro.get(a.get("netElementRef"), [a.get("netElementRef")])}), None)
    name = extras.get("name") or (doc.name_of(line_element) if line_element is not None else None) \
        or _metadata(doc, "title") or Path(path).stem
    document = {"name": name}
    description = extras.get("description")
    if description is None and line_element is not None:
        first_name = doc.find(line_element, "name")
        description = first_name.get("description") if first_name is not None else None
    if description is None and not ours:
        description = (f"imported from railML {version} ({Path(path).name}); path "
                       + " → ".join(s.id for s in path_.steps))
    if description is not None:
        document["description"] = description
    document["length_m"] = length
    if line_element is not None and line_element.get(RC + "maxBallastOhmKm") is not None:
        document["max_ballast_ohm_km"] = doc.float_attr(line_element, RC + "maxBallastOhmKm")
    if "max_ballast_ohm_km" in extras:
        document["max_ballast_ohm_km"] = extras["max_ballast_ohm_km"]
    if line_element is not None and line_element.get(RC + "divergingRoutes") is not None:
        routes = line_element.get(RC + "divergingRoutes")
        if json_nesting_depth(routes) > MAX_JSON_DEPTH:       # json.loads would recurse past Python's limit
            doc.fail(line_element, f"rcs:divergingRoutes nested more than {MAX_JSON_DEPTH} deep: not a JSON list "
                                   "of routes")
        try:                 # the line loader checks the routes themselves (signal, frog)
            document["diverging_routes"] = json.loads(routes)
        except json.JSONDecodeError:
            raise UserError(f"{path}: line {line_element.get('id')}: rcs:divergingRoutes is not a JSON list") from None
    document["electrification"] = _electrification(doc, fi, locate, extras, notes)
    detectors, joints = _detectors(doc, fi, locate, extras, notes)
    signals = _block_signals(doc, fi, locate, notes)
    document["block_sections"] = _sections(doc, locate, detectors, signals, document["electrification"]["system"],
                                           extras, notes)
    if joints:           # none and an empty list are the same to the loader; a TVM line lists none
        document["insulated_joints"] = joints
    zones = [d.zone for d in detectors if d.zone is not None]
    if zones:
        document["separation_zones"] = zones
    document["stations"] = _stations(doc, fi, locate, path_, notes)
    document["gradients"] = _gradients(doc, locate, notes)
    document["curves"] = _curves(doc, locate, notes)
    limits, restrictions = _speeds(doc, fi, locate, line_element, extras, notes)
    if restrictions:
        document["temporary_restrictions"] = restrictions
    document["speed_limits"] = limits
    notes.extend(_ignored(doc, fi))
    return RailmlImport(document, version, [s.id for s in path_.steps], notes)


def _metadata(doc: _Doc, field_name: str) -> Optional[str]:
    metadata = doc.find(doc.root, "metadata")
    if metadata is None:
        return None
    element = metadata.find("{http://purl.org/dc/elements/1.1/}" + field_name)
    return element.text.strip() if element is not None and element.text and element.text.strip() else None


def _electrification(doc: _Doc, fi, locate: _Locator, extras, notes) -> dict:
    if "electrification" in extras:
        return dict(extras["electrification"])
    systems = {s.get("id"): s for s in doc.findall(doc.root, "common", "electrificationSystems",
                                                   "electrificationSystem")}
    found, covered = {}, 0.0
    sections = doc.findall(fi, "electrifications", "electrificationSection")
    if not sections:
        notes.append("no electrificationSection: DC 3 kV assumed (railcosim's trains are electric; a sidecar's "
                     "electrification says otherwise)")
        return {"system": "DC3000"}
    for section in sections:
        stretches = locate.intervals(section)
        if not stretches or section.get("contactLineType") == "none":
            continue
        reference = doc.find(section, "electrificationSystemRef")
        system = systems.get(reference.get("ref")) if reference is not None else None
        if reference is not None and system is None:
            doc.fail(section, f"electrificationSystemRef {reference.get('ref')!r}: no such electrificationSystem")
        voltage = doc.float_attr(system, "voltage") if system is not None else None
        frequency = doc.float_attr(system, "frequency") if system is not None else None
        if frequency in (None, 0) and voltage is None and system is None:
            notes.append(f"electrificationSection {section.get('id')}: no electrificationSystem; taken as DC 3 kV")
        if frequency not in (None, 0) and abs(frequency - 50) > 0.5:
            doc.fail(system, f"frequency {frequency:g} Hz: railcosim models DC and 50 Hz AC traction only")
        key = "AC25000" if frequency not in (None, 0) else "DC3000"
        entry = {"system": key}
        if voltage is not None:
            entry["nominal_voltage_v"] = voltage
        found.setdefault(json.dumps(entry, sort_keys=True), (section, entry))
        covered += sum(b - a for a, b, _, _ in stretches)
    if not found:
        return {"system": "none"}
    if len(found) > 1:
        (first, _), (second, _) = list(found.values())[:2]
        doc.fail(second, f"its traction supply differs from electrificationSection {first.get('id')!r} on the "
                         "same path; a line has one traction supply")
    (section, entry), = found.values()
    if covered < locate.path.length - 1.0:
        notes.append(f"electrification covers {covered:g} m of the {locate.path.length:g} m path; taken as "
                     "electrified throughout")
    return entry


def _detectors(doc: _Doc, fi, locate: _Locator, extras, notes):
    """Train detection elements on the path (sorted) and the insulated joints of the line file.
    A border marked ``rcs:separationZone`` (or named in the sidecar's zones) is a UM71
    separation zone: its :attr:`_Detector.zone` is the line file's entry."""
    found: List[_Detector] = []
    joints = []
    off_path = 0
    joint_extras = extras.get("joints", {})
    zone_extras = extras.get("zones", {})
    defaults = extras.get("defaults", {})
    for element in doc.findall(fi, "trainDetectionElements", "trainDetectionElement"):
        spots = locate.spots(element)
        if not spots:
            off_path += 1
            continue
        kind = element.get("type") or element.get("detectionType") or "trackCircuit"
        position = _clean(spots[0][0])
        zone = None
        if element.get(RC + "separationZone") in ("true", "1") or element.get("id") in zone_extras:
            if kind == "insulatedRailJoint":
                doc.fail(element, "an insulated rail joint marked a separation zone: a UM71 separation zone "
                                  "is a jointless track-circuit border (type trackCircuit)")
            zone = {"position_m": position}
            length = zone_extras.get(element.get("id"), {}).get("length_m")
            if length is None and element.get(RC + "separationZoneLengthM") is not None:
                length = doc.float_attr(element, RC + "separationZoneLengthM")
            if length is not None:
                zone["length_m"] = length
        found.append(_Detector(position, element.get("id"), kind, element, zone))
        if kind == "insulatedRailJoint":
            joint = {"position_m": position}
            if element.get(RC + "impedanceBond") is not None:
                joint["impedance_bond"] = element.get(RC + "impedanceBond") == "true"
            if element.get(RC + "bondLeadOffsetM") is not None:
                joint["bond_lead_offset_m"] = doc.float_attr(element, RC + "bondLeadOffsetM")
            for key in ("impedance_bond", "bond_lead_offset_m"):
                value = joint_extras.get(element.get("id"), {}).get(key, defaults.get(key))
                if value is not None and (key not in joint or key in joint_extras.get(element.get("id"), {})):
                    joint[key] = value
            joints.append(joint)
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


@dataclass
class _Signal:
    position: float
    name: str
    id: str


def _block_signals(doc: _Doc, fi, locate: _Locator, notes) -> List[_Signal]:
    signals, other_kinds, against, off_path = [], {}, 0, 0
    for element in doc.findall(fi, "signalsIS", "signalIS"):
        kind = _signal_kind(doc, element)
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
        signals.append(_Signal(position, doc.name_of(element) or element.get("id"), element.get("id")))
    if other_kinds:
        notes.append("signals that close no block ignored: " + ", ".join(f"{n} {k}" for k, n in sorted(other_kinds.items())))
    if against:
        notes.append(f"{against} block signal(s) for the other running direction ignored")
    if off_path:
        notes.append(f"{off_path} signal(s) off the running path ignored")
    signals.sort(key=lambda s: s.position)
    return signals


def _tvd_sections(doc: _Doc) -> List[object]:
    return [tvd for assets in _interlocking_assets(doc) for tvd in doc.findall(assets, "tvdSections", "tvdSection")]


def _sections(doc: _Doc, locate: _Locator, detectors: List[_Detector], signals: List[_Signal], electrification: str,
              extras, notes) -> List[dict]:
    """Block sections: the path between consecutive train detectors, each the TVD section that
    both demarcate (docs/railml.md#block-sections)."""
    path_ = locate.path
    length = path_.length
    tvds = _tvd_sections(doc)
    # the TVD section(s) each detector (or buffer stop) demarcates
    demarcates: Dict[str, List[object]] = {}
    exit_signals: Dict[str, set] = {}
    for tvd in tvds:
        for tag in ("hasDemarcatingTraindetector", "hasDemarcatingBufferstop"):
            for ref in doc.findall(tvd, tag):
                demarcates.setdefault(ref.get("ref"), []).append(tvd)
        exits = set()
        for ref in doc.findall(tvd, "hasExitSignal"):
            target = doc.by_id.get(ref.get("ref"))
            if target is not None and _local(target) == "signalIL":
                refers = doc.find(target, "refersTo")
                exits.add(refers.get("ref") if refers is not None else ref.get("ref"))
            else:
                exits.add(ref.get("ref"))
        exit_signals[tvd.get("id")] = exits
    points = list(detectors)
    if not points:
        if not signals:
            raise UserError(f"{doc.path}: no train detection element and no block signal on the running path "
                            f"({' → '.join(s.id for s in path_.steps)}): no block section can be made")
        points = [_Detector(_clean(s.position), f"joint at signal {s.name}", "insulatedRailJoint", None) for s in signals]
        notes.append("no train detection on the path: an insulated joint assumed at each block signal "
                     f"({', '.join(s.name for s in signals)})")
    # the path's ends close the first and the last stretch when a buffer stop or nothing else does
    buffer_stops = []
    for stop in doc.findall(doc.find(doc.root, "infrastructure", "functionalInfrastructure"), "bufferStops",
                            "bufferStop"):
        for position, _ in locate.spots(stop):
            buffer_stops.append(_Detector(_clean(position), stop.get("id"), "bufferStop", stop))
    bounds = sorted(points + buffer_stops, key=lambda d: d.position)
    if bounds[0].position > 1e-6:
        bounds.insert(0, _Detector(0, "the path's start", "pathEnd", None))
    if bounds[-1].position < length - 1e-6:
        bounds.append(_Detector(_clean(length), "the path's end", "pathEnd", None))
    section_extras = extras.get("sections", {})
    defaults = extras.get("defaults", {})
    sections, derived, open_ends = [], [], []
    for a, b in zip(bounds[:-1], bounds[1:]):
        if b.position - a.position < 1e-6:
            continue
        common = [t for t in demarcates.get(a.id, []) if t in demarcates.get(b.id, [])]
        tvd = common[0] if common else None
        if tvds and tvd is None:
            if a.kind == "pathEnd" or b.kind == "pathEnd":
                open_ends.append((a, b))    # track beyond the first or last detector: checked below
                continue
            made_so_far = {id(s["_tvd"]) for s in sections}
            # the TVD section left open here: one of the two detectors demarcates it, and it is
            # not closed elsewhere on the path
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
        if tvd is not None:
            ident = tvd.get("id")
            name = (doc.find(tvd, "designator").get("entry") if doc.find(tvd, "designator") is not None
                    else None) or ident
        else:
            ident = f"S{len(sections) + 1}"
            name = str(len(sections) + 1)
            derived.append(ident)
        sections.append({"_tvd": tvd, "_id": ident, "_end": b, "name": name, "start_m": a.position,
                         "end_m": b.position})
    made = {id(s["_tvd"]) for s in sections if s["_tvd"] is not None}
    for a, b in open_ends:
        detector, end = (b, a) if a.kind == "pathEnd" else (a, b)
        unclosed = [t.get("id") for t in demarcates.get(detector.id, []) if id(t) not in made]
        if unclosed:
            raise UserError(f"{doc.path}: tvdSection {unclosed[0]!r}: no train detection at its end on the running "
                            f"path: it runs from {detector.id!r} ({detector.position:g} m) to {end.id} "
                            f"({end.position:g} m) with no detector there")
        notes.append(f"{end.position - detector.position if end is b else detector.position - end.position:g} m of "
                     f"track beyond {detector.id!r} ({detector.position:g} m) to {end.id} has no track circuit")
    if derived and not tvds:
        notes.append("no tvdSections in the interlocking: block sections made between consecutive train "
                     f"detectors ({', '.join(derived)}; name them in the sidecar's sections)")
    if not sections:
        raise UserError(f"{doc.path}: no block section on the running path")
    # signals: at each section's exit, facing the train
    used = set()
    carrier_default = defaults.get("carrier_hz") or (DEFAULTS["carrier_hz_ac"] if electrification == "AC25000"
                                                     else DEFAULTS["carrier_hz_dc"])
    transmitter_default = defaults.get("transmitter", DEFAULTS["transmitter"])
    assumed = {"carrier": 0, "transmitter": 0, "ballast": 0}
    result, idents, ends = [], [], []
    for k, section in enumerate(sections):
        tvd = section.pop("_tvd")
        ident = section.pop("_id")
        ends.append(section.pop("_end"))
        idents.append(ident)
        end = section["end_m"]
        exits = exit_signals.get(ident, set())
        candidates = [s for s in signals if s.id not in used and end - SIGNAL_TO_JOINT_M - 1e-6 <= s.position <= end + 1e-6]
        preferred = [s for s in candidates if s.id in exits] or candidates
        signal = preferred[-1] if preferred else None
        if signal is not None:
            used.add(signal.id)
        entry = {"name": section["name"], "start_m": section["start_m"], "end_m": end,
                 "signal": signal.name if signal is not None else ""}
        own = section_extras.get(ident, {})
        carrier = own.get("carrier_hz") or (doc.float_attr(tvd, "frequency") if tvd is not None else None)
        if carrier is None:
            carrier = carrier_default
            assumed["carrier"] += 1
        transmitter = own.get("transmitter") or (tvd.get(RC + "transmitter") if tvd is not None else None)
        if transmitter is None and carrier in TVM_CARRIERS_HZ:
            transmitter = TVM_TRANSMITTER      # only a UM71 circuit carries an audio frequency
        if transmitter is None:
            transmitter = transmitter_default
            assumed["transmitter"] += 1
        if transmitter == "alternate":     # the other type than the section before (docs/wayside_coder.md)
            transmitter = "KPT-7" if result and result[-1]["transmitter"] == "KPT-5" else "KPT-5"
        ballast = own.get("ballast_ohm_km") or (doc.float_attr(tvd, RC + "ballastOhmKm") if tvd is not None
                                                else None)
        if ballast is None:
            ballast = defaults.get("ballast_ohm_km", DEFAULTS["ballast_ohm_km"])
            assumed["ballast"] += 1
        if carrier not in ALSN_CARRIERS_HZ + TVM_CARRIERS_HZ:
            where = f"tvdSection {ident!r}" if tvd is not None else f"block section {ident}"
            raise UserError(f"{doc.path}: {where}: frequency {carrier:g} Hz is no ALSN carrier (25, 50 or 75 Hz) "
                            "nor a TVM one (1700, 2000, 2300 or 2600 Hz)")
        if "name" in own:
            entry["name"] = own["name"]
        entry.update({"transmitter": transmitter, "carrier_hz": int(carrier), "ballast_ohm_km": ballast})
        result.append(entry)
    _check_separation_zones(doc, result, idents, ends, detectors)
    result = _split_long(result, notes)
    unused = [s.name for s in signals if s.id not in used]
    if unused:
        notes.append(f"block signals not at a section's exit (more than {SIGNAL_TO_JOINT_M:g} m before its end) "
                     f"ignored: {', '.join(unused)}")
    for what, count in assumed.items():
        if count:
            value = {"carrier": f"{carrier_default} Hz", "transmitter": transmitter_default,
                     "ballast": f"{defaults.get('ballast_ohm_km', DEFAULTS['ballast_ohm_km'])} Ω·km"}[what]
            notes.append(f"{what} of {count} block section(s) not in the file: {value} assumed (docs/railml.md#defaults)")
    return result


def _check_separation_zones(doc: _Doc, sections: List[dict], idents: List[str], ends: List[_Detector],
                            detectors: List[_Detector]) -> None:
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


def _stations(doc: _Doc, fi, locate: _Locator, path_: _Path, notes) -> List[dict]:
    stations, taken = [], set()
    platforms_of: Dict[str, object] = {}
    for platform in doc.findall(fi, "platforms", "platform"):
        if platform.get("belongsToParent"):
            platforms_of.setdefault(platform.get("belongsToParent"), platform)
    for op in _stations_elements(doc):
        spots = locate.spots(op)
        if not spots:
            for start, end, _, _ in locate.intervals(op):
                spots = [((start + end) / 2, None)]
        if not spots:
            continue
        entry = {"name": doc.name_of(op) or op.get("id"), "stop_m": _clean(spots[0][0])}
        platform = platforms_of.get(op.get("id"))
        if platform is not None:
            taken.add(platform.get("id"))
            length = doc.find(platform, "length")
            if length is not None and doc.float_attr(length, "value") is not None:
                entry["platform_length_m"] = doc.float_attr(length, "value")
        stations.append(entry)
    for platform in doc.findall(fi, "platforms", "platform"):
        if platform.get("id") in taken or platform.get("belongsToParent") in {op.get("id") for op in _stations_elements(doc)}:
            continue
        stretches = [s for s in locate.intervals(platform) if s[2]]
        if not stretches:
            continue
        start, end = min(s[0] for s in stretches), max(s[1] for s in stretches)
        entry = {"name": doc.name_of(platform) or platform.get("id"), "stop_m": _clean(end),
                 "platform_length_m": _clean(end - start)}
        stations.append(entry)
        notes.append(f"platform {platform.get('id')} has no operationalPoint: a station stopping at its far end "
                     f"({entry['stop_m']:g} m)")
    stations.sort(key=lambda s: s["stop_m"])
    unique = []
    for station in stations:
        if unique and station["stop_m"] <= unique[-1]["stop_m"] + 1e-6:
            notes.append(f"station {station['name']} at {station['stop_m']:g} m: at the place of "
                         f"{unique[-1]['name']}; ignored")
            continue
        if any(s["name"] == station["name"] for s in unique):
            station = {**station, "name": f"{station['name']} ({station['stop_m']:g} m)"}
        unique.append(station)
    if not unique:
        raise UserError(f"{doc.path}: no operationalPoint (station or stopping point) or platform on the running "
                        f"path ({' → '.join(s.id for s in path_.steps)}): a timetable needs stations")
    return unique


def _gradients(doc: _Doc, locate: _Locator, notes) -> List[dict]:
    pieces, arcs = [], 0
    for curve in doc.findall(doc.root, "infrastructure", "geometry", "gradientCurves", "gradientCurve"):
        gradient = doc.float_attr(curve, "gradient")
        if curve.get("curveType") != "straight" or gradient is None:
            arcs += 1
            continue
        if abs(gradient) > 40:
            doc.fail(curve, f"gradient {gradient:g} ‰: railcosim's trains run on at most ±40 ‰")
        for start, end, _, forward in locate.intervals(curve):
            # railML gives a gradient along its netElement's orientation: a netElement run
            # backwards climbs where it falls
            pieces.append((start, end, gradient if forward else -gradient))
    if arcs:
        notes.append(f"{arcs} vertical arc(s) (gradientCurve not straight, or no gradient) ignored: the "
                     "gradient before each holds through it")
    return _piecewise(pieces, "permille", 0.0, locate.path.length, notes, "gradient")


def _piecewise(pieces, key: str, default, length: float, notes, what: str) -> List[dict]:
    """Piecewise-constant entries (start_m, key) from covered stretches; gaps hold ``default``."""
    pieces = sorted(pieces, key=lambda p: (p[0], p[1]))
    entries, cursor, gaps = [], 0, 0.0
    for start, end, value in pieces:
        start, end = _clean(start), _clean(end)
        if end <= cursor:
            continue
        if start > cursor + 1e-6:
            entries.append({"start_m": cursor, key: default})
            gaps += start - cursor
        entries.append({"start_m": max(start, cursor), key: value})
        cursor = end
    if cursor < length - 1e-6 and pieces:
        entries.append({"start_m": cursor, key: default})
        gaps += length - cursor
    if not entries:
        entries = [{"start_m": 0, key: default}]
        gaps = length
    merged = []
    for entry in entries:
        if merged and merged[-1][key] == entry[key]:
            continue
        merged.append(entry)
    merged[0]["start_m"] = 0
    if gaps > 1.0:
        notes.append(f"{what} not given over {gaps:g} m of the path: {default} assumed there")
    return merged


def _curves(doc: _Doc, locate: _Locator, notes) -> List[dict]:
    curves, skipped = [], 0
    for curve in doc.findall(doc.root, "infrastructure", "geometry", "horizontalCurves", "horizontalCurve"):
        radius = doc.float_attr(curve, "radius")
        if curve.get("curveType") == "straight":
            continue
        if curve.get("curveType") != "arc" or not radius or abs(radius) < 100:
            skipped += 1
            continue
        for start, end, _, _ in locate.intervals(curve):
            curves.append({"start_m": _clean(start), "end_m": _clean(end), "radius_m": abs(radius)})
    if skipped:
        notes.append(f"{skipped} horizontal curve(s) that are no arc of radius ≥ 100 m (transitions, tight "
                     "yard curves) ignored")
    return sorted(curves, key=lambda c: c["start_m"])


def _profiles(doc: _Doc) -> Dict[str, Optional[str]]:
    """speedProfile id → our train category (None: a profile we cannot place): its trainType
    passenger or freight; a profile named high_speed (as our export writes it) is high_speed."""
    categories = {}
    for profile in doc.findall(doc.root, "common", "speedProfiles", "speedProfile"):
        train_type = doc.find(profile, "trainType")
        category = {"passenger": "passenger", "freight": "freight"}.get(
            train_type.get("type") if train_type is not None else None)
        if category is None and doc.name_of(profile) == "high_speed":
            category = "high_speed"
        categories[profile.get("id")] = category
    return categories


def _speeds(doc: _Doc, fi, locate: _Locator, line_element, extras, notes):
    profiles = _profiles(doc)
    defaults = extras.get("defaults", {})
    line_speed = None
    if line_element is not None:
        performance = doc.find(line_element, "linePerformance")
        line_speed = doc.float_attr(performance, "maxSpeed") if performance is not None else None
    default_speed = defaults.get("speed_kmh") or line_speed
    permanent, restrictions, unplaced, against = [], [], 0, 0
    for section in doc.findall(fi, "speeds", "speedSection"):
        speed = doc.float_attr(section, "maxSpeed")
        if speed is None:
            continue
        refs = [r.get("ref") for r in doc.findall(section, "validForSpeedProfile")]
        categories = [profiles.get(r) for r in refs]
        if refs and not any(categories):
            unplaced += 1
            continue
        categories = [c for c in categories if c]
        for start, end, faces, _ in locate.intervals(section):
            if not faces:
                against += 1
                continue
            if section.get("isTemporary") == "true":
                entry = {}
                name = doc.name_of(section)
                if name:
                    entry["name"] = name
                entry.update({"start_m": _clean(start), "end_m": _clean(end), "speed_kmh": speed})
                if categories:
                    entry["categories"] = categories
                restrictions.append(entry)
            else:
                permanent.append((start, end, speed, categories))
    if unplaced:
        notes.append(f"{unplaced} speedSection(s) only for speed profiles that name no passenger or freight "
                     "train ignored")
    if against:
        notes.append(f"{against} speedSection stretch(es) for the other running direction ignored")
    if default_speed is None:
        default_speed = DEFAULTS["speed_kmh"]
    categories = ["passenger", "freight"] + (["high_speed"] if any("high_speed" in c for *_, c in permanent) else [])
    points = sorted({0, *(_clean(p[0]) for p in permanent), *(_clean(p[1]) for p in permanent)})
    points = [p for p in points if p < locate.path.length - 1e-6]
    entries, uncovered = [], 0.0
    for k, start in enumerate(points):
        end = points[k + 1] if k + 1 < len(points) else locate.path.length
        middle = (start + end) / 2
        entry = {"start_m": start}
        for category in categories:
            applying = [speed for a, b, speed, cats in permanent if a <= middle < b and (not cats or category in cats)]
            if not applying:
                fallback = default_speed if category != "freight" else (
                    defaults.get("freight_speed_kmh") or min(default_speed, 200))
                if category == "high_speed":
                    fallback = entry["passenger_kmh"]
                applying = [fallback]
                if category == "passenger":
                    uncovered += end - start
            entry[f"{category}_kmh"] = min(applying)
        if entries and all(entries[-1][f"{c}_kmh"] == entry[f"{c}_kmh"] for c in categories):
            continue
        entries.append(entry)
    for entry in entries:
        entry["freight_kmh"] = min(entry["freight_kmh"], 200)
    if uncovered > 1.0:
        source = "the sidecar's default speed" if defaults.get("speed_kmh") else (
            "the line's linePerformance maxSpeed" if line_speed else "the default speed")
        notes.append(f"no speedSection over {uncovered:g} m of the path: {source} ({default_speed:g} km/h) there")
    return entries, sorted(restrictions, key=lambda r: r["start_m"])


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
        bounds = [_clean(section["start_m"] + length * k / pieces) for k in range(pieces)] + [section["end_m"]]
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


#: functionalInfrastructure containers the import reads (others are listed as not read)
_READ = {"trainDetectionElements", "signalsIS", "speeds", "operationalPoints", "platforms", "electrifications",
         "lines", "tracks", "bufferStops"}


def _ignored(doc: _Doc, fi) -> List[str]:
    notes = []
    skipped = sorted({_local(child) for child in (fi if fi is not None else []) if _local(child) and
                      etree.QName(child).namespace == doc.ns and _local(child) not in _READ})
    if skipped:
        notes.append("not read (no place in a railcosim line): functionalInfrastructure " + ", ".join(skipped))
    interlocking = doc.find(doc.root, "interlocking")
    if interlocking is not None:
        other = sorted({_local(child) for assets in _interlocking_assets(doc) for child in assets
                        if _local(child) not in ("tvdSections", "signalsIL", "designator")}
                       | {_local(child) for child in interlocking
                          if _local(child) not in ("assetsForIL", "assetsForInterlockings")})
        if other:
            notes.append("not read from the interlocking (railcosim's block logic is the automatic block, "
                         "docs/wayside_coder.md): " + ", ".join(other))
    for tag in ("rollingstock", "timetable"):
        if doc.find(doc.root, tag) is not None:
            notes.append(f"railML {tag} not read (give --rolling-stock / --timetable files)")
    return notes


def _load_sidecar(sidecar) -> dict:
    """The sidecar's document (docs/railml.md#the-sidecar), checked against its JSON schema."""
    if sidecar is None:
        return {}
    import jsonschema

    path = Path(sidecar)
    try:
        document = read_json_file(path)
    except FmuInputError as error:
        raise UserError(f"--sidecar: {error}") from None
    schema = json.loads((SCHEMA_DIR / SIDECAR_SCHEMA).read_text())
    errors = sorted(jsonschema.Draft202012Validator(schema).iter_errors(document), key=lambda e: list(e.absolute_path))
    if errors:
        where_ = ".".join(str(p) for p in errors[0].absolute_path) or "(top level)"
        raise UserError(f"--sidecar: {path}: field {where_}: {errors[0].message}")
    return document


# ---- export ---------------------------------------------------------------------------------------
def export_railml(document: dict, version: str = "3.2") -> bytes:
    """A line document as railML ``version`` infrastructure (docs/railml.md#export): one netElement
    of the line's length, every position a ``pos`` on it; what railML has no place for in our
    extension namespace. The bytes of the XML file."""
    ns = RAILML_NS[version]
    nsmap = {None: ns, "rcs": EXTENSION_NS}

    def el(parent, tag, attrib=None, **more):
        element = etree.SubElement(parent, "{%s}%s" % (ns, tag))
        for key, value in {**(attrib or {}), **more}.items():
            if value is not None:
                element.set(key, value if isinstance(value, str) else _text(value))
        return element

    def name(parent, text, description=None):
        el(parent, "name", name=text, language="und", description=description)

    def spot(parent, ident, position, direction="both"):
        el(parent, "spotLocation", id=ident, netElementRef="ne_line", applicationDirection=direction, pos=position)

    def stretch(parent, ident, start, end, direction="both"):
        location = el(parent, "linearLocation", id=ident, applicationDirection=direction)
        el(location, "associatedNetElement", netElementRef="ne_line", keepsOrientation="true",
           posBegin=start, posEnd=end)

    root = etree.Element("{%s}railML" % ns, nsmap=nsmap, version=version)
    length = document["length_m"]
    limit_categories = ["passenger", "freight"] + (["high_speed"] if any("high_speed_kmh" in s
                                                                          for s in document["speed_limits"]) else [])
    categories = list(limit_categories)
    for restriction in document.get("temporary_restrictions", []):
        categories += [c for c in restriction.get("categories", []) if c not in categories]
    common = el(root, "common", id="common")
    electrification = document["electrification"]
    if electrification["system"] != "none":
        systems = el(common, "electrificationSystems")
        el(systems, "electrificationSystem", id="es_line", voltage=electrification.get("nominal_voltage_v"),
           frequency=50 if electrification["system"] == "AC25000" else 0)
    profiles = el(common, "speedProfiles")
    for category in categories:
        profile = el(profiles, "speedProfile", id=f"sp_{category}")
        name(profile, category)
        if category in ("passenger", "freight"):
            el(profile, "trainType", type=category)

    infrastructure = el(root, "infrastructure", id="infrastructure")
    topology = el(infrastructure, "topology")
    element = el(el(topology, "netElements"), "netElement", id="ne_line", length=length)
    positioning = el(element, "associatedPositioningSystem", id="ne_line_aps")
    el(positioning, "intrinsicCoordinate", id="ne_line_begin", intrinsicCoord=0)
    el(positioning, "intrinsicCoordinate", id="ne_line_end", intrinsicCoord=1)
    level = el(el(el(topology, "networks"), "network", id="network"), "level", id="network_micro",
               descriptionLevel="Micro")
    el(level, "networkResource", ref="ne_line")

    geometry = el(infrastructure, "geometry")
    if document["curves"]:
        horizontal = el(geometry, "horizontalCurves")
        for k, curve in enumerate(document["curves"], 1):
            entity = el(horizontal, "horizontalCurve", id=f"hc_{k}", curveType="arc", radius=curve["radius_m"])
            stretch(entity, f"hc_{k}_loc", curve["start_m"], curve["end_m"])
    gradients = el(geometry, "gradientCurves")
    for k, gradient in enumerate(document["gradients"]):
        end = document["gradients"][k + 1]["start_m"] if k + 1 < len(document["gradients"]) else length
        entity = el(gradients, "gradientCurve", id=f"gc_{k + 1}", curveType="straight", gradient=gradient["permille"])
        stretch(entity, f"gc_{k + 1}_loc", gradient["start_m"], end)

    fi = el(infrastructure, "functionalInfrastructure")
    if electrification["system"] != "none":
        section = el(el(fi, "electrifications"), "electrificationSection", id="el_line", contactLineType="overhead")
        stretch(section, "el_line_loc", 0, length)
        el(section, "electrificationSystemRef", ref="es_line")
    line = el(el(fi, "lines"), "line", id="line")
    name(line, document["name"], document.get("description"))
    stretch(line, "line_loc", 0, length)
    if "max_ballast_ohm_km" in document:
        line.set(RC + "maxBallastOhmKm", _text(document["max_ballast_ohm_km"]))
    if document.get("diverging_routes"):
        line.set(RC + "divergingRoutes", json.dumps(document["diverging_routes"], ensure_ascii=False))
    points = el(fi, "operationalPoints")
    for k, station in enumerate(document["stations"], 1):
        op = el(points, "operationalPoint", id=f"op_{k}")
        name(op, station["name"])
        spot(op, f"op_{k}_loc", station["stop_m"])
        el(el(op, "opOperations"), "opOperation", operationalType="station")
    if any("platform_length_m" in s for s in document["stations"]):
        platforms = el(fi, "platforms")
        for k, station in enumerate(document["stations"], 1):
            if "platform_length_m" in station:
                platform = el(platforms, "platform", id=f"pl_{k}", belongsToParent=f"op_{k}")
                name(platform, station["name"])
                stretch(platform, f"pl_{k}_loc", max(station["stop_m"] - station["platform_length_m"], 0),
                        station["stop_m"])
                el(platform, "length", value=station["platform_length_m"], type="physical")
    sections = document["block_sections"]
    signalled = [(k, s) for k, s in enumerate(sections, 1) if s["signal"]]
    if signalled:
        signals = el(fi, "signalsIS")
        for k, section in signalled:
            signal = el(signals, "signalIS", id=f"sig_{k}", isSwitchable="true")
            name(signal, section["signal"])
            spot(signal, f"sig_{k}_loc", section["end_m"], "normal")
            el(signal, "isTrainMovementSignal")
    speeds = el(fi, "speeds")
    limits = document["speed_limits"]
    for k, limit in enumerate(limits):
        end = limits[k + 1]["start_m"] if k + 1 < len(limits) else length
        for category in limit_categories:
            speed = limit.get(f"{category}_kmh", limit["passenger_kmh"])
            entity = el(speeds, "speedSection", id=f"ss_{k + 1}_{category}", maxSpeed=speed, isTemporary="false")
            stretch(entity, f"ss_{k + 1}_{category}_loc", limit["start_m"], end, "normal")
            el(entity, "validForSpeedProfile", ref=f"sp_{category}")
    for k, restriction in enumerate(document.get("temporary_restrictions", []), 1):
        entity = el(speeds, "speedSection", id=f"tsr_{k}", maxSpeed=restriction["speed_kmh"], isTemporary="true")
        if "name" in restriction:
            name(entity, restriction["name"])
        stretch(entity, f"tsr_{k}_loc", restriction["start_m"], restriction["end_m"], "normal")
        for category in restriction.get("categories", []):
            el(entity, "validForSpeedProfile", ref=f"sp_{category}")
    # train detection: the insulated joints, and a track-circuit border at every section end
    # that has no joint (a jointless border); a border between two UM71 circuits is their tuned
    # separation zone, which railML has no word for (our extension marks it)
    zones = {float(z["position_m"]): z for z in document.get("separation_zones", [])}
    detection = el(fi, "trainDetectionElements")
    detector_at: Dict[float, str] = {}
    for k, joint in enumerate(document.get("insulated_joints", []), 1):
        entity = el(detection, "trainDetectionElement", id=f"tde_joint_{k}", type="insulatedRailJoint")
        spot(entity, f"tde_joint_{k}_loc", joint["position_m"])
        if "impedance_bond" in joint:
            entity.set(RC + "impedanceBond", _text(bool(joint["impedance_bond"])))
        if "bond_lead_offset_m" in joint:
            entity.set(RC + "bondLeadOffsetM", _text(joint["bond_lead_offset_m"]))
        detector_at.setdefault(float(joint["position_m"]), entity.get("id"))
    for k, position in enumerate(sorted({float(p) for s in sections for p in (s["start_m"], s["end_m"])}), 1):
        if position not in detector_at:
            entity = el(detection, "trainDetectionElement", id=f"tde_border_{k}", type="trackCircuit")
            value = next(p for s in sections for p in (s["start_m"], s["end_m"]) if float(p) == position)
            spot(entity, f"tde_border_{k}_loc", value)
            if position in zones:
                entity.set(RC + "separationZone", "true")
                if "length_m" in zones[position]:
                    entity.set(RC + "separationZoneLengthM", _text(zones[position]["length_m"]))
            detector_at[position] = entity.get("id")

    interlocking = el(root, "interlocking")
    if version == "3.1":
        assets = el(interlocking, "assetsForIL", id="assets")
    else:
        assets = el(el(interlocking, "assetsForInterlockings"), "assetsForInterlocking", id="assets")
    tvds = el(assets, "tvdSections")
    for k, section in enumerate(sections, 1):
        tvd = el(tvds, "tvdSection", id=f"tvd_{k}", residualRouteCancellationDelay="PT0S",
                 partialRouteReleaseDelay="PT0S", technology="trackCircuit", frequency=section["carrier_hz"])
        el(tvd, "designator", register="_railcosim", entry=section["name"])
        tvd.set(RC + "transmitter", section["transmitter"])
        tvd.set(RC + "ballastOhmKm", _text(section["ballast_ohm_km"]))
        if section["signal"]:
            el(tvd, "hasExitSignal", ref=f"sig_{k}")
        for position in (section["start_m"], section["end_m"]):
            el(tvd, "hasDemarcatingTraindetector", ref=detector_at[float(position)])
    if signalled:
        signals_il = el(assets, "signalsIL")
        for k, _ in signalled:
            signal_il = el(signals_il, "signalIL", id=f"sig_{k}_il", isVirtual="false", function="block")
            el(signal_il, "refersTo", ref=f"sig_{k}")
    return etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True)


# ---- validation -------------------------------------------------------------------------------------
class _LocalSchemas(etree.Resolver):
    """Schema imports resolved on this machine: the Dublin Core schema railML's common3.xsd names
    by its web address (from the user's folder when it holds a dc.xsd, else our stand-in), no
    network."""

    def __init__(self, folder: Path):
        super().__init__()
        self.folder = folder

    def resolve(self, url, public_id, context):
        if url and url.startswith(("http://", "https://")):
            local = self.folder / Path(url).name
            if Path(url).name == "dc.xsd" and not local.is_file():
                local = DUBLIN_CORE_XSD
            if local.is_file():
                return self.resolve_filename(str(local), context)
            raise UserError(f"--schema {self.folder}: the railML schema imports {url}, which is not in the folder "
                            "(no network is used): put a copy there")
        return None


def validate_railml(path, schema_dir) -> Tuple[bool, List[str]]:
    """``path`` against the railML XSD in ``schema_dir`` (its railml3.xsd) and our extension
    schema: (valid, every error as 'line N: message')."""
    schema_dir = Path(schema_dir)
    root_xsd = schema_dir / "railml3.xsd"
    if not root_xsd.is_file():
        raise UserError(f"--schema {schema_dir}: no railml3.xsd there (the folder of the railML 3.1 or 3.2 "
                        "schema files as railML.org distributes them)")
    doc = _parse(Path(path))
    try:
        target = etree.parse(str(root_xsd), etree.XMLParser(resolve_entities=False, no_network=True)
                             ).getroot().get("targetNamespace")
    except etree.XMLSyntaxError as error:      # an undefined entity, a truncated file, not XML at all
        raise UserError(f"--schema {schema_dir}: {root_xsd}:{error.lineno}: not an XML document "
                        f"({error.msg})") from None
    except OSError as error:
        raise UserError(f"--schema {schema_dir}: {root_xsd}: cannot be read ({error})") from None
    if target != doc.ns:
        raise UserError(f"--schema {schema_dir}: holds the railML schema of {target}; {path} is railML "
                        f"{VERSION_OF_NS[doc.ns]} ({doc.ns})")
    driver = (f'<xs:schema xmlns:xs="http://www.w3.org/2001/XMLSchema" targetNamespace="urn:railcosim:validation">'
              f'<xs:import namespace="{doc.ns}" schemaLocation="{root_xsd.resolve().as_uri()}"/>'
              f'<xs:import namespace="{EXTENSION_NS}" schemaLocation="{EXTENSION_XSD.as_uri()}"/>'
              f'</xs:schema>')
    parser = etree.XMLParser(no_network=True)
    parser.resolvers.add(_LocalSchemas(schema_dir))
    try:
        schema = etree.XMLSchema(etree.fromstring(driver.encode(), parser, base_url=str(schema_dir.resolve()) + "/"))
    except etree.XMLSchemaParseError as error:
        # the first problem, in the file it is in (an included schema's own, not the driver's)
        entry = next((e for e in error.error_log if e.filename and not e.filename.startswith("<")), None)
        where = f"{_file_of(entry.filename)}:{entry.line}: " if entry is not None else ""
        message = entry.message if entry is not None else str(error)
        raise UserError(f"--schema {schema_dir}: {where}the schema does not load ({' '.join(message.split())})") \
            from None
    valid = schema.validate(doc.root.getroottree())
    return valid, [f"line {e.line}: {e.message}" for e in schema.error_log]


def _file_of(url: str) -> str:
    """A path for messages from the file: URL lxml names a schema file by."""
    from urllib.parse import unquote, urlparse

    return unquote(urlparse(url).path) if url.startswith("file:") else url


def system_line_file(system_path) -> Path:
    """The line file the components of a system (folder or .ssp) read: the one every
    ``line_file`` parameter names, else the bundled default line."""
    from fmus.data.loader import DEFAULT_LINE
    from orchestrator.verdicts.system_checks import FMU_RESOURCES_ROOT
    from orchestrator.graph import resolve_data_file
    from orchestrator.ssp import open_system

    system = open_system(Path(system_path))
    try:
        found = {}
        for component in system.components.values():
            for parameter in component.parameters:
                if parameter.name.rpartition(".")[2] == "line_file" and parameter.value:
                    value = resolve_data_file(parameter.value, system.folder)
                    path = Path(value)
                    if not path.is_absolute() and not path.is_file() and (FMU_RESOURCES_ROOT / path).is_file():
                        path = FMU_RESOURCES_ROOT / path
                    if not path.is_file():
                        raise UserError(f"{parameter.origin}: {component.name}.line_file {parameter.value!r}: "
                                        "no such file in the system")
                    found.setdefault(path.resolve(), (component.name, path, json.loads(path.read_text("utf-8"))))
        documents = {json.dumps(doc, sort_keys=True) for _, _, doc in found.values()}
        if len(documents) > 1:
            (a, pa, _), (b, pb, _) = list(found.values())[:2]
            raise UserError(f"{system_path}: {a}.line_file ({pa}) and {b}.line_file ({pb}) differ: a system "
                            "exports one line")
        if found:
            return next(iter(found.values()))[1] if system.temp_dir is None else _copy_out(next(iter(found.values()))[1])
        return Path(DEFAULT_LINE)
    finally:
        system.close()


def _copy_out(path: Path) -> Path:
    """A file of an unpacked .ssp, copied out before the extraction folder goes."""
    import tempfile

    target = Path(tempfile.mkdtemp(prefix="railcosim_line_")) / path.name
    target.write_bytes(path.read_bytes())
    return target
