"""The simulated robot of ``hrc console --simulate-robot``: it does what the dispatcher decides, each
event at the start of its window.

A `RobotStep` with window ``[earliest, latest]`` is acknowledged at run time ``earliest`` (or at once,
when the dispatcher's time is already past it); the end of a robot phase, whose window starts at the
phase's start plus its shortest duration, therefore comes after a duration inside the robot's bounds.
When the decision changes before the event is due (the person pressed something), the pending event
is dropped and the new decision's is scheduled. Acknowledgements go through the same
`ConsoleSession.robot_message` as a real controller's.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Callable

from hrc.console.session import ConsoleSession

__all__ = ["SimulatedRobot"]


class SimulatedRobot:
    """Schedules the robot's next event on the running event loop; `update()` after every change."""

    def __init__(self, session: ConsoleSession, changed: Callable[[], None]) -> None:
        self.session = session
        self.changed = changed
        self._key: tuple[str, str, str, float] | None = None
        self._handle: asyncio.TimerHandle | None = None
        self.errors: list[str] = []

    def update(self) -> None:
        step = self.session.robot_step()
        key = None if step is None else (step.action, step.phase, step.event, step.earliest)
        if key == self._key:
            return
        self.stop()
        self._key = key
        if step is not None and key is not None and self.session.clock.started:
            delay = self.session.clock.real_delay(step.earliest) + 0.002  # never a hair early
            self._handle = asyncio.get_running_loop().call_later(delay, self._act, key)

    def stop(self) -> None:
        if self._handle is not None:
            self._handle.cancel()
        self._handle = None
        self._key = None

    def _act(self, key: tuple[str, str, str, float]) -> None:
        self._handle = None
        action, phase, event, earliest = key
        t = max(earliest, self.session.dispatcher.now)
        reply = self.session.robot_message(json.dumps({"type": "ack", "action": action, "phase": phase,
                                                       "event": event, "t": t}), source="simulated robot")
        if reply["ok"]:
            self.changed()
        else:  # shown in the log; the run waits for the person
            self.errors.append(str(reply["error"]))
