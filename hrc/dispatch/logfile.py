"""The dispatcher's log file: its format, its reader (torn ends dropped) and its locked, appending writer.

Every message a dispatcher is given and every answer it gives, in order, so that a fresh dispatcher
over the same compiled folder replays the run answer for answer (`hrc.dispatch.protocol.replay`) and a
crashed run resumes (`hrc.dispatch.durable`). One JSON record a line; version 2::

    {"hrc_dispatch_log": 2, "compiled": "d41d8cd98f00b204", "plans": 32}     the header
    {"in": "{\\"t\\": 0, \\"event\\": \\"tick\\"}"}                              a message, as text
    {"out": "{\\"t\\": 0.0, \\"ok\\": true, ...}"}                              its answer
    {"in_b64": "/3Q="}                 a message that is not UTF-8: its bytes, base64
    {"in_more": "..."} ... {"in_b64": "..."}     a message longer than MAX_LINE: its bytes in parts
    {"resumed": 12}                    another process took the log over after 12 messages
    {"plans": {"after": 7, "for": {...}, "ids": [...], "sha256": "..."}}   plans compiled on demand,
                                       adopted after 7 messages (`hrc.dispatch.on_demand`)

**Lossless.** A message is stored as the bytes received (less its ``\\n``): over-long, not UTF-8, with
U+2028, U+0085, NUL or anything else in it; records are written with ``ensure_ascii``, so the file is
ASCII and no character of a message can end a record. The reader splits on ``b"\\n"`` only (never
`str.splitlines`, which also splits on U+2028, U+0085, form feeds...).

**Torn ends.** A crash or power cut while a record was written leaves an incomplete last line, or a
message without its answer, or a tail of NUL bytes. `read_log` drops that end and says so (`Torn`).

**Nothing else is reinterpreted** (issue 34: a header line appended at the end made ``--resume`` start
over "after 0 messages", dropping 30 logged ones). A version-2 log is one header, on its first line,
then records in sequence: each message (in parts, for an over-long one) followed by its answer, a
``{"resumed": N}`` only between messages and only with N the number of messages before it. A second
header anywhere, a record out of that sequence, a record that is not strict JSON (`read_json`: a key
given twice, ...) or has other keys than its own, and any damaged *whole* line, at the end too, are
refused (`InputError` naming the line): a crash leaves an incomplete line, never a whole wrong one. An
answer edited in place is found by the replay that ``--resume`` and ``--replay`` make (each `Message`
knows the `line` of its answer).

**Version 1** (before issue 26: text records with ``ensure_ascii=False``, over-long and non-UTF-8
messages replaced by placeholders, so such a replay differs) is still read, for ``--replay``.

**Writer.** `LogWriter` holds the file locked (``fcntl.flock``, exclusive) for as long as the process
lives, so that a second dispatcher on the same log is refused; it appends with ``O_APPEND``; when a
write fails (a full disk) it cuts the file back to its last whole record so that the next write starts
on a clean line; when an ``fsync`` fails it trusts the file no more (`LogWriter.broken`): after such a
failure the kernel may have dropped the unwritten pages and a retried ``fsync`` would succeed falsely
("fsyncgate", PostgreSQL 2018), so only a restart with ``--resume`` (which reads what is really on
disk) goes on.
"""

from __future__ import annotations

import base64
import binascii
import errno
import fcntl
import json
import os
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from hrc.errors import InputError, LogWriteError, MessageError

from .limits import MAX_LINE, read_json

__all__ = ["LOG_VERSION", "PART", "LogContents", "LogWriter", "Message", "Torn", "encode_answer",
           "encode_header", "encode_input", "encode_input_part", "encode_plans", "read_log"]

LOG_VERSION = 2
PART = 49152
"""Bytes of an over-long message per ``in_more``/``in_b64`` record (65,536 characters of base64)."""
_RECORD_MAX = 8 * MAX_LINE  # the longest record a writer makes (a MAX_LINE message, each byte escaped)
_RECORD_KEYS = frozenset({"in", "in_b64", "in_more", "out", "resumed", "plans"})  # each record is one of them, alone


@dataclass(frozen=True, slots=True)
class Message:
    """One logged message: `data`, its bytes (the first ``MAX_LINE + 1`` of them when it was longer:
    enough to give the same answer), `size` its full length in bytes, `answer` the logged answer, and
    `line` the line of the log that holds its answer and `message_line` the line its (first) record starts
    on (1 = the header; 0: not read from a file)."""

    data: bytes
    size: int
    answer: str
    line: int = field(default=0, compare=False)
    message_line: int = field(default=0, compare=False)


@dataclass(frozen=True, slots=True)
class Torn:
    """The damaged end `read_log` dropped: `nbytes` bytes from byte `offset` (line `line`), and why."""

    line: int
    offset: int
    nbytes: int
    why: str

    def __str__(self) -> str:
        return (f"its last record is torn ({self.why}; a crash or power cut mid-write): "
                f"{self.nbytes} bytes from line {self.line} dropped")


@dataclass(frozen=True, slots=True)
class LogContents:
    """What `read_log` found: the `header` of the log's last session, its `messages`, the byte `size`
    of the log up to the end of the last whole message (where a resumed run appends), the `torn` end
    dropped (None: none), and how many times the run was `resumed`."""

    header: Mapping[str, Any]
    messages: tuple[Message, ...]
    size: int
    torn: Torn | None
    resumed: int
    added: tuple[tuple[int, Mapping[str, Any]], ...] = ()  # (messages before, the "plans" record's value)

    @property
    def version(self) -> int:
        return int(self.header["hrc_dispatch_log"])


# -- records ----------------------------------------------------------------------------------------
def _record(obj: Mapping[str, Any]) -> bytes:
    return (json.dumps(obj, ensure_ascii=True, separators=(", ", ": ")) + "\n").encode("ascii")


def encode_input(data: bytes) -> bytes:
    """The record of a message of at most `MAX_LINE` bytes (`data` without its ``\\n``)."""
    try:
        return _record({"in": data.decode("utf-8")})  # strict: no lone surrogates either
    except UnicodeDecodeError:
        return _record({"in_b64": base64.b64encode(data).decode("ascii")})


def encode_input_part(data: bytes, last: bool) -> bytes:
    """One part (at most `PART` bytes) of an over-long message; the last one closes the message."""
    return _record({"in_b64" if last else "in_more": base64.b64encode(data).decode("ascii")})


def encode_answer(answer: str) -> bytes:
    """The record of an answer."""
    return _record({"out": answer})


def encode_plans(value: Mapping[str, Any]) -> bytes:
    """The record of plans compiled on demand (`hrc.dispatch.on_demand.Added.record`'s value)."""
    return _record({"plans": value})


def encode_header(header: Mapping[str, Any]) -> bytes:
    return _record(header)


# -- reading ----------------------------------------------------------------------------------------
class _Damaged(Exception):
    pass


def _lines(path: Path) -> Iterator[tuple[int, bytes]]:
    """(offset, line) for each line of the file, ``\\n`` kept; a line longer than a record is cut there."""
    with open(path, "rb") as fh:
        offset = 0
        while True:
            raw = fh.readline(_RECORD_MAX + 1)
            if not raw:
                return
            yield offset, raw
            offset += len(raw)


def _b64(value: Any) -> bytes:
    if not isinstance(value, str):
        raise _Damaged("base64 expected")
    try:
        return base64.b64decode(value, validate=True)
    except binascii.Error as err:
        raise _Damaged(f"bad base64 ({err})") from None


class _Pending:
    """A message read so far whose answer has not come yet (over-long ones come in parts)."""

    def __init__(self, line: int, offset: int) -> None:
        self.line = line
        self.offset = offset
        self.first = bytearray()
        self.size = 0
        self.closed = False

    def add(self, data: bytes, last: bool) -> None:
        self.first += data[:MAX_LINE + 1 - len(self.first)]
        self.size += len(data)
        self.closed = last


def _input_data(rec: Mapping[str, Any]) -> tuple[bytes, bool]:
    """A message record's bytes, and whether it ends the message."""
    if "in" in rec:
        if not isinstance(rec["in"], str):
            raise _Damaged("'in' must be a string")
        return rec["in"].encode("utf-8", "surrogatepass"), True
    if "in_b64" in rec:
        return _b64(rec["in_b64"]), True
    return _b64(rec["in_more"]), False


def read_log(path: str | os.PathLike[str]) -> LogContents:
    """The log's last session: its header, its messages, where its whole records end, its torn end.

    Raises `InputError` naming the line at fault when the file is not a dispatcher log or is damaged
    before its end. Reads the file once, record by record (memory: the messages, each cut to
    ``MAX_LINE + 1`` bytes).
    """
    file = Path(path)
    if not file.is_file():
        raise InputError(str(file), "", "no such log file" if not file.exists() else "the log must be a regular file")
    header: dict[str, Any] | None = None
    messages: list[Message] = []
    pending: _Pending | None = None
    added: list[tuple[int, Mapping[str, Any]]] = []
    good = resumed = number = 0
    try:
        for offset, raw in _lines(file):
            number += 1
            try:
                if not raw.endswith(b"\n"):
                    raise _Damaged("an incomplete line" if len(raw) <= _RECORD_MAX else "a line longer than any record")
                try:
                    rec = read_json(raw, max_bytes=_RECORD_MAX + 1, max_depth=4)
                except MessageError as err:
                    raise _Damaged(f"not a JSON record: {err}") from None
                if not isinstance(rec, dict):
                    raise _Damaged("not a log record")
                if "hrc_dispatch_log" in rec:
                    if rec["hrc_dispatch_log"] not in (1, LOG_VERSION):
                        raise _Damaged(f"an unknown log version {rec['hrc_dispatch_log']!r}")
                    if header is not None and (header["hrc_dispatch_log"], rec["hrc_dispatch_log"]) != (1, 1):
                        raise InputError(str(file), "", "a header line inside the log (a log has one header, "
                                                        "on its first line): the log is damaged; not read as a "
                                                        "shorter one", number)
                    # version 1 appended a header per run: replay the last session; a message left
                    # without its answer before it was never answered
                    header, messages, pending, resumed = rec, [], None, 0
                    added = []
                    good = offset + len(raw)
                elif header is None:
                    raise InputError(str(file), "", "not an hrc dispatch log (no header line)", number)
                elif header["hrc_dispatch_log"] == LOG_VERSION and (len(rec) != 1 or not set(rec) <= _RECORD_KEYS):
                    raise _Damaged(f"not a log record (keys {', '.join(sorted(rec))[:80]})")
                elif "in" in rec or "in_b64" in rec or "in_more" in rec:
                    if pending is not None and pending.closed:
                        raise _Damaged("a message after a message without its answer")
                    if pending is not None and "in" in rec:
                        raise _Damaged("a text message inside the parts of an over-long one")
                    data, last = _input_data(rec)
                    pending = pending or _Pending(number, offset)
                    pending.add(data, last)
                elif "out" in rec:
                    if pending is None or not pending.closed:
                        raise _Damaged("an answer without its message")
                    if not isinstance(rec["out"], str):
                        raise _Damaged("'out' must be a string")
                    messages.append(Message(bytes(pending.first), pending.size, rec["out"], number, pending.line))
                    pending = None
                    good = offset + len(raw)
                elif "plans" in rec and pending is None:
                    if not isinstance(rec["plans"], dict) or rec["plans"].get("after") != len(messages):
                        raise InputError(str(file), "", "records out of sequence: plans added after "
                                                        f"{str(rec['plans'])[:40]}, but {len(messages)} messages "
                                                        "came before: the log is damaged", number)
                    added.append((len(messages), rec["plans"]))
                    good = offset + len(raw)
                elif "resumed" in rec and pending is None:
                    if header["hrc_dispatch_log"] == LOG_VERSION and (isinstance(rec["resumed"], bool) or
                                                                      rec["resumed"] != len(messages)):
                        raise InputError(str(file), "", f"records out of sequence: resumed after "
                                                        f"{str(rec['resumed'])[:20]} messages, but {len(messages)} "
                                                        "came before: the log is damaged", number)
                    resumed += 1
                    good = offset + len(raw)
                else:
                    raise _Damaged("not a log record")
            except _Damaged as err:
                return replace(_torn_end(file, header, messages, good, resumed, number, offset, pending, str(err)),
                               added=tuple(added))
    except OSError as err:
        raise InputError(str(file), "", f"cannot read the log ({err.strerror or err})") from err
    if header is None:
        raise InputError(str(file), "", "not an hrc dispatch log (no header line)")
    torn = None
    if pending is not None:
        torn = Torn(pending.line, pending.offset, file.stat().st_size - pending.offset, "a message without its answer")
    return LogContents(header, tuple(messages), good, torn, resumed, tuple(added))


def _torn_end(file: Path, header: dict[str, Any] | None, messages: list[Message], good: int, resumed: int,
              number: int, offset: int, pending: _Pending | None, why: str) -> LogContents:
    """A bad record at line `number`: a torn end if it is an incomplete line and nothing but NUL padding
    follows, else damage."""
    if header is None:
        raise InputError(str(file), "", f"not an hrc dispatch log ({why})", number)
    with open(file, "rb") as fh:
        fh.seek(offset)
        raw = fh.readline(_RECORD_MAX + 1)
    if raw.endswith(b"\n") and raw.strip(b"\x00 \t\r\n"):  # whole: a crash leaves no such line
        raise InputError(str(file), "", f"damaged record ({why}): the log is damaged, not just torn at its end",
                         number)
    with open(file, "rb") as fh:
        fh.seek(offset)
        fh.readline(_RECORD_MAX + 1)  # the bad line itself
        for chunk in iter(lambda: fh.read(1 << 16), b""):
            if chunk.strip(b"\x00 \t\r\n"):
                raise InputError(str(file), "", f"damaged record ({why}) followed by more records: the log is "
                                                "damaged, not just torn at its end", number)
    line, start = (pending.line, pending.offset) if pending is not None else (number, offset)
    size = file.stat().st_size
    return LogContents(header, tuple(messages), good, Torn(line, start, size - start, why), resumed)


# -- writing ----------------------------------------------------------------------------------------
class LogWriter:
    """Appends to a log it holds locked for the life of the process (see the module docstring).

    Open with `create` (a new or empty file: writes the header) or `open_existing` (a log to resume).
    `append` writes whole records or none: on failure the file is cut back and `LogWriteError` raised;
    after a failed sync the writer is `broken` and refuses everything.
    """

    def __init__(self, path: Path, fd: int, size: int) -> None:
        self.path = path
        self._fd = fd
        self.size = size  # bytes of whole records
        self.broken: str | None = None

    @staticmethod
    def _open_locked(path: Path, create: bool) -> int:
        if path.exists() and not path.is_file():
            raise InputError(str(path), "", "the log must be a regular file")
        flags = os.O_RDWR | os.O_APPEND | os.O_CLOEXEC | (os.O_CREAT if create else 0)
        try:
            fd = os.open(path, flags, 0o644)
        except OSError as err:
            raise InputError(str(path), "", f"cannot open the log ({err.strerror or err})") from err
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError as err:
            os.close(fd)
            if err.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise InputError(str(path), "", "in use: another hrc dispatch or console holds this log "
                                                "(one process per log)") from err
            raise InputError(str(path), "", f"cannot lock the log ({err.strerror or err})") from err
        return fd

    @classmethod
    def create(cls, path: str | os.PathLike[str], header: Mapping[str, Any]) -> LogWriter:
        """A new log at `path` (an existing empty file will do) with `header` written and synced."""
        file = Path(path)
        file.parent.mkdir(parents=True, exist_ok=True)
        fd = cls._open_locked(file, create=True)
        writer = cls(file, fd, 0)
        try:
            if os.fstat(fd).st_size:
                raise InputError(str(file), "", "this log holds a run already: continue it with --resume, "
                                                "or give a new file")
            writer.append(encode_header(header), sync=True)
            _sync_folder(file.parent)
        except BaseException:
            writer.close()
            raise
        return writer

    @classmethod
    def open_existing(cls, path: str | os.PathLike[str]) -> tuple[LogWriter, LogContents]:
        """The existing log at `path`, locked, and what it holds (`read_log`); nothing written yet: a
        resumed run first cuts off the torn end (`cut_to` ``contents.size``)."""
        file = Path(path)
        if not file.exists():
            raise InputError(str(file), "", "no such log file")
        fd = cls._open_locked(file, create=False)
        try:
            contents = read_log(file)
        except BaseException:
            os.close(fd)
            raise
        return cls(file, fd, contents.size), contents

    def cut_to(self, size: int) -> None:
        """Cut the file back to `size` bytes (whole records), synced; `LogWriteError` (and `broken`) if not."""
        try:
            if os.fstat(self._fd).st_size != size:
                os.ftruncate(self._fd, size)
                os.fsync(self._fd)
        except OSError as err:
            self.broken = f"the log cannot be cut back to its last whole record ({err.strerror or err})"
            raise LogWriteError(self.broken) from err
        self.size = size

    def _write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            view = view[os.write(self._fd, view):]

    def _sync(self) -> None:
        os.fsync(self._fd)

    def append(self, data: bytes, sync: bool) -> None:
        """Append whole records (`data`), synced to disk when `sync`; `LogWriteError` if not done, and
        then the file is cut back to where it was (after a failed sync, as far as the kernel lets us)."""
        if self.broken is not None:
            raise LogWriteError(self.broken)
        before = self.size
        try:
            self._write(data)
        except OSError as err:
            why = f"the log cannot be written ({err.strerror or err})"
            try:
                os.ftruncate(self._fd, before)  # no half record for the next one to follow
            except OSError as cut:
                self.broken = f"{why}, nor cut back ({cut.strerror or cut}); restart with --resume"
                raise LogWriteError(self.broken) from err
            raise LogWriteError(why) from err
        self.size = before + len(data)
        if not sync:
            return
        try:
            self._sync()
        except OSError as err:
            self.broken = (f"the log could not be synced ({err.strerror or err}): nothing more is accepted; "
                           "restart with --resume")
            try:  # what was refused must not come back on resume: take it out of the file
                os.ftruncate(self._fd, before)
                self.size = before
                os.fsync(self._fd)
            except OSError:
                pass
            raise LogWriteError(self.broken) from err

    def close(self) -> None:
        """Release the file (and its lock)."""
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1


def _sync_folder(folder: Path) -> None:
    """The folder's entry for a new file on disk too (a new file's name lives in its folder)."""
    fd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)
