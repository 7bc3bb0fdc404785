"""Zip archives (.ssp, .fmu) unpacked safely: no member outside the destination (zip-slip), no
more unpacked than a bound (a zip bomb refused before it fills the disk), a member this Python
cannot decompress, that is corrupt or cannot be written is an error naming ``<archive>!<member>``
(orchestrator/errors.py). Every extraction of ours goes through :func:`safe_extract`: a .ssp
when it is opened, each FMU before its slave is made (fmpy is given the extracted folder)."""
from __future__ import annotations

import math
import os
import shutil
import zipfile
import zlib
from pathlib import Path

from orchestrator.errors import UserError

#: the environment variable that sets the most one archive may unpack to, in MB (10⁶ bytes)
MAX_UNPACKED_VARIABLE = "RAILCOSIM_MAX_UNPACKED_MB"
#: its default: about 50× the largest archive shipped (tvm430.ssp, 10.6 MB unpacked; an FMU of
#: ours 1.4–2.5 MB), room for third-party FMUs with large binaries
DEFAULT_MAX_UNPACKED_MB = 512.0
_BYTES_PER_MB = 1_000_000
#: bytes copied per read while a member is extracted
_CHUNK_BYTES = 1 << 20


def max_unpacked_bytes() -> int:
    """The bound on what one archive unpacks to: $RAILCOSIM_MAX_UNPACKED_MB, else the default."""
    text = os.environ.get(MAX_UNPACKED_VARIABLE)
    if text is None or not text.strip():
        return int(DEFAULT_MAX_UNPACKED_MB * _BYTES_PER_MB)
    try:
        megabytes = float(text)
    except ValueError:
        megabytes = math.nan
    if not (math.isfinite(megabytes) and megabytes > 0):
        raise UserError(f"{MAX_UNPACKED_VARIABLE}={text!r}: must be a positive number of megabytes (10^6 bytes)")
    return int(megabytes * _BYTES_PER_MB)


def shown_size(size_bytes: int) -> str:
    """A size for a message: MB to a tenth, a small one in bytes."""
    return f"{size_bytes / _BYTES_PER_MB:.1f} MB" if size_bytes >= 100_000 else f"{size_bytes} bytes"


def safe_extract(archive_path: Path, dest: Path) -> None:
    """Extract a zip (.ssp or .fmu) into ``dest`` (a new folder of the caller's), refusing
    members that would land outside it and an archive that would unpack to more than
    :func:`max_unpacked_bytes` or than the free space at ``dest``."""
    try:
        archive = zipfile.ZipFile(archive_path)
    except zipfile.BadZipFile:
        raise UserError(f"{archive_path}: not a zip archive (or cut short)") from None
    except OSError as error:
        raise UserError(f"{archive_path}: cannot open ({error.strerror})") from None
    root = dest.resolve()
    with archive:
        members = archive.infolist()
        for member in members:
            target = (dest / member.filename).resolve()
            if os.path.isabs(member.filename) or not (target == root or root in target.parents):
                raise UserError(f"{archive_path}: member {member.filename!r} would be extracted outside "
                                "the extraction folder (zip-slip); refusing the archive")
        budget = _check_declared_sizes(archive_path, members, dest)
        for member in members:
            budget -= _extract_member(archive, member, dest, archive_path, budget)


def _check_declared_sizes(archive_path: Path, members, dest: Path) -> int:
    """From the central directory, before anything is written: the sizes the members declare
    against the bound and against the free space at ``dest``; returns the bound in bytes."""
    bound = max_unpacked_bytes()
    declared = sum(member.file_size for member in members)
    if declared > bound:
        largest = max(members, key=lambda member: member.file_size)
        raise UserError(f"{archive_path}: unpacks to {shown_size(declared)} (its largest member, "
                        f"{archive_path}!{largest.filename}, {shown_size(largest.file_size)}), more than the "
                        f"{shown_size(bound)} allowed; refusing the archive (set {MAX_UNPACKED_VARIABLE} to raise "
                        "the bound, docs/reliability.md)")
    place = next((folder for folder in (dest, *dest.parents) if folder.is_dir()), None)
    try:
        free = shutil.disk_usage(place).free if place is not None else None
    except OSError:
        free = None
    if free is not None and declared > free:
        raise UserError(f"{archive_path}: unpacks to {shown_size(declared)}, but {dest.parent} has {shown_size(free)} "
                        "free; refusing the archive")
    return bound


#: zip compression methods zipfile can read here: stored and deflate always (zlib is imported
#: above), bzip2 and LZMA where zipfile could import their modules (it holds None otherwise)
READABLE_ZIP_METHODS = frozenset(
    [zipfile.ZIP_STORED, zipfile.ZIP_DEFLATED]
    + [method for method, module in ((zipfile.ZIP_BZIP2, zipfile.bz2), (zipfile.ZIP_LZMA, zipfile.lzma))
       if module is not None])


def _extract_member(archive: zipfile.ZipFile, member: zipfile.ZipInfo, dest: Path, archive_path: Path,
                    budget: int) -> int:
    """One member; returns the bytes written. The bytes are counted as they are written: a
    member that would write more than it declares, or more than is left of the bound
    (``budget``), is stopped there, whatever its header says. A member in a compression method
    that cannot be read here, that cannot be read (bad CRC, corrupt deflate stream, cut short)
    or written (no space left, a name too long, a name twice) is an error naming
    ``<archive>!<member>``."""
    name = f"{archive_path}!{member.filename}"
    if member.compress_type not in READABLE_ZIP_METHODS:
        raise UserError(f"{name}: compressed with a method this Python "
                        f"cannot read (zip method {member.compress_type}); repack it with deflate")
    target = dest / member.filename
    allowed = min(member.file_size, budget)
    written = 0
    try:
        if member.is_dir():
            target.mkdir(parents=True, exist_ok=True)
            return 0
        target.parent.mkdir(parents=True, exist_ok=True)
        # a new file in the caller's new folder: O_EXCL (a name the archive holds twice is
        # refused, not one of the copies silently kept), never through a link
        fd = os.open(target, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC, 0o666)
        with os.fdopen(fd, "wb") as sink, archive.open(member) as source:
            while True:
                chunk = source.read(_CHUNK_BYTES)
                if not chunk:
                    return written
                written += len(chunk)
                if written > allowed:
                    raise UserError(f"{name}: unpacks to more than "
                                    + (f"the {member.file_size} bytes it declares; the archive is corrupt or crafted"
                                       if allowed == member.file_size else
                                       f"the bound on the archive ({shown_size(budget)} left of it)")
                                    + "; refusing the archive")
                sink.write(chunk)
    except (zipfile.BadZipFile, zlib.error, EOFError) as error:
        raise UserError(f"{name}: cannot be read from the archive "
                        f"({error or type(error).__name__}); the archive is corrupt") from None
    except FileExistsError:           # a name twice, or a file where another member needs a folder
        raise UserError(f"{name}: its path is taken by another member of the archive; refusing the archive") from None
    except OSError as error:          # a full temp folder, a file-size limit, a name too long
        raise UserError(f"{name}: cannot be extracted into {dest.parent} "
                        f"({error.strerror or error})") from None
