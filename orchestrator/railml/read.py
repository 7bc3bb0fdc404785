"""railML 3.1 / 3.2 infrastructure read into a line-file document (docs/railml.md):
:func:`import_railml` takes the running path through the topology (topology.py), in running
order with its length, and along it the block sections with their signals and joints
(blocks.py), stations, gradients, curves, speed limits, temporary restrictions and the
electrification. What it does not read, and every default it assumed, is listed in
:attr:`RailmlImport.notes` (the CLI prints them as one warning block); an optional sidecar
(docs/railml.md#the-sidecar) says what the file does not.

Bad input is a :class:`~orchestrator.errors.UserError` of one line naming the file and the
railML element's ``id``.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Dict, List, Optional

from lxml import etree

from fmus.data.loader import MAX_JSON_DEPTH, json_nesting_depth, read_json_file
from fmus.errors import FmuInputError
from orchestrator.errors import UserError
from orchestrator.railml.blocks import block_sections, block_signals, detectors
from orchestrator.railml.document import (DEFAULTS, EXTENSION_NS, RC, SCHEMA_DIR, SIDECAR_SCHEMA, VERSION_OF_NS,
                                          Document, interlocking_assets, local_name, parse_document, station_elements)
from orchestrator.railml.topology import (Locator, RunningPath, choose_path, clean_position, macro_members,
                                          net_elements)


@dataclass
class RailmlImport:
    """A line document, where it came from, and what was ignored or assumed."""
    document: dict
    version: str
    path_ids: List[str]
    notes: List[str] = field(default_factory=list)



def import_railml(path, line_id: Optional[str] = None, sidecar=None) -> RailmlImport:
    """Read railML 3.1 or 3.2 infrastructure into a line document (module docstring)."""
    doc = parse_document(Path(path))
    notes: List[str] = []
    version = VERSION_OF_NS[doc.ns]
    stated_version = doc.root.get("version")
    if stated_version and stated_version != version:
        notes.append(f"<railML version={stated_version!r}> in the railML {version} namespace: read as {version}")
    extras = load_sidecar(sidecar)
    if extras.get("line_id") and line_id is None:
        line_id = extras["line_id"]
    elements = net_elements(doc, notes)
    path_ = choose_path(doc, elements, line_id, extras.get("via", []), notes)
    macro = macro_members(doc)
    locate = Locator(doc, path_, elements, macro)
    fi = doc.find(doc.root, "infrastructure", "functionalInfrastructure")
    line_element = _line_element(doc, fi, line_id, path_, macro)
    document = _line_header(doc, version, line_element, path_, extras)
    document["electrification"] = _electrification(doc, fi, locate, extras, notes)
    found, joints = detectors(doc, fi, locate, extras, notes)
    signals = block_signals(doc, fi, locate, notes)
    section_ids: List[str] = []
    document["block_sections"] = block_sections(doc, locate, found, signals, document["electrification"]["system"],
                                                extras, notes, section_ids)
    _refuse_unused_keys(sidecar, extras, section_ids, found, path_)
    if joints:           # none and an empty list are the same to the loader; a TVM line lists none
        document["insulated_joints"] = joints
    zones = [d.zone for d in found if d.zone is not None]
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


def _refuse_unused_keys(sidecar, extras: dict, section_ids: List[str], found, path_: RunningPath) -> None:
    """Every id the sidecar's ``sections``, ``joints`` and ``zones`` name is one the import uses:
    a block section of the running path, an insulated joint on it, a train detection element on
    it. A key for an element off the path (another track, a typing error) would be ignored in
    silence; it is refused in one line naming it and the sidecar."""
    on_path = {
        "sections": (set(section_ids), "block section"),           # a tvdSection's id, or S1, S2, …
        "joints": ({d.id for d in found if d.kind == "insulatedRailJoint"}, "insulated joint"),
        "zones": ({d.id for d in found if d.id}, "trainDetectionElement"),
    }
    unused = [(group, key) for group, (ids, _) in on_path.items() for key in extras.get(group, {}) if key not in ids]
    if unused:
        group, key = unused[0]
        more = f" (and {len(unused) - 1} more: {', '.join(f'{g}.{k}' for g, k in unused[1:])})" if len(unused) > 1 else ""
        raise UserError(f"--sidecar: {sidecar}: {group}.{key}: no {on_path[group][1]} {key!r} on the running path "
                        f"({', '.join(s.id for s in path_.steps)}){more}; the import would not use it: remove it, "
                        "or choose the path with line_id or via")


def _line_element(doc: Document, fi, line_id: Optional[str], path_: RunningPath, macro):
    """The railML line imported: the one named, else the first whose netElements hold the path
    (None: the file has no such line)."""
    if line_id is not None:
        return doc.by_id.get(line_id)
    on_path = set(path_.by_id)
    return next((line for line in doc.findall(fi, "lines", "line") if on_path <= {
        m for location in doc.findall(line, "linearLocation") for a in doc.findall(location, "associatedNetElement")
        for m in macro.get(a.get("netElementRef"), [a.get("netElementRef")])}), None)


def _line_header(doc: Document, version: str, line_element, path_: RunningPath, extras) -> dict:
    """The line document's first fields: name, description, length, and what our extension
    (or the sidecar) says of the whole line: its highest ballast, its diverging routes."""
    ours = EXTENSION_NS in {ns for element in doc.root.iter() if isinstance(element.tag, str)
                            for ns in element.nsmap.values()}
    name = extras.get("name") or (doc.name_of(line_element) if line_element is not None else None) \
        or _metadata(doc, "title") or doc.path.stem
    document = {"name": name}
    description = extras.get("description")
    if description is None and line_element is not None:
        first_name = doc.find(line_element, "name")
        description = first_name.get("description") if first_name is not None else None
    if description is None and not ours:
        description = (f"imported from railML {version} ({doc.path.name}); path "
                       + " → ".join(s.id for s in path_.steps))
    if description is not None:
        document["description"] = description
    document["length_m"] = clean_position(path_.length)
    if line_element is not None and line_element.get(RC + "maxBallastOhmKm") is not None:
        document["max_ballast_ohm_km"] = doc.float_attr(line_element, RC + "maxBallastOhmKm")
    if "max_ballast_ohm_km" in extras:
        document["max_ballast_ohm_km"] = extras["max_ballast_ohm_km"]
    if line_element is not None and line_element.get(RC + "divergingRoutes") is not None:
        document["diverging_routes"] = _diverging_routes(doc, line_element)
    return document


def _diverging_routes(doc: Document, line_element) -> list:
    """Our extension's diverging routes of a line, a JSON list (the line loader checks the
    routes themselves: signal, frog)."""
    routes = line_element.get(RC + "divergingRoutes")
    if json_nesting_depth(routes) > MAX_JSON_DEPTH:       # json.loads would recurse past Python's limit
        doc.fail(line_element, f"rcs:divergingRoutes nested more than {MAX_JSON_DEPTH} deep: not a JSON list "
                               "of routes")
    try:
        return json.loads(routes)
    except json.JSONDecodeError:
        raise UserError(f"{doc.path}: line {line_element.get('id')}: rcs:divergingRoutes is not a JSON list") from None


def _metadata(doc: Document, field_name: str) -> Optional[str]:
    metadata = doc.find(doc.root, "metadata")
    if metadata is None:
        return None
    element = metadata.find("{http://purl.org/dc/elements/1.1/}" + field_name)
    return element.text.strip() if element is not None and element.text and element.text.strip() else None


def _electrification(doc: Document, fi, locate: Locator, extras, notes) -> dict:
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



def _stations(doc: Document, fi, locate: Locator, path_: RunningPath, notes) -> List[dict]:
    stations, taken = [], set()
    platforms_of: Dict[str, object] = {}
    for platform in doc.findall(fi, "platforms", "platform"):
        if platform.get("belongsToParent"):
            platforms_of.setdefault(platform.get("belongsToParent"), platform)
    for op in station_elements(doc):
        spots = locate.spots(op)
        if not spots:
            for start, end, _, _ in locate.intervals(op):
                spots = [((start + end) / 2, None)]
        if not spots:
            continue
        entry = {"name": doc.name_of(op) or op.get("id"), "stop_m": clean_position(spots[0][0])}
        platform = platforms_of.get(op.get("id"))
        if platform is not None:
            taken.add(platform.get("id"))
            length = doc.find(platform, "length")
            if length is not None and doc.float_attr(length, "value") is not None:
                entry["platform_length_m"] = doc.float_attr(length, "value")
        stations.append(entry)
    station_ids = {op.get("id") for op in station_elements(doc)}
    for platform in doc.findall(fi, "platforms", "platform"):
        if platform.get("id") in taken or platform.get("belongsToParent") in station_ids:
            continue
        stretches = [s for s in locate.intervals(platform) if s[2]]
        if not stretches:
            continue
        start, end = min(s[0] for s in stretches), max(s[1] for s in stretches)
        entry = {"name": doc.name_of(platform) or platform.get("id"), "stop_m": clean_position(end),
                 "platform_length_m": clean_position(end - start)}
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


def _gradients(doc: Document, locate: Locator, notes) -> List[dict]:
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
        start, end = clean_position(start), clean_position(end)
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


def _curves(doc: Document, locate: Locator, notes) -> List[dict]:
    curves, skipped = [], 0
    for curve in doc.findall(doc.root, "infrastructure", "geometry", "horizontalCurves", "horizontalCurve"):
        radius = doc.float_attr(curve, "radius")
        if curve.get("curveType") == "straight":
            continue
        if curve.get("curveType") != "arc" or not radius or abs(radius) < 100:
            skipped += 1
            continue
        for start, end, _, _ in locate.intervals(curve):
            curves.append({"start_m": clean_position(start), "end_m": clean_position(end), "radius_m": abs(radius)})
    if skipped:
        notes.append(f"{skipped} horizontal curve(s) that are no arc of radius ≥ 100 m (transitions, tight "
                     "yard curves) ignored")
    return sorted(curves, key=lambda c: c["start_m"])


def _profiles(doc: Document) -> Dict[str, Optional[str]]:
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



def _speeds(doc: Document, fi, locate: Locator, line_element, extras, notes):
    """The permanent speed limits per train category over the whole path, and the temporary
    restrictions; where no speedSection says, the sidecar's default speed, else the line's
    maxSpeed, else the built-in default."""
    defaults = extras.get("defaults", {})
    line_speed = None
    if line_element is not None:
        performance = doc.find(line_element, "linePerformance")
        line_speed = doc.float_attr(performance, "maxSpeed") if performance is not None else None
    default_speed = defaults.get("speed_kmh") or line_speed
    permanent, restrictions = _speed_sections(doc, fi, locate, notes)
    if default_speed is None:
        default_speed = DEFAULTS["speed_kmh"]
    entries, uncovered = _speed_limits(permanent, default_speed, defaults, locate.path.length)
    if uncovered > 1.0:
        source = "the sidecar's default speed" if defaults.get("speed_kmh") else (
            "the line's linePerformance maxSpeed" if line_speed else "the default speed")
        notes.append(f"no speedSection over {uncovered:g} m of the path: {source} ({default_speed:g} km/h) there")
    return entries, sorted(restrictions, key=lambda r: r["start_m"])


def _speed_sections(doc: Document, fi, locate: Locator, notes):
    """The speedSections on the path facing the train: permanent ones as (start, end, speed,
    categories), temporary ones as the line file's restrictions."""
    profiles = _profiles(doc)
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
                entry.update({"start_m": clean_position(start), "end_m": clean_position(end), "speed_kmh": speed})
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
    return permanent, restrictions


def _speed_limits(permanent, default_speed: float, defaults: dict, length: float):
    """The line file's speed limits from the permanent speed sections: one entry wherever a
    category's lowest applying speed changes, the default where none applies; and the length
    without any passenger speed section (m)."""
    categories = ["passenger", "freight"] + (["high_speed"] if any("high_speed" in c for *_, c in permanent) else [])
    points = sorted({0, *(clean_position(p[0]) for p in permanent), *(clean_position(p[1]) for p in permanent)})
    points = [p for p in points if p < length - 1e-6]
    entries, uncovered = [], 0.0
    for k, start in enumerate(points):
        end = points[k + 1] if k + 1 < len(points) else length
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
    return entries, uncovered


#: functionalInfrastructure containers the import reads (others are listed as not read)
_READ = {"trainDetectionElements", "signalsIS", "speeds", "operationalPoints", "platforms", "electrifications",
         "lines", "tracks", "bufferStops"}


def _ignored(doc: Document, fi) -> List[str]:
    notes = []
    skipped = sorted({local_name(child) for child in (fi if fi is not None else []) if local_name(child) and
                      etree.QName(child).namespace == doc.ns and local_name(child) not in _READ})
    if skipped:
        notes.append("not read (no place in a railcosim line): functionalInfrastructure " + ", ".join(skipped))
    interlocking = doc.find(doc.root, "interlocking")
    if interlocking is not None:
        other = sorted({local_name(child) for assets in interlocking_assets(doc) for child in assets
                        if local_name(child) not in ("tvdSections", "signalsIL", "designator")}
                       | {local_name(child) for child in interlocking
                          if local_name(child) not in ("assetsForIL", "assetsForInterlockings")})
        if other:
            notes.append("not read from the interlocking (railcosim's block logic is the automatic block, "
                         "docs/wayside_coder.md): " + ", ".join(other))
    for tag in ("rollingstock", "timetable"):
        if doc.find(doc.root, tag) is not None:
            notes.append(f"railML {tag} not read (give --rolling-stock / --timetable files)")
    return notes


def load_sidecar(sidecar) -> dict:
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
