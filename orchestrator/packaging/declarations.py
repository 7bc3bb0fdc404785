"""Each port declared once: what the facades declare (fmus/fmi/ports.py ``Port``), written out
where it is read without them — each unit's committed ``fmus/<unit>/contract.json`` and the port
tables of docs/interfaces.md.

Both are made from the modelDescription the facade writes in process, the one ``railcosim
build`` puts into its FMU (same class, default build sizes), so a manifest, a table and a built
FMU cannot say different things. The rest is derived at run time from the same declarations:
a facade's copy of its core's outputs (``FacadeSlave.output_fields``, each output's
``core_field``) and the fail-safe values a DCP master shows for a silent slave (each output's
``fail_safe``, annotated on its variable in the modelDescription and from there in the
``.dcpx`` that ``railcosim dcp-slave`` writes).

    python -m orchestrator.packaging.declarations            # rewrite the manifests and tables
    python -m orchestrator.packaging.declarations --check    # list what differs; exit 1 if any

tests/test_declarations.py runs the check, so a port changed in a facade and not here fails.
"""
from __future__ import annotations

import argparse
import importlib
import sys
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence
from xml.etree import ElementTree

from lxml import etree

from orchestrator.contracts import manifest_of_description, manifest_text
from orchestrator.errors import UserError
from orchestrator.fmu import fail_safe_of
from orchestrator.packaging.builder import FMUS_ROOT, UnitSpec, discover_units
from orchestrator.ports import element_name

#: the checkout this module lives in: the manifests under fmus/, the tables in docs/
CHECKOUT = FMUS_ROOT.parent
INTERFACES_PAGE = Path("docs") / "interfaces.md"
_BEGIN = ("<!-- ports of {model}: written from fmus/{unit}/facade.py by "
          "`python -m orchestrator.packaging.declarations`; change the facade, not this table -->")
_END = "<!-- end of the ports of {model} -->"


def model_description(spec: UnitSpec) -> etree._Element:
    """The modelDescription of a unit's facade at the default build sizes, as its FMU holds it."""
    facade = getattr(importlib.import_module(spec.facade_module), spec.model_identifier)
    written = facade(instance_name="declarations").to_xml()
    return etree.fromstring(ElementTree.tostring(written, encoding="utf-8"))


def _cell(value: Optional[str]) -> str:
    return "" if value is None else value.replace("|", "\\|")


def _range(port: Mapping) -> str:
    low, high = port["min"], port["max"]
    if low is not None and high is not None:
        return f"{low} … {high}"
    return f"≥ {low}" if low is not None else f"≤ {high}" if high is not None else ""


def _start(port: Mapping) -> str:
    start = port["start"]
    return '""' if start == "" and port["type"] == "String" else _cell(start)


def _fail_safe(value: Optional[float], fmi_type: str) -> str:
    if value is None:
        return ""
    if fmi_type == "Boolean":
        return "true" if value else "false"
    return f"{value:g}"


def port_table(manifest: Mapping, fail_safe: Mapping[str, float]) -> List[str]:
    """A unit's ports as a Markdown table, in declaration order: every field of its manifest,
    an array named with its shape (``u_tx[8,40]``), and where the unit declares any a fail-safe
    column."""
    with_fail_safe = bool(fail_safe)
    head = ["port", "causality", "type", "unit", "start", "range", *(["fail-safe"] if with_fail_safe else []),
            "description"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, port in manifest["ports"].items():
        cells = [element_name(name, port.get("shape") or ()), port["causality"], port["type"], _cell(port["unit"]),
                 _start(port), _range(port)]
        if with_fail_safe:
            cells.append(_fail_safe(fail_safe.get(name), port["type"]))
        cells.append(_cell(port["description"]))
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _with_table(page: str, spec: UnitSpec, table: Sequence[str]) -> str:
    """``page`` with the unit's generated table replaced (between its two marker lines)."""
    begin = _BEGIN.format(model=spec.model_identifier, unit=spec.unit)
    end = _END.format(model=spec.model_identifier)
    lines = page.split("\n")
    if lines.count(begin) != 1 or lines.count(end) != 1 or lines.index(begin) > lines.index(end):
        raise UserError(f"{INTERFACES_PAGE}: expected one pair of lines\n  {begin}\n  {end}\n"
                        f"around the port table of {spec.model_identifier}")
    first, last = lines.index(begin), lines.index(end)
    return "\n".join(lines[:first + 1] + ["", *table, ""] + lines[last:])


def generated(checkout: Path = CHECKOUT) -> Dict[Path, str]:
    """Every file the declarations are written to, by path relative to the checkout, with the
    text it must hold."""
    page_path = checkout / INTERFACES_PAGE
    if not page_path.is_file():
        raise UserError(f"{page_path}: not found (the declarations are written into a checkout of railcosim)")
    files: Dict[Path, str] = {}
    page = page_path.read_text(encoding="utf-8")
    for spec in discover_units():
        root = model_description(spec)
        manifest = manifest_of_description(root)      # its ports in declaration order
        files[Path("fmus") / spec.unit / "contract.json"] = manifest_text(manifest)
        page = _with_table(page, spec, port_table(manifest, fail_safe_of(root)))
    files[INTERFACES_PAGE] = page
    return files


def drifted(files: Mapping[Path, str], checkout: Path = CHECKOUT) -> List[Path]:
    """The files whose committed text is not the one the facades' declarations give."""
    return [path for path, text in files.items()
            if not (checkout / path).is_file() or (checkout / path).read_text(encoding="utf-8") != text]


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m orchestrator.packaging.declarations",
                                     description="Write each unit's contract.json and the port tables of "
                                                 "docs/interfaces.md from the facades' port declarations.")
    parser.add_argument("--check", action="store_true",
                        help="write nothing; list the files that differ and exit 1 if any does")
    args = parser.parse_args(argv)
    try:
        files = generated()
    except UserError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2
    changed = drifted(files)
    for path in changed:
        if args.check:
            print(f"{path}: differs from the facades' declarations")
        else:
            (CHECKOUT / path).write_text(files[path], encoding="utf-8")
            print(f"wrote {path}")
    return 1 if args.check and changed else 0


if __name__ == "__main__":
    sys.exit(main())
