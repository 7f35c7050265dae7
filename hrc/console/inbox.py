"""The console's messages on their way to the dispatcher: each client's rate limited, the robot's first.

Every message from a page or the robot controller passes two gates as it arrives (on the event loop,
before any dispatcher work): its client's `TokenBucket` (a steady rate with a small burst; over it, a
one-line refusal at once) and its client's room in the `Inbox` (a few messages waiting at most; over
it, the same). Then one worker takes them from the inbox one at a time, the robot's before any page's,
so that a page pressing as fast as it can never delays the robot's acknowledgements by more than the
one message under way, and memory stays bounded whatever a client sends.

A token bucket (Turner 1986; the "leaky bucket as a meter" of ITU-T I.371): `rate` tokens a second
flow into a bucket of `burst`; a message takes one, or is refused when none is left.

>>> now = iter([0.0, 0.0, 0.0, 1.0])
>>> bucket = TokenBucket(rate=1.0, burst=2, clock=lambda: next(now))
>>> [bucket.take(), bucket.take(), bucket.take(), bucket.take()]
[True, True, False, True]
"""

from __future__ import annotations

import asyncio
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

__all__ = ["Inbox", "Letter", "TokenBucket"]

C = TypeVar("C")


class TokenBucket:
    """At most `burst` at once, `rate` a second on average; `clock` in seconds (monotonic)."""

    def __init__(self, rate: float, burst: int, clock: Callable[[], float] = time.monotonic) -> None:
        if not rate > 0 or burst < 1:
            raise ValueError(f"a token bucket needs rate > 0 and burst >= 1, got {rate}, {burst}")
        self.rate = rate
        self.burst = burst
        self._clock = clock
        self._tokens = float(burst)
        self._at = clock()

    def take(self) -> bool:
        """One token if there is one (True), else False; O(1)."""
        now = self._clock()
        self._tokens = min(float(self.burst), self._tokens + (now - self._at) * self.rate)
        self._at = now
        if self._tokens >= 1.0:
            self._tokens -= 1.0
            return True
        return False


@dataclass(frozen=True, slots=True)
class Letter(Generic[C]):
    """A message waiting: who sent it (`client`), whether that is the robot, the message, its reply id."""

    client: C
    robot: bool
    message: dict[str, Any]
    reply_id: str | int | None


class Inbox(Generic[C]):
    """Messages waiting for the one worker: the robot's first, then the pages' in arrival order.

    `per_client` caps the messages one client may have waiting; `put` says False when it is reached.
    """

    def __init__(self, per_client: int) -> None:
        self.per_client = per_client
        self._robot: deque[Letter[C]] = deque()
        self._pages: deque[Letter[C]] = deque()
        self._waiting: dict[int, int] = {}
        self._ready = asyncio.Event()

    def __len__(self) -> int:
        return len(self._robot) + len(self._pages)

    def put(self, letter: Letter[C]) -> bool:
        key = id(letter.client)
        if self._waiting.get(key, 0) >= self.per_client:
            return False
        self._waiting[key] = self._waiting.get(key, 0) + 1
        (self._robot if letter.robot else self._pages).append(letter)
        self._ready.set()
        return True

    async def get(self) -> Letter[C]:
        """The next letter, the robot's first; waits while there is none."""
        while not (self._robot or self._pages):
            self._ready.clear()
            await self._ready.wait()
        letter = self._robot.popleft() if self._robot else self._pages.popleft()
        key = id(letter.client)
        self._waiting[key] -= 1
        if not self._waiting[key]:
            del self._waiting[key]
        return letter
