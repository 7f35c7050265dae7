"""Temporal net creator (Strassmair & Taylor 2014, section V.A): one STNU per plan.

For every leg of every agent (travel to a phase's location, then the phase's manipulation) the STNU
has four timepoints, named for what they are: ``AGENT.PHASE.ACTION.depart``, ``.arrive``, ``.start``,
``.end``, plus the origin ``start`` (the task's start, T = 0). Links, in milliseconds:

- travel ``depart -> arrive``: the human's is a **contingent** link ``[free, max * travel_slack]``
  (a person walks at most at their speed, sometimes slower, `Agent.travel_slack`; the co-worker may
  be in the way); the
  robot's is a **requirement** link ``[max, +inf)``: the robot yields to the human, so it must plan for
  the worst-case time the co-worker costs it (``max`` from motion acquisition), and may drive slower;
- manipulation ``start -> end``: contingent ``[lb, ub]`` for the human, requirement ``[lb, ub]`` for the
  robot (the phase's duration bounds for that agent);
- waiting: ``start -> first depart``, ``arrive -> start`` and ``end -> next depart`` are ``[0, +inf)``;
- task graph: ``before.end -> after.start`` in ``[0, +inf)``;
- temporal constraints: ``lb <= T(to) - T(from) <= ub`` between the named events;
- makespan deadline: ``0 <= T(last end) - T(start) <= deadline`` for each agent's last phase.

A leg with no travel (already there) gets ``depart -> arrive`` in ``[0, 0]``. Seconds are converted to
ticks here and only here: contingent bounds are widened outward (floor lb, ceil ub) so rounding never
makes a plan look more controllable than it is; requirement bounds are rounded to the nearest tick.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from hrc.model import Event, Plan, Task
from hrc.motion import Motion
from hrc.plans import Leg, agent_legs
from hrc.temporal import STNU, ContingentLink, RequirementLink
from hrc.temporal.ticks import to_ticks

__all__ = ["ORIGIN", "TICKS_PER_SECOND", "PlanNetwork", "create_stnu", "event_timepoint", "leg_timepoint",
           "seconds_to_ticks"]

TICKS_PER_SECOND = 1000
"""The temporal core's exact unit: milliseconds."""

ORIGIN = "start"


def seconds_to_ticks(s: float) -> int:
    """Model seconds to the core's ticks, rounded to the nearest (`hrc.temporal.ticks.to_ticks`)."""
    return to_ticks(s, TICKS_PER_SECOND)


def _floor_ticks(s: float) -> int:
    return math.floor(s * TICKS_PER_SECOND + 1e-9)


def _ceil_ticks(s: float) -> int:
    return math.ceil(s * TICKS_PER_SECOND - 1e-9)


def leg_timepoint(leg: Leg, what: str) -> str:
    """``AGENT.PHASE.ACTION.WHAT`` with WHAT in depart / arrive / start / end."""
    return f"{leg.agent}.{leg.phase}.{leg.action}.{what}"


def event_timepoint(plan: Plan, event: Event) -> str:
    """The timepoint of a task event (``ACTION.PHASE.start|end``) in `plan`'s STNU."""
    return f"{plan.agent_of(event.action)}.{event.phase}.{event.action}.{event.boundary}"


@dataclass(frozen=True, slots=True)
class PlanNetwork:
    """A plan's STNU and, per link ``(source, target)``, what it means in words (for explanations)."""

    stnu: STNU
    meaning: tuple[tuple[tuple[str, str], tuple[str, str]], ...]  # (source, target) -> (kind, text)
    last_ends: tuple[str, ...]


def create_stnu(task: Task, plan: Plan, motions: tuple[Motion, ...]) -> PlanNetwork:
    """Encode `plan` (with its motions' duration bounds) as an STNU; see the module docstring."""
    timepoints: list[str] = [ORIGIN]
    reqs: list[RequirementLink] = []
    conts: list[ContingentLink] = []
    meaning: dict[tuple[str, str], tuple[str, str]] = {}
    motion_of = {(m.agent, m.leg): m for m in motions}
    last_ends = []

    # kinds: "human" (a contingent duration), "robot" (a robot duration), "limit" (deadline or
    # temporal constraint), "order" (sequencing, waiting, task graph)
    def req(a: str, b: str, lb: int | None, ub: int | None, kind: str, text: str) -> None:
        reqs.append(RequirementLink(a, b, lb, ub))
        meaning.setdefault((a, b), (kind, text))

    def cont(a: str, b: str, lb: float, ub: float, text: str) -> None:
        conts.append(ContingentLink(a, b, _floor_ticks(lb), _ceil_ticks(ub)))
        meaning[(a, b)] = ("human", text)

    for agent in task.agents:
        prev_end = ORIGIN
        for leg in agent_legs(task, plan, agent.id):
            dep, arr, st, en = (leg_timepoint(leg, w) for w in ("depart", "arrive", "start", "end"))
            timepoints += [dep, arr, st, en]
            step = f"{leg.action}.{leg.phase}"
            req(prev_end, dep, 0, None, "order", f"{agent.id} leaves for {step} after its previous step")
            motion = motion_of[(agent.id, leg.index)]
            route = f"{agent.id}'s travel {leg.origin} -> {leg.location}"
            if motion.max_time <= 0:
                req(dep, arr, 0, 0, "order", f"{agent.id} is already at {leg.location}")
            elif agent.is_human:
                ub = motion.max_time * agent.travel_slack
                cont(dep, arr, motion.free_time, ub, f"{route} ({motion.free_time:.1f}-{ub:.1f} s)")
            else:
                why = ""
                if motion.interference:
                    causes = ", ".join(f"{i.other_agent} {i.other_origin}->{i.other_target}"
                                       for i in motion.interference)
                    why = f", incl. {motion.max_time - motion.free_time:.1f} s yielding to {causes}"
                req(dep, arr, seconds_to_ticks(motion.max_time), None, "robot",
                    f"{route} (>= {motion.max_time:.1f} s{why})")
            req(arr, st, 0, None, "order", f"{agent.id} waits at {leg.location} before {leg.action}.{leg.phase}")
            bounds = task.action(leg.action).phase(leg.phase).duration(agent.id)
            what = f"{agent.id}'s {leg.phase} of {leg.action} ({bounds.lb:g}-{bounds.ub:g} s)"
            if agent.is_human:
                cont(st, en, bounds.lb, bounds.ub, what)
            else:
                req(st, en, seconds_to_ticks(bounds.lb), seconds_to_ticks(bounds.ub), "robot", what)
            prev_end = en
        if prev_end != ORIGIN:
            last_ends.append(prev_end)

    for pr in task.precedence:
        a = event_timepoint(plan, Event(pr.before.action, pr.before.phase, "end"))
        b = event_timepoint(plan, Event(pr.after.action, pr.after.phase, "start"))
        req(a, b, 0, None, "order", f"task graph: {pr.after} after {pr.before}")
    for c in task.constraints:
        a, b = event_timepoint(plan, c.source), event_timepoint(plan, c.target)
        c_ub = None if math.isinf(c.bounds.ub) else seconds_to_ticks(c.bounds.ub)
        req(a, b, seconds_to_ticks(c.bounds.lb), c_ub, "limit",
            f"constraint {c.target} - {c.source} in [{c.bounds.lb:g}, {c.bounds.ub:g}] s")
    if task.deadline is not None:
        for end in last_ends:
            req(ORIGIN, end, 0, seconds_to_ticks(task.deadline), "limit", f"makespan deadline {task.deadline:g} s")

    stnu = STNU(tuple(timepoints), tuple(reqs), tuple(conts), name=f"{task.name}:{plan.id}")
    return PlanNetwork(stnu=stnu, meaning=tuple(sorted(meaning.items())), last_ends=tuple(last_ends))
