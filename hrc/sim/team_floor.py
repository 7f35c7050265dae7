"""The shop floor of a team (issue 37): every person and every robot as a disc in the pymunk world.

`hrc.sim.floor.Floor` holds one person and one robot; `TeamFloor` holds any number of each, by the same
rules taken pair by pair (`Mover`, the route walking and the closest-approach geometry are the floor's):

- **each person walks on** at their pace and stops `CONTACT` short of every robot (a person stops in front
  of a machine); people do not stop for each other (the task leaves two people to give way as people do,
  docs/motion.md "More than two agents": the compile reports where they may meet), and their closest
  approach is measured (`people_min`);
- **each robot keeps the safety margin from every person present**, as the one robot does (it slows in
  the `slowdown` band, never steps closer than the margin, and backs off along its route when a person
  keeps coming closer), and **stops `CONTACT` short of every other robot**: two robots are kept apart by
  the passing order their plan chose (`hrc.motion.conflicts`), and the floor never pushes one into the
  other;
- **co-work at a joint spot** (`cowork`: the pairs the run loop says co-work now, `hrc.sim.team_run`):
  ``(person, robot)``, the separation is not asked for between the two of a pair, and their distance is
  not measured, as on the one-pair floor; ``(robot, robot)`` (two robots of one joint phase, the one driving
  up to, standing at or driving away from the spot first, the one standing there second), neither stops
  short of the other and their distance and contacts are not measured: a location is a point, so both stand
  at it, as a person and a robot do (docs/simulate.md, "Two robots at a joint spot").

Measured: `min_free` per robot-person pair (the separation, outside co-work) and per other pair, and pymunk
contacts per pair (`contacts`: each step in which two discs touched, asked of pymunk only when two discs
are closer than `QUERY_GAP`): a robot-person contact is an `overlaps` of the one-pair floor, a robot-robot
contact a violation (0 expected; `robot_contacts`: co-working robots left out).

**Under speed and separation monitoring** (a task with `safety:`), each robot obeys `hrc.sim.ssm` against
every person present (`hrc.sim.ssm.ssm_limit`, the one pair's rule, taken person by person): towards each
person it drives towards, no faster than the protective separation from that person allows, so the most
demanding one (the closest, for robots of one speed) decides its speed (top, the reduced speed, or a
protective stop), and the step ends exactly where the free distance to any of them reaches ``S_p`` of the
speed it drove; it keeps ``S_p(0)`` from every person when it drives at all, and backs off as above when a
person keeps coming closer than that. Two robots keep `CONTACT` apart, as without `safety:` (ISO/TS 15066
keeps a robot from a person; two robots are kept apart by their plan's passing order). One `SsmTally` per
robot (`ssm`, by id) counts its protective stops, their time, its slowing, its closest approach to a person
while driving towards them, the closest a person walked up to it standing, and breaches.

Persons move first, then robots, in task order; each is walked against where the others stand at that
moment, so steps are short while two of them move near each other (`safe_step`).
Cost: O(agents^2) per step for the distances, one pymunk step only when two discs nearly touch.
"""

from __future__ import annotations

import math
from itertools import combinations

from hrc.model import Task
from hrc.motion.separation import protective_separation
from hrc.motion.world import World
from hrc.sim.floor import (
    CONTACT,
    MAX_STEP,
    MIN_STEP,
    QUERY_GAP,
    Mover,
    _closest,
    _entry,
    add_mover,
    place_mover,
    tally,
    time_to_stop,
)
from hrc.sim.ssm import SsmTally, ssm_limit

__all__ = ["TeamFloor", "is_team"]

Point = tuple[float, float]


def is_team(task: Task) -> bool:
    """Whether `task` has other than one person and one robot (it runs on this floor, `hrc.sim.team_run`)."""
    people = sum(1 for a in task.agents if a.is_human)
    return (people, len(task.agents) - people) != (1, 1)


class TeamFloor:
    """The world with every agent's disc (`movers`, by id, in task order); `advance` moves them by the rules
    of the module docstring."""

    def __init__(self, task: Task, slowdown: float = 0.0) -> None:
        self.task = task
        self.world = World(task.workspace)
        self.margin = task.safety_margin
        self.slowdown = slowdown
        self.movers: dict[str, Mover] = {a.id: add_mover(self.world, task, a) for a in task.agents}
        self.people = tuple(self.movers[a.id] for a in task.agents if a.is_human)
        self.robots = tuple(self.movers[a.id] for a in task.agents if not a.is_human)
        self.pairs = tuple(combinations(task.agent_ids, 2))  # task order: (a, b) with a before b
        self.min_free: dict[tuple[str, str], float] = {p: math.inf for p in self.pairs}
        self.contacts: dict[tuple[str, str], int] = {p: 0 for p in self.pairs}
        self.cowork: frozenset[tuple[str, str]] = frozenset()  # pairs co-working now (module docstring)
        self.cowork_time = 0.0  # s in which some pair co-worked
        # speed and separation monitoring (a task with safety:): one tally per robot; every robot keeps S_p(0)
        # from every person, and driving the band up to S_p at its own speed (`safe_step`)
        self.ssm: dict[str, SsmTally] | None = None
        self._band: dict[str, float] = {}
        if task.safety is not None:
            self.ssm = {r.agent.id: SsmTally(task.safety) for r in self.robots}
            self.margin = protective_separation(task.safety, 0.0).total
            self._band = {r.agent.id: protective_separation(task.safety, r.agent.speed).total - self.margin
                          for r in self.robots}

    # -- distances ---------------------------------------------------------------------------------------

    @staticmethod
    def gap(a: Mover, b: Mover, pa: Point | None = None, pb: Point | None = None) -> float:
        """Free distance (m) between two discs (at `pa` / `pb` instead of where they are, if given); inf
        when either is away from the floor."""
        if not (a.present and b.present):
            return math.inf
        p, q = pa or a.xy, pb or b.xy
        return math.hypot(p[0] - q[0], p[1] - q[1]) - a.agent.radius - b.agent.radius

    def _key(self, a: Mover, b: Mover) -> tuple[str, str]:
        x, y = a.agent.id, b.agent.id
        return (x, y) if (x, y) in self.min_free else (y, x)

    def shared(self, a: Mover, b: Mover) -> bool:
        """The two co-work now (a person and a robot: their separation is not asked for; two robots: neither
        stops short of the other)."""
        return (a.agent.id, b.agent.id) in self.cowork or (b.agent.id, a.agent.id) in self.cowork

    def separation(self) -> float:
        """The smallest free distance seen between a robot and a person (outside co-work), inf: never both
        on the floor."""
        return min((d for (a, b), d in self.min_free.items() if self._kinds(a, b) == {True, False}),
                   default=math.inf)

    def _kinds(self, a: str, b: str) -> set[bool]:
        return {self.movers[a].agent.is_human, self.movers[b].agent.is_human}

    def robot_contacts(self) -> int:
        return sum(n for (a, b), n in self.contacts.items() if self._kinds(a, b) == {False})

    def overlaps(self) -> int:
        """Robot-person contacts (the one-pair floor's `overlaps`)."""
        return sum(n for (a, b), n in self.contacts.items() if self._kinds(a, b) == {True, False})

    # -- time --------------------------------------------------------------------------------------------

    time_to_stop = staticmethod(time_to_stop)

    # `safe_step` and `advance` stay apart from `Floor`'s: the one-pair floor's steps carry speed and
    # separation monitoring and co-work of its one pair (and `_sync` is being reworked on its own branch).
    def safe_step(self) -> float:
        """A step (s) short enough that no two agents come near each other in it unseen: for every pair of
        which both move (or a robot moves near a person with a `slowdown` band), half the time their joint
        pace takes to close the gap down to what the rules keep between them (at least `MIN_STEP`; under
        speed and separation monitoring, as with a `slowdown` band, for a robot and a person of whom one moves:
        down to ``S_p`` at the robot's speed, the rule being one of the gap at each step's start); else
        `MAX_STEP` (a walk against a standing disc stops exactly where it must, `_walk`)."""
        step = MAX_STEP
        for m, n in combinations(self.movers.values(), 2):
            if not (m.present and n.present) or not (m.moving or n.moving):
                continue
            banded = (self.slowdown > 0 or self.ssm is not None) and m.agent.is_human != n.agent.is_human
            if not (m.moving and n.moving) and not banded:
                continue
            if m.agent.is_human and n.agent.is_human:
                keep = 0.0
            elif m.agent.is_human != n.agent.is_human:
                person, robot = (m, n) if m.agent.is_human else (n, m)
                if self.shared(person, robot):
                    continue
                keep = self.margin + (self.slowdown if self.ssm is None else self._band[robot.agent.id])
            elif self.shared(m, n):
                continue
            else:
                keep = CONTACT
            g = self.gap(m, n) - keep
            if math.isfinite(g):
                step = min(step, max(MIN_STEP, g / (m.agent.speed + n.agent.speed) / 2))
        return step

    def advance(self, h: float) -> None:
        """Move every agent for `h` seconds: the people first, then the robots (module docstring)."""
        for m in self.people:
            if m.present and m.moving:
                self._person_step(m, h)
        for m in self.robots:
            if m.moving:
                self._robot_step(m, h)
        if self.cowork:
            self.cowork_time += h
        self._sync(h)

    def _person_step(self, m: Mover, h: float) -> None:
        want = min(m.speed * h, m.remaining)
        got = want
        stops = [r for r in self.robots if not self.shared(m, r)]
        for r in stops:  # stop CONTACT short of every robot (or as close as it already is)
            floor = min(CONTACT, self.gap(m, r)) - 1e-12
            got = min(got, self._reach(m, want, r.xy, m.agent.radius + r.agent.radius + floor))
        self._measure(m, got, stops + [p for p in self.people if p is not m])
        before = [self.gap(m, r) for r in stops] if self.ssm is not None else []
        self._move(m, got)
        if self.ssm is not None:  # the person walked up to a standing robot (stopped, or at a place)?
            for r, free_before in zip(stops, before, strict=True):
                ssm = self.ssm[r.agent.id]
                ssm.person_step(not r.moving or ssm.stopped, free_before, self.gap(m, r))
        tally(m, h, want, got, got)

    def _robot_step(self, m: Mover, h: float) -> None:
        want = min(m.speed * h, m.remaining)
        ahead = m.at(m.s + min(want, 1e-3) if want > 0 else m.s)
        people = [p for p in self.people if p.present and not self.shared(p, m)]
        others = [r for r in self.robots if r is not m and not self.shared(m, r)]
        ssm = None if self.ssm is None else self.ssm[m.agent.id]
        scale, closing_in, allowed = 1.0, False, m.speed
        keeps: list[float] = []  # per person, the free distance the step keeps from them
        closing: list[Mover] = []  # the people it drives towards
        for p in people:
            before = self.gap(m, p)
            towards = self.gap(m, p, ahead) < before
            if towards:
                closing.append(p)
                closing_in = closing_in or before < self.margin - 1e-6  # the person came closer than it stopped
            if ssm is not None:  # the most demanding person decides the speed (`hrc.sim.ssm.ssm_limit`)
                speed, keep = ssm_limit(ssm.safety, before, m.speed, towards, self.margin)
                allowed = min(allowed, speed)
                keeps.append(keep)
                continue
            keeps.append(min(self.margin, before))
            if towards and self.slowdown > 0 and before < self.margin + self.slowdown:
                scale = min(scale, max(0.0, min(1.0, (before - self.margin) / self.slowdown)))
        if ssm is not None:  # a step at `allowed` ends at S_p(allowed) from every person it drives towards
            want = min(want, allowed * h)
            if allowed > 0:  # (S_p(allowed) is below each one's distance: `ssm_speed` allowed at most that)
                sp = protective_separation(ssm.safety, allowed).total
                keeps = [sp if p in closing else k for p, k in zip(people, keeps, strict=True)]
        want *= scale
        got = want
        for p, limit in zip(people, keeps, strict=True):
            got = min(got, self._reach(m, want, p.xy, m.agent.radius + p.agent.radius + limit - 1e-12))
        for r in others:
            limit = min(CONTACT, self.gap(m, r))
            got = min(got, self._reach(m, want, r.xy, m.agent.radius + r.agent.radius + limit - 1e-12))
        self._measure(m, got, people + others)
        self._move(m, got)
        if ssm is not None:
            free = min((self.gap(m, p) for p in closing), default=math.inf)
            ssm.robot_step(h, m.speed, allowed, bool(closing), max(0.0, got), free)
        if got <= 1e-12 and closing_in and m.s > 0:  # a person keeps coming: make room, back along the route
            self._back_off(m, m.speed * h / 2, people)
        tally(m, h, min(m.speed * h, m.remaining + max(0.0, got)), got, max(0.0, got))

    @staticmethod
    def _reach(m: Mover, want: float, centre: Point, reach: float) -> float:
        """How far `m` may go of `want` metres before its centre comes closer than `reach` to `centre`
        (`hrc.sim.floor._entry`: exact on the route's segments)."""
        if want <= 0:
            return 0.0
        ex, ey = m.at(m.s + want)
        cx, cy = centre
        if (ex - cx) ** 2 + (ey - cy) ** 2 >= reach * reach:
            return want
        return max(0.0, _entry(m, m.s + want, cx, cy, reach) - m.s)

    def _measure(self, m: Mover, got: float, others: list[Mover]) -> None:
        """The closest approach on the way of `m`'s step to each of `others` (free distance, per pair)."""
        for o in others:
            if not (m.present and o.present):
                continue
            key = self._key(m, o)
            radii = m.agent.radius + o.agent.radius
            if math.dist(m.xy, o.xy) - got - radii < self.min_free[key]:
                self.min_free[key] = min(self.min_free[key], _closest(m, m.s + got, *o.xy) - radii)

    # Apart from the one-pair floor's `Floor._walk` on purpose: the step is split into how far (`_reach`,
    # against every other disc) and the move, and a move never goes back (`max(0, got)`); `_walk` moves by
    # its one limit as computed, so one shared walk would change the one-pair floor's numbers in the last bit.
    @staticmethod
    def _move(m: Mover, got: float) -> None:
        m.s += max(0.0, got)
        if m.s >= m.stop_at - 1e-9:
            m.s, m.moving = m.stop_at, False
        m.xy = m.at(m.s)

    def _back_off(self, m: Mover, distance: float, people: list[Mover]) -> None:
        s = max(0.0, m.s - distance)
        p = m.at(s)
        if min(self.gap(m, q, p) for q in people) > min(self.gap(m, q) for q in people) and \
                all(self.gap(m, r, p) >= min(CONTACT, self.gap(m, r)) for r in self.robots
                    if r is not m and not self.shared(m, r)):
            m.s, m.xy = s, p

    def _sync(self, h: float) -> None:
        """The pymunk bodies to the agents' positions; each pair's free distance at the step's end; pymunk
        asked for contacts when two discs are closer than `QUERY_GAP` (co-working pairs left out)."""
        close: list[tuple[Mover, Mover]] = []
        for a, b in self.pairs:
            m, n = self.movers[a], self.movers[b]
            if not (m.agent.is_human and n.agent.is_human) and self.shared(m, n):
                continue
            d = self.gap(m, n)
            if math.isfinite(d):
                self.min_free[(a, b)] = min(self.min_free[(a, b)], d)
                if d <= QUERY_GAP:
                    close.append((m, n))
        if not close:
            for m in self.movers.values():
                m.body.position = m.xy
            return
        for m in self.movers.values():
            old = m.body.position
            m.body.velocity = ((m.xy[0] - old.x) / h, (m.xy[1] - old.y) / h) if h > 0 else (0.0, 0.0)
        self.world.space.step(h if h > 0 else 1e-9)
        for m in self.movers.values():
            m.body.position = m.xy
            m.body.velocity = (0.0, 0.0)
            self.world.space.reindex_shapes_for_body(m.body)
        for m, n in close:
            hits = self.world.space.shape_query(m.shape)
            if any(hit.shape is n.shape and any(p.distance < -1e-6 for p in hit.contact_point_set.points)
                   for hit in hits):
                self.contacts[self._key(m, n)] += 1

    place = staticmethod(place_mover)
