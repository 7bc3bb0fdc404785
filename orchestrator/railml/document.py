"""A railML 3.1 / 3.2 file as the import and the validation read it: the namespaces, our
extension's, the shipped schemas, the defaults the import assumes (docs/railml.md#defaults), and
:class:`Document`, the parsed file whose ids and references are checked before anything is read
and whose every number is read through one check (:meth:`Document.float_attr`). The look-ups of
the functional infrastructure that both the choice of the running path and the block sections
need (a signal's kind, the stations, the interlocking's assets) are here too.
"""
from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Dict, Optional

from lxml import etree

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

#: built-in defaults (docs/railml.md#defaults): the shipped lines' values
DEFAULTS = {
    "carrier_hz_dc": 50, "carrier_hz_ac": 25,       # 50 Hz cannot be used under 50 Hz AC traction
    "transmitter": "alternate",                      # KPT-5, KPT-7, KPT-5, … as the shipped lines
    "ballast_ohm_km": 1.0,                           # the normative minimum (docs/rail_line.md)
    "speed_kmh": 80.0,                               # where no speed section and no line maxSpeed
    "freight_speed_kmh": None,                       # None: the passenger speed, at most 200
}
SIGNAL_FUNCTIONS_CLOSING_A_BLOCK = {"main", "block", "exit", "entry", "intermediate", "intermediateStop",
                                    "junction", "combined"}
STATION_TYPES = {"station", "stoppingPoint", "halt"}

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


def shown_value(value: str) -> str:
    """An attribute's value for a message: a 4000-digit number is not repeated in full."""
    return repr(value) if len(value) <= 40 else f"{value[:20]!r}… ({len(value)} characters)"


def _attribute(name: str) -> str:
    """An attribute's name as the file writes it (our extension's with its rcs: prefix)."""
    return "rcs:" + name[len(RC):] if name.startswith(RC) else name


def local_name(element) -> str:
    return etree.QName(element).localname if isinstance(element.tag, str) else ""


class Document:
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
            if not ident and local_name(element) in IDENTIFIED and etree.QName(element).namespace == self.ns:
                self.fail(element, f"attribute id {'empty' if ident == '' else 'missing'} (the import names and "
                                   f"links every {local_name(element)} by its id)")
            if ident is None:
                continue
            first = self.by_id.setdefault(ident, element)
            if first is not element:
                self.fail(element, f"id {ident!r} is also the id of the {local_name(first)} at line {first.sourceline} "
                                   "(railML ids are unique in a file)")
        for element in elements:
            for name, value in element.attrib.items():
                local = _attribute(name).rpartition(":")[2]
                if (local == "ref" or local.endswith("Ref") or local in REFERENCE_ATTRIBUTES) and \
                        value not in self.by_id:
                    owner = element if element.get("id") is not None else next(
                        (e for e in element.iterancestors() if e.get("id")), element)
                    what = f"attribute {_attribute(name)}={shown_value(value)}" if owner is element else \
                        f"<{local_name(element)} {_attribute(name)}={shown_value(value)}> at line {element.sourceline}"
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
        tag = "" if isinstance(element_or_id, str) else local_name(element_or_id)
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
            self.fail(element, f"{shown}={shown_value(value)} is not a number")
        if isinstance(number, float) and not math.isfinite(number) and value.strip().lower() in _NOT_FINITE:
            self.fail(element, f"{shown}={shown_value(value)} is not a finite number")
        # float() reads 1e400 as inf; an int of 4000 digits would not even convert to float
        if not abs(number) <= MAX_MAGNITUDE:
            self.fail(element, f"{shown}={shown_value(value)} is beyond ±{MAX_MAGNITUDE:g}: no railway "
                               "quantity is that large")
        if (minimum is not None and number < minimum) or (maximum is not None and number > maximum):
            bounds = f"from {minimum:g} to {maximum:g}" if minimum is not None and maximum is not None else (
                f"at least {minimum:g}" if minimum is not None else f"at most {maximum:g}")
            self.fail(element, f"{shown}={shown_value(value)}: must be {bounds}{what}")
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


def parse_document(path: Path) -> Document:
    """The railML 3 file at ``path``, parsed without entities or network; anything else refused in one line."""
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
    return Document(path, root, qname.namespace)


# ---- functional infrastructure read by the path and the block sections ------------------------------
def signal_kind(doc: Document, signal) -> Optional[str]:
    """'main', 'distant', … of a signalIS: its signalIL's function, else its isTrainMovementSignal's
    type (railML 3.2), else 'main' for a train movement signal; None for other signals (speed
    boards, mileposts)."""
    function = _signal_functions(doc).get(signal.get("id"))
    if function:
        return function
    movement = doc.find(signal, "isTrainMovementSignal")
    if movement is not None:
        return movement.get("type") or movement.get("function") or "main"
    if not any(local_name(child).startswith("is") and local_name(child).endswith("Signal")
               or local_name(child) in ("isMilepost", "isStopPost") for child in signal):
        return "main"          # no function given at all: taken as a main signal (docs/railml.md#defaults)
    return None


def _signal_functions(doc: Document) -> Dict[str, str]:
    cache = getattr(doc, "_signal_functions", None)
    if cache is None:
        cache = {}
        for assets in interlocking_assets(doc):
            for signal_il in doc.findall(assets, "signalsIL", "signalIL"):
                refers = doc.find(signal_il, "refersTo")
                if refers is not None and signal_il.get("function"):
                    cache[refers.get("ref")] = signal_il.get("function")
        doc._signal_functions = cache
    return cache


def interlocking_assets(doc: Document) -> list:
    """railML 3.1's interlocking/assetsForIL, or 3.2's interlocking/assetsForInterlockings/
    assetsForInterlocking (either is read from either version: files in the wild mix them)."""
    interlocking = doc.find(doc.root, "interlocking")
    return doc.findall(interlocking, "assetsForIL") + doc.findall(interlocking, "assetsForInterlockings",
                                                                     "assetsForInterlocking")


def station_elements(doc: Document) -> list:
    fi = doc.find(doc.root, "infrastructure", "functionalInfrastructure")
    stations = []
    for op in doc.findall(fi, "operationalPoints", "operationalPoint"):
        types = {o.get("operationalType") for o in doc.findall(op, "opOperations", "opOperation")}
        if not types or types & STATION_TYPES:
            stations.append(op)
    return stations
