"""Zip archives (.ssp, .fmu) unpacked safely: no member outside the destination (zip-slip), a
member this Python cannot decompress or that is corrupt is an error naming
``<archive>!<member>`` (orchestrator/errors.py)."""
from __future__ import annotations

import os
import zipfile
import zlib
from pathlib import Path

from orchestrator.errors import UserError


def safe_extract(archive_path: Path, dest: Path) -> None:
    """Extract a zip (.ssp or .fmu), refusing members that would land outside ``dest``."""
    try:
        archive = zipfile.ZipFile(archive_path)
    except zipfile.BadZipFile:
        raise UserError(f"{archive_path}: not a zip archive (or cut short)") from None
    except OSError as error:
        raise UserError(f"{archive_path}: cannot open ({error.strerror})") from None
    root = dest.resolve()
    with archive:
        for member in archive.namelist():
            target = (dest / member).resolve()
            if os.path.isabs(member) or not (target == root or root in target.parents):
                raise UserError(f"{archive_path}: member {member!r} would be extracted outside "
                                "the extraction folder (zip-slip); refusing the archive")
        for member in archive.infolist():
            _extract_member(archive, member, dest, archive_path)


#: zip compression methods zipfile can read here: stored and deflate always (zlib is imported
#: above), bzip2 and LZMA where zipfile could import their modules (it holds None otherwise)
READABLE_ZIP_METHODS = frozenset(
    [zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED]
    + [method for method, module in ((zipfile.ZIP_BZIP2, zipfile.bz2), (zipfile.ZIP_LZMA, zipfile.lzma))
       if module is not None])


def _extract_member(archive: zipfile.ZipFile, member: zipfile.ZipInfo, dest: Path, archive_path: Path) -> None:
    """One member; a member in a compression method that cannot be read here, or that cannot be
    read (bad CRC, corrupt deflate stream, cut short), is an error naming ``<archive>!<member>``."""
    if member.compress_type not in READABLE_ZIP_METHODS:
        raise UserError(f"{archive_path}!{member.filename}: compressed with a method this Python "
                        f"cannot read (zip method {member.compress_type}); repack it with deflate")
    try:
        archive.extract(member, dest)
    except (zipfile.BadZipFile, zlib.error, EOFError) as error:
        raise UserError(f"{archive_path}!{member.filename}: cannot be read from the archive "
                        f"({error or type(error).__name__}); the archive is corrupt") from None
