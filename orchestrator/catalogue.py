"""What ships with railcosim, for `railcosim list`: the systems (run by name), the studies (run
by name) and the roles an FMU can be checked against (`contract check --manifest ROLE`,
`conform --role ROLE`), each with one line saying what it is (docs/scenarios.md,
docs/studies.md, docs/contracts.md have the details).

Read-only: nothing is written, built or run, so listing is instant in a checkout and in an
installed package alike.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Dict, List, Sequence

import fmus
from orchestrator.conformance import ROLES
from orchestrator.conformance.vectors import DATA_DIR

#: one line per shipped system (orchestrator/systems/shipped.py writes them; docs/scenarios.md
#: describes each and its verdict)
SYSTEM_DESCRIPTIONS: Dict[str, str] = {
    "free_run": "one passenger train on the default 20 km line A-B-C (DC 3 kV, ALSN 50 Hz), "
                "its ATO driving to the default timetable",
    "ato_only": "the free run's train and ATO without the signal chain: the fast system for "
                "timetable and energy studies",
    "following": "two trains on one line: the follower stops before a red signal behind the "
                 "halted leader and goes on when the line clears",
    "als_en_following": "following with ALS-EN digital cab signalling",
    "fire_dqpsk_following": "following with FIRE_DQPSK digital cab signalling",
    "faults": "the free run with an open feed, failed code transmitters and a broken rail, each "
              "injected and repaired by its scenario",
    "joints_at_speed": "160 km/h through a station throat: three short track circuits inside one "
                       "block (joints without signals)",
    "freight_ac": "a heavy freight train (5152 t, 944 m) on an AC 25 kV line, ALSN 25 Hz",
    "same_block": "a follower starting in the track circuit where the leader stands: no code, "
                  "held at departure until the circuit clears",
    "als_en": "the free run with ALS-EN digital cab signalling",
    "fire_dqpsk": "the free run with FIRE_DQPSK digital cab signalling",
    "alsu": "the free run with ALSU (two of six tones) on a 4-aspect block, a diverging route into B "
            "and a permanent restriction",
    "alsu_following": "following with ALSU cab signalling",
    "tvm430": "a TGV set at 300 km/h on a 42 km high-speed line with TVM-430 (27-bit words on "
              "1700 / 2300 Hz track circuits), stopping at the end",
    "tvm430_following": "two TGV sets 3 min apart under TVM-430: the follower closes in on the halted "
                        "leader under the steps 300-270-230-170-0",
    "tvm300": "a TGV set at 300 km/h on a 42 km Atlantique-like line with TVM-300 (one of 18 sub-frequencies on "
              "1700 / 2300 Hz track circuits of 2000 m), stopping at the end",
    "tvm300_following": "two TGV sets 4 min apart under TVM-300: the follower steps down the cascade "
                        "300-270-220-160-80-0 behind the halted leader",
    "suburban": "one ЭР2 EMU stopping at all 13 stations of the 36 km suburban line (DC 3 kV, 4-aspect "
                "ALSN block of 31 sections)",
    "suburban_peak": "ten ЭР2 EMUs on the suburban line at its blocking-time headway plus 10 %, the "
                     "followers drawing up from holding tracks (docs/capacity.md)",
    "tvm430_headway": "five TGV sets on the high-speed line at TVM-430's co-simulated headway (docs/capacity.md)",
}

#: one line per role (the unit an FMU in that role replaces)
ROLE_DESCRIPTIONS: Dict[str, str] = {
    "wayside_coder": "automatic-block aspects and the cab code each section's transmitter sends",
    "rail_line": "track circuits with trains: code currents, coil EMF at each train, track relays",
    "loco_receiver": "the coil EMF decoded into the cab aspect",
    "traction": "the train's longitudinal dynamics: position, speed, energy",
    "ato_controller": "ATP supervision and automatic driving to the timetable",
}


def _study_entry(name: str, path: Path) -> dict:
    """A shipped study's name, description and number of runs (read through the study loader,
    so the count is the one `railcosim study NAME` runs)."""
    from orchestrator.study.spec import load_study

    spec = load_study(path)
    return {"name": name, "description": str(spec.data.get("description", "")),
            "runs": len(spec.runs), "file": str(path)}


def _role_entry(role: str) -> dict:
    manifest = json.loads((Path(fmus.__file__).resolve().parent / role / "contract.json").read_text(encoding="utf-8"))
    vectors = json.loads((DATA_DIR / f"{role}.json").read_text(encoding="utf-8"))["vectors"]
    return {"name": role, "description": ROLE_DESCRIPTIONS.get(role, ""),
            "fmu": f"{manifest['model_identifier']}.fmu", "vectors": len(vectors)}


def catalogue(system_names: Sequence[str], default_system: str) -> dict:
    """Systems (the names given; the shipped ones in the order of docs/scenarios.md), shipped
    studies and roles, as plain data."""
    from orchestrator.study import shipped_studies

    known = list(SYSTEM_DESCRIPTIONS)
    ordered = sorted(system_names, key=lambda name: (known.index(name) if name in known else len(known), name))
    systems = [{"name": name, "description": SYSTEM_DESCRIPTIONS.get(name, ""), "default": name == default_system}
               for name in ordered]
    studies = [_study_entry(name, path) for name, path in shipped_studies().items()]
    roles = [_role_entry(role) for role in sorted(ROLES, key=list(ROLE_DESCRIPTIONS).index)]
    return {"systems": systems, "studies": studies, "roles": roles}


def _rows(entries: List[dict], name_of, detail_of) -> List[str]:
    names = [name_of(e) for e in entries]
    width = max(map(len, names), default=0)
    return [f"  {name:<{width}}  {detail_of(e)}" for name, e in zip(names, entries)]


def format_text(listing: dict) -> str:
    """The listing as plain text: per kind present, a heading saying how a name is used, then
    one row per name."""
    blocks = []
    if "systems" in listing:
        blocks.append(["systems (railcosim run NAME; docs/scenarios.md):"] + _rows(
            listing["systems"], lambda s: s["name"] + (" (default)" if s["default"] else ""), lambda s: s["description"]))
    if "studies" in listing:
        blocks.append(["studies (railcosim study NAME; docs/studies.md):"] + _rows(
            listing["studies"], lambda s: s["name"], lambda s: f"{s['description']} ({s['runs']} runs)"))
    if "roles" in listing:
        blocks.append(["roles (railcosim contract check FMU --manifest ROLE, railcosim conform --role ROLE; "
                       "docs/contracts.md):"] + _rows(
            listing["roles"], lambda r: r["name"],
            lambda r: f"{r['fmu']}: {r['description']} ({r['vectors']} conformance vectors)"))
    return "\n\n".join("\n".join(block) for block in blocks)
