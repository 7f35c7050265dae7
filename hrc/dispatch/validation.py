"""Set validation (Strassmair & Taylor 2014, section V.B): what was seen, and which plans still agree.

`History` is what the dispatcher has accepted so far: each agent's legs in the order they were seen,
the time of every reported event, the legs ended, the announced next actions, which people are away
(`gone`; `away`: some person is). `History.add` checks an observation against the *task* (known names,
time never going backwards, no duplicate, an agent's events in order, no end without a start, one leg at
a time, an action's phases in order, the task graph's precedence) and raises `DispatchError` with a
one-line reason otherwise, changing nothing. `agrees` checks it against one *plan*: a plan stays a
candidate exactly while its allocation and each agent's order of legs extend what was seen (and, while
people are away, it gives them nothing they have not started). Timing never drops a plan: a plan whose
timing history broke is still an instruction for finishing the task (section V.B); ranking deals with it.

`agreeing` is set validation by index: which plans of a pool agree with the history, from the dispatch
form's sequences (``seq``: each agent's actions in order), as a few vectorised comparisons of the seen
prefixes, never a Python loop over the plans. A plan's legs are its actions' phases, action after action,
so a plan agrees exactly when each agent's sequence starts with the actions it was seen doing and the
legs it was seen on are those actions' phases in that order (which depends on the history alone: an
agent who left an action half done for another agrees with no plan).

**Routes.** Plans that agree on who does what in which order may still send an agent along different
routes on the same leg: straight, round a detour, or with a stop at a waiting place (the compile's
motion pattern, a part of each plan). A leg under way is driven or walked along one of them: the one the
agent was told when it left (the best plan's, as the robot's order and the person's hint came from it),
and for the person, what they were seen doing (a stop reported at a waiting place). Set validation keeps
only the plans with that route on that leg (`RouteIndex`, `route_signature`), so the robot is never told
an event of a route it is not driving ("park" on a straight drive), and no plan is named whose
instructions rest on a route nobody took. A route is told by its `route_signature`: whether it stops at
a waiting place, and the upper bound of each stretch of travel (to the stop or the location, and from
the stop on): a detour takes longer than the straight route. The compile computes them
(`hrc.compile.route_signatures`) and stores them with the dispatch form, so set validation only reads them.

`executed` turns a history into one plan's executed timepoints (ticks): each seen event pins its
timepoint; an unreported earlier event of the same leg (a depart, an arrival, a stop at a waiting place
that the detector does not report) is pinned at the time of the next reported one, which is when it is
known to have happened at the latest. `seen_arrays` is the same history as the dispatch form's core reads
it: the seen events' ticks by agent, leg position and event (every candidate has the same legs at those
positions).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from types import MappingProxyType

import numpy as np

from hrc.compile.dispatch_form import DispatchForm
from hrc.compile.route_signatures import RouteSig, route_signatures
from hrc.compile.route_signatures import route_signature as _route_signature
from hrc.compile.temporal_net_creator import ORIGIN, TICKS_PER_SECOND
from hrc.errors import DispatchError
from hrc.model import Action, Task

from .messages import LEG_EVENTS, Observation
from .plan_set import EventKey, PlanEntry

__all__ = ["MAX_JUMP", "History", "RouteIndex", "RouteSig", "agreeing", "agrees", "executed", "route_signature",
           "seen_arrays", "ticks"]

MAX_JUMP = 3600.0
"""Seconds: a message more than this after the last one is refused as a clock error. One bad time (a
tick at 1e9 s) would otherwise move the run's clock past every later message, each then refused as
"time goes backwards"; where that much time really passed, ticks at most this far apart bring it."""

_ORDER = {e: i for i, e in enumerate(LEG_EVENTS)}
_EMPTY: Mapping = MappingProxyType({})


def ticks(seconds: float) -> int:
    """Seconds to the temporal core's ticks (milliseconds), to the nearest."""
    return round(seconds * TICKS_PER_SECOND)


@dataclass(frozen=True, slots=True)
class History:
    """What was seen (see the module docstring); build with `History.start`, extend with `add`."""

    task: Task
    human: str
    now: float = 0.0
    times: Mapping[EventKey, float] = field(default_factory=lambda: _EMPTY)
    legs: Mapping[str, tuple[tuple[str, str], ...]] = field(default_factory=lambda: _EMPTY)
    ended: frozenset[tuple[str, str]] = frozenset()
    doer: Mapping[str, str] = field(default_factory=lambda: _EMPTY)  # action -> agent that began it
    announced: Mapping[str, str] = field(default_factory=lambda: _EMPTY)  # agent -> next action
    away: bool = False  # some person is away: the one person of a task of one
    gone: frozenset[str] = frozenset()  # the people away (issue 37: any person of a team)

    @classmethod
    def start(cls, task: Task) -> History:
        human = next((a.id for a in task.agents if a.is_human), "")
        return cls(task, human, legs=MappingProxyType({a.id: () for a in task.agents}))

    @property
    def absent(self) -> frozenset[str]:
        """The people away (`gone`), none when `away` is off (a copy read as everyone present:
        ``replace(history, away=False)``)."""
        return self.gone if self.away else frozenset()

    def current(self, agent: str) -> tuple[str, str] | None:
        """The leg `agent` is on (seen, not ended), or None."""
        legs = self.legs.get(agent, ())
        return legs[-1] if legs and legs[-1] not in self.ended else None

    def actions_seen(self, agent: str) -> tuple[str, ...]:
        out: list[str] = []
        for action, _ in self.legs.get(agent, ()):
            if action not in out:
                out.append(action)
        return tuple(out)

    def last_event(self, agent: str, action: str, phase: str) -> str | None:
        seen = [e for e in LEG_EVENTS if (agent, action, phase, e) in self.times]
        return seen[-1] if seen else None

    def add(self, obs: Observation) -> History:
        """This history with `obs` (a leg event, away, back or tick); `DispatchError` if the task forbids it."""
        if obs.t < self.now:
            raise DispatchError(f"time goes backwards: t = {obs.t:g} s is before the last message ({self.now:g} s)")
        if obs.t > self.now + MAX_JUMP:
            raise DispatchError(f"t = {obs.t:g} s is {obs.t - self.now:g} s after the last message ({self.now:g} s): "
                                f"more than {MAX_JUMP:g} s at once, a clock error? (if that much time passed, "
                                f"send ticks at most {MAX_JUMP:g} s apart)")
        if obs.event == "tick":
            return replace(self, now=obs.t)
        if obs.event in ("away", "back"):
            people = [a.id for a in self.task.agents if a.is_human]
            who = self.human if obs.agent is None else obs.agent
            if who not in people:
                if len(people) <= 1:
                    raise DispatchError(f"only the human ({self.human}) can be away or back, not {obs.agent!r}")
                raise DispatchError(f"only a person ({', '.join(people)}) can be away or back, not {obs.agent!r}")
            name = "the human" if len(people) == 1 else who
            if obs.event == "away" and who in self.gone:
                raise DispatchError(f"{name} is already away")
            if obs.event == "back" and who not in self.gone:
                raise DispatchError(f"{name} is not away")
            gone = self.gone | {who} if obs.event == "away" else self.gone - {who}
            return replace(self, now=obs.t, away=bool(gone), gone=gone)
        return self._leg_event(obs)

    def _leg_event(self, obs: Observation) -> History:
        task = self.task
        names = _names(task)
        agent, action, phase, event = obs.key
        if agent not in names.agents:
            raise DispatchError(f"unknown agent {agent!r} (agents: {', '.join(task.agent_ids)})")
        act = names.actions.get(action)  # type: ignore[arg-type]
        if act is None:
            raise DispatchError(f"unknown action {action!r}")
        phases = names.phases[act.id]
        if phase not in phases:
            raise DispatchError(f"action {action!r} has no phase {phase!r} (phases: {', '.join(phases)})")
        if agent not in act.agents:
            raise DispatchError(f"{agent} cannot do {action} (the task gives it to {', '.join(act.agents)})")
        if agent in self.absent:
            who = "the human" if sum(a.is_human for a in task.agents) == 1 else agent
            raise DispatchError(f"{who} is away: send 'back' before {action}.{phase} {event}")
        what = f"{agent} {action}.{phase} {event}"
        if obs.key in self.times:
            raise DispatchError(f"duplicate: {what} was seen at {self.times[obs.key]:g} s")
        other = self.doer.get(action)
        if act.joint:  # every agent of it does it; its one start and end are its lead's (`Task.lead`)
            # (with a crew to choose, any robot that may be in it: set validation keeps the plans it leads)
            if act.crew_choice:
                if event in ("start", "end") and task.agent(agent).is_human:
                    raise DispatchError(f"{what}: {action} is a joint action, the robot of its crew starts and "
                                        f"ends it")
                lead = agent
            else:
                lead = task.lead(action)
            if agent != lead and event in ("start", "end"):
                raise DispatchError(f"{what}: {action} is a joint action, the {lead} starts and ends it")
        elif other is not None and other != agent:
            raise DispatchError(f"{action} is being done by the {other}, not the {agent}")
        leg = (action, phase)
        current = self.current(agent)
        if leg in self.ended:
            raise DispatchError(f"{what}: {action}.{phase} has ended already")
        if leg == current:
            last = self.last_event(agent, action, phase)
            if last is not None and _ORDER[event] <= _ORDER[last]:
                raise DispatchError(f"{what} comes after its {last}, which was seen already")
        else:
            if current is not None:
                raise DispatchError(f"{what}: the {agent} has not ended {current[0]}.{current[1]} yet")
            earlier = phases[:phases.index(phase)]
            open_ = [p for p in earlier if (action, p) not in self.ended]
            if open_:
                raise DispatchError(f"{what}: {action}.{open_[0]} comes first and has not ended")
        if event == "end" and (agent, action, phase, "start") not in self.times:
            raise DispatchError(f"{what} without a start")
        if _ORDER[event] >= _ORDER["start"]:
            for before in names.before.get(leg, ()):
                if before not in self.ended:
                    raise DispatchError(f"{what}: the task graph wants {before[0]}.{before[1]} to end first")
        announced = dict(self.announced)
        if obs.next is not None:
            if obs.next not in task.action_ids:
                raise DispatchError(f"unknown next action {obs.next!r}")
            if obs.next in self.doer or obs.next == action:
                raise DispatchError(f"next action {obs.next!r} has begun already")
            if agent not in task.action(obs.next).agents:
                raise DispatchError(f"{agent} cannot do the next action {obs.next!r}")
            announced[agent] = obs.next
        elif agent in announced and action == announced[agent]:
            del announced[agent]  # the announced action has begun
        times = dict(self.times)
        times[obs.key] = obs.t
        legs = dict(self.legs)
        if leg != current:
            legs[agent] = (*legs.get(agent, ()), leg)
        ended = self.ended | {leg} if event == "end" else self.ended
        doer = dict(self.doer)
        doer.setdefault(action, agent)
        # (`replace`, written out: its look at the fields cost as much as the rest at every message)
        return History(task, self.human, obs.t, MappingProxyType(times), MappingProxyType(legs), ended,
                       MappingProxyType(doer), MappingProxyType(announced), self.away, self.gone)


@dataclass(frozen=True, slots=True)
class _Names:
    """What `History.add` looks up in a task at every message, as sets and maps (`_names`)."""

    agents: frozenset[str]
    actions: Mapping[str, Action]
    phases: Mapping[str, tuple[str, ...]]  # action -> its phases' ids, in order
    before: Mapping[tuple[str, str], tuple[tuple[str, str], ...]]  # leg -> the legs the task graph ends first


_NAMES: dict[int, tuple[Task, _Names]] = {}


def _names(task: Task) -> _Names:
    """`task`'s `_Names`, made once per task (the task is kept with them: its id stays its own)."""
    found = _NAMES.get(id(task))
    if found is None or found[0] is not task:
        if len(_NAMES) >= 64:
            _NAMES.clear()
        before: dict[tuple[str, str], list[tuple[str, str]]] = {}
        for p in task.precedence:  # in the task's order: the first one not ended is named
            before.setdefault((p.after.action, p.after.phase), []).append((p.before.action, p.before.phase))
        found = _NAMES[id(task)] = (task, _Names(frozenset(task.agent_ids), {a.id: a for a in reversed(task.actions)},
                                                 {a.id: tuple(p.id for p in a.phases) for a in reversed(task.actions)},
                                                 {leg: tuple(v) for leg, v in before.items()}))
    return found[1]


def agrees(entry: PlanEntry, history: History) -> bool:
    """Whether the plan's allocation and per-agent order extend what was seen (set validation)."""
    for agent, seen in history.legs.items():
        if entry.legs[agent][:len(seen)] != seen:
            return False
    for agent, nxt in history.announced.items():
        seen_actions = history.actions_seen(agent)
        rest = [a for a in entry.plan.sequence(agent) if a not in seen_actions]
        if not rest or rest[0] != nxt:
            return False
    return all(len(entry.plan.sequence(p)) == len(history.actions_seen(p)) for p in history.absent)


def executed(entry: PlanEntry, history: History) -> dict[str, int]:
    """The plan's executed timepoints (ticks) under `history`: the origin at 0, every reported event, and
    every unreported earlier event of a reported leg at the time of the next reported one."""
    out = {ORIGIN: 0}
    times, points = history.times, entry.leg_points
    for agent, seen in history.legs.items():
        for action, phase in seen:
            pending: list[str] = []
            for event, node in points[(agent, action, phase)]:
                t = times.get((agent, action, phase, event))
                if t is None:
                    pending.append(node)
                    continue
                tick = round(t * TICKS_PER_SECOND)  # `ticks`, inlined: a decision reads every seen event
                if pending:
                    for p in pending:
                        out[p] = tick
                    pending = []
                out[node] = tick
    return out


def agreeing(form: DispatchForm, history: History, pool: np.ndarray) -> np.ndarray:
    """The plans of `pool` (indices, kept in their order) whose allocation and per-agent order extend what
    was seen: `agrees` for many plans at once (see the module docstring)."""
    pool = np.asarray(pool, dtype=np.int64)
    task = form.task
    action_index = {a: i for i, a in enumerate(task.action_ids)}
    A = form.seq.shape[2]
    keep = np.ones(len(pool), dtype=bool)
    for g, agent in enumerate(task.agent_ids):
        actions = history.actions_seen(agent)
        legs = history.legs.get(agent, ())
        if [(a, p.id) for a in actions for p in task.action(a).phases][:len(legs)] != list(legs):
            return pool[:0]  # its legs are not its actions' phases in order: no plan has them so
        seen = [action_index[a] for a in actions]
        if seen:
            keep &= np.all(form.seq[pool, g, :len(seen)] == np.array(seen, dtype=np.int16), axis=1)
        nxt = history.announced.get(agent)
        if nxt is not None:
            keep &= form.seq[pool, g, len(seen)] == action_index[nxt] if len(seen) < A else False
        if agent in history.absent and len(seen) < A:
            keep &= form.seq[pool, g, len(seen)] < 0  # the robot does every action the human has not begun
    return pool[keep]


def seen_arrays(history: History, legs: int) -> tuple[np.ndarray, np.ndarray]:
    """``(seen, legs_seen)``: the tick of each seen event by agent, leg position and event (`LEG_EVENTS`;
    -1: not seen), shape (agents, `legs`, 6), and how many legs of each agent were seen."""
    agents = history.task.agent_ids
    seen = np.full((len(agents), legs, len(LEG_EVENTS)), -1, dtype=np.int64)
    counts = np.zeros(len(agents), dtype=np.int32)
    times = history.times
    for g, agent in enumerate(agents):
        for k, (action, phase) in enumerate(history.legs.get(agent, ())):
            counts[g] = k + 1
            for e, event in enumerate(LEG_EVENTS):
                t = times.get((agent, action, phase, event))
                if t is not None:
                    seen[g, k, e] = ticks(t)
    return seen, counts


def route_signature(entry: PlanEntry, agent: str, action: str, phase: str) -> RouteSig:
    """The route of `agent`'s leg `action`.`phase` in the plan, from its STNU
    (`hrc.compile.route_signatures.route_signature`, the definition); `RouteIndex` reads the same from
    the dispatch form."""
    return _route_signature(entry.stnu, dict(entry.leg_points[(agent, action, phase)]))


class RouteIndex:
    """Each plan's route on each leg position (`route_signature`), shared by a dispatcher's forks: set
    validation reads it for a leg under way. From the form's ``routes.npy`` (by shape, made by the
    compile) where it has one; else (a form written before it) made for a plan when first asked and kept:
    ``sig[p, g, k]``, -2 in the first column: not made yet."""

    def __init__(self, form: DispatchForm) -> None:
        self.form = form
        P, G, L, _ = form.nodes.shape
        self.by_shape = form.routes
        self.shape = None if form.routes is None else np.ascontiguousarray(form.plans["shape"], dtype=np.int64)
        self.sig: np.ndarray | None = None
        self._shape = (P, G, L, 3)

    def routes(self, plans: np.ndarray, g: int, k: int) -> np.ndarray:
        """``(len(plans), 3)``: the plans' routes on agent g's k-th leg (int64)."""
        plans = np.asarray(plans, dtype=np.int64)
        if self.by_shape is not None and self.shape is not None:
            return np.asarray(self.by_shape[self.shape[plans], g, k], dtype=np.int64)
        if self.sig is None:
            self.sig = np.full(self._shape, -2, dtype=np.int64)
        missing = plans[self.sig[plans, 0, 0, 0] == -2]
        if len(missing):
            form = self.form
            self.sig[np.unique(missing)] = route_signatures(
                form.nodes, (form.edges_ptr, form.edges_u, form.edges_v, form.edges_w),
                (form.conts_ptr, form.conts_a, form.conts_c, form.conts_ub), np.unique(missing))
        return self.sig[plans, g, k]
