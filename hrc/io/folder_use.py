"""A compile output folder in use by a live run, and the compile that must not replace it meanwhile.

A run (``hrc console``, ``hrc dispatch``, ``hrc ros2``) reads an output folder when it starts and some of
it later (a plan's motions, by offset into ``compiled.json``). A compile into the same folder would swap
a new output in under it (`hrc.io.claim`), and the run would then read the new files at the old offsets
(issue 34: ``/state`` answered 500 and acknowledgements went unanswered). So:

- the run holds the folder (`FolderUse`): a shared ``flock`` on the folder itself (its directory, not a
  file beside it: the run may have no right to write there), taken before anything in it is read and
  kept as long as the run is, and the files it reads later opened once, at the start, through it;
- the compile (`FolderClaim`) refuses a folder that is held (`check_unused`, one line, before any work),
  and holds the folder exclusively (`exclusive`) while it swaps the new output in, so that no run can
  start reading the earlier output in the middle of the swap; a run that started during the compile
  makes the swap refuse, and the earlier output stays.

Why the folder's own lock: ``flock`` belongs to the folder (its inode), which the swap moves; a run
that took its lock on a folder that a swap had just moved aside (between its ``open`` and its ``flock``)
sees that the path no longer names it and takes the new one (`FolderUse.__enter__`). The kernel drops a
lock when its process ends, however it ends: a killed run never blocks a compile.

Example::

    with FolderUse("out/ws") as use:           # shared: any number of runs at once
        compiled = use.open("compiled.json")    # this folder's file, whatever is swapped in later
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import time
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from hrc.errors import InputError

__all__ = ["USE_WAIT", "FolderUse", "check_unused", "exclusive"]

USE_WAIT = 2.0
"""Seconds a run waits for a compile's swap (milliseconds) before it gives up on the folder."""

_DIRECTORY = os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_CLOEXEC", 0)


def _same(fd: int, path: Path) -> bool:
    try:
        here, now = os.fstat(fd), os.stat(path)
    except OSError:
        return False
    return (here.st_dev, here.st_ino) == (now.st_dev, now.st_ino)


class FolderUse:
    """`folder` held by a live run (module docstring): a context manager, or `acquire` / `release` for
    an object that holds it as long as it lives. Raises `InputError` when `folder` is not a folder, or a
    compile is swapping it for longer than `USE_WAIT` seconds."""

    def __init__(self, folder: str | os.PathLike[str]) -> None:
        self.folder = Path(folder)
        self._fd: int | None = None

    def acquire(self) -> FolderUse:
        deadline = time.monotonic() + USE_WAIT
        while True:
            try:
                fd = os.open(self.folder, _DIRECTORY)
            except OSError as err:
                raise InputError(str(self.folder), "", f"cannot open the folder: {err.strerror or err}") from err
            try:
                fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
            except BlockingIOError:  # a compile swaps a new output in: a moment
                os.close(fd)
                if time.monotonic() >= deadline:
                    raise InputError(str(self.folder), "", "a compile is replacing this folder now; start again "
                                                           "once it has ended") from None
                time.sleep(0.02)
                continue
            except BaseException:
                os.close(fd)
                raise
            if _same(fd, self.folder):  # else it was swapped aside between open and flock: the new one
                self._fd = fd
                return self
            os.close(fd)

    def release(self) -> None:
        fd, self._fd = self._fd, None
        if fd is not None:
            os.close(fd)  # the lock goes with the last descriptor of it

    def __enter__(self) -> FolderUse:
        return self.acquire()

    def __exit__(self, *exc: object) -> None:
        self.release()

    def __del__(self) -> None:
        self.release()

    @property
    def held(self) -> bool:
        return self._fd is not None

    def open(self, name: str) -> BinaryIO:
        """The file `name` of the held folder (not of whatever the path names later), for reading."""
        if self._fd is None:
            raise ValueError("open() of a folder not held")
        fd = os.open(name, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0), dir_fd=self._fd)
        return os.fdopen(fd, "rb")


def _in_use(fd: int) -> bool:
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    fcntl.flock(fd, fcntl.LOCK_UN)
    return False


def _refusal(folder: Path, when: str) -> InputError:
    return InputError(str(folder), "--out", f"a live run (hrc console, dispatch or ros2) uses this output folder"
                                            f"{when}; replacing it would change the plans under that run: stop "
                                            "the run first, or compile into another --out")


def check_unused(folder: str | os.PathLike[str]) -> None:
    """Raise `InputError` (one line) when a live run holds `folder` (`FolderUse`); nothing when it is not
    a folder (yet)."""
    path = Path(folder)
    try:
        fd = os.open(path, _DIRECTORY)
    except OSError:
        return
    try:
        if _in_use(fd):
            raise _refusal(path, "")
    finally:
        os.close(fd)


@contextlib.contextmanager
def exclusive(folder: str | os.PathLike[str]) -> Iterator[None]:
    """`folder` held exclusively for the context (a swap): no run holds it, none starts meanwhile. Raises
    `InputError` at once when a run holds it (one started during the compile). Nothing when there is no
    such folder."""
    path = Path(folder)
    try:
        fd = os.open(path, _DIRECTORY)
    except OSError:
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise _refusal(path, " (a run started during the compile); the earlier output is kept") from None
        yield
    finally:
        os.close(fd)
