"""Bounds for reading network files from strangers: how much, which files, which numbers, and how errors
name what they found.

Every reader of `hrc.temporal` takes its bytes from `read_bounded` and its integers from `parse_int`, and
writes names and snippets into error messages through `show`, so that a hostile or odd file ends in one
`NetworkFileError` line, quickly, in bounded memory:

* only regular files are read (a FIFO, ``/dev/zero``, a terminal or a folder is refused before any byte is
  read; a FIFO is opened non-blocking, so refusing it cannot hang), and at most `MAX_FILE_BYTES`;
* a network file holds at most `MAX_TIMEPOINTS` timepoints and `MAX_BOUNDS` finite bounds (edges of the
  distance graph), counted while reading, so that reading and checking the largest accepted network stays
  well within 2 GiB (about 1 KB per bound all told);
* integers are ASCII digits with an optional sign, at most `MAX_DIGITS` of them, checked *before*
  conversion (Python's ``int()`` accepts other scripts' digits, refuses more than 4,300 and takes
  quadratic time below that); decimal bounds (HEATlab) are within ``±MAX_MAGNITUDE`` units;
* names, file paths and snippets are shown with control characters, quotes and non-printing characters
  escaped (``repr`` style) and cut to `SHOW_CHARS`, so a message is always one line.

>>> show("a\\nb")
"'a\\\\nb'"
>>> parse_int(" -42 ", "f", "k", 1)
-42
"""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path

from hrc.errors import NetworkFileError

__all__ = ["MAX_BOUNDS", "MAX_DIGITS", "MAX_FILE_BYTES", "MAX_MAGNITUDE", "MAX_TIMEPOINTS", "SHOW_CHARS",
           "check_size", "parse_int", "read_bounded", "show", "show_path"]

MAX_FILE_BYTES = 256 * 2**20
"""Largest network file read (256 MiB; a 100,000-timepoint GraphML file is about 40 MiB)."""
MAX_DIGITS = 40
"""Most digits in an integer of a network file (room for HEATlab networks scaled to exact integers and
written back as GraphML; far below what could slow arithmetic down)."""
MAX_MAGNITUDE = 10**15
"""Largest absolute value of a decimal bound of a HEATlab file, in the file's unit."""
MAX_TIMEPOINTS = 500_000
"""Most timepoints in a network file."""
MAX_BOUNDS = 1_000_000
"""Most finite bounds (two per requirement or contingent link with both bounds) in a network file."""
SHOW_CHARS = 80
"""Longest name or snippet quoted in an error message."""

_INT = re.compile(r"[+-]?[0-9]+")


def show(text: str) -> str:
    """``text`` quoted for a one-line message: ``repr`` escapes (newlines, tabs, control and non-printing
    characters), cut to `SHOW_CHARS` characters with ``...`` marking the cut."""
    if len(text) > SHOW_CHARS:
        return repr(text[:SHOW_CHARS]) + "..."
    return repr(text)


def show_path(path: str | os.PathLike[str]) -> str:
    """A file path for messages: as given, unless it holds characters that would break the line."""
    text = os.fspath(path)
    return text if text.isprintable() else show(text)


def read_bounded(path: str | os.PathLike[str], file: str) -> bytes:
    """The bytes of the regular file ``path`` (at most `MAX_FILE_BYTES`); ``file`` names it in errors.

    Raises `NetworkFileError` for a missing or unreadable file, anything but a regular file, and a file
    over the limit (also one that grows past it while being read).
    """
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_NOCTTY", 0) | getattr(os, "O_BINARY", 0)
    try:
        fd = os.open(Path(path), flags)
    except OSError as err:
        raise NetworkFileError(file, "", f"cannot read: {err.strerror or err}") from err
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise NetworkFileError(file, "", f"not a regular file ({_kind(info.st_mode)}); give an STNU file")
        if info.st_size > MAX_FILE_BYTES:
            raise NetworkFileError(file, "", f"file is {info.st_size:,} bytes, over the limit of "
                                             f"{MAX_FILE_BYTES:,} bytes for a network file")
        chunks: list[bytes] = []
        total = 0
        while True:
            chunk = os.read(fd, min(1 << 20, MAX_FILE_BYTES + 1 - total))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
            if total > MAX_FILE_BYTES:
                raise NetworkFileError(file, "", f"file grew over the limit of {MAX_FILE_BYTES:,} bytes while "
                                                 "being read")
        return b"".join(chunks)
    except OSError as err:
        raise NetworkFileError(file, "", f"cannot read: {err.strerror or err}") from err
    finally:
        os.close(fd)


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a folder"
    if stat.S_ISFIFO(mode):
        return "a FIFO"
    if stat.S_ISCHR(mode):
        return "a character device"
    if stat.S_ISBLK(mode):
        return "a block device"
    if stat.S_ISSOCK(mode):
        return "a socket"
    return "not a plain file"


def parse_int(text: str, file: str, key: str, line: int | None, *, what: str = "an integer") -> int:
    """``text`` (surrounding white space allowed) as an int of at most `MAX_DIGITS` ASCII digits; raises
    `NetworkFileError` naming ``file``, ``line`` and ``key`` otherwise."""
    token = text.strip()
    if not _INT.fullmatch(token):
        raise NetworkFileError(file, key, f"expected {what}, found {show(token)}", line)
    digits = len(token) - (token[0] in "+-")
    if digits > MAX_DIGITS:
        raise NetworkFileError(file, key, f"{what} with {digits} digits is out of range (at most {MAX_DIGITS} "
                                          "digits)", line)
    return int(token)


def check_size(timepoints: int, bounds: int, file: str, line: int | None = None) -> None:
    """Refuse a network over `MAX_TIMEPOINTS` timepoints or `MAX_BOUNDS` bounds (`NetworkFileError`)."""
    if timepoints > MAX_TIMEPOINTS:
        raise NetworkFileError(file, "", f"more than {MAX_TIMEPOINTS:,} timepoints, over the limit for a network "
                                         "file", line)
    if bounds > MAX_BOUNDS:
        raise NetworkFileError(file, "", f"more than {MAX_BOUNDS:,} bounds, over the limit for a network file", line)
