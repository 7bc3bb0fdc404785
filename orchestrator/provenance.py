"""Where a run came from: the railcosim version, the system's content hash and the date, written
into every run's metadata.json and shown by ``railcosim --version`` and ``report.html``."""
from __future__ import annotations

import hashlib
from datetime import datetime, timezone
from importlib import metadata as package_metadata
from pathlib import Path


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
