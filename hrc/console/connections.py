"""Bounded connections: a cap below the open-file limit, a deadline for a request's headers, and the
oldest unauthenticated connections shed first, so that the robot's controller always gets in.

Issue 34: under the usual limit of 1,024 open files, 1,100 idle connections from any local process
(opened, never a byte sent) used up the console's file descriptors; ``accept()`` failed (EMFILE), the
robot's controller could not reconnect, and asyncio wrote an error per failed ``accept()`` (117 MB in
12 s). A connection costs its file descriptor before any request is read, so the bound has to be on
connections, below the ASGI app: `ConnectionLimiter` is told of each connection as uvicorn's HTTP
protocol takes it (`limited_protocol`), and of each request as the access guard admits it (`admitted`).

- **Cap.** At most `cap` connections are held, and asyncio accepts at most `burst` at once (it takes
  up to that many connections per wake-up, each a descriptor, before the first is counted here, and
  a connection shed to make room keeps its descriptor until the loop's next pass: about three bursts
  are in flight): `budget` splits the process's ``RLIMIT_NOFILE``, less the descriptors open now (the
  log, the dispatch form's maps) and `RESERVE_FILES`, between the two, at most `MAX_CONNECTIONS` and
  `MAX_BURST`. So ``accept()`` never fails for want of a descriptor (EMFILE made asyncio stop
  accepting for a second each time, with a traceback on stderr).
- **A long listening queue.** The kernel's queue of connections not yet accepted costs the process
  no descriptor, so it is `MAX_BACKLOG` long whatever the limit (Linux clamps it to
  ``net.core.somaxconn``, 4,096 by default since 5.4). A short one (it was the accept burst, 306 at
  1,024 files) is what made a flood slow to drain: over it the kernel drops a new connection's SYN
  (the client tries again after 1, 3, 7, 15, 31 s) or, past a SYN cookie, its last ACK (the client
  then believes it is connected and the server never hears of it), so 2,000 idle connections trickled
  in over a minute, and the robot controller's own SYN waited its second behind them. In the queue,
  the flood is drained at the loop's speed and the robot's connection is taken in its turn.
- **Shed, unauthenticated first.** A connection over the cap makes room by closing the oldest one that
  has not sent a whole request yet; failing that, the oldest plain HTTP one (a page's keep-alive, a
  refused request); an admitted websocket (the robot's controller, a page's) is never shed. With none
  to shed, the new connection is closed.
- **Deadlines.** A connection that has not sent a whole request's headers within `HEADER_TIMEOUT`
  seconds is closed (slow or idle clients hold nothing for long); an idle keep-alive connection is
  closed by uvicorn after `KEEP_ALIVE` seconds (``timeout_keep_alive``).

uvicorn's own ``limit_concurrency`` is not used: over it, uvicorn answers 503 to every new request,
the robot's websocket upgrade included, which is the lockout this module prevents.
"""

from __future__ import annotations

import asyncio
import os
import resource
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from uvicorn.protocols.http.h11_impl import H11Protocol

__all__ = ["HEADER_TIMEOUT", "KEEP_ALIVE", "MAX_BACKLOG", "MAX_BURST", "MAX_CONNECTIONS", "RESERVE_FILES",
           "ConnectionLimiter", "budget", "limited_protocol"]

MAX_CONNECTIONS = 512
"""Connections held at most (pages are 16 at most, the robot's controller one; the rest is headroom)."""
MAX_BACKLOG = 4096
"""The listening queue's length (the kernel's: no descriptor of this process; clamped to ``somaxconn``)."""
MAX_BURST = 128
"""asyncio's accepts per wake-up at most (each a descriptor before it is counted here)."""
IN_FLIGHT_BURSTS = 3
"""Bursts of descriptors not counted as held at once: accepted, being made transports, shed but not yet closed."""
RESERVE_FILES = 64
"""File descriptors kept free below ``RLIMIT_NOFILE`` besides the connections and the accept burst."""
HEADER_TIMEOUT = 5.0
"""Seconds for a new connection to send a whole request's headers, or it is closed."""
KEEP_ALIVE = 5.0
"""Seconds an idle keep-alive connection is kept (uvicorn's ``timeout_keep_alive``)."""


def budget() -> tuple[int, int]:
    """``(cap, burst)`` for this process now (see the module docstring): at a limit of 1,024 open files
    with 20 open, ``(512, 128)``; at 20,000, the same; at 256 with 6 open, ``(108, 26)``."""
    soft = resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    if soft == resource.RLIM_INFINITY:
        return MAX_CONNECTIONS, MAX_BURST
    try:
        used = len(os.listdir("/proc/self/fd"))
    except OSError:
        used = 64
    free = max(32, soft - used - RESERVE_FILES)
    burst = max(8, min(MAX_BURST, free // (2 * IN_FLIGHT_BURSTS + 1)))
    return max(8, min(MAX_CONNECTIONS, free - IN_FLIGHT_BURSTS * burst)), burst


@dataclass(slots=True)
class _Held:
    transport: asyncio.BaseTransport
    state: str  # "new": no whole request yet; "http": requests; "trusted": an admitted websocket
    deadline: asyncio.TimerHandle | None = None


def _peer(address: Any) -> tuple[str, int] | None:
    if isinstance(address, list | tuple) and len(address) >= 2:
        return str(address[0]), int(address[1])
    return None


class ConnectionLimiter:
    """The connections held, oldest first (see the module docstring), at most `cap`, accepted at most
    `burst` at a time (`budget`, unless `cap` is given), `backlog` waiting in the kernel's queue;
    `shed` and `refused` count the connections closed to make room and those closed for want of any;
    `fault(kind, text)` is told of each (`hrc.console.supervise.Throttle` says it once a second)."""

    def __init__(self, cap: int | None = None, header_timeout: float = HEADER_TIMEOUT,
                 fault: Callable[[str, str], None] | None = None) -> None:
        self.cap, self.burst = budget()
        self.backlog = MAX_BACKLOG
        if cap is not None:
            self.cap = cap
        self.header_timeout = header_timeout
        self.fault = fault or (lambda _kind, _text: None)
        self._held: OrderedDict[tuple[str, int], _Held] = OrderedDict()
        self.shed = 0
        self.refused = 0
        self.timed_out = 0

    def __len__(self) -> int:
        return len(self._held)

    def opened(self, transport: asyncio.BaseTransport, loop: asyncio.AbstractEventLoop) -> None:
        """A new connection (its transport): held, after making room if the cap is reached."""
        peer = _peer(transport.get_extra_info("peername"))
        if peer is None:
            return
        if len(self._held) >= self.cap:
            self._purge()
        if len(self._held) >= self.cap and not self._shed_one():
            self.refused += 1
            self.fault("refused", f"hrc console: {len(self._held)} connections held (the cap), none of them "
                                  "unauthenticated: a new connection was closed")
            transport.close()
            return
        held = _Held(transport, "new")
        held.deadline = loop.call_later(self.header_timeout, self._expire, peer, transport)
        self._held[peer] = held

    def closed(self, transport: asyncio.BaseTransport) -> None:
        """A connection ended (its transport)."""
        peer = _peer(transport.get_extra_info("peername"))
        held = self._held.get(peer) if peer is not None else None
        if peer is not None and held is not None and held.transport is transport and held.state != "trusted":
            self._forget(peer)  # (an upgraded websocket's ends elsewhere: purged when it is closed)

    def admitted(self, client: Any, trusted: bool) -> None:
        """A whole request came on the connection from `client` (ASGI ``scope["client"]``); `trusted`: a
        websocket the access guard let through (never shed)."""
        peer = _peer(client)
        held = self._held.get(peer) if peer is not None else None
        if held is None:
            return
        if held.deadline is not None:
            held.deadline.cancel()
            held.deadline = None
        held.state = "trusted" if trusted else "http"

    def _expire(self, peer: tuple[str, int], transport: asyncio.BaseTransport) -> None:
        held = self._held.get(peer)
        if held is not None and held.transport is transport and held.state == "new":
            self.timed_out += 1
            self._forget(peer)
            transport.close()

    def _forget(self, peer: tuple[str, int]) -> None:
        held = self._held.pop(peer)
        if held.deadline is not None:
            held.deadline.cancel()

    def _purge(self) -> None:
        for peer in [p for p, h in self._held.items() if h.transport.is_closing()]:
            self._forget(peer)

    def _shed_one(self) -> bool:
        for state in ("new", "http"):
            peer = next((p for p, h in self._held.items() if h.state == state), None)
            if peer is not None:
                held = self._held[peer]
                self._forget(peer)
                held.transport.close()
                self.shed += 1
                self.fault("shed", f"hrc console: {self.cap} connections held (the cap): the oldest without "
                                   f"{'a whole request' if state == 'new' else 'a websocket'} closed to make "
                                   f"room ({self.shed} in all)")
                return True
        return False


def limited_protocol(limiter: ConnectionLimiter) -> type[H11Protocol]:
    """uvicorn's h11 HTTP protocol, each of its connections told to `limiter` (``uvicorn.Config(http=...)``)."""

    class LimitedH11Protocol(H11Protocol):
        def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
            super().connection_made(transport)
            limiter.opened(transport, self.loop)

        def connection_lost(self, exc: Exception | None) -> None:
            limiter.closed(self.transport)
            super().connection_lost(exc)

    return LimitedH11Protocol
