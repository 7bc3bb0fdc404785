"""The values a study takes from each run's summary.json (docs/studies.md, "Collected keys").

A key is a dotted path into summary.json — ``trains.0.energy_kwh``, or with names instead of
list positions ``trains.train.stops.B.arrival_deviation_s`` (an element whose ``name`` or
``station`` is that word) — or one of the derived keys below, which add up what the run's
verdict is made of over every train and receiver.
"""
from __future__ import annotations

from typing import Dict, List


def _verdict(summary: dict):
    from orchestrator.analysis.verdict import safety_parts

    return safety_parts(summary)[1].split(" (")[0]


def _total(group: str, key: str):
    return lambda summary: sum(int(item.get(key, 0) or 0) for item in summary.get(group, []))


def _missed(summary: dict) -> int:
    from orchestrator.analysis.verdict import missed_stops

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


def collect(summary: dict, keys: List[str], derived: bool = True) -> Dict[str, object]:
    return {key: value_of(summary, key, derived) for key in keys}
