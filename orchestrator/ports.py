"""An FMU's ports as a manifest: name → causality, variability, type, unit, min, max, start,
description and, for an array, its shape (``u_tx`` with shape [8, 40]), read from its
modelDescription.xml.

The ports of the contract manifests (``fmus/<unit>/contract.json``, orchestrator/contracts.py)
and the connectors written into SSDs (orchestrator/sspgen.py) are both this form.
"""
from __future__ import annotations

import itertools
import json
import re
import zipfile
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Tuple

from lxml import etree

#: an FMI 2.0 structured name: a base and, for an array element, its indices from 1
#: (``u_tx[2,7]``; spaces around an index are read too)
_ELEMENT = re.compile(r"^(?P<base>[^\[]+)(?:\[(?P<index>\s*[0-9]+\s*(?:,\s*[0-9]+\s*)*)\])?$")


def split_element(name: str) -> Optional[Tuple[str, Tuple[int, ...]]]:
    """``u_tx[2,7]`` → ("u_tx", (2, 7)); ``x`` → ("x", ()); None for a name of neither form.
    The one reader of element names: every module that needs a port's base or indices asks it."""
    match = _ELEMENT.match(name)
    if not match:
        return None
    index = match.group("index")
    return match.group("base"), tuple(int(i) for i in index.split(",")) if index else ()


def base_of(name: str) -> str:
    """The port an element belongs to (``rolling_stock_file[2]`` → ``rolling_stock_file``); a
    name of no element form is its own."""
    parsed = split_element(name)
    return parsed[0] if parsed else name


def element_name(base: str, index: Sequence[int]) -> str:
    """("u_tx", (2, 7)) → ``u_tx[2,7]``; ("x", ()) → ``x``."""
    return f"{base}[{','.join(str(i) for i in index)}]" if len(index) else base


def element_names(base: str, shape: Sequence[int]) -> List[str]:
    """Every element of a port of ``shape``, row-major, indices from 1 (``()``: the port itself)."""
    if not len(shape):
        return [base]
    return [element_name(base, index) for index in itertools.product(*(range(1, n + 1) for n in shape))]


def manifest_of(fmu_path: Path) -> Dict[str, dict]:
    """The ports of the FMU at ``fmu_path``."""
    with zipfile.ZipFile(fmu_path) as archive:
        return ports_of_description(etree.fromstring(archive.read("modelDescription.xml")))


def ports_of_description(root: etree._Element) -> Dict[str, dict]:
    """The ports of a modelDescription (its root element)."""
    ports: Dict[str, dict] = {}
    for sv in root.find("ModelVariables"):
        typed = sv[0]
        base, index = split_element(sv.get("name")) or (sv.get("name"), ())
        entry = {"causality": sv.get("causality", "local"), "variability": sv.get("variability", "continuous"),
                 "type": etree.QName(typed).localname, "unit": typed.get("unit"),
                 "min": typed.get("min"), "max": typed.get("max"), "start": typed.get("start"),
                 "description": sv.get("description")}
        if index:
            shape = list(index)
            previous = ports.get(base)
            if previous is not None:
                entry["shape"] = [max(a, b) for a, b in zip(previous["shape"], shape)]
                if entry["start"] != previous.get("start"):
                    entry["start"] = previous["start"] if previous["start"] == "varies" else "varies"
            else:
                entry["shape"] = shape
        ports[base] = entry
    return ports


def read_manifest(path: Path) -> Dict[str, dict]:
    """The ports of a contract manifest (its ``ports``; a file of ports alone is read as such)."""
    manifest = json.loads(Path(path).read_text())
    return manifest["ports"] if isinstance(manifest.get("ports"), dict) else manifest
