"""An agent's mechanics in a simulated run, the same for one person and one robot (`hrc.sim.run`) and for a
team (`hrc.sim.team_run`): the task graph's bookkeeping, a leg (its route, the departure, the waiting place
and the arrival), the way home, the next phase, a robot's acknowledgement and its work phase, and a run's
outcome (the deadline, the task's constraints, the time each agent was busy, the first plan kept).

The loop (Strassmair & Taylor 2014, Fig. 5, online process, every box simulated but the dispatcher) is
each run module's own: what it does with these pieces (the person's absences, the stand-offs, a motion
detector for one pair; many people and robots for a team) is where the two differ.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterable, Mapping
from typing import Generic, Protocol, TypeVar

from hrc.compile.compiler import CompiledPlan, CompiledPlanSet
from hrc.model import Task
from hrc.motion import PathLibrary
from hrc.plans import must_precede
from hrc.sim.detector import Detector, Happening
from hrc.sim.floor import Mover
from hrc.sim.giveway import Ways
from hrc.sim.policies import Order, SimRoute
from hrc.sim.replay import broken_constraints, executed, plan_network, timepoint_times

__all__ = ["ACK", "EPS", "AgentLoop", "Walker", "acknowledged", "add_busy", "constraints_met"]

EPS = 1e-9
ACK = 0.002  # s: a robot's acknowledgement snaps into its window when this close to it


class Walker(Protocol):
    """An agent's state in a run loop (`hrc.sim.standoff.AgentState`, `hrc.sim.team_run._Agent`)."""

    id: str
    mover: Mover
    home: str
    loc: str | None
    mode: str
    action: str | None
    pi: int
    route: SimRoute | None
    parked: bool
    work_start: float
    work_end: float
    duration: float
    order: Order | None
    predicted: float
    moved: float


class _Plans(Protocol):
    """What the mechanics ask of a run's controller (one pair's or a team's)."""

    @property
    def first_plan(self) -> str | None: ...

    def observe(self, h: Happening) -> None: ...

    def route(self, agent: str, action: str, phase: str) -> SimRoute | None: ...

    def current(self) -> CompiledPlan | None: ...


class _Context(Protocol):
    @property
    def paths(self) -> PathLibrary: ...


W = TypeVar("W", bound=Walker)


def acknowledged(t: float, o: Order | None, event: str, action: str | None, phase: str | None) -> tuple[float, bool]:
    """A robot's event at `t` as acknowledged against the window of its order `o` (when it is the order for
    this event): snapped into the window within `ACK`, and whether it fell outside (late)."""
    if o is None or (o.action, o.phase, o.event) != (action, phase, event):
        return t, False
    if t < o.earliest - EPS and o.earliest - t <= ACK:
        t = o.earliest
    if o.latest is not None and t > o.latest + EPS and t - o.latest <= ACK:
        t = o.latest
    return t, t < o.earliest - ACK or (o.latest is not None and t > o.latest + ACK)


def constraints_met(task: Task, happenings: Iterable[Happening]) -> bool:
    """The task's temporal constraints, on the times of the events whoever did them."""
    at: dict[str, float] = {}
    for h in happenings:
        if h.action and h.phase and h.event in ("start", "end"):
            at.setdefault(f"{h.action}.{h.phase}.{h.event}", h.t)
    for c in task.constraints:
        a, b = at.get(str(c.source)), at.get(str(c.target))
        if a is None or b is None or not (c.bounds.lb - 1e-3 <= b - a <= c.bounds.ub + 1e-3):
            return False
    return True


def add_busy(busy: dict[str, float], times: Mapping[str, float], span: float) -> None:
    """Adds to each agent of `busy` the time (up to `span`) it worked or travelled by its own timepoints
    (a stop at a waiting place is not busy)."""
    for name, t in times.items():
        if name.count(".") != 3:
            continue
        base, what = name.rsplit(".", 1)
        agent = name.split(".", 1)[0]
        if agent not in busy:
            continue
        if what == "end" and base + ".start" in times:
            busy[agent] += min(t, span) - min(times[base + ".start"], span)
        elif what == "arrive" and base + ".depart" in times:
            busy[agent] += min(t, span) - min(times[base + ".depart"], span)
            if base + ".unpark" in times and base + ".park" in times:
                busy[agent] -= times[base + ".unpark"] - times[base + ".park"]


class AgentLoop(Generic[W]):
    """The mechanics both run loops derive from (module docstring); `emit` and `_robot` are each loop's."""

    task: Task
    ctx: _Context
    ctl: _Plans
    ways: Ways
    detector: Detector
    t: float
    cap: float
    excess: float
    last_obs: float
    joint: Collection[str]  # the joint actions (a team's: with their agents)
    joint_stay: dict[str, str]
    last: dict[str, tuple[str, str]]

    def _init_task(self, task: Task, time_cap: float | None) -> None:
        """The task graph's bookkeeping and the time cap (default five times the deadline, or 600 s)."""
        self.t = 0.0
        self.happenings: list[Happening] = []
        self.started: dict[str, str] = {}  # action -> agent that started it (first depart)
        self.ended: set[tuple[str, str]] = set()
        self.phases = {a.id: tuple(p.id for p in a.phases) for a in task.actions}
        self.preds: dict[tuple[str, str], list[tuple[str, str]]] = {}
        for pr in task.precedence:
            self.preds.setdefault((pr.after.action, pr.after.phase), []).append((pr.before.action, pr.before.phase))
        self.before = must_precede(task)
        self.total = sum(len(v) for v in self.phases.values())
        deadline = task.deadline if task.deadline is not None else 120.0
        self.cap = time_cap if time_cap is not None else 5 * deadline

    def emit(self, agent: W, event: str, action: str | None = None, phase: str | None = None) -> None:
        raise NotImplementedError

    def _robot(self, agent: W) -> bool:
        """Whether `agent` is a robot (its travel's excess over the prediction is counted)."""
        raise NotImplementedError

    def _lead(self, action: str) -> str | None:
        """Who starts joint `action` in this run (`Task.lead`; a team's with a crew to choose: its crew's,
        `hrc.sim.team_run._TeamRun._lead`)."""
        return self.task.lead(action)

    # -- bookkeeping ---------------------------------------------------------------------------------

    def _tell(self, h: Happening) -> None:
        self.last_obs = max(self.last_obs, h.t)
        self.ctl.observe(h)

    def _deliver_detected(self) -> bool:
        """The detector's releases (the person's events) to the controller, each no earlier than the last."""
        if not self.detector.pending:  # (asked at every step: nothing to release, most of the time)
            return False
        out = self.detector.release(self.t)
        for h in out:
            t = max(h.t, self.last_obs)  # later still when the clock has moved on: as late as it is told
            delay = None if h.delay is None else round(h.delay + t - h.t, 3)
            self._tell(Happening(t, h.agent, h.event, h.action, h.phase, delay))
        return bool(out)

    def ready(self, action: str, phase: str) -> bool:
        return all(p in self.ended for p in self.preds.get((action, phase), ()))

    def done(self) -> bool:
        return len(self.ended) == self.total

    # -- a leg -----------------------------------------------------------------------------------------

    def _clearance(self, a: W) -> float:
        return a.mover.agent.radius + self.task.safety_margin

    def route_for(self, agent: W, action: str, phase: str, planned: bool = True) -> SimRoute:
        """The plan's route for the leg if the agent stands where it starts, else the shortest one."""
        target = self.task.action(action).phase(phase).location
        if planned:
            route = self.ctl.route(agent.id, action, phase)
            if route is not None and math.dist(route.points[0], agent.mover.xy) < 1e-6 \
                    and math.dist(route.points[-1], self.ctx.paths.locations[target]) < 1e-6:
                return route
        if agent.loc is None:  # somewhere on the floor (made room, gave up a leg): the roadmap's way from there
            goal = self.ctx.paths.locations[target]
            return SimRoute(self.ways.route(self._clearance(agent), agent.mover.xy, goal) or (agent.mover.xy, goal))
        return SimRoute(self.ctx.paths.get(agent.id, agent.loc, target).points)

    def depart(self, agent: W, action: str, phase: str, speed: float, planned: bool = True) -> None:
        route = self.route_for(agent, action, phase, planned)
        agent.route, agent.parked, agent.mode, agent.moved = route, False, "travel", 0.0
        length = sum(math.dist(p, q) for p, q in zip(route.points, route.points[1:], strict=False))
        agent.predicted = length / agent.mover.agent.speed
        agent.mover.set_route(route.points, route.speed or speed, route.park_s)
        agent.loc = None
        self.emit(agent, "depart", action, phase)
        self._arrival_check(agent)

    def _arrival_check(self, agent: W) -> bool:
        """After a travel stopped: the waiting place or the arrival."""
        if agent.mode != "travel" or agent.mover.moving:
            return False
        assert agent.action is not None
        phase = self.phases[agent.action][agent.pi]
        if agent.route is not None and agent.route.park_s is not None and not agent.parked:
            agent.parked, agent.mode = True, "parked"
            self.emit(agent, "park", agent.action, phase)
            return True
        agent.mode, agent.loc = "arrived", self.task.action(agent.action).phase(phase).location
        if self._robot(agent):
            self.excess += max(0.0, agent.moved - agent.predicted)
        self.emit(agent, "arrive", agent.action, phase)
        return True

    def go_home(self, agent: W) -> bool:
        """An agent with nothing to do goes back to its start, out of the way (False: it is there)."""
        if agent.loc == agent.home:
            return False
        home = self.ctx.paths.locations[agent.home]
        if agent.loc is None:  # somewhere on the floor (made room, gave up a leg): the roadmap's way home
            if math.dist(agent.mover.xy, home) < 1e-6:
                agent.loc = agent.home
                return False
            points: tuple[tuple[float, float], ...] = self.ways.route(self._clearance(agent), agent.mover.xy, home) \
                or (agent.mover.xy, home)
        else:
            points = self.ctx.paths.get(agent.id, agent.loc, agent.home).points
        agent.mover.set_route(points, agent.mover.agent.speed)
        agent.mode, agent.loc = "home", None
        return True

    def _home_reached(self, a: W) -> bool:
        """Whether `a`, on its way home, got there now (free again; a walk away from a joint spot is over)."""
        if a.mode != "home" or a.mover.moving:
            return False
        a.mode, a.loc = "free", a.home
        self.joint_stay.pop(a.id, None)
        return True

    def _next_phase(self, a: W) -> None:
        assert a.action is not None
        a.pi += 1
        if a.pi >= len(self.phases[a.action]):
            a.action, a.pi = None, 0
        a.mode = "free"

    def _next_of(self, agent: W, step: tuple[str, str]) -> tuple[str, str] | None:
        """`agent`'s phase after `step` in the current plan (None: none, or no plan)."""
        action, phase = step
        phases = self.phases[action]
        i = phases.index(phase)
        if i + 1 < len(phases):
            return (action, phases[i + 1])
        cp = self.ctl.current()
        seq = () if cp is None else cp.plan.sequence(agent.id)
        if action not in seq or seq.index(action) + 1 >= len(seq):
            return None
        nxt = seq[seq.index(action) + 1]
        return (nxt, self.phases[nxt][0])

    def _now(self, agent: W) -> tuple[str, str] | None:
        """The phase `agent` is at (or on its way to), else the last it ended."""
        if agent.action is not None:
            return (agent.action, self.phases[agent.action][agent.pi])
        return self.last.get(agent.id)

    # -- a robot's leg ---------------------------------------------------------------------------------

    def _robot_depart(self, a: W, o: Order) -> bool:
        """A free robot leaves for the phase its order names once the order's time has come."""
        if o.event != "depart" or self.t < o.earliest - EPS:
            return False
        a.action, a.pi, a.order = o.action, self.phases[o.action].index(o.phase), o
        self.depart(a, o.action, o.phase, a.mover.agent.speed)
        return True

    def _robot_parked(self, a: W, o: Order | None, mine: bool, phase: str) -> bool:
        """A robot at its waiting place leaves it when told to; told to arrive, the plan followed now (one
        compiled on demand, `hrc.sim.on_demand`) has no stop on this leg, so it goes on as if told to leave
        the waiting place now."""
        if mine and o is not None and (o.event == "arrive" or (o.event == "unpark" and self.t >= o.earliest - EPS)):
            a.order = o
            return self._unpark(a, phase)
        return False

    # -- work phases --------------------------------------------------------------------------

    def _robot_start(self, a: W, o: Order, phase: str, quantile: float) -> None:
        """The robot starts its phase as told: its duration is its bounds' `quantile` (its draw)."""
        assert a.action is not None
        bounds = self.task.action(a.action).phase(phase).duration(a.id)
        a.order, a.mode, a.work_start = o, "work", self.t
        a.duration = bounds.lb + quantile * (bounds.ub - bounds.lb)
        self.emit(a, "start", a.action, phase)

    def _robot_work(self, a: W, o: Order | None, mine: bool, joint: bool, phase: str) -> bool:
        """The robot works its phase until its duration is over, no earlier than its end's window (and no
        later, but a joint phase's end is nature's: every role done); then it ends it."""
        end = a.work_start + a.duration
        if mine and o is not None and o.event == "end":
            end = max(end, o.earliest)
            if o.latest is not None and not joint:
                end = min(end, o.latest)
            a.order = o
        a.work_end = end
        return self._work_done(a, phase)

    def _work_done(self, a: W, phase: str) -> bool:
        """An agent working its own phase ends it once its time is over."""
        if self.t >= a.work_end - EPS:
            self.emit(a, "end", a.action, phase)
            self._next_phase(a)
            return True
        return False

    def _joint_done(self, a: W, phase: str) -> bool:
        """An agent working a joint phase another agent leads (starts and ends) goes on once it has ended."""
        if a.mode == "work" and (a.action, phase) in self.ended:
            self._next_phase(a)
            return True
        return False

    def _unpark(self, a: W, phase: str) -> bool:
        """The agent leaves its waiting place (it was told to, or its guide says now)."""
        a.mode = "travel"
        a.mover.resume()
        self.emit(a, "unpark", a.action, phase)
        return True

    # -- the outcome -----------------------------------------------------------------------------------

    def _outcome(self) -> tuple[bool, dict[str, float], float | None, bool, bool, float]:
        """Whether every phase ended, the timepoints' times, the makespan, the deadline and the task's
        limits met, and the span measured (the makespan, else the time the run stopped)."""
        task = self.task
        finished = self.done()
        times = timepoint_times(self.happenings)
        ends = [h.t for h in self.happenings if h.event == "end"]
        makespan = max(ends) if finished and ends else None
        deadline_met = finished and (task.deadline is None or (makespan or 0.0) <= task.deadline + 1e-3)
        limits_met = deadline_met and constraints_met(task, self.happenings)
        span = makespan if makespan is not None else self.t
        return finished, times, makespan, bool(deadline_met), bool(limits_met), span

    def _first_kept(self, cps: CompiledPlanSet, finished: bool, times: Mapping[str, float],
                    seqs: Mapping[str, tuple[str, ...]]) -> tuple[CompiledPlan | None, bool, tuple[str, ...]]:
        """The first plan, whether the run kept to it (allocation and sequences; a joint action is its
        lead's) and, if so, the constraints of its network the times broke."""
        first_cp = next((cp for cp in cps.plans if cp.plan.id == self.ctl.first_plan), None)
        alloc = {a: ((self._lead(a) or "") if a in self.joint else ag) for a, ag in self.started.items()}
        kept = first_cp is not None and finished and executed(first_cp, alloc, seqs)
        broken: tuple[str, ...] = ()
        if kept and first_cp is not None:
            broken = tuple(broken_constraints(plan_network(cps, first_cp), times))
        return first_cp, bool(kept), broken
