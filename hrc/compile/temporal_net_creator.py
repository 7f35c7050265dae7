"""Temporal net creator (Strassmair & Taylor 2014, section V.A): one STNU per plan.

For every leg of every agent (travel to a phase's location, then the phase's manipulation) the STNU
has four timepoints, named for what they are: ``AGENT.PHASE.ACTION.depart``, ``.arrive``, ``.start``,
``.end``, plus the origin ``Z`` (the task's start, T = 0; the CSTNU Tool's name for it). Links, in
milliseconds:

- travel ``depart -> arrive``: the human's is a **contingent** link ``[t, t * travel_slack]`` along the
  shortest route (a person walks at most at their speed, sometimes slower, `Agent.travel_slack`); the
  robot's is a **rigid requirement** ``[t, t]`` along its route (shortest or a detour): the robot drives
  without stopping, so where it is at every moment of a trip is known, which the passing orders rely on;
- manipulation ``start -> end``: contingent ``[lb, ub]`` for the human, requirement ``[lb, ub]`` for the
  robot (the phase's duration bounds for that agent);
- waiting: ``Z -> first depart``, ``arrive -> start`` and ``end -> next depart`` are ``[0, +inf)``:
  an agent waits where it stands (see "the human" below);
- task graph: ``before.end -> after.start`` in ``[0, +inf)``;
- **passing orders** (spatial constraints, `hrc.motion.conflicts`): at each place where the two agents'
  occupancies would meet, the plan's chosen order as ``T(later) - T(earlier) >= gap``, rounded up;
- temporal constraints: ``lb <= T(to) - T(from) <= ub`` between the named events;
- makespan deadline: ``0 <= T(last end) - T(Z) <= deadline`` for each agent's last phase.

The constraints the task *asks for* (temporal constraints and the deadline, kind "limit") come last in
``stnu.requirements`` (`PlanNetwork.n_limits` of them), so that a schedule can be computed without them
(a plan that breaks the deadline is still the instruction for finishing the task).

**The human.** As in the paper, only the human's *durations* are contingent: the robot's strategy
decides when the human leaves for a step and starts it (the human waits when asked). The stricter
reading ``human_waits=False`` (`hrc compile --human-waits no`) takes that from the robot: the human
leaves for each step the moment the previous one ends (``end -> next depart`` in ``[0, 0]``, the first
departure at T = 0) and starts a manipulation on arrival (``arrive -> start`` in ``[0, 0]``) unless the
task graph makes them wait for a phase of the robot's, in which case the start stays free after the
arrival (the person waits for the task, which the robot cannot hurry beyond its own steps).

**Waiting places.** A leg whose route stops at a waiting place (`hrc.motion.motions.Route`: the agent's
own start, out of the co-worker's way) has two more timepoints, ``.park`` (there) and ``.unpark``
(leaving it): ``depart -> park`` and ``unpark -> arrive`` are travel links as above, ``park -> unpark``
is ``[0, +inf)``, the wait.

A leg with no travel (already there) gets ``depart -> arrive`` in ``[0, 0]``. Seconds are converted to
ticks here and only here: contingent bounds are widened outward (floor lb, ceil ub) and passing-order
gaps rounded up, so rounding never makes a plan look more controllable than it is; other requirement
bounds are rounded to the nearest tick.

**Joint actions** (issue 37; Strassmair & Taylor 2014, section IV, "support the pile", left there for
future work). A phase of a joint action (`hrc.model.Action.roles`) is on a leg of every agent of it, and
is one synchronisation: each agent travels to the place as usual (its own ``depart``, ``arrive``), and the
phase has **one start and one end for all**, the timepoints of its *lead* (`hrc.model.Task.lead`, the
robot: ``robot.PHASE.ACTION.start`` / ``.end``; the other agents' legs have no start or end of their own,
`leg_names` names the lead's for them). Links:

- ``arrive -> start`` in ``[0, +inf)`` for *each* agent of it: the start waits for every arrival (also
  with ``human_waits=False``: the person waits at the place for the co-worker);
- ``start -> end``: the phase lasts until the last role is done, ``[max lb, max ub]`` over the roles'
  durations, **contingent** when a person takes part (a requirement link when only robots do). For a
  robot role whose duration the robot picks this over-approximates what can happen (the true end is
  ``max(person's, robot's)``, inside the range whatever the robot picks), so a DC verdict is sound;
- every agent's next ``depart`` follows the one end; the task graph and the limits name the action's
  events as usual (`event_timepoint` finds the lead through the plan's allocation).

*What DC means here.* The start is controllable (the robot executes it), and every person's arrival is a
contingent timepoint that must precede it. A dynamic strategy may execute a timepoint only on what it
has observed, so it cannot execute the start while an arrival before it is still unobserved: executing it
at t with the arrival unobserved would let nature put the arrival after t and break ``start >= arrive``.
So in a DC plan the robot *waits for the person's arrival event* and then starts (at once, or later if
other constraints say so), and the residual network stays DC whatever the person's walk and share of the
work take. The real-time execution (`hrc.temporal.execution`, the dispatcher's DC mode) gives the start
no window before the arrival is observed (`tests/test_joint.py`, hypothesis over histories). With
``human_waits`` (the paper's reading) the robot also says when the person leaves for the place, so it can
choose the person's departure late enough that both meet without idling long; the person's walk and the
phase's end stay contingent. The CSTNU Tool reads these networks as they are (one contingent link per
person's walk, one per joint phase) and agrees on every one of `tasks/cube_stacking_joint.yaml`.

**More agents** (issue 37). Nothing here counts to two: every agent's legs get their timepoints, every
person's travels and manipulations are contingent links and every robot's requirements, whoever else is
on the floor; a person's "waits for the robot" (``human_waits=False``) reads "waits for another agent's
step"; the deadline bounds every agent's last end. The passing orders between two robots
(`hrc.motion.conflicts.floor_pairs`) are requirement links like those between a robot and a person; two
people get none (`hrc.motion.conflicts.people_meetings`). A joint action's lead is its first robot.

**One tick.** A person's action that may take no time at all (a duration ``[0, ub]`` with ``ub > 0``)
gets the contingent link ``[1 ms, ub]``: a person's action takes at least a millisecond. The CSTNU Tool
reads contingent links only with ``0 < lb`` (`hrc.temporal.graphml`), and this keeps every STNU the
compile writes readable by it; a duration of exactly ``[0, 0]`` stays a fixed duration (written as a
requirement link). It is the only bound rounded inward, by one tick.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

from hrc.caches import make_room
from hrc.model import Agent, Event, Plan, Task
from hrc.motion import Motion, Separation, TimeRef
from hrc.plans import Leg, agent_legs, per_plan
from hrc.temporal import STNU, ContingentLink, RequirementLink
from hrc.temporal.ticks import to_ticks

__all__ = ["ORIGIN", "TICKS_PER_SECOND", "PlanNetwork", "block_target", "blocked_stnu", "create_stnu",
           "event_timepoint", "leg_names", "leg_timepoint", "ref_namer", "ref_timepoint", "relabel_timepoints",
           "seconds_to_ticks", "with_separations"]

TICKS_PER_SECOND = 1000
"""The temporal core's exact unit: milliseconds."""

ORIGIN = "Z"


def seconds_to_ticks(s: float) -> int:
    """Model seconds to the core's ticks, rounded to the nearest (`hrc.temporal.ticks.to_ticks`)."""
    return to_ticks(s, TICKS_PER_SECOND)


def block_target(timepoints: Sequence[str], origin: str = ORIGIN) -> int:
    """The index of the timepoint that a blocked plan's network puts before the origin: the first one after
    it in the network's order (`blocked_stnu`). Raises ValueError for a network of the origin alone."""
    return next(i for i, t in enumerate(timepoints) if t != origin)


def blocked_stnu(stnu: STNU) -> STNU:
    """The network a blocked plan's STNU file holds (motion acquisition found no order of passing that keeps
    the co-workers apart, `hrc.compile.motion_pattern`): `stnu` (which carries none of the plan's passing
    orders) and ``T(X) - T(Z) <= -1`` for X its first timepoint after the origin (`block_target`): X before
    the start, which with ``T(X) >= T(Z)`` is a negative cycle, so the file alone reads inconsistent (hrc
    and the CSTNU Tool alike) as the compile ranked it. The block is in the written file and the dispatch
    form (`hrc.compile.dispatch_form.plan_record`), not in the plan's network in memory, which the
    simulator's motion-blind runs still dispatch (docs/simulate.md)."""
    x = stnu.timepoints[block_target(stnu.timepoints)]
    return stnu.inserted(len(stnu.requirements), (RequirementLink(ORIGIN, x, None, -1),))


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


def ref_timepoint(task: Task, plan: Plan, ref: TimeRef) -> str:
    """The timepoint a `TimeRef` (agent, leg index, event) names in `plan`'s STNU."""
    if ref.agent == "":
        return ORIGIN
    return leg_names(task, plan)[ref.agent][ref.leg][ref.what]  # a joint action's start and end: its lead's


_LEG_TIMEPOINTS = ("depart", "park", "unpark", "arrive", "start", "end")


@per_plan(256)
def leg_names(task: Task, plan: Plan) -> dict[str, list[dict[str, str]]]:
    """Per agent and leg, the name of each timepoint the leg may have (`leg_timepoint`), remembered per
    plan (`hrc.plans.per_plan`): a plan's compile names thousands of references (conflicts, passing
    orders, output). A joint action's phase has one start and one end for all its agents, its lead's
    (`_leg_names`)."""
    return {a.id: [_leg_names(task, plan, a.id, leg) for leg in agent_legs(task, plan, a.id)] for a in task.agents}


def _leg_names(task: Task, plan: Plan, agent: str, leg: Leg) -> dict[str, str]:
    """`_names` of a leg; for a joint action's leg of an agent other than its lead, the start and end are
    the lead's (the module docstring, "joint actions")."""
    here = _names(agent, leg.phase, leg.action)
    if not task.has_joint or not task.action(leg.action).joint:
        return here
    lead = plan.agent_of(leg.action)
    if lead == agent:
        return here
    shared = _names(lead, leg.phase, leg.action)
    return {**here, "start": shared["start"], "end": shared["end"]}


def ref_namer(task: Task, plan: Plan) -> Callable[[TimeRef], str]:
    """`ref_timepoint` for many references of one plan (the names are built once per plan)."""
    table = leg_names(task, plan)

    def name(ref: TimeRef) -> str:
        return ORIGIN if ref.agent == "" else table[ref.agent][ref.leg][ref.what]

    return name


def relabel_timepoints(task: Task, plan: Plan, other: Plan) -> dict[str, str]:
    """For two plans whose legs differ only in their actions' ids (a relabelling of identical actions,
    `hrc.plans.relabellings`): the name in `other`'s STNU of every timepoint `create_stnu` may give
    `plan`'s (every leg's, and the origin's). Raises ValueError if their legs differ otherwise."""
    names = {ORIGIN: ORIGIN}
    for agent in task.agents:
        mine, theirs = agent_legs(task, plan, agent.id), agent_legs(task, other, agent.id)
        if len(mine) != len(theirs):
            raise ValueError(f"plans {plan.id} and {other.id} give {agent.id} different numbers of legs")
        for a, b in zip(mine, theirs, strict=True):
            if (a.origin, a.location, a.phase) != (b.origin, b.location, b.phase):
                raise ValueError(f"plans {plan.id} and {other.id} differ in {agent.id}'s leg {a.index}")
        for a_names, b_names in zip(leg_names(task, plan)[agent.id], leg_names(task, other)[agent.id], strict=True):
            names.update((a_names[w], b_names[w]) for w in _LEG_TIMEPOINTS)
    return names


@dataclass(frozen=True, slots=True)
class PlanNetwork:
    """A plan's STNU and, per link ``(source, target)``, what it means in words (for explanations).

    The last `n_limits` requirement links are the task's limits (temporal constraints, deadline).
    """

    stnu: STNU
    meaning: tuple[tuple[tuple[str, str], tuple[str, str]], ...]  # (source, target) -> (kind, text)
    last_ends: tuple[str, ...]
    n_limits: int = 0
    _free: list[STNU] = field(default_factory=list, repr=False, compare=False)  # `without_limits`, once built

    def without_limits(self) -> STNU:
        """The STNU without the task's temporal constraints and deadline (built once: the classification,
        the bound and the search each read it, and the native core's index arrays of it are cached by
        identity, `hrc.temporal.rul.edge_arrays`)."""
        if not self._free:
            s = self.stnu
            self._free.append(s.truncated(len(s.requirements) - self.n_limits) if self.n_limits else s)
        return self._free[0]


# A link as `create_stnu` adds it: the link, whether it is contingent, and its meaning (``(source,
# target)``, ``(kind, text)``). A requirement's meaning is kept only if its pair has none yet; a
# contingent link's replaces any.
_Op = tuple[RequirementLink | ContingentLink, bool, tuple[str, str], tuple[str, str]]


class _Skeleton:
    """What `create_stnu` builds of one plan that does not depend on its routes (`_skeleton`, once per
    plan and reading): per leg, the key of its travel links and its links after the arrival; the task
    graph and the limits. The links themselves depend only on the legs (their agent, step, places and
    the step before), which recur across the plans of a task: each is built once per task (`_task_ops`)."""

    def __init__(self, task: Task, plan: Plan, human_waits: bool) -> None:
        self.human_waits = human_waits
        self._ops = ops = _task_ops(task)  # cleared in place at its cap, never replaced
        waits_on = ops.get(("waits on",))
        if waits_on is None:
            waits_on = ops[("waits on",)] = {}
            for p in task.precedence:
                waits_on.setdefault((p.after.action, p.after.phase), []).append(p.before.action)
        owner = dict(plan.allocation)
        self.legs: list[tuple[Agent, Leg, tuple, list[_Op]]] = []  # agent, leg, travel key, links after travel
        self.joins: set[int] = set()  # legs whose start and end are another agent's (joint actions)
        last_ends = []
        for agent in task.agents:
            prev_end = ORIGIN
            for leg in agent_legs(task, plan, agent.id):
                waits_for_robot = any(owner[b] != agent.id for b in waits_on.get((leg.action, leg.phase), ()))
                lead = owner[leg.action] if task.has_joint and task.action(leg.action).joint else None
                crew = task.crew(leg.action, plan) if lead is not None else ()  # the plan's crew of it
                key: tuple = ("after", agent.id, leg.action, leg.phase, leg.location, waits_for_robot, human_waits,
                              lead, crew)
                after = ops.get(key)
                if after is None:
                    after = ops[key] = (_after(task, agent, leg, waits_for_robot, human_waits) if lead is None
                                        else _joint_after(task, agent, leg, lead, crew))
                if lead is not None and lead != agent.id:
                    self.joins.add(len(self.legs))
                self.legs.append((agent, leg, ("travel", agent.id, leg.action, leg.phase, leg.origin, leg.location,
                                               prev_end, human_waits), after))
                prev_end = _names(lead or agent.id, leg.phase, leg.action)["end"]
            if prev_end != ORIGIN and prev_end not in last_ends:
                last_ends.append(prev_end)
        self.last_ends = tuple(last_ends)
        self.graph: list[_Op] = []
        for i, pr in enumerate(task.precedence):
            a = event_timepoint(plan, Event(pr.before.action, pr.before.phase, "end"))
            b = event_timepoint(plan, Event(pr.after.action, pr.after.phase, "start"))
            key = ("graph", i, a, b)
            op = ops.get(key)
            if op is None:
                op = ops[key] = _req(a, b, 0, None, "order", f"task graph: {pr.after} after {pr.before}")
            self.graph.append(op)
        self.limits: list[_Op] = []
        for i, c in enumerate(task.constraints):
            a, b = event_timepoint(plan, c.source), event_timepoint(plan, c.target)
            key = ("limit", i, a, b)
            op = ops.get(key)
            if op is None:
                c_ub = None if math.isinf(c.bounds.ub) else seconds_to_ticks(c.bounds.ub)
                op = ops[key] = _req(a, b, seconds_to_ticks(c.bounds.lb), c_ub, "limit",
                                     f"constraint {c.target} - {c.source} in [{c.bounds.lb:g}, {c.bounds.ub:g}] s")
            self.limits.append(op)
        if task.deadline is not None:
            for end in last_ends:
                key = ("deadline", end)
                op = ops.get(key)
                if op is None:
                    op = ops[key] = _req(ORIGIN, end, 0, seconds_to_ticks(task.deadline), "limit",
                                         f"makespan deadline {task.deadline:g} s")
                self.limits.append(op)

    def travel(self, i: int, motion: Motion) -> tuple[list[str], list[_Op]]:
        """Leg `i`'s timepoints and its links up to the arrival (the wait before it and the travel) along
        `motion`."""
        agent, leg, leg_key, _ = self.legs[i]
        ops = self._ops
        key = (*leg_key, motion.time, motion.via, motion.park, motion.park_time, motion.speed)
        found = ops.get(key)
        if found is None:
            found = ops[key] = _travel_ops(agent, leg, leg_key[6], self.human_waits, motion)
        if i in self.joins:  # the joint phase's start and end are its lead's timepoints, listed there
            return found[0][:-2], found[1]
        return found


_TASK_OPS: dict[int, tuple[Task, dict[tuple, Any]]] = {}  # per task, by identity: the last few
_TASK_OPS_CAP = 20_000  # entries kept per task (about 1 kB each: 20 MB at most)


def _task_ops(task: Task) -> dict[tuple, Any]:
    """The links `_Skeleton` has built for `task`, by what they depend on."""
    hit = _TASK_OPS.get(id(task))
    if hit is None or hit[0] is not task:
        make_room(_TASK_OPS, 4)
        hit = _TASK_OPS[id(task)] = (task, {})
    if len(hit[1]) > _TASK_OPS_CAP:
        hit[1].clear()
    return hit[1]


@functools.lru_cache(maxsize=4096)
def _names(agent: str, phase: str, action: str) -> dict[str, str]:
    """The names of a leg's timepoints (`leg_timepoint`), by what they are (callers must not change it)."""
    return {w: f"{agent}.{phase}.{action}.{w}" for w in _LEG_TIMEPOINTS}


def _after(task: Task, agent: Agent, leg: Leg, waits_for_robot: bool, human_waits: bool) -> list[_Op]:
    """A leg's links after the arrival: the wait before its step, and the step's duration."""
    here = _names(agent.id, leg.phase, leg.action)
    arr, st, en = here["arrive"], here["start"], here["end"]
    step = f"{leg.action}.{leg.phase}"
    after: list[_Op] = []
    if agent.is_human and not human_waits and not waits_for_robot:
        after.append(_req(arr, st, 0, 0, "order", f"{agent.id} starts {step} on arrival"))
    else:
        after.append(_req(arr, st, 0, None, "order", f"{agent.id} waits at {leg.location} before {step}"))
    bounds = task.action(leg.action).phase(leg.phase).duration(agent.id)
    what = f"{agent.id}'s {leg.phase} of {leg.action} ({bounds.lb:g}-{bounds.ub:g} s)"
    if agent.is_human:
        after.append(_cont(st, en, bounds.lb, bounds.ub, what))
    else:
        after.append(_req(st, en, seconds_to_ticks(bounds.lb), seconds_to_ticks(bounds.ub), "robot", what))
    return after


def _joint_after(task: Task, agent: Agent, leg: Leg, lead: str, crew: tuple[str, ...]) -> list[_Op]:
    """A joint action's leg's links after the arrival (the module docstring, "joint actions"): the one
    start waits for this agent's arrival; the lead's leg also carries the phase's duration, from the one
    start to the one end, contingent when a person takes part. Over the plan's `crew` only (`Task.crew`):
    the agents of the action the plan did not choose take no part in it."""
    here = _names(agent.id, leg.phase, leg.action)
    shared = _names(lead, leg.phase, leg.action)
    step = f"{leg.action}.{leg.phase}"
    after = [_req(here["arrive"], shared["start"], 0, None, "order",
                  f"{step} starts when {agent.id} is at {leg.location} (joint action)")]
    if agent.id != lead:
        return after
    action = task.action(leg.action)
    phase = action.phase(leg.phase)
    lb = max(phase.duration(a).lb for a in crew)
    ub = max(phase.duration(a).ub for a in crew)
    roles = ", ".join(f"{action.role_of(ag)} {ag} {phase.duration(ag).lb:g}-{phase.duration(ag).ub:g} s"
                      for role, _ in action.roles for ag in crew if action.role_of(ag) == role)
    what = f"{leg.phase} of {leg.action}, ending for all at once ({roles}: {lb:g}-{ub:g} s)"
    if any(task.agent(a).is_human for a in crew):
        after.append(_cont(shared["start"], shared["end"], lb, ub, what))
    else:
        after.append(_req(shared["start"], shared["end"], seconds_to_ticks(lb), seconds_to_ticks(ub), "robot", what))
    return after


def _travel_ops(agent: Agent, leg: Leg, prev_end: str, human_waits: bool,
                motion: Motion) -> tuple[list[str], list[_Op]]:
    """A leg's timepoints and its links up to the arrival: the wait after the step before, the travel."""
    here = _names(agent.id, leg.phase, leg.action)
    dep, arr, st, en = here["depart"], here["arrive"], here["start"], here["end"]
    step = f"{leg.action}.{leg.phase}"
    ops: list[_Op] = []
    if agent.is_human and not human_waits:
        ops.append(_req(prev_end, dep, 0, 0, "order",
                        f"{agent.id} leaves for {step} as soon as the previous step ends"))
    else:
        ops.append(_req(prev_end, dep, 0, None, "order", f"{agent.id} leaves for {step} after its previous step"))
    route = f"{agent.id}'s travel {leg.origin} -> {leg.location}"
    if motion.park:
        park, unpark = here["park"], here["unpark"]
        ops.append(_travel(agent, dep, park, motion.park_time, f"{agent.id}'s travel {leg.origin} -> {motion.park} "
                                                              f"to wait there for {step}"))
        ops.append(_req(park, unpark, 0, None, "order", f"{agent.id} waits at {motion.park} before {step}"))
        ops.append(_travel(agent, unpark, arr, motion.time - motion.park_time,
                           f"{agent.id}'s travel {motion.park} -> {leg.location}"))
        return [dep, park, unpark, arr, st, en], ops
    if motion.time <= 0:
        ops.append(_req(dep, arr, 0, 0, "order", f"{agent.id} is already at {leg.location}"))
    else:
        ops.append(_travel(agent, dep, arr, motion.time, route + (f" round {motion.via}" if motion.via else "")
                           + (f" at a reduced {motion.speed:g} m/s" if motion.speed else "")))
    return [dep, arr, st, en], ops


@per_plan(64)
def _skeleton(task: Task, plan: Plan, human_waits: bool) -> _Skeleton:
    return _Skeleton(task, plan, human_waits)


def _req(a: str, b: str, lb: int | None, ub: int | None, kind: str, text: str) -> _Op:
    return RequirementLink(a, b, lb, ub), False, (a, b), (kind, text)


def _cont(a: str, b: str, lb: float, ub: float, text: str) -> _Op:
    low, high = _floor_ticks(lb), _ceil_ticks(ub)
    if low == 0 < high:  # a person's action takes at least one tick (module docstring, "one tick")
        low = 1
    return ContingentLink(a, b, low, high), True, (a, b), ("human", text)


def _travel(agent: Agent, a: str, b: str, t: float, text: str) -> _Op:
    if t <= 0:
        return _req(a, b, 0, 0, "order", text)
    if agent.is_human:
        ub = t * agent.travel_slack
        return _cont(a, b, t, ub, f"{text} ({t:.1f}-{ub:.1f} s)")
    ticks = seconds_to_ticks(t)
    return _req(a, b, ticks, ticks, "robot", f"{text} ({t:.1f} s)")


def create_stnu(task: Task, plan: Plan, motions: Sequence[Motion],
                separations: Sequence[tuple[Separation, str]] = (), human_waits: bool = True) -> PlanNetwork:
    """Encode `plan` as an STNU (see the module docstring).

    `motions`: one per leg (`hrc.motion.plan_motions`); `separations`: the chosen passing orders, each
    with its meaning in words; `human_waits`: the paper's reading (True) or the stricter one (False).
    The links that do not depend on the routes are built once per plan (`_Skeleton`).
    """
    sk = _skeleton(task, plan, human_waits)
    motion_of = {(m.agent, m.leg): m for m in motions}
    timepoints: list[str] = [ORIGIN]
    reqs: list[RequirementLink] = []
    conts: list[ContingentLink] = []
    meaning: dict[tuple[str, str], tuple[str, str]] = {}

    def add(ops: list[_Op]) -> None:
        for link, contingent, pair, said in ops:
            if contingent:
                conts.append(link)  # type: ignore[arg-type]
                meaning[pair] = said
            else:
                reqs.append(link)  # type: ignore[arg-type]
                meaning.setdefault(pair, said)

    for i, (agent, leg, _, after) in enumerate(sk.legs):
        names, ops = sk.travel(i, motion_of[(agent.id, leg.index)])
        timepoints += names
        add(ops)
        add(after)
    add(sk.graph)
    n_before = len(reqs)
    add(sk.limits)
    stnu = STNU(tuple(timepoints), tuple(reqs), tuple(conts), name=f"{task.name}:{plan.id}")
    net = PlanNetwork(stnu=stnu, meaning=tuple(sorted(meaning.items())), last_ends=sk.last_ends,
                      n_limits=len(reqs) - n_before)
    return with_separations(net, separations, ref_namer(task, plan)) if separations else net


def with_separations(net: PlanNetwork, separations: Sequence[tuple[Separation, str]],
                     name: Callable[[TimeRef], str]) -> PlanNetwork:
    """`net` (built without passing orders) with these passing orders added before its limits.

    `name` maps a `TimeRef` to its timepoint (`ref_namer`). Cheaper than building the plan's network
    again, for a search that tries many sets of orders on one plan.
    """
    reqs = list(net.stnu.requirements)
    cut = len(reqs) - net.n_limits
    meaning = dict(net.meaning)
    added = []
    for sep, text in separations:
        a, b = name(sep.earlier), name(sep.later)
        added.append(RequirementLink(a, b, _ceil_ticks(sep.gap), None))
        meaning.setdefault((a, b), ("space", text))
    stnu = net.stnu.inserted(cut, tuple(added))
    return PlanNetwork(stnu=stnu, meaning=tuple(sorted(meaning.items())), last_ends=net.last_ends,
                       n_limits=net.n_limits)
