"""The human action detector: what the dispatcher learns of the person, and when.

Strassmair & Taylor 2014, section V.B and Fig. 5: the Human Action Detector "determines the human
action choice and the execution timing" and updates the dispatcher cyclically. Here it sees every leg
event of the person (leaving for a phase, reaching a waiting place and leaving it, arriving, starting
and ending the manipulation) and their absences, and passes each on `delay` seconds later, stamped
with the time it is passed on: a detector that needs a while to be sure tells the dispatcher late,
and the dispatcher believes what it is told, and how late it is (`Happening.delay`, the message's
``delay``: issue 32, an observation later than the stated maximum voids the guarantee). Events keep
their order; several due at once go together.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

__all__ = ["Detector", "Happening"]


@dataclass(frozen=True, slots=True)
class Happening:
    """Something that happened on the floor at time `t`: a leg event (`event` in depart / park / unpark /
    arrive / start / end, with `agent`, `action`, `phase`) or the person's "away" / "back". As passed on
    late by a `Detector`: `t` the time it was passed on, `delay` how long after it happened (None: on time,
    or not said)."""

    t: float
    agent: str
    event: str
    action: str | None = None
    phase: str | None = None
    delay: float | None = None

    def key(self) -> tuple[str, str | None, str | None, str]:
        return (self.agent, self.action, self.phase, self.event)


class Detector:
    """A FIFO of the person's happenings, each released `delay` seconds after it happened."""

    def __init__(self, delay: float = 0.0) -> None:
        if not (delay >= 0 and math.isfinite(delay)):
            raise ValueError(f"detection delay must be a finite number >= 0, got {delay}")
        self.delay = delay
        self._queue: deque[Happening] = deque()

    def see(self, happening: Happening) -> None:
        self._queue.append(happening)

    def next_due(self) -> float:
        """When the next happening is released (inf when nothing is pending)."""
        return self._queue[0].t + self.delay if self._queue else math.inf

    def release(self, now: float) -> list[Happening]:
        """The happenings due by `now`, in order, stamped with the time they are released."""
        out = []
        while self._queue and self._queue[0].t + self.delay <= now + 1e-9:
            h = self._queue.popleft()
            out.append(Happening(max(h.t + self.delay, h.t), h.agent, h.event, h.action, h.phase,
                                 self.delay if self.delay > 0 else None))
        return out

    @property
    def pending(self) -> int:
        return len(self._queue)
