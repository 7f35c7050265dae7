"""The simulated robot of ``hrc console --simulate-robot``: it does what the dispatcher decides, each
event at the start of its window.

A `RobotStep` with window ``[earliest, latest]`` is acknowledged at run time ``earliest`` (or at once,
when the dispatcher's time is already past it); the end of a robot phase, whose window starts at the
phase's start plus its shortest duration, therefore comes after a duration inside the robot's bounds.
When the decision changes before the event is due (the person pressed something), the pending event
is dropped and the new decision's is scheduled. Acknowledgements go through the same
`ConsoleSession.robot_message` as a real controller's.

A joint action (issue 37) the robot has started ends when its last role is done, which a real controller
senses; told to wait for that end, the simulated robot reports it at the earliest the step can end (its
start plus the largest of the roles' shortest durations), as it does every event at its window's start.

A team's console (issue 37) runs one simulated robot per robot id, each acting on its own entry of the
decision's ``robots`` and acknowledging under its own id.
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Callable

from hrc.console.session import ConsoleSession
from hrc.dispatch.messages import WaitFor

__all__ = ["SimulatedRobot"]


class SimulatedRobot:
    """Schedules the robot's next event on the running event loop; `update()` after every change."""

    def __init__(self, session: ConsoleSession, changed: Callable[[], None], robot: str | None = None) -> None:
        self.session = session
        self.changed = changed
        self.robot = robot  # a team's robot id (None: the one robot of one person and one robot)
        self._key: tuple[str, str, str, float] | None = None
        self._handle: asyncio.TimerHandle | None = None
        self.errors: list[str] = []

    def update(self) -> None:
        step = self.session.robot_step(self.robot)
        key = self._joint_end() if step is None else (step.action, step.phase, step.event, step.earliest)
        if key == self._key:
            return
        self.stop()
        self._key = key
        if key is not None and self.session.clock.started:
            delay = self.session.clock.real_delay(key[3]) + 0.002  # never a hair early
            self._handle = asyncio.get_running_loop().call_later(delay, self._act, key)

    def _joint_end(self) -> tuple[str, str, str, float] | None:
        """Told to wait for its own end of a joint phase it started: that end, at the earliest it can be."""
        d = self.session.dispatcher
        wait = d.decision.robot if self.robot is None else (d.decision.robots or {}).get(self.robot)
        if not isinstance(wait, WaitFor) or wait.event != "end" or not d.task.action(wait.action).joint \
                or self.session.lead(wait.action) != wait.agent \
                or (self.robot is not None and wait.agent != self.robot):
            return None
        started = d.seen.times.get((wait.agent, wait.action, wait.phase, "start"))
        if started is None:
            return None
        phase = d.task.action(wait.action).phase(wait.phase)
        shortest = max(iv.lb for _, iv in phase.durations)
        return (wait.action, wait.phase, "end", round(started + shortest, 3))

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
                                                       "event": event, "t": t}), source="simulated robot",
                                          robot=self.robot)
        if reply["ok"]:
            self.changed()
        else:  # shown in the log; the run waits for the person
            self.errors.append(str(reply["error"]))
