"""The files a command writes into a folder the user names, made so that nothing planted there
redirects them (docs/reliability.md, "What a run writes"): the folder's lock, files created
without following a symbolic link, files replaced whole.

An output folder may be shared (a path in /tmp, a group's scratch folder). A symbolic link
another user planted at a name the run writes — its lock file, a result file, the temporary
file written beside one — would have the run write into whatever file the link names that the
user can write. So every such file is opened with ``O_NOFOLLOW`` (a temporary file also with
``O_EXCL``), and a link at one of these names, or as the output folder itself, is refused in one
line naming it.
"""
from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import secrets
import stat
from pathlib import Path
from typing import Optional, Tuple, Union

from orchestrator.errors import UserError

#: the lock file a command keeps in the folder it writes (a run's, a study's)
LOCK_FILE = ".railcosim.lock"


def _link_target(path: Path) -> str:
    try:
        return f" (to {os.readlink(path)})"
    except OSError:
        return ""


def link_refused(path: Path) -> UserError:
    """The one line for a symbolic link where a file is to be written."""
    return UserError(f"{path}: is a symbolic link{_link_target(path)}; railcosim writes no file "
                     "through a link (remove it, or write elsewhere)")


def _folder_link_refused(label: str, folder: Path) -> UserError:
    return UserError(f"{label}: {folder} is a symbolic link{_link_target(folder)}; railcosim writes "
                     "into no folder through a link (give the folder itself)")


def refuse_link(path: Path) -> None:
    """A :func:`link_refused` error when ``path`` is a symbolic link (a dangling one too)."""
    if os.path.islink(path):
        raise link_refused(path)


def open_without_link(path: Path, flags: int, mode: int = 0o666) -> int:
    """``os.open`` that never follows a symbolic link at ``path`` itself (a link in a folder
    above it is the user's own path and is followed); a link there is :func:`link_refused`,
    any other failure the OSError."""
    try:
        return os.open(path, flags | os.O_NOFOLLOW | os.O_CLOEXEC, mode)
    except OSError as error:
        if error.errno == errno.ELOOP and os.path.islink(path):
            raise link_refused(Path(path)) from None
        raise


def create_file(path: Path, binary: bool = False):
    """``path`` opened for writing from empty (created if missing) without following a link at
    it: UTF-8 text with ``newline=""`` (the csv module's own line ends), or binary."""
    fd = open_without_link(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC)
    return os.fdopen(fd, "wb") if binary else os.fdopen(fd, "w", encoding="utf-8", newline="")


@contextlib.contextmanager
def replacing(path: Path, binary: bool = False, concurrent: bool = False):
    """A file to write ``path``'s new content into, written beside it and renamed over it when
    the block ends (removed if the block fails): a reader sees the old file or the new one,
    never half of one, and a link planted at either name is replaced, never written through.

    The file beside is created new (O_EXCL, O_NOFOLLOW): ``.NAME.tmp``, an earlier one (a
    writer killed mid-write) removed first, where the writer holds the folder (a run's or a
    study's lock, the build lock); ``concurrent``: other processes may replace the same file
    at the same time (the shipped systems' refresh, the packer), so it gets a name of its own,
    ``.NAME.<random>.tmp``, and no writer renames another's half-written file. Text is UTF-8."""
    path = Path(path)
    if concurrent:
        fd, temp = _created_beside(path)
    else:
        temp = path.with_name(f".{path.name}.tmp")
        try:
            os.unlink(temp)             # an earlier writer's, killed mid-write (a link: the link only)
        except FileNotFoundError:
            pass
        fd = open_without_link(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL)
    try:
        with (os.fdopen(fd, "wb") if binary else os.fdopen(fd, "w", encoding="utf-8")) as handle:
            yield handle
        os.replace(temp, path)
    except BaseException:
        try:
            os.unlink(temp)
        except OSError:
            pass
        raise


def _created_beside(path: Path) -> Tuple[int, Path]:
    """A new file ``.NAME.<random>.tmp`` beside ``path`` (O_EXCL: never an existing name, nor a
    link) and its descriptor."""
    while True:
        temp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp")
        try:
            return open_without_link(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL), temp
        except FileExistsError:
            continue


def replace_file(path: Path, data: Union[str, bytes], concurrent: bool = False) -> None:
    """``path`` replaced whole by ``data`` (text, UTF-8, or bytes), through :func:`replacing`."""
    with replacing(path, binary=isinstance(data, bytes), concurrent=concurrent) as handle:
        handle.write(data)


class FolderLock:
    """An exclusive lock on a folder for this process: ``flock`` on its ``.railcosim.lock``,
    which records the holder's process id. A second holder fails at once with one line; the
    lock goes with the process however it ends (even ``kill -9``) and the lock file stays
    (removing it could let two processes lock two different files).

    ``label`` starts every message (``--output results``); ``holder`` names who else may hold
    the folder (``another run``, ``another study``)."""

    def __init__(self, folder: Path, label: str, holder: str = "another run"):
        self.folder = Path(folder)
        self.label = label
        self.holder = holder
        self._fd: Optional[int] = None
        self._identity: Optional[Tuple[int, int]] = None

    @property
    def held(self) -> bool:
        return self._fd is not None

    def acquire(self) -> "FolderLock":
        """Make the folder (and its parents) and lock it; a UserError when the folder is a
        symbolic link, cannot be made, or is locked by another process."""
        if self._fd is not None:
            return self
        if os.path.islink(self.folder):
            raise _folder_link_refused(self.label, self.folder)
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
            folder_fd = os.open(self.folder, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW | os.O_CLOEXEC)
        except OSError as error:
            if error.errno == errno.ELOOP:          # made a link meanwhile
                raise _folder_link_refused(self.label, self.folder) from None
            raise UserError(f"{self.label}: cannot create the folder ({error.strerror or error})") from None
        try:
            folder_stat = os.fstat(folder_fd)
            # in the folder just opened (not wherever the name points by now), never through a link
            fd = os.open(LOCK_FILE, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_CLOEXEC, 0o644, dir_fd=folder_fd)
        except OSError as error:
            if error.errno == errno.ELOOP:
                raise UserError(f"{self.label}: its lock file {link_refused(self.folder / LOCK_FILE)}") from None
            raise UserError(f"{self.label}: cannot create its lock file {LOCK_FILE} "
                            f"({error.strerror or error})") from None
        finally:
            os.close(folder_fd)
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            os.close(fd)
            raise UserError(f"{self.label}: its lock file {self.folder / LOCK_FILE} is not a regular file; remove it")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.read(fd, 32).decode(errors="replace").strip()
            os.close(fd)
            raise UserError(f"{self.label}: in use by {self.holder}"
                            + (f" (process {holder})" if holder.isdigit() else "")
                            + "; choose another --output or wait for it to end") from None
        self._fd = fd
        self._identity = (folder_stat.st_dev, folder_stat.st_ino)
        try:
            # written, then cut to its length: a truncation to zero would have ext4 flush the
            # file when it is closed (its auto_da_alloc), up to 0.2 s on a busy disk
            pid = f"{os.getpid()}\n".encode()
            os.pwrite(fd, pid, 0)
            os.ftruncate(fd, len(pid))
        except OSError:
            pass                          # the pid only makes the message above nicer
        return self

    def lost(self) -> Optional[str]:
        """None while the folder locked is still at its name; else the one line saying it was
        removed or replaced (what was written into it is gone with it)."""
        if self._identity is None:
            return None
        try:
            now = os.lstat(self.folder)
            if (now.st_dev, now.st_ino) == self._identity:
                return None
            what = "replaced by another folder or file"
        except OSError:
            what = "removed"
        return f"{self.label}: the folder was {what} while it was written; its files are lost"

    def release(self) -> None:
        """Unlock (the lock file stays)."""
        fd, self._fd = self._fd, None
        if fd is not None:
            os.close(fd)

    def __enter__(self) -> "FolderLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
