"""The dispatcher (Strassmair & Taylor 2014, section V.B, Fig. 5): the robot's next step from what it sees.

Each message runs the paper's cycle: *update* the history with the observation (`History.add`, which
refuses what the task forbids), *validate* the set (`agrees`: plans whose allocation or order contradict
the history drop out; timing never drops a plan), *rank* it (`evaluate`, `rank_key`: DC > consistent >
inconsistent, then remaining makespan, idle time, APA preference, plan id) and *decide* from the best
plan of the highest non-empty class:

- DC: Hunsberger's real-time execution decisions over the residual network (`hrc.temporal.execution`,
  `ExecutionMode.DC`): the robot's next timepoint in a window in which executing it keeps the rest DC
  whatever the human's remaining durations, or wait for the human's event it depends on;
- consistent: the same windows with the human's durations read as the plan's (`ExecutionMode.STN`);
- inconsistent: as early as the lower bounds allow (`ExecutionMode.EARLIEST`), no latest time: finishing
  beats the deadline;
- where the task has preferences (APA), the window for a DC or consistent plan is narrowed to the DO
  window of the robot's timepoint, recompiled on the residual network at each decision (Wilcox et al.
  2012, Fig. 8: recompile on every deviation), where the two meet;
- the end of a drive under way (``arrive``, ``park``) is no decision: the robot drives a route in its
  planned time, so its window is that time after the departure, whatever the class.

The human's own departures and starts are theirs (`uncontrolled`): the robot never goes together with one
it must follow. Started actions are never preempted: validation keeps only plans that continue every leg
under way with its agent. When the human leaves (``away``), the candidates are the plans that give every
action the human has not started to the robot (if there are none, the set stays as it was and the robot
does its own part); ``back`` brings back every plan that agrees with the history.

The plan being followed keeps its hold (`_lead`): while a DC candidate keeps the person's part of the
last best plan (what they were shown), a DC plan that gives it up ranks after it, so a switch never rests
on a choice the person has not made (the robot's strategy may assume only that the person follows the
plan shown until they choose otherwise: docs/dispatch.md). Legs under way keep their route (`_tell_route`,
`_on_routes`): the one told when the leg began, or a waiting place where the agent was seen stopping.
While the person's walk or manipulation is under way, the answer carries their next instruction ahead
(`_ahead`). A person's event estimated within `bound_tolerance` of their hint's bound is read on it
(`_on_bound`); one learnt later than `max_observation_delay` voids the guarantee (`_late`). Where the
sensing may err or be late, the robot's windows hold for every time the person's seen events may truly
have happened (`_windows`, `_hinted`: docs/dispatch.md, "Windows from what the robot can know").

Nothing here reads a clock: time comes in with the messages, so a run replays from its log to the same
decisions. A refused message raises `DispatchError` and leaves the dispatcher as it was.
"""

from __future__ import annotations

import copy
import os
from collections.abc import Mapping
from dataclasses import dataclass, replace
from types import MappingProxyType
from typing import Any, Literal

import numpy as np

from hrc.errors import DispatchError, HrcError
from hrc.model import Task
from hrc.motion.separation import limits
from hrc.temporal import ExecutionMode, ExecutionWindow, real_time_state
from hrc.temporal.execution import residual_origin

from .fallback import fallback_decision, fallback_steps
from .messages import LEG_EVENTS, Ahead, Candidate, Decision, HumanOption, Observation, RobotStep, WaitFor, ack_note
from .native import NO_BOUND
from .plan_set import EventKey, PlanEntry, PlanSet, load_plan_set, plan_set_from_compiled
from .ranking import CLASS_ORDER, NO_FINISH, Ranker
from .validation import History, RouteIndex, RouteSig, agreeing, executed, seen_arrays, ticks

__all__ = ["UNDO_SECONDS", "Dispatcher"]

UNDO_SECONDS = 10.0
"""How long after a human observation it may still be withdrawn with ``undo``."""

_MODES = {"DC": ExecutionMode.DC, "consistent": ExecutionMode.STN, "inconsistent": ExecutionMode.EARLIEST}
_CORE_MODES = {ExecutionMode.DC: "DC", ExecutionMode.STN: "STN", ExecutionMode.EARLIEST: "EARLIEST"}
_FROM_CORE = {name: mode for mode, name in _CORE_MODES.items()}

_Unlearnt = tuple[tuple[str, str, str, str], str, int, "int | None", int]
"""A person's next event that may have happened unlearnt (`Dispatcher._unlearnt`): its key, timepoint, the
earliest it may have happened, the latest (None: it may still be to come) and its leg's position."""


@dataclass(frozen=True, slots=True)
class _State:
    """Everything a message changes, replaced whole when a message is accepted."""

    history: History
    accepted: tuple[Observation, ...]  # every accepted message, undo included (the log's order)
    effective: tuple[Observation, ...]  # the observations that stand (withdrawn ones removed)
    plans: np.ndarray  # the candidates: indices into the plan set, ascending (compile rank order)
    cls: np.ndarray  # their class codes (`CLASS_ORDER`), finish ticks (`NO_FINISH`: none) and idle ticks
    finish: np.ndarray
    idle: np.ndarray
    best: int  # the best candidate's index in the plan set, -1 when none is left
    decision: Decision
    do_forms: MappingProxyType  # plan index -> APA's DO form of the plan (`_do_form`), or False
    seen: np.ndarray  # the history as the core reads it (`seen_arrays`), and now in ticks
    legs_seen: np.ndarray
    now: int
    told: Mapping[tuple[int, int], RouteSig]  # (agent index, leg position) -> the route told (`RouteSig`)
    lead: np.ndarray | None  # per candidate: 1 for a DC plan that gives up the followed person's part
    deviation: Mapping[str, Any] | None  # this answer's: an observation later than the stated delay
    hinted: Mapping[tuple[str, str, str, str], tuple[int, int]]  # what the person was told (`_hinted`)
    read: bool = False  # cls, finish, idle from the person's events as they may truly have happened (`_reading`)


ANSWERED_DEPTH = 4
"""`Dispatcher.observe` keeps the answers to the first this many messages from the start (`_answered`)."""
ANSWERED_KEPT = 1024
"""... and at most this many of them (a few MB)."""


class Dispatcher:
    """A state machine over a compiled plan set: `observe` a message, get a `Decision`.

    Build with `from_folder` (an `hrc compile` output folder) or `from_compiled` (in memory).
    `feasible_only` drops plans that are not DC or consistent; when none is left the robot is told
    nothing more (``Decision.stopped``), as Chaski-style dispatchers do (for comparisons).
    `use_preferences`: where the task has preferences, the robot's window is narrowed to APA's DO window
    (`_preferred`), at the cost of one small QP per decision. `threads`: how many threads set ranking may
    use on a large message (default: up to 4, as the machine has cores; 1 where processes share the cores,
    as the simulator's workers do). `ranker`: share the set ranking of another dispatcher on the same set.
    `max_observation_delay` (s): the longest a person's event may reach the dispatcher after it happened
    (`Observation.delay`); a later one voids the guarantee (`Decision.deviation`). Default: the longest
    delay of the compile's sensing (`Task.sensing`, what its classes were checked under), else none stated.
    `bound_tolerance` (s):
    a person's event estimated within this of a bound of the hint they were given is read as on the
    bound (`_on_bound`); 0 (buttons): never.
    """

    def __init__(self, plan_set: PlanSet, *, feasible_only: bool = False, use_preferences: bool = True,
                 ranker: Ranker | None = None, threads: int | None = None,
                 max_observation_delay: float | None = None, bound_tolerance: float = 0.0) -> None:
        self.plan_set = plan_set
        self.bound_tolerance = bound_tolerance
        self.feasible_only = feasible_only
        self.fallback = False  # no plan agrees: answer with the fallback, not a refusal (`hrc.dispatch.on_demand`)
        self.use_preferences = use_preferences
        sensing = plan_set.task.sensing
        if max_observation_delay is None and sensing is not None:  # the classes hold up to this delay only
            max_observation_delay = sensing.delay[1]
        self.max_observation_delay = max_observation_delay
        self.ranker = ranker if ranker is not None and ranker.plan_set is plan_set else Ranker(plan_set, threads)
        self.routes = RouteIndex(plan_set.form)  # shared by forks: a function of the plans alone
        agents = plan_set.task.agents
        self._robot = next((a.id for a in agents if not a.is_human), "")  # the first robot (and person, below)
        # the team (issue 37): every robot is told its next step and every person their hint, robots first;
        # a team other than one of each is answered per agent (`Decision.robots`, `Decision.people`)
        self._robots = tuple(a.id for a in agents if not a.is_human)
        self._people = tuple(a.id for a in agents if a.is_human)
        self._team = (len(self._robots), len(self._people)) != (1, 1)
        # joint actions (issue 37): action -> its agents; empty for a task without
        self._joint = MappingProxyType({a.id: a.agents for a in plan_set.task.actions if a.joint})
        self._human_g = next((g for g, a in enumerate(plan_set.task.agents) if a.is_human), -1)
        self._people_g = [g for g, a in enumerate(agents) if a.is_human]
        self._nodes: dict[int, dict[str, frozenset[str]]] = {}  # plan -> agent -> every other agent's timepoints
        self._arcs: dict[int, tuple] = {}  # plan -> its distance graph, by head (`_ahead`)
        self._dists: dict[tuple[int, tuple[str, ...]], np.ndarray | None] = {}  # (plan, steps) -> distances (`_ahead`)
        self._dos: dict[tuple, Any] = {}  # (plan, what happened, now) -> its DO form (`_preferred`)
        self._same: dict[tuple[bytes, int], np.ndarray] = {}  # (candidates, last best) -> person's part kept (`_lead`)
        self._spans: dict[tuple[int, int, int], tuple[int, int | None]] = {}  # (plan, a, b) -> a drive's (`_arrival`)
        self._routed: dict[tuple, np.ndarray] = {}  # (candidates, legs told or parked) -> those on them (`_on_routes`)
        # (state, message) -> the state it led to, for a run's first messages (`observe`): shared by forks
        self._answered: dict[tuple[int, Observation], tuple[_State, PlanSet, _State]] = {}
        # told with each robot step (a task with safety: only), each robot its own (S_p at its speed)
        found = {a.id: limits(plan_set.task, a) for a in plan_set.task.agents if not a.is_human}
        self._limits = None if plan_set.task.safety is None else \
            {r: MappingProxyType(x) for r, x in found.items() if x is not None}
        history = History.start(plan_set.task)
        everything = np.arange(len(plan_set), dtype=np.int64)
        self._state = self._settle(history, (), (), everything, {}, None)

    @classmethod
    def from_folder(cls, out_dir: str | os.PathLike[str], *, allow_partial: bool = False,
                    **options: Any) -> Dispatcher:
        """Load an `hrc compile` output folder (raises `hrc.errors.InputError` naming the file at fault;
        a partial output only with `allow_partial`)."""
        return cls(load_plan_set(out_dir, allow_partial=allow_partial), **options)

    @classmethod
    def from_compiled(cls, cps: Any, **options: Any) -> Dispatcher:
        """From an in-memory `hrc.compile.compiler.CompiledPlanSet`."""
        return cls(plan_set_from_compiled(cps), **options)

    def fork(self) -> Dispatcher:
        """An independent dispatcher in this one's state, sharing the loaded plan set (read-only): a
        message to one never reaches the other, since each message replaces the state whole. O(1): the
        simulator forks a fresh dispatcher per run instead of loading the plans again."""
        return copy.copy(self)

    # ------------------------------------------------------------------ read-only views
    @property
    def task(self) -> Task:
        return self.plan_set.task

    @property
    def now(self) -> float:
        return self._state.history.now

    @property
    def decision(self) -> Decision:
        return self._state.decision

    @property
    def history(self) -> tuple[Observation, ...]:
        """The observations that stand (an undone one is gone), in the order they were accepted."""
        return self._state.effective

    @property
    def accepted(self) -> tuple[Observation, ...]:
        """Every accepted message, ticks and undos included: replaying these gives the same state."""
        return self._state.accepted

    @property
    def seen(self) -> History:
        return self._state.history

    @property
    def candidate_indices(self) -> np.ndarray:
        """The remaining plans' indices in the plan set, best first."""
        st = self._state
        return st.plans[self.ranker.order(st.plans, st.cls, st.finish, st.idle, st.lead)]

    @property
    def remaining(self) -> np.ndarray:
        """The remaining plans' indices in the plan set, in compile rank order (not ranked: cheap; read-only,
        for the human action detector, `hrc.detect`), and the best one's: `best_index` (-1: none)."""
        return self._state.plans

    @property
    def best_index(self) -> int:
        return self._state.best

    def _candidate(self, at: int) -> Candidate:
        st = self._state
        p = int(st.plans[at])
        form = self.plan_set.form
        plan = form.plan(p)
        pref = float(form.plans["preference"][p])
        finish = int(st.finish[at])
        return Candidate(self.plan_set.id(p), CLASS_ORDER[int(st.cls[at])],
                         None if finish == NO_FINISH else finish / 1000, int(st.idle[at]) / 1000,
                         None if pref != pref else pref, MappingProxyType(dict(plan.allocation)),
                         MappingProxyType(dict(plan.sequences)))

    @property
    def best(self) -> Candidate | None:
        """The best remaining plan, as `candidates` would list it first (None: no plan left)."""
        st = self._state
        if st.best < 0:
            return None
        return self._candidate(int(np.searchsorted(st.plans, st.best)))

    @property
    def candidates(self) -> tuple[Candidate, ...]:
        """The remaining plans, ranked best first (one value per plan: for a large set, `best` and
        `Decision.candidates` say the same for less)."""
        st = self._state
        return tuple(self._candidate(int(at)) for at in self.ranker.order(st.plans, st.cls, st.finish, st.idle,
                                                                            st.lead))

    def human_options(self, agent: str | None = None) -> tuple[HumanOption, ...]:
        """Leg events the human (`agent`, a person of a team; default: the first) may report now that the
        task and some remaining plan allow, in task order (a console's buttons): the next event of the leg
        under way, or the start of a next leg."""
        history = self._state.history
        human = history.human if agent is None else agent
        if not human or human in history.absent:
            return ()
        found: set[tuple[str, str, str]] = set()
        for obs in self._next_events(human, history):
            try:
                history.add(obs)
            except DispatchError:
                continue
            found.add((obs.action or "", obs.phase or "", obs.event))
        order = {(a.id, p.id): k for k, (a, p) in enumerate((a, p) for a in self.task.actions for p in a.phases)}
        return tuple(HumanOption(*f) for f in sorted(found, key=lambda f: (order[(f[0], f[1])],
                                                                            LEG_EVENTS.index(f[2]))))

    def planned_times(self, plan_id: str | None = None) -> dict[EventKey, float]:
        """Seen times where seen, else the plan's earliest schedule given the history (seconds), for
        every event of the plan (default: the best plan). `KeyError` for a plan not in the set."""
        st = self._state
        p = st.best if plan_id is None else self.plan_set.index(plan_id)
        if p < 0:
            return {}
        history = st.history
        form = self.plan_set.form
        times = self.ranker.schedule(p, st.seen, st.legs_seen, st.now)
        if times is None:  # no schedule: what happened, unreported events at their next reported one
            entry = self.plan_set.entry(p)
            done = executed(entry, history)
            return {key: history.times.get(key, done[node] / 1000 if node in done else 0.0)
                    for node, key in entry.events.items() if key in history.times or node in done}
        out: dict[EventKey, float] = {}
        plan = form.plan(p)
        from hrc.plans import agent_legs

        for g, agent in enumerate(self.task.agents):
            for k, leg in enumerate(agent_legs(self.task, plan, agent.id)):
                for e, event in enumerate(LEG_EVENTS):
                    x = int(form.nodes[p, g, k, e])
                    if x >= 0:
                        key = (agent.id, leg.action, leg.phase, event)
                        seen_t = history.times.get(key)
                        out[key] = seen_t if seen_t is not None else times[x] / 1000
        return out

    # ------------------------------------------------------------------ the cycle
    def observe(self, obs: Observation) -> Decision:
        """Take one message; the new `Decision`. Raises `DispatchError` (state unchanged) when refused.

        A message is a function of the state it reaches and the plan set: the same message to the same
        state object (a fork's, shared with the dispatcher it was forked from, and each state such a message
        led to) leads to the same new state, kept (`_answered`) for the first `ANSWERED_DEPTH` messages from
        the start. The simulator forks every run from one dispatcher, and every run of a policy begins with
        the same messages (the robot's and the person's first departures, at the plan's times): these, the
        costliest (every plan still a candidate), are decided once per process. Not with compile on demand
        (`fallback`: the plan set grows under the forks) nor where the answer reads more than the state
        (a subclass's own `_span`: a detector's estimates)."""
        state = self._state
        memo = self._answered if len(state.accepted) < ANSWERED_DEPTH and not self.fallback and \
            type(self)._span is Dispatcher._span else None
        if memo is not None:
            hit = memo.get((id(state), obs))
            if hit is not None and hit[0] is state and hit[1] is self.plan_set:
                self._state = hit[2]
                return hit[2].decision
        decision = self._observe(obs)
        if memo is not None:
            if len(memo) >= ANSWERED_KEPT:
                memo.clear()
            memo[(id(state), obs)] = (state, self.plan_set, self._state)
        return decision

    def _observe(self, obs: Observation) -> Decision:
        """`observe` (without `_answered`)."""
        state = self._state
        if obs.event == "undo":
            return self._undo(obs)
        obs = self._on_bound(obs)
        history = state.history.add(obs)
        form = self.plan_set.form
        if obs.event == "tick" or (obs.event != "back" and _validated_by(state.history) == _validated_by(history)):
            kept = state.plans  # nothing set validation reads has changed
        else:  # "back" brings back every plan that agrees with the history
            pool = np.arange(len(self.plan_set), dtype=np.int64) if obs.event == "back" else state.plans
            kept = agreeing(form, history, pool)
            if obs.event == "back":
                kept = self._on_routes(kept, history, state.told)
            if not len(kept) and history.away:
                # no plan lets the robot finish alone from here (say it is on its way to a leg that needs
                # the person's work first): "away" is a fact, not a request, and so is what the robot does
                # meanwhile; it goes on with the plans that agree with what was seen, and waits for the
                # person where they need them (refusing its own arrival left it standing for good)
                kept = agreeing(form, _present(history), pool)
        if not len(kept) and not self.fallback:
            raise DispatchError(f"no remaining plan allows {_describe(obs)} "
                                f"({len(state.plans)} plans agreed with what was seen before)")
        told = state.told
        if obs.event in LEG_EVENTS:
            told, changed = self._tell_route(state, history, obs)
            if changed or kept is not state.plans:
                kept = self._on_routes(kept, history, told)
        ack = None
        if obs.agent in self._robots and obs.event in LEG_EVENTS:  # what this robot was told
            ack = ack_note(state.decision.robot if not self._team else (state.decision.robots or {}).get(obs.agent),
                           obs)
        deviation = self._late(obs)
        hinted = self._hinted(state, obs)
        self._state = self._settle(history, (*state.accepted, obs), (*state.effective, obs), kept, state.do_forms,
                                   state, _seen_after(state, history, obs), ack, told, deviation, hinted)
        return self._state.decision

    def _hinted(self, state: _State, obs: Observation) -> Mapping[tuple[str, str, str, str], tuple[int, int]]:
        """`state.hinted` with when `obs` (a person's leg event seen for the first time, through a sensing
        path that may err or be late) may truly have happened, ``(earliest, latest)`` in ticks (`_windows`):

        - dated (a detector's estimate, `bound_tolerance` > 0): within the tolerance of `obs.t`; and when
          `obs.t` is the last message's time, the estimate may have been moved up to it (the clock never
          goes back), so up to `obs.delay` before;
        - undated (buttons late by up to `max_observation_delay`): between that much before `obs.t` and
          `obs.t`;

        narrowed to the window the person had been told for it (`_told`). The person does as told: the
        model the classes are checked in. Unchanged on buttons on time (nothing is uncertain).
        """
        hinted = state.hinted
        history = state.history
        if obs.event not in LEG_EVENTS or obs.agent not in self._people or obs.key in history.times:
            return hinted
        at = ticks(obs.t)
        if self.bound_tolerance > 0:
            tol = ticks(self.bound_tolerance)
            back = ticks(obs.delay) if obs.delay is not None and obs.t <= history.now else 0
            lo, hi = at - tol - back, at + tol
            span = self._span(obs)
            if span is not None:  # the detector's own statement for this estimate, where wider
                lo, hi = min(lo, ticks(span[0])), max(hi, ticks(span[1]))
        elif self.max_observation_delay:
            lo, hi = at - ticks(self.max_observation_delay), at
        else:
            return hinted
        lo = max(lo, 0)  # not before the run's start (the origin)
        told = hinted.get(obs.key)  # (`_told`)
        if told is not None:
            lo = max(lo, told[0])
            if told[1] != NO_BOUND:
                hi = min(hi, told[1])
        return MappingProxyType({**hinted, obs.key: (min(lo, at), max(hi, at))})

    def _told(self, hinted: Mapping[tuple[str, str, str, str], tuple[int, int]], history: History,
              decision: Decision) -> Mapping[tuple[str, str, str, str], tuple[int, int]]:
        """`hinted` with the window `decision` gives the person for their next event, not yet seen: the
        hint's (`Decision.human`), or the instruction ahead's (`Decision.ahead`: the robot's event seen plus
        the gap, no latest), widened to every window told for it so far (the person may have acted on an
        earlier one before the dispatcher learnt it: a hint's earliest moves up with the clock); not once
        the latest told has passed, less than the stated delay ago (the person did it as told: `_unlearnt`;
        a window told again then, from the reading "not yet", let a late button's time in). Kept only
        where a sensing path may err or be late (`_hinted` reads it)."""
        if self.bound_tolerance <= 0 and not self.max_observation_delay:
            return hinted
        for person in self._people:  # each person's own hint or instruction ahead (a team's: issue 37)
            hint, ahead = self._told_to(decision, person)
            hinted = self._told_one(hinted, history, person, hint, ahead)
        return hinted

    def _told_to(self, decision: Decision, person: str) -> tuple[RobotStep | WaitFor | None, Ahead | None]:
        """What `decision` tells `person`: their hint and their instruction ahead (one person: `Decision.human`
        and `ahead`; a team's: their entries of `people` and `aheads`)."""
        if not self._team:
            return decision.human, decision.ahead
        return (decision.people or {}).get(person), (decision.aheads or {}).get(person)

    def _told_one(self, hinted: Mapping[tuple[str, str, str, str], tuple[int, int]], history: History, person: str,
                  hint: RobotStep | WaitFor | None, ahead: Ahead | None
                  ) -> Mapping[tuple[str, str, str, str], tuple[int, int]]:
        """`_told` for one person."""
        window = None
        if isinstance(hint, RobotStep):
            key = (person, hint.action, hint.phase, hint.event)
            window = (ticks(hint.earliest), NO_BOUND if hint.latest is None else ticks(hint.latest))
        elif hint is None and ahead is not None and ahead.wait_for is not None:
            seen_t = history.times.get(tuple(ahead.wait_for.split(".")))  # type: ignore[arg-type]
            key = tuple(ahead.next.split("."))  # type: ignore[assignment]
            if seen_t is not None:
                window = (ticks(seen_t + ahead.gap), NO_BOUND)
        if window is None or key in history.times:
            return hinted
        before = hinted.get(key)
        if before is not None and before[1] != NO_BOUND and \
                before[1] < ticks(history.now) <= before[1] + ticks(self.max_observation_delay or 0.0):
            return hinted  # its latest has passed unlearnt: done as told (`_unlearnt`), not told again
        if before is not None:
            window = (min(before[0], window[0]), NO_BOUND if NO_BOUND in (before[1], window[1])
                      else max(before[1], window[1]))
            if window == before:
                return hinted
        return MappingProxyType({**hinted, key: window})

    def adopt(self, plan_set: PlanSet) -> Decision:
        """Take `plan_set`, this set's plans followed by more (compiled on demand: `hrc.dispatch.on_demand`;
        or this very set), and decide again from every plan of it that agrees with what was seen, as
        ``back`` does (a plan set aside for its route alone is one again); the new `Decision`. The plans
        already here keep their indices. `ValueError` when `plan_set` does not start with them."""
        old, st = self.plan_set, self._state
        n = len(old)
        if len(plan_set) < n or plan_set.task is not old.task or \
                not np.array_equal(plan_set.form.plans["id"][:n], old.form.plans["id"]):
            raise ValueError("the new plan set must hold this one's plans first")
        if plan_set is not old:
            self.plan_set = plan_set
            self.ranker = Ranker(plan_set, self.ranker.threads)
            self.routes = RouteIndex(plan_set.form)
            # the caches by plan index are shared by forks, whose added plans differ: this one's own from here
            self._nodes = {p: v for p, v in self._nodes.items() if p < n}
            self._arcs = {p: v for p, v in self._arcs.items() if p < n}
            self._dists = {k: v for k, v in self._dists.items() if k[0] < n}
            self._dos = {k: v for k, v in self._dos.items() if k[0] < n}
            self._same, self._spans = {}, {k: v for k, v in self._spans.items() if k[0] < n}
            self._routed = {}
        pool = np.arange(len(plan_set), dtype=np.int64)
        kept = agreeing(plan_set.form, st.history, pool)
        if not len(kept) and st.history.away:  # as `observe` reads an absence
            kept = agreeing(plan_set.form, _present(st.history), pool)
        kept = self._on_routes(kept, st.history, st.told)
        self._state = self._settle(st.history, st.accepted, st.effective, kept, st.do_forms, st)
        return self._state.decision

    def _on_bound(self, obs: Observation) -> Observation:
        """`obs` read on the bound of the hint the person was given for it when it was estimated within
        `bound_tolerance` of it, or within the span its sensing path states for it (`_span`), before its
        earliest, or after its latest but not before now: a sensor's estimate that close cannot tell the
        person from one who did as told, and reading it as a violation turned DC plans inconsistent (issue
        32: departures estimated 2-40 ms before a hinted earliest). An undated press (buttons: no tolerance,
        a stated delay) after the latest told, by no more than the stated delay, is read on it: the event
        may have happened by then (a start pressed 0.39 s late after an arrival pressed 0.28 s late read 14 ms
        past its window; the followed plan turned inconsistent and the dispatcher moved to a plan giving the
        person another action: the outside driver, workshop, buttons uniform in [0, 0.5] s, seed 10)."""
        tol = self.bound_tolerance
        state = self._state
        if obs.agent not in self._people:
            return obs
        hint = self._told_to(state.decision, obs.agent)[0]  # what this person was told (a team's: issue 37)
        if tol <= 0 and self.max_observation_delay and isinstance(hint, RobotStep) and hint.latest is not None \
                and obs.event in LEG_EVENTS and \
                (hint.action, hint.phase, hint.event) == (obs.action, obs.phase, obs.event) and \
                hint.latest < obs.t <= hint.latest + self.max_observation_delay and hint.latest >= state.history.now:
            return replace(obs, t=hint.latest)  # an undated press up to the stated delay after the latest told
        if tol <= 0 or obs.event not in LEG_EVENTS or \
                not isinstance(hint, RobotStep) or (hint.action, hint.phase, hint.event) != (obs.action, obs.phase,
                                                                                                 obs.event):
            return obs
        above = below = tol
        span = self._span(obs)
        if span is not None:  # the detector's own statement for this estimate, where wider
            above, below = max(tol, span[1] - obs.t), max(tol, obs.t - span[0])
        # compared in the core's ticks (ms): in floats 14.736 - 0.136 > 14.6, and an estimate exactly the
        # tolerance early was read off its bound (issue 37: a team's DC plan of zero slack turned inconsistent)
        if ticks(hint.earliest) - ticks(above) <= ticks(obs.t) < ticks(hint.earliest):
            return replace(obs, t=hint.earliest)
        if hint.latest is not None and ticks(hint.latest) < ticks(obs.t) <= ticks(hint.latest) + ticks(below) and \
                hint.latest >= state.history.now:
            return replace(obs, t=hint.latest)
        return obs

    def _span(self, obs: Observation) -> tuple[float, float] | None:
        """Where `obs` may truly have happened, ``(earliest, latest)`` in seconds, as its sensing path states
        it beyond `bound_tolerance` (`hrc.detect.online.DetectingDispatcher`: a change point's confidence
        interval); None here: the tolerance alone."""
        del obs
        return None

    def _late(self, obs: Observation) -> Mapping[str, Any] | None:
        """The deviation of an observation of the human that reached the dispatcher later than the stated
        maximum delay (`max_observation_delay`): the guarantee of every class assumed no later sensing.
        None otherwise."""
        limit = self.max_observation_delay
        if limit is None or obs.delay is None or obs.agent not in self._people or obs.delay <= limit:
            return None
        return MappingProxyType({"late": {"event": f"{obs.agent}.{obs.action}.{obs.phase}.{obs.event}",
                                          "delay": round(obs.delay, 3), "max": limit}})

    def _tell_route(self, state: _State, history: History, obs: Observation
                    ) -> tuple[Mapping[tuple[int, int], RouteSig], bool]:
        """The routes of the legs under way with `obs` (see `hrc.dispatch.validation`): a leg seen for the
        first time takes the route of the plan that was best when it began (what the agent was told), if
        that plan gives the agent this leg there; and whether set validation must read them again (a new
        route, or a stop at a waiting place seen)."""
        agent = obs.agent or ""
        g = self.task.agent_ids.index(agent)
        k = history.legs[agent].index((obs.action, obs.phase))
        told = state.told
        if (g, k) in told or state.best < 0:
            return told, obs.event == "park"
        legs = self.plan_set.entry(state.best).legs.get(agent, ())
        if k >= len(legs) or legs[k] != (obs.action, obs.phase):
            return told, obs.event == "park"
        sig = tuple(self.routes.routes(np.array([state.best]), g, k)[0].tolist())
        return MappingProxyType({**told, (g, k): sig}), True

    def _on_routes(self, kept: np.ndarray, history: History, told: Mapping[tuple[int, int], RouteSig]) -> np.ndarray:
        """The plans of `kept` that drive or walk each leg seen along its route (`_tell_route`): the one
        told, or with a stop at a waiting place where the agent was seen stopping although told otherwise.
        A fact is never refused for it: if no plan is left, `kept` as it was."""
        legs = []  # (g, k, the route told, seen parking) of each leg that narrows the plans
        for g, agent in enumerate(self.task.agent_ids):
            for k, (action, phase) in enumerate(history.legs.get(agent, ())):
                sig = told.get((g, k))
                parked = (agent, action, phase, "park") in history.times
                if sig is not None or parked:
                    legs.append((g, k, sig, parked))
        if not legs:
            return kept
        # shared by forks: a function of the plans, the legs and their routes alone (no times), which the
        # runs of a simulation meet again and again
        key = (kept.tobytes(), tuple(legs)) if len(kept) <= 512 else None
        found = None if key is None else self._routed.get(key)
        if found is not None:
            return found
        out = kept
        for g, k, sig, parked in legs:
            routes = self.routes.routes(out, g, k)
            if parked and (sig is None or sig[0] == 0):
                out = out[routes[:, 0] == 1]
            else:
                out = out[np.all(routes == np.array(sig, dtype=np.int64), axis=1)]
        found = out if len(out) else kept
        if key is not None:
            if len(self._routed) >= 1024:
                self._routed.clear()
            self._routed[key] = found
        return found

    def _undo(self, obs: Observation) -> Decision:
        state = self._state
        if obs.t < state.history.now:
            raise DispatchError(f"time goes backwards: t = {obs.t:g} s is before the last message "
                                f"({state.history.now:g} s)")
        last = next((k for k in range(len(state.effective) - 1, -1, -1) if state.effective[k].event != "tick"),
                    None)  # the last observation that is not a tick: only ticks may follow the one withdrawn
        if last is None or state.effective[last].agent not in (*self._people, None):
            raise DispatchError("nothing to undo: the last observation is not the human's")
        target = state.effective[last]
        if obs.t - target.t > UNDO_SECONDS:
            raise DispatchError(f"too late to undo: the last human observation was {obs.t - target.t:g} s ago "
                                f"(at most {UNDO_SECONDS:g} s)")
        effective = state.effective[:last] + state.effective[last + 1:]
        history = History.start(self.task)
        for o in effective:
            history = history.add(o)
        history = history.add(Observation(obs.t, "tick"))
        kept = agreeing(self.plan_set.form, history, np.arange(len(self.plan_set), dtype=np.int64))
        told = MappingProxyType({(g, k): sig for (g, k), sig in state.told.items()
                                 if k < len(history.legs.get(self.task.agent_ids[g], ()))})
        kept = self._on_routes(kept, history, told)
        self._state = self._settle(history, (*state.accepted, obs), effective, kept, state.do_forms, state,
                                   told=told)
        return self._state.decision

    def _settle(self, history: History, accepted: tuple[Observation, ...], effective: tuple[Observation, ...],
                kept: np.ndarray, do_forms: Any, previous: _State | None,
                core: tuple[np.ndarray, np.ndarray] | None = None, ack: Any = None,
                told: Mapping | None = None, deviation: Mapping[str, Any] | None = None,
                hinted: Mapping | None = None) -> _State:
        """Rank `kept` under `history` (set ranking, `Ranker`), decide. A plan's evaluation is taken from
        the `previous` state when what enters it is the same (the seen events and now: a tick at the same
        time, an announced next action, away), else made again. `core`: the history as `seen_arrays`
        makes it, when the caller has it."""
        form = self.plan_set.form
        if hinted is None:  # what the person was told, as the previous state had it
            hinted = previous.hinted if previous is not None else MappingProxyType({})
        seen, legs_seen = core if core is not None else seen_arrays(history, form.nodes.shape[2])
        now = ticks(history.now)
        read = self._reading(history, kept, (seen, legs_seen), hinted, previous)
        if read is not None:
            cls, finish, idle = read
        elif previous is not None and not previous.read and previous.now == now and \
                np.array_equal(previous.seen, seen) and np.array_equal(previous.legs_seen, legs_seen) and \
                len(previous.plans):
            where = np.minimum(np.searchsorted(previous.plans, kept), len(previous.plans) - 1)
            known = previous.plans[where] == kept
            cls, finish, idle = previous.cls[where], previous.finish[where], previous.idle[where]
            if not known.all():
                fresh = self.ranker.evaluate(kept[~known], seen, legs_seen, now)
                for column, values in zip((cls, finish, idle), fresh, strict=True):
                    column[~known] = values
        else:
            cls, finish, idle = self.ranker.evaluate(kept, seen, legs_seen, now)
        if self.feasible_only:
            feasible = cls != CLASS_ORDER.index("inconsistent")
            kept, cls, finish, idle = kept[feasible], cls[feasible], finish[feasible], idle[feasible]
        counts = dict(zip(CLASS_ORDER, np.bincount(cls, minlength=3).tolist(), strict=True))
        lead = None if deviation is not None else self._lead(kept, cls, previous)
        at = self.ranker.best(kept, cls, finish, idle, lead)
        if at < 0 and self.fallback and not self.feasible_only:  # no plan agrees: compile on demand
            if not self._team:
                decision = fallback_decision(history, self._robot,
                                             None if previous is None else previous.decision.robot, counts, ack,
                                             deviation)
            else:  # every robot its own fallback step (issue 37), the people told nothing
                told = {} if previous is None else (previous.decision.robots or {})
                steps = fallback_steps(history, self._robots, told)
                decision = fallback_decision(history, self._robot, None, counts, ack, deviation,
                                             self._per_agent(steps, {}, history))
            best = -1
        elif at < 0:
            decision = Decision(history.now, None, None, MappingProxyType(counts), None, history.away, True, ack=ack,
                                deviation=deviation, **self._per_agent({}, {}, history))
            best = -1
        else:
            best = int(kept[at])
            plan_class = CLASS_ORDER[int(cls[at])]
            entry = self.plan_set.entry(best)
            do = dict(do_forms)
            done = executed(entry, history)
            steps = self._steps(entry, done, history, plan_class, best, do, (seen, legs_seen), hinted)
            do_forms = MappingProxyType(do)
            if self._limits is not None:
                for r in self._robots:
                    step = steps[r]
                    if isinstance(step, RobotStep):
                        steps[r] = replace(step, separation=self._limits[r])
            robot, human = steps.get(self._robot), steps.get(history.human)
            if not self._team:
                ahead = self._ahead(entry, best, done, history) if human is None else None
                decision = Decision(history.now, entry.id, plan_class, MappingProxyType(counts), robot, history.away,
                                    False, human, ack, deviation, ahead)
            else:  # each person under way is told their step ahead
                aheads = {h: a for h in self._people if steps[h] is None
                          for a in [self._ahead(entry, best, done, history, h)] if a is not None}
                decision = Decision(history.now, entry.id, plan_class, MappingProxyType(counts), robot, history.away,
                                    False, human, ack, deviation, aheads.get(history.human),
                                    **self._per_agent(steps, aheads, history))
        told = (previous.told if previous is not None else MappingProxyType({})) if told is None else told
        hinted = self._told(hinted, history, decision)
        return _State(history, accepted, effective, kept, cls, finish, idle, best, decision,
                      MappingProxyType(dict(do_forms)), seen, legs_seen, now, MappingProxyType(dict(told)), lead,
                      deviation, hinted, read is not None)

    def _reading(self, history: History, kept: np.ndarray, seen: tuple[np.ndarray, np.ndarray],
                 hinted: Mapping[tuple[str, str, str, str], tuple[int, int]], previous: _State | None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """``(cls, finish, idle)`` of `kept` with the person's next event, told and not yet learnt although
        its told latest has passed, less than the stated delay ago (`_unlearnt`), read as the windows read
        it (`_windows`): done as told, at some time between the earliest told (not before the person's last
        event seen) and the latest. The class is the worse of the two readings (Bhargava, Muise & Williams
        2018: controllable under the delay when one strategy holds for every time the unobserved event may
        have had), the remaining makespan and idle time the later one's. Read as "not yet" (the plain
        history), the unseen departure was at now or later, past its told latest: the plan turned
        "consistent" until the late button came, though the person had done as told, and the best plan
        could move (issue 32). The event is the one of the plan being followed (the last best); a plan that
        gives the person another next step is read without it. None when there is no such event (always
        with buttons on time). While the told window is still open, the plain reading ("not yet", the
        person may still do it) stands: the robot's windows hold for an early one too (`_windows`); reading
        it here as well cost a set ranking per message (kitting under buttons' delay: p99 14 -> 90 ms). In a
        team every person's such event (issue 37), all at their earliest, then all at their latest."""
        if not hinted or not len(kept) or previous is None or previous.best < 0 or \
                not np.any(kept == previous.best):
            return None
        form = self.plan_set.form
        now = ticks(history.now)
        p = previous.best
        entry = self.plan_set.entry(p)
        passed = [u for u in self._unlearnts(entry, executed(entry, history), history, hinted) if u[3] is not None]
        if not passed:
            return None
        counts = seen[1].copy()
        readings = [(seen[0].copy(), counts), (seen[0].copy(), counts)]
        other = np.zeros(len(kept), dtype=bool)  # the plans whose person has another next step
        for (human, _, _, e_name), _, lo, late, k in passed:
            # not before the person's last event seen (a window told ahead may open before their work ends)
            lo = max(lo, max((ticks(t) for key, t in history.times.items() if key[0] == human), default=0))
            assert late is not None  # (`passed`)
            late = max(late, lo)
            g, e = self.task.agent_ids.index(human), LEG_EVENTS.index(e_name)
            counts[g] = max(int(counts[g]), k + 1)  # the first event of a leg not yet seen begun
            for (arr, _), t in zip(readings, (lo, late), strict=True):
                arr[g, k, e] = t
            other |= form.nodes[kept, g, k, e] < 0
            n = len(history.actions_seen(human))
            if k >= len(history.legs.get(human, ())) and n < form.seq.shape[2]:  # a leg not yet begun
                other |= form.seq[kept, g, n] != form.seq[p, g, n]
        mine = kept[~other]
        cls_lo, _, _ = self.ranker.evaluate(mine, *readings[0], now)
        cls_hi, finish_hi, idle_hi = self.ranker.evaluate(mine, *readings[1], now)
        if not other.any():
            return np.maximum(cls_lo, cls_hi), finish_hi, idle_hi
        cls, finish, idle = (np.empty(len(kept), dtype=c.dtype) for c in (cls_hi, finish_hi, idle_hi))
        cls[~other], finish[~other], idle[~other] = np.maximum(cls_lo, cls_hi), finish_hi, idle_hi
        cls[other], finish[other], idle[other] = self.ranker.evaluate(kept[other], seen[0], seen[1], now)
        return cls, finish, idle

    def _per_agent(self, steps: Mapping[str, RobotStep | WaitFor | None], aheads: Mapping[str, Ahead],
                   history: History) -> dict[str, Any]:
        """A team's answer per agent (`Decision.robots`, `people`, `aheads`; an agent not in `steps` is told
        nothing); nothing for one person and one robot, whose answer is as it always was."""
        if not self._team:
            return {}
        return {"robots": MappingProxyType({r: steps.get(r) for r in self._robots}),
                "people": MappingProxyType({h: steps.get(h) for h in self._people}),
                "aheads": MappingProxyType(dict(aheads)),
                "away": tuple(h for h in self._people if h in history.absent)}

    def _ahead(self, entry: PlanEntry, p: int, done: dict[str, int], history: History,
               person: str | None = None) -> Ahead | None:
        """The person's instruction ahead (`Ahead`), while their next event in the plan is nature's (a walk
        or a manipulation under way): their next own step after it, and the robot's last event not yet
        done that the plan's network orders no later than that step (a distance ``T(x) - T(step) <= -gap <= 0``
        in its STN reading: requirement links, contingent links at their bounds, by Bellman-Ford from
        the step); when there is none, the robot's event already done that holds the step back latest, if
        that is after now. None when the person is not under way, away, done, or the network has a negative cycle
        (no schedule: nothing to promise). `person`: which person (default: the first); in a team the robots'
        events are every robot's, and of several the one that holds the step back by the largest gap."""
        human = history.human if person is None else person
        if not human or human in history.absent:
            return None
        contingent = entry.stnu.contingent_timepoints
        pending = [(a, ph, e, n) for a, ph in entry.legs.get(human, ())
                   for e, n in entry.leg_points[(human, a, ph)] if n not in done]
        if not pending or pending[0][3] not in contingent:
            return None
        at_step = next((k for k, x in enumerate(pending) if x[3] not in contingent), None)
        if at_step is None:
            return None
        step = pending[at_step]
        # the person's stay where the step begins (issue 32): when the step is a departure for a leg
        # without a walk (depart -> arrive in [0, 0] where the person stands), the legs of that place after
        # it with their work, up to the departure that walks away; no sensor tells these steps apart (on
        # kitting the detector learnt inspect's end only when the person walked away after label and
        # deliver's take, and the person, told when to "depart" for label but nothing of the rest, waited
        # for the chart's planned times, 5.7 and 6.8 s). The bound is the stay's latest: every step of it
        # holds by it (the first goes no earlier than the rest), so the person may go through the stay as
        # told for its first step (the simulated person does: `hrc.sim.policies`)
        sources = [step]
        if step[2] == "depart" and at_step + 1 < len(pending) and pending[at_step + 1][3] not in contingent:
            for k in range(at_step + 1, len(pending)):
                x = pending[k]
                if x[3] in contingent:
                    if x[2] == "arrive":  # a walk: the stay ended with the departure before it
                        break
                    continue  # the work of a leg here
                sources.append(x)
        at = self.plan_set.node_index(p)
        key = (p, tuple(x[3] for x in sources))
        if key in self._dists:  # shared by forks, like the arcs: a function of the plan and the step alone
            dist = self._dists[key]
        else:
            if len(self._dists) >= 4096:
                self._dists.clear()
            dist = self._dists[key] = self._distances(p, [at[x[3]] for x in sources])
        if dist is None:
            return None
        order = [(k, e, n) for robot in self._robots for k, (a, ph) in enumerate(entry.legs.get(robot, ()))
                 for e, (_, n) in enumerate(entry.leg_points[(robot, a, ph)]) if n not in done]
        before = [n for _, _, n in order if dist[at[n]] <= 0]
        if len(self._robots) > 1 and before:  # several robots: the one that holds the step back longest
            before = [min(before, key=lambda n: float(dist[at[n]]))]
        if not before:
            # a robot event already done may still hold the step back: ``T(step) >= T(x) + gap`` after now
            # (issue 32: once the robot had left, "wait 4 s after its departure" fell from the instruction and
            # the person, told nothing, left at once, breaking the passing order)
            now = ticks(history.now)
            bound = [(done[n] - float(dist[at[n]]), n) for robot in self._robots for a, ph in entry.legs.get(robot, ())
                     for _, n in entry.leg_points[(robot, a, ph)] if n in done and dist[at[n]] <= 0]
            bound = [b for b in bound if b[0] > now]
            if bound:
                before = [max(bound)[1]]
        wait, gap = None, 0.0
        if before:
            agent, action, phase, event = entry.events[before[-1]]
            wait, gap = f"{agent}.{action}.{phase}.{event}", round(-float(dist[at[before[-1]]]) / 1000, 3) + 0.0
        after = f"{human}.{pending[0][0]}.{pending[0][1]}.{pending[0][2]}"
        return Ahead(after, f"{human}.{step[0]}.{step[1]}.{step[2]}", wait, gap)

    def _distances(self, p: int, sources: list[int]) -> np.ndarray | None:
        """Plan `p`'s network's distances from the nearest of timepoints `sources` (by position) in its STN reading
        (requirement links, contingent links at their bounds: `_ahead`), by Bellman-Ford; None on a
        negative cycle."""
        arcs = self._arcs.get(p)
        if arcs is None:  # shared by forks: a function of the plan alone; a few hundred plans at most
            if len(self._arcs) >= 256:
                self._arcs.clear()
            a = self.plan_set.form.arrays(p)
            u = np.concatenate([a.edges[:, 0], a.conts[:, 0], a.conts[:, 1]])
            v = np.concatenate([a.edges[:, 1], a.conts[:, 1], a.conts[:, 0]])
            w = np.concatenate([a.edges[:, 2], a.conts[:, 3], -a.conts[:, 2]]).astype(np.float64)
            by = np.argsort(v, kind="stable")  # arcs grouped by their head: one reduceat per pass
            heads, starts = np.unique(v[by], return_index=True)
            arcs = self._arcs[p] = (a.n, u[by], w[by], heads, starts)
        n, u, w, heads, starts = arcs
        dist = np.full(n, np.inf)
        dist[sources] = 0.0
        for _ in range(n + 1):
            relaxed = dist.copy()
            if len(u):
                relaxed[heads] = np.minimum(dist[heads], np.minimum.reduceat(dist[u] + w, starts))
            if np.array_equal(relaxed, dist):
                return dist
            dist = relaxed
        return None

    def _lead(self, kept: np.ndarray, cls: np.ndarray, previous: _State | None) -> np.ndarray | None:
        """The plan being followed keeps its hold (docs/dispatch.md, "What the robot may assume"): the
        person's part of the last best plan (their remaining actions in their order) is what they were
        shown and may be doing; while some DC candidate keeps it, a DC plan that gives it up ranks after
        every DC plan that keeps it (1 in the column `Ranker` reads after the class). None when no
        candidate keeps it (the person chose otherwise), none of those is DC (the promise is lost: the
        best plan as ranked), or there is nothing to choose."""
        g = self._human_g
        if previous is None or previous.best < 0 or g < 0 or not len(kept):
            return None
        key = (kept.tobytes(), previous.best) if len(kept) <= 512 else None
        same = None if key is None else self._same.get(key)
        if same is None:
            seq = self.plan_set.form.seq
            if len(self._people_g) > 1:  # every person's part
                gs = self._people_g
                same = np.all((seq[kept][:, gs] == seq[previous.best, gs]).reshape(len(kept), -1), axis=1)
            else:
                same = np.all(seq[kept, g] == seq[previous.best, g], axis=1)
            if key is not None:  # shared by forks: a function of the plans alone
                if len(self._same) >= 1024:
                    self._same.clear()
                self._same[key] = same
        dc = cls == 0
        if not (same & dc).any() or not (dc & ~same).any():
            return None
        return (dc & ~same).astype(np.int8)

    def _steps(self, entry: PlanEntry, done: dict[str, int], history: History, plan_class: str,
               index: int, do: dict[int, Any], seen: tuple[np.ndarray, np.ndarray],
               hinted: Mapping[tuple[str, str, str, str], tuple[int, int]] | None = None
               ) -> dict[str, RobotStep | WaitFor | None]:
        """Each robot's next step in `entry` (module docstring) and each person's hint (`Decision.human`),
        by agent id, robots first; `seen`: the history as the core reads it (`seen_arrays`); `hinted`: what
        the person was told (`_hinted`). No agent goes together with another's own event it must follow
        (every other agent's timepoints are uncontrolled for it)."""
        now = ticks(history.now)
        agents = (*self._robots, *self._people)
        out: dict[str, RobotStep | WaitFor | None] = dict.fromkeys(agents)
        contingent = entry.stnu.contingent_timepoints
        nodes = self._nodes.get(index)
        if nodes is None:  # shared by forks: a function of the plan alone; a few hundred plans at most
            if len(self._nodes) >= 256:
                self._nodes.clear()
            every = frozenset(entry.events)
            nodes = self._nodes[index] = {a: every - frozenset(n for n, ev in entry.events.items() if ev[0] == a)
                                          for a in agents}
        asks: list[tuple[int, str, str, str, str, str, frozenset[str]]] = []
        for slot, agent in enumerate(agents):
            nxt = next(((action, phase, event, node) for action, phase in entry.legs.get(agent, ())
                        for event, node in entry.leg_points[(agent, action, phase)] if node not in done), None)
            if nxt is not None and self._joint and nxt[0] in self._joint:
                held = self._joint_hold(entry, agent, nxt, done)
                if held is not None:  # a joint action: its start waits for every agent's observed arrival
                    out[agent] = held
                    continue
            if nxt is None or nxt[3] in contingent or agent in history.absent:
                continue
            action, phase, event, node = nxt
            arrival = self._arrival(entry, index, agent, action, phase, event, node, done, now)
            if arrival is not None:  # under way: it gets there when its drive says
                out[agent] = arrival
                continue
            uncontrolled = frozenset(n for n in nodes[agent] if n not in done and n not in contingent)
            asks.append((slot, agent, action, phase, event, node, uncontrolled))
        if not asks:
            return out
        mode, found = self._windows(entry, index, done, history, _MODES[plan_class], asks, seen, hinted or {})
        found = self._unlock(entry, index, done, history, mode, asks, found, seen, hinted or {})
        for (_, agent, action, phase, event, node, _), step in zip(asks, found, strict=True):
            if isinstance(step, tuple):
                earliest, latest = step
                step_ = RobotStep(action, phase, event, earliest / 1000,
                                  None if latest is None or mode is ExecutionMode.EARLIEST else latest / 1000)
                if agent in self._robots and mode is not ExecutionMode.EARLIEST and self.use_preferences:
                    step_ = self._preferred(entry, index, do, done, now, node, step_)
                out[agent] = step_
                continue
            waits = sorted(step, key=lambda n: (entry.events.get(n, ("",))[0] == agent, n))
            w_agent, w_action, w_phase, w_event = entry.events.get(waits[0], ("", "", "", waits[0]))
            out[agent] = WaitFor(w_agent, w_action, w_phase, w_event)
        return out

    def _unlock(self, entry: PlanEntry, p: int, done: dict[str, int], history: History, mode: ExecutionMode,
                asks: list[tuple[int, str, str, str, str, str, frozenset[str]]],
                found: list[tuple[int, int | None] | list[str]], seen: tuple[np.ndarray, np.ndarray],
                hinted: Mapping[tuple[str, str, str, str], tuple[int, int]]
                ) -> list[tuple[int, int | None] | list[str]]:
        """`found` with a mutual wait undone: the robot's next timepoint X waits for the person's next one
        V (``d(X, V) <= 0``: V no later than X, and V is the person's own, `uncontrolled`) while V waits
        for X (``d(V, X) <= 0``): the two must go at the same instant, and each agent waiting for the other
        stalls the run (issue 37: the joint workshop's seed 186, a deadline with no slack left forcing the
        robot's end of a put and the person's next start together). The robot, the one the dispatcher
        drives, goes first: X's window read without V as uncontrolled (executing X at a tick of it keeps
        the rest DC, `hrc.temporal.execution`: V may then go at that same tick), and the person is told to
        wait for X, as before. Unchanged everywhere else."""
        if len(asks) != 2 or not isinstance(found[0], list) or not isinstance(found[1], list):
            return found
        robot, human = asks
        if robot[1] not in self._robots or human[1] not in self._people or robot[5] not in found[1] or \
                human[5] not in found[0]:
            return found
        freed = (*robot[:6], robot[6] - {human[5]})
        _, again = self._windows(entry, p, done, history, mode, [freed], seen, hinted)
        return [again[0], found[1]]

    def _joint_hold(self, entry: PlanEntry, agent: str, nxt: tuple[str, str, str, str],
                    done: dict[str, int]) -> WaitFor | None:
        """For the next event `nxt` of `agent` on a joint action (issue 37): the start, while some other
        agent of it has not been seen arriving at the place, waits for that arrival, whatever the plan's
        class (in a DC plan the real-time execution waits anyway, `hrc.compile.temporal_net_creator`, "joint
        actions"; in the others the robot must not start on a predicted arrival); the end, nature's, is
        waited for. None otherwise (the departure and the drive are as for any leg)."""
        action, phase, event, _ = nxt
        if event == "end":
            return WaitFor(agent, action, phase, "end")
        if event != "start":
            return None
        for other in self._joint[action]:  # the plan's crew of it (`hrc.model.Task.crew`): the agents with a leg
            if other != agent and (other, action, phase) in entry.leg_points:
                node = dict(entry.leg_points[(other, action, phase)])["arrive"]
                if node not in done:
                    return WaitFor(other, action, phase, "arrive")
        return None

    def _windows(self, entry: PlanEntry, p: int, done: dict[str, int], history: History, mode: ExecutionMode,
                 asks: list[tuple[int, str, str, str, str, str, frozenset[str]]], seen: tuple[np.ndarray, np.ndarray],
                 hinted: Mapping[tuple[str, str, str, str], tuple[int, int]]
                 ) -> tuple[ExecutionMode, list[tuple[int, int | None] | list[str]]]:
        """`_windows_at` from what the dispatcher can know of the person's events: with a sensor whose
        estimates may be `bound_tolerance` off (the motion detector), each seen event of the person
        happened somewhere in ``[t - tol, t + tol]`` around its estimate ``t``, narrowed to the window they
        were told (`_hinted`: the person does as told). A window must hold for every such time: the latest
        from the earliest times, the earliest from the latest (each bound is monotone in every executed
        time), the waits of either. This is the variable-delay reduction of `hrc.temporal.delay` (an
        observation point ``C' = t + tol`` telling ``C`` to within ``[C' - 2 tol, C']``) applied at run
        time, to executable events of the person as well as contingent ones (issue 32: a departure estimated
        20-90 ms late let the robot pass 20-90 ms late). Where the two do not meet (the error is more than
        the plan's slack) the window at the estimates, as without the sensor's error. The person's next
        event, when it may have happened unlearnt (`_unlearnt`), is read so for every ask but its own (the
        person's window for it: nothing to read early); in a team, every person's (issue 37), each ask read
        with every other person's."""
        unlearnts = self._unlearnts(entry, done, history, hinted)
        groups: dict[tuple[_Unlearnt, ...], list[int]] = {}
        for i, ask in enumerate(asks):  # the unlearnt events each ask reads: all but its own
            groups.setdefault(tuple(u for u in unlearnts if u[1] != ask[5]), []).append(i)
        if len(groups) == 1:
            ((read, _),) = groups.items()
            return self._read(entry, p, done, history, mode, asks, seen, hinted, read)
        used: ExecutionMode | None = None
        found: list[tuple[int, int | None] | list[str]] = [[] for _ in asks]
        for read, at in sorted(groups.items(), key=lambda g: -len(g[0])):  # (one person's: the rest first)
            mode_g, found_g = self._read(entry, p, done, history, mode, [asks[i] for i in at], seen, hinted, read)
            used = mode_g if used is None else max(used, mode_g, key=_rank)
            for i, f in zip(at, found_g, strict=True):
                found[i] = f
        assert used is not None
        return used, found

    def _read(self, entry: PlanEntry, p: int, done: dict[str, int], history: History, mode: ExecutionMode,
              asks: list[tuple[int, str, str, str, str, str, frozenset[str]]], seen: tuple[np.ndarray, np.ndarray],
              hinted: Mapping[tuple[str, str, str, str], tuple[int, int]], unlearnt: tuple[_Unlearnt, ...]
              ) -> tuple[ExecutionMode, list[tuple[int, int | None] | list[str]]]:
        """`_windows` for `asks`, with `unlearnt` (the people's next events, or none) read as `_estimates`
        reads them."""
        box = self._estimates(entry, done, history, seen, hinted, unlearnt)
        if box is None:
            return self._windows_at(entry, p, done, history, mode, asks, seen)
        (done_lo, seen_lo), (done_hi, seen_hi) = box
        mode_lo, early = self._windows_at(entry, p, done_lo, history, mode, asks, seen_lo)
        mode_hi, late = self._windows_at(entry, p, done_hi, history, mode, asks, seen_hi)
        used = max(mode_lo, mode_hi, key=_rank)
        plain: list[tuple[int, int | None] | list[str]] | None = None
        out: list[tuple[int, int | None] | list[str]] = []
        for i, (a, b) in enumerate(zip(early, late, strict=True)):
            if isinstance(a, list) or isinstance(b, list):
                out.append(a if isinstance(a, list) else b)
                continue
            earliest, latest = b[0], a[1]
            if latest is not None and latest < earliest:
                if plain is None:
                    used_plain, plain = self._windows_at(entry, p, done, history, mode, asks, seen)
                    used = max(used, used_plain, key=_rank)
                out.append(plain[i])
                continue
            out.append((earliest, latest))
        return used, out

    def _estimates(self, entry: PlanEntry, done: dict[str, int], history: History,
                   seen: tuple[np.ndarray, np.ndarray], hinted: Mapping[tuple[str, str, str, str], tuple[int, int]],
                   unlearnt: tuple[_Unlearnt, ...] = ()
                   ) -> tuple[tuple[dict[str, int], tuple[np.ndarray, np.ndarray]],
                              tuple[dict[str, int], tuple[np.ndarray, np.ndarray]]] | None:
        """`done` and `seen` with each seen event of every person at the earliest, then at the latest time
        it may have happened (`_windows`), and `unlearnt`, the people's next events when they may have
        happened unlearnt (`_unlearnt`), at the earliest they may have, then at the latest (or not yet); None
        without a sensor's error or before any event of a person. A team's people each by their own events
        (issue 37: before, the first person's alone, and the robot's windows held for the others' events
        at the times the late buttons gave)."""
        if not self._people or not hinted:
            return None
        shift = {key: hinted[key] for key in history.times if key in hinted}
        if not shift and not unlearnt:
            return None
        ids = self.task.agent_ids
        nodes = {key: node for node, key in entry.events.items() if key in shift}
        ends = {c.target: c for c in entry.stnu.contingents}
        out = []
        for side in (0, 1):
            moved = dict(done)
            times = dict(shift)
            for key, node in sorted(nodes.items(), key=lambda kn: history.times[kn[0]]):
                if node not in moved:
                    continue
                t = shift[key][side]
                link = ends.get(node)
                if link is not None and link.source in moved:  # not outside the link from the event before:
                    start = moved[link.source]  # a walk's arrival learnt 7 s late did not happen before the
                    t = max(t, start + link.lb) if side == 0 else min(t, start + link.ub)  # departure
                    t = min(max(t, shift[key][0]), shift[key][1])
                moved[node] = t
                times[key] = (t, t)
            _in_order(entry, history, moved, times, side)
            arr = seen[0].copy()
            for key, bounds in times.items():
                arr[ids.index(key[0]), history.legs[key[0]].index((key[1], key[2])), LEG_EVENTS.index(key[3])] = \
                    bounds[side]
            counts = seen[1]
            for u in unlearnt:
                at = (u[2], u[3])[side]
                if at is None:
                    continue
                key, node, k = u[0], u[1], u[4]
                g = ids.index(key[0])
                moved[node] = at
                _pending_at(entry, history, key, moved, at)
                arr[g, k, LEG_EVENTS.index(key[3])] = at
                if k >= counts[g]:  # the first event of a leg not yet seen begun
                    counts = counts.copy() if counts is seen[1] else counts
                    counts[g] = k + 1
            out.append((moved, (arr, counts)))
        return out[0], out[1]

    def _unlearnts(self, entry: PlanEntry, done: dict[str, int], history: History,
                   hinted: Mapping[tuple[str, str, str, str], tuple[int, int]]) -> tuple[_Unlearnt, ...]:
        """`_unlearnt` of every person, in task order (a team's: each person's next event is their own, told
        to them and learnt through their own sensing, issue 37); at most one for one person."""
        if not hinted:
            return ()
        return tuple(u for person in self._people for u in [self._unlearnt(entry, done, history, hinted, person)]
                     if u is not None)

    def _unlearnt(self, entry: PlanEntry, done: dict[str, int], history: History,
                  hinted: Mapping[tuple[str, str, str, str], tuple[int, int]], person: str | None = None
                  ) -> _Unlearnt | None:
        """The person's next own event in `entry` when it may have happened without the robot knowing yet
        (issue 32): they were told a window ``[lo, hi]`` for it (`_told`) and ``lo`` has passed, no later than
        the stated delay after ``hi`` (beyond that, an event not seen was not done as told: the plain
        reading). The delay-robust strategy reads it as possibly done at any time it was told (Bhargava,
        Muise & Williams 2018, variable delay: a contingent point is known only once observed, and the
        executable one of a person who does as told lies in their window): ``(key, node, lo, late, leg)``,
        `late` the latest it may have happened (``hi`` once passed) or None while it may also be still to
        come, `leg` its position among the person's legs. None otherwise (and always with buttons on time:
        nothing is told then, `_told`). `person`: whose (default: the first; `_unlearnts`: every person's)."""
        human = history.human if person is None else person
        legs = history.legs.get(human, ())
        now = ticks(history.now)
        contingent = entry.stnu.contingent_timepoints
        for k, (action, phase) in enumerate(entry.legs.get(human, ())):
            for event, node in entry.leg_points[(human, action, phase)]:
                if node in done:
                    continue
                key = (human, action, phase, event)
                told = hinted.get(key)
                if node in contingent or told is None or key in history.times or told[0] > now:
                    return None
                if k > len(legs) or (k < len(legs) and legs[k] != (action, phase)):
                    return None  # not the person's next step as seen
                lo, hi = told
                if hi == NO_BOUND or now <= hi:
                    return key, node, lo, None, k
                if now - hi > ticks(self.max_observation_delay or 0.0):
                    return None
                return key, node, lo, hi, k
        return None

    def _windows_at(self, entry: PlanEntry, p: int, done: dict[str, int], history: History, mode: ExecutionMode,
                    asks: list[tuple[int, str, str, str, str, str, frozenset[str]]],
                    seen: tuple[np.ndarray, np.ndarray]
                    ) -> tuple[ExecutionMode, list[tuple[int, int | None] | list[str]]]:
        """The mode (`mode`, or stricter where the residual's own checks say so: the two DC checks never
        disagree, but the stricter reading wins if they did) and, per ask, its timepoint's execution
        window ``(earliest, latest)`` in ticks or the timepoints it must wait for
        (`hrc.temporal.execution.RealTimeState.step`): in the C core when it is built, else in Python."""
        native = self.ranker.native
        if native is not None:
            names = entry.stnu.timepoints  # the form's numbering (`PlanSet.entry`)
            at = self.plan_set.node_index(p)
            unc = np.zeros((len(asks), len(names)), dtype=bool)
            for i, ask in enumerate(asks):
                unc[i, [at[name] for name in ask[6]]] = True
            got = native.windows(p, seen[0], seen[1], ticks(history.now), _CORE_MODES[mode],
                                 [at[ask[5]] for ask in asks], unc)
            if got is not None:
                used, results = got
                return _FROM_CORE[used], [[names[v] for v in r] if isinstance(r, list)
                                          else (r[0], None if r[1] == NO_BOUND else r[1]) for r in results]
        # a time the person's event may have had can be after the last message's (`_estimates`): the clock
        # stays at now, as in the C core (reading it at that time instead held every other event of the
        # plan back to it: a hint 0.5 s late on the detect-team case, tests/test_detect_team.py)
        state = real_time_state(entry.stnu, done, ticks(history.now), ahead=True)
        if _rank(state.default_mode()) > _rank(mode):
            mode = state.default_mode()
        out: list[tuple[int, int | None] | list[str]] = []
        for ask in asks:
            step = state.step(ask[5], mode, uncontrolled=ask[6])
            out.append((step.earliest, step.latest) if isinstance(step, ExecutionWindow) else list(step.until))
        return mode, out

    def _preferred(self, entry: PlanEntry, index: int, do: dict[int, Any], done: dict[str, int], now: int,
                   node: str, step: RobotStep) -> RobotStep:
        """`step` narrowed to the DO window of its timepoint where the two meet (Wilcox, Nikolaidis & Shah
        2012): the plan's DO form (Fig. 5, APA on its residual network read as an STP with the task's
        preferences) dispatched by propagation from what has happened, and compiled again (Fig. 8, line 7)
        when what happened left it. As it was when the task has no preferences, the plan keeps none, or
        the two windows do not meet: the class's promise comes first."""
        task = self.task
        if not task.preferences:
            return step
        form = do.get(index)
        past = None if form is None or form is False else _past(form, done)
        if form is None or (form is not False and not _within(form, done, past)):
            past = None
            # shared by forks: the same plan from the same events at the same time (each simulated run's
            # first) has the same DO form; its rows follow `done`'s order, so the key does too
            key = (index, tuple(done.items()), now)
            form = self._dos.get(key)
            if form is None:
                if len(self._dos) >= 1024:
                    self._dos.clear()
                form = self._dos[key] = _do_form(entry, done, now, task.preferences)
            do[index] = form
        if form is False:
            return step
        events, apsp = form
        at, times = _past(form, done) if past is None else past
        i = events[node]
        lo = np.max(times - apsp[i, at])
        hi = np.min(times + apsp[at, i])
        earliest = max(step.earliest, round(max(lo, now) / 1000, 3))
        latest = step.latest
        if hi != float("inf"):
            latest = round(hi / 1000, 3) if latest is None else min(latest, round(hi / 1000, 3))
        if latest is not None and latest < earliest:
            return step
        return RobotStep(step.action, step.phase, step.event, earliest, latest)

    def _arrival(self, entry: PlanEntry, p: int, agent: str, action: str, phase: str, event: str, node: str,
                 done: dict[str, int], now: int) -> RobotStep | None:
        """The end of a drive under way (``arrive`` or ``park`` after an executed ``depart`` or ``unpark``):
        not a decision but the drive's own time, from the link between the two (the robot drives a route
        in exactly its time; a window of it when the link is a range), never before now. None otherwise."""
        if event not in ("arrive", "park"):
            return None
        points = entry.leg_points[(agent, action, phase)]
        names = [n for _, n in points]
        prev = names[names.index(node) - 1]
        if prev not in done:
            return None
        at = self.plan_set.node_index(p)
        a, b = at[prev], at[node]
        span = self._spans.get((p, a, b))
        if span is None:  # shared by forks: a function of the plan alone
            form = self.plan_set.form
            e0, e1 = int(form.edges_ptr[p]), int(form.edges_ptr[p + 1])
            u, v, w = form.edges_u[e0:e1], form.edges_v[e0:e1], form.edges_w[e0:e1]
            ahead = w[(u == a) & (v == b)]  # T(b) - T(a) <= w
            back = w[(u == b) & (v == a)]  # T(a) - T(b) <= w: T(b) - T(a) >= -w
            if len(self._spans) >= 4096:
                self._spans.clear()
            span = self._spans[(p, a, b)] = (max(0, *(-int(x) for x in back)),
                                             min((int(x) for x in ahead), default=None))
        lo, hi = span
        start = done[prev]
        earliest = max(now, start + lo)
        latest = None if hi is None else max(earliest, start + hi)
        return RobotStep(action, phase, event, earliest / 1000, None if latest is None else latest / 1000)

    def _next_events(self, agent: str, history: History) -> list[Observation]:
        """The events `agent` could report next in some remaining plan: later events of its leg under way
        (up to its start: depart and arrive may go unreported), or the depart and start of its next leg."""
        st = self._state
        if not len(st.plans):
            return []
        form = self.plan_set.form
        g = self.task.agent_ids.index(agent)
        seen = history.legs.get(agent, ())
        current = history.current(agent)
        t = history.now
        if current is not None:
            last = history.last_event(agent, *current)
            order = LEG_EVENTS.index(last) if last else -1
            out: dict[str, None] = {}
            # the events each plan has on this leg (park and unpark only where it stops on the way)
            for has in np.unique(form.nodes[st.plans, g, len(seen) - 1, :] >= 0, axis=0):
                events = [e for e, present in zip(LEG_EVENTS, has.tolist(), strict=True)
                          if present and LEG_EVENTS.index(e) > order]
                events = events[:events.index("start") + 1] if "start" in events else events[:1]
                out.update(dict.fromkeys(events))
            events = sorted(out, key=LEG_EVENTS.index)
            return [Observation(t, e, agent, current[0], current[1]) for e in events]
        legs: set[tuple[str, str]] = set()
        done = history.actions_seen(agent)
        if seen:  # an action's next phase comes next, in every remaining plan
            action, phase = seen[-1]
            phases = [p.id for p in self.task.action(action).phases]
            if phase != phases[-1]:
                legs.add((action, phases[phases.index(phase) + 1]))
        if not legs and len(done) < form.seq.shape[2]:
            for a in np.unique(form.seq[st.plans, g, len(done)]).tolist():
                if a >= 0:
                    action = self.task.action_ids[a]
                    legs.add((action, self.task.action(action).phases[0].id))
        return [Observation(t, e, agent, action, phase) for action, phase in sorted(legs) for e in ("depart", "start")]


_DOForm = tuple[dict[str, int], Any]  # event -> index, the DO form's APSP matrix (ticks); index 0: its origin


def _do_form(entry: PlanEntry, done: dict[str, int], now: int, preferences: Any) -> _DOForm | Literal[False]:
    """APA's DO form of the plan's residual network (`residual_network`: its origin, at the task's
    start, first, then the plan's timepoints), read as an STP with the task's `preferences`: its event
    index and APSP matrix in ticks; False when the plan can keep no preferred interval. What
    `hrc.apa.plan.plan_preference_value` and `hrc.apa.compile.do_apsp` compute on the residual
    `STNU`, built here straight as the rows APA compiles (`hrc.apa.compile.Rows`, the same rows in the
    same order), with no objects and no conversion through seconds (Wilcox et al. 2012, Fig. 5 on Fig. 8's
    line 7: the DO form compiled again from what happened)."""
    from hrc.apa.compile import Rows, compile_rows, rows_apsp  # the QP solver only where preferences are used
    from hrc.apa.model import PreferenceFunction
    from hrc.compile.temporal_net_creator import event_timepoint
    from hrc.temporal.graphml import tool_name
    from hrc.temporal.ticks import to_ticks

    stnu = entry.stnu
    names = stnu.timepoints
    index = {v: k + 1 for k, v in enumerate(names)}  # 0: the residual's origin
    inf = float("inf")
    src: list[int] = []
    dst: list[int] = []
    lbs: list[float] = []
    ubs: list[float] = []

    def row(a: int, b: int, lb: float, ub: float) -> None:
        src.append(a)
        dst.append(b)
        lbs.append(lb)
        ubs.append(ub)

    for r in stnu.requirements:  # residual_network's links, in its order
        if r.source in done and r.target in done:
            continue
        row(index[r.source], index[r.target], -inf if r.lb is None else r.lb, inf if r.ub is None else r.ub)
    for x, t in done.items():
        row(0, index[x], t, t)
    contingent = stnu.contingent_timepoints
    for x in names:
        if x not in done and x not in contingent:
            row(0, index[x], now, inf)
    for c in stnu.contingents:
        if c.target in done:
            continue
        lb, ub = c.lb, c.ub
        if c.source in done:
            elapsed = now - done[c.source]
            lb, ub = max(lb, elapsed), max(ub, elapsed)
        row(index[c.source], index[c.target], lb, ub)
    prefs = []
    for p in preferences:
        a = index.get(tool_name(event_timepoint(entry.plan, p.source)))
        b = index.get(tool_name(event_timepoint(entry.plan, p.target)))
        if a is None or b is None:
            return False
        prefs.append((len(src), PreferenceFunction(p.kind, tuple(p.coefficients))))
        row(a, b, to_ticks(p.domain.lb, 1000), to_ticks(p.domain.ub, 1000))
    rows = Rows(len(names) + 1, np.array(src, dtype=np.int64), np.array(dst, dtype=np.int64),
                np.array(lbs, dtype=np.float64), np.array(ubs, dtype=np.float64), tuple(prefs))
    try:
        result = compile_rows(rows, ticks_per_second=1000)
    except HrcError:
        return False
    if not result.consistent or result.do_lb is None or result.do_ub is None:
        return False
    events = {residual_origin(stnu): 0}
    events.update(index)
    return events, rows_apsp(rows, result.do_lb, result.do_ub)


def _in_order(entry: PlanEntry, history: History, moved: dict[str, int],
              times: dict[tuple[str, str, str, str], tuple[int, int]], side: int) -> None:
    """One reading of `_estimates` (`side` 0: each seen event as early as it may have been, 1: as late) kept
    in each person's own order: an event read early is not before the one they reported before it, one read
    late not after the one they reported after it; and the events of a leg nobody reported (a start pressed
    without its walk: `hrc.dispatch.validation.executed` puts them at the next reported event's time) read
    with the reported one after them, as the C core derives them from the same reading. Else a start read
    0.5 s before its press came before its own unreported arrival, or before a departure told to be on
    time (found by fuzz/targets.py ``crew_history``; the Python reading and the core's differed)."""
    for agent in dict.fromkeys(key[0] for key in times):
        seq = [((agent, action, phase, ev), node) for action, phase in history.legs.get(agent, ())
               for ev, node in entry.leg_points[(agent, action, phase)]
               if (agent, action, phase, ev) in history.times and node in moved]
        bound: int | None = None
        for key, node in (seq if side == 0 else reversed(seq)):
            t = moved[node]
            if key in times and bound is not None:
                t = max(t, bound) if side == 0 else min(t, bound)
                moved[node] = t
                times[key] = (t, t)
            bound = t if bound is None else max(bound, t) if side == 0 else min(bound, t)
        for key, node in seq:
            if key in times:
                _pending_at(entry, history, key, moved, moved[node])


def _pending_at(entry: PlanEntry, history: History, key: tuple[str, str, str, str], moved: dict[str, int],
                t: int) -> None:
    """In `moved`, the events of `key`'s leg before it that nobody reported, at `t` (`_in_order`)."""
    agent, action, phase, event = key
    points = entry.leg_points[(agent, action, phase)]
    at = next(i for i, (ev, _) in enumerate(points) if ev == event)
    for ev, node in reversed(points[:at]):
        if (agent, action, phase, ev) in history.times:
            return
        moved[node] = t


def _past(form: _DOForm, done: dict[str, int]) -> tuple[np.ndarray, np.ndarray]:
    """The index in the DO form and the tick of its origin and of every executed timepoint in it."""
    events = form[0]
    at, times = [0], [0]
    for x, t in done.items():
        k = events.get(x)
        if k is not None:
            at.append(k)
            times.append(t)
    return np.array(at, dtype=np.int64), np.array(times, dtype=np.int64)


def _within(form: _DOForm, done: dict[str, int],
            past: tuple[np.ndarray, np.ndarray] | None = None) -> bool:
    """Whether what happened keeps to the DO form (every pair of executed timepoints within its bounds,
    to the tick): otherwise the optimal policy was left and APA compiles again (Fig. 8, line 7). `past`:
    `_past` of the two, when the caller has it."""
    at, times = _past(form, done) if past is None else past
    apart = times[None, :] - times[:, None]  # [i, j]: T(j) - T(i)
    ok = apart <= form[1][at[:, None], at] + 1
    ok.flat[::len(at) + 1] = True  # the diagonal (`np.fill_diagonal`'s own step, without its checks)
    return bool(ok.all())


def _validated_by(history: History) -> tuple:
    """What set validation reads of a history (`agreeing`): each agent's legs, the announced next
    actions, whether the human is away."""
    return (tuple(history.legs.items()), tuple(sorted(history.announced.items())), history.absent)


def _seen_after(state: _State, history: History, obs: Observation) -> tuple[np.ndarray, np.ndarray]:
    """`seen_arrays` of `history`, which is `state`'s with `obs` added: `state`'s arrays, with the cell of
    a leg event set (its agent's leg position: the last of its legs, or the one it names)."""
    if obs.event not in LEG_EVENTS:
        return state.seen, state.legs_seen
    agent = obs.agent or ""
    g = history.task.agent_ids.index(agent)
    legs = history.legs[agent]
    k = legs.index((obs.action, obs.phase))
    seen, legs_seen = state.seen.copy(), state.legs_seen.copy()
    seen[g, k, LEG_EVENTS.index(obs.event)] = ticks(obs.t)
    legs_seen[g] = len(legs)
    return seen, legs_seen


def _rank(mode: ExecutionMode) -> int:
    return {ExecutionMode.DC: 0, ExecutionMode.STN: 1, ExecutionMode.EARLIEST: 2}[mode]


def _human(task: Task) -> str:
    return next((a.id for a in task.agents if a.is_human), "")


def _present(history: History) -> History:
    from dataclasses import replace

    return replace(history, away=False, gone=frozenset())


def _describe(obs: Observation) -> str:
    if obs.action is None:
        return obs.event
    return f"{obs.agent} {obs.action}.{obs.phase} {obs.event}" + (f" (next {obs.next})" if obs.next else "")

