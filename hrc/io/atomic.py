"""Atomic file output: write to a temporary file beside the target, then rename over it.

A reader (or a crash) never sees a half-written file: the temporary file is flushed to the disk
(``fsync``) before the rename, and its folder after it (`hrc.io.durable`), so that after a power cut the
name holds the old bytes or the new ones. `atomic_dir` does the same for a whole output folder: it is
built in a staging folder beside it, flushed, and swapped into place when complete (`hrc.io.claim`:
one process at a time, never a moment without the folder, a killed run's leftovers cleaned by the next).
`AtomicFile` is the streaming form of `write_bytes_atomic`, for a file written over a whole run (an
MCAP recording): it grows under a hidden name beside its target and takes the target's name only when
`commit` is called.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from hrc.io.claim import FolderClaim
from hrc.io.durable import fsync_folder

__all__ = ["AtomicFile", "atomic_dir", "write_bytes_atomic", "write_text_atomic"]


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


class AtomicFile:
    """A new file at `path`, written through `file` under a hidden name beside it (``.NAME.XXXX.tmp``) and
    given its name by `commit`: flushed to the disk, then linked to `path`, which must not exist then
    either (a file that appeared meanwhile is never overwritten: `FileExistsError`), then the folder
    flushed. `discard` removes it. A run killed before `commit` leaves only the hidden file (no reader
    takes it for the real one); nothing is ever under `path` but a whole file.

    Raises `FileExistsError` at once when `path` exists, `IsADirectoryError` when it is a folder.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        self.check(self.path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{self.path.name}.", suffix=".tmp", dir=self.path.parent)
        self.tmp = Path(tmp)
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
        fsync_folder(self.path.parent)
        return self.path

    def discard(self) -> None:
        """Remove the hidden file (nothing is ever at `path`); idempotent, and quiet: what was not written
        (a full disk) is dropped."""
        self.done = True
        with contextlib.suppress(OSError):
            self.file.close()
        with contextlib.suppress(FileNotFoundError):
            os.unlink(self.tmp)
