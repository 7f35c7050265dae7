"""The controllers of a team's simulated run (issue 37): the dispatcher in charge of every robot, or the
fixed plan, and each person's reading of their own part of it.

- `TeamDispatched`: the dispatcher (`hrc.dispatch.Dispatcher`, as ``hrc dispatch`` serves a team): each
  robot's order is its own entry of the answer (`Decision.robots`); each person's next action and the
  times of their events come from their own hint (`Decision.people`), their instruction ahead
  (`Decision.aheads`), else the best plan's planned times of their own events (what their console page
  would show): never another agent's part, never the true events;
  Over a searched compile (a task beyond ``--max-plans``) it compiles on demand as the one pair's does
  (`hrc.sim.on_demand`): every robot goes on from its own fallback step until plans extending every
  agent's observed prefix come;
- `TeamFixed`: the compile's best plan, no adaptation: each robot does its legs in order at the plan's
  earliest schedule, skipping an action another agent has started;
- `make_team_controller`: a fresh one per run (a dispatcher forked from a per-process pristine one).

The one-pair controllers are `hrc.sim.policies`'; the policies (`POLICIES`) are the same.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

from hrc.compile.compiler import CompiledPlan, CompiledPlanSet
from hrc.compile.temporal_net_creator import leg_timepoint
from hrc.errors import HrcError
from hrc.plans import agent_legs
from hrc.sim.detector import Happening
from hrc.sim.policies import Answering, Order, Policy, SimRoute, hinted, leg_route, order_of
from hrc.sim.run import SimContext

__all__ = ["TeamController", "TeamDispatched", "TeamFixed", "make_team_controller"]


class TeamDispatched(Answering):
    """The dispatcher in charge of every robot (`Decision.robots`), each person reading their own hint."""

    def __init__(self, dispatcher: Any, cps: CompiledPlanSet, ctx: SimContext, blind: bool) -> None:
        super().__init__(dispatcher, cps, ctx.paths, blind)
        self._orders: tuple[Any, dict[str, Order | None]] = (None, {})
        # answers that said a person's observation came later than the stated maximum delay (as the one
        # pair's `DispatchedController.late_observations`); None without a stated delay
        self.late_observations: int | None = None if dispatcher.max_observation_delay is None else 0
        # with the motion detector (issue 37): per person, the events it gave ``(given at, estimated t,
        # event, action, phase)``, those the dispatcher refused, and the departures it withdrew (undo)
        people = [a.id for a in cps.task.agents if a.is_human]
        self.detected: dict[str, list[tuple[float, float, str, str, str]]] = {p: [] for p in people}
        self.detect_refused: dict[str, list[str]] = {p: [] for p in people}
        self.withdrawn = dict.fromkeys(people, 0)

    def position(self, now: float, person: str, t: float, x: float, y: float) -> bool:
        """`person`'s position measured at `t` reaches their motion detector at run time `now`
        (`hrc.detect.online.DetectingDispatcher.position`, as the one pair's `DispatchedController.position`);
        whether it gave an event."""
        t0 = time.perf_counter()
        try:
            given, refused = self.d.position(t, x, y, person)
        except HrcError as err:  # refused (time going backwards): nothing changed
            self.latencies.append(time.perf_counter() - t0)
            self.refused.append(f"{t:.3f} {person} position: {str(err).splitlines()[0]}")
            return False
        self.latencies.append(time.perf_counter() - t0)
        self.detect_refused[person] += refused
        detected = self.detected[person]
        for ev, _ in given:
            if ev.event == "undo":  # their last event given (a departure for the wrong place) withdrawn
                self.withdrawn[person] += 1
                if detected:
                    detected.pop()
                continue
            detected.append((round(now, 3), ev.t, ev.event, ev.action, ev.phase))
            if self.late_observations is not None and round(max(0.0, t - ev.t), 3) > self.d.max_observation_delay:
                self.late_observations += 1
        if given:
            self._after(self.d.decision)
        return bool(given)

    def observe(self, h: Happening) -> None:
        obs = self._observation(h)
        if self.on_demand is not None:  # compile on demand (`hrc.sim.on_demand`), as the one pair's
            self._adopt(obs.t)
        dec = self._answer(obs, h)
        if dec is not None:
            if dec.deviation is not None and "late" in dec.deviation and self.late_observations is not None:
                self.late_observations += 1
            self._after(dec)
            if self.on_demand is not None:
                self._ask(obs.t, dec)

    def order(self, robot: str) -> Order | None:
        """`robot`'s entry of the answer as an order (made once per answer)."""
        dec = self.d.decision
        if dec is not self._orders[0]:
            self._orders = (dec, {})
        made = self._orders[1]
        if robot not in made:
            made[robot] = order_of((dec.robots or {}).get(robot), dec.fallback)
        return made[robot]

    def human_next(self, person: str, taken: Mapping[str, str]) -> str | None:
        hint = hinted((self.d.decision.people or {}).get(person), taken)
        if hint is not None:
            return hint
        cp = self.current()
        if cp is None:
            return None
        return next((a for a in cp.plan.sequence(person) if a not in taken), None)

    # `Answering.guided` as `DispatchedController.guide_time`, on each person's own hint and instruction
    # ahead (`Decision.people`, `aheads`), without widening an instruction ahead to the person's whole stay
    # (`_in_stay`, built for the one person's console).
    def guide_time(self, person: str, action: str, phase: str, event: str) -> float | None:
        """When `person` does this event, from their own part of the answers (`DispatchedController.guide_time`
        for one person): their hint's earliest when it is about this event, inf when it says to wait; their
        instruction ahead; else the best plan's planned time of their event."""
        if self.plan_id is None:
            return None
        dec = self.d.decision
        return self.guided(person, (dec.people or {}).get(person), (dec.aheads or {}).get(person),
                           (action, phase, event))

    def route(self, agent: str, action: str, phase: str) -> SimRoute | None:
        cp = self.current()
        return None if cp is None else leg_route(self.cps.task, cp, self.real, agent, action, phase, self.blind)


class TeamFixed:
    """The compile's best plan carried out as planned by every robot (no dispatcher): each robot does its
    legs in order at the plan's earliest schedule (or as soon as it can), skipping an action another agent
    has started."""

    def __init__(self, cps: CompiledPlanSet) -> None:
        self.cps, self.task = cps, cps.task
        self.cp = cps.plans[0]
        self.first_plan = self.plan_id = self.cp.plan.id
        self.first_class = self.plan_class = self.cp.plan_class.value
        self.schedule = dict(self.cp.classification.schedule)
        self.legs = {a.id: agent_legs(self.task, self.cp.plan, a.id) for a in self.task.agents}
        self.latencies: list[float] = []
        self.refused: list[str] = []
        self.switches = 0
        self.stopped = False
        self.seen: dict[str, str] = {}
        self.done: set[tuple[str, str, str, str]] = set()

    def observe(self, h: Happening) -> None:
        if h.action is not None and h.event in ("depart", "start"):
            self.seen.setdefault(h.action, h.agent)
        if h.action is not None and h.phase is not None:
            self.done.add((h.agent, h.action, h.phase, h.event))

    def tick(self, t: float) -> None:
        return None

    def order(self, robot: str) -> Order | None:
        for leg in self.legs[robot]:
            if self.seen.get(leg.action, robot) != robot and not self.task.action(leg.action).joint:
                continue
            motion = next(m for m in self.cp.motions if m.agent == robot and m.leg == leg.index)
            for ev in ["depart"] + (["park", "unpark"] if motion.park else []) + ["arrive", "start", "end"]:
                if (robot, leg.action, leg.phase, ev) not in self.done:
                    return Order(leg.action, leg.phase, ev, self.schedule.get(leg_timepoint(leg, ev), 0.0), None)
        return None

    def current(self) -> CompiledPlan | None:
        return self.cp

    def human_next(self, person: str, taken: Mapping[str, str]) -> str | None:
        return next((a for a in self.cp.plan.sequence(person) if a not in taken), None)

    def guide_time(self, person: str, action: str, phase: str, event: str) -> float | None:
        leg = next((lg for lg in self.legs[person] if (lg.action, lg.phase) == (action, phase)), None)
        return None if leg is None else self.schedule.get(leg_timepoint(leg, event))

    def route(self, agent: str, action: str, phase: str) -> SimRoute | None:
        return leg_route(self.task, self.cp, self.cps.paths, agent, action, phase, False)


TeamController = TeamDispatched | TeamFixed


def make_team_controller(ctx: SimContext, policy: Policy) -> TeamController:
    """A fresh controller for one run of `policy` (a dispatcher forked from a per-process pristine one)."""
    cps = ctx.compiles[policy.compile]
    if not policy.dispatched:
        return TeamFixed(cps)
    motion = ctx.settings.motion
    key = ("team-dispatcher", policy.name) + (("motion",) if motion else ())
    pristine = ctx.cache.get(key)
    if pristine is None:
        from hrc.dispatch import Dispatcher

        if motion:  # one motion detector per person in front of it (issue 37), as for one pair
            from hrc.detect import DetectingDispatcher, DetectParams

            pristine = ctx.cache[key] = DetectingDispatcher.from_compiled(
                cps, feasible_only=policy.feasible_only, threads=1,
                params=DetectParams(sigma=max(ctx.settings.sensor.sigma, 0.01)))
        else:
            pristine = ctx.cache[key] = Dispatcher.from_compiled(cps, feasible_only=policy.feasible_only, threads=1)
    ctl = TeamDispatched(pristine.fork(), cps, ctx, policy.compile == "blind")
    if cps.search and not motion and not policy.feasible_only:  # a searched compile: compile on demand
        from hrc.sim.on_demand import attach

        ctl.on_demand = attach(ctx.cache, policy.compile, cps, ctl.d)
    return ctl
