"""A line-file document written as railML 3.2 (or 3.1) infrastructure (docs/railml.md#export):
one netElement of the line's length, every position a ``pos`` on it, and what railML has no
place for in our extension namespace (``rcs:``); ``import_railml(export_railml(line))`` gives
the line document back (tests/test_railml.py runs it for every shipped line). And the line
file a system's components read (:func:`system_line_file`), which ``railcosim export railml``
writes.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Dict, List

from lxml import etree

from orchestrator.errors import UserError
from orchestrator.railml.document import EXTENSION_NS, RAILML_NS, RC


def _text(value) -> str:
    """The railML literal of a line-file number (an int stays an int)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    return repr(float(value))


class _Builder:
    """Elements in one railML namespace; every location on the one netElement ``ne_line``."""

    def __init__(self, ns: str):
        self.ns = ns

    def el(self, parent, tag, attrib=None, **more):
        element = etree.SubElement(parent, "{%s}%s" % (self.ns, tag))
        for key, value in {**(attrib or {}), **more}.items():
            if value is not None:
                element.set(key, value if isinstance(value, str) else _text(value))
        return element

    def name(self, parent, text, description=None):
        self.el(parent, "name", name=text, language="und", description=description)

    def spot(self, parent, ident, position, direction="both"):
        self.el(parent, "spotLocation", id=ident, netElementRef="ne_line", applicationDirection=direction,
                pos=position)

    def stretch(self, parent, ident, start, end, direction="both"):
        location = self.el(parent, "linearLocation", id=ident, applicationDirection=direction)
        self.el(location, "associatedNetElement", netElementRef="ne_line", keepsOrientation="true",
                posBegin=start, posEnd=end)


def export_railml(document: dict, version: str = "3.2") -> bytes:
    """A line document as railML ``version`` infrastructure (module docstring). The bytes of the
    XML file."""
    ns = RAILML_NS[version]
    x = _Builder(ns)
    root = etree.Element("{%s}railML" % ns, nsmap={None: ns, "rcs": EXTENSION_NS}, version=version)
    limit_categories = ["passenger", "freight"] + (["high_speed"] if any("high_speed_kmh" in s
                                                                          for s in document["speed_limits"]) else [])
    categories = list(limit_categories)
    for restriction in document.get("temporary_restrictions", []):
        categories += [c for c in restriction.get("categories", []) if c not in categories]
    _common(x, root, document["electrification"], categories)
    infrastructure = x.el(root, "infrastructure", id="infrastructure")
    _topology(x, infrastructure, document["length_m"])
    _geometry(x, infrastructure, document)
    fi = x.el(infrastructure, "functionalInfrastructure")
    _line(x, fi, document)
    _stations(x, fi, document["stations"])
    sections = document["block_sections"]
    signalled = [(k, s) for k, s in enumerate(sections, 1) if s["signal"]]
    _signals(x, fi, signalled)
    _speeds(x, fi, document, limit_categories)
    detector_at = _train_detection(x, fi, document)
    _interlocking(x, root, version, sections, signalled, detector_at)
    return etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True)


def _common(x: _Builder, root, electrification: dict, categories: List[str]) -> None:
    """The traction supply and one speed profile per train category."""
    common = x.el(root, "common", id="common")
    if electrification["system"] != "none":
        systems = x.el(common, "electrificationSystems")
        x.el(systems, "electrificationSystem", id="es_line", voltage=electrification.get("nominal_voltage_v"),
             frequency=50 if electrification["system"] == "AC25000" else 0)
    profiles = x.el(common, "speedProfiles")
    for category in categories:
        profile = x.el(profiles, "speedProfile", id=f"sp_{category}")
        x.name(profile, category)
        if category in ("passenger", "freight"):
            x.el(profile, "trainType", type=category)


def _topology(x: _Builder, infrastructure, length) -> None:
    """One netElement of the line's length in a micro-level network."""
    topology = x.el(infrastructure, "topology")
    element = x.el(x.el(topology, "netElements"), "netElement", id="ne_line", length=length)
    positioning = x.el(element, "associatedPositioningSystem", id="ne_line_aps")
    x.el(positioning, "intrinsicCoordinate", id="ne_line_begin", intrinsicCoord=0)
    x.el(positioning, "intrinsicCoordinate", id="ne_line_end", intrinsicCoord=1)
    level = x.el(x.el(x.el(topology, "networks"), "network", id="network"), "level", id="network_micro",
                 descriptionLevel="Micro")
    x.el(level, "networkResource", ref="ne_line")


def _geometry(x: _Builder, infrastructure, document: dict) -> None:
    """The curves and the gradients, each over its stretch."""
    geometry = x.el(infrastructure, "geometry")
    if document["curves"]:
        horizontal = x.el(geometry, "horizontalCurves")
        for k, curve in enumerate(document["curves"], 1):
            entity = x.el(horizontal, "horizontalCurve", id=f"hc_{k}", curveType="arc", radius=curve["radius_m"])
            x.stretch(entity, f"hc_{k}_loc", curve["start_m"], curve["end_m"])
    gradients = x.el(geometry, "gradientCurves")
    for k, gradient in enumerate(document["gradients"]):
        end = document["gradients"][k + 1]["start_m"] if k + 1 < len(document["gradients"]) else document["length_m"]
        entity = x.el(gradients, "gradientCurve", id=f"gc_{k + 1}", curveType="straight",
                      gradient=gradient["permille"])
        x.stretch(entity, f"gc_{k + 1}_loc", gradient["start_m"], end)


def _line(x: _Builder, fi, document: dict) -> None:
    """The electrification over the whole line, and the railML line with what our extension
    says of it (its highest ballast, its diverging routes)."""
    length = document["length_m"]
    if document["electrification"]["system"] != "none":
        section = x.el(x.el(fi, "electrifications"), "electrificationSection", id="el_line",
                       contactLineType="overhead")
        x.stretch(section, "el_line_loc", 0, length)
        x.el(section, "electrificationSystemRef", ref="es_line")
    line = x.el(x.el(fi, "lines"), "line", id="line")
    x.name(line, document["name"], document.get("description"))
    x.stretch(line, "line_loc", 0, length)
    if "max_ballast_ohm_km" in document:
        line.set(RC + "maxBallastOhmKm", _text(document["max_ballast_ohm_km"]))
    if document.get("diverging_routes"):
        line.set(RC + "divergingRoutes", json.dumps(document["diverging_routes"], ensure_ascii=False))


def _stations(x: _Builder, fi, stations: List[dict]) -> None:
    """An operationalPoint at each station's stop, and a platform ending there where the line
    file gives its length."""
    points = x.el(fi, "operationalPoints")
    for k, station in enumerate(stations, 1):
        op = x.el(points, "operationalPoint", id=f"op_{k}")
        x.name(op, station["name"])
        x.spot(op, f"op_{k}_loc", station["stop_m"])
        x.el(x.el(op, "opOperations"), "opOperation", operationalType="station")
    if any("platform_length_m" in s for s in stations):
        platforms = x.el(fi, "platforms")
        for k, station in enumerate(stations, 1):
            if "platform_length_m" in station:
                platform = x.el(platforms, "platform", id=f"pl_{k}", belongsToParent=f"op_{k}")
                x.name(platform, station["name"])
                x.stretch(platform, f"pl_{k}_loc", max(station["stop_m"] - station["platform_length_m"], 0),
                          station["stop_m"])
                x.el(platform, "length", value=station["platform_length_m"], type="physical")


def _signals(x: _Builder, fi, signalled) -> None:
    """A train movement signal at the exit of every section that has one, facing the train."""
    if not signalled:
        return
    signals = x.el(fi, "signalsIS")
    for k, section in signalled:
        signal = x.el(signals, "signalIS", id=f"sig_{k}", isSwitchable="true")
        x.name(signal, section["signal"])
        x.spot(signal, f"sig_{k}_loc", section["end_m"], "normal")
        x.el(signal, "isTrainMovementSignal")


def _speeds(x: _Builder, fi, document: dict, limit_categories: List[str]) -> None:
    """The permanent limits, one speedSection per category and stretch, then the temporary
    restrictions."""
    speeds = x.el(fi, "speeds")
    limits = document["speed_limits"]
    for k, limit in enumerate(limits):
        end = limits[k + 1]["start_m"] if k + 1 < len(limits) else document["length_m"]
        for category in limit_categories:
            speed = limit.get(f"{category}_kmh", limit["passenger_kmh"])
            entity = x.el(speeds, "speedSection", id=f"ss_{k + 1}_{category}", maxSpeed=speed, isTemporary="false")
            x.stretch(entity, f"ss_{k + 1}_{category}_loc", limit["start_m"], end, "normal")
            x.el(entity, "validForSpeedProfile", ref=f"sp_{category}")
    for k, restriction in enumerate(document.get("temporary_restrictions", []), 1):
        entity = x.el(speeds, "speedSection", id=f"tsr_{k}", maxSpeed=restriction["speed_kmh"], isTemporary="true")
        if "name" in restriction:
            x.name(entity, restriction["name"])
        x.stretch(entity, f"tsr_{k}_loc", restriction["start_m"], restriction["end_m"], "normal")
        for category in restriction.get("categories", []):
            x.el(entity, "validForSpeedProfile", ref=f"sp_{category}")


def _train_detection(x: _Builder, fi, document: dict) -> Dict[float, str]:
    """The insulated joints, and a track-circuit border at every section end that has no joint
    (a jointless border); a border between two UM71 circuits is their tuned separation zone,
    which railML has no word for (our extension marks it). Position → the detector's id."""
    sections = document["block_sections"]
    zones = {float(z["position_m"]): z for z in document.get("separation_zones", [])}
    detection = x.el(fi, "trainDetectionElements")
    detector_at: Dict[float, str] = {}
    for k, joint in enumerate(document.get("insulated_joints", []), 1):
        entity = x.el(detection, "trainDetectionElement", id=f"tde_joint_{k}", type="insulatedRailJoint")
        x.spot(entity, f"tde_joint_{k}_loc", joint["position_m"])
        if "impedance_bond" in joint:
            entity.set(RC + "impedanceBond", _text(bool(joint["impedance_bond"])))
        if "bond_lead_offset_m" in joint:
            entity.set(RC + "bondLeadOffsetM", _text(joint["bond_lead_offset_m"]))
        detector_at.setdefault(float(joint["position_m"]), entity.get("id"))
    for k, position in enumerate(sorted({float(p) for s in sections for p in (s["start_m"], s["end_m"])}), 1):
        if position not in detector_at:
            entity = x.el(detection, "trainDetectionElement", id=f"tde_border_{k}", type="trackCircuit")
            value = next(p for s in sections for p in (s["start_m"], s["end_m"]) if float(p) == position)
            x.spot(entity, f"tde_border_{k}_loc", value)
            if position in zones:
                entity.set(RC + "separationZone", "true")
                if "length_m" in zones[position]:
                    entity.set(RC + "separationZoneLengthM", _text(zones[position]["length_m"]))
            detector_at[position] = entity.get("id")
    return detector_at


def _interlocking(x: _Builder, root, version: str, sections: List[dict], signalled, detector_at) -> None:
    """One TVD section per block section (its carrier, and our extension's transmitter and
    ballast), demarcated by the detectors at its ends, and a block signalIL for each signal."""
    interlocking = x.el(root, "interlocking")
    if version == "3.1":
        assets = x.el(interlocking, "assetsForIL", id="assets")
    else:
        assets = x.el(x.el(interlocking, "assetsForInterlockings"), "assetsForInterlocking", id="assets")
    tvds = x.el(assets, "tvdSections")
    for k, section in enumerate(sections, 1):
        tvd = x.el(tvds, "tvdSection", id=f"tvd_{k}", residualRouteCancellationDelay="PT0S",
                   partialRouteReleaseDelay="PT0S", technology="trackCircuit", frequency=section["carrier_hz"])
        x.el(tvd, "designator", register="_railcosim", entry=section["name"])
        tvd.set(RC + "transmitter", section["transmitter"])
        tvd.set(RC + "ballastOhmKm", _text(section["ballast_ohm_km"]))
        if section["signal"]:
            x.el(tvd, "hasExitSignal", ref=f"sig_{k}")
        for position in (section["start_m"], section["end_m"]):
            x.el(tvd, "hasDemarcatingTraindetector", ref=detector_at[float(position)])
    if signalled:
        signals_il = x.el(assets, "signalsIL")
        for k, _ in signalled:
            signal_il = x.el(signals_il, "signalIL", id=f"sig_{k}_il", isVirtual="false", function="block")
            x.el(signal_il, "refersTo", ref=f"sig_{k}")


def system_line_file(system_path) -> Path:
    """The line file the components of a system (folder or .ssp) read: the one every
    ``line_file`` parameter names, else the bundled default line."""
    from fmus.data.loader import DEFAULT_LINE
    from orchestrator.graph import resolve_data_file
    from orchestrator.ssp import open_system
    from orchestrator.verdicts.system_checks import FMU_RESOURCES_ROOT

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
