"""Open a console on an `hrc compile` output folder and serve it (what ``hrc console`` calls)."""

from __future__ import annotations

import asyncio
import gc
import logging
import os
import signal
import socket
import threading
from collections.abc import Callable
from typing import Any

import uvicorn

from hrc.compile.output import read_header
from hrc.console.access import Credentials
from hrc.console.clock import RunClock
from hrc.console.connections import KEEP_ALIVE, limited_protocol
from hrc.console.runlog import next_log_path, open_log, resume_log
from hrc.console.server import MAX_FRAME, ConsoleServer
from hrc.console.session import ConsoleSession
from hrc.console.supervise import DenialFilter, ThrottleFilter
from hrc.dispatch import Dispatcher
from hrc.dispatch.routes import PlanRoutes, plan_motions
from hrc.errors import HrcError
from hrc.motion import plan_paths

__all__ = ["open_console", "serve"]

_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def open_console(out_dir: str | os.PathLike[str], *, speed: float = 1.0, log: str | os.PathLike[str] | None = None,
                 simulate_robot: bool = False, tick: float = 2.0, credentials: Credentials | None = None,
                 resume: str | os.PathLike[str] | None = None, allow_partial: bool = False,
                 report: Callable[[str], None] | None = None,
                 record: str | os.PathLike[str] | None = None, detect: Any = None,
                 record_format: str = "foxglove") -> ConsoleServer:
    """A console for the compiled plan set in `out_dir`, its log at `log` (default: the first free
    ``OUT_DIR/runs/console-N.jsonl``), or the run logged at `resume` continued (its torn end, if any,
    reported through `report`), `credentials` its secrets (default: new ones); `detect`: the motion
    detector's `hrc.detect.DetectParams` (None: buttons only). The run's clock starts
    when the first page or robot controller connects.

    Raises `InputError` when `out_dir` is not an ``hrc compile`` output (or a partial one, unless
    `allow_partial`), when `log` holds a run already, when a log is held by another process, or when
    `resume` is no log of this compiled set. Cost: loading the plan set (its dispatch form: well under a
    second for 40,320 plans) and planning the free-space paths again (about 2 s for the workshop).
    `record`: also record the run as MCAP into this new file (`hrc.record`; ``session.recording``, which
    the caller closes when the server has stopped), in `record_format` (`hrc.record.FORMATS`).
    """
    if detect is not None:  # the motion detector in front (`hrc.detect`): `detect` is its DetectParams
        from hrc.detect import DetectingDispatcher

        dispatcher = DetectingDispatcher.from_folder(out_dir, allow_partial=allow_partial, params=detect)
    else:
        dispatcher = Dispatcher.from_folder(out_dir, allow_partial=allow_partial)
    compiled = read_header(out_dir)
    routes = PlanRoutes(plan_motions(out_dir, dispatcher.plan_set),
                        plan_paths(dispatcher.task, seed=int(compiled.get("seed", 0))))
    recording = None
    if record is not None:  # before the log: a taken name must not leave a new log behind
        from hrc.record import open_folder_recording

        recording = open_folder_recording(record, out_dir, dispatcher, report, routes.routes, record_format,
                                          ways=routes.way)
    try:
        if resume is not None:
            logged, resumed = resume_log(resume, dispatcher)
            if resumed.torn is not None and report is not None:
                report(f"{resume}: {resumed.torn}")
        else:
            logged = open_log(next_log_path(out_dir) if log is None else log, dispatcher)
    except BaseException:
        if recording is not None:
            recording.abort()
        raise
    if recording is not None:
        if resume is not None:
            recording.feed((m.data, m.answer) for m in resumed.replayed)
        logged.listeners.append(recording.listener)
    session = ConsoleSession(logged, compiled, routes, RunClock(speed, offset=logged.dispatcher.now))
    session.recording = recording
    if resume is not None:
        session.restore(resumed.replayed)
        if report is not None:
            report(f"resumed {resume} after {resumed.messages} messages (each answered as logged), "
                   f"at run time {logged.dispatcher.now:g} s")
    return ConsoleServer(session, simulate_robot=simulate_robot, tick=tick, credentials=credentials)


MAX_HEADER_BYTES = 16384
"""Bytes of a request line and headers at most (h11 answers 431 beyond)."""


def _quiet_logs(server: ConsoleServer) -> None:
    """uvicorn's and asyncio's errors at most once a second per kind (with the count held back), and
    not the line uvicorn writes after every refused websocket (`hrc.console.supervise.DenialFilter`)."""
    denials = DenialFilter()
    server.guard.on_refused_upgrade = denials.refused
    throttle = ThrottleFilter()
    for name in ("uvicorn.error", "asyncio"):
        logger = logging.getLogger(name)
        for old in [f for f in logger.filters if isinstance(f, DenialFilter | ThrottleFilter)]:
            logger.removeFilter(old)  # (a second console in one process)
        if name == "uvicorn.error":
            logger.addFilter(denials)
        logger.addFilter(throttle)


class _Server(uvicorn.Server):
    """uvicorn's server with the listening queue `backlog` long while asyncio accepts ``config.backlog``
    at a time (`hrc.console.connections`): asyncio takes one number for both, ``listen()`` and its
    accepts per wake-up, so the queue is set again once it listens (``listen()`` on a listening socket
    sets its queue's length)."""

    def __init__(self, config: uvicorn.Config, backlog: int) -> None:
        super().__init__(config)
        self.backlog = backlog

    async def startup(self, sockets: list[socket.socket] | None = None) -> None:
        await super().startup(sockets=sockets)
        for sock in sockets or ():
            sock.listen(self.backlog)


def serve(server: ConsoleServer, host: str = "127.0.0.1", port: int = 8765,
          ready: Callable[[str], None] | None = None) -> str:
    """Serve until SIGINT or SIGTERM; `ready(base_url)` is called once the socket listens (port 0: any
    free port), with the address served (``http://HOST:PORT/``, no token). Returns the name of the signal
    that stopped it ("" when none did), once the server has shut down gracefully (the message being
    handled finished, in the log and answered): a stop, as ``hrc ros2``'s, not an error. Raises
    `HrcError` when the address cannot be listened on."""
    sock = socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET, socket.SOCK_STREAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        sock.bind((host, port))
        sock.listen(server.connections.backlog)  # the kernel's queue: long, no descriptor of ours
    except (OSError, OverflowError) as err:
        sock.close()
        raise HrcError(f"cannot listen on {host}:{port}: {getattr(err, 'strerror', None) or err}") from err
    bound = sock.getsockname()[1]
    server.guard.listen(host, bound)
    # proxy_headers off: no client may pass itself off as another address or scheme. Connections are
    # bounded below the app (`hrc.console.connections`): a cap under the open-file limit, a deadline for
    # headers, unauthenticated ones shed first; h11 bounds a request's headers to MAX_HEADER_BYTES
    config = uvicorn.Config(server.app, log_level="warning", ws_max_size=MAX_FRAME, ws_ping_interval=5.0,
                            ws_ping_timeout=10.0, timeout_graceful_shutdown=2, lifespan="on",
                            proxy_headers=False, server_header=False, http=limited_protocol(server.connections),
                            timeout_keep_alive=int(KEEP_ALIVE), h11_max_incomplete_event_size=MAX_HEADER_BYTES,
                            backlog=server.connections.burst)
    _quiet_logs(server)
    if ready is not None:
        shown = f"[{host}]" if ":" in host else host
        ready(f"http://{shown}:{bound}/")
    # What was loaded (the plan set, the paths: some 90,000 objects) moves to the garbage collector's
    # permanent generation: a full collection scanned it for ~100 ms, a pause in front of the robot's
    # next acknowledgement (the `gc` docs' advice for a long-lived server with a large, stable heap)
    gc.freeze()
    # uvicorn takes SIGINT and SIGTERM while it serves, shuts down gracefully and then raises the signal
    # again for the handler that was in place: here one that notes it (hrc.cli's would make it an error)
    stop: list[int] = []
    main = threading.current_thread() is threading.main_thread()
    previous = {s: signal.signal(s, lambda signum, _frame: stop.append(signum)) for s in _STOP_SIGNALS} if main else {}
    try:
        asyncio.run(_Server(config, server.connections.backlog).serve(sockets=[sock]))
    finally:
        gc.unfreeze()  # let the bindings' objects be collected at exit, as usual
        for s, handler in previous.items():
            signal.signal(s, handler)
    return signal.Signals(stop[0]).name if stop else ""
