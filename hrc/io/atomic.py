"""Atomic file output: write to a temporary file beside the target, then rename over it.

A reader (or a crash) never sees a half-written file. `atomic_dir` does the same for a whole output
folder: it is built under a temporary name and renamed into place when complete.
"""

from __future__ import annotations

import contextlib
import errno
import functools
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

__all__ = ["atomic_dir", "write_bytes_atomic", "write_text_atomic"]


@functools.cache
def _umask() -> int:
    """The process umask (read once: `os.umask` can only be read by setting it, briefly)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> None:
    """Write `data` to `path` so that readers see the old file or the new one, never a part.

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
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_text_atomic(path: str | os.PathLike[str], text: str) -> None:
    write_bytes_atomic(path, text.encode("utf-8"))


def _make_parents(folder: Path) -> list[Path]:
    """``mkdir -p folder``; returns the folders it created, deepest first (to remove them on failure)."""
    missing = []
    for p in (folder, *folder.parents):
        if p.exists() or p.is_symlink():
            break
        missing.append(p)
    folder.mkdir(parents=True, exist_ok=True)
    return missing


def _remove_created(created: list[Path]) -> None:
    for p in created:  # deepest first; only while empty (nothing of anybody else's is removed)
        with contextlib.suppress(OSError):
            p.rmdir()


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a fresh staging folder; on success it replaces `path` (an existing folder is swapped out).

    On any failure (an exception, KeyboardInterrupt, a failed rename) the staging folder is removed,
    the folders made for it too, and an existing `path` is left as it was.
    """
    target = Path(path)
    created = _make_parents(target.parent)
    try:
        staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=target.parent))
    except BaseException:
        _remove_created(created)
        raise
    try:
        yield staging
        os.chmod(staging, 0o777 & ~_umask())  # mkdtemp makes it private (0o700)
        old = None
        if target.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{target.name}.old.", dir=target.parent))
            try:
                os.replace(target, old / "x")
            except BaseException:
                old.rmdir()
                raise
        try:
            os.replace(staging, target)
        except BaseException:
            if old is not None:  # put the earlier output back
                os.replace(old / "x", target)
                old.rmdir()
            raise
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        _remove_created(created)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
