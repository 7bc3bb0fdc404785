"""Pack a shipped system folder and the FMUs it names into one .ssp archive (atomically:
written beside the old archive, then renamed over it: orchestrator/folders.py ``replacing``).

A system's own data files (its ``resources/``) are also copied into the ``resources/`` of each
FMU inside the archive. Our runner resolves a relative data-file parameter against the system
(docs/interfaces.md, "Data files"); another engine (libcosim, FMPy) passes the String as written,
and the FMU then finds the file in its own resources (docs/third_party.md).

An archive records a fingerprint of what it was packed from (the folder's files, and each FMU's
build content hash, or its bytes for an FMU built elsewhere) in its zip comment; packing again with the same inputs leaves it untouched."""
from __future__ import annotations

import hashlib
import os
import tempfile
import zipfile
from pathlib import Path
from typing import List, Optional

from lxml import etree

from orchestrator.folders import replacing
from orchestrator.packaging.builder import stored_hash
from orchestrator.provenance import file_digest, system_files
from orchestrator.ssp import NS, in_build_folder


#: bump when the archive layout changes, so that archives packed by older code are repacked
PACK_FORMAT = b"railcosim-pack 1"


def _fmu_digest(fmu: Path) -> bytes:
    """What an FMU is made from: the content hash our build stores in it (the same whenever it
    is built from the same sources), else the hash of its bytes (a foreign FMU)."""
    built = stored_hash(fmu)
    return b"content_hash " + built.encode() if built else b"sha256 " + file_digest(fmu)


def fingerprint(folder: Path, fmu_dir: Path, sources: List[str]) -> bytes:
    """What the archive of ``folder`` is made from: its files' names and bytes and the FMUs it
    takes from ``fmu_dir`` (:func:`_fmu_digest`)."""
    digest = hashlib.sha256(PACK_FORMAT)
    for path in system_files(folder):
        digest.update(path.relative_to(folder).as_posix().encode() + b"\0" + file_digest(path))
    for source in sorted(set(sources)):
        if not (folder / source).is_file():
            digest.update(source.encode() + b"\0" + _fmu_digest(fmu_dir / in_build_folder(source)))
    return PACK_FORMAT + b" " + digest.hexdigest().encode()


def _sources(folder: Path) -> List[str]:
    """The FMU source of every component of the folder's SSD."""
    root = etree.parse(str(folder / "SystemStructure.ssd")).getroot()
    return [c.get("source") for c in root.iter(f"{{{NS['ssd']}}}Component") if c.get("source")]


def _packed_from(target: Path) -> Optional[bytes]:
    try:
        with zipfile.ZipFile(target) as archive:
            return archive.comment
    except (OSError, zipfile.BadZipFile):
        return None


def pack_system(folder: Path, fmu_dir: Path, dest: Path, force: bool = False) -> Path:
    """<dest>/<name>.ssp with the folder's files plus each component's FMU under its source path,
    unless an archive packed from the same inputs is there already (``force``: pack anyway)."""
    return _pack(folder, _sources(folder), fmu_dir, dest, force)[0]


def _pack(folder: Path, sources: List[str], fmu_dir: Path, dest: Path, force: bool) -> "tuple[Path, bool]":
    target = dest / f"{folder.name}.ssp"
    stamp = fingerprint(folder, fmu_dir, sources)
    if not force and target.is_file() and _packed_from(target) == stamp:
        return target, False
    dest.mkdir(parents=True, exist_ok=True)
    # written beside and renamed into place: a reader of the .ssp (a run started meanwhile)
    # sees the old archive or the new one, never a half-written zip
    with replacing(target, binary=True, concurrent=True) as handle:
        with zipfile.ZipFile(handle, "w", zipfile.ZIP_DEFLATED) as archive:
            archive.comment = stamp
            for path in system_files(folder):
                archive.write(path, path.relative_to(folder).as_posix())
            data_files = sorted(p for p in (folder / "resources").glob("*")
                                if p.is_file() and p.suffix != ".fmu")
            for source in sorted(set(sources)):
                if not (folder / source).is_file():
                    _write_fmu(archive, fmu_dir / in_build_folder(source), source, data_files)
        os.fchmod(handle.fileno(), 0o644)       # an archive is for everyone, whatever the umask
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
    if not ssp_root.is_dir():
        return packed
    for folder in sorted(p for p in ssp_root.iterdir() if (p / "SystemStructure.ssd").is_file()):
        sources = _sources(folder)
        if all((folder / s).is_file() or (fmu_dir / in_build_folder(s)).is_file() for s in sources):
            target, written = _pack(folder, sources, fmu_dir, dest, force)
            packed.append(target)
            if written and repacked is not None:
                repacked.append(target)
    return packed
