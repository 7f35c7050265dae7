"""The loop of ``hrc dispatch``: JSON lines from a file descriptor (stdin), one answer a line out, each
message in the log before its answer is printed, several messages per ``fsync`` when they come fast.

**Group commit.** The loop answers every whole line that has already arrived (up to `BATCH` of them,
or for up to `BATCH_WAIT` seconds), then commits them to the log with one sync
(`hrc.dispatch.durable.LoggedDispatcher.commit`) and only then prints their answers; a lone message is
committed and answered at once. So a burst of messages costs one ``fsync``, not one each, and no
answer is printed before its message is on disk.

**Bounded memory.** Lines are read in 64 KiB chunks; a line longer than `MAX_LINE` is never held
whole: it is streamed into the log in parts (`LoggedDispatcher.take_long`) and refused. Splitting is
on ``\\n`` only.
"""

from __future__ import annotations

import gc
import json
import os
import select
import sys
import time
from collections.abc import Iterator
from typing import IO

from hrc.errors import HrcError, LogWriteError

from .durable import LoggedDispatcher, log_refusal
from .limits import MAX_LINE
from .on_demand import OnDemand, wanted

__all__ = ["BATCH", "BATCH_WAIT", "LineSource", "serve"]

BATCH = 256
"""Most messages answered per commit."""
BATCH_WAIT = 0.005
"""Seconds: a batch is committed once its first answer has waited this long (or no more input has come)."""
_CHUNK = 1 << 16


class LineSource:
    """Lines from a file descriptor, split on ``\\n`` only, without waiting when asked not to.

    `next(wait)` gives ``("line", bytes)`` (at most ``MAX_LINE + 1`` bytes, no ``\\n``), ``("long", b"")``
    when the next line is longer (read it with `long_line`), ``("none", b"")`` when nothing has arrived
    and `wait` is false, or ``("eof", b"")``. A last line without ``\\n`` counts as a line.
    """

    def __init__(self, fd: int) -> None:
        self.fd = fd
        self.buf = bytearray()
        self.eof = False

    def _read(self, wait: bool) -> bool:
        """More bytes into the buffer; False when none came (nothing yet, or the end)."""
        if self.eof:
            return False
        if not wait and not select.select([self.fd], [], [], 0)[0]:
            return False
        data = os.read(self.fd, _CHUNK)
        if not data:
            self.eof = True
            return False
        self.buf += data
        return True

    def next(self, wait: bool) -> tuple[str, bytes]:
        searched = 0
        while True:
            end = self.buf.find(b"\n", searched, MAX_LINE + 2)
            if end >= 0:
                line = bytes(self.buf[:end])
                del self.buf[:end + 1]  # cheap: CPython's bytearray deletes from the front in O(1)
                return "line", line
            if len(self.buf) > MAX_LINE + 1:
                return "long", b""
            searched = len(self.buf)
            if not self._read(wait):
                if not self.eof:
                    return "none", b""
                if self.buf:
                    line = bytes(self.buf)
                    self.buf.clear()
                    return "line", line
                return "eof", b""

    def long_line(self) -> Iterator[bytes]:
        """The over-long line `next` announced, in chunks, its ``\\n`` consumed (read to the end: its
        consumer must exhaust it)."""
        while True:
            end = self.buf.find(b"\n")
            if end >= 0:
                chunk = bytes(self.buf[:end])
                del self.buf[:end + 1]
                yield chunk
                return
            if self.buf:
                chunk = bytes(self.buf)
                self.buf.clear()
                yield chunk
            if not self._read(wait=True) and self.eof:
                return


def _flush(logged: LoggedDispatcher, answers: list[str], out: IO[str]) -> None:
    if not answers:
        return
    try:
        logged.commit()
        lines = answers
    except LogWriteError as err:  # none of them changed anything
        lines = [log_refusal(a, err) for a in answers]
    out.write("".join(line + "\n" for line in lines))
    out.flush()
    answers.clear()


def serve(logged: LoggedDispatcher, fd_in: int, out: IO[str], on_demand: OnDemand | None = None) -> int:
    """Answer every line of `fd_in` on `out` until the end of the input; 0. `on_demand`: compile plans in
    the background when no plan agrees with what was seen (`hrc.dispatch.on_demand`), adopted before the
    first message after they came.

    The plan set loaded before moves to the garbage collector's permanent generation while this runs: a
    full collection would scan it (about 100 ms for the workshop's console) in front of an answer.
    """
    gc.freeze()
    try:
        return _serve(logged, LineSource(fd_in), out, on_demand)
    finally:
        gc.unfreeze()
        if on_demand is not None:
            on_demand.close()


def _adopt(logged: LoggedDispatcher, on_demand: OnDemand | None, answers: list[str], out: IO[str]) -> None:
    """Plans compiled on demand that have come: the answers before them out, then the plans into the log
    and the state (`LoggedDispatcher.add_plans`). A failure is said on stderr; the run goes on."""
    if on_demand is None or not on_demand.running:
        return
    try:
        got = on_demand.done()
        if got is None:
            return
        _flush(logged, answers, out)
        n = logged.add_plans(*got)
        print(f"hrc dispatch: compiled on demand: {n} new plans after message {logged.messages}",
              file=sys.stderr, flush=True)
        on_demand.ask(wanted(logged.working))  # the person may have gone on meanwhile
    except (HrcError, LogWriteError) as err:
        print(f"hrc dispatch: {' '.join(str(err).split())[:300]}", file=sys.stderr, flush=True)


def _serve(logged: LoggedDispatcher, source: LineSource, out: IO[str], on_demand: OnDemand | None = None) -> int:
    answers: list[str] = []
    oldest = 0.0
    while True:
        if answers and (len(answers) >= BATCH or time.monotonic() - oldest > BATCH_WAIT):
            _flush(logged, answers, out)
        kind, data = source.next(wait=not answers)
        if kind in ("line", "long"):
            _adopt(logged, on_demand, answers, out)
        if kind == "none":
            _flush(logged, answers, out)
        elif kind == "eof":
            _flush(logged, answers, out)
            return 0
        elif kind == "long":
            _flush(logged, answers, out)
            out.write(logged.take_long(source.long_line()) + "\n")
            out.flush()
        else:
            if not answers:
                oldest = time.monotonic()
            answers.append(_take(logged, data))
            if on_demand is not None:
                on_demand.ask(wanted(logged.working))


def _take(logged: LoggedDispatcher, data: bytes) -> str:
    """`LoggedDispatcher.take`, supervised: it answers every message itself (`protocol.answer` turns a
    defect into that message's refusal); should anything around it fail, the message is refused here,
    said once on stderr, and the loop goes on (issue 34)."""
    try:
        return logged.take(data)
    except Exception as err:  # noqa: BLE001 - one message must not end the run
        why = f"internal error ({type(err).__name__}: {err}); nothing changed"
        print(f"hrc dispatch: {' '.join(why.split())[:300]}", file=sys.stderr, flush=True)
        return json.dumps({"t": None, "ok": False, "error": " ".join(why.split())[:500]})
