"""The run's clock: seconds from the run's start, as the dispatcher expects them.

The server reads a monotonic clock (never the wall clock, which may jump) and converts it to *run
seconds*: ``(monotonic() - start) * speed``. The run starts when `start` is called (the console calls it
when the first page or robot controller connects, so that no one misses its first seconds); until then
its time is 0. With ``speed = 1`` run seconds are real seconds; a larger
speed lets a person (or a browser test) go through a whole run faster, the simulated robot keeping to
the same run-second schedule. Times are rounded to the millisecond, the unit of ``compiled.json``.

A resumed run (``hrc console --resume LOG``) goes on from its last logged time (`offset`): run time
does not pass while the console is down; the next press or acknowledgement says what happened.
"""

from __future__ import annotations

import time
from collections.abc import Callable

__all__ = ["RunClock"]


class RunClock:
    """Run seconds since construction, `speed` run seconds per real second.

    >>> ticks = iter([10.0, 12.5])
    >>> clock = RunClock(speed=2.0, monotonic=lambda: next(ticks))
    >>> clock.start()
    >>> clock.now()
    5.0
    """

    def __init__(self, speed: float = 1.0, monotonic: Callable[[], float] = time.monotonic,
                 offset: float = 0.0) -> None:
        if not speed > 0:
            raise ValueError(f"speed must be positive, got {speed}")
        self.speed = float(speed)
        self.offset = float(offset)
        self._monotonic = monotonic
        self._start: float | None = None

    @property
    def started(self) -> bool:
        return self._start is not None

    def start(self) -> None:
        """Start the run now (again: no effect)."""
        if self._start is None:
            self._start = self._monotonic()

    def now(self) -> float:
        """Run seconds since the start plus `offset`, to the millisecond (`offset` before the start)."""
        if self._start is None:
            return round(self.offset, 3)
        return round(self.offset + (self._monotonic() - self._start) * self.speed, 3)

    def real_delay(self, run_t: float) -> float:
        """Real seconds from now until run time `run_t` (0 when it has passed; inf before the start)."""
        if self._start is None:
            return float("inf")
        return max(0.0, (run_t - self.offset - (self._monotonic() - self._start) * self.speed) / self.speed)
