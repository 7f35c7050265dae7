"""The console's web server: one page, its script and style, a websocket for pages and one for the
robot controller, all served by `hrc` itself (no internet at run time).

Starlette over uvicorn: a small, well-kept ASGI toolkit whose websockets and static responses are all
this needs, run by uvicorn's single event loop, which also serializes every message into the one
dispatcher. Routes::

    GET /                 the page            GET /static/console.{js,css}
    GET /state            the run now (JSON)  GET /log      the run's log file so far (JSON lines)
    WS  /ws               pages: pushes "setup" once, then "state" after every change; takes presses
    WS  /robot            the robot controller (docs/console.md): pushes "decision", takes "ack"

Every route and websocket is behind `hrc.console.access.AccessGuard`: this server's own Host and Origin
only, the page's secret everywhere but ``/robot``, the robot's own secret there.

Each message that arrives is checked at once (its client's rate first, before it is even parsed; then
size, JSON nesting) and put in the `hrc.console.inbox.Inbox`; one worker takes the robot's messages
before the pages' and hands them to the session one at a time. A client over its rate is refused
without an answer for each message, told so in one line at most once a second (with the count): a
flood then costs the server a token-bucket check per message. Every queue is bounded (messages waiting
per client, replies waiting for a slow client, pages connected), so no client can make the server's
memory grow.

With ``simulate_robot`` the server plays the robot: each robot event is acknowledged at the start of
its window (`hrc.console.robot`), and ``/robot`` refuses controllers.

A team (issue 37): a person's page connects as ``/ws?person=ID`` and presses as that person (``/ws``
alone is the shared view, which may not press); each robot's controller connects as ``/robot?robot=ID``
(the robot's secret, one controller per robot) and acknowledges for that robot only; each person has a
secret of their own that opens their page only (`hrc.console.access`); ``--simulate-robot``
plays every robot. An id not of the team is refused before anything is served. With ``--detect motion``
a controller's link also carries the tracker's positions, each naming its person (`ConsoleSession`).
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from collections.abc import AsyncIterator
from dataclasses import replace
from importlib import resources
from typing import Any

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import FileResponse, PlainTextResponse, Response
from starlette.routing import Route, WebSocketRoute
from starlette.websockets import WebSocket, WebSocketState

from hrc.console.access import AccessGuard, Credentials, new_token
from hrc.console.connections import ConnectionLimiter
from hrc.console.inbox import Inbox, Letter, TokenBucket
from hrc.console.robot import SimulatedRobot
from hrc.console.session import ConsoleSession, Reply, parse
from hrc.console.supervise import Throttle

__all__ = ["MAX_FRAME", "MAX_MESSAGE", "MAX_PAGES", "PAGE_RATE", "ROBOT_RATE", "SUMMARY_EVERY", "ConsoleServer"]

MAX_MESSAGE = 4096        # bytes: no legitimate message comes near it (a longer one gets a one-line refusal)
MAX_FRAME = 65536         # bytes: a longer websocket frame closes the connection (1009), read no further
SEND_TIMEOUT = 5.0        # s: a client that cannot take a message in this time is dropped (it reconnects)
QUEUE = 64                # messages waiting for one client before it is dropped as too slow
MAX_PAGES = 16            # pages connected at once (tabs of the person's; more are refused)
PAGE_RATE = (5.0, 10)     # a page's messages: 5 a second, 10 at once (a person presses far less)
ROBOT_RATE = (50.0, 100)  # the robot controller's
WAITING = 8               # messages of one client waiting for the dispatcher
SUMMARY_EVERY = 1.0       # s: a client over its rate is told so at most this often (one line with the count)
_STATIC = {"console.js": "text/javascript; charset=utf-8", "console.css": "text/css; charset=utf-8"}
# Nothing but this server: no other host for scripts, styles, images or connections.
_CSP = ("default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; connect-src 'self'; "
        "base-uri 'none'; form-action 'none'; frame-ancestors 'none'")
_NO_STORE = {"Cache-Control": "no-store", "Referrer-Policy": "no-referrer", "X-Content-Type-Options": "nosniff"}


def _page_file(name: str) -> bytes:
    return resources.files("hrc.console").joinpath("page", name).read_bytes()


def _json(obj: Any) -> str:
    """Compact JSON, ASCII: a lone surrogate a page sent stays an escape and never breaks a response."""
    return json.dumps(obj, separators=(",", ":"), ensure_ascii=True)


class _Client:
    """One websocket, the queue of messages waiting for it (one writer task per client, so sends never
    interleave), and the rate its messages may come at."""

    def __init__(self, ws: WebSocket, rate: tuple[float, int], who: str | None = None, robot: bool = False) -> None:
        self.ws = ws
        self.who = who  # a team's person or robot id (None: one of each, or the shared view)
        self.robot = robot
        self.queue: asyncio.Queue[str] = asyncio.Queue(QUEUE)
        self.bucket = TokenBucket(*rate)
        self.over = 0  # messages over the rate since the last refusal said how many
        self.told_at = -SUMMARY_EVERY

    def over_the_rate(self) -> dict[str, Any] | None:
        """A message over the rate: refused; the refusal that says so, at most once a second."""
        self.over += 1
        now = time.monotonic()
        if now - self.told_at < SUMMARY_EVERY:
            return None
        count, self.over, self.told_at = self.over, 0, now
        return Reply.error(f"refused: {count} message{'s' if count > 1 else ''} over the limit of "
                           f"{self.bucket.rate:g} a second (no answer each until they slow down); nothing changed")

    def push(self, message: dict[str, Any]) -> bool:
        try:
            self.queue.put_nowait(_json(message))
            return True
        except asyncio.QueueFull:
            return False

    async def write(self) -> None:
        while True:
            text = await self.queue.get()
            async with asyncio.timeout(SEND_TIMEOUT):  # in this task: no extra hop as with wait_for
                await self.ws.send_text(text)


async def _receive(ws: WebSocket) -> str | bytes | None:
    """The next message's text, or None when the client has gone."""
    message = await ws.receive()
    if message["type"] == "websocket.disconnect":
        return None
    return message.get("text") if message.get("text") is not None else message.get("bytes") or b""


async def _close(ws: WebSocket, code: int) -> None:
    with contextlib.suppress(Exception):  # it may have gone already
        await ws.close(code=code)


class ConsoleServer:
    """The ASGI app (`app`, behind its `guard`) around one `ConsoleSession`; `tick` is in run seconds
    (0: no ticks). `credentials`: the run's secrets (default: new ones)."""

    def __init__(self, session: ConsoleSession, simulate_robot: bool = False, tick: float = 2.0,
                 credentials: Credentials | None = None) -> None:
        self.session = session
        self.tick = tick
        self.pages: set[_Client] = set()
        self.controllers: dict[str | None, _Client] = {}  # robot id (None: the one robot) -> its controller
        self.inbox: Inbox[_Client] = Inbox(WAITING)
        # one simulated robot per robot of a team, each on its own id; the one robot otherwise
        ids: tuple[str | None, ...] = session.robots if session.team else (None,)
        self.sims = [SimulatedRobot(session, self.changed, r) for r in ids] if simulate_robot else []
        self.sim = self.sims[0] if self.sims else None
        session.robot_link = "simulated" if simulate_robot else "none"
        if session.team and simulate_robot:
            session.robot_links.update(dict.fromkeys(session.robots, "simulated"))
        credentials = credentials or Credentials.generate()
        if session.team and not credentials.people:  # a secret per person's own page (issue 37)
            credentials = replace(credentials, people=tuple((p, new_token()) for p in session.people))
        self.credentials = credentials
        routes = Starlette(routes=[
            Route("/", self.index), Route("/static/{name}", self.static), Route("/state", self.state),
            Route("/log", self.log), WebSocketRoute("/ws", self.page_socket),
            WebSocketRoute("/robot", self.robot_socket),
        ], lifespan=self._lifespan)
        self.guard = AccessGuard(routes, self.credentials)
        self.app = self.guard
        self.faults = Throttle()  # faults survived, by kind (said on stderr once a second at most)
        self.connections = ConnectionLimiter(fault=self.fault)  # held by `hrc.console.run.serve`'s protocol
        self.guard.on_request = self.connections.admitted
        self.received = 0  # websocket messages received
        self.limited = 0   # of which refused at once by a rate limit or a full inbox

    # -- plain HTTP ---------------------------------------------------------------------------------
    async def index(self, request: Request) -> Response:
        return Response(_page_file("index.html"), media_type="text/html; charset=utf-8",
                        headers={"Content-Security-Policy": _CSP, **_NO_STORE})

    async def static(self, request: Request) -> Response:
        name = request.path_params["name"]
        if name not in _STATIC:
            return PlainTextResponse("not found", status_code=404)
        return Response(_page_file(name), media_type=_STATIC[name], headers=_NO_STORE)

    async def state(self, request: Request) -> Response:
        traffic = {"received": self.received, "limited": self.limited, "denied": self.guard.denied,
                   "faults": self.faults.count.get("message", 0) + self.faults.count.get("push", 0)
                   + self.faults.count.get("tick", 0),
                   "connections": len(self.connections), "shed": self.connections.shed,
                   "timed_out": self.connections.timed_out}
        return Response(_json({**self.session.state(), "traffic": traffic}), media_type="application/json",
                        headers=_NO_STORE)

    async def log(self, request: Request) -> Response:
        path = self.session.log_path
        if path is None:
            return PlainTextResponse("", media_type="application/x-ndjson", headers=_NO_STORE)
        return FileResponse(path, media_type="application/x-ndjson", headers=_NO_STORE)

    # -- pushing changes ----------------------------------------------------------------------------
    def changed(self) -> None:
        """After every accepted message: the new state to every page, the decision to the robot."""
        state = self.session.state()
        for client in list(self.pages):
            if not client.push(state):
                self._drop(client)
        for robot, client in list(self.controllers.items()):
            if not client.push(self._decision(robot)):
                self._drop(client)
        for sim in self.sims:
            sim.update()

    def _decision(self, robot: str | None = None) -> dict[str, Any]:
        s = self.session
        return {"type": "decision", "seq": s.seq, "now": s.now(), "finished": s.finished,
                "decision": s.dispatcher.decision.to_json()} | ({"robot": robot} if robot is not None else {})

    def _drop(self, client: _Client) -> None:
        self.pages.discard(client)
        if client.robot and self.controllers.get(client.who) is client:
            self._unlink(client.who)
        asyncio.get_running_loop().create_task(_close(client.ws, 1013))

    def _unlink(self, robot: str | None) -> None:
        self.controllers.pop(robot, None)
        if robot is None:
            self.session.robot_link = "none"
        else:
            self.session.robot_links[robot] = "none"
            self.session.robot_link = "connected" if self.controllers else "none"

    # -- messages in --------------------------------------------------------------------------------
    def _admit(self, client: _Client, frame: str | bytes) -> dict[str, Any] | None:
        """Check a message as it arrives: the refusal to send at once, or None (into the inbox, or over its
        client's rate with the refusal already said this second)."""
        self.received += 1
        if not client.bucket.take():  # first, and before parsing: a flood costs next to nothing
            self.limited += 1
            return client.over_the_rate()
        if len(frame) > MAX_MESSAGE:
            return Reply.error(f"malformed message (longer than {MAX_MESSAGE} bytes)")
        msg = parse(frame)
        if isinstance(msg, str):
            return Reply.error(msg)
        mid = msg.get("id")
        mid = mid if isinstance(mid, str | int) and not isinstance(mid, bool) else None
        ident = {} if mid is None else {"id": mid}
        if not self.inbox.put(Letter(client, client.robot, msg, mid)):
            self.limited += 1
            return {**Reply.error(f"refused: {WAITING} messages of yours are still waiting; nothing changed"),
                    **ident}
        return None

    async def _serve(self, client: _Client) -> None:
        writer = asyncio.create_task(client.write())
        try:
            while True:
                frame = await _receive(client.ws)
                if frame is None:
                    break
                refusal = self._admit(client, frame)
                if refusal is not None:
                    # a client that sends faster than it reads its refusals is not sent more of them (its
                    # queue is full): they go unanswered rather than growing memory; nothing changed
                    client.push({"type": "reply", **refusal})
                await asyncio.sleep(0)  # a flood on one connection must not keep the others (the robot) waiting
        finally:
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await writer

    async def _worker(self) -> None:
        """The one consumer of the inbox: each message to the session, its reply, then the new state.

        Supervised (issue 34): whatever goes wrong while one message is handled becomes that message's
        one-line refusal (said on stderr at most once a second, counted in ``/state``'s ``traffic``),
        and the worker takes the next one; it never ends but by cancellation."""
        while True:
            letter = await self.inbox.get()
            ident = {} if letter.reply_id is None else {"id": letter.reply_id}
            error_before = self.session.log_error
            who = letter.client.who
            try:
                reply = (self.session.robot_message(letter.message, robot=who) if letter.robot
                         else self.session.page_message(letter.message, person=who))
            except Exception as err:  # noqa: BLE001 - one message's fault must not stop every answer
                self.fault("message", f"hrc console: internal error while handling a "
                                      f"{'robot' if letter.robot else 'page'} message ({type(err).__name__}: "
                                      f"{err}); it was refused")
                reply = Reply.error(f"refused: internal error ({type(err).__name__}); nothing changed")
            if not letter.client.push({"type": "reply", **reply, **ident}):
                self._drop(letter.client)
            await asyncio.sleep(0)  # the reply goes out before the state is built
            if reply["ok"] or self.session.log_error != error_before:
                self._changed_safely()

    def fault(self, kind: str, text: str) -> None:
        """A fault survived: said once per interval (`hrc.console.supervise.Throttle`), counted."""
        self.faults.note(kind, text)

    def _changed_safely(self) -> None:
        """`changed`, its own failure said and survived (whatever state there is, pushed)."""
        try:
            self.changed()
        except Exception as err:  # noqa: BLE001 - the message was answered; the next push may do
            self.fault("push", f"hrc console: the new state could not be pushed ({type(err).__name__}: {err})")

    def _start_run(self) -> None:
        """The run's clock starts when the first page or robot controller connects."""
        if not self.session.clock.started:
            self.session.clock.start()
            self._changed_safely()

    async def _refuse_id(self, ws: WebSocket, what: str, given: str | None, known: tuple[str, ...]) -> bool:
        """Refuse (one line, then close) a websocket naming an id not of the team; whether it was."""
        if given is None or given in known:
            return False
        await ws.accept()
        await ws.send_text(_json({"type": "reply", "ok": False,
                                  "error": f"refused: unknown {what} {given[:40]!r} "
                                           f"({'people' if what == 'person' else 'robots'}: {', '.join(known)})"}))
        await ws.close(code=1008)
        return True

    async def page_socket(self, ws: WebSocket) -> None:
        if len(self.pages) >= MAX_PAGES:
            await ws.close(code=1013)
            return
        person = ws.query_params.get("person")
        if await self._refuse_id(ws, "person", person, self.session.people):
            return
        await ws.accept()
        self._start_run()
        client = _Client(ws, PAGE_RATE, person if self.session.team else None)
        client.push(self.session.setup())
        client.push(self.session.state())
        self.pages.add(client)
        try:
            await self._serve(client)
        finally:
            self.pages.discard(client)

    async def robot_socket(self, ws: WebSocket) -> None:
        given = ws.query_params.get("robot")
        if await self._refuse_id(ws, "robot", given, self.session.robots):
            return
        robot = given if self.session.team else None
        await ws.accept()
        why = ("the robot is simulated (--simulate-robot)" if self.sims
               else f"a team's controller names its robot: /robot?robot=ID (robots: {', '.join(self.session.robots)})"
               if self.session.team and robot is None
               else "a robot controller is already connected" if robot in self.controllers else None)
        if why:
            await ws.send_text(_json({"type": "reply", "ok": False, "error": f"refused: {why}"}))
            await ws.close(code=1008)
            return
        self._start_run()
        client = self.controllers[robot] = _Client(ws, ROBOT_RATE, robot, robot=True)
        self.session.robot_link = "connected"
        if robot is not None:
            self.session.robot_links[robot] = "connected"
        client.push({"type": "hello", "now": self.session.now(), "speed": self.session.clock.speed}
                    | ({"robot": robot} if robot is not None else {}))
        self._changed_safely()  # the decision to the robot, the link to the pages
        try:
            await self._serve(client)
        finally:
            if self.controllers.get(robot) is client:
                self._unlink(robot)
                self._changed_safely()

    # -- time passing -------------------------------------------------------------------------------
    async def _ticker(self) -> None:
        s = self.session
        while self.tick > 0:
            await asyncio.sleep(self.tick / s.clock.speed)
            try:
                if s.clock.started and not s.finished and s.clock.now() - s.dispatcher.now >= self.tick:
                    error_before = s.log_error
                    if s.tick()["ok"] or s.log_error != error_before:
                        self._changed_safely()
            except Exception as err:  # noqa: BLE001 - supervised, as the worker
                self.fault("tick", f"hrc console: internal error on a tick ({type(err).__name__}: {err})")

    @contextlib.asynccontextmanager
    async def _lifespan(self, app: Starlette) -> AsyncIterator[None]:
        tasks = [asyncio.create_task(self._ticker()), asyncio.create_task(self._worker())]
        for sim in self.sims:
            sim.update()
        try:
            yield
        finally:
            for task in tasks:
                task.cancel()
            for sim in self.sims:
                sim.stop()
            for client in list(self.pages):
                if client.ws.client_state == WebSocketState.CONNECTED:
                    with contextlib.suppress(Exception):
                        await client.ws.close(code=1001)
            self.session.logged.close()
