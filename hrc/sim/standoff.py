"""Standoffs on the floor: the two co-workers keep each other from going on, and one gives way.

Strassmair & Taylor 2014 (section V.A) note that in a plan "one worker might block the other's way";
motion acquisition orders them so that it does not happen (`hrc.motion.conflicts`). On the simulated
floor it still can: under a policy that ignores motion, a plan the compile found blocked, a person who
does not follow the plan. A person on a real floor does not stand facing a robot for ever, and a robot
that is in someone's way makes room; these rules do that, deterministically, and count what it cost.

An agent is *held up* when the co-worker keeps it from going on (the floor cuts its steps,
`Mover.blocked_for`; or, after making room, the standing co-worker is in its way back). After
`ASIDE_AFTER` seconds of that, the standoff is resolved, in this order:

- the co-worker is *working* (manipulating), or away: the held-up agent goes round it on the roadmap if
  it can (not when the co-worker works at its goal), else waits: the work ends;
- the co-worker *stands* idle (waiting at a location or a waiting place, or after making room): the
  held-up agent goes round it if that is at most `WALK_ROUND` metres longer, else the co-worker **makes
  room**, else the agent goes round it however long the way;
- both are *on the move* and one holds the other up (head-on, in a passage): the robot makes room for
  the person, else (no spot for it) the person for the robot, else the held-up agent goes round. Of two
  robots (a team, `hrc.sim.team_run`), the one whose next phase may not start makes room for the one whose
  may, else the later in task order, else the other; of two people, the same (`yields`).

Making room (`hrc.sim.giveway.Ways.spot`): the agent goes to the nearest roadmap milestone at least
``reach + CLEAR`` (in a tight place ``reach + AWAY``) from every point of the co-worker's way (its
position, the rest of its route, its goal), and waits there until the co-worker is clear of its way
back or on (farther than ``reach + CLEAR`` from it, and not about to cross it); then an agent that stood
goes back to where it stood and is as it was (arrived, parked, ...), one that was on its way goes on to
where it was going, one that had nothing under way stays. When both wait to move and their ways cross,
the one whose next phase may start goes first, else the one room was last made for (by the other of the
pair), else the person, else (two of a kind) the earlier in task order.
An agent waiting to go back or on asks the co-worker standing in its way to make room only when it has
business there (its phase may start, or it was on its way or at a waiting place) and is not simply
waiting for that co-worker's phase (the co-worker's next phase may start and its own may not); a robot
that stopped (its controller has no plan left, or, under speed and separation monitoring, it is in a
protective stop) never asks. So two agents with nothing to do there do not chase each other round.

Every resolution counts in `standoffs`; the time each agent spends making room in `robot_aside` /
`human_aside`; the robot's slowed or stopped time in `robot_yield` as before. The floor's rule (the
person stops 2 cm short of the robot, the robot at the safety margin) holds throughout, so the discs
never overlap whatever the routes.

`Standoffs` holds the rules as methods of a run loop, for a pair of agents at a time: the one pair's
(`hrc.sim.run._Run`) and a team's (`hrc.sim.team_run._TeamRun`, every pair that meets on its floor) both
derive from it and say what is theirs through a few hooks (`_reach` of a pair, `_yields`, `_halted`,
`_guided`, `_coworks_at`, `_room_made` / `_room_made_for`, `_blocker`, `_also`: the other agents a spot
and a way round keep clear of); `yields` is the give-way order of two of a kind (two robots, two people).
`AgentState` is one agent's state in the one pair's loop (a team's `_Agent` has the same fields, `Yielder`);
`hrc.sim.giveway` finds the spots and the ways round. Cost: nothing while nobody is held up; one roadmap
search per resolution.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, TypeVar

import numpy as np

from hrc.model import Task
from hrc.sim.agents import AgentLoop, Walker
from hrc.sim.floor import Mover
from hrc.sim.giveway import Disc, Ways, polyline_length, samples
from hrc.sim.policies import Order, SimRoute

__all__ = ["ASIDE_AFTER", "AWAY", "CLEAR", "WAIT_STEP", "WALK_ROUND", "AgentState", "Aside", "Standoffs", "Yielder",
           "yields"]

ASIDE_AFTER = 2.0  # s: held up by the co-worker this long (or waiting this long to go on) is a standoff
WALK_ROUND = 3.0  # m: a way round a standing co-worker at most this much longer is taken before asking it to move
CLEAR = 0.3  # m: beyond reach, how far a spot to make room at lies from every point of the co-worker's way,
# and how far the co-worker must be from an agent's way back before it goes back
AWAY = 0.05  # m: the same for a spot in a tight place (no spot CLEAR away), and for two ways that cross
WAIT_STEP = 0.25  # s: how often an agent that made room and is held up looks again


@dataclass(frozen=True, slots=True)
class Aside:
    """What an agent that makes room left: its mode, location, leg route and mover state; `standing`:
    it stood (it goes back there, `target` = where it stood) or was on its way (it goes on, `target` =
    its route's end)."""

    mode: str
    loc: str | None
    route: SimRoute | None
    parked: bool
    standing: bool
    xy: tuple[float, float]
    points: tuple[tuple[float, float], ...]
    cum: tuple[float, ...]
    s: float
    stop_at: float
    speed: float

    @property
    def target(self) -> tuple[float, float]:
        return self.xy if self.standing else self.points[-1]

    @classmethod
    def of(cls, a: Yielder) -> Aside:
        m = a.mover
        return cls(a.mode, a.loc, a.route, a.parked, not m.moving, m.xy, tuple(m.points), tuple(m.cum), m.s,
                   m.stop_at, m.speed)


@dataclass(slots=True)
class AgentState:
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
    aside: Aside | None = None  # what it left to make room (None: not making room)
    next_way: tuple[tuple[float, float], ...] | None = None  # its way back or on, from the spot
    wait_for: float = 0.0  # s waited at the spot with the standing co-worker in that way
    held_up: bool = False  # the standing co-worker is in its way back or on
    aside_time: float = 0.0  # s spent making room (to the spot, there, back)
    predicted: float = 0.0  # predicted moving time of the current travel (robot)
    moved: float = 0.0  # moving time of the current travel so far, pauses excluded
    blocker: str | None = None  # a team's: the agent that holds it up at the spot (`held_up`)


class Yielder(Walker, Protocol):
    """What the standoff rules read and write of an agent (`AgentState`; a team's `hrc.sim.team_run._Agent`)."""

    aside: Aside | None
    next_way: tuple[tuple[float, float], ...] | None
    wait_for: float
    held_up: bool
    aside_time: float
    blocker: str | None


S = TypeVar("S", bound=Yielder)


def yields(a_startable: bool, b_startable: bool, a_first_in_task: bool) -> bool:
    """Whether `a` makes room for `b`, of two agents of one kind both on the move (two robots, two people;
    issue 37): the one whose next phase may not start makes room for the one whose may (it has the task's
    business there now); else the later in task order (deterministic)."""
    if a_startable != b_startable:
        return b_startable
    return not a_first_in_task


class Standoffs(AgentLoop[S]):
    """The standoff rules (module docstring), as methods of the run loop that derives from this."""

    task: Task
    ways: Ways
    phases: dict[str, tuple[str, ...]]
    standoffs: int

    # -- what each loop says of a pair ------------------------------------------------------------------

    def _reach(self, a: S, b: S) -> float:
        """The centre distance `a` and `b` keep when one makes room or goes round the other: the radii and the
        margin, or, under speed and separation monitoring, the protective separation at the robot's speed
        (a spot nearer its way would leave the robot stopped by its own controller: `hrc.sim.ssm`)."""
        raise NotImplementedError

    def _yields(self, x: S, y: S) -> tuple[tuple[S, S], tuple[S, S]]:
        """Of `x` and `y`, both on the move, who makes room for whom first, and who then."""
        raise NotImplementedError

    def _before(self, a: S, b: S) -> bool:
        """The last tie-break of `_first`: `a` goes before `b` (the person, of the one pair)."""
        raise NotImplementedError

    def _halted(self, a: S) -> bool:
        """`a` is a robot that stopped (it never asks to be let through)."""
        raise NotImplementedError

    def _guided(self, a: S, action: str, phase: str) -> bool:
        """For a person who follows the plan: the plan does not have them wait for the robot at this phase."""
        raise NotImplementedError

    def _room_made(self, g: S, o: S) -> None:
        """`g` makes room for `o` (remembered for `_first`)."""
        raise NotImplementedError

    def _room_made_for(self, a: S, b: S) -> S | None:
        """Which of `a` and `b` room was last made for (None: not known)."""
        raise NotImplementedError

    def _coworks_at(self, a: S, other: S, target: tuple[float, float]) -> bool:
        """Whether `other` stands at `target` to co-work with `a` there (a joint action, issue 37: each loop
        says when), so that it is not in `a`'s way back or on; never without joint actions."""
        return False

    def _also(self, a: S, o: S) -> tuple[Disc, ...]:
        """The discs, besides `o`'s, that `a`'s spot and way round keep clear of (a team's other agents)."""
        return ()

    def _blocker(self, a: S, others: Sequence[S]) -> S | None:
        """Which of `others` holds `a` up (None: none does)."""
        return others[0] if others else None

    # -- the rules ---------------------------------------------------------------------------------------

    def _stuck(self, a: S) -> float:
        """Seconds `a` has wanted to go on and could not because of the co-worker."""
        if a.mode == "work":
            return 0.0
        return a.mover.blocked_for if a.mover.moving else (a.wait_for if a.mode == "aside_wait" else 0.0)

    def _way(self, a: S) -> np.ndarray:
        """Where `a` is and means to go next: the rest of its route, or its way on after making room."""
        m = a.mover
        if m.moving:
            return samples([m.xy] + [p for p, c in zip(m.points, m.cum, strict=True) if c > m.s])
        if a.mode == "aside_wait" and a.next_way is not None:
            return samples(a.next_way)
        return np.asarray([m.xy])

    def _give_way(self, a: S, others: Sequence[S]) -> bool:
        """`a`'s steps of making room (to a spot, waiting there, back or on), and, when it has been held up
        by one of `others` (`_blocker`) for `ASIDE_AFTER` seconds, the standoff's resolution (module docstring)."""
        if a.mode == "aside" and not a.mover.moving:
            assert a.aside is not None
            a.mode, a.wait_for = "aside_wait", 0.0
            a.next_way = self.ways.route(self._clearance(a), a.mover.xy, a.aside.target) or (a.mover.xy, a.aside.target)
            return True
        if a.mode == "aside_wait" and self._go_on(a, others):
            return True
        if a.mode == "returning" and not a.mover.moving:
            self._restore(a)
            return True
        if self._stuck(a) >= ASIDE_AFTER:
            a.mover.blocked_for = a.wait_for = 0.0
            y = self._blocker(a, others)
            return y is not None and self._resolve(a, y)
        return False

    def _resolve(self, x: S, y: S) -> bool:
        """`x` has been held up by `y`: who gives way, and how (module docstring)."""
        if y.mode in ("work", "away", "gone") or not y.mover.present:
            return self._walk_round(x, y, math.inf)  # y is busy (it will be done) or gone: round it, or wait
        if y.mode == "aside" and y.mover.moving and self._stuck(y) < ASIDE_AFTER:
            return False  # y is on its way out of x's way
        if not y.mover.moving:  # y stands idle: x goes round it if that is short, else y makes room
            return self._walk_round(x, y, WALK_ROUND) or self._make_room(y, x) or self._walk_round(x, y, math.inf)
        # both on the move: the robot gives way to the person, else the person to the robot (`_yields`)
        (g1, o1), (g2, o2) = self._yields(x, y)
        return self._make_room(g1, o1) or self._make_room(g2, o2) or self._walk_round(x, y, math.inf)

    def _make_room(self, g: S, o: S) -> bool:
        """`g` goes to the nearest spot off `o`'s way (`hrc.sim.giveway.Ways.spot`); False if there is none."""
        if g.mode in ("work", "away", "gone"):
            return False
        reach = self._reach(g, o)
        way, disc, also = self._way(o), Disc(o.mover.xy, reach), self._also(g, o)
        spot = self.ways.spot(self._clearance(g), g.mover.xy, disc, way, reach + CLEAR, also) \
            or self.ways.spot(self._clearance(g), g.mover.xy, disc, way, reach + AWAY, also)  # a tight place
        if spot is None and also:  # none clear of the others too: one clear of `o` (the floor still keeps
            spot = self.ways.spot(self._clearance(g), g.mover.xy, disc, way, reach + CLEAR) \
                or self.ways.spot(self._clearance(g), g.mover.xy, disc, way, reach + AWAY)  # them apart)
        if spot is None or len(spot) < 2:
            return False
        if g.aside is None:
            g.aside = Aside.of(g)
        g.mode, g.loc, g.next_way = "aside", None, None
        g.mover.set_route(spot, g.mover.agent.speed)
        self.standoffs += 1
        self._room_made(g, o)
        return True

    def _walk_round(self, x: S, y: S, extra: float) -> bool:
        """`x` goes round the standing `y` to where it is going, if the way round is at most `extra` metres
        longer than the way it is held up on."""
        reach = self._reach(x, y)
        m = x.mover
        if x.mode == "aside_wait" and x.aside is not None:
            start, goal, ahead = m.xy, x.aside.target, polyline_length(x.next_way or (m.xy,))
        elif m.moving and x.mode in ("travel", "home", "aside", "returning"):
            start, goal = m.xy, m.points[-1]
            ahead = m.length - m.s
        else:
            return False
        also = self._also(x, y)
        way = self.ways.route(self._clearance(x), start, goal, Disc(y.mover.xy, reach), also)
        if way is None and also:  # none clear of the others too: one round `y` only
            way = self.ways.route(self._clearance(x), start, goal, Disc(y.mover.xy, reach))
        if way is None or len(way) < 2 or polyline_length(way) > ahead + extra:
            return False
        if x.mode == "aside_wait":
            self._go(x, way)
        else:
            self._set_way(x, way)
        self.standoffs += 1
        return True

    def _go_on(self, a: S, others: Sequence[S]) -> bool:
        """After making room: back to where it stood, or on to where it was going, once every one of `others`
        is clear of that way (not within reach + `CLEAR` of it, and not about to cross it)."""
        assert a.aside is not None
        if a.aside.mode == "free" and a.aside.standing:  # it had nothing under way there: it stays here
            self._go(a, (a.mover.xy,))
            return True
        if a.next_way is None:
            a.next_way = self.ways.route(self._clearance(a), a.mover.xy, a.aside.target) or (a.mover.xy, a.aside.target)
        mine = samples(a.next_way)
        for other in others:
            if not self._clear_of(a, mine, other):
                return False
        self._go(a, a.next_way)
        return True

    def _clear_of(self, a: S, mine: np.ndarray, other: S) -> bool:
        """Whether `other` leaves `a`'s way back or on (`mine`, its samples) free; if not, whether it holds
        `a` up (`held_up`, by `blocker`: it stands in that way and `a` may ask it to move, `_needs_way`)."""
        assert a.aside is not None
        o = other.mover
        if not o.present or self._coworks_at(a, other, a.aside.target):
            return True
        reach = self._reach(a, other)
        near = float(np.min(np.hypot(mine[:, 0] - o.xy[0], mine[:, 1] - o.xy[1])))
        waits = other.mode == "aside_wait" and other.next_way is not None
        first = waits and self._first(other, a)  # the co-worker waits to go too, and goes first
        if near < reach + CLEAR:
            a.held_up = not o.moving and not first and self._needs_way(a, other)
            a.blocker = other.id
            return False
        if o.moving or first:
            theirs = self._way(other)
            if float(np.min(np.hypot(mine[:, None, 0] - theirs[None, :, 0],
                                     mine[:, None, 1] - theirs[None, :, 1]))) < reach + AWAY:
                a.held_up = False
                return False
        return True

    def _first(self, a: S, b: S) -> bool:
        """When both wait to go back or on and their ways cross: `a` goes before `b` if its next phase may
        start (the task graph's predecessors have ended) and `b`'s may not; else the one room was last
        made for; else the person (`_before`)."""
        ra, rb = self._startable(a), self._startable(b)
        if ra != rb:
            return ra
        last = self._room_made_for(a, b)
        if last is not None:
            return last is a
        return self._before(a, b)

    def _needs_way(self, a: S, other: S) -> bool:
        """Whether `a`, waiting to go back or on, may ask `other`, standing in its way, to move: it was on
        its way, or waited at a waiting place, or its phase there may start now; and it is not waiting
        for `other` anyway (`other`'s next phase may start and `a`'s may not: `other` goes on first).
        Never a robot that stopped."""
        if self._halted(a):
            return False
        assert a.aside is not None
        mine = self._startable(a)
        return (not a.aside.standing or a.aside.mode == "parked" or mine) and (mine or not self._startable(other))

    def _startable(self, a: S) -> bool:
        """`a`'s next phase may start as far as the task graph goes (and, for a person who follows the
        plan, the plan does not have them wait for the robot)."""
        if a.action is None:
            return False
        phase = self.phases[a.action][a.pi]
        return self.ready(a.action, phase) and self._guided(a, a.action, phase)

    def _go(self, a: S, way: tuple[tuple[float, float], ...]) -> None:
        assert a.aside is not None
        a.held_up, a.wait_for, a.next_way = False, 0.0, None
        if a.aside.standing and a.aside.mode != "free":
            a.mode = "returning"
            a.mover.set_route(way, a.mover.agent.speed)
            return
        snap, a.aside = a.aside, None
        a.mode, a.route, a.parked = snap.mode, snap.route, snap.parked
        if a.mode == "free":  # it stays at the spot, off the co-worker's way; its next leg starts here
            a.mover.set_route((a.mover.xy,), 0.0)
            return
        self._set_way(a, way, snap.speed)

    def _set_way(self, a: S, way: tuple[tuple[float, float], ...], speed: float | None = None) -> None:
        """`a` travels on along `way` (a leg with a waiting place not reached yet stops at its end, and
        waits there for the order to go on, which then arrives at once)."""
        a.mover.set_route(way, speed or a.mover.speed or a.mover.agent.speed)
        if a.mode == "travel" and a.route is not None and a.route.park_s is not None and not a.parked:
            a.route = SimRoute(way, a.route.park, polyline_length(way))

    def _restore(self, a: S) -> None:
        """Back where it stood before making room: as it was."""
        snap = a.aside
        assert snap is not None
        a.mode, a.loc, a.route, a.parked, a.aside = snap.mode, snap.loc, snap.route, snap.parked, None
        m = a.mover
        m.points, m.cum, m.s, m.stop_at, m.speed = list(snap.points), list(snap.cum), snap.s, snap.stop_at, snap.speed
        m.xy, m.moving = snap.xy, False
