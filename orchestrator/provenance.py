"""Where a run came from: the railcosim version, the system's content hash and the date, written
into every run's metadata.json and shown by ``railcosim --version`` and ``report.html``."""
from __future__ import annotations

import hashlib
import subprocess
from datetime import datetime, timezone
from importlib import metadata as package_metadata
from pathlib import Path
from typing import Dict, Mapping, Optional

#: the checkout railcosim runs from, when it runs from one (an editable install)
CHECKOUT = Path(__file__).resolve().parents[1]


def railcosim_version() -> str:
    """The installed distribution's version (pyproject.toml's ``version``)."""
    try:
        return package_metadata.version("railcosim")
    except package_metadata.PackageNotFoundError:     # run from a checkout that was never installed
        return "unknown (not installed)"


def content_hash(path: Path) -> str:
    """SHA-256 of a file, or of a folder's files (their relative names and bytes, sorted), so
    that a system folder and the .ssp packed from it are each told apart from an edited copy."""
    digest = hashlib.sha256()
    path = Path(path)
    files = [path] if path.is_file() else sorted(p for p in path.rglob("*") if p.is_file())
    for file in files:
        if path.is_dir():
            digest.update(file.relative_to(path).as_posix().encode() + b"\0")
        digest.update(file.read_bytes())
        digest.update(b"\0")
    return digest.hexdigest()


def utc_now_iso() -> str:
    """The present instant, UTC, to the second (ISO 8601)."""
    return datetime.now(timezone.utc).replace(microsecond=0).isoformat()


def source_revision() -> Optional[str]:
    """The git commit railcosim runs from (``describe --always --dirty``: ``-dirty`` when the
    checkout has changes), None when it is not run from a git checkout: an editable install
    keeps one version number through every commit."""
    if not (CHECKOUT / ".git").exists():
        return None
    try:
        done = subprocess.run(["git", "-C", str(CHECKOUT), "describe", "--always", "--dirty", "--abbrev=12"],
                              capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() or None if done.returncode == 0 else None


def data_file_hashes(components: Mapping[str, Mapping[str, object]]) -> Dict[str, str]:
    """SHA-256 of every data file a component's ``*_file`` parameter names (resolved paths, as
    metadata.json records them): the line, timetable, rolling stock and code tables that a
    system's folder does not hold. A bundled default (no parameter set) is railcosim's own:
    its version and source revision say which."""
    found = {}
    for parameters in components.values():
        for name, value in parameters.items():
            if name.endswith("_file") and value and str(value) not in found:
                path = Path(str(value))
                if path.is_file():
                    found[str(value)] = content_hash(path)
    return dict(sorted(found.items()))
