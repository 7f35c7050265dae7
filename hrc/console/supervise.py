"""What keeps the console answering when something goes wrong: one line per interval for repeated
faults, not one per event (issue 34: 1,100 idle connections wrote 117 MB of errors in 12 s).

`Throttle` says a kind of fault at most once per `interval` seconds, with how many more there were;
`ThrottleFilter` does the same for a `logging` logger (uvicorn's and asyncio's, whose errors on a
refused upgrade or a failed ``accept()`` would otherwise be written once per event).

>>> now = iter([0.0, 0.1, 0.2, 1.5])
>>> said = []
>>> throttle = Throttle(said.append, interval=1.0, clock=lambda: next(now))
>>> for _ in range(4):
...     _ = throttle.note("accept", "hrc console: cannot accept a connection")
>>> said
['hrc console: cannot accept a connection', 'hrc console: cannot accept a connection (2 more like it since)']
"""

from __future__ import annotations

import logging
import sys
import time
from collections.abc import Callable

__all__ = ["INTERVAL", "DenialFilter", "Throttle", "ThrottleFilter", "stderr_line"]

INTERVAL = 1.0
"""Seconds: a kind of fault is said at most this often."""


def stderr_line(text: str) -> None:
    """`text` as one line on stderr (what the operator reads)."""
    print(" ".join(text.split())[:500], file=sys.stderr, flush=True)


class Throttle:
    """Say each kind of fault at most once per `interval` (with the count of those not said since);
    `count` holds how many of each kind there were in all."""

    def __init__(self, say: Callable[[str], None] = stderr_line, interval: float = INTERVAL,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.say = say
        self.interval = interval
        self.clock = clock
        self.count: dict[str, int] = {}
        self._told: dict[str, tuple[float, int]] = {}  # kind -> (when last said, how many since)

    def note(self, kind: str, text: str) -> bool:
        """One fault of `kind`; True when `text` was said now."""
        self.count[kind] = self.count.get(kind, 0) + 1
        now = self.clock()
        at, since = self._told.get(kind, (-self.interval - 1.0, 0))
        if now - at < self.interval:
            self._told[kind] = (at, since + 1)
            return False
        self._told[kind] = (now, 0)
        self.say(text if not since else f"{text} ({since} more like it since)")
        return True


class ThrottleFilter(logging.Filter):
    """A logging filter that passes each message template at most once per `interval`, the count of
    those it held back added to the next one it passes."""

    def __init__(self, interval: float = INTERVAL, clock: Callable[[], float] = time.monotonic) -> None:
        super().__init__()
        self._throttle = Throttle(self._keep, interval, clock)
        self._kept: str | None = None

    def _keep(self, text: str) -> None:
        self._kept = text

    def filter(self, record: logging.LogRecord) -> bool:
        self._kept = None
        self._throttle.note(f"{record.name}:{record.msg}", "")
        if self._kept is None:
            return False
        if self._kept:  # "" when said at once; else " (N more like it since)"
            record.msg = f"{record.msg}{self._kept}"
        return True


class DenialFilter(logging.Filter):
    """Drops the error line uvicorn's websockets-sansio protocol writes after every websocket refused with
    a denial response ("ASGI callable returned without completing handshake.": it never marks such a
    handshake complete; Kludex/uvicorn pull request 3138, open), one line per refusal the access guard
    `refused` made, so that a genuine incomplete handshake is still said."""

    MESSAGE = "ASGI callable returned without completing handshake."
    PENDING = 64

    def __init__(self) -> None:
        super().__init__()
        self.expected = 0

    def refused(self) -> None:
        """The access guard refused a websocket: its spurious line is coming."""
        self.expected = min(self.PENDING, self.expected + 1)

    def filter(self, record: logging.LogRecord) -> bool:
        if self.expected and record.getMessage() == self.MESSAGE:
            self.expected -= 1
            return False
        return True
