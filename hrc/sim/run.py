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
starts, else the shortest route from where it stands (the roadmap's, `hrc.sim.giveway`, from a spot
off the locations). An agent with nothing to do (the plan gives it nothing now) goes back to its start,
out of the way, as the plans assume ("steps out of the way"). A leg to where the agent already stands
(two phases at one place) arrives at once.

**Standoffs** (the two keep each other from going on) are resolved as co-workers on a real floor do:
one makes room or goes round the other (`hrc.sim.standoff`).
The robot acknowledges an event inside its window when it happened within 2 ms of it (its clock's
resolution against the core's 1 ms ticks); `late` counts the ones outside.

Ends: when every phase has ended (finished), or unfinished: nobody can go on (`stuck`: nothing is due
any more, e.g. the person left for good with actions only they may do, or the robot stopped), nobody
has moved for `stall` seconds while someone wanted to (`deadlock`: a standoff the rules above did not
resolve), or the time cap. What a run measures is `RunResult`.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from hrc.compile.compiler import CompiledPlanSet
from hrc.detect.sensor import Sensor, SensorModel
from hrc.errors import SimulationError
from hrc.model import Task
from hrc.motion import PathLibrary, separation
from hrc.sim.agents import acknowledged, add_busy
from hrc.sim.detection import Detection, detection_of
from hrc.sim.detector import Detector, Happening
from hrc.sim.floor import CONTACT, MIN_STEP, Floor
from hrc.sim.giveway import Ways
from hrc.sim.human import HumanDraws, HumanModel, draw_human
from hrc.sim.policies import (
    POLICIES,
    Controller,
    DispatchedController,
    FixedController,
    Order,
    Policy,
)
from hrc.sim.ssm import SsmMeasures
from hrc.sim.standoff import ASIDE_AFTER, WAIT_STEP, AgentState, Standoffs
from hrc.sim.team_floor import is_team

__all__ = ["AgentFrame", "RunResult", "SimContext", "SimSettings", "make_controller", "simulate_run"]

_EPS = 1e-9
_DETECTED = ("depart", "arrive", "start", "end")  # the events a motion detector gives
_DRAIN = 12.0  # s after the last phase in which a motion detector may still give the person's last events
_QUIET = 30.0  # s with nothing due but the tracker's positions: nobody can go on (stuck)


AgentFrame = tuple[float, tuple[tuple[float, float, bool], ...], tuple[tuple[str, str], ...]]
"""A team's recorded frame (issue 37): its time, each agent's ``(x, y, present)`` in task order, and the
(person, robot) pairs co-working then (`hrc.sim.team_floor.TeamFloor.cowork`)."""


@dataclass(frozen=True, slots=True)
class SimSettings:
    """What every run of a simulation shares besides the task: the person's model, the detector's delay
    (s), the robot's slowdown band (m, beyond the safety margin), the dispatcher's tick (s: time passing
    is reported when the robot waits and nothing else was said for that long; 0, the default: never,
    every observation carries the time anyway), the stall limit and the time cap (s; default five times the
    deadline, or 600 s); the `detector` ("buttons": the person's events, `detection_delay` late; "motion":
    their position through the `sensor` to `hrc.detect`'s detector, for the dispatched policies)."""

    human: HumanModel = HumanModel()
    detection_delay: float = 0.0
    slowdown: float = 0.0
    tick: float = 0.0
    stall: float = 60.0
    time_cap: float | None = None
    detector: str = "buttons"
    sensor: SensorModel = SensorModel()

    def to_json(self) -> dict:
        out = {"human": self.human.to_json(), "detection_delay": self.detection_delay, "slowdown": self.slowdown,
               "tick": self.tick, "stall": self.stall, "time_cap": self.time_cap}
        if self.detector != "buttons":  # a buttons simulation's file stays as it was
            out.update(detector=self.detector, sensor=self.sensor.to_json())
        return out

    @property
    def motion(self) -> bool:
        """The person's position goes to a motion detector in front of the dispatcher (`hrc.detect`), not
        their events (``--detector motion``)."""
        return self.detector == "motion"


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
    standoffs: int
    robot_aside: float
    human_aside: float
    min_distance: float | None
    overlaps: int
    plan_switches: int
    first_plan: str | None
    first_class: str | None
    first_blocked: bool
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
    detection: Detection | None = None
    ssm: SsmMeasures | None = None  # speed and separation monitoring's counts (a task with safety:)
    late_observations: int | None = None  # answers with a deviation (late); None: no delay stated
    first_sensing_class: str | None = None  # the first plan's class in the compile (under its sensing), with it
    latencies: tuple[float, ...] = field(default=(), compare=False)
    on_demand: dict | None = None  # compile on demand's misses and recovery (`hrc.sim.on_demand`), or None
    joint: dict | None = None  # a task with joint actions only: co-work and the joint starts (`_Run._joint_result`)
    compile_seconds: tuple[float, ...] = field(default=(), compare=False)  # its compiles' wall times
    happenings: tuple[Happening, ...] = field(default=(), compare=False)
    frames: tuple[tuple[float, float, float, float, float, bool], ...] = field(default=(), compare=False)
    cowork_frames: tuple[bool, ...] = field(default=(), compare=False)  # per frame, a joint task's: in co-work
    team: dict | None = None  # a team's (issue 37): per agent and per pair (`hrc.sim.team_run`); None for 1+1
    agent_frames: tuple[AgentFrame, ...] = field(default=(), compare=False)  # a team's recorded frames

    def to_json(self) -> dict:
        def r(x: float | None) -> float | None:
            return None if x is None or not math.isfinite(x) else round(x, 3)

        return {"run": self.run, "finished": self.finished, "reason": self.reason, "makespan": r(self.makespan),
                "deadline_met": self.deadline_met, "limits_met": self.limits_met,
                "human_idle": r(self.human_idle), "robot_idle": r(self.robot_idle),
                "robot_yield": r(self.robot_yield), "human_held": r(self.human_held), "standoffs": self.standoffs,
                "robot_aside": r(self.robot_aside), "human_aside": r(self.human_aside),
                "min_distance": r(self.min_distance), "overlaps": self.overlaps,
                "plan_switches": self.plan_switches, "first_plan": self.first_plan, "first_class": self.first_class,
                "first_blocked": self.first_blocked, "final_plan": self.final_plan, "first_kept": self.first_kept,
                "first_broken": list(self.first_broken),
                "refused": list(self.refused), "late_robot_events": self.late,
                "robot_travel_excess": r(self.robot_travel_excess), "human_sequence": list(self.human_sequence),
                "robot_sequence": list(self.robot_sequence), "overruns": self.overruns, "absent": r(self.absent),
                **({} if self.late_observations is None else {"late_observations": self.late_observations,
                                                              "first_sensing_class": self.first_sensing_class}),
                **({} if self.detection is None else {"detection": self.detection.to_json()}),
                **({} if self.ssm is None else {"ssm": self.ssm.to_json()}),
                **({} if self.on_demand is None else {"on_demand": self.on_demand}),
                **({} if self.joint is None else {"joint": self.joint}),
                **({} if self.team is None else {"team": self.team})}


def make_controller(ctx: SimContext, policy: Policy) -> Controller:
    """A fresh controller for one run of `policy` (a dispatcher copied from a per-process pristine one)."""
    cps = ctx.compiles[policy.compile]
    if not policy.dispatched:
        return FixedController(cps)

    motion = ctx.settings.motion
    key = ("dispatcher", policy.name, motion)
    pristine = ctx.cache.get(key)
    if pristine is None:
        from hrc.dispatch import Dispatcher

        if motion:
            from hrc.detect import DetectingDispatcher, DetectParams

            pristine = ctx.cache[key] = DetectingDispatcher.from_compiled(
                cps, feasible_only=policy.feasible_only, threads=1,
                params=DetectParams(sigma=max(ctx.settings.sensor.sigma, 0.01)))
        else:
            pristine = ctx.cache[key] = Dispatcher.from_compiled(cps, feasible_only=policy.feasible_only, threads=1)
    # A dispatcher replaces its whole (immutable) state on every message, so a shallow copy of a fresh one
    # is a fresh one: 30 us instead of 0.3 s (workshop) for `from_compiled` (the API has no reset or copy).
    ctl = DispatchedController(pristine.fork(), cps, ctx.paths, policy.compile == "blind")
    if cps.search and not motion and not policy.feasible_only:  # a searched compile: compile on demand
        from hrc.sim.on_demand import attach

        ctl.on_demand = attach(ctx.cache, policy.compile, cps, ctl.d)
    return ctl


def simulate_run(ctx: SimContext, policy: str, index: int, record: bool = False,
                 controller: Callable[[SimContext, Policy], Controller] = make_controller) -> RunResult:
    """Run `index` of `policy`: the same person (drawn from ``(seed, index)``) under every policy.

    `record` keeps the happenings and the agents' positions at every step (for figures). One person and
    one robot: a team runs on the team floor (`hrc.sim.team_run.simulate_team_run`; `hrc.sim.montecarlo.run_one`
    picks), `SimulationError` here."""
    if is_team(ctx.task):
        raise SimulationError(f"{ctx.task.source}: agents: a team runs in hrc.sim.team_run, not on the one-pair floor")
    rng = np.random.default_rng([ctx.seed, index])
    draws = draw_human(ctx.task, ctx.settings.human, rng)
    ctl = controller(ctx, POLICIES[policy])
    sensor = None
    if ctx.settings.motion and isinstance(ctl, DispatchedController):  # its own numbers: the same person
        sensor = Sensor(ctx.settings.sensor, np.random.default_rng([ctx.seed, index, 28]))
    return _Run(ctx, POLICIES[policy], draws, ctl, record, sensor).run(index)


_Pair = tuple[AgentState, AgentState]


class _Run(Standoffs[AgentState]):
    ctx: SimContext
    ctl: Controller

    def __init__(self, ctx: SimContext, policy: Policy, draws: HumanDraws, ctl: Controller, record: bool,
                 sensor: Sensor | None = None) -> None:
        self.ctx, self.policy, self.draws, self.ctl, self.record = ctx, policy, draws, ctl, record
        self.sensor = sensor
        # when the last phase ended: (t, closest, overlaps, robot held, person held); the rest is the drain
        self.finished_at: tuple[float, float, int, float, float] | None = None
        self.quiet_since: float | None = None
        task = self.task = ctx.task
        s = ctx.settings
        self.model: HumanModel = s.human
        self.floor = Floor(task, s.slowdown)
        self.detector = Detector(s.detection_delay)
        hum = next(a for a in task.agents if a.is_human)
        rob = next(a for a in task.agents if not a.is_human)
        self.h = AgentState(hum.id, self.floor.human, hum.start, hum.start)
        self.r = AgentState(rob.id, self.floor.robot, rob.start, rob.start)
        self._init_task(task, s.time_cap)
        self._joint_init()
        self.choices = 0
        self.last_obs = 0.0
        self.last_tick = 0.0
        self.absence_done = False
        self.away_since: float | None = None
        self.absent = 0.0
        self.held_since: float | None = None
        self.late = 0
        self._dctl = ctl if isinstance(ctl, DispatchedController) else None  # (asked at every step)
        self.frames: list[tuple[float, float, float, float, float, bool]] = []
        self.excess = 0.0
        self.standoffs = 0
        self.room_for: AgentState | None = None
        self.ways = Ways(self.floor.world, ctx.paths, ctx.cache)

    # -- bookkeeping ---------------------------------------------------------------------------------

    def emit(self, agent: AgentState, event: str, action: str | None = None, phase: str | None = None) -> None:
        h = Happening(self.t, agent.id, event, action, phase)
        self.happenings.append(h)
        if action is not None and event == "depart":
            self.started.setdefault(action, agent.id)
        if self.joint and action is not None:
            self._joint_emit(agent, event, action, phase)
        if event == "end" and action is not None and phase is not None:
            self.ended.add((action, phase))
        if agent is self.h:
            if self.sensor is None or action is None:  # a tracker sees positions, not away and back
                self.detector.see(h)
            else:
                assert isinstance(self.ctl, DispatchedController)
                self.ctl.known.append(h)  # the person knows what they did (their guide: `_guide`)
            return
        # against the window the robot was given for this event (arrive, park: the travel's end)
        t, late = acknowledged(self.t, self.ctl.order(), event, action, phase)
        self.late += late
        self._tell(Happening(max(t, self.last_obs), agent.id, event, action, phase))

    def _robot(self, agent: AgentState) -> bool:
        return agent is self.r

    # -- the standoff rules' hooks (`hrc.sim.standoff.Standoffs`): the one pair ----------------------------

    def _reach(self, a: AgentState, b: AgentState) -> float:
        robot = next(x for x in self.task.agents if not x.is_human)
        return separation.reach(self.task, robot.speed)

    def _yields(self, x: AgentState, y: AgentState) -> tuple[_Pair, _Pair]:
        return (self.r, self.h), (self.h, self.r)

    def _before(self, a: AgentState, b: AgentState) -> bool:
        return a is self.h

    def _halted(self, a: AgentState) -> bool:
        return a is self.r and self.ctl.stopped

    def _guided(self, a: AgentState, action: str, phase: str) -> bool:
        return a is not self.h or math.isfinite(self.guide(action, phase, "start"))

    def _room_made(self, g: AgentState, o: AgentState) -> None:
        self.room_for = o

    def _room_made_for(self, a: AgentState, b: AgentState) -> AgentState | None:
        return self.room_for

    # -- the person ------------------------------------------------------------------------------------

    def allowed(self) -> list[str]:
        """Actions the task graph allows the person to take now (module docstring of hrc.sim.human)."""
        out = []
        taken = self._taken()
        for action in self.task.actions:
            if action.id in taken or self.h.id not in action.agents:
                continue
            if all(b in taken for b, a in self.before if a == action.id):  # (a joint one: when they joined it)
                out.append(action.id)
        return out

    def choose(self) -> str | None:
        m = self.model
        if m.choice == "follow" and not self.ctl.stopped:
            return self.ctl.human_next(self._taken())  # the plan's order is valid: no need to filter it
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

    def _home_or_aside(self, a: AgentState, other: AgentState) -> bool | None:
        """The steps both agents share: going home, and giving way to `other`. True or False when one of
        them decided this step (something happened, or nothing may), None when the agent's own rules
        decide."""
        mode = a.mode
        if mode not in ("home", "aside", "aside_wait", "returning"):  # not going home, not making room: a
            m = a.mover  # standoff only when held up `ASIDE_AFTER` s on its way (`_give_way`, `_stuck`)
            if mode == "work" or not m.moving or m.blocked_for < ASIDE_AFTER:
                return None
        if self._home_reached(a):
            return True
        if self._give_way(a, (other,)):
            return True
        if a.mode in ("home", "aside", "aside_wait", "returning"):
            return False
        return None

    def human(self) -> bool:
        a, t = self.h, self.t
        if a.mode == "gone":
            return False
        if a.mode == "away":
            if a.back_at is None or t < a.back_at - _EPS:
                return False
            reach = a.mover.agent.radius + self.r.mover.agent.radius
            if math.dist(a.mover.xy, self.r.mover.xy) - reach < CONTACT:  # the robot stands where they left:
                home = self.ctx.paths.locations[a.home]  # they come back in at their start
                if math.dist(home, self.r.mover.xy) - reach < self.task.safety_margin:
                    return False
                self.floor.place(a.mover, home)
                a.loc = a.home
            a.mover.present = True
            a.mode = "free"
            self.absent += t - (self.away_since or t)
            self.emit(a, "back")
            return True
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
            return t >= self.guide(a.action, phase, "unpark") - _EPS and self._unpark(a, phase)
        if self.joint and a.action in self.joint:  # the robot starts and ends it (`_joint_start`)
            return self._joint_done(a, phase)
        if a.mode == "arrived":
            if self.ready(a.action, phase) and t >= self.guide(a.action, phase, "start") - _EPS:
                a.mode, a.work_start = "work", t
                a.work_end = t + self.draws.durations[(a.action, phase)]
                self.emit(a, "start", a.action, phase)
                return True
            return False
        return a.mode == "work" and self._work_done(a, phase)

    # -- joint actions (issue 37) ----------------------------------------------------------------------
    # A joint action is on both agents' legs: each walks or drives there (depart, arrive); the robot starts
    # it when both are there and ends it when both roles are done (the person's drawn time and its own: the
    # duration is contingent); the person works from the robot's start and goes on when it ends. Co-work
    # at its spot (`Floor.cowork`, docs/motion.md "Joint actions"): the robot standing there over a stay
    # that covers the joint phase, the person walking up to the spot, staying at it or walking away.
    # A task without joint actions takes none of these paths (`self.joint` empty).

    def _joint_init(self) -> None:
        task = self.task
        self.joint = frozenset(a.id for a in task.actions if a.joint)
        self.joint_spots = frozenset(p.location for a in task.actions if a.joint for p in a.phases)
        self.joined: set[str] = set()  # joint actions the person has left for
        self.person_arrived: set[tuple[str, str]] = set()  # (action, phase) the person has arrived at
        self.last: dict[str, tuple[str, str]] = {}  # agent -> its last phase ended (a joint one: both agents')
        self.joint_stay: dict[str, str] = {}  # agent -> the spot of a joint phase of its stay (until it is elsewhere)
        self.told: set[tuple[str, str]] = set()  # joint phases the robot was told to start
        self.told_early: set[tuple[str, str]] = set()  # ... before the person had arrived there
        self.cowork_frames: list[bool] = []  # recorded with the frames (`RunResult.cowork_frames`)
        self._told: object = None

    def _taken(self) -> dict[str, str]:
        """`started` as the person reads it: a joint action the robot has left for is still theirs to go to."""
        if not self.joint:
            return self.started
        return {a: ag for a, ag in self.started.items() if a not in self.joint or a in self.joined}

    def _joint_emit(self, agent: AgentState, event: str, action: str, phase: str | None) -> None:
        if agent is self.h:
            if event == "depart" and action in self.joint:
                self.joined.add(action)
            elif event == "arrive" and phase is not None:
                self.person_arrived.add((action, phase))
        if event == "end" and phase is not None:
            self.last[agent.id] = (action, phase)
            if action in self.joint:
                self.last[self.h.id] = (action, phase)
        if phase is None:
            return
        where = self.task.action(action).phase(phase).location
        if event == "start" and action in self.joint:  # both agents' stays there cover it
            self.joint_stay[self.h.id] = self.joint_stay[self.r.id] = where
        elif event == "arrive" and self.joint_stay.get(agent.id) != where:  # its walk away is over
            self.joint_stay.pop(agent.id, None)

    def _joint_told(self, o: object) -> None:
        """Each new order: a joint phase the robot is told to start, and told early when the person has not
        arrived there (the target: never; the dispatcher waits for the observed arrival)."""
        self._told = o
        assert isinstance(o, Order)
        if o.event == "start" and o.action in self.joint:
            self.told.add((o.action, o.phase))
            if (o.action, o.phase) not in self.person_arrived:
                self.told_early.add((o.action, o.phase))

    def _person_there(self, action: str, phase: str) -> bool:
        h = self.h
        return h.mode == "arrived" and h.action == action and self.phases[action][h.pi] == phase

    def _joint_start(self, action: str, phase: str) -> None:
        """The robot started the joint phase: the person works their role's drawn time; the phase ends when
        the later of the two is done (the robot reports it)."""
        h, d = self.h, self.draws.durations[(action, phase)]
        h.mode, h.work_start, h.work_end = "work", self.t, self.t + d
        self.r.duration = max(self.r.duration, d)

    def _joint_at(self, step: tuple[str, str], spot: str) -> bool:
        return step[0] in self.joint and self.task.action(step[0]).phase(step[1]).location == spot

    def _covers(self, agent: AgentState, step: tuple[str, str] | None, spot: str) -> bool:
        """Whether `agent`'s stay at `spot` for `step` covers a joint phase there: `step` is one, or the
        agent's next phase is one at the same spot (it stays)."""
        if step is None:
            return False
        nxt = None if self._joint_at(step, spot) else self._next_of(agent, step)
        return self._joint_at(step, spot) or (nxt is not None and self.task.action(step[0]).phase(step[1]).location
                                             == spot and self._joint_at(nxt, spot))

    def _cowork_spot(self) -> str | None:
        """The joint spot where the robot stands over a stay that covers a joint phase there, or None."""
        r = self.r
        spot = r.loc
        if spot is None or spot not in self.joint_spots or r.mover.moving:
            return None
        now = self._now(r) if r.mode in ("arrived", "work") else self.last.get(r.id)
        return spot if self.joint_stay.get(r.id) == spot or self._covers(r, now, spot) else None

    def _cowork(self) -> bool:
        """Whether the two co-work now (the comment above): the robot stands at the spot over its joint stay,
        and the person walks up to it for their own stay there that covers the joint phase, stays there
        over it, or walks away from it after it. The separation is not asked for between them."""
        h = self.h
        spot = self._cowork_spot()
        if spot is None or not h.mover.present:
            return False
        if h.loc == spot:  # their stay there: over the joint phase, or before it
            return self.joint_stay.get(h.id) == spot or self._covers(h, self._now(h), spot)
        if h.loc is not None:
            return False
        xy = self.ctx.paths.locations[spot]
        if h.mode in ("travel", "parked", "returning") and math.dist(h.mover.points[-1], xy) < 1e-6 \
                and self._covers(h, self._now(h), spot):
            return True  # walking up (or back, after making room) for the joint stay
        return h.mode in ("travel", "parked", "home") and math.dist(h.mover.points[0], xy) < 1e-6 \
            and self.joint_stay.get(h.id) == spot  # walking away after it

    def _coworks_at(self, a: AgentState, other: AgentState, target: tuple[float, float]) -> bool:
        """`Standoffs`: the person, after making room, goes back or on to where the robot co-works with them
        (it stands there for the joint action: not in their way)."""
        spot = self._cowork_spot() if self.joint and a is self.h else None
        return spot is not None and math.dist(self.ctx.paths.locations[spot], target) < 1e-6

    def _end_name(self, action: str, phase: str) -> str:
        """The timepoint of the person's end of `action.phase` (a joint phase's is the robot's)."""
        return f"{self.r.id if action in self.joint else self.h.id}.{phase}.{action}.end"

    def _joint_result(self) -> dict | None:
        if not self.joint:
            return None
        return {"told_to_start": len(self.told), "told_before_arrival": len(self.told_early),
                "cowork_seconds": round(self.floor.cowork_time, 3)}

    # -- the robot -------------------------------------------------------------------------------------

    def robot(self) -> bool:
        a, t = self.r, self.t
        o = self.ctl.order()
        if self.joint and o is not None and o is not self._told:
            self._joint_told(o)
        moved = self._home_or_aside(a, self.h)
        if moved is not None:
            return moved
        if a.mode == "free":
            if o is None:
                if self.joint and self._cowork() and self.floor.free() < self.floor.margin:
                    return False  # done at the joint spot: it stands until the person is out of reach
                return False if self.ctl.stopped else self.go_home(a)
            return self._robot_depart(a, o)
        if a.mode == "travel":
            return self._arrival_check(a)
        assert a.action is not None
        phase = self.phases[a.action][a.pi]
        mine = o is not None and (o.action, o.phase) == (a.action, phase)
        if a.mode == "parked":
            return self._robot_parked(a, o, mine, phase)
        if a.mode == "arrived":
            if mine and o is not None and o.event == "start" and t >= o.earliest - _EPS and self.ready(a.action, phase):
                joint = bool(self.joint) and a.action in self.joint
                if joint and not self._person_there(a.action, phase):
                    return False  # a joint action starts when both are there
                self._robot_start(a, o, phase, self.draws.robot[(a.action, phase)])
                if joint:
                    self._joint_start(a.action, phase)
                return True
            return False
        if a.mode == "work":
            return self._robot_work(a, o, mine, bool(self.joint) and a.action in self.joint, phase)
        return False

    # -- the loop --------------------------------------------------------------------------------------

    def deliver(self) -> bool:
        changed = self._deliver_detected()
        if self.sensor is not None:
            assert isinstance(self.ctl, DispatchedController)
            for t, x, y in self.sensor.due(self.t):
                changed = self.ctl.position(self.t, t, x, y) or changed
        return changed

    def _sample(self) -> None:
        """The tracker measures the person (nobody while they are away) at its times up to now."""
        sensor = self.sensor
        while sensor is not None and sensor.next_time <= self.t + _EPS:
            sensor.measure(sensor.next_time, self.h.mover.xy if self.h.mover.present else None)

    def _drained(self) -> bool:
        """After the last phase: the motion detector has given every leg event of the person, or had
        `_DRAIN` seconds to (the person walks home meanwhile, and it sees them leave)."""
        if self.sensor is None:
            return True
        assert self.finished_at is not None and isinstance(self.ctl, DispatchedController)
        given = {d[2:] for d in self.ctl.detected}
        wanted = {(h.event, h.action, h.phase) for h in self.happenings if h.agent == self.h.id
                  and h.action is not None and h.event in _DETECTED}
        return wanted <= given or self.t >= self.finished_at[0] + _DRAIN

    def next_time(self) -> float:
        """The next time something is due (module docstring, 2.): the soonest of the candidates below that
        is later than now, capped at the time cap; inf when none is (stuck). (Run at every step: the
        soonest kept as the candidates come, where a list of them was filtered and its minimum taken; the
        same float.)"""
        t = self.t
        low = t + _EPS
        best = math.inf
        c = self.detector.next_due()
        if low < c < best:
            best = c
        step = None  # the floor's safe step, the same for both agents (asked once)
        for ag in (self.h, self.r):
            m = ag.mover
            if m.moving:
                if m.speed > 0:  # `time_to_stop`
                    c = t + max(0.0, m.stop_at - m.s) / m.speed
                    if low < c < best:
                        best = c
                if step is None:
                    step = self.floor.safe_step()
                c = t + step
                if low < c < best:
                    best = c
                if m.blocked_for > 0:  # held up: a standoff when it has been for ASIDE_AFTER seconds
                    c = t + max(ASIDE_AFTER - m.blocked_for, MIN_STEP)
                    if low < c < best:
                        best = c
            if ag.mode == "work":
                c = ag.work_end
                if low < c < best:
                    best = c
        h = self.h
        if h.mode == "away" and h.back_at is not None:
            c = max(h.back_at, t + 0.1)
            if low < c < best:
                best = c
        absence = self.draws.absence
        if absence is not None and not self.absence_done:
            c = absence[0]
            if low < c < best:
                best = c
        if h.mode in ("free", "parked", "arrived") and self.model.choice == "follow" and not self.ctl.stopped:
            for c in self._guide_times():
                if low < c < best:
                    best = c
        if (h.mode == "aside_wait" and h.held_up) or (self.r.mode == "aside_wait" and self.r.held_up):
            c = t + WAIT_STEP  # an agent that made room looks again whether it may go back or on
            if low < c < best:
                best = c
        o = self.ctl.order()
        if o is not None and o.event in ("depart", "unpark", "start"):
            c = o.earliest
            if low < c < best:
                best = c
        if self._dctl is not None:
            due = self._dctl.due()
            if due is not None and low < due < best:  # plans compiled on demand come then (`hrc.sim.on_demand`)
                best = due
            if self.ctx.settings.tick > 0 and not self.done():
                if o is None or o.event == "wait" or h.mode in ("free", "parked", "arrived"):
                    c = max(self.last_obs, self.last_tick) + self.ctx.settings.tick
                    if low < c < best:
                        best = c
        if self.sensor is not None:  # the tracker goes on measuring; the detector may yet give an event
            future = [] if best == math.inf else [best]
            quiet = not future and self.finished_at is None
            self.quiet_since = (self.quiet_since if self.quiet_since is not None else t) if quiet else None
            if self.quiet_since is None or t - self.quiet_since < _QUIET:
                future += [c for c in (self.sensor.next_time, self.sensor.next_arrival()) if c > low]
            return min(min(future), self.cap) if future else math.inf
        return min(best, self.cap) if best < math.inf else math.inf  # nothing due: nobody can go on (stuck)

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
        h, r = self.h, self.r
        hm, rm = h.mover, r.mover
        dctl = self._dctl
        tick = self.ctx.settings.tick
        stall = self.ctx.settings.stall
        while True:
            if self.sensor is not None:
                self._sample()
            for _ in range(100):
                changed = self.deliver()
                changed = self.human() or changed
                changed = self.robot() or changed
                if not changed:
                    break
            if self.joint:
                self.floor.cowork = self._cowork()
            if self.done():
                if self.finished_at is None:
                    self.finished_at = (self.t, self.floor.min_free, self.floor.overlaps, self.floor.robot.held,
                                        self.floor.human.held)
                if self._drained():
                    break
            if self.t >= self.cap - _EPS:
                reason = "time cap"
                break
            nt = self.next_time()
            if not math.isfinite(nt):
                reason = "stuck: " + self._why_stuck()
                break
            tick_due = max(self.last_obs, self.last_tick) + tick
            hxy, rxy, seen = hm.xy, rm.xy, len(self.happenings)
            self.advance(nt - self.t)
            for ag in (h, r):
                mode = ag.mode
                if mode == "travel":
                    if ag.mover.moving:
                        ag.moved += nt - self.t
                elif mode in ("aside", "aside_wait", "returning"):
                    ag.aside_time += nt - self.t
                    if mode == "aside_wait" and ag.held_up:
                        ag.wait_for += nt - self.t
            self.t = nt
            if dctl is not None:
                if tick > 0 and abs(nt - tick_due) < _EPS:
                    self.last_tick = nt
                    dctl.tick(max(nt, self.last_obs))
                    self.last_obs = max(nt, self.last_obs)
                elif (due := dctl.due()) is not None and nt >= due - _EPS:  # the plans compiled on demand
                    dctl.tick(max(nt, self.last_obs))  # have come: a tick takes them in
                    self.last_obs = max(nt, self.last_obs)
            if (hm.moving or rm.moving or h.mode == "aside_wait" or r.mode == "aside_wait") and \
                    hxy == hm.xy and rxy == rm.xy and seen == len(self.happenings):
                stall_since = self.t if stall_since is None else stall_since
                if self.t - stall_since > stall:
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
            if self.joint:
                self.cowork_frames.append(self.floor.cowork)

    def _why_stuck(self) -> str:
        if self.h.mode == "gone":
            return "the person left for good"
        if self.ctl.stopped:
            return "the robot stopped (no plan left)"
        o = self.ctl.order()
        return f"waiting: robot {self.r.mode} ({o}), person {self.h.mode}"

    def _result(self, index: int, reason: str) -> RunResult:
        finished, times, makespan, deadline_met, limits_met, span = self._outcome()
        human_busy, robot_busy = self._busy(times, span)
        human_seq = tuple(dict.fromkeys(h.action for h in self.happenings
                                        if h.agent == self.h.id and h.event == "depart" and h.action))
        robot_seq = tuple(dict.fromkeys(h.action for h in self.happenings
                                        if h.agent == self.r.id and h.event == "depart" and h.action))
        ctl = self.ctl
        first = ctl.first_plan
        first_cp, kept, broken = self._first_kept(self.ctx.compiles[self.policy.compile], finished, times,
                                                  {self.h.id: human_seq, self.r.id: robot_seq})
        if self.h.mode == "away" and self.away_since is not None:
            self.absent += span - self.away_since
        od = getattr(ctl, "on_demand", None)  # compile on demand (`hrc.sim.on_demand`), with a searched compile
        min_free, overlaps = self.floor.min_free, self.floor.overlaps
        robot_held, human_held = self.floor.robot.held, self.floor.human.held
        if self.finished_at is not None:  # the floor as it was when the last phase ended (not the drain)
            _, min_free, overlaps, robot_held, human_held = self.finished_at
        return RunResult(
            policy=self.policy.name, run=index, finished=finished, reason="" if finished else reason,
            makespan=makespan, deadline_met=bool(deadline_met), limits_met=bool(limits_met),
            human_idle=max(0.0, span - human_busy - self.absent), robot_idle=max(0.0, span - robot_busy),
            robot_yield=robot_held, human_held=human_held, standoffs=self.standoffs,
            robot_aside=self.r.aside_time, human_aside=self.h.aside_time,
            min_distance=None if not math.isfinite(min_free) else min_free, overlaps=overlaps,
            plan_switches=ctl.switches, first_plan=first, first_class=ctl.first_class,
            first_blocked=first_cp is not None and first_cp.blocked, final_plan=ctl.plan_id,
            first_kept=bool(kept), first_broken=broken, refused=tuple(ctl.refused), late=self.late,
            robot_travel_excess=self.excess, human_sequence=human_seq, robot_sequence=robot_seq,
            overruns=sum(1 for k in self.draws.overrun if times.get(self._end_name(k[0], k[1])) is not None),
            absent=self.absent, detection=self._detection(), latencies=tuple(ctl.latencies),
            late_observations=getattr(ctl, "late_observations", None),
            first_sensing_class=None if first_cp is None else first_cp.plan_class.value,
            ssm=None if self.floor.ssm is None else self.floor.ssm.measures(),
            on_demand=None if od is None else od.to_json(), joint=self._joint_result(),
            compile_seconds=() if od is None else tuple(od.compile_seconds),
            happenings=tuple(self.happenings) if self.record else (), frames=tuple(self.frames),
            cowork_frames=tuple(self.cowork_frames))

    def _detection(self) -> Detection | None:
        """How the motion detector did against what happened (None: buttons)."""
        if self.sensor is None:
            return None
        assert isinstance(self.ctl, DispatchedController)
        truth = [(h.t, h.event, h.action or "", h.phase or "") for h in self.happenings
                 if h.agent == self.h.id and h.action is not None and h.event in _DETECTED]
        return detection_of(truth, self.ctl.detected, tuple(self.ctl.detect_refused), self.ctl.withdrawn)

    def _busy(self, times: dict[str, float], span: float) -> tuple[float, float]:
        busy = {self.h.id: 0.0, self.r.id: 0.0}
        for action in self.joint:  # the person works it too, from the robot's start to its end
            for phase in self.phases[action]:
                a, b = times.get(f"{self.r.id}.{phase}.{action}.start"), times.get(f"{self.r.id}.{phase}.{action}.end")
                if a is not None and b is not None:
                    busy[self.h.id] += min(b, span) - min(a, span)
        add_busy(busy, times, span)
        return busy[self.h.id], busy[self.r.id]
