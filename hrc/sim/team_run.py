"""One simulated run of a team (issue 37): every person and every robot of the task on one floor.

The loop is `hrc.sim.run`'s (Strassmair & Taylor 2014, Fig. 5, every box simulated but the dispatcher),
taken over every agent of the task (`hrc.sim.montecarlo.run_one` hands a task of other than one person and
one robot here):

- **each robot** carries out its own entry of the dispatcher's answer (`Decision.robots`, the same
  `hrc.dispatch.Dispatcher` as ``hrc dispatch`` serves a team with), or its part of the fixed plan; each
  of its events is acknowledged at once with the time it happened (snapped into its window within 2 ms,
  `late` counts the others), with its own id;
- **each person** is a simulated person (`hrc.sim.human`: their own draws, `draw_people`) who reads only
  their own hint (`Decision.people`, their entry of `ahead`, else the best plan's planned times for their
  events: what their console page would show): with ``--human follow`` they take the next action the
  hint or the plan gives them and leave and start when it says; ``preferred`` and ``free`` choose among
  what the task graph allows them, as one person does; their events reach the dispatcher through the
  detector (its delay);
- **joint actions** as the one-pair loop does them: every agent of its crew walks or drives there;
  its lead (the crew's first robot, `Task.lead`) starts it when every other agent of the crew has arrived
  there, and ends it when every role's time is done (each person's drawn time, each robot's own); the
  others work from the lead's start and go on at its end; the person and the robot co-work at its spot
  (`TeamFloor.cowork`) while the robot stands there over the joint stay and the person walks up, stays
  or walks away. When the crew is a choice of the plan (`Action.crew_choice`), it is who left for the
  action (`_TeamRun.crew`): people read their own part or join while it has room for them, and a person
  outside it keeps off its spot (`_TeamRun._idle`); docs/simulate.md, "A crew chosen by the plan";
- **the floor** is `hrc.sim.team_floor.TeamFloor`: a person stops short of every robot, a robot keeps the
  margin from every person and stops short of every other robot; the separation is measured for every
  robot-person pair and a robot-robot contact is counted (a violation). Under speed and separation
  monitoring (`safety:`) every robot obeys `hrc.sim.ssm` against every person, its counts per robot in the
  run's ``team.ssm`` and all of them as one in ``ssm`` (as the one pair reports it).

A person's absence (``--absence-rate``) is the one pair's, per person: between two actions they leave
the floor and the dispatcher is told that person's ``away`` (the others and the robots go on), and
``back`` when they return (`_TeamRun._leave`, `_come_back`). With ``--detector motion`` each person has a
tracker of their own (`hrc.detect.sensor.Sensor`, their own random numbers) whose positions go, naming them,
to their own detector in front of the dispatcher (`hrc.detect.online`; the one pair's drain after the last
phase, `_drained`, and its floor measures taken at the last phase). Over a searched compile (a task beyond
``--max-plans``) the dispatcher compiles on demand as the one pair's does (`hrc.sim.on_demand`): every
robot goes on from its own fallback step, the run is woken when the plans come (`next_time`) and a tick
takes them in; the run reports its misses and recovery (``on_demand``).

**Stand-offs** are resolved per pair of agents by the one pair's rules (`hrc.sim.standoff.Standoffs`, from
which this loop derives; `_TeamRun._home_or_aside`): an agent held up `ASIDE_AFTER` seconds by another
(`_blocker`: the one nearest the next 2 m of its way) goes round it or has it make room as one pair does;
both on the move, a robot makes room for a person first, and of two robots the one whose next phase may not
start makes room for the one whose may, else the later in task order (`_yields`); a robot that stopped
(no plan left, or in a protective stop under `safety:`) never asks to be let through (`_halted`). People
are not kept apart by the floor, so a person is held up only by a robot (`_holders`). A spot to make room at
and a way round keep clear of every other agent on the floor too (`_also`: three at one place). A run in
which everyone under way is held up (or, nobody under way, everyone waiting to go back after making room
is held up there), or nobody has moved, for `stall` seconds ends as a deadlock (counted, as in the one-pair
loop).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from hrc.detect.sensor import Sensor
from hrc.motion.separation import reach as pair_reach
from hrc.sim.agents import acknowledged, add_busy
from hrc.sim.detection import Detection, detection_of
from hrc.sim.detector import Detector, Happening
from hrc.sim.floor import CONTACT, MIN_STEP, Mover
from hrc.sim.giveway import Disc, Ways
from hrc.sim.human import HumanDraws, draw_people
from hrc.sim.policies import POLICIES, Order, Policy, SimRoute
from hrc.sim.run import AgentFrame, RunResult, SimContext
from hrc.sim.ssm import combined
from hrc.sim.standoff import ASIDE_AFTER, CLEAR, WAIT_STEP, Aside, Standoffs, yields
from hrc.sim.team_floor import TeamFloor
from hrc.sim.team_policies import TeamController, TeamDispatched, make_team_controller

__all__ = ["simulate_team_run"]

_EPS = 1e-9
_HELD = 2.0  # s: an agent held up this long makes the loop look at the floor again at least this often
_DETECTED = ("depart", "arrive", "start", "end")  # the events a motion detector gives
_DRAIN = 12.0  # s after the last phase in which the motion detectors may still give the people's last events
_QUIET = 30.0  # s with nothing due but the trackers' positions: nobody can go on (stuck)
_AHEAD = 8  # samples (every 0.25 m) of a held-up agent's way in which its blocker stands (`_blocker`)


def simulate_team_run(ctx: SimContext, policy: str, index: int, record: bool = False,
                      controller: Callable[[SimContext, Policy], TeamController] = make_team_controller) -> RunResult:
    """Run `index` of `policy` for a team: the same people (drawn from ``(seed, index)``) under every policy.
    `record` keeps the happenings and every agent's position at every step (for figures)."""
    rng = np.random.default_rng([ctx.seed, index])
    draws = draw_people(ctx.task, ctx.settings.human, rng)
    ctl = controller(ctx, POLICIES[policy])
    sensors = None
    if ctx.settings.motion and isinstance(ctl, TeamDispatched):  # a tracker per person, its own numbers
        people = [a.id for a in ctx.task.agents if a.is_human]
        sensors = {p: Sensor(ctx.settings.sensor, np.random.default_rng([ctx.seed, index, 28, k]))
                   for k, p in enumerate(people)}
    return _TeamRun(ctx, POLICIES[policy], draws, ctl, record, sensors).run(index)


# -- the run ---------------------------------------------------------------------------------------------------

class _Agent:
    """One agent's state in the loop (a mutable builder)."""

    __slots__ = ("id", "mover", "human", "home", "loc", "mode", "action", "pi", "route", "parked", "work_start",
                 "work_end", "duration", "order", "predicted", "moved", "draws", "back_at", "away_since",
                 "absence_done", "absent", "aside", "next_way", "wait_for", "held_up", "aside_time", "blocker",
                 "off")

    def __init__(self, agent_id: str, mover: Mover, human: bool, home: str, draws: HumanDraws | None) -> None:
        self.id, self.mover, self.human, self.home = agent_id, mover, human, home
        self.loc: str | None = home
        self.mode = "free"  # free, travel, parked, arrived, work, home
        self.action: str | None = None
        self.pi = 0
        self.route: SimRoute | None = None
        self.parked = False
        self.work_start = self.work_end = self.duration = 0.0
        self.order: Order | None = None
        self.predicted = self.moved = 0.0
        self.draws = draws
        # a person's absence (`HumanDraws.absence`): mode "away" until `back_at`, "gone" for good
        self.back_at: float | None = None
        self.away_since: float | None = None
        self.absence_done = False
        self.absent = 0.0  # s away so far
        # making room (`hrc.sim.standoff`, `AgentState`'s fields of the same names)
        self.aside: Aside | None = None
        self.next_way: tuple[tuple[float, float], ...] | None = None
        self.wait_for = 0.0
        self.held_up = False
        self.aside_time = 0.0
        self.blocker: str | None = None
        self.off = False  # walking off a joint spot whose crew it is not in (`_TeamRun._walk_off`), not home


class _TeamRun(Standoffs[_Agent]):
    ctx: SimContext
    ctl: TeamController
    joint: dict[str, tuple[str, ...]]

    def __init__(self, ctx: SimContext, policy: Policy, draws: dict[str, HumanDraws], ctl: TeamController,
                 record: bool, sensors: dict[str, Sensor] | None = None) -> None:
        self.ctx, self.policy, self.ctl, self.record = ctx, policy, ctl, record
        self.sensors = sensors  # ``--detector motion``: each person's tracker (issue 37), by person
        self.quiet_since: float | None = None
        task = self.task = ctx.task
        s = ctx.settings
        self.model = s.human
        self.floor = TeamFloor(task, s.slowdown)
        self.ways = Ways(self.floor.world, ctx.paths, ctx.cache)
        self.detector = Detector(s.detection_delay)
        self.agents = {a.id: _Agent(a.id, self.floor.movers[a.id], a.is_human, a.start, draws.get(a.id))
                       for a in task.agents}
        self.people = [self.agents[a.id] for a in task.agents if a.is_human]
        self.robots = [self.agents[a.id] for a in task.agents if not a.is_human]
        self.robot_q = next(iter(draws.values())).robot  # the robots' duration quantiles (one per phase)
        self._init_task(task, s.time_cap)
        self.started_at: dict[str, float] = {}  # action -> when `started` took it
        self.joint = {a.id: a.agents for a in task.actions if a.joint}  # every candidate of each joint action
        self.choosing = {a.id: a for a in task.actions if a.crew_choice}  # those whose crew the plan chooses
        self.joined: dict[str, set[str]] = {a: set() for a in self.agents}  # joint actions each agent left for
        self.joint_stay: dict[str, str] = {}  # agent -> the joint spot of its stay (until it is elsewhere)
        self.last: dict[str, tuple[str, str]] = {}  # agent -> the last phase it ended (a joint one: all its agents)
        self.told: set[tuple[str, str]] = set()
        self.told_early: set[tuple[str, str]] = set()
        self._told: dict[str, Order | None] = {}
        self.choices = {a: 0 for a in self.agents}
        self.last_obs = self.last_tick = 0.0
        self.late = 0
        self.excess = 0.0
        self.finished_at: float | None = None
        self.frames: list[AgentFrame] = []
        self.standoffs = 0
        self.room_for: dict[frozenset[str], str] = {}  # a pair -> the one of it room was last made for
        self.rank = {a: k for k, a in enumerate(self.agents)}  # task order

    # -- bookkeeping ---------------------------------------------------------------------------------

    def emit(self, a: _Agent, event: str, action: str | None = None, phase: str | None = None) -> None:
        h = Happening(self.t, a.id, event, action, phase)
        self.happenings.append(h)
        if action is not None and event == "depart":
            first = self.started.get(action)
            # the same instant, a robot's departure takes it over a person's who chose freely: the robot's
            # order was given before their choice (a robot never chooses again; the person sees it and does)
            if first is None or (not a.human and self.agents[first].human and self.started_at[action] == self.t):
                self.started[action] = a.id
                self.started_at[action] = self.t
            if action in self.joint:
                self.joined[a.id].add(action)
        if action is not None and phase is not None:
            self._joint_note(a, event, action, phase)
        if event == "end" and action is not None and phase is not None:
            self.ended.add((action, phase))
        if a.human:
            if self.sensors is None or action is None:  # a tracker sees positions, not away and back
                self.detector.see(h)
            return
        t, late = acknowledged(self.t, self.ctl.order(a.id), event, action, phase)
        self.late += late
        self._tell(Happening(max(t, self.last_obs), a.id, event, action, phase))

    def _robot(self, a: _Agent) -> bool:
        return not a.human

    # The bookkeeping of `emit` stays apart from the one-pair loop's (`_Run.emit`, `_joint_emit`): there a
    # motion tracker may stand between the person and the dispatcher, and the joint notes are the pair's.
    def _joint_note(self, a: _Agent, event: str, action: str, phase: str) -> None:
        if event == "end":
            for ag in self.crew(action) if action in self.joint else (a.id,):
                self.last[ag] = (action, phase)
        where = self.task.action(action).phase(phase).location
        if event == "start" and action in self.joint:  # every agent's stay there covers it
            for ag in self.crew(action):
                self.joint_stay[ag] = where
        elif event == "arrive" and self.joint_stay.get(a.id) != where:
            self.joint_stay.pop(a.id, None)

    def taken(self, a: _Agent) -> dict[str, str]:
        """`started` as `a` reads it: a joint action of theirs is theirs to go to until they have left for it
        (with a crew to choose: while they may still join those who left for it, `_may_join`)."""
        return {x: ag for x, ag in self.started.items()
                if x not in self.joint or a.id not in self.joint[x] or x in self.joined[a.id]
                or (x in self.choosing and not self._may_join(a.id, x))}

    # -- crews (issue 37): a joint action whose crew is a choice of the plan (`Action.crew_choice`) ----------
    # Who does it is decided on the floor as an allocation is: each person reads their own part (their hint,
    # the plan they follow) or, choosing freely, joins while the crew has room for them; the robots go where
    # their orders send them. The crew is the agents who left for it (`joined`); the dispatcher narrows its
    # plans by them (`hrc.dispatch`, set validation). An action with one crew keeps its agents throughout.

    def came(self, action: str) -> tuple[str, ...]:
        """The agents (task order) who left for joint `action`."""
        return tuple(ag for ag in self.joint[action] if action in self.joined[ag])

    def crew(self, action: str) -> tuple[str, ...]:
        """The crew of joint `action` as the run knows it (task order): its one crew; with a crew to choose,
        those who left for it, and until they fill it, the current plan's crew when it holds them (what the
        plan expects; else those who came alone)."""
        if action not in self.choosing:
            return self.joint[action]
        came = self.came(action)
        if len(came) < self.choosing[action].needed:
            cp = self.ctl.current()
            planned = () if cp is None else self.task.crew(action, cp.plan)
            if set(came) <= set(planned):
                return planned
        return came

    def _may_join(self, agent: str, action: str) -> bool:
        """Whether `agent` may still join those who left for `action`: with them, part of one of its crews."""
        with_them = set(self.came(action)) | {agent}
        return any(with_them <= set(c) for c in self.choosing[action].crews)

    def _complete(self, action: str) -> bool:
        """Whether every agent of `action`'s crew has left for it (always, with one crew to do it: its agents
        go)."""
        return action not in self.choosing or len(self.came(action)) == self.choosing[action].needed

    def _kept_off(self, a: _Agent) -> list[tuple[float, float]]:
        """Where `a` must not stand idle: the spots of the joint phases still to do, with a crew to choose,
        whose crew (`crew`) they are not in."""
        locs = self.ctx.paths.locations
        return [locs[ph.location] for x, act in self.choosing.items() if a.id not in self.crew(x)
                for ph in act.phases if (x, ph.id) not in self.ended]

    def _off_reach(self, a: _Agent) -> float:
        """How far `a` keeps from such a spot: a robot's reach from them driving up to it (and `CLEAR`)."""
        return max((self._reach(a, r) for r in self.robots if r is not a), default=0.0) + CLEAR

    def _idle(self, a: _Agent) -> bool:
        """A person with nothing to do (with a crew to choose): they go home (`go_home`), but not to where a
        joint phase whose crew they are not in is still to be done; standing within `_off_reach` of such a spot,
        they walk off it (`_walk_off`); else they stay where they are."""
        spots = self._kept_off(a)
        away = self._off_reach(a)
        near = [xy for xy in spots if math.dist(a.mover.xy, xy) < away]
        if near:
            return self._walk_off(a, near, away)
        home = self.ctx.paths.locations[a.home]
        if any(math.dist(home, xy) < away for xy in spots):
            return False
        return self.go_home(a)

    def _walk_off(self, a: _Agent, spots: list[tuple[float, float]], away: float) -> bool:
        """`a` walks to the nearest roadmap milestone `away` from every one of `spots` (`Ways.spot`, as making
        room does), keeping clear of the other agents; then stands there, free (False: no such spot)."""
        way = np.asarray(spots, dtype=float)
        points = self.ways.spot(self._clearance(a), a.mover.xy, None, way, away, self._also(a, a))
        if points is None or len(points) < 2:
            return False
        a.mover.set_route(points, a.mover.agent.speed)
        a.mode, a.loc, a.off = "home", None, True
        return True

    def _home_reached(self, a: _Agent) -> bool:
        """`AgentLoop._home_reached`; walking off a joint spot (`_walk_off`), it stands where it got to."""
        if a.off and a.mode == "home" and not a.mover.moving:
            a.mode, a.loc, a.off = "free", None, False
            return True
        return super()._home_reached(a)

    def _lead(self, action: str) -> str | None:
        """Who starts joint `action` (`Task.lead`): the first robot of its crew; None while a crew to choose
        is not complete (nobody may start it yet)."""
        if action not in self.choosing:
            return self.task.lead(action)
        if not self._complete(action):
            return None
        return self.task.crew_lead(self.came(action))

    # -- stand-offs (`hrc.sim.standoff`), per pair of agents ------------------------------------------------

    def _holders(self, a: _Agent) -> list[_Agent]:
        """The agents that can hold `a` up on the floor: every other but, for a person, the other people (the
        floor does not keep people apart: they walk past each other)."""
        return [o for o in self.agents.values() if o is not a and not (a.human and o.human)]

    def _home_or_aside(self, a: _Agent) -> bool | None:
        """The one pair's `_Run._home_or_aside` against every agent that can hold `a` up: going home, and
        giving way. True or False when one of them decided this step, None when the agent's own rules decide."""
        mode = a.mode
        if mode not in ("home", "aside", "aside_wait", "returning"):
            m = a.mover
            if mode == "work" or not m.moving or m.blocked_for < ASIDE_AFTER:
                return None
        if self._home_reached(a):
            return True
        if self._give_way(a, self._holders(a)):
            return True
        if a.mode in ("home", "aside", "aside_wait", "returning"):
            return False
        return None

    def _blocker(self, a: _Agent, others: Sequence[_Agent]) -> _Agent | None:
        """Who holds `a` up: at the spot it made room at, the one that stands in its way back or on; on its
        way, the one nearest the next `_AHEAD` metres of its route (beyond what the two keep; ties: task order)."""
        if a.mode == "aside_wait":
            return next((o for o in others if o.id == a.blocker), None)
        ahead = self._way(a)[:_AHEAD]
        best, gap = None, math.inf
        for o in others:
            if not o.mover.present:
                continue
            x, y = o.mover.xy
            d = float(np.min(np.hypot(ahead[:, 0] - x, ahead[:, 1] - y))) - self._reach(a, o)
            if d < gap - 1e-12:
                best, gap = o, d
        return best

    def _also(self, a: _Agent, o: _Agent) -> tuple[Disc, ...]:
        """Every other agent on the floor that can hold `a` up, besides `o`: its spot and way round keep their
        reach from them too (three at one place: a spot off one agent's way must not be in another's), a
        standing robot's from a person at its standing separation (`S_p(0)` under `safety:`); when there is
        none such, `Standoffs` takes one clear of `o` only."""
        return tuple(Disc(x.mover.xy, self._reach(a, x, x.mover.moving)) for x in self._holders(a)
                     if x is not o and x.mover.present)

    def _reach(self, a: _Agent, b: _Agent, moving: bool = True) -> float:
        """A robot and a person: the one pair's (`hrc.motion.separation.reach` at that robot's speed, or
        standing when not `moving`); two robots or two people: the radii and the margin."""
        x, y = a.mover.agent, b.mover.agent
        if x.is_human != y.is_human:
            person, robot = (x, y) if x.is_human else (y, x)
            return pair_reach(self.task, robot.speed if moving else 0.0, person, robot)
        return pair_reach(self.task, 0.0, x, y)

    def _yields(self, x: _Agent, y: _Agent) -> tuple[tuple[_Agent, _Agent], tuple[_Agent, _Agent]]:
        """A robot and a person: the robot makes room first, as for one pair; two robots (or two people): the
        one whose next phase may not start, else the later in task order (`hrc.sim.standoff.yields`)."""
        if x.human != y.human:
            person, robot = (x, y) if x.human else (y, x)
            return (robot, person), (person, robot)
        g, o = (x, y) if yields(self._startable(x), self._startable(y), self.rank[x.id] < self.rank[y.id]) else (y, x)
        return (g, o), (o, g)

    def _before(self, a: _Agent, b: _Agent) -> bool:
        return a.human if a.human != b.human else self.rank[a.id] < self.rank[b.id]

    def _halted(self, a: _Agent) -> bool:
        """A robot whose controller stopped, or (under speed and separation monitoring) in a protective stop."""
        if a.human:
            return False
        return self.ctl.stopped or (self.floor.ssm is not None and self.floor.ssm[a.id].stopped)

    def _guided(self, a: _Agent, action: str, phase: str) -> bool:
        return not a.human or math.isfinite(self.guide(a, action, phase, "start"))

    def _room_made(self, g: _Agent, o: _Agent) -> None:
        self.room_for[frozenset((g.id, o.id))] = o.id

    def _room_made_for(self, a: _Agent, b: _Agent) -> _Agent | None:
        last = self.room_for.get(frozenset((a.id, b.id)))
        return None if last is None else self.agents[last]

    def _coworks_at(self, a: _Agent, other: _Agent, target: tuple[float, float]) -> bool:
        """`other` stands at `target` for a joint phase of theirs with `a` (it is not in `a`'s way back)."""
        if not self.joint or other.action not in self.joint or a.id not in self.crew(other.action):
            return False
        where = self.task.action(other.action).phase(self.phases[other.action][other.pi]).location
        return other.mode in ("arrived", "work") and math.dist(self.ctx.paths.locations[where], target) < 1e-6

    # -- the people ------------------------------------------------------------------------------------

    def allowed(self, a: _Agent) -> list[str]:
        taken = self.taken(a)
        return [x.id for x in self.task.actions if x.id not in taken and a.id in x.agents
                and all(b in taken for b, y in self.before if y == x.id)]

    def choose(self, a: _Agent) -> str | None:
        m = self.model
        if m.choice == "follow" and not self.ctl.stopped:
            return self.ctl.human_next(a.id, self.taken(a))
        allowed = self.allowed(a)
        if not allowed:
            return None
        if m.choice == "free":
            assert a.draws is not None
            u = a.draws.choice[min(self.choices[a.id], len(a.draws.choice) - 1)]
            return allowed[min(int(u * len(allowed)), len(allowed) - 1)]
        order = m.preferred or self.task.action_ids
        return ([x for x in order if x in allowed] + [x for x in allowed if x not in order])[0]

    def guide(self, a: _Agent, action: str, phase: str, event: str) -> float:
        if self.model.choice != "follow" or self.ctl.stopped:
            return self.t
        g = self.ctl.guide_time(a.id, action, phase, event)
        return self.t if g is None else g

    # A person's absence follows the one pair's (`hrc.sim.run._Run.human`): between two actions, at the time
    # drawn, they leave the floor ("away", seen by the dispatcher through the detector as that person's
    # `away`: docs/dispatch.md, `History.gone`), the robots and the other people go on; they come back in
    # where they left (at their start if a robot stands there), and say `back`. For good: "gone".
    def _leave(self, a: _Agent) -> bool:
        """`a` leaves now if their absence is due (they are between two actions)."""
        absence = None if a.draws is None else a.draws.absence
        if absence is None or a.absence_done or self.t < absence[0] - _EPS:
            return False
        a.absence_done = True
        a.mode = "away" if absence[1] is not None else "gone"
        a.back_at = None if absence[1] is None else self.t + absence[1]
        a.away_since = self.t
        a.mover.present = False
        self.emit(a, "away")
        return True

    def _come_back(self, a: _Agent) -> bool:
        """`a`, away, comes back once their time is up and no robot stands where they come in."""
        if a.back_at is None or self.t < a.back_at - _EPS:
            return False
        def gap(xy: tuple[float, float]) -> float:  # to the nearest robot (they are off the floor: no `gap`)
            return min((math.dist(xy, r.mover.xy) - a.mover.agent.radius - r.mover.agent.radius
                        for r in self.robots), default=math.inf)

        if gap(a.mover.xy) < CONTACT:
            home = self.ctx.paths.locations[a.home]  # a robot stands where they left: in at their start
            if gap(home) < self.task.safety_margin:
                return False
            self.floor.place(a.mover, home)
            a.loc = a.home
        a.mover.present = True
        a.mode = "free"
        a.absent += self.t - (a.away_since if a.away_since is not None else self.t)
        a.away_since = None
        self.emit(a, "back")
        return True

    def person(self, a: _Agent) -> bool:
        t = self.t
        if a.mode == "gone":
            return False
        if a.mode == "away":
            return self._come_back(a)
        moved = self._home_or_aside(a)
        if moved is not None:
            return moved
        if a.mode == "free":
            if a.action is None:
                if self._leave(a):
                    return True
                nxt = self.choose(a)
                if nxt is None:
                    return self._idle(a) if self.choosing else self.go_home(a)
                if t < self.guide(a, nxt, self.phases[nxt][0], "depart") - _EPS:
                    return False
                a.action, a.pi = nxt, 0
                self.choices[a.id] += 1
            action = a.action
            if action in self.choosing and a.pi == 0 and not self._may_join(a.id, action):
                a.action = None  # its crew filled without them (they see who left for it): they choose again
                return True
            phase = self.phases[action][a.pi]
            if t < self.guide(a, action, phase, "depart") - _EPS:
                return False
            assert a.draws is not None
            self.depart(a, action, phase, a.mover.agent.speed / a.draws.pace[(action, phase)])
            return True
        if a.mode in ("travel", "parked", "arrived") and self._taken_by_another(a):
            a.action, a.pi, a.mode = None, 0, "free"  # they see someone else on it: they choose again
            a.mover.moving = False
            a.loc = next((loc for loc, xy in self.ctx.paths.locations.items()
                          if math.dist(xy, a.mover.xy) < 1e-6), None)
            return True
        if a.mode == "travel":
            return self._arrival_check(a)
        assert a.action is not None
        phase = self.phases[a.action][a.pi]
        if a.mode == "parked":
            return t >= self.guide(a, a.action, phase, "unpark") - _EPS and self._unpark(a, phase)
        if a.action in self.joint:  # the lead starts and ends it (`_joint_start`)
            return self._joint_done(a, phase)
        if a.mode == "arrived":
            if self.ready(a.action, phase) and t >= self.guide(a, a.action, phase, "start") - _EPS:
                assert a.draws is not None
                a.mode, a.work_start = "work", t
                a.work_end = t + a.draws.durations[(a.action, phase)]
                self.emit(a, "start", a.action, phase)
                return True
            return False
        return a.mode == "work" and self._work_done(a, phase)

    def _taken_by_another(self, a: _Agent) -> bool:
        """`a` is on the way to the first phase of an action (not a joint one) that another agent left for
        first (the same instant: the dispatcher took the other's; a person who chose freely sees it)."""
        x = a.action
        return x is not None and a.pi == 0 and x not in self.joint and self.started.get(x, a.id) != a.id

    # -- joint actions ---------------------------------------------------------------------------------

    def _there(self, a: _Agent, action: str, phase: str) -> bool:
        return a.mode == "arrived" and a.action == action and self.phases[action][a.pi] == phase

    def _joint_start(self, lead: _Agent, action: str, phase: str) -> None:
        """The lead started the joint phase: every other agent of it works its role's time; the phase ends
        when the last of them is done (the lead reports it)."""
        for ag in self.crew(action):
            other = self.agents[ag]
            if other is lead:
                continue
            if other.human:
                assert other.draws is not None
                d = other.draws.durations[(action, phase)]
            else:
                bounds = self.task.action(action).phase(phase).duration(ag)
                d = bounds.lb + self.robot_q[(action, phase)] * (bounds.ub - bounds.lb)
            other.mode, other.work_start, other.work_end = "work", self.t, self.t + d
            lead.duration = max(lead.duration, d)

    def _told_now(self, r: _Agent, o: Order | None) -> None:
        """Each new order: a joint phase the robot is told to start, and told early when another agent of
        it has not arrived there (the target: never)."""
        self._told[r.id] = o
        if o is None or o.event != "start" or o.action not in self.joint:
            return
        self.told.add((o.action, o.phase))
        arrived = {(h.agent, h.action, h.phase) for h in self.happenings if h.event == "arrive"}
        if not self._complete(o.action) or any((ag, o.action, o.phase) not in arrived
                                               for ag in self.crew(o.action) if ag != r.id):
            self.told_early.add((o.action, o.phase))

    def _joint_at(self, step: tuple[str, str], spot: str, pair: tuple[str, str]) -> bool:
        return step[0] in self.joint and set(pair) <= set(self.crew(step[0])) \
            and self.task.action(step[0]).phase(step[1]).location == spot

    def _covers(self, a: _Agent, step: tuple[str, str] | None, spot: str, pair: tuple[str, str]) -> bool:
        """Whether `a`'s stay at `spot` for `step` covers a joint phase of `pair` there (`step` is one, or the
        next phase, at the same spot, is one)."""
        if step is None:
            return False
        if self._joint_at(step, spot, pair):
            return True
        nxt = self._next_of(a, step)
        return nxt is not None and self.task.action(step[0]).phase(step[1]).location == spot \
            and self._joint_at(nxt, spot, pair)

    def _cowork(self) -> frozenset[tuple[str, str]]:
        """The pairs co-working now (the one-pair loop's `_Run._cowork`, per pair of a joint action): a robot
        stands at the spot over a stay that covers their joint phase, and the other of the pair (a person, or
        another robot of that phase) comes up to it for that stay, stays there or goes away after it. A
        (person, robot) pair is named so; two robots as (the other, the one standing), and, both standing
        there, as (the later, the earlier in task order): the earlier is the lead, which the compile has
        arrive first and leave last (`hrc.motion.conflicts._coworking`, the first robot of a pair in the
        robot's slot)."""
        out = set()
        for r in self.robots:
            spot = r.loc
            if spot is None or r.mover.moving:
                continue
            now = self._now(r) if r.mode in ("arrived", "work") else self.last.get(r.id)
            for p in self.people + [o for o in self.robots if o is not r]:
                pair = (p.id, r.id)
                if not (self.joint_stay.get(r.id) == spot or self._covers(r, now, spot, pair)):
                    continue
                if not any(set(pair) <= set(ags) for ags in self.joint.values()) or not p.mover.present:
                    continue
                xy = self.ctx.paths.locations[spot]
                if p.loc == spot:
                    shared = self.joint_stay.get(p.id) == spot or self._covers(p, self._now(p), spot, pair)
                elif p.loc is not None:
                    shared = False
                elif p.mode in ("travel", "parked", "returning") and math.dist(p.mover.points[-1], xy) < 1e-6 \
                        and self._covers(p, self._now(p), spot, pair):
                    shared = True
                else:
                    shared = p.mode in ("travel", "parked", "home") and math.dist(p.mover.points[0], xy) < 1e-6 \
                        and self.joint_stay.get(p.id) == spot
                if shared:
                    out.add(pair)
        # two robots both standing there: named once, the earlier one standing
        return frozenset((a, b) for a, b in out if (b, a) not in out or self.rank[b] < self.rank[a])

    # -- the robots ------------------------------------------------------------------------------------

    def robot(self, a: _Agent) -> bool:
        t = self.t
        o = self.ctl.order(a.id)
        if self.joint and o is not self._told.get(a.id, False):
            self._told_now(a, o)
        moved = self._home_or_aside(a)
        if moved is not None:
            return moved
        if a.mode == "free":
            if o is None:
                if any(r == a.id and self.floor.gap(self.floor.movers[p], a.mover) < self.floor.margin
                       for p, r in self.floor.cowork):
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
        joint = a.action in self.joint
        if joint and self._lead(a.action) != a.id:  # another robot leads it (or its crew is still to come):
            return self._joint_done(a, phase)  # work from its start to its end
        if a.mode == "arrived":
            if mine and o is not None and o.event == "start" and t >= o.earliest - _EPS and self.ready(a.action, phase):
                if joint and not all(self._there(self.agents[ag], a.action, phase)
                                     for ag in self.crew(a.action) if ag != a.id):
                    return False  # a joint action starts when all its agents are there
                self._robot_start(a, o, phase, self.robot_q[(a.action, phase)])
                if joint:
                    self._joint_start(a, a.action, phase)
                return True
            return False
        if a.mode == "work":
            return self._robot_work(a, o, mine, joint, phase)
        return False

    # -- the loop --------------------------------------------------------------------------------------

    def deliver(self) -> bool:
        changed = self._deliver_detected()
        if self.sensors is not None:  # every person's positions due, in time order (then task order)
            assert isinstance(self.ctl, TeamDispatched)
            due = sorted((t, k, p, x, y) for k, (p, sensor) in enumerate(self.sensors.items())
                         for t, x, y in sensor.due(self.t))
            for t, _, p, x, y in due:
                changed = self.ctl.position(self.t, p, t, x, y) or changed
        return changed

    def _sample(self) -> None:
        """Each tracker measures its person (nobody while they are away) at its times up to now."""
        for p, sensor in (self.sensors or {}).items():
            mover = self.agents[p].mover
            while sensor.next_time <= self.t + _EPS:
                sensor.measure(sensor.next_time, mover.xy if mover.present else None)

    def _drained(self) -> bool:
        """After the last phase: every person's motion detector has given each of their leg events, or had
        `_DRAIN` seconds to (they walk home meanwhile, and it sees them leave)."""
        if self.sensors is None:
            return True
        assert self.finished_at is not None and isinstance(self.ctl, TeamDispatched)
        for p in self.sensors:
            given = {d[2:] for d in self.ctl.detected[p]}
            wanted = {(h.event, h.action, h.phase) for h in self.happenings if h.agent == p
                      and h.action is not None and h.event in _DETECTED}
            if not wanted <= given:
                return self.t >= self.finished_at + _DRAIN
        return True

    def _detection(self) -> tuple[Detection | None, dict[str, Detection]]:
        """How the motion detectors did against what happened: all people's together, and each person's (their
        true events against the events given as theirs: an event given for the wrong person is unmatched)."""
        if self.sensors is None:
            return None, {}
        assert isinstance(self.ctl, TeamDispatched)
        ctl = self.ctl
        each = {}
        for p in self.sensors:
            truth = [(h.t, h.event, h.action or "", h.phase or "") for h in self.happenings
                     if h.agent == p and h.action is not None and h.event in _DETECTED]
            each[p] = detection_of(truth, ctl.detected[p], tuple(ctl.detect_refused[p]), ctl.withdrawn[p])
        dets = list(each.values())
        return Detection(sum(d.truth for d in dets), sum(d.given for d in dets), sum(d.matched for d in dets),
                         tuple(x for d in dets for x in d.delays), tuple(x for d in dets for x in d.leads),
                         tuple(x for d in dets for x in d.refused), sum(d.withdrawn for d in dets)), each

    # `next_time`, `run` and `_result` stay apart from `_Run`'s: the one pair has absences, stand-offs,
    # compile on demand and a motion detector's drain, and a stall rule of its own (an agent making room
    # waits on purpose); a team's result has its per-agent and per-pair part.
    def next_time(self) -> float:
        t = self.t
        cands = [self.detector.next_due()]
        for a in self.agents.values():
            m = a.mover
            if m.moving:
                cands.append(t + self.floor.time_to_stop(m))
                if m.blocked_for > 0:
                    cands.append(t + max(_HELD - m.blocked_for % _HELD, MIN_STEP))
            if a.mode == "work":
                cands.append(a.work_end)
            if a.mode == "aside_wait" and a.held_up:  # made room: it looks again whether it may go back or on
                cands.append(t + WAIT_STEP)
        if any(a.mover.moving for a in self.agents.values()):
            cands.append(t + self.floor.safe_step())
        for p in self.people:
            if p.mode == "away" and p.back_at is not None:
                cands.append(max(p.back_at, t + 0.1))  # (again a little later while a robot stands in the way)
            absence = None if p.draws is None else p.draws.absence
            if absence is not None and not p.absence_done:
                cands.append(absence[0])
        if self.model.choice == "follow" and not self.ctl.stopped:
            for p in self.people:
                if p.mode not in ("away", "gone"):
                    cands += self._guide_times(p)
        for r in self.robots:
            o = self.ctl.order(r.id)
            if o is not None and o.event in ("depart", "unpark", "start"):
                cands.append(o.earliest)
        if isinstance(self.ctl, TeamDispatched) and self.ctx.settings.tick > 0 and not self.done():
            cands.append(max(self.last_obs, self.last_tick) + self.ctx.settings.tick)
        if isinstance(self.ctl, TeamDispatched) and (due := self.ctl.due()) is not None:
            cands.append(due)  # plans compiled on demand come then (`hrc.sim.on_demand`)
        future = [c for c in cands if c > t + _EPS and math.isfinite(c)]
        if self.sensors is not None:  # the trackers go on measuring; a detector may yet give an event
            quiet = not future and self.finished_at is None
            self.quiet_since = (self.quiet_since if self.quiet_since is not None else t) if quiet else None
            if self.quiet_since is None or t - self.quiet_since < _QUIET:
                future += [c for sensor in self.sensors.values()
                           for c in (sensor.next_time, sensor.next_arrival()) if c > t + _EPS]
        return min(min(future), self.cap) if future else math.inf

    def _guide_times(self, a: _Agent) -> list[float]:
        if a.mode == "free":
            nxt = a.action or self.choose(a)
            g = None if nxt is None else self.ctl.guide_time(a.id, nxt, self.phases[nxt][a.pi if a.action else 0],
                                                             "depart")
        elif a.mode in ("parked", "arrived") and a.action is not None:
            g = self.ctl.guide_time(a.id, a.action, self.phases[a.action][a.pi],
                                    "unpark" if a.mode == "parked" else "start")
        else:
            g = None
        return [] if g is None else [g]

    def run(self, index: int) -> RunResult:
        reason = ""
        stall_since: float | None = None
        kept: tuple | None = None  # with trackers: the floor's measures at the last phase (the drain left out)
        while True:
            if self.sensors is not None:
                self._sample()
            for _ in range(100):
                changed = self.deliver()
                for p in self.people:
                    if self.person(p):  # the robots act on an answer that knows it (a detector without delay)
                        changed = True
                        self.deliver()
                for r in self.robots:
                    changed = self.robot(r) or changed
                if not changed:
                    break
            if self.joint:
                self.floor.cowork = self._cowork()
            if self.done():
                if self.finished_at is None:
                    self.finished_at = self.t
                    kept = self._measures()
                if self._drained():
                    break
                if self.t >= self.finished_at + _DRAIN:
                    break
            if self.t >= self.cap - _EPS:
                reason = "time cap"
                break
            nt = self.next_time()
            if not math.isfinite(nt):
                reason = "stuck: " + self._why_stuck()
                break
            tick_due = max(self.last_obs, self.last_tick) + self.ctx.settings.tick
            before = (tuple(a.mover.xy for a in self.agents.values()), len(self.happenings))
            self.advance(nt - self.t)
            for a in self.agents.values():
                if a.mode == "travel":
                    if a.mover.moving:
                        a.moved += nt - self.t
                elif a.mode in ("aside", "aside_wait", "returning"):
                    a.aside_time += nt - self.t
                    if a.mode == "aside_wait" and a.held_up:
                        a.wait_for += nt - self.t
            self.t = nt
            if self.ctx.settings.tick > 0 and abs(nt - tick_due) < _EPS:
                self.last_tick = nt
                self.ctl.tick(max(nt, self.last_obs))
                self.last_obs = max(nt, self.last_obs)
            elif isinstance(self.ctl, TeamDispatched) and (due := self.ctl.due()) is not None and nt >= due - _EPS:
                self.ctl.tick(max(nt, self.last_obs))  # the plans compiled on demand have come: a tick takes them in
                self.last_obs = max(nt, self.last_obs)
            moving = [a.mover for a in self.agents.values() if a.mover.moving]
            waiting = [a for a in self.agents.values() if a.mode == "aside_wait"]  # made room, to go back or on
            # everyone under way is held up (an agent waiting to go back waits for them), or nobody is under
            # way and everyone waiting to go back is held up there
            held = all(m.blocked_for > 0 for m in moving) and (bool(moving) or (bool(waiting)
                                                                              and all(a.held_up for a in waiting)))
            if held or ((moving or waiting)
                        and before == (tuple(a.mover.xy for a in self.agents.values()), len(self.happenings))):
                stall_since = self.t if stall_since is None else stall_since
                if self.t - stall_since > self.ctx.settings.stall:
                    reason = "deadlock: agents block each other"
                    break
            else:
                stall_since = None
        if kept is not None and self.sensors is not None:
            self._measures(kept)
        return self._result(index, reason)

    def _measures(self, back: tuple | None = None) -> tuple:
        """The floor's measures now (closest approaches, contacts, co-work, held time), or, given them, put
        back: a run with trackers goes on a while after its last phase (`_drained`), not measured, as one
        pair's."""
        floor = self.floor
        if back is None:
            return (dict(floor.min_free), dict(floor.contacts), floor.cowork_time,
                    {a: ag.mover.held for a, ag in self.agents.items()})
        floor.min_free, floor.contacts, floor.cowork_time = dict(back[0]), dict(back[1]), back[2]
        for a, held in back[3].items():
            self.agents[a].mover.held = held
        return back

    def advance(self, h: float) -> None:
        if h <= 0:
            return
        self.floor.advance(h)
        if self.record:
            self.frames.append((self.t + h, tuple((a.mover.xy[0], a.mover.xy[1], a.mover.present)
                                                  for a in self.agents.values()), tuple(sorted(self.floor.cowork))))

    def _why_stuck(self) -> str:
        gone = [p.id for p in self.people if p.mode == "gone"]
        if gone:
            return f"{', '.join(gone)} left for good"
        if self.ctl.stopped:
            return "the robots stopped (no plan left)"
        robots = ", ".join(f"{r.id} {r.mode} ({self.ctl.order(r.id)})" for r in self.robots)
        people = ", ".join(f"{p.id} {p.mode}" for p in self.people)
        return f"waiting: {robots}; {people}"

    def _result(self, index: int, reason: str) -> RunResult:
        finished, times, makespan, deadline_met, limits_met, span = self._outcome()
        busy = self._busy(times, span)
        seqs = {a: tuple(dict.fromkeys(h.action for h in self.happenings
                                       if h.agent == a and h.event == "depart" and h.action)) for a in self.agents}
        ctl = self.ctl
        first_cp, kept, broken = self._first_kept(self.ctx.compiles[self.policy.compile], finished, times, seqs)
        od = getattr(ctl, "on_demand", None)  # compile on demand (`hrc.sim.on_demand`), with a searched compile
        floor = self.floor
        separation = floor.separation()
        for p in self.people:  # still away when the run ended
            if p.mode in ("away", "gone") and p.away_since is not None:
                p.absent += max(0.0, span - p.away_since)
                p.away_since = None
        idle = {a: max(0.0, span - busy[a] - self.agents[a].absent) for a in self.agents}
        people = [p.id for p in self.people]
        robots = [r.id for r in self.robots]

        def r3(x: float) -> float | None:
            return round(x, 3) if math.isfinite(x) else None

        team = {"agents": {a: {"kind": "human" if self.agents[a].human else "robot", "idle": r3(idle[a]),
                               "held": r3(self.agents[a].mover.held), "sequence": list(seqs[a])}
                           for a in self.agents},
                "min_distance": {f"{a}-{b}": r3(d) for (a, b), d in floor.min_free.items()},
                "robot_contacts": floor.robot_contacts(),
                "people_contacts": sum(n for (a, b), n in floor.contacts.items()
                                       if self.agents[a].human and self.agents[b].human)}
        ssm = None
        if floor.ssm is not None:  # speed and separation monitoring: each robot's, and all of them as one
            per = {r: t.measures() for r, t in floor.ssm.items()}
            team["ssm"] = {r: m.to_json() for r, m in per.items()}
            ssm = combined(list(per.values()))
        detection, each = self._detection()
        if each:  # with trackers: each person's detector against their own events (issue 37)
            team["detection"] = {p: d.to_json() for p, d in each.items()}
        joint = None
        if self.joint:
            joint = {"told_to_start": len(self.told), "told_before_arrival": len(self.told_early),
                     "cowork_seconds": round(floor.cowork_time, 3)}
        return RunResult(
            policy=self.policy.name, run=index, finished=finished, reason="" if finished else reason,
            makespan=makespan, deadline_met=bool(deadline_met), limits_met=bool(limits_met),
            human_idle=sum(idle[p] for p in people), robot_idle=sum(idle[r] for r in robots),
            robot_yield=sum(self.agents[r].mover.held for r in robots),
            human_held=sum(self.agents[p].mover.held for p in people), standoffs=self.standoffs,
            robot_aside=sum(self.agents[r].aside_time for r in robots),
            human_aside=sum(self.agents[p].aside_time for p in people),
            min_distance=None if not math.isfinite(separation) else separation,
            overlaps=floor.overlaps(), plan_switches=ctl.switches, first_plan=ctl.first_plan,
            first_class=ctl.first_class, first_blocked=first_cp is not None and first_cp.blocked,
            final_plan=ctl.plan_id, first_kept=bool(kept), first_broken=broken, refused=tuple(ctl.refused),
            late=self.late, robot_travel_excess=self.excess, human_sequence=seqs[people[0]] if people else (),
            robot_sequence=seqs[robots[0]] if robots else (), overruns=sum(
                1 for p in self.people if p.draws is not None for x, ph in p.draws.overrun
                if x in seqs[p.id] and f"{self._lead(x) if x in self.joint else p.id}.{ph}.{x}.end" in times),
            absent=sum(p.absent for p in self.people), latencies=tuple(ctl.latencies), joint=joint, team=team, ssm=ssm,
            detection=detection,
            late_observations=getattr(ctl, "late_observations", None),
            first_sensing_class=None if first_cp is None else first_cp.plan_class.value,
            on_demand=None if od is None else od.to_json(),
            compile_seconds=() if od is None else tuple(od.compile_seconds),
            happenings=tuple(self.happenings) if self.record else (),
            agent_frames=tuple(self.frames))

    def _busy(self, times: dict[str, float], span: float) -> dict[str, float]:
        busy = dict.fromkeys(self.agents, 0.0)
        for action, ags in self.joint.items():  # every other agent works it from the lead's start to its end
            lead = self._lead(action)
            if action in self.choosing:  # its crew: those who came (none started it while incomplete)
                ags = self.came(action)
            for phase in self.phases[action]:
                a, b = times.get(f"{lead}.{phase}.{action}.start"), times.get(f"{lead}.{phase}.{action}.end")
                if a is not None and b is not None:
                    for ag in ags:
                        if ag != lead:
                            busy[ag] += min(b, span) - min(a, span)
        add_busy(busy, times, span)
        return busy
