"""The values a study takes from each run's summary.json (docs/studies.md, "Collected keys").

A key is a dotted path into summary.json — ``trains.0.energy_kwh``, or with names instead of
list positions ``trains.train.stops.B.arrival_deviation_s`` (an element whose ``name`` or
``station`` is that word) — or one of the derived keys below, which add up what the run's
verdict is made of over every train and receiver, or ``final.COMP.VAR``: the last recorded
value of an output in the run's results.csv.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Dict, List, Optional


def _verdict(summary: dict):
    from orchestrator.verdicts.verdict import safety_parts

    return safety_parts(summary)[1].split(" (")[0]


def _total(group: str, key: str):
    return lambda summary: sum(int(item.get(key, 0) or 0) for item in summary.get(group, []))


def _missed(summary: dict) -> int:
    from orchestrator.verdicts.verdict import missed_stops

    return len(missed_stops(summary))


DERIVED = {
    "verdict": _verdict,                                        # safe, UNSAFE or not judged
    "signals_passed_at_danger": _total("trains", "signals_passed_at_danger"),
    "atp_interventions": _total("trains", "atp_interventions"),
    "wrong_side_failures": _total("receivers", "wrong_side_failures"),
    "unsafe_indications": _total("receivers", "unsafe_indications"),
    "missed_stops": _missed,
}


class _Missing(Exception):
    pass


def _step(node, part: str):
    if isinstance(node, dict):
        if part in node:
            return node[part]
        raise _Missing
    if isinstance(node, list):
        if part.lstrip("-").isdigit():
            index = int(part)
            if -len(node) <= index < len(node):
                return node[index]
            raise _Missing
        for item in node:
            if isinstance(item, dict) and part in (item.get("name"), item.get("station")):
                return item
    raise _Missing


def value_of(summary: dict, key: str, derived: bool = True):
    """The value ``key`` names in ``summary``; None when the summary has no such entry (a run
    that stopped early, a stop not reached)."""
    if derived and key in DERIVED and key not in summary:
        return DERIVED[key](summary)
    node = summary
    try:
        for part in key.split("."):
            node = _step(node, part)
    except _Missing:
        return None
    if isinstance(node, (dict, list)):
        return None
    return node


FINAL = "final."


def final_values(results_csv: Path) -> Dict[str, float]:
    """The last row of a results.csv, column → value (empty when the file has no row)."""
    import csv

    try:
        with open(results_csv, newline="") as f:
            header = next(csv.reader([f.readline()]), [])
            f.seek(0, os.SEEK_END)
            size = f.tell()
            f.seek(max(0, size - 65536))            # the last row is far shorter than this
            tail = f.read().splitlines()
    except OSError:
        return {}
    last = next(csv.reader([tail[-1]]), []) if tail else []
    if len(last) != len(header) or last == header:
        return {}
    values = {}
    for name, text in zip(header, last):
        try:
            values[name] = float(text)
        except ValueError:
            values[name] = text
    return values


def collect(summary: dict, keys: List[str], derived: bool = True,
            results_csv: Optional[Path] = None) -> Dict[str, object]:
    finals = final_values(results_csv) if results_csv is not None and any(k.startswith(FINAL) for k in keys) else {}
    return {key: finals.get(key[len(FINAL):]) if key.startswith(FINAL) else value_of(summary, key, derived)
            for key in keys}
