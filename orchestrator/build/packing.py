"""Pack a shipped system folder and the FMUs it names into one .ssp archive (atomically:
written to a temporary file in the same folder, then renamed over the old archive).

A system's own data files (its ``resources/``) are also copied into the ``resources/`` of each
FMU inside the archive. Our runner resolves a relative data-file parameter against the system
(docs/interfaces.md, "Data files"); another engine (libcosim, FMPy) passes the String as written,
and the FMU then finds the file in its own resources (docs/third_party.md).

An archive records a fingerprint of what it was packed from (the folder's files and the FMUs'
bytes) in its zip comment; packing again with the same inputs leaves it untouched."""
from __future__ import annotations

import hashlib
import os
import tempfile
import zipfile
from pathlib import Path
from typing import Dict, List, Optional

from lxml import etree

from orchestrator.ssp import NS


#: bump when the archive layout changes, so that archives packed by older code are repacked
PACK_FORMAT = b"railcosim-pack 1"


def _system_files(folder: Path) -> List[Path]:
    return [p for p in sorted(folder.rglob("*")) if p.is_file() and "__pycache__" not in p.parts]


def _file_digest(path: Path, cache: Dict[Path, bytes]) -> bytes:
    if path not in cache:
        digest = hashlib.sha256()
        with open(path, "rb") as handle:
            for block in iter(lambda: handle.read(1 << 20), b""):
                digest.update(block)
        cache[path] = digest.digest()
    return cache[path]


def fingerprint(folder: Path, fmu_dir: Path, sources: List[str], cache: Optional[Dict[Path, bytes]] = None) -> bytes:
    """What the archive of ``folder`` is made from: its files' names and bytes and those of the
    FMUs it takes from ``fmu_dir``."""
    cache = {} if cache is None else cache
    digest = hashlib.sha256(PACK_FORMAT)
    for path in _system_files(folder):
        digest.update(path.relative_to(folder).as_posix().encode() + b"\0" + _file_digest(path, cache))
    for source in sorted(set(sources)):
        if not (folder / source).is_file():
            digest.update(source.encode() + b"\0" + _file_digest(fmu_dir / Path(source).name, cache))
    return PACK_FORMAT + b" " + digest.hexdigest().encode()


def _packed_from(target: Path) -> Optional[bytes]:
    try:
        with zipfile.ZipFile(target) as archive:
            return archive.comment
    except (OSError, zipfile.BadZipFile):
        return None


def pack_system(folder: Path, fmu_dir: Path, dest: Path, force: bool = False,
                cache: Optional[Dict[Path, bytes]] = None) -> Path:
    """<dest>/<name>.ssp with the folder's files plus each component's FMU under its source path,
    unless an archive packed from the same inputs is there already (``force``: pack anyway)."""
    return _pack(folder, fmu_dir, dest, force, cache)[0]


def _pack(folder: Path, fmu_dir: Path, dest: Path, force: bool, cache) -> "tuple[Path, bool]":
    ssd = folder / "SystemStructure.ssd"
    root = etree.parse(str(ssd)).getroot()
    sources = [c.get("source") for c in root.iter(f"{{{NS['ssd']}}}Component") if c.get("source")]
    target = dest / f"{folder.name}.ssp"
    stamp = fingerprint(folder, fmu_dir, sources, cache)
    if not force and target.is_file() and _packed_from(target) == stamp:
        return target, False
    dest.mkdir(parents=True, exist_ok=True)
    # written beside and renamed into place: a reader of the .ssp (a run started meanwhile)
    # sees the old archive or the new one, never a half-written zip
    handle, temp_name = tempfile.mkstemp(prefix=f".{folder.name}.", suffix=".ssp.tmp", dir=dest)
    os.close(handle)
    temp = Path(temp_name)
    try:
        with zipfile.ZipFile(temp, "w", zipfile.ZIP_DEFLATED) as archive:
            archive.comment = stamp
            for path in _system_files(folder):
                archive.write(path, path.relative_to(folder).as_posix())
            data_files = sorted(p for p in (folder / "resources").glob("*")
                                if p.is_file() and p.suffix != ".fmu")
            for source in sorted(set(sources)):
                if not (folder / source).is_file():
                    _write_fmu(archive, fmu_dir / Path(source).name, source, data_files)
        os.chmod(temp, 0o644)             # mkstemp makes it private; an archive is for everyone
        os.replace(temp, target)
    except BaseException:
        temp.unlink(missing_ok=True)
        raise
    return target, True


def _write_fmu(archive: zipfile.ZipFile, fmu: Path, member: str, data_files: List[Path]) -> None:
    """The FMU as ``member``, with the system's data files added to its resources (the system's
    copy replaces a bundled file of the same name, as our runner would choose it)."""
    if not data_files:
        archive.write(fmu, member)
        return
    added = {f"resources/{path.name}": path for path in data_files}
    with tempfile.SpooledTemporaryFile(max_size=64 << 20) as buffer:
        with zipfile.ZipFile(fmu) as source, zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as copy:
            for info in source.infolist():
                if info.filename not in added:
                    copy.writestr(info, source.read(info))
            for name, path in added.items():
                copy.write(path, name)
        buffer.seek(0)
        archive.writestr(zipfile.ZipInfo.from_file(fmu, member), buffer.read(), zipfile.ZIP_STORED)


def pack_systems(ssp_root: Path, fmu_dir: Path, dest: Path, force: bool = False,
                 repacked: Optional[List[Path]] = None) -> List[Path]:
    """Pack every shipped system whose FMUs are all built (those whose inputs changed, or all
    with ``force``); returns every archive, and adds those written to ``repacked``."""
    packed = []
    cache: Dict[Path, bytes] = {}
    if not ssp_root.is_dir():
        return packed
    for folder in sorted(p for p in ssp_root.iterdir() if (p / "SystemStructure.ssd").is_file()):
        root = etree.parse(str(folder / "SystemStructure.ssd")).getroot()
        sources = [c.get("source") for c in root.iter(f"{{{NS['ssd']}}}Component")]
        if all((folder / s).is_file() or (fmu_dir / Path(s).name).is_file() for s in sources):
            target, written = _pack(folder, fmu_dir, dest, force, cache)
            packed.append(target)
            if written and repacked is not None:
                repacked.append(target)
    return packed
