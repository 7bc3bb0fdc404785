"""Where a run came from: the railcosim version, the system's content hash and the date, written
into every run's metadata.json and shown by ``railcosim --version`` and ``report.html``."""
from __future__ import annotations

import hashlib
import subprocess
from datetime import datetime, timezone
from importlib import metadata as package_metadata
from pathlib import Path
from typing import Dict, List, Mapping, Optional

#: the checkout railcosim runs from, when it runs from one (an editable install)
CHECKOUT = Path(__file__).resolve().parents[1]


def railcosim_version() -> str:
    """The installed distribution's version (pyproject.toml's ``version``)."""
    try:
        return package_metadata.version("railcosim")
    except package_metadata.PackageNotFoundError:     # run from a checkout that was never installed
        return "unknown (not installed)"


def system_files(folder: Path) -> List[Path]:
    """A system folder's files, sorted, bytecode caches left out: what it is made of (its hash
    here, what the packer puts in its .ssp: orchestrator/packaging/packing.py)."""
    return [p for p in sorted(Path(folder).rglob("*")) if p.is_file() and "__pycache__" not in p.parts]


def file_digest(path: Path) -> bytes:
    """SHA-256 of a file's bytes, read a megabyte at a time."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.digest()


def content_hash(path: Path) -> str:
    """SHA-256 (hex) of a file, or of a folder's files (their relative names and digests, in
    :func:`system_files` order), so that a system folder and the .ssp packed from it are each
    told apart from an edited copy."""
    path = Path(path)
    if path.is_file():
        return file_digest(path).hex()
    digest = hashlib.sha256()
    for file in system_files(path):
        digest.update(file.relative_to(path).as_posix().encode() + b"\0" + file_digest(file))
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
