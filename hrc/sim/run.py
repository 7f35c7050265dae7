"""One simulated run: the task carried out on the floor in simulated time, the policy in charge.

The run loop is a discrete-event simulation with continuous motion in between (Strassmair & Taylor
2014, Fig. 5, online process, with every box simulated except the dispatcher, which is the real one):

1. at the current time, until nothing changes: the detector releases what it has seen of the person
   (`hrc.sim.detector`) to the controller; the **person** (`hrc.sim.human`) leaves for a phase, pauses at
   a waiting place, arrives, starts or ends a manipulation, leaves or comes back; the **robot** carries
   out the controller's current order (`hrc.sim.policies`: the dispatcher's decision, or the fixed
   plan) and each of its events is acknowledged to the controller at once with the time it happened;
   a phase starts only when the task graph's predecessors have ended on the floor (whoever's plan says
   what);
2. time advances to the next thing due (a manipulation's end, an arrival, an order's earliest time, a
   planned departure of a person who follows the plan, a detection, an absence), in steps short enough
   near the co-worker (`hrc.sim.floor.Floor.safe_step`), the discs moving on the floor meanwhile.

Routes: the current plan's (its detours and waiting places) when the agent stands where the plan's leg
starts, else the shortest route from where it stands. An agent with nothing to do (the plan gives it
nothing now) goes back to its start, out of the way, as the plans assume ("steps out of the way"). An
agent that stands at a location (waiting, not working) while the co-worker has been stopped by it for
`ASIDE_AFTER` seconds makes room: it walks `ASIDE` metres along the route to another location, the one
that ends farthest from the co-worker's way (and, if it is still in the way there, goes to its start),
and comes back once the co-worker is through.
The robot acknowledges an event inside its window when it happened within 2 ms of it (its clock's
resolution against the core's 1 ms ticks); `late` counts the ones outside.

Ends: when every phase has ended (finished), or unfinished: nobody can go on (`stuck`, e.g. the person
left for good with actions only they may do, or the robot stopped), the two block each other for
`stall` seconds (`deadlock`), or the time cap. What a run measures is `RunResult`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from hrc.compile.compiler import CompiledPlanSet
from hrc.model import Task
from hrc.motion import PathLibrary
from hrc.plans import must_precede
from hrc.sim.detector import Detector, Happening
from hrc.sim.floor import CONTACT, Floor, Mover
from hrc.sim.human import HumanDraws, HumanModel, draw_human
from hrc.sim.policies import (
    POLICIES,
    Controller,
    DispatchedController,
    FixedController,
    Order,
    Policy,
    SimRoute,
)
from hrc.sim.replay import broken_constraints, executed, plan_network, timepoint_times

__all__ = ["ASIDE", "ASIDE_AFTER", "RunResult", "SimContext", "SimSettings", "make_controller", "simulate_run"]

_EPS = 1e-9
ASIDE = 1.5  # m: how far an agent in the co-worker's way steps aside, along a route to another location
ASIDE_AFTER = 2.0  # s: after the co-worker has been stopped by it this long
_ACK = 0.002  # s: the robot's acknowledgement snaps into its window when this close to it


@dataclass(frozen=True, slots=True)
class SimSettings:
    """What every run of a simulation shares besides the task: the person's model, the detector's delay
    (s), the robot's slowdown band (m, beyond the safety margin), the dispatcher's tick (s: time passing
    is reported when the robot waits and nothing else was said for that long; 0, the default: never,
    every observation carries the time anyway), the stall limit and the time cap (s; default five times the
    deadline, or 600 s)."""

    human: HumanModel = HumanModel()
    detection_delay: float = 0.0
    slowdown: float = 0.0
    tick: float = 0.0
    stall: float = 60.0
    time_cap: float | None = None

    def to_json(self) -> dict:
        return {"human": self.human.to_json(), "detection_delay": self.detection_delay, "slowdown": self.slowdown,
                "tick": self.tick, "stall": self.stall, "time_cap": self.time_cap}


@dataclass(slots=True)
class SimContext:
    """What a worker needs to simulate any run: the task, its compiles by kind ("motion", "blind"), the
    real paths (the motion-aware compile's library), the settings and the seed. Plain picklable data;
    `cache` holds per-process pristine dispatchers (never pickled)."""

    task: Task
    compiles: dict[str, CompiledPlanSet]
    settings: SimSettings
    seed: int
    cache: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def paths(self) -> PathLibrary:
        return self.compiles["motion"].paths

    def __getstate__(self) -> dict:
        return {"task": self.task, "compiles": self.compiles, "settings": self.settings, "seed": self.seed}

    def __setstate__(self, state: dict) -> None:
        for k, v in state.items():
            setattr(self, k, v)
        self.cache = {}


@dataclass(frozen=True, slots=True)
class RunResult:
    """What one run measured (times in s, distances in m; see docs/simulate.md for each field)."""

    policy: str
    run: int
    finished: bool
    reason: str
    makespan: float | None
    deadline_met: bool
    limits_met: bool
    human_idle: float
    robot_idle: float
    robot_yield: float
    human_held: float
    min_distance: float | None
    overlaps: int
    plan_switches: int
    first_plan: str | None
    first_class: str | None
    final_plan: str | None
    first_kept: bool
    first_broken: tuple[str, ...]
    refused: tuple[str, ...]
    late: int
    robot_travel_excess: float
    human_sequence: tuple[str, ...]
    robot_sequence: tuple[str, ...]
    overruns: int
    absent: float
    latencies: tuple[float, ...] = field(default=(), compare=False)
    happenings: tuple[Happening, ...] = field(default=(), compare=False)
    frames: tuple[tuple[float, float, float, float, float, bool], ...] = field(default=(), compare=False)

    def to_json(self) -> dict:
        def r(x: float | None) -> float | None:
            return None if x is None or not math.isfinite(x) else round(x, 3)

        return {"run": self.run, "finished": self.finished, "reason": self.reason, "makespan": r(self.makespan),
                "deadline_met": self.deadline_met, "limits_met": self.limits_met,
                "human_idle": r(self.human_idle), "robot_idle": r(self.robot_idle),
                "robot_yield": r(self.robot_yield), "human_held": r(self.human_held),
                "min_distance": r(self.min_distance), "overlaps": self.overlaps,
                "plan_switches": self.plan_switches, "first_plan": self.first_plan, "first_class": self.first_class,
                "final_plan": self.final_plan, "first_kept": self.first_kept, "first_broken": list(self.first_broken),
                "refused": list(self.refused), "late_robot_events": self.late,
                "robot_travel_excess": r(self.robot_travel_excess), "human_sequence": list(self.human_sequence),
                "robot_sequence": list(self.robot_sequence), "overruns": self.overruns, "absent": r(self.absent)}


@dataclass(slots=True)
class _Agent:
    """One agent's state in the run loop (a mutable builder)."""

    id: str
    mover: Mover
    home: str
    loc: str | None
    mode: str = "free"  # free, travel, parked, arrived, work, home, away, gone
    action: str | None = None
    pi: int = 0  # index of the next phase of `action`
    route: SimRoute | None = None
    parked: bool = False
    work_end: float = 0.0
    work_start: float = 0.0
    duration: float = 0.0
    back_at: float | None = None
    order: Order | None = None  # the order being carried out (robot)
    aside: tuple[tuple[float, float], ...] | None = None  # the way to a spot out of the co-worker's way
    aside_mode: str = ""  # the mode to return to after making room
    predicted: float = 0.0  # predicted moving time of the current travel (robot)
    moved: float = 0.0  # moving time of the current travel so far, pauses excluded


def make_controller(ctx: SimContext, policy: Policy) -> Controller:
    """A fresh controller for one run of `policy` (a dispatcher copied from a per-process pristine one)."""
    cps = ctx.compiles[policy.compile]
    if not policy.dispatched:
        return FixedController(cps)

    key = ("dispatcher", policy.name)
    pristine = ctx.cache.get(key)
    if pristine is None:
        from hrc.dispatch import Dispatcher

        pristine = ctx.cache[key] = Dispatcher.from_compiled(cps, feasible_only=policy.feasible_only)
    # A dispatcher replaces its whole (immutable) state on every message, so a shallow copy of a fresh one
    # is a fresh one: 30 us instead of 0.3 s (workshop) for `from_compiled` (the API has no reset or copy).
    return DispatchedController(pristine.fork(), cps, ctx.paths, policy.compile == "blind")


def simulate_run(ctx: SimContext, policy: str, index: int, record: bool = False,
                 controller: Callable[[SimContext, Policy], Controller] = make_controller) -> RunResult:
    """Run `index` of `policy`: the same person (drawn from ``(seed, index)``) under every policy.

    `record` keeps the happenings and the agents' positions at every step (for figures)."""
    rng = np.random.default_rng([ctx.seed, index])
    draws = draw_human(ctx.task, ctx.settings.human, rng)
    return _Run(ctx, POLICIES[policy], draws, controller(ctx, POLICIES[policy]), record).run(index)


class _Run:
    def __init__(self, ctx: SimContext, policy: Policy, draws: HumanDraws, ctl: Controller, record: bool) -> None:
        self.ctx, self.policy, self.draws, self.ctl, self.record = ctx, policy, draws, ctl, record
        task = self.task = ctx.task
        s = ctx.settings
        self.model: HumanModel = s.human
        self.floor = Floor(task, s.slowdown)
        self.detector = Detector(s.detection_delay)
        hum = next(a for a in task.agents if a.is_human)
        rob = next(a for a in task.agents if not a.is_human)
        self.h = _Agent(hum.id, self.floor.human, hum.start, hum.start)
        self.r = _Agent(rob.id, self.floor.robot, rob.start, rob.start)
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
        self.choices = 0
        self.last_obs = 0.0
        self.last_tick = 0.0
        self.absence_done = False
        self.away_since: float | None = None
        self.absent = 0.0
        self.held_since: float | None = None
        self.late = 0
        self.frames: list[tuple[float, float, float, float, float, bool]] = []
        self.excess = 0.0
        self.reroutes = 0
        deadline = task.deadline if task.deadline is not None else 120.0
        self.cap = s.time_cap if s.time_cap is not None else 5 * deadline

    # -- bookkeeping ---------------------------------------------------------------------------------

    def emit(self, agent: _Agent, event: str, action: str | None = None, phase: str | None = None) -> None:
        h = Happening(self.t, agent.id, event, action, phase)
        self.happenings.append(h)
        if action is not None and event == "depart":
            self.started.setdefault(action, agent.id)
        if event == "end" and action is not None and phase is not None:
            self.ended.add((action, phase))
        if agent is self.h:
            self.detector.see(h)
            return
        t = self.t
        o = self.ctl.order()  # the window the robot was given for this event (arrive, park: the travel's end)
        if o is not None and (o.action, o.phase, o.event) == (action, phase, event):
            if t < o.earliest - _EPS:
                t = o.earliest if o.earliest - t <= _ACK else t
            if o.latest is not None and t > o.latest + _EPS:
                t = o.latest if t - o.latest <= _ACK else t
            if t < o.earliest - _ACK or (o.latest is not None and t > o.latest + _ACK):
                self.late += 1
        self._tell(Happening(max(t, self.last_obs), agent.id, event, action, phase))

    def _tell(self, h: Happening) -> None:
        self.last_obs = max(self.last_obs, h.t)
        self.ctl.observe(h)

    def ready(self, action: str, phase: str) -> bool:
        return all(p in self.ended for p in self.preds.get((action, phase), ()))

    def done(self) -> bool:
        return len(self.ended) == self.total

    def route_for(self, agent: _Agent, action: str, phase: str, planned: bool) -> SimRoute:
        """The plan's route for the leg if the agent stands where it starts, else the shortest one."""
        target = self.task.action(action).phase(phase).location
        if planned:
            route = self.ctl.route(agent.id, action, phase)
            if route is not None and math.dist(route.points[0], agent.mover.xy) < 1e-6 \
                    and math.dist(route.points[-1], self.ctx.paths.locations[target]) < 1e-6:
                return route
        if agent.loc is None:  # somewhere on the floor (backed off): go straight to the nearest route start
            return SimRoute((agent.mover.xy, self.ctx.paths.locations[target]))
        return SimRoute(self.ctx.paths.get(agent.id, agent.loc, target).points)

    def depart(self, agent: _Agent, action: str, phase: str, speed: float, planned: bool) -> None:
        route = self.route_for(agent, action, phase, planned)
        agent.route, agent.parked, agent.mode, agent.moved = route, False, "travel", 0.0
        length = sum(math.dist(p, q) for p, q in zip(route.points, route.points[1:], strict=False))
        agent.predicted = length / agent.mover.agent.speed
        agent.mover.set_route(route.points, speed, route.park_s)
        agent.loc = None
        self.emit(agent, "depart", action, phase)
        self._arrival_check(agent)

    def _arrival_check(self, agent: _Agent) -> bool:
        """After a travel stopped: the waiting place or the arrival."""
        if agent.mode != "travel" or agent.mover.moving:
            return False
        assert agent.action is not None
        phase = self.phases[agent.action][agent.pi]
        if agent.route is not None and agent.route.park_s is not None and not agent.parked:
            agent.parked = True
            agent.mode = "parked"
            self.emit(agent, "park", agent.action, phase)
            return True
        agent.mode = "arrived"
        agent.loc = self.task.action(agent.action).phase(phase).location
        if agent is self.r:
            self.excess += max(0.0, agent.moved - agent.predicted)
        self.emit(agent, "arrive", agent.action, phase)
        return True

    def make_room(self, agent: _Agent, other: _Agent) -> bool:
        """If `agent` stands at a location and has held `other` up for a while, step aside (module docstring)."""
        if agent.loc is None or other.mover.blocked_for < ASIDE_AFTER or agent.aside is not None:
            return False
        spot = self._aside_route(agent, other)
        if spot is None:
            return False
        agent.aside, agent.aside_mode, agent.mode = spot, agent.mode, "aside"
        agent.mover.set_route(spot, agent.mover.agent.speed)
        other.mover.blocked_for = 0.0
        return True

    def _aside_route(self, agent: _Agent, other: _Agent) -> tuple[tuple[float, float], ...] | None:
        """The first `ASIDE` metres of the route from here to some other location, the one whose end is
        farthest from the rest of the co-worker's current route."""
        assert agent.loc is not None
        m = other.mover
        ahead = [m.at(m.s + k * 0.25) for k in range(int(max(0.0, m.stop_at - m.s) / 0.25) + 1)] or [m.xy]
        best: tuple[float, tuple[tuple[float, float], ...]] | None = None
        for loc in sorted(self.ctx.paths.locations):
            if loc == agent.loc:
                continue
            try:
                path = self.ctx.paths.get(agent.id, agent.loc, loc)
            except KeyError:
                continue
            prefix = _prefix(path.points, min(ASIDE, path.length * 0.8))
            end = prefix[-1]
            score = min(math.dist(end, p) for p in ahead)
            if best is None or score > best[0]:
                best = (score, prefix)
        return None if best is None else best[1]

    def reroute(self, agent: _Agent, other: _Agent) -> bool:
        """`agent` has been stopped by the standing (or as stuck) co-worker for a while: go round it (the
        roadmap without the edges the co-worker's disc blocks, `hrc.motion.detours`). False if there is no
        way round or the co-worker stands at the agent's goal (then it is the co-worker's turn to make room)."""
        m, o = agent.mover, other.mover
        goal = m.at(m.length)
        stands = not o.moving or o.blocked_for >= ASIDE_AFTER  # standing, or as stuck as this agent
        if m.blocked_for < ASIDE_AFTER or not stands or not m.moving or agent.mode != "travel":
            return False
        reach = m.agent.radius + o.agent.radius + self.task.safety_margin
        if math.dist(o.xy, goal) < reach:
            return False
        points = None
        for back in (0.0, 0.4, 0.8, 1.2):  # from where it stands, or from a little back along its way
            if back > m.s:
                break
            start = m.at(m.s - back)
            points = _round(self.task, self.ctx.paths, m.agent.radius + self.task.safety_margin, o.agent.radius,
                            o.xy, start, goal)
            if points is not None:
                if back > 0:
                    points = [m.at(m.s - x) for x in np.linspace(0.0, back, 4)[:-1]] + points
                break
        m.blocked_for = 0.0
        if points is None:
            return False
        stop = None if agent.route is None or agent.route.park_s is None or agent.parked else len(points)
        speed = m.speed
        m.set_route(tuple(points), speed)
        if stop is not None and agent.route is not None:
            agent.route = SimRoute(tuple(points), agent.route.park, _length(points))
        self.reroutes += 1
        return True

    def come_back(self, agent: _Agent, other: _Agent) -> bool:
        """After making room: back to the location once the co-worker is through (or not coming)."""
        if agent.mode == "aside":
            if not agent.mover.moving:
                agent.mode = "aside_wait"
                return True
            return False
        assert agent.aside is not None and agent.loc is not None
        here = self.ctx.paths.locations[agent.loc]
        m = other.mover
        if m.blocked_for >= ASIDE_AFTER and agent.home != agent.loc:  # still in the way: wait at home instead
            way = _round(self.task, self.ctx.paths, agent.mover.agent.radius + self.task.safety_margin,
                         m.agent.radius, m.xy, agent.mover.xy, self.ctx.paths.locations[agent.home])
            m.blocked_for = 0.0
            if way is not None:
                agent.mover.set_route(tuple(way), agent.mover.agent.speed)
                agent.aside = self.ctx.paths.get(agent.id, agent.loc, agent.home).points  # back: home -> loc
                agent.mode = "aside"
                return True
        coming = m.moving and math.dist(m.at(m.stop_at), here) < 1e-6
        reach = agent.mover.agent.radius + m.agent.radius + self.task.safety_margin + 0.3
        if coming or math.dist(m.xy, here) < reach:
            return False
        agent.mover.set_route(agent.aside[::-1], agent.mover.agent.speed)
        agent.mode = "returning"
        return True

    def _aside_step(self, a: _Agent, other: _Agent) -> bool:
        if a.mode == "travel" and self.reroute(a, other):
            return True
        if a.mode in ("aside", "aside_wait"):
            return self.come_back(a, other)
        if a.mode == "returning":
            if a.mover.moving:
                return False
            a.mode, a.aside = a.aside_mode, None
            return True
        if a.mode in ("free", "arrived") and not (a.mode == "arrived" and self._may_start(a)):
            return self.make_room(a, other)
        return False

    def _may_start(self, a: _Agent) -> bool:
        return a.action is not None and self.ready(a.action, self.phases[a.action][a.pi])

    def go_home(self, agent: _Agent) -> bool:
        if agent.loc is None or agent.loc == agent.home:
            return False
        path = self.ctx.paths.get(agent.id, agent.loc, agent.home)
        agent.mover.set_route(path.points, agent.mover.agent.speed)
        agent.mode, agent.loc = "home", None
        return True

    # -- the person ------------------------------------------------------------------------------------

    def allowed(self) -> list[str]:
        """Actions the task graph allows the person to take now (module docstring of hrc.sim.human)."""
        out = []
        for action in self.task.actions:
            if action.id in self.started or self.h.id not in action.agents:
                continue
            if all(b in self.started for b, a in self.before if a == action.id):
                out.append(action.id)
        return out

    def choose(self) -> str | None:
        m = self.model
        if m.choice == "follow" and not self.ctl.stopped:
            return self.ctl.human_next(self.started)  # the plan's order is valid: no need to filter it
        allowed = self.allowed()
        if not allowed:
            return None
        if m.choice == "free":
            u = self.draws.choice[min(self.choices, len(self.draws.choice) - 1)]
            return allowed[min(int(u * len(allowed)), len(allowed) - 1)]
        order = m.preferred or self.task.action_ids
        ranked = [a for a in order if a in allowed] + [a for a in allowed if a not in order]
        return ranked[0]

    def guide(self, action: str, phase: str, event: str) -> float:
        """When a person who follows the plan does `event` (now if the plan does not say)."""
        if self.model.choice != "follow" or self.ctl.stopped:
            return self.t
        g = self.ctl.guide_time(action, phase, event)
        return self.t if g is None else g

    def _home_or_aside(self, a: _Agent, other: _Agent) -> bool | None:
        """The steps both agents share: going home, and making room for `other`. True or False when one
        of them decided this step (something happened, or nothing may), None when the agent's own rules
        decide."""
        if a.mode == "home":
            if not a.mover.moving:
                a.mode, a.loc = "free", a.home
                return True
            return False
        if self._aside_step(a, other):
            return True
        if a.mode in ("aside", "aside_wait", "returning"):
            return False
        return None

    def human(self) -> bool:
        a, t = self.h, self.t
        if a.mode == "gone":
            return False
        if a.mode == "away":
            free = math.hypot(a.mover.xy[0] - self.r.mover.xy[0], a.mover.xy[1] - self.r.mover.xy[1]) \
                - a.mover.agent.radius - self.r.mover.agent.radius
            if a.back_at is not None and t >= a.back_at - _EPS and free >= CONTACT:
                a.mover.present = True
                a.mode = "free"
                self.absent += t - (self.away_since or t)
                self.emit(a, "back")
                return True
            return False
        moved = self._home_or_aside(a, self.r)
        if moved is not None:
            return moved
        if a.mode == "free":
            if a.action is None:
                absence = self.draws.absence
                if absence is not None and not self.absence_done and t >= absence[0] - _EPS:
                    self.absence_done = True
                    a.mode = "away" if absence[1] is not None else "gone"
                    a.back_at = None if absence[1] is None else t + absence[1]
                    self.away_since = t
                    a.mover.present = False
                    self.emit(a, "away")
                    return True
                nxt = self.choose()
                if nxt is None:  # nothing to do now: step out of the way
                    return self.go_home(a)
                phase = self.phases[nxt][0]
                if t < self.guide(nxt, phase, "depart") - _EPS:
                    return False
                a.action, a.pi = nxt, 0
                self.choices += 1
            action = a.action
            assert action is not None
            phase = self.phases[action][a.pi]
            if t < self.guide(action, phase, "depart") - _EPS:
                return False
            pace = self.draws.pace[(action, phase)]
            self.depart(a, action, phase, a.mover.agent.speed / pace, self.model.choice == "follow")
            return True
        if a.mode == "travel":
            return self._arrival_check(a)
        assert a.action is not None
        phase = self.phases[a.action][a.pi]
        if a.mode == "parked":
            if t >= self.guide(a.action, phase, "unpark") - _EPS:
                a.mode = "travel"
                a.mover.resume()
                self.emit(a, "unpark", a.action, phase)
                return True
            return False
        if a.mode == "arrived":
            if self.ready(a.action, phase) and t >= self.guide(a.action, phase, "start") - _EPS:
                a.mode, a.work_start = "work", t
                a.work_end = t + self.draws.durations[(a.action, phase)]
                self.emit(a, "start", a.action, phase)
                return True
            return False
        if a.mode == "work" and t >= a.work_end - _EPS:
            self.emit(a, "end", a.action, phase)
            self._next_phase(a)
            return True
        return False

    def _next_phase(self, a: _Agent) -> None:
        assert a.action is not None
        a.pi += 1
        if a.pi >= len(self.phases[a.action]):
            a.action, a.pi = None, 0
        a.mode = "free"

    # -- the robot -------------------------------------------------------------------------------------

    def robot(self) -> bool:
        a, t = self.r, self.t
        o = self.ctl.order()
        moved = self._home_or_aside(a, self.h)
        if moved is not None:
            return moved
        if a.mode == "free":
            if o is None:
                return False if self.ctl.stopped else self.go_home(a)
            if o.event != "depart" or t < o.earliest - _EPS:
                return False
            a.action, a.pi, a.order = o.action, self.phases[o.action].index(o.phase), o
            self.depart(a, o.action, o.phase, a.mover.agent.speed, True)
            return True
        if a.mode == "travel":
            return self._arrival_check(a)
        assert a.action is not None
        phase = self.phases[a.action][a.pi]
        mine = o is not None and (o.action, o.phase) == (a.action, phase)
        if a.mode == "parked":
            if mine and o is not None and o.event == "unpark" and t >= o.earliest - _EPS:
                a.order = o
                a.mode = "travel"
                a.mover.resume()
                self.emit(a, "unpark", a.action, phase)
                return True
            return False
        if a.mode == "arrived":
            if mine and o is not None and o.event == "start" and t >= o.earliest - _EPS and self.ready(a.action, phase):
                bounds = self.task.action(a.action).phase(phase).duration(a.id)
                a.order, a.mode, a.work_start = o, "work", t
                a.duration = bounds.lb + self.draws.robot[(a.action, phase)] * (bounds.ub - bounds.lb)
                self.emit(a, "start", a.action, phase)
                return True
            return False
        if a.mode == "work":
            end = a.work_start + a.duration
            if mine and o is not None and o.event == "end":
                end = max(end, o.earliest)
                if o.latest is not None:
                    end = min(end, o.latest)
                a.order = o
            a.work_end = end
            if t >= end - _EPS:
                self.emit(a, "end", a.action, phase)
                self._next_phase(a)
                return True
        return False

    # -- the loop --------------------------------------------------------------------------------------

    def deliver(self) -> bool:
        out = self.detector.release(self.t)
        for h in out:
            self._tell(Happening(max(h.t, self.last_obs), h.agent, h.event, h.action, h.phase))
        return bool(out)

    def next_time(self) -> float:
        t = self.t
        cands = [self.cap, self.detector.next_due()]
        for ag in (self.h, self.r):
            if ag.mover.moving:
                cands.append(t + self.floor.time_to_stop(ag.mover))
                cands.append(t + self.floor.safe_step())
            if ag.mode == "work":
                cands.append(ag.work_end)
        if self.h.mode == "away" and self.h.back_at is not None:
            cands.append(max(self.h.back_at, t + 0.1))
        absence = self.draws.absence
        if absence is not None and not self.absence_done:
            cands.append(absence[0])
        if self.h.mode in ("free", "parked", "arrived") and self.model.choice == "follow" and not self.ctl.stopped:
            cands += self._guide_times()
        o = self.ctl.order()
        if o is not None and o.event in ("depart", "unpark", "start"):
            cands.append(o.earliest)
        if isinstance(self.ctl, DispatchedController) and self.ctx.settings.tick > 0 and not self.done():
            if o is None or o.event == "wait" or self.h.mode in ("free", "parked", "arrived"):
                cands.append(max(self.last_obs, self.last_tick) + self.ctx.settings.tick)
        future = [c for c in cands if c > t + _EPS]
        return min(future) if future else math.inf

    def _guide_times(self) -> list[float]:
        a = self.h
        out = []
        if a.mode == "free":
            nxt = a.action or self.choose()
            if nxt is not None:
                g = self.ctl.guide_time(nxt, self.phases[nxt][a.pi if a.action else 0], "depart")
                if g is not None:
                    out.append(g)
        elif a.action is not None:
            ev = "unpark" if a.mode == "parked" else "start"
            g = self.ctl.guide_time(a.action, self.phases[a.action][a.pi], ev)
            if g is not None:
                out.append(g)
        return out

    def run(self, index: int) -> RunResult:
        reason = ""
        stall_since: float | None = None
        while True:
            for _ in range(100):
                changed = self.deliver()
                changed = self.human() or changed
                changed = self.robot() or changed
                if not changed:
                    break
            if self.done():
                break
            if self.t >= self.cap - _EPS:
                reason = "time cap"
                break
            nt = self.next_time()
            if not math.isfinite(nt):
                reason = "stuck: " + self._why_stuck()
                break
            tick_due = max(self.last_obs, self.last_tick) + self.ctx.settings.tick
            before = (self.h.mover.s, self.r.mover.s, len(self.happenings))
            self.advance(nt - self.t)
            for ag in (self.h, self.r):
                if ag.mode == "travel" and ag.mover.moving:
                    ag.moved += nt - self.t
            self.t = nt
            if isinstance(self.ctl, DispatchedController) and self.ctx.settings.tick > 0 and abs(nt - tick_due) < _EPS:
                self.last_tick = nt
                self.ctl.tick(max(nt, self.last_obs))
                self.last_obs = max(nt, self.last_obs)
            held = (self.h.mover.moving or self.r.mover.moving) and before[:2] == (self.h.mover.s, self.r.mover.s)
            if held:
                stall_since = self.t if stall_since is None else stall_since
                if self.t - stall_since > self.ctx.settings.stall:
                    reason = "deadlock: the two block each other"
                    break
            else:
                stall_since = None
        return self._result(index, reason)

    def advance(self, h: float) -> None:
        if h <= 0:
            return
        self.floor.advance(h)
        if self.record:
            hx, hy = self.h.mover.xy
            rx, ry = self.r.mover.xy
            self.frames.append((self.t + h, hx, hy, rx, ry, self.h.mover.present))

    def _why_stuck(self) -> str:
        if self.h.mode == "gone":
            return "the person left for good"
        if self.ctl.stopped:
            return "the robot stopped (no plan left)"
        o = self.ctl.order()
        return f"waiting: robot {self.r.mode} ({o}), person {self.h.mode}"

    def _result(self, index: int, reason: str) -> RunResult:
        task = self.task
        finished = self.done()
        times = timepoint_times(self.happenings)
        ends = [h.t for h in self.happenings if h.event == "end"]
        makespan = max(ends) if finished and ends else None
        deadline_met = finished and (task.deadline is None or (makespan or 0.0) <= task.deadline + 1e-3)
        limits_met = deadline_met and self._constraints_met()
        span = makespan if makespan is not None else self.t
        human_busy, robot_busy = self._busy(times, span)
        human_seq = tuple(dict.fromkeys(h.action for h in self.happenings
                                        if h.agent == self.h.id and h.event == "depart" and h.action))
        robot_seq = tuple(dict.fromkeys(h.action for h in self.happenings
                                        if h.agent == self.r.id and h.event == "depart" and h.action))
        ctl = self.ctl
        first = ctl.first_plan
        cps = self.ctx.compiles[self.policy.compile]
        first_cp = next((cp for cp in cps.plans if cp.plan.id == first), None)
        alloc = {a: ag for a, ag in self.started.items()}
        kept = first_cp is not None and finished and executed(first_cp, alloc, {self.h.id: human_seq,
                                                                                 self.r.id: robot_seq})
        broken: tuple[str, ...] = ()
        if kept and first_cp is not None:
            broken = tuple(broken_constraints(plan_network(cps, first_cp), times))
        if self.h.mode == "away" and self.away_since is not None:
            self.absent += span - self.away_since
        min_free = self.floor.min_free
        return RunResult(
            policy=self.policy.name, run=index, finished=finished, reason="" if finished else reason,
            makespan=makespan, deadline_met=bool(deadline_met), limits_met=bool(limits_met),
            human_idle=max(0.0, span - human_busy - self.absent), robot_idle=max(0.0, span - robot_busy),
            robot_yield=self.floor.robot.held, human_held=self.floor.human.held,
            min_distance=None if not math.isfinite(min_free) else min_free, overlaps=self.floor.overlaps,
            plan_switches=ctl.switches, first_plan=first, first_class=ctl.first_class, final_plan=ctl.plan_id,
            first_kept=bool(kept), first_broken=broken, refused=tuple(ctl.refused), late=self.late,
            robot_travel_excess=self.excess, human_sequence=human_seq, robot_sequence=robot_seq,
            overruns=sum(1 for k in self.draws.overrun if times.get(f"{self.h.id}.{k[1]}.{k[0]}.end") is not None),
            absent=self.absent, latencies=tuple(ctl.latencies),
            happenings=tuple(self.happenings) if self.record else (), frames=tuple(self.frames))

    def _constraints_met(self) -> bool:
        """The task's temporal constraints, on the times of the events whoever did them."""
        at: dict[str, float] = {}
        for h in self.happenings:
            if h.action and h.phase and h.event in ("start", "end"):
                at.setdefault(f"{h.action}.{h.phase}.{h.event}", h.t)
        for c in self.task.constraints:
            a, b = at.get(str(c.source)), at.get(str(c.target))
            if a is None or b is None or not (c.bounds.lb - 1e-3 <= b - a <= c.bounds.ub + 1e-3):
                return False
        return True

    def _busy(self, times: dict[str, float], span: float) -> tuple[float, float]:
        busy = {self.h.id: 0.0, self.r.id: 0.0}
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
        return busy[self.h.id], busy[self.r.id]


def _prefix(points: tuple[tuple[float, float], ...], length: float) -> tuple[tuple[float, float], ...]:
    """The polyline `points` cut after `length` metres."""
    out = [points[0]]
    left = length
    for p, q in zip(points, points[1:], strict=False):
        d = math.dist(p, q)
        if d >= left:
            f = left / d if d > 0 else 0.0
            out.append((p[0] + f * (q[0] - p[0]), p[1] + f * (q[1] - p[1])))
            return tuple(out)
        out.append(q)
        left -= d
    return tuple(out)


def _length(points: Sequence[tuple[float, float]]) -> float:
    return sum(math.dist(p, q) for p, q in zip(points, points[1:], strict=False))


def _round(task: Task, paths: PathLibrary, clearance: float, other_radius: float, other: tuple[float, float],
           here: tuple[float, float], goal: tuple[float, float]) -> list[tuple[float, float]] | None:
    """A route from `here` to `goal` keeping `clearance` from obstacles and from a standing disc at `other`."""
    import shapely

    from hrc.model import Obstacle, Workspace
    from hrc.motion.detours import blocked_region
    from hrc.motion.planner import Roadmap
    from hrc.motion.world import World

    roadmap = paths.roadmaps.get(clearance)
    if roadmap is None:
        return None
    region = blocked_region([(other,)], other_radius + 0.02)
    zone = shapely.union_all([p.buffer(clearance) for p in region])
    if zone.intersects(shapely.Point(here)) or zone.intersects(shapely.Point(goal)):
        return None
    ws = task.workspace
    extra = tuple(Obstacle(f"co-worker{i}", tuple((float(x), float(y)) for x, y in p.exterior.coords[:-1]))
                  for i, p in enumerate(region))
    world = World(Workspace(ws.name, ws.bounds, ws.obstacles + extra, ws.locations))
    pts = np.asarray(roadmap.points)
    ij = np.array([(i, j) for i, j, _ in roadmap.edges])
    lines = shapely.linestrings(np.stack([pts[ij[:, 0]], pts[ij[:, 1]]], axis=1))
    hit = shapely.intersects(lines, zone)
    pruned = Roadmap(roadmap.clearance, roadmap.points, [e for e, h in zip(roadmap.edges, hit, strict=True) if not h])
    if not (world.point_clear(*here, clearance) and world.point_clear(*goal, clearance)):
        return None
    found = pruned.routes(world, [here, goal])[(0, 1)]
    return None if found is None else [(float(x), float(y)) for x, y in found]
