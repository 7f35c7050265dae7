"""An output folder claimed for replacing: one process at a time, a staging folder beside it, a swap that
never leaves it missing, and whatever a killed run left beside it cleaned up by the next claim.

Beside an output folder ``P/NAME`` a claim keeps

- ``P/.NAME.lock``, the claim itself: locked (``flock``) by the process that holds it, and its journal:
  the process id, then each folder the process is about to make beside NAME, written and flushed before
  the folder is made::

      hrc output claim: pid 1234
      staging .NAME.staging-1234-9f3a0c1e
      aside .NAME.aside-1234-77b0e2d4

- ``P/.NAME.staging-PID-XXXXXXXX``: where the new NAME is built (`FolderClaim.staging`);
- ``P/.NAME.aside-PID-XXXXXXXX``: the earlier NAME during a swap where the file system cannot exchange
  two names in one step (below).

The kernel releases a lock when its process ends, however it ends (SIGKILL included; a power cut ends
them all). So a journal found unlocked is a dead process's, and the folders it names are that run's
leftovers: provably ours (named in our journal, in our pattern) and stale (their process is gone). The
next claim of the same folder removes them, or, for a run that died between the two renames of a swap
(NAME missing, the earlier output aside), puts the earlier output back first. A folder no journal names
is never touched, nor is NAME while another live process holds its claim (`InputError`), nor while a
live run reads it (`hrc.io.folder_use`: refused when claimed, and when a run started meanwhile, at the
swap).

The swap, when the staging folder's context ends without an exception: everything under the staging
folder is flushed to the disk (`sync_tree`) before any name points at it; then it is exchanged with NAME
in one atomic step (`exchange`), the parent folder is flushed, and the staging name, which now holds the
earlier output, is removed. Where the system cannot exchange: NAME is renamed aside (journaled first),
the staging folder renamed to NAME, the parent flushed, the aside removed. So at every instant NAME is the
earlier output or the new one, except in the fallback between its two renames, where a crash leaves NAME
missing and the earlier output aside, which the next claim puts back.

The claim ends, normally or by an exception, by undoing its own leftovers the same way and removing its
journal: nothing is left beside NAME. Only a kill leaves the journal and a staging folder, for the next
claim to clean.

Example::

    with FolderClaim("out/run") as claim:   # out/.run.lock taken; a killed run's leftovers cleaned
        with claim.staging() as stage:      # out/.run.staging-...
            (stage / "result.txt").write_text("done")
    # out/run is the new folder; nothing else is left in out/
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import re
import secrets
import shutil
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from hrc.errors import InputError
from hrc.io.durable import exchange, fsync_folder, sync_tree
from hrc.io.folder_use import check_unused, exclusive

__all__ = ["LOCK_WAIT", "FolderClaim"]

_HEADER = "hrc output claim: pid "

LOCK_WAIT = 2.0
"""Seconds a claim waits for another process to release the folder before it refuses."""


def _exists(path: Path) -> bool:
    return path.exists() or path.is_symlink()


def _make_parents(folder: Path) -> list[Path]:
    """``mkdir -p folder``; returns the folders it created, deepest first (to remove them on failure)."""
    missing = []
    for p in (folder, *folder.parents):
        if _exists(p):
            break
        missing.append(p)
    folder.mkdir(parents=True, exist_ok=True)
    return missing


def _remove(path: Path) -> bool:
    """Remove `path` (a folder tree, or a file or link); True when it is gone."""
    if path.is_symlink() or not path.is_dir():
        with contextlib.suppress(FileNotFoundError):
            path.unlink()
    else:
        shutil.rmtree(path, ignore_errors=True)
    return not _exists(path)


class FolderClaim:
    """`target` claimed for replacing (see the module docstring): a context manager; `staging` gives the
    folder to build the new `target` in, swapped into place when its context ends without an exception.
    `recovered` says what the claim found and cleaned up of a killed run, one sentence each."""

    def __init__(self, target: str | os.PathLike[str]) -> None:
        self.target = Path(target)
        self.parent = self.target.parent
        self.lock_path = self.parent / f".{self.target.name}.lock"
        self.recovered: list[str] = []
        self._fd: int | None = None
        self._created: list[Path] = []
        self._pattern = re.compile(re.escape(f".{self.target.name}.") + r"(staging|aside)-\d+-[0-9a-f]{8}")

    def __enter__(self) -> FolderClaim:
        self._created = _make_parents(self.parent)
        try:
            self._fd = self._lock()
            check_unused(self.target)  # a live run reads it (`hrc.io.folder_use`)
            self.recovered = self._undo(self._journal(self._fd), found=True)
            os.ftruncate(self._fd, 0)
            self._append(f"{_HEADER}{os.getpid()}\n")
        except BaseException:
            self._release()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self._release()

    # --- the lock and its journal ---------------------------------------------------------------------

    def _lock(self) -> int:
        """The journal, open and locked by this process. Raises `InputError` when a live process holds it
        for longer than `LOCK_WAIT` seconds (a killed compile's workers hold it until they are gone, a
        moment after their parent)."""
        deadline = time.monotonic() + LOCK_WAIT
        while True:
            fd = os.open(self.lock_path, os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0), 0o666)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                pid = self._holder(fd)
                os.close(fd)
                if time.monotonic() < deadline:
                    time.sleep(0.05)
                    continue
                raise InputError(str(self.target), "", f"another process{f' (pid {pid})' if pid else ''} is "
                                 f"writing this output folder now (it holds {self.lock_path.name} beside it); "
                                 "wait for it to end, or stop it") from None
            except BaseException:
                os.close(fd)
                raise
            # the holder before us removes the file when it is done: locked, it must still be the file
            with contextlib.suppress(FileNotFoundError):
                here, now = os.fstat(fd), os.stat(self.lock_path)
                if (here.st_dev, here.st_ino) == (now.st_dev, now.st_ino):
                    return fd
            os.close(fd)

    def _journal(self, fd: int) -> list[str]:
        return os.pread(fd, 1 << 20, 0).decode("utf-8", "replace").splitlines()

    def _holder(self, fd: int) -> str:
        lines = self._journal(fd)
        return lines[0].removeprefix(_HEADER) if lines and lines[0].startswith(_HEADER) else ""

    def _append(self, line: str) -> None:
        assert self._fd is not None
        data = line.encode("utf-8")
        os.lseek(self._fd, 0, os.SEEK_END)
        while data:
            data = data[os.write(self._fd, data):]
        os.fsync(self._fd)

    def _new(self, kind: str) -> Path:
        """A name for a folder of `kind` beside the target, journaled (and flushed) before it is made."""
        name = f".{self.target.name}.{kind}-{os.getpid()}-{secrets.token_hex(4)}"
        self._append(f"{kind} {name}\n")
        return self.parent / name

    def _undo(self, journal: list[str], found: bool) -> list[str]:
        """Undo what `journal` says was made beside the target: an aside folder goes back to the target
        when the target is missing (a swap cut between its renames), every other one is removed. `found`:
        a killed run's journal (say what was done) rather than this claim's own. Returns what was done."""
        pid = journal[0].removeprefix(_HEADER) if journal and journal[0].startswith(_HEADER) else "?"
        entries = []
        for line in journal[1:]:
            kind, _, name = line.partition(" ")
            match = self._pattern.fullmatch(name)
            if match is not None and match.group(1) == kind:
                entries.append((kind, self.parent / name))
        done = []
        for kind, path in sorted(entries, key=lambda e: e[0] != "aside"):  # an aside first: it may go back
            if not path.is_dir() or path.is_symlink():
                continue
            if kind == "aside" and not _exists(self.target):
                os.rename(path, self.target)
                fsync_folder(self.parent)
                done.append(f"put the earlier output back in {self.target}: a run (pid {pid}) was stopped in "
                            "the middle of replacing it")
            elif _remove(path):
                done.append(f"removed {path.name}, left by a run (pid {pid}) that was killed")
            else:  # pragma: no cover - a file the process may not remove: the journal keeps it for later
                raise OSError(errno.ENOTEMPTY, "cannot remove the leftover of a killed run", str(path))
        if done or entries:
            fsync_folder(self.parent)
        return done if found else []

    def _release(self) -> None:
        """Undo this claim's own leftovers (a staging folder, an aside one), remove the journal and unlock."""
        fd, self._fd = self._fd, None
        if fd is not None:
            try:
                self._undo(self._journal(fd), found=False)
                self.lock_path.unlink()  # still locked: no other claim has it
            except OSError:  # the journal stays for the next claim, which finishes the cleaning
                pass
            finally:
                os.close(fd)
        for p in self._created:  # folders made for the target, deepest first; only while empty
            with contextlib.suppress(OSError):
                p.rmdir()

    # --- building and swapping ------------------------------------------------------------------------

    @contextlib.contextmanager
    def staging(self, check_earlier: Callable[[Path, Path], None] | None = None) -> Iterator[Path]:
        """A new, empty staging folder beside the target (permissions as ``mkdir`` gives); when the
        context ends without an exception it replaces the target (the swap: module docstring), and on
        any exception it is removed and the target left as it was.

        `check_earlier(earlier, new)`: called during the swap with the earlier target folder once it no
        longer has the target's name (nothing can be added to it through that name then) and the new
        one; if it raises, the swap is undone (the target is the earlier folder again) and the exception
        goes on. The compile refuses there to remove files it did not write."""
        if self._fd is None:
            raise ValueError("staging() outside the claim's context")
        path = self._new("staging")
        os.mkdir(path)
        try:
            yield path
            self._swap(path, check_earlier)
        except BaseException:
            _remove(path)
            raise

    def _swap(self, staging: Path, check_earlier: Callable[[Path, Path], None] | None) -> None:
        sync_tree(staging)
        with exclusive(self.target):  # no live run reads the earlier target, none starts during the swap
            self._swap_held(staging, check_earlier)

    def _swap_held(self, staging: Path, check_earlier: Callable[[Path, Path], None] | None) -> None:
        target = self.target
        if not _exists(target):
            os.rename(staging, target)
            fsync_folder(self.parent)
            return
        if exchange(staging, target):  # the staging name holds the earlier output now
            try:
                if check_earlier is not None:
                    check_earlier(staging, target)
            except BaseException:
                exchange(staging, target)
                raise
            fsync_folder(self.parent)
            _remove(staging)
            return
        aside = self._new("aside")
        os.rename(target, aside)
        try:
            if check_earlier is not None:
                check_earlier(aside, staging)
            os.rename(staging, target)
        except BaseException:
            os.rename(aside, target)
            raise
        fsync_folder(self.parent)
        _remove(aside)
