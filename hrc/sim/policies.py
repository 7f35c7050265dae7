"""The robot's policies compared by the simulator, and the controllers that carry them out.

`POLICIES` is the registry `hrc simulate --policy` offers (in this order):

- ``hrc``: the dispatcher (`hrc.dispatch.Dispatcher`, the same code as ``hrc dispatch``) on the
  motion-aware compile: set validation, set ranking and the robot's next step at every observation
  (Strassmair & Taylor 2014, section V.B);
- ``motion-blind``: the same dispatcher on a compile whose travel times are straight-line distance over
  speed, with no interference between the co-workers (`hrc.sim.blind`), as systems that ignore motion;
- ``feasible-only``: the dispatcher on the motion-aware compile keeping only DC or consistent plans
  (Chaski's behaviour, ``feasible_only=True``): when none is left, the robot stops;
- ``fixed``: the compile's best plan, no adaptation: the robot does its part of it, in its order, at
  the times of the plan's earliest schedule (or as soon as the task graph lets it), whatever the person
  does; it skips an action the person has already started.

A controller turns the policy into orders for the simulated robot (`Order`: an event of one of its
legs and the window for it, or wait) and, for a person who follows the plan, says which action the
current plan gives them next and when each of their events is planned (`guide_time`). Routes are the
current plan's: its motion pattern's route per leg (shortest, a detour, a stop at a waiting place);
for the motion-blind compile, whose routes are straight lines through the furniture, the real shortest
routes of the motion-aware compile (the floor is the same for every policy).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from hrc.compile.compiler import CompiledPlan, CompiledPlanSet
from hrc.compile.temporal_net_creator import leg_timepoint
from hrc.errors import HrcError
from hrc.model import Task
from hrc.motion import PathLibrary
from hrc.plans import agent_legs
from hrc.sim.detector import Happening
from hrc.sim.on_demand import OnDemandRun

__all__ = ["POLICIES", "Answering", "Controller", "DispatchedController", "FixedController", "Order", "Policy",
           "SimRoute", "hinted", "leg_route", "order_of"]


@dataclass(frozen=True, slots=True)
class Policy:
    """A policy: which compile it reads (`compile`: "motion" or "blind"), whether the dispatcher drops
    plans that are not DC or consistent, whether it adapts at all (`dispatched`), and what it is."""

    name: str
    compile: str
    feasible_only: bool
    dispatched: bool
    description: str


POLICIES: dict[str, Policy] = {p.name: p for p in (
    Policy("hrc", "motion", False, True, "the dispatcher on the motion-aware compile"),
    Policy("motion-blind", "blind", False, True,
           "the dispatcher on a compile with straight-line travel times and no interference"),
    Policy("feasible-only", "motion", True, True,
           "the dispatcher keeping only DC or consistent plans (Chaski); the robot stops when none is left"),
    Policy("fixed", "motion", False, False, "the compile's best plan, no adaptation"),
)}


@dataclass(frozen=True, slots=True)
class Order:
    """What the robot is told: do `event` of `action.phase` within ``[earliest, latest]`` (`latest`
    None: no upper bound), or, with `event` "wait", wait for `action.phase` of the person."""

    action: str
    phase: str
    event: str
    earliest: float = 0.0
    latest: float | None = None


@dataclass(frozen=True, slots=True)
class SimRoute:
    """A leg's route on the floor: `points` from the leg's origin to its location, and the arc length at
    which the agent stops at the waiting place `park` (None: no stop); `speed` a reduced speed the plan
    drives it at (0: the agent's own)."""

    points: tuple[tuple[float, float], ...]
    park: str = ""
    park_s: float | None = None
    speed: float = 0.0


def leg_route(task: Task, cp: CompiledPlan, real: PathLibrary, agent: str, action: str, phase: str,
              blind: bool) -> SimRoute | None:
    """The route of `agent` for `action.phase` in plan `cp` (None when the plan does not give it the phase)."""
    legs = agent_legs(task, cp.plan, agent) if action in cp.plan.sequence(agent) else ()  # a joint one: both
    leg = next((lg for lg in legs if (lg.action, lg.phase) == (action, phase)), None)
    if leg is None:
        return None
    if blind:
        return SimRoute(real.get(agent, leg.origin, leg.location).points)
    motion = next(m for m in cp.motions if m.agent == agent and m.leg == leg.index)
    if not motion.points:
        return SimRoute(real.get(agent, leg.origin, leg.location).points)
    if motion.park:
        speed = motion.speed or task.agent(agent).speed
        return SimRoute(motion.points, motion.park, motion.park_time * speed, motion.speed)
    return SimRoute(motion.points, speed=motion.speed)


class Controller:
    """The interface the run loop drives (see the module docstring); `log` collects what it refused."""

    name: str = ""
    stopped: bool = False
    plan_id: str | None = None
    plan_class: str | None = None
    first_plan: str | None = None
    first_class: str | None = None
    switches: int = 0
    latencies: list[float]
    refused: list[str]
    late: int = 0

    def observe(self, h: Happening) -> None:
        raise NotImplementedError

    def order(self) -> Order | None:
        raise NotImplementedError

    def human_next(self, started: Mapping[str, str]) -> str | None:
        raise NotImplementedError

    def guide_time(self, action: str, phase: str, event: str) -> float | None:
        raise NotImplementedError

    def route(self, agent: str, action: str, phase: str) -> SimRoute | None:
        raise NotImplementedError

    def current(self) -> CompiledPlan | None:
        raise NotImplementedError


def order_of(step: Any, fallback: str | None) -> Order | None:
    """A robot's step of a dispatcher's answer as an order: a timed event, a wait (a `WaitFor`, or no step
    in a fallback answer: no plan yet, stay, do not go home; in a team's, another robot may continue its
    leg meanwhile), or None (nothing: it goes home)."""
    if step is None and fallback is not None:
        return Order("", "", "wait")
    if step is None:
        return None
    if hasattr(step, "earliest"):
        return Order(step.action, step.phase, step.event, float(step.earliest),
                     None if step.latest is None else float(step.latest))
    return Order(step.action, step.phase, "wait")


def hinted(hint: Any, taken: Mapping[str, str]) -> str | None:
    """The action a person's hint tells them to leave for next (None: it does not, or it is taken)."""
    if hint is not None and getattr(hint, "event", "") == "depart" and hasattr(hint, "earliest") \
            and hint.action not in taken:
        return str(hint.action)
    return None


class Answering:
    """What a controller over the real dispatcher (`d`) does with each observation and keeps of the answers,
    for one pair (`DispatchedController`) and a team (`hrc.sim.team_policies.TeamDispatched`)."""

    latencies: list[float]
    refused: list[str]
    plan_class: str | None
    first_class: str | None

    def __init__(self, dispatcher: Any, cps: CompiledPlanSet, real: PathLibrary, blind: bool) -> None:
        self.d, self.cps, self.real, self.blind = dispatcher, cps, real, blind
        self.by_id = {cp.plan.id: cp for cp in cps.plans}
        self.latencies = []
        self.refused = []
        self.switches = 0
        self._times: dict | None = None
        dec = dispatcher.decision
        self.first_plan: str | None = dec.plan
        self.plan_id: str | None = dec.plan
        self.first_class = self.plan_class = dec.plan_class
        self.stopped = bool(dec.stopped)
        self.on_demand: OnDemandRun | None = None  # compile on demand (`hrc.sim.on_demand`): a searched compile

    def observe(self, h: Happening) -> None:
        raise NotImplementedError

    def _ask(self, t: float, dec: Any) -> None:
        """After an answer: a miss (the fallback after a plan) counted; plans asked for (`hrc.sim.on_demand`;
        a team's as one pair's: the prefix is every agent's)."""
        from hrc.dispatch.on_demand import wanted
        from hrc.sim.on_demand import COMPILE_DELAY

        od = self.on_demand
        assert od is not None
        if dec.fallback is None:
            if od.missed_at is not None:
                od.recovery.append(t - od.missed_at)
                od.missed_at = None
            return
        if od.missed_at is None:
            od.misses += 1
            od.missed_at = t
        prefix = wanted(self.d)
        if prefix is not None and od.pending is None:
            od.pending = (prefix, t + COMPILE_DELAY)

    def _adopt(self, t: float) -> None:
        """The plans asked for, compiled (`hrc.sim.on_demand.Compiles`), adopted once their time has come."""
        from hrc.dispatch.on_demand import adopt, plan_rows

        od = self.on_demand
        assert od is not None
        if od.pending is None or t < od.pending[1] - 1e-9:
            return
        prefix = od.pending[0]
        od.pending = None
        plans, seconds = od.compiles.plans(prefix)
        if seconds is not None:
            od.compile_seconds.append(seconds)
        for cp in plans:
            self.by_id.setdefault(cp.plan.id, cp)
        self.d, n = adopt(self.d, plan_rows(plans))
        od.adopted += n

    def due(self) -> float | None:
        """When the run must wake this controller (plans compiled on demand come), or None."""
        return None if self.on_demand is None else self.on_demand.due()

    @staticmethod
    def _observation(h: Happening) -> Any:
        """What the dispatcher is told of `h` (its time to the core's millisecond)."""
        from hrc.dispatch import Observation

        return Observation(t=round(h.t, 3), event=h.event, agent=h.agent, action=h.action, phase=h.phase,
                           delay=h.delay)

    def _answer(self, obs: Any, h: Happening) -> Any | None:
        """The dispatcher's answer to `obs` (its latency kept), or None: refused (logged), state unchanged."""
        t0 = time.perf_counter()
        try:
            dec = self.d.observe(obs)
        except HrcError as err:  # DispatchError: refused, state unchanged
            self.latencies.append(time.perf_counter() - t0)
            self.refused.append(f"{obs.t:.3f} {h.agent}.{h.action}.{h.phase}.{h.event}: {str(err).splitlines()[0]}")
            return None
        self.latencies.append(time.perf_counter() - t0)
        return dec

    def _after(self, dec: Any) -> None:
        self._times = None
        if dec.plan != self.plan_id and dec.plan is not None:
            if self.plan_id is not None:
                self.switches += 1
            if self.first_plan is None:
                self.first_plan, self.first_class = dec.plan, dec.plan_class
        self.plan_id, self.plan_class = dec.plan, dec.plan_class
        self.stopped = bool(dec.stopped)

    def tick(self, t: float) -> None:
        """Tell the dispatcher that time has passed (when it has nothing else to hear)."""
        self.observe(Happening(t, "", "tick"))

    def current(self) -> CompiledPlan | None:
        return self.by_id.get(self.plan_id) if self.plan_id is not None else None

    def guided(self, person: str, hint: Any, ahead: Any, key: tuple[str, str, str],
               in_stay: Callable[[str, str, str, str], bool] | None = None) -> float | None:
        """When `person` does their event `key` (action, phase, event) by their own part of the answers:
        their `hint`'s earliest when it is about this event, inf when it says to wait; their instruction
        `ahead` when it names the event (or, with `in_stay`, a step of the stay it names): `gap` seconds
        after the event it waits for once seen (inf before), at once when it waits for none; else the best
        plan's planned time. The one pair's `DispatchedController.guide_time` and a team's person's
        (`hrc.sim.team_policies.TeamDispatched.guide_time`) both read it."""
        action, phase, event = key
        if hint is not None:
            if not hasattr(hint, "earliest"):
                return math.inf  # WaitFor: the person waits for the robot's event
            if (hint.action, hint.phase, hint.event) == key:
                return float(hint.earliest)
        if hint is None and ahead is not None and (ahead.next == f"{person}.{action}.{phase}.{event}" or (
                in_stay is not None and in_stay(ahead.next, action, phase, event))):
            if ahead.wait_for is None:
                return None
            seen = self.d.seen.times.get(tuple(ahead.wait_for.split(".")))
            return math.inf if seen is None else float(seen) + float(ahead.gap)
        if self._times is None:
            self._times = dict(self.d.planned_times())
        t = self._times.get((person, action, phase, event))
        return None if t is None or not math.isfinite(t) else float(t)


class DispatchedController(Answering, Controller):
    """The dispatcher in charge: observations in, the decision's robot step out (``hrc.dispatch``)."""

    def __init__(self, dispatcher: Any, cps: CompiledPlanSet, real: PathLibrary, blind: bool) -> None:
        super().__init__(dispatcher, cps, real, blind)
        self.detected: list[tuple[float, float, str, str, str]] = []  # (given at, estimated t, event, action, phase)
        self.detect_refused: list[str] = []
        self.withdrawn = 0  # departures the detector gave and withdrew (undo)
        self.known: list[Happening] = []  # the person's own events, when a motion detector stands between
        # answers that said an observation came later than the stated maximum delay (`Decision.deviation`);
        # None when the dispatcher was given no maximum (a compile without `sensing:`)
        self.late_observations: int | None = None if dispatcher.max_observation_delay is None else 0
        self._ordered: tuple[Any, Order | None] = (None, None)

    def observe(self, h: Happening) -> None:
        obs = self._observation(h)
        if self.on_demand is not None:
            self._adopt(obs.t)
        dec = self._answer(obs, h)
        if dec is None:
            return
        if dec.deviation is not None and "late" in dec.deviation and self.late_observations is not None:
            self.late_observations += 1
        self._after(dec)
        if self.on_demand is not None:
            self._ask(obs.t, dec)

    def position(self, now: float, t: float, x: float, y: float) -> bool:
        """The person's position measured at `t` reaches the motion detector at run time `now`
        (`hrc.detect.online.DetectingDispatcher.position`); whether it gave an event."""
        t0 = time.perf_counter()
        try:
            given, refused = self.d.position(t, x, y)
        except HrcError as err:  # refused (time going backwards): nothing changed
            self.latencies.append(time.perf_counter() - t0)
            self.refused.append(f"{t:.3f} position: {str(err).splitlines()[0]}")
            return False
        self.latencies.append(time.perf_counter() - t0)
        self.detect_refused += refused
        for ev, _ in given:
            if ev.event == "undo":  # the last event given (a departure for the wrong place) withdrawn
                self.withdrawn += 1
                if self.detected:
                    self.detected.pop()
                continue
            self.detected.append((round(now, 3), ev.t, ev.event, ev.action, ev.phase))
            # the delay the detector said (`DetectingDispatcher.position`) beyond the dispatcher's maximum: its
            # answer had a deviation (several events of one position: one answer shown, each counted)
            if self.late_observations is not None and round(max(0.0, t - ev.t), 3) > self.d.max_observation_delay:
                self.late_observations += 1
        if given:
            self._after(self.d.decision)
        return bool(given)

    def order(self) -> Order | None:
        decision = self.d.decision
        if decision is self._ordered[0]:  # asked every step of the floor: made once per decision
            return self._ordered[1]
        order = order_of(decision.robot, decision.fallback)
        self._ordered = (decision, order)
        return order

    def human_next(self, started: Mapping[str, str]) -> str | None:
        # what to do next: what the console shows (the when: `guide_time`); the dispatcher's hint: the
        # human's next departure in the best plan
        hint = hinted(self.d.decision.human, started)
        if hint is not None:
            return hint
        cp = self.current()
        if cp is None:
            return None
        return next((a for a in cp.plan.sequence(_human(self.cps.task)) if a not in started), None)

    def guide_time(self, action: str, phase: str, event: str) -> float | None:
        """When the person does this event, from the answers they were given alone (never the true events:
        a real person reads the console): the hint's earliest when it is about this event, inf when it
        says to wait for a robot event (`Decision.human`); when the answer's instruction ahead names it
        (`Decision.ahead`: given while their walk or manipulation was under way, so that after it they need
        not wait for the dispatcher to learn that it ended), `gap` seconds after the robot's event it
        names once an answer has acknowledged that event (inf before), at once when it names none; else
        the best plan's planned time (`Dispatcher.planned_times`, the console's chart)."""
        if self.plan_id is None:
            return None
        decision = self.d.decision
        return self.guided(_human(self.cps.task), decision.human, getattr(decision, "ahead", None),
                           (action, phase, event), self._in_stay)

    def _in_stay(self, named: str, action: str, phase: str, event: str) -> bool:
        """Whether the person's `event` of `action`.`phase` is a step of the stay whose first step, a
        departure for a leg without a walk, the instruction ahead names (`named`): a start at that place,
        or a departure from it (the person's last own event was there), while the dispatcher has not learnt
        them past it (a motion detector cannot tell steps apart at one place). `Dispatcher._ahead` gives
        the stay's bound then: the person goes through the stay as told for its first step."""
        if event not in ("depart", "start") or not self.known or not named.endswith(".depart"):
            return False
        task = self.cps.task
        if (_human(task), action, phase, event) in self.d.seen.times:
            # learnt already (a motion detector may date a start at an arrival it gave before the person
            # was there): the stay's bound is for the steps after it, which this one does not wait for
            return False
        _, n_action, n_phase, _ = named.split(".")
        here = task.action(n_action).phase(n_phase).location
        last = self.known[-1]
        if last.action is None or last.phase is None or task.action(last.action).phase(last.phase).location != here:
            return False
        return event == "depart" or task.action(action).phase(phase).location == here

    def route(self, agent: str, action: str, phase: str) -> SimRoute | None:
        cp = self.current()
        return None if cp is None else leg_route(self.cps.task, cp, self.real, agent, action, phase, self.blind)


class FixedController(Controller):
    """The compile's best plan carried out as planned (no dispatcher)."""

    def __init__(self, cps: CompiledPlanSet) -> None:
        self.cps = cps
        self.task = cps.task
        cp = cps.plans[0]
        self.cp = cp
        self.first_plan = self.plan_id = cp.plan.id
        self.first_class = self.plan_class = cp.plan_class.value
        self.schedule = dict(cp.classification.schedule)
        self.robot = next(a.id for a in self.task.agents if not a.is_human)
        self.legs = agent_legs(self.task, cp.plan, self.robot)
        self.latencies = []
        self.refused = []
        self.seen: dict[str, str] = {}  # action -> agent, as the robot has seen them started
        self.done: set[tuple[str, str, str]] = set()  # (action, phase, event) of the robot's own legs
        self._order: tuple[Order | None] | None = None

    def observe(self, h: Happening) -> None:
        if h.action is not None and h.event in ("depart", "start"):
            self.seen.setdefault(h.action, h.agent)
        if h.agent == self.robot and h.action is not None and h.phase is not None:
            self.done.add((h.action, h.phase, h.event))
        self._order = None

    def order(self) -> Order | None:
        if self._order is None:
            self._order = (self._next_order(),)
        return self._order[0]

    def _next_order(self) -> Order | None:
        for leg in self.legs:
            if self.seen.get(leg.action, self.robot) != self.robot and not self.task.action(leg.action).joint:
                continue  # the person took it: skip (a joint action is both agents')
            motion = next(m for m in self.cp.motions if m.agent == self.robot and m.leg == leg.index)
            events = ["depart"] + (["park", "unpark"] if motion.park else []) + ["arrive", "start", "end"]
            for ev in events:
                if (leg.action, leg.phase, ev) not in self.done:
                    at = self.schedule.get(leg_timepoint(leg, ev), 0.0)
                    return Order(leg.action, leg.phase, ev, at, None)
        return None

    def current(self) -> CompiledPlan | None:
        return self.cp

    def human_next(self, started: Mapping[str, str]) -> str | None:
        return next((a for a in self.cp.plan.sequence(_human(self.task)) if a not in started), None)

    def guide_time(self, action: str, phase: str, event: str) -> float | None:
        human = _human(self.task)
        if action not in self.cp.plan.sequence(human):  # not theirs (a joint action is in both sequences)
            return None
        leg = next(lg for lg in agent_legs(self.task, self.cp.plan, human) if (lg.action, lg.phase) == (action, phase))
        return self.schedule.get(leg_timepoint(leg, event))

    def route(self, agent: str, action: str, phase: str) -> SimRoute | None:
        return leg_route(self.task, self.cp, self.cps.paths, agent, action, phase, False)


def _human(task: Task) -> str:
    return next(a.id for a in task.agents if a.is_human)
