"""The run's clock: seconds from the run's start, as the dispatcher expects them.

The server reads a monotonic clock (never the wall clock, which may jump) and converts it to *run
seconds*: ``(monotonic() - start) * speed``. With ``speed = 1`` run seconds are real seconds; a larger
speed lets a person (or a browser test) go through a whole run faster, the simulated robot keeping to
the same run-second schedule. Times are rounded to the millisecond, the unit of ``compiled.json``.
"""

from __future__ import annotations

import time
from collections.abc import Callable

__all__ = ["RunClock"]


class RunClock:
    """Run seconds since construction, `speed` run seconds per real second.

    >>> ticks = iter([10.0, 12.5])
    >>> clock = RunClock(speed=2.0, monotonic=lambda: next(ticks))
    >>> clock.now()
    5.0
    """

    def __init__(self, speed: float = 1.0, monotonic: Callable[[], float] = time.monotonic) -> None:
        if not speed > 0:
            raise ValueError(f"speed must be positive, got {speed}")
        self.speed = float(speed)
        self._monotonic = monotonic
        self._start = monotonic()

    def now(self) -> float:
        """Run seconds since the start, to the millisecond."""
        return round((self._monotonic() - self._start) * self.speed, 3)

    def real_delay(self, run_t: float) -> float:
        """Real seconds from now until run time `run_t` (0 when it has passed)."""
        return max(0.0, (run_t - (self._monotonic() - self._start) * self.speed) / self.speed)
