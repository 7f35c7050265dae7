"""The robot's safe fallback when no compiled plan agrees with what was seen (issue 35, compile on demand).

When the person does something no plan of the set has (with a searched compile, `hrc.compile.search`,
the set holds the best plans and a plan for their first choices, not every plan), the dispatcher has no
plan to decide from until plans that extend the history are compiled (`hrc.dispatch.on_demand`). Its
answer meanwhile is the robot's next step that *every* plan extending the history allows:

- a leg under way is never preempted (set validation keeps only plans that continue every leg under
  way with its agent, and History refuses a new leg before the current one ended; Strassmair & Taylor
  2014, section V.B, footnote 3: non-preemptive), so every such plan has the robot finish it: its next
  event on that leg, ``"fallback": "continue"``. The arrival of a drive keeps the window it was told
  (the drive's own time); an end of its manipulation comes within the phase's duration bounds after its
  start; a start waits for the task graph (`hrc.model.Task.precedence`) like any start;
- a stop at a waiting place (``park``) is left only when a plan's passing order says so: wait;
- between legs the plans that extend the history may differ in the robot's next leg, so there is no
  step they all allow: wait (robot None, ``"fallback": "wait"``).

No step here rests on the plans' temporal guarantee (there is no plan): the answer says so with its
``fallback`` key, and the class is None.
"""

from __future__ import annotations

from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

from .messages import Decision, RobotStep, WaitFor
from .validation import History

__all__ = ["fallback_decision", "fallback_step"]

_NEXT = {"depart": "arrive", "unpark": "arrive", "arrive": "start", "start": "end"}


def fallback_step(history: History, robot: str, told: RobotStep | WaitFor | None) -> RobotStep | None:
    """The robot's next step that every plan extending `history` allows (module docstring), or None
    (wait). `told`: the robot's step in the last answer (a drive under way keeps its window)."""
    task = history.task
    current = history.current(robot)
    if current is None:
        return None
    action, phase = current
    last = history.last_event(robot, action, phase)
    event = _NEXT.get(last or "")
    if event is None:
        return None
    now = history.now
    if isinstance(told, RobotStep) and (told.action, told.phase, told.event) == (action, phase, event):
        return RobotStep(action, phase, event, max(now, told.earliest), told.latest)
    if event == "start":
        for p in task.precedence:
            if (p.after.action, p.after.phase) == current and (p.before.action, p.before.phase) not in history.ended:
                return None
        return RobotStep(action, phase, event, now, None)
    if event == "end":
        bounds = task.action(action).phase(phase).duration(robot)
        began = history.times[(robot, action, phase, "start")]
        latest = None if bounds.ub == float("inf") else round(max(now, began + bounds.ub), 3)
        return RobotStep(action, phase, event, round(max(now, began + bounds.lb), 3), latest)
    return RobotStep(action, phase, event, now, None)


def fallback_decision(history: History, robot: str, told: RobotStep | WaitFor | None,
                      counts: Mapping[str, int], ack: Any, deviation: Mapping[str, Any] | None) -> Decision:
    """The answer while no plan agrees with `history` (module docstring)."""
    step = fallback_step(history, robot, told)
    return Decision(history.now, None, None, MappingProxyType(dict(counts)), step, history.away, False, None, ack,
                    deviation, None, "wait" if step is None else "continue")
