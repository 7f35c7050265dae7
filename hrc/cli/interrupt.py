"""SIGINT and SIGTERM as a request to stop, acted on only where stopping is safe (`DeferredInterrupt`).

Why the handler does not raise. Python's default for SIGINT (and `hrc.cli`'s for SIGTERM) raises
KeyboardInterrupt from the handler, and a handler runs between any two bytecodes of the main thread:
also those of a callback that C code called, such as pymunk's collision and garbage-collection callbacks
(through cffi), a ``__del__`` method or a weakref callback. An exception raised there is printed and
dropped by the C side: a compile whose SIGTERM landed in a pymunk callback went on and exited 0 (issue
26). Raised in the middle of writing the final files, it threw away every plan compiled.

So here the handler only notes the signal. The compile calls `DeferredInterrupt.check` where stopping is
safe: between units of work, at least once a second while it waits for workers, between path plans,
between its phases. `check` raises KeyboardInterrupt once a signal came, and the compile then stops as
documented (a partial output, or the earlier output kept). What runs between two checks finishes first:
writing ``compiled.json`` (a partial one too), the report, the swap of the output folder. Once the run
is over its caller looks at `requested` once more: a signal that came after the last check still ends
the process with status 130, never 0, whatever was written.

A second signal while a stop is under way changes nothing (what is being written is the point of
stopping this way). SIGKILL stops the process at once; the next compile into the same folder removes
what it left (`hrc.io.claim`), and its workers die with it (`hrc.compile.executors`).

Example::

    with DeferredInterrupt() as interrupt:
        for unit in work:
            interrupt.check()      # raises KeyboardInterrupt here, never inside `unit`
            unit()
    if interrupt.requested:
        ...                        # came after the last check: say so, exit 130
"""

from __future__ import annotations

import signal
import threading
from types import FrameType
from typing import Any

__all__ = ["DeferredInterrupt"]


class DeferredInterrupt:
    """Within its context (in the main thread; elsewhere signals cannot be handled and it does nothing),
    SIGINT and SIGTERM only set `signum` (the first one that came); `check` raises KeyboardInterrupt
    once one did. The handlers in place before are put back on exit."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.signum: int | None = None
        self._previous: dict[int, Any] = {}

    def __enter__(self) -> DeferredInterrupt:
        if threading.current_thread() is threading.main_thread():
            for sig in self.SIGNALS:
                self._previous[sig] = signal.signal(sig, self._note)
        return self

    def __exit__(self, *exc: object) -> None:
        for sig, previous in self._previous.items():
            signal.signal(sig, previous)
        self._previous.clear()

    def _note(self, signum: int, frame: FrameType | None) -> None:
        if self.signum is None:
            self.signum = signum

    @property
    def requested(self) -> bool:
        """Whether a signal came."""
        return self.signum is not None

    @property
    def name(self) -> str:
        """The signal's name (``SIGTERM``), or "" when none came."""
        return "" if self.signum is None else signal.Signals(self.signum).name

    def check(self) -> None:
        """Raise KeyboardInterrupt if a signal came: call where stopping is safe."""
        if self.signum is not None:
            raise KeyboardInterrupt(self.name)
