"""Atomic file output: write to a temporary file beside the target, then rename over it.

A reader (or a crash) never sees a half-written file: the temporary file is flushed to the disk
(``fsync``) before the rename, and its folder after it (`hrc.io.durable`), so that after a power cut the
name holds the old bytes or the new ones. `atomic_dir` does the same for a whole output folder: it is
built in a staging folder beside it, flushed, and swapped into place when complete (`hrc.io.claim`:
one process at a time, never a moment without the folder, a killed run's leftovers cleaned by the next).
`AtomicFile` is the streaming form of `write_bytes_atomic`, for a file written over a whole run (an
MCAP recording): it grows under a hidden name beside its target and takes the target's name only when
`commit` is called; the hidden file of a run killed before that is removed by the next `AtomicFile` in
the same folder (`clean_stale`).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import functools
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from hrc.io.claim import FolderClaim
from hrc.io.durable import fsync_folder

__all__ = ["AtomicFile", "atomic_dir", "clean_stale", "write_bytes_atomic", "write_text_atomic"]

_MARK = "hrc-"
"""An `AtomicFile`'s hidden name is ``.NAME.hrc-XXXXXXXX.tmp``: the pattern `clean_stale` looks for."""


@functools.cache
def _umask() -> int:
    """The process umask (read once: `os.umask` can only be read by setting it, briefly)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> None:
    """Write `data` to `path` so that readers see the old file or the new one, never a part, also after a
    crash: the new file is flushed before it is renamed over the old one, and the folder after.

    The file gets the permissions an ordinary ``open(path, "w")`` would give (``0o666 & ~umask``),
    not the private ``0o600`` of the temporary file.
    """
    target = Path(path)
    if target.is_dir():
        raise IsADirectoryError(errno.EISDIR, "is a folder; expected a file name", str(target))
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=target.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise
    fsync_folder(target.parent)


def write_text_atomic(path: str | os.PathLike[str], text: str) -> None:
    write_bytes_atomic(path, text.encode("utf-8"))


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a fresh staging folder beside `path`; on success it replaces `path` (`FolderClaim`: its
    files flushed to the disk first, an existing `path` exchanged with it in one step, the parent folder
    flushed after). On any failure (an exception, KeyboardInterrupt, a failed rename) the staging folder
    is removed, the folders made for it too, and an existing `path` is left as it was. Raises
    `hrc.errors.InputError` while another process is writing `path`."""
    with FolderClaim(path) as claim, claim.staging() as stage:
        yield stage


def _locked_by_a_live_process(fd: int) -> bool:
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    return False


def clean_stale(folder: str | os.PathLike[str]) -> list[Path]:
    """Remove the hidden files (``.NAME.hrc-XXXXXXXX.tmp``) that an `AtomicFile` of a process now gone
    left in `folder` (a recording killed with SIGKILL, a power cut); the paths removed.

    Which are stale is known, not guessed: a writer holds an exclusive ``flock`` on its hidden file from
    before the file has that name until it is removed or renamed, and the kernel drops the lock when the
    process dies. So a file of the pattern that can be locked is a dead writer's; one that cannot is being
    written. Other files are never touched. Never raises (a folder that cannot be read is left alone)."""
    removed: list[Path] = []
    try:
        found = sorted(Path(folder).glob(f".*.{_MARK}*.tmp"))
    except OSError:
        return removed
    for path in found:
        try:
            fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
        except OSError:
            continue  # gone meanwhile, a symlink, not ours to read
        try:
            if _locked_by_a_live_process(fd) or not os.path.samestat(os.fstat(fd), os.lstat(path)):
                continue
            os.unlink(path)
            removed.append(path)
        except OSError:
            continue
        finally:
            os.close(fd)
    return removed


class AtomicFile:
    """A new file at `path`, written through `file` under a hidden name beside it
    (``.NAME.hrc-XXXXXXXX.tmp``) and given its name by `commit`: flushed to the disk, then linked to
    `path`, which must not exist then either (a file that appeared meanwhile is never overwritten:
    `FileExistsError`), then the folder flushed. `discard` removes it. A run killed before `commit`
    leaves only the hidden file (no reader takes it for the real one), which the next `AtomicFile` in the
    same folder removes (`clean_stale`; `cleaned` says what it removed); nothing is ever under `path` but
    a whole file.

    The hidden file is locked (``flock``) by its writer from before it takes its hidden name until it is
    gone, through a descriptor of its own (`_lock`) that `commit` and `discard` close last.

    Raises `FileExistsError` at once when `path` exists, `IsADirectoryError` when it is a folder.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.check(self.path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.cleaned = clean_stale(self.path.parent)
        fd, new = tempfile.mkstemp(prefix=f".{self.path.name}.{_MARK}", suffix=".new", dir=self.path.parent)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX)  # a new file: no one else holds it
            self._lock = os.dup(fd)  # the lock lives as long as one descriptor of the file is open
            self.tmp = Path(new[: -len(".new")] + ".tmp")
            os.rename(new, self.tmp)  # under the name `clean_stale` looks for only once locked
        except BaseException:
            with contextlib.suppress(OSError):
                os.unlink(new)
            os.close(fd)
            raise
        self.file: BinaryIO = os.fdopen(fd, "w+b")
        self.done = False

    @staticmethod
    def check(path: str | os.PathLike[str]) -> None:
        """Raise as the constructor does when `path` is taken (a caller that checks before a long start)."""
        target = Path(path)
        if target.is_dir():
            raise IsADirectoryError(errno.EISDIR, "is a folder; expected a file name", str(target))
        if target.exists() or target.is_symlink():
            raise FileExistsError(errno.EEXIST, "exists already (give a new file name)", str(target))

    def commit(self) -> Path:
        """Give the file its name (see the class docstring); the path."""
        if self.done:
            raise ValueError(f"{self.path}: committed or discarded already")
        try:
            self.file.flush()
            os.fsync(self.file.fileno())
            self.file.close()
            os.chmod(self.tmp, 0o666 & ~_umask())
            try:
                os.link(self.tmp, self.path)  # never over a file: EEXIST if one appeared meanwhile
            except OSError as err:
                if err.errno not in (errno.EPERM, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EXDEV):
                    raise
                if self.path.exists():  # a file system without hard links: check, then rename
                    raise FileExistsError(errno.EEXIST, "exists already", str(self.path)) from err
                os.replace(self.tmp, self.path)
                self.tmp = self.path
        except BaseException:
            self.discard()
            raise
        self.done = True
        if self.tmp != self.path:
            os.unlink(self.tmp)
        self._unlock()
        fsync_folder(self.path.parent)
        return self.path

    def _unlock(self) -> None:
        if self._lock >= 0:
            with contextlib.suppress(OSError):
                os.close(self._lock)
            self._lock = -1

    def discard(self) -> None:
        """Remove the hidden file (nothing is ever at `path`); idempotent, and quiet: what was not written
        (a full disk) is dropped."""
        self.done = True
        with contextlib.suppress(OSError):
            self.file.close()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.tmp)
        self._unlock()
