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

**Teams** (issue 37): every robot gets its own step by the same rule (`fallback_steps`), each from its
own legs, so a robot is only ever told the next event of a leg it is on itself: never the start of an
action another robot or a person is doing or has done (History refuses a second doer), never a new leg.
A joint action (`hrc.model.Action.roles`; its start and end are its lead's, `hrc.model.Task.lead`) is
started only when every agent of its crew has been seen arriving at the place (a crew the plan chooses,
`hrc.model.Action.crews`: the agents seen on it, once they are one of its crews; until then it is held,
waiting for the arrival of one seen on it, or with no step): until then its lead waits for
the first missing arrival (``wait_for``, as `Dispatcher._joint_hold` with a plan); its end is nature's
when a person takes part (the lead is told to wait for it), else within the longest of its agents'
duration bounds; an agent of it that is not its lead has no start or end of its own and waits. The
people are told nothing (their hints come from a plan).

No step here rests on the plans' temporal guarantee (there is no plan): the answer says so with its
``fallback`` key (``"continue"`` when some robot has a step, else ``"wait"``), and the class is None.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any

from hrc.model import Action

from .messages import Decision, RobotStep, WaitFor
from .validation import History

__all__ = ["fallback_decision", "fallback_step", "fallback_steps"]

_NEXT = {"depart": "arrive", "unpark": "arrive", "arrive": "start", "start": "end"}


def fallback_step(history: History, robot: str, told: RobotStep | WaitFor | None) -> RobotStep | WaitFor | None:
    """The robot's next step that every plan extending `history` allows (module docstring), or None
    (wait). `told`: the robot's step in the last answer (a drive under way keeps its window). A `WaitFor`
    only on a joint action (its start waits for every agent's arrival; its end with a person is nature's)."""
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
    act = task.action(action)
    crew = _crew(history, act) if act.joint else (robot,)
    if act.joint and event in ("start", "end"):
        held, instead = _joint(history, robot, crew, action, phase, event)
        if held:
            return instead
    if isinstance(told, RobotStep) and (told.action, told.phase, told.event) == (action, phase, event):
        return RobotStep(action, phase, event, max(now, told.earliest), told.latest)
    if event == "start":
        for p in task.precedence:
            if (p.after.action, p.after.phase) == current and (p.before.action, p.before.phase) not in history.ended:
                return None
        return RobotStep(action, phase, event, now, None)
    if event == "end":
        ph, doers = act.phase(phase), crew or (robot,)  # a joint one: its crew's slowest role
        lb, ub = max(ph.duration(a).lb for a in doers), max(ph.duration(a).ub for a in doers)
        began = history.times[(robot, action, phase, "start")]
        latest = None if ub == float("inf") else round(max(now, began + ub), 3)
        return RobotStep(action, phase, event, round(max(now, began + lb), 3), latest)
    return RobotStep(action, phase, event, now, None)


def _crew(history: History, act: Action) -> tuple[str, ...] | None:
    """The agents of a joint action's crew (task order): its one crew, or where the plan chooses it
    (`Action.crew_choice`) the agents seen on it (a leg of it begun) once they are one of its crews; None
    until then."""
    if not act.crew_choice:
        return act.agents
    seen = tuple(ag for ag in act.agents if act.id in history.actions_seen(ag))
    return seen if seen in act.crews else None


def _joint(history: History, robot: str, agents: tuple[str, ...] | None, action: str, phase: str,
           event: str) -> tuple[bool, WaitFor | None]:
    """The start or end of a joint action for `robot` (`agents`: its crew, `_crew`): whether it is held, and
    what it is told instead (module docstring); not held, it is told as any leg's. A crew not complete yet
    (a choice of the plan, only some of it seen): held, waiting for the arrival of the first agent seen on
    it that has not arrived, else with no step."""
    task = history.task
    if agents is None:
        act = task.action(action)
        for other in act.agents:
            if (other != robot and action in history.actions_seen(other)
                    and (other, action, phase, "arrive") not in history.times):
                return True, WaitFor(other, action, phase, "arrive")
        return True, None
    lead = task.crew_lead(agents)
    if robot != lead:
        return True, None  # its lead starts and ends it
    if event == "start":
        for other in agents:
            if other != robot and (other, action, phase, "arrive") not in history.times:
                return True, WaitFor(other, action, phase, "arrive")
        return False, None
    if any(task.agent(a).is_human for a in agents):  # nature's: the last role done
        return True, WaitFor(robot, action, phase, "end")
    return False, None


def fallback_steps(history: History, robots: Sequence[str],
                   told: Mapping[str, RobotStep | WaitFor | None]) -> dict[str, RobotStep | WaitFor | None]:
    """Every robot's fallback step (`fallback_step`, each from its own legs), by id in `robots`' order;
    `told`: each robot's step in the last answer."""
    return {r: fallback_step(history, r, told.get(r)) for r in robots}


def fallback_decision(history: History, robot: str, told: RobotStep | WaitFor | None,
                      counts: Mapping[str, int], ack: Any, deviation: Mapping[str, Any] | None,
                      team: Mapping[str, Any] | None = None) -> Decision:
    """The answer while no plan agrees with `history` (module docstring): `robot`'s step. For a team
    (`team`: `Dispatcher._per_agent`'s ``robots``, ``people``, ``aheads``, ``away``, with every robot's
    step from `fallback_steps`), `robot` is the first robot and the key ``fallback`` says ``"continue"``
    when any robot has a step."""
    step = fallback_step(history, robot, told) if team is None else team["robots"].get(robot)
    steps = [step] if team is None else list(team["robots"].values())
    return Decision(history.now, None, None, MappingProxyType(dict(counts)), step, history.away, False, None, ack,
                    deviation, None, "wait" if all(s is None for s in steps) else "continue", **(team or {}))
