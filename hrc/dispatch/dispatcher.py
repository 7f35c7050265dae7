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

Nothing here reads a clock: time comes in with the messages, so a run replays from its log to the same
decisions. A refused message raises `DispatchError` and leaves the dispatcher as it was.
"""

from __future__ import annotations

import copy
import os
from collections.abc import Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Literal

from hrc.errors import DispatchError, HrcError
from hrc.model import Task
from hrc.temporal import ExecutionMode, ExecutionWindow, real_time_state

from .messages import LEG_EVENTS, Candidate, Decision, HumanOption, Observation, RobotStep, WaitFor
from .plan_set import EventKey, PlanEntry, PlanSet, load_plan_set, plan_set_from_compiled
from .ranking import Evaluation, evaluate, rank_key, schedule
from .validation import History, agrees, executed, ticks

__all__ = ["UNDO_SECONDS", "Dispatcher"]

UNDO_SECONDS = 10.0
"""How long after a human observation it may still be withdrawn with ``undo``."""

_MODES = {"DC": ExecutionMode.DC, "consistent": ExecutionMode.STN, "inconsistent": ExecutionMode.EARLIEST}


@dataclass(frozen=True, slots=True)
class _State:
    """Everything a message changes, replaced whole when a message is accepted."""

    history: History
    accepted: tuple[Observation, ...]  # every accepted message, undo included (the log's order)
    effective: tuple[Observation, ...]  # the observations that stand (withdrawn ones removed)
    ranked: tuple[int, ...]  # indices into the plan set, best first
    evaluations: MappingProxyType  # index -> (key, Evaluation)
    decision: Decision
    do_forms: MappingProxyType  # plan index -> APA's DO form of the plan (`_do_form`), or False


class Dispatcher:
    """A state machine over a compiled plan set: `observe` a message, get a `Decision`.

    Build with `from_folder` (an `hrc compile` output folder) or `from_compiled` (in memory).
    `feasible_only` drops plans that are not DC or consistent; when none is left the robot is told
    nothing more (``Decision.stopped``), as Chaski-style dispatchers do (for comparisons).
    `use_preferences`: where the task has preferences, the robot's window is narrowed to APA's DO window
    (`_preferred`), at the cost of one small QP per decision.
    """

    def __init__(self, plan_set: PlanSet, *, feasible_only: bool = False, use_preferences: bool = True) -> None:
        self.plan_set = plan_set
        self.feasible_only = feasible_only
        self.use_preferences = use_preferences
        human = _human(plan_set.task)
        self._human_nodes = [frozenset(n for n, ev in e.events.items() if ev[0] == human) for e in plan_set.plans]
        self._robot_nodes = [frozenset(n for n, ev in e.events.items() if ev[0] != human) for e in plan_set.plans]
        history = History.start(plan_set.task)
        self._state = self._settle(history, (), (), tuple(range(len(plan_set.plans))), {}, {})

    @classmethod
    def from_folder(cls, out_dir: str | os.PathLike[str], **options: Any) -> Dispatcher:
        """Load an `hrc compile` output folder (raises `hrc.errors.InputError` naming the file at fault)."""
        return cls(load_plan_set(out_dir), **options)

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
    def candidates(self) -> tuple[Candidate, ...]:
        """The remaining plans, ranked best first."""
        out = []
        for i in self._state.ranked:
            entry, ev = self.plan_set.plans[i], self._state.evaluations[i][1]
            out.append(Candidate(entry.id, ev.plan_class, None if ev.finish is None else ev.finish / 1000,
                                 ev.idle / 1000, entry.preference, MappingProxyType(dict(entry.plan.allocation)),
                                 MappingProxyType(dict(entry.plan.sequences))))
        return tuple(out)

    def human_options(self) -> tuple[HumanOption, ...]:
        """Leg events the human may report now that the task and some remaining plan allow, in task order
        (a console's buttons): the next event of the leg under way, or the start of a next leg."""
        history = self._state.history
        human = history.human
        if not human or history.away:
            return ()
        found: set[tuple[str, str, str]] = set()
        for i in self._state.ranked:
            entry = self.plan_set.plans[i]
            for obs in self._next_events(entry, human, history):
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
        index = self._state.ranked[0] if plan_id is None else next(
            i for i, e in enumerate(self.plan_set.plans) if e.id == plan_id)
        entry = self.plan_set.plans[index]
        history = self._state.history
        done = executed(entry, history)
        from hrc.temporal import residual_network

        found = schedule(residual_network(entry.stnu, done, ticks(history.now)), self.plan_set.rank_by) or {}
        out: dict[EventKey, float] = {}
        for node, key in entry.events.items():
            if key in history.times:
                out[key] = history.times[key]
            elif node in done:
                out[key] = done[node] / 1000
            elif node in found:
                out[key] = found[node] / 1000
        return out

    # ------------------------------------------------------------------ the cycle
    def observe(self, obs: Observation) -> Decision:
        """Take one message; the new `Decision`. Raises `DispatchError` (state unchanged) when refused."""
        state = self._state
        if obs.event == "undo":
            return self._undo(obs)
        history = state.history.add(obs)
        plans = self.plan_set.plans
        if obs.event == "tick":
            kept: tuple[int, ...] = state.ranked
        else:  # "back" brings back every plan that agrees with the history
            pool: Sequence[int] = range(len(plans)) if obs.event == "back" else state.ranked
            kept = tuple(i for i in pool if agrees(plans[i], history))
            if not kept and history.away:
                # no plan lets the robot finish alone from here (say it is on its way to a leg that needs
                # the person's work first): "away" is a fact, not a request, and so is what the robot does
                # meanwhile; it goes on with the plans that agree with what was seen, and waits for the
                # person where they need them (refusing its own arrival left it standing for good)
                kept = tuple(i for i in pool if agrees(plans[i], _present(history)))
        if not kept:
            raise DispatchError(f"no remaining plan allows {_describe(obs)} "
                                f"({len(state.ranked)} plans agreed with what was seen before)")
        self._state = self._settle(history, (*state.accepted, obs), (*state.effective, obs), kept,
                                   state.evaluations, state.do_forms)
        return self._state.decision

    def _undo(self, obs: Observation) -> Decision:
        state = self._state
        if obs.t < state.history.now:
            raise DispatchError(f"time goes backwards: t = {obs.t:g} s is before the last message "
                                f"({state.history.now:g} s)")
        human = state.history.human
        last = next((k for k in range(len(state.effective) - 1, -1, -1) if state.effective[k].event != "tick"),
                    None)  # the last observation that is not a tick: only ticks may follow the one withdrawn
        if last is None or state.effective[last].agent not in (human, None):
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
        kept = tuple(i for i in range(len(self.plan_set.plans)) if agrees(self.plan_set.plans[i], history))
        self._state = self._settle(history, (*state.accepted, obs), effective, kept, state.evaluations,
                                   state.do_forms)
        return self._state.decision

    def _settle(self, history: History, accepted: tuple[Observation, ...], effective: tuple[Observation, ...],
                kept: Sequence[int], previous: Any, do_forms: Any) -> _State:
        """Rank `kept` under `history` (re-checking only plans whose evaluation inputs changed), decide."""
        plans = self.plan_set.plans
        now = ticks(history.now)
        evaluations: dict[int, tuple[Any, Evaluation]] = {}
        done_of: dict[int, dict[str, int]] = {}
        for i in kept:
            done = executed(plans[i], history)
            done_of[i] = done
            finished = len(done) == len(plans[i].stnu.timepoints)
            key = (done, None if finished else now)  # what enters its residual network
            old = previous.get(i)
            if old is not None and old[0] == key:
                evaluations[i] = old
            else:
                evaluations[i] = (key, evaluate(plans[i], done, now, self.plan_set.rank_by))
        if self.feasible_only:
            kept = [i for i in kept if evaluations[i][1].plan_class != "inconsistent"]
        ranked = tuple(sorted(kept, key=lambda i: rank_key(plans[i], evaluations[i][1])))
        counts = {"DC": 0, "consistent": 0, "inconsistent": 0}
        for i in ranked:
            counts[evaluations[i][1].plan_class] += 1
        if not ranked:
            decision = Decision(history.now, None, None, MappingProxyType(counts), None, history.away, True)
        else:
            best = ranked[0]
            do = dict(do_forms)
            robot, human = self._steps(plans[best], done_of[best], history, evaluations[best][1].plan_class, best,
                                       do)
            do_forms = MappingProxyType(do)
            decision = Decision(history.now, plans[best].id, evaluations[best][1].plan_class,
                                MappingProxyType(counts), robot, history.away, False, human)
        return _State(history, accepted, effective, ranked, MappingProxyType(evaluations), decision,
                      MappingProxyType(dict(do_forms)))

    def _steps(self, entry: PlanEntry, done: dict[str, int], history: History, plan_class: str,
               index: int, do: dict[int, Any]) -> tuple[RobotStep | WaitFor | None, RobotStep | WaitFor | None]:
        """The robot's next step in `entry` (module docstring) and the human's hint (`Decision.human`)."""
        robot = next((a.id for a in self.task.agents if not a.is_human), "")
        human = history.human
        now = ticks(history.now)
        state = None
        mode = _MODES[plan_class]
        out: list[RobotStep | WaitFor | None] = []
        contingent = entry.stnu.contingent_timepoints
        for agent, other_nodes in ((robot, self._human_nodes[index]), (human, self._robot_nodes[index])):
            nxt = next(((action, phase, event, node) for action, phase in entry.legs.get(agent, ())
                        for event, node in entry.leg_points[(agent, action, phase)] if node not in done), None)
            if nxt is None or nxt[3] in contingent or (agent == human and history.away):
                out.append(None)
                continue
            action, phase, event, node = nxt
            arrival = self._arrival(entry, agent, action, phase, event, node, done, now)
            if arrival is not None:  # under way: it gets there when its drive says
                out.append(arrival)
                continue
            if state is None:
                state = real_time_state(entry.stnu, done, now)
                if _rank(state.default_mode()) > _rank(mode):  # the two DC checks disagree: the stricter reading
                    mode = state.default_mode()
            uncontrolled = [n for n in other_nodes if n not in done and n not in contingent]
            step = state.step(node, mode, uncontrolled=uncontrolled)
            if isinstance(step, ExecutionWindow):
                latest = None if step.latest is None or mode is ExecutionMode.EARLIEST else step.latest / 1000
                found = RobotStep(action, phase, event, step.earliest / 1000, latest)
                if agent == robot and mode is not ExecutionMode.EARLIEST and self.use_preferences:
                    found = self._preferred(entry, index, do, state.residual, done, now, node, found)
                out.append(found)
                continue
            waits = sorted(step.until, key=lambda n: (entry.events.get(n, ("",))[0] == agent, n))
            w_agent, w_action, w_phase, w_event = entry.events.get(waits[0], ("", "", "", waits[0]))
            out.append(WaitFor(w_agent, w_action, w_phase, w_event))
        return out[0], out[1]

    def _preferred(self, entry: PlanEntry, index: int, do: dict[int, Any], residual: Any, done: dict[str, int],
                   now: int, node: str, step: RobotStep) -> RobotStep:
        """`step` narrowed to the DO window of its timepoint where the two meet (Wilcox, Nikolaidis & Shah
        2012): the plan's DO form (Fig. 5, APA on its residual network read as an STP with the task's
        preferences) dispatched by propagation from what has happened, and compiled again (Fig. 8, line 7)
        when what happened left it. As it was when the task has no preferences, the plan keeps none, or
        the two windows do not meet: the class's promise comes first."""
        task = self.task
        if not task.preferences:
            return step
        form = do.get(index)
        if form is None or (form is not False and not _within(form, done)):
            form = do[index] = _do_form(entry, residual, task.preferences)
        if form is False:
            return step
        events, apsp = form
        past = _past(form, done)
        i = events[node]
        lo = max(t - apsp[i, j] for j, t in past)
        hi = min(t + apsp[j, i] for j, t in past)
        earliest = max(step.earliest, round(max(lo, now) / 1000, 3))
        latest = step.latest
        if hi != float("inf"):
            latest = round(hi / 1000, 3) if latest is None else min(latest, round(hi / 1000, 3))
        if latest is not None and latest < earliest:
            return step
        return RobotStep(step.action, step.phase, step.event, earliest, latest)

    @staticmethod
    def _arrival(entry: PlanEntry, agent: str, action: str, phase: str, event: str, node: str,
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
        lo, hi = 0, None
        for r in entry.stnu.requirements:
            if (r.source, r.target) == (prev, node):
                lo = max(lo, r.lb or 0)
                hi = r.ub if hi is None or (r.ub is not None and r.ub < hi) else hi
            elif (r.source, r.target) == (node, prev):
                if r.ub is not None:
                    lo = max(lo, -r.ub)
                if r.lb is not None:
                    hi = -r.lb if hi is None else min(hi, -r.lb)
        start = done[prev]
        earliest = max(now, start + lo)
        latest = None if hi is None else max(earliest, start + hi)
        return RobotStep(action, phase, event, earliest / 1000, None if latest is None else latest / 1000)

    @staticmethod
    def _next_events(entry: PlanEntry, agent: str, history: History) -> list[Observation]:
        """The events `agent` could report next in `entry`: later events of its leg under way, or the
        events of its next leg (start included: depart and arrive may go unreported)."""
        seen = history.legs.get(agent, ())
        legs = entry.legs[agent]
        current = history.current(agent)
        t = history.now
        if current is not None:
            last = history.last_event(agent, *current)
            order = LEG_EVENTS.index(last) if last else -1
            events = [e for e, _ in entry.leg_points[(agent, *current)] if LEG_EVENTS.index(e) > order]
            if "start" in events:
                events = events[:events.index("start") + 1]
            else:
                events = events[:1]
            return [Observation(t, e, agent, current[0], current[1]) for e in events]
        if len(seen) >= len(legs):
            return []
        action, phase = legs[len(seen)]
        return [Observation(t, e, agent, action, phase) for e in ("depart", "start")]


_DOForm = tuple[dict[str, int], Any]  # event -> index, the DO form's APSP matrix (ticks); index 0: its origin


def _do_form(entry: PlanEntry, residual: Any, preferences: Any) -> _DOForm | Literal[False]:
    """APA's DO form of the plan's residual network (its event index and APSP matrix in ticks, the
    residual's origin, at the task's start, first), or False when the plan can keep no preferred interval."""
    from hrc.apa.compile import do_apsp
    from hrc.apa.plan import plan_preference_value  # the QP solver only where preferences are used
    from hrc.compile.temporal_net_creator import event_timepoint
    from hrc.temporal.graphml import tool_name

    prefs = [(tool_name(event_timepoint(entry.plan, p.source)), tool_name(event_timepoint(entry.plan, p.target)), p)
             for p in preferences]
    try:
        result = plan_preference_value(residual, prefs)
    except HrcError:
        return False
    if not result.consistent:
        return False
    return {e: k for k, e in enumerate(result.stpp.events)}, do_apsp(result)


def _past(form: _DOForm, done: dict[str, int]) -> list[tuple[int, int]]:
    """``(index in the DO form, tick)`` of its origin and of every executed timepoint."""
    events = form[0]
    return [(0, 0)] + [(events[x], t) for x, t in done.items() if x in events]


def _within(form: _DOForm, done: dict[str, int]) -> bool:
    """Whether what happened keeps to the DO form (every pair of executed timepoints within its bounds,
    to the tick): otherwise the optimal policy was left and APA compiles again (Fig. 8, line 7)."""
    apsp = form[1]
    past = _past(form, done)
    return all(t2 - t1 <= apsp[i, j] + 1 for i, t1 in past for j, t2 in past if i != j)


def _rank(mode: ExecutionMode) -> int:
    return {ExecutionMode.DC: 0, ExecutionMode.STN: 1, ExecutionMode.EARLIEST: 2}[mode]


def _human(task: Task) -> str:
    return next((a.id for a in task.agents if a.is_human), "")


def _present(history: History) -> History:
    from dataclasses import replace

    return replace(history, away=False)


def _describe(obs: Observation) -> str:
    if obs.action is None:
        return obs.event
    return f"{obs.agent} {obs.action}.{obs.phase} {obs.event}" + (f" (next {obs.next})" if obs.next else "")

