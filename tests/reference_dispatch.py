"""The dispatcher by its definitions, plan by plan, for the tests: the oracle `hrc.dispatch.Dispatcher` is
compared with on every message.

It reads an output folder the way the dispatcher read it before the dispatch form existed: ``compiled.json``
and every plan's GraphML file (or ``stnu.zip`` member), parsed into `STNU` values, independently of the
form's arrays. Each message then runs the paper's cycle on those objects, one plan at a time:

- set validation: `agrees` on every plan of the pool (the plans left, every plan on ``back``/``undo``),
  then each leg seen on its route (`route_signature` of the plan's STNU): the route of the plan that was
  best when the leg began, if that plan gives the agent the leg there; a stop at a waiting place where the
  agent was seen stopping; all of it dropped if no plan is left;
- set ranking: `reference_evaluate` (the residual network's DC check and earliest schedule) of every plan
  left, sorted by class, then (while a DC plan keeps the person's sequence of the last best plan) DC
  plans that keep it before DC plans that do not, then the rest of `rank_key`;
- the decision: `real_time_state` (the residual network, the bypass DC check, full propagation in Python)
  for the best plan's next robot and human events, and APA's DO form compiled on the residual network
  through `plan_preference_value` (objects, `Fraction` conversions and all) where the task has preferences.

APA's DO form is compiled on the dispatch form's network of the plan (`apa_entry`), the same distance
graph as the GraphML file's (tests/test_dispatch_fastnet.py) in the rows the dispatcher hands APA: where
a preference leaves the optimum free (a linear one), an interior-point solver's choice on the optimal
face depends on how the constraints are written, and either choice is a DO form.

It is slow on purpose (no arrays, no C, no sharing between plans): what it computes is easy to check
against the definitions in docs/dispatch.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

from hrc.compile.output import iter_plans, load_compiled_task, read_header
from hrc.dispatch import UNDO_SECONDS
from hrc.dispatch.dispatcher import _rank
from hrc.dispatch.messages import (
    LEG_EVENTS,
    Ahead,
    Candidate,
    Decision,
    HumanOption,
    Observation,
    RobotStep,
    WaitFor,
    ack_note,
)
from hrc.dispatch.plan_set import PlanEntry, _Archive, plan_entry
from hrc.dispatch.ranking import rank_key, reference_evaluate
from hrc.dispatch.validation import History, agrees, executed, route_signature, ticks
from hrc.errors import DispatchError, HrcError
from hrc.model import Plan
from hrc.temporal import ExecutionMode, ExecutionWindow, real_time_state, residual_network
from hrc.temporal.graphml import read_network

_MODES = {"DC": ExecutionMode.DC, "consistent": ExecutionMode.STN, "inconsistent": ExecutionMode.EARLIEST}


def read_entries(folder: str | Path) -> tuple[Any, list[PlanEntry], str]:
    """The task, every plan's `PlanEntry` from ``compiled.json`` and the GraphML files, and ``rank_by``."""
    folder = Path(folder)
    task = load_compiled_task(folder)
    data = read_header(folder)  # the plans' full entries: from compiled.json or plans.jsonl (iter_plans)
    archive = (_Archive(folder, str(folder / "compiled.json"), data.get("stnu_archive", "stnu.zip"))
               if data.get("stnu_files") == "archive" else None)
    entries = []
    for i, p in enumerate(iter_plans(folder)):
        plan = Plan(tuple((a.id, p["allocation"][a.id]) for a in task.actions),
                    tuple((g.id, tuple(p["sequences"][g.id])) for g in task.agents))
        stnu = archive.read(p["stnu"], f"plans[{i}]") if archive else read_network(folder / p["stnu"])
        blocked = p["pattern"]["candidates"] == 0
        entries.append(plan_entry(task, plan, p["rank"], p["class"], p["preference"], stnu, p["stnu"], blocked))
    return task, entries, data["options"]["rank_by"]


class ReferenceDispatcher:
    """`hrc.dispatch.Dispatcher`'s behaviour from its definitions (the module docstring); `observe` as
    there, so `hrc.dispatch.protocol.handle_line` drives it too."""

    def __init__(self, task: Any, plans: Sequence[PlanEntry], rank_by: str, *, feasible_only: bool = False,
                 use_preferences: bool = True, memo: dict | None = None, apa_entry: Any = None,
                 max_observation_delay: float | None = None) -> None:
        self.task, self.plans, self.rank_by = task, list(plans), rank_by
        self.apa_entry = apa_entry or (lambda i: self.plans[i])
        self.memo = {} if memo is None else memo  # (plan, executed, now) -> evaluation: runs share their start
        self.feasible_only, self.use_preferences = feasible_only, use_preferences
        self.max_observation_delay = max_observation_delay
        self.told: dict[tuple[str, int], tuple[int, int, int]] = {}  # (agent, leg position) -> route told
        self.best: int | None = None  # the plan of the last answer
        self.history = History.start(task)
        self.effective: tuple[Observation, ...] = ()
        self.accepted: tuple[Observation, ...] = ()  # every accepted message (the protocol's tick gap reads it)
        self.ranked: list[int] = []
        self.evals: dict[int, Any] = {}
        self.do_forms: dict[int, Any] = {}
        self.decision = self._settle(self.history, list(range(len(self.plans))))

    # --------------------------------------------------------------------------------- the cycle
    def observe(self, obs: Observation) -> Decision:
        if obs.event == "undo":
            return self._undo(obs)
        history = self.history.add(obs)
        if obs.event == "tick":
            kept = list(self.ranked)
        else:
            pool = range(len(self.plans)) if obs.event == "back" else self.ranked
            kept = [i for i in pool if agrees(self.plans[i], history)]
            if not kept and history.away:
                kept = [i for i in pool if agrees(self.plans[i], replace(history, away=False))]
        told = dict(self.told)
        if obs.event in LEG_EVENTS and kept:
            agent = obs.agent or ""
            k = history.legs[agent].index((obs.action, obs.phase))
            if (agent, k) not in told and self.best is not None:
                legs = self.plans[self.best].legs.get(agent, ())
                if k < len(legs) and legs[k] == (obs.action, obs.phase):
                    told[(agent, k)] = route_signature(self.plans[self.best], agent, obs.action, obs.phase)
        if kept and obs.event in (*LEG_EVENTS, "back"):
            kept = self._on_routes(kept, history, told)
        if not kept:
            what = obs.event if obs.action is None else \
                f"{obs.agent} {obs.action}.{obs.phase} {obs.event}" + (f" (next {obs.next})" if obs.next else "")
            raise DispatchError(f"no remaining plan allows {what} ({len(self.ranked)} plans agreed with what was "
                                "seen before)")
        robot = next(a.id for a in self.task.agents if not a.is_human)
        ack = ack_note(self.decision.robot, obs) if obs.agent == robot and obs.event in LEG_EVENTS else None
        self.effective = (*self.effective, obs)
        self.accepted = (*self.accepted, obs)
        self.told = told
        late = None
        limit = self.max_observation_delay
        if limit is not None and obs.delay is not None and obs.agent == history.human and obs.delay > limit:
            late = MappingProxyType({"late": {"event": f"{obs.agent}.{obs.action}.{obs.phase}.{obs.event}",
                                              "delay": round(obs.delay, 3), "max": limit}})
        self.decision = replace(self._settle(history, kept, follow=late is None), ack=ack, deviation=late)
        return self.decision

    def _on_routes(self, kept: list[int], history: History, told: dict) -> list[int]:
        out = kept
        for agent, legs in history.legs.items():
            for k, (action, phase) in enumerate(legs):
                sig = told.get((agent, k))
                parked = (agent, action, phase, "park") in history.times
                if sig is None and not parked:
                    continue
                if parked and (sig is None or sig[0] == 0):
                    out = [i for i in out if route_signature(self.plans[i], agent, action, phase)[0] == 1]
                else:
                    out = [i for i in out if route_signature(self.plans[i], agent, action, phase) == sig]
        return out if out else kept

    def _undo(self, obs: Observation) -> Decision:
        if obs.t < self.history.now:
            raise DispatchError(f"time goes backwards: t = {obs.t:g} s is before the last message "
                                f"({self.history.now:g} s)")
        human = self.history.human
        last = next((k for k in range(len(self.effective) - 1, -1, -1) if self.effective[k].event != "tick"), None)
        if last is None or self.effective[last].agent not in (human, None):
            raise DispatchError("nothing to undo: the last observation is not the human's")
        target = self.effective[last]
        if obs.t - target.t > UNDO_SECONDS:
            raise DispatchError(f"too late to undo: the last human observation was {obs.t - target.t:g} s ago "
                                f"(at most {UNDO_SECONDS:g} s)")
        effective = self.effective[:last] + self.effective[last + 1:]
        history = History.start(self.task)
        for o in effective:
            history = history.add(o)
        history = history.add(Observation(obs.t, "tick"))
        kept = [i for i in range(len(self.plans)) if agrees(self.plans[i], history)]
        self.told = {(a, k): sig for (a, k), sig in self.told.items() if k < len(history.legs.get(a, ()))}
        kept = self._on_routes(kept, history, self.told)
        self.effective = effective
        self.accepted = (*self.accepted, obs)
        self.decision = self._settle(history, kept)
        return self.decision

    def _settle(self, history: History, kept: list[int], follow: bool = True) -> Decision:
        now = ticks(history.now)
        evals = {i: self._evaluate(i, history, now) for i in kept}
        if self.feasible_only:
            kept = [i for i in kept if evals[i].plan_class != "inconsistent"]
        gives_up = {i: 0 for i in kept}
        if follow and self.best is not None:  # the person's part of the plan followed keeps its hold
            human = history.human
            shown = self.plans[self.best].plan.sequence(human)
            dc = [i for i in kept if evals[i].plan_class == "DC"]
            same = {i for i in dc if self.plans[i].plan.sequence(human) == shown}
            if same:
                gives_up = {i: int(i in dc and i not in same) for i in kept}
        ranked = sorted(kept, key=lambda i: (rank_key(self.plans[i], evals[i])[0], gives_up[i],
                                             *rank_key(self.plans[i], evals[i])[1:]))
        counts = {"DC": 0, "consistent": 0, "inconsistent": 0}
        for i in ranked:
            counts[evals[i].plan_class] += 1
        self.history, self.ranked, self.evals = history, ranked, evals
        if not ranked:
            self.best = None
            return Decision(history.now, None, None, MappingProxyType(counts), None, history.away, True)
        best = self.best = ranked[0]
        entry = self.plans[best]
        done = executed(entry, history)
        robot, human = self._steps(entry, done, history, evals[best].plan_class, best)
        ahead = _ahead(entry, done, history) if human is None else None
        return Decision(history.now, entry.id, evals[best].plan_class, MappingProxyType(counts), robot,
                        history.away, False, human, ahead=ahead)

    def _evaluate(self, i: int, history: History, now: int) -> Any:
        done = executed(self.plans[i], history)
        key = (i, frozenset(done.items()), now)
        found = self.memo.get(key)
        if found is None:
            found = self.memo[key] = reference_evaluate(self.plans[i], done, now, self.rank_by)
            if len(self.memo) > 200_000:
                self.memo.clear()
        return found

    def _steps(self, entry: PlanEntry, done: dict[str, int], history: History, plan_class: str, index: int) -> tuple:
        robot = next(a.id for a in self.task.agents if not a.is_human)
        human = history.human
        now = ticks(history.now)
        state = None
        mode = _MODES[plan_class]
        out: list[Any] = []
        contingent = entry.stnu.contingent_timepoints
        human_nodes = {n for n, ev in entry.events.items() if ev[0] == human}
        robot_nodes = set(entry.events) - human_nodes
        for agent, other in ((robot, human_nodes), (human, robot_nodes)):
            nxt = next(((a, p, e, n) for a, p in entry.legs.get(agent, ()) for e, n in entry.leg_points[(agent, a, p)]
                        if n not in done), None)
            if nxt is None or nxt[3] in contingent or (agent == human and history.away):
                out.append(None)
                continue
            action, phase, event, node = nxt
            arrival = _arrival(entry, agent, action, phase, event, node, done, now)
            if arrival is not None:
                out.append(arrival)
                continue
            if state is None:
                state = real_time_state(entry.stnu, done, now)
                if _rank(state.default_mode()) > _rank(mode):
                    mode = state.default_mode()
            step = state.step(node, mode, uncontrolled=[n for n in other if n not in done and n not in contingent])
            if isinstance(step, ExecutionWindow):
                latest = None if step.latest is None or mode is ExecutionMode.EARLIEST else step.latest / 1000
                found = RobotStep(action, phase, event, step.earliest / 1000, latest)
                if agent == robot and mode is not ExecutionMode.EARLIEST and self.use_preferences:
                    found = self._preferred(index, history, now, node, found)
                out.append(found)
                continue
            waits = sorted(step.until, key=lambda n: (entry.events.get(n, ("",))[0] == agent, n))
            out.append(WaitFor(*entry.events.get(waits[0], ("", "", "", waits[0]))))
        return out[0], out[1]

    def _preferred(self, index: int, history: History, now: int, node: str, step: RobotStep) -> RobotStep:
        if not self.task.preferences:
            return step
        entry = self.apa_entry(index)
        done = executed(entry, history)
        form = self.do_forms.get(index)
        if form is None or (form is not False and not _within(form, done)):
            residual = residual_network(entry.stnu, done, now)
            form = self.do_forms[index] = _do_form(entry, residual, self.task.preferences)
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

    # --------------------------------------------------------------------------------- views
    @property
    def now(self) -> float:
        return self.history.now

    @property
    def candidates(self) -> tuple[Candidate, ...]:
        out = []
        for i in self.ranked:
            e, ev = self.plans[i], self.evals[i]
            out.append(Candidate(e.id, ev.plan_class, None if ev.finish is None else ev.finish / 1000, ev.idle / 1000,
                                 e.preference, MappingProxyType(dict(e.plan.allocation)),
                                 MappingProxyType(dict(e.plan.sequences))))
        return tuple(out)

    def human_options(self) -> tuple[HumanOption, ...]:
        history = self.history
        human = history.human
        if not human or history.away:
            return ()
        found = set()
        for i in self.ranked:
            for obs in _next_events(self.plans[i], human, history):
                try:
                    history.add(obs)
                except DispatchError:
                    continue
                found.add((obs.action, obs.phase, obs.event))
        order = {(a.id, p.id): k for k, (a, p) in enumerate((a, p) for a in self.task.actions for p in a.phases)}
        ordered = sorted(found, key=lambda f: (order[(f[0], f[1])], LEG_EVENTS.index(f[2])))
        return tuple(HumanOption(*f) for f in ordered)

    def planned_times(self, plan_id: str | None = None) -> dict:
        index = self.ranked[0] if plan_id is None else next(i for i, e in enumerate(self.plans) if e.id == plan_id)
        entry = self.plans[index]
        history = self.history
        done = executed(entry, history)
        from hrc.dispatch.ranking import schedule

        found = schedule(residual_network(entry.stnu, done, ticks(history.now)), self.rank_by) or {}
        out = {}
        for node, key in entry.events.items():
            if key in history.times:
                out[key] = history.times[key]
            elif node in done:
                out[key] = done[node] / 1000
            elif node in found:
                out[key] = found[node] / 1000
        return out


def _do_form(entry: PlanEntry, residual: Any, preferences: Any) -> Any:
    """APA's DO form of the residual network: its event index and APSP matrix, or False."""
    from hrc.apa.compile import do_apsp
    from hrc.apa.plan import plan_preference_value
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


def _past(form: Any, done: dict[str, int]) -> list[tuple[int, int]]:
    events = form[0]
    return [(0, 0)] + [(events[x], t) for x, t in done.items() if x in events]


def _within(form: Any, done: dict[str, int]) -> bool:
    apsp = form[1]
    past = _past(form, done)
    return all(t2 - t1 <= apsp[i, j] + 1 for i, t1 in past for j, t2 in past if i != j)


def _arrival(entry: PlanEntry, agent: str, action: str, phase: str, event: str, node: str, done: dict[str, int],
             now: int) -> RobotStep | None:
    if event not in ("arrive", "park"):
        return None
    names = [n for _, n in entry.leg_points[(agent, action, phase)]]
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


def _next_events(entry: PlanEntry, agent: str, history: History) -> list[Observation]:
    seen = history.legs.get(agent, ())
    legs = entry.legs[agent]
    current = history.current(agent)
    t = history.now
    if current is not None:
        last = history.last_event(agent, *current)
        order = LEG_EVENTS.index(last) if last else -1
        events = [e for e, _ in entry.leg_points[(agent, *current)] if LEG_EVENTS.index(e) > order]
        events = events[:events.index("start") + 1] if "start" in events else events[:1]
        return [Observation(t, e, agent, current[0], current[1]) for e in events]
    if len(seen) >= len(legs):
        return []
    action, phase = legs[len(seen)]
    return [Observation(t, e, agent, action, phase) for e in ("depart", "start")]


def _ahead(entry: PlanEntry, done: dict[str, int], history: History) -> Ahead | None:
    """The person's next own step after the event of theirs now due (nature's), and the robot's last
    event not done whose distance from that step (from any step of the stay it begins, when it is a
    departure for a leg without a walk) in the STN reading (requirement links both ways,
    contingent links at their bounds) is at most 0: Bellman-Ford over the link objects, by name; when
    there is none, the done robot event at that distance whose time plus the gap is latest, if after now."""
    human = history.human
    if not human or history.away:
        return None
    stnu = entry.stnu
    contingent = stnu.contingent_timepoints
    pending = [(a, p, e, n) for a, p in entry.legs.get(human, ()) for e, n in entry.leg_points[(human, a, p)]
               if n not in done]
    if not pending or pending[0][3] not in contingent:
        return None
    at_step = next((k for k, x in enumerate(pending) if x[3] not in contingent), None)
    if at_step is None:
        return None
    step = pending[at_step]
    # a departure for a leg without a walk: the stay there (those legs and their work, up to the walk away)
    # is bound as one, from each of its own steps (issue 32)
    sources = [step[3]]
    if step[2] == "depart" and at_step + 1 < len(pending) and pending[at_step + 1][3] not in contingent:
        for x in pending[at_step + 1:]:
            if x[3] in contingent and x[2] == "arrive":
                break
            if x[3] not in contingent:
                sources.append(x[3])
    arcs = []  # (u, v, w): T(v) - T(u) <= w
    for r in stnu.requirements:
        if r.ub is not None:
            arcs.append((r.source, r.target, r.ub))
        if r.lb is not None:
            arcs.append((r.target, r.source, -r.lb))
    for c in stnu.contingents:
        arcs += [(c.source, c.target, c.ub), (c.target, c.source, -c.lb)]
    origin = stnu.timepoints[0]
    arcs += [(x, origin, 0) for x in stnu.timepoints if x != origin]  # every timepoint at or after the origin
    dist = {x: float("inf") for x in stnu.timepoints}
    for x in sources:
        dist[x] = 0.0
    for _ in range(len(dist) + 1):
        changed = False
        new = dict(dist)
        for u, v, w in arcs:
            if dist[u] + w < new[v]:
                new[v] = dist[u] + w
                changed = True
        dist = new
        if not changed:
            break
    else:
        return None
    robot = next(a.id for a in history.task.agents if not a.is_human)
    before = [n for a, p in entry.legs.get(robot, ()) for _, n in entry.leg_points[(robot, a, p)]
              if n not in done and dist[n] <= 0]
    if not before:  # else the done robot event that holds the step back latest, if after now (ties: by name)
        now = round(history.now * 1000)
        held = sorted((done[n] - dist[n], n) for a, p in entry.legs.get(robot, ())
                      for _, n in entry.leg_points[(robot, a, p)] if n in done and dist[n] <= 0)
        if held and held[-1][0] > now:
            before = [held[-1][1]]
    wait = ".".join(entry.events[before[-1]]) if before else None
    gap = round(-dist[before[-1]] / 1000, 3) + 0.0 if before else 0.0
    return Ahead(f"{human}.{pending[0][0]}.{pending[0][1]}.{pending[0][2]}", f"{human}.{step[0]}.{step[1]}.{step[2]}",
                 wait, gap)
