"""Contract manifests: the committed manifest of an FMU (orchestrator/contracts.py), and the diff
of its ports against a built one.

Arrays are collapsed (``u_tx`` with shape [8, 40]) so a manifest stays readable; every field
a user's model relies on is compared: causality, variability, type, unit, min, max, start,
description. ``railcosim contract check`` classifies the differences (orchestrator/contracts.py).
"""
from __future__ import annotations

from pathlib import Path
from typing import Dict, List, Tuple

import fmus
from orchestrator.errors import UserError, did_you_mean
from orchestrator.ports import manifest_of, read_manifest  # noqa: F401 (the contract API)

#: the roles whose reference manifests ship in the package (fmus/<role>/contract.json)
ROLES = ("wayside_coder", "rail_line", "loco_receiver", "traction", "ato_controller")


def role_manifest_path(role: str) -> Path:
    return Path(fmus.__file__).resolve().parent / role / "contract.json"


def resolve_manifest(name: str) -> Tuple[Path, str]:
    """(file, name to show) of ``--manifest``: a manifest file, or a role meaning its shipped one."""
    path = Path(name)
    if path.is_file():
        return path, str(path)
    if name in ROLES:
        return role_manifest_path(name), name
    if path.suffix == ".json" or "/" in name or path.exists():
        raise UserError(f"--manifest {name}: no such file")
    raise UserError(f"--manifest {name}: neither a manifest file nor a role{did_you_mean(name, ROLES)} "
                    f"(roles: {', '.join(ROLES)})")


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
