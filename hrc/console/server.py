"""The console's web server: one page, its script and style, a websocket for pages and one for the
robot controller, all served by `hrc` itself (no internet at run time).

Starlette over uvicorn: a small, well-kept ASGI toolkit whose websockets and static responses are all
this needs, run by uvicorn's single event loop, which also serializes every message into the one
dispatcher. Routes::

    GET /                 the page            GET /static/console.{js,css}
    GET /state            the run now (JSON)  GET /log      the run's log so far (JSON lines)
    WS  /ws               pages: pushes "setup" once, then "state" after every change; takes presses
    WS  /robot            the robot controller (docs/console.md): pushes "decision", takes "ack"

Every route and websocket is behind `hrc.console.access.AccessGuard`: this server's own Host and Origin
only, the page's secret everywhere but ``/robot``, the robot's own secret there.

With ``simulate_robot`` the server plays the robot: each robot event is acknowledged at the start of
its window (`hrc.console.robot`), and ``/robot`` refuses controllers.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
from collections.abc import AsyncIterator
from importlib import resources
from typing import Any

from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import FileResponse, PlainTextResponse, Response
from starlette.routing import Route, WebSocketRoute
from starlette.websockets import WebSocket, WebSocketState

from hrc.console.access import AccessGuard, Credentials
from hrc.console.robot import SimulatedRobot
from hrc.console.session import ConsoleSession, Reply, parse

__all__ = ["MAX_FRAME", "MAX_MESSAGE", "ConsoleServer"]

MAX_MESSAGE = 4096        # bytes: no legitimate message comes near it (a longer one gets a one-line refusal)
MAX_FRAME = 65536         # bytes: a longer websocket frame closes the connection (1009), read no further
SEND_TIMEOUT = 5.0        # s: a client that cannot take a message in this time is dropped (it reconnects)
QUEUE = 64                # messages waiting for one client before it is dropped as too slow
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
    """One websocket and the queue of messages waiting for it (one writer task per client, so sends
    never interleave)."""

    def __init__(self, ws: WebSocket) -> None:
        self.ws = ws
        self.queue: asyncio.Queue[str] = asyncio.Queue(QUEUE)

    def push(self, message: dict[str, Any]) -> bool:
        try:
            self.queue.put_nowait(_json(message))
            return True
        except asyncio.QueueFull:
            return False

    async def write(self) -> None:
        while True:
            text = await self.queue.get()
            await asyncio.wait_for(self.ws.send_text(text), SEND_TIMEOUT)


async def _receive(ws: WebSocket) -> str | bytes | None:
    """The next message's text, or None when the client has gone."""
    message = await ws.receive()
    if message["type"] == "websocket.disconnect":
        return None
    return message.get("text") if message.get("text") is not None else message.get("bytes") or b""


class ConsoleServer:
    """The ASGI app (`app`, behind its `guard`) around one `ConsoleSession`; `tick` is in run seconds
    (0: no ticks). `credentials`: the run's secrets (default: new ones)."""

    def __init__(self, session: ConsoleSession, simulate_robot: bool = False, tick: float = 2.0,
                 credentials: Credentials | None = None) -> None:
        self.session = session
        self.tick = tick
        self.pages: set[_Client] = set()
        self.robot: _Client | None = None
        self.sim = SimulatedRobot(session, self.changed) if simulate_robot else None
        session.robot_link = "simulated" if simulate_robot else "none"
        self.credentials = credentials or Credentials.generate()
        routes = Starlette(routes=[
            Route("/", self.index), Route("/static/{name}", self.static), Route("/state", self.state),
            Route("/log", self.log), WebSocketRoute("/ws", self.page_socket),
            WebSocketRoute("/robot", self.robot_socket),
        ], lifespan=self._lifespan)
        self.guard = AccessGuard(routes, self.credentials)
        self.app = self.guard

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
        return Response(_json(self.session.state()), media_type="application/json", headers=_NO_STORE)

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
        if self.robot is not None and not self.robot.push(self._decision()):
            self._drop(self.robot)
        if self.sim is not None:
            self.sim.update()

    def _decision(self) -> dict[str, Any]:
        s = self.session
        return {"type": "decision", "seq": s.seq, "now": s.now(), "finished": s.finished,
                "decision": s.dispatcher.decision.to_json()}

    def _drop(self, client: _Client) -> None:
        self.pages.discard(client)
        if self.robot is client:
            self.robot = None
            self.session.robot_link = "none"
        asyncio.get_running_loop().create_task(client.ws.close(code=1013))

    # -- websockets ---------------------------------------------------------------------------------
    async def _serve(self, client: _Client, handle: Any) -> None:
        writer = asyncio.create_task(client.write())
        try:
            while True:
                text = await _receive(client.ws)
                if text is None:
                    break
                if len(text) > MAX_MESSAGE:
                    reply: dict[str, Any] = Reply.error(f"malformed message (longer than {MAX_MESSAGE} bytes)")
                else:
                    msg = parse(text)
                    reply = Reply.error(msg) if isinstance(msg, str) else handle(msg)
                    mid = msg.get("id") if isinstance(msg, dict) else None
                    if isinstance(mid, str | int) and not isinstance(mid, bool):
                        reply = {**reply, "id": mid}
                client.push({"type": "reply", **reply})
                if reply["ok"] or self.session.log_error is not None:
                    self.changed()
        finally:
            writer.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await writer

    def _start_run(self) -> None:
        """The run's clock starts when the first page or robot controller connects."""
        if not self.session.clock.started:
            self.session.clock.start()
            self.changed()

    async def page_socket(self, ws: WebSocket) -> None:
        await ws.accept()
        self._start_run()
        client = _Client(ws)
        client.push(self.session.setup())
        client.push(self.session.state())
        self.pages.add(client)
        try:
            await self._serve(client, self.session.page_message)
        finally:
            self.pages.discard(client)

    async def robot_socket(self, ws: WebSocket) -> None:
        await ws.accept()
        why = ("the robot is simulated (--simulate-robot)" if self.sim is not None
               else "a robot controller is already connected" if self.robot is not None else None)
        if why:
            await ws.send_text(json.dumps({"type": "reply", "ok": False, "error": f"refused: {why}"}))
            await ws.close(code=1008)
            return
        self._start_run()
        client = self.robot = _Client(ws)
        self.session.robot_link = "connected"
        client.push({"type": "hello", "now": self.session.now(), "speed": self.session.clock.speed})
        self.changed()  # the decision to the robot, the link to the pages
        try:
            await self._serve(client, self.session.robot_message)
        finally:
            if self.robot is client:
                self.robot = None
                self.session.robot_link = "none"
                self.changed()

    # -- time passing -------------------------------------------------------------------------------
    async def _ticker(self) -> None:
        s = self.session
        while self.tick > 0:
            await asyncio.sleep(self.tick / s.clock.speed)
            if s.clock.started and not s.finished and s.clock.now() - s.dispatcher.now >= self.tick:
                error_before = s.log_error
                if s.tick()["ok"] or s.log_error != error_before:
                    self.changed()

    @contextlib.asynccontextmanager
    async def _lifespan(self, app: Starlette) -> AsyncIterator[None]:
        ticker = asyncio.create_task(self._ticker())
        if self.sim is not None:
            self.sim.update()
        try:
            yield
        finally:
            ticker.cancel()
            if self.sim is not None:
                self.sim.stop()
            for client in list(self.pages):
                if client.ws.client_state == WebSocketState.CONNECTED:
                    with contextlib.suppress(Exception):
                        await client.ws.close(code=1001)
            self.session.logged.close()
