"""A dispatcher whose state changes only once the message is in its log (write-ahead), and crash resume.

**Write-ahead.** `LoggedDispatcher.take` answers a message on a copy of the dispatcher's state
(`Dispatcher.fork`, O(1): each accepted message replaces the state whole) and queues the message and
its answer for the log; `commit` appends them and syncs the file, and only then does the copy become
the state. The caller gives the answers out after `commit` returns. If the log cannot be written,
`commit` drops the copy and raises `LogWriteError`: the state is as it was before those messages, and
the caller refuses them. So nothing answered is ever missing from the log, and nothing missing from
the log ever changed the state. Several messages may share one `commit`, one ``fsync`` (group
commit; ``hrc dispatch`` does so with whatever input has arrived).

**What is synced.** A commit with an accepted message is ``fsync``'d before it returns. A commit of
refusals only is written but not synced (a refusal changes nothing, so a power cut that loses one
loses no state; the next accepted message's ``fsync`` carries it to disk): a flood of bad messages
costs writes, not syncs. A ``kill -9`` loses nothing written.

**Resume** (`LoggedDispatcher.resume`): the log is locked, read (a torn end is dropped:
`hrc.dispatch.logfile.Torn`), every message is replayed through a fresh dispatcher (deterministic:
time comes only with the messages) and each answer checked against the logged one; then the torn end
is cut off, a ``{"resumed": N}`` record appended, and the run goes on appending to the same log,
answering as the uninterrupted run would have.

**Listeners.** `listeners` are called with each message's bytes and its answer once they are committed
(in the log, or given out when there is no log), in order: what was answered, never what a failed
commit took back. ``--record`` hangs its MCAP recorder here (`hrc.record`). A listener must not raise:
the state is committed before it is called (the recorder catches its own failures and stops recording).
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

from hrc.compile.extend import Prefix
from hrc.errors import InputError, LogWriteError

from .dispatcher import Dispatcher
from .limits import MAX_LINE
from .logfile import (
    LOG_VERSION,
    PART,
    LogWriter,
    Message,
    Torn,
    encode_answer,
    encode_input,
    encode_input_part,
    encode_plans,
)
from .on_demand import Added, PlanRows, Replay, adopt, announce, rows_digest
from .protocol import answer, is_accepted, log_header

__all__ = ["LoggedDispatcher", "Resumed", "log_refusal"]


@dataclass(frozen=True, slots=True)
class Resumed:
    """What `LoggedDispatcher.resume` did: the `replayed` messages (each answered as logged), the `torn`
    end dropped (None: none), and how many times the run had been resumed before."""

    replayed: tuple[Message, ...]
    torn: Torn | None
    before: int

    @property
    def messages(self) -> int:
        return len(self.replayed)


def log_refusal(answer_line: str, err: LogWriteError) -> str:
    """The refusal that replaces `answer_line` when its message could not be logged (same ``t``)."""
    try:
        t = json.loads(answer_line).get("t")
    except ValueError:
        t = None
    return json.dumps({"t": t, "ok": False, "error": f"refused: {err}; nothing changed"}, ensure_ascii=False)


class LoggedDispatcher:
    """A `Dispatcher` and the log it writes ahead of every change (`log` None: no log, same interface).

    `dispatcher` is the committed state: what every reader (the console's page, the robot) sees.
    Not thread-safe: one caller at a time (``hrc dispatch``'s loop, the console's event loop).
    """

    def __init__(self, dispatcher: Dispatcher, log: LogWriter | None = None) -> None:
        self._committed = dispatcher
        self.log = log
        self._work: Dispatcher | None = None
        self._records: list[bytes] = []
        self._sync = False
        self._taken: list[tuple[bytes, str]] = []
        self.listeners: list[Callable[[bytes, str], None]] = []
        self.messages = 0  # messages taken (the log's count: refusals too)
        self.announce = 0  # plans adopted on demand that the next accepted answer says (`add_plans`)
        self._mark = (0, 0)  # both as of the last commit

    @classmethod
    def create(cls, dispatcher: Dispatcher, path: str | os.PathLike[str]) -> LoggedDispatcher:
        """A fresh run logged to `path`: a new or empty file (`InputError` if it holds a run, or is locked)."""
        return cls(dispatcher, LogWriter.create(path, log_header(dispatcher, LOG_VERSION)))

    @classmethod
    def resume(cls, dispatcher: Dispatcher, path: str | os.PathLike[str]) -> tuple[LoggedDispatcher, Resumed]:
        """The run logged at `path`, rebuilt in `dispatcher` (fresh, over the same compiled folder), to go
        on appending. Raises `InputError` (not a version-2 log, locked, damaged) or `HrcError` (another
        compiled set; an answer that differs from the logged one) and then leaves the file as it was."""
        writer, contents = LogWriter.open_existing(path)
        try:
            if contents.version != LOG_VERSION:
                raise InputError(str(path), "", f"a version-{contents.version} log cannot be resumed (hrc dispatch "
                                                "--replay still reads it)")
            replay = Replay(dispatcher, contents, str(path))  # plans compiled on demand: compiled again
            for number, ((got, was), message) in enumerate(zip(replay, contents.messages, strict=True), 1):
                if got != was:
                    raise InputError(str(path), "", f"message {number}'s answer differs from the logged one (an "
                                                    "edited log, another hrc, or the compiled folder changed?): "
                                                    "not resuming", message.line or None)
            dispatcher = replay.dispatcher
            writer.cut_to(contents.size)
            writer.append(json.dumps({"resumed": len(contents.messages)}).encode("ascii") + b"\n", sync=True)
        except BaseException:
            writer.close()
            raise
        logged = cls(dispatcher, writer)
        logged.messages, logged.announce = len(contents.messages), replay.pending
        logged._mark = (logged.messages, logged.announce)
        return logged, Resumed(contents.messages, contents.torn, contents.resumed)

    @property
    def dispatcher(self) -> Dispatcher:
        """The state as committed (the messages taken since the last `commit` are not in it yet)."""
        return self._committed

    @property
    def working(self) -> Dispatcher:
        """The state with the messages taken since the last `commit` (what their answers said)."""
        return self._work if self._work is not None else self._committed

    @property
    def path(self) -> Path | None:
        return None if self.log is None else self.log.path

    def take(self, data: bytes) -> str:
        """Answer one message (its line's bytes, no ``\\n``), on the copy; given out only after `commit`."""
        work = self._work if self._work is not None else self._committed.fork()
        line = answer(work, data)
        self._work = work
        self.messages += 1
        if self.announce and is_accepted(line):
            line, self.announce = announce(line, self.announce), 0
        if self.log is not None:
            self._records += (encode_input(data), encode_answer(line))
            self._sync = self._sync or is_accepted(line)
        if self.listeners:
            self._taken.append((data, line))
        return line

    def take_line(self, line: str) -> str:
        """`take` for a message as text (the console's own JSON)."""
        return self.take(line.encode("utf-8", "surrogatepass"))

    def commit(self) -> None:
        """The messages taken so far into the log (synced when one was accepted), then into the state.

        Raises `LogWriteError` when the log could not be written: then none of them changed anything.
        """
        work, records, sync, taken = self._work, self._records, self._sync, self._taken
        self._work, self._records, self._sync, self._taken = None, [], False, []
        if self.log is not None and records:
            try:
                self.log.append(b"".join(records), sync=sync)
            except LogWriteError:
                self.messages, self.announce = self._mark  # those messages never were
                raise
        self._mark = (self.messages, self.announce)
        if work is not None:
            self._committed = work
        self._tell(taken)

    def _tell(self, taken: list[tuple[bytes, str]]) -> None:
        for data, line in taken:
            for listener in self.listeners:
                listener(data, line)

    def submit(self, data: bytes) -> str:
        """`take` then `commit`: the answer, or the refusal saying that the log could not be written."""
        line = self.take(data)
        try:
            self.commit()
        except LogWriteError as err:
            return log_refusal(line, err)
        return line

    def add_plans(self, prefix: Prefix, rows: PlanRows) -> int:
        """Adopt plans compiled on demand for `prefix` (`hrc.dispatch.on_demand`), between two messages:
        the messages taken so far committed, the plans' record into the log (synced), then the state takes
        them; the next accepted answer says ``"new_plans"``. How many were new. `LogWriteError`: they
        were not adopted (the messages before are committed or refused as `commit` says)."""
        self.commit()
        work, n = adopt(self._committed, rows)
        if self.log is not None:
            added = Added(self.messages, prefix, tuple(r[0] for r in rows), rows_digest(rows))
            self.log.append(encode_plans(added.record()["plans"]), sync=True)
        self._committed = work
        self.announce = n or self.announce
        self._mark = (self.messages, self.announce)
        return n

    def take_long(self, chunks: Iterable[bytes]) -> str:
        """Answer a message longer than `MAX_LINE` arriving in `chunks` (all of them are read), logging all
        its bytes as they come, in bounded memory; committed at once. It is refused either way (too long);
        if the log fails the refusal says so instead."""
        self.commit()
        log = self.log
        start = 0 if log is None else log.size
        first = bytearray()
        part = bytearray()
        failure: LogWriteError | None = None
        for chunk in chunks:
            first += chunk[:MAX_LINE + 1 - len(first)]
            if log is None or failure is not None:
                continue
            part += chunk
            try:
                while len(part) > PART:
                    log.append(encode_input_part(bytes(part[:PART]), last=False), sync=False)
                    del part[:PART]
            except LogWriteError as err:
                failure = err
        line = answer(self._committed, bytes(first))
        if log is None:
            self.messages += 1
            self._mark = (self.messages, self.announce)
            self._tell([(bytes(first), line)])
            return line
        if failure is None:
            try:
                log.append(encode_input_part(bytes(part), last=True) + encode_answer(line), sync=False)
                self.messages += 1
                self._mark = (self.messages, self.announce)
                self._tell([(bytes(first), line)])
                return line
            except LogWriteError as err:
                failure = err
        try:
            log.cut_to(start)  # none of its parts stays
        except LogWriteError as err:
            failure = err
        return log_refusal(line, failure)

    def close(self) -> None:
        if self.log is not None:
            self.log.close()
