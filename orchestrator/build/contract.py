"""Contract manifests: the committed port list of an FMU, and the diff against a built one.

Arrays are collapsed (``u_tx`` with shape [8, 40]) so a manifest stays readable; every field
a user's model relies on is compared: causality, variability, type, unit, min, max, start.
"""
from __future__ import annotations

import json
import re
import zipfile
from pathlib import Path
from typing import Dict, List

from lxml import etree

_INDEX = re.compile(r"^(?P<base>[^\[]+)(\[(?P<index>[0-9,]+)\])?$")


def manifest_of(fmu_path: Path) -> Dict[str, dict]:
    with zipfile.ZipFile(fmu_path) as archive:
        root = etree.fromstring(archive.read("modelDescription.xml"))
    ports: Dict[str, dict] = {}
    for sv in root.find("ModelVariables"):
        typed = sv[0]
        match = _INDEX.match(sv.get("name"))
        base = match.group("base")
        entry = {"causality": sv.get("causality", "local"), "variability": sv.get("variability", "continuous"),
                 "type": etree.QName(typed).localname, "unit": typed.get("unit"),
                 "min": typed.get("min"), "max": typed.get("max"), "start": typed.get("start")}
        index = match.group("index")
        if index:
            shape = [int(i) for i in index.split(",")]
            previous = ports.get(base)
            if previous is not None:
                entry["shape"] = [max(a, b) for a, b in zip(previous["shape"], shape)]
                if entry["start"] != previous.get("start"):
                    entry["start"] = previous["start"] if previous["start"] == "varies" else "varies"
            else:
                entry["shape"] = shape
        ports[base] = entry
    return ports


def diff(manifest: Dict[str, dict], built: Dict[str, dict]) -> List[str]:
    problems = []
    for name in sorted(set(manifest) | set(built)):
        if name not in built:
            problems.append(f"{name}: in the manifest, missing from the FMU")
        elif name not in manifest:
            problems.append(f"{name}: in the FMU, not in the manifest")
        else:
            for key in sorted(set(manifest[name]) | set(built[name])):
                if manifest[name].get(key) != built[name].get(key):
                    problems.append(f"{name}.{key}: manifest {manifest[name].get(key)!r}, "
                                    f"FMU {built[name].get(key)!r}")
    return problems


def write_manifest(fmu_path: Path, manifest_path: Path) -> None:
    Path(manifest_path).write_text(json.dumps(manifest_of(Path(fmu_path)), indent=1, sort_keys=True) + "\n")


def read_manifest(path: Path) -> Dict[str, dict]:
    return json.loads(Path(path).read_text())
