"""The shop floor in simulated time: the two agents as discs in the pymunk world, moving along routes.

The workspace is `hrc.motion.World` (pymunk space + FCL objects); each agent is a kinematic circle body
in it (`World.add_agent`). A `Mover` holds an agent's current route (a polyline, parameterised by arc
length) and how far along it is; `Floor.advance(h)` moves both for `h` seconds:

- **the person walks on**, at their pace (their speed divided by the leg's pace factor), but never
  steps into the robot: a step that would bring the discs closer than `CONTACT` is cut short there
  (a person stops in front of a machine, the robot does not push);
- **standoffs are the run loop's**: `blocked_for` says how long an agent has been (mostly) stopped by
  the co-worker; `hrc.sim.run` then has one of them make room or go round (`hrc.sim.giveway`);
- **the robot keeps its safety distance**: while the free distance between the discs is within
  ``safety_margin + slowdown`` and shrinking, its speed scales down linearly to zero at
  ``safety_margin`` (the task's margin, the one motion acquisition keeps between the co-workers), and
  it never takes a step that brings the free distance below the margin; when the person keeps coming
  closer than the margin, the robot backs off along the route it came (never past the leg's origin).
  The default ``slowdown`` is 0: the robot stops right at the margin, exactly the model motion
  acquisition assumes (`hrc.motion.conflicts`: discs closer than ``r_h + r_r + margin`` meet).
- **under speed and separation monitoring** (a task with `safety:`), the robot obeys `hrc.sim.ssm`
  instead: driving towards the person no faster than the protective separation allows (slowing,
  stopping, resuming by itself), never closer than ``S_p(0)`` when it drives, backing off as above when
  the person keeps coming closer than that; `ssm` counts its protective stops and the closest approaches.

A route that ends where it starts (the next phase at the same place) is over at once (`moving` False).

**Co-work at a joint spot** (issue 37, docs/motion.md, "Joint actions"): while `cowork` is set (by the run
loop, `hrc.sim.run`: the robot stands at the spot of a joint action over its stay there, and the person
walks up to that spot, stays at it or walks away from it), the separation is not asked for between the two:
the person walks on through the robot's reach to the spot (a location is a point: both stand at it), the
robot stands. Those steps take no part in `min_free` and `overlaps` (the separation outside the co-work
spot, as motion acquisition keeps it); `cowork_time` counts their seconds. The robot never moves in
co-work: the run loop clears the flag before it drives.

Each step moves the bodies in the pymunk space (velocity set, ``space.step``, position set exactly
on the route) and asks pymunk for contacts between the two discs: `overlaps` counts the steps in which
they touched, an independent check of the rule above. `min_free` is the smallest free distance seen (at
each step's end, and on the way of each walk).
Cost: O(1) per step and agent (where a step would bring the discs too close, the point to stop at is
solved for on the route's segments), plus, only when the discs nearly touch, one pymunk step and shape
query.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import pymunk

from hrc.model import Agent, Task
from hrc.motion.separation import protective_separation
from hrc.motion.world import World
from hrc.sim.ssm import SsmTally, ssm_limit

__all__ = ["CONTACT", "MAX_STEP", "MIN_STEP", "Floor", "Mover", "add_mover", "place_mover", "tally", "time_to_stop"]

Point = tuple[float, float]

CONTACT = 0.02
"""m: the smallest free distance a walking person leaves to the robot (they stop rather than touch it)."""

MIN_STEP, MAX_STEP = 0.02, 0.5
"""s: the shortest and longest step of the floor (`Floor.safe_step`)."""

QUERY_GAP = 0.001
"""m: discs farther apart than this do not touch (pymunk's circle contact is the same free distance, so
it can report no penetration); pymunk is stepped and asked only when they are closer."""


@dataclass(slots=True)
class Mover:
    """One agent's disc on the floor and its current route (`points`, arc lengths `cum`), `s` along it."""

    agent: Agent
    body: pymunk.Body
    shape: pymunk.Circle
    xy: Point
    points: list[Point] = field(default_factory=lambda: [(0.0, 0.0)])
    cum: list[float] = field(default_factory=lambda: [0.0])
    s: float = 0.0
    stop_at: float = 0.0  # arc length at which this travel pauses (a waiting place) or ends
    moving: bool = False
    speed: float = 0.0  # m/s on this travel
    present: bool = True  # False while the person is away from the floor
    held: float = 0.0  # seconds held up by the co-worker (robot: slowed or stopped; person: stopped)
    travelled: float = 0.0  # seconds spent travelling (moving or held up on the way)
    blocked_for: float = 0.0  # seconds it has been (mostly) stopped by the co-worker, in a row

    @property
    def length(self) -> float:
        return self.cum[-1]

    def set_route(self, points: tuple[Point, ...], speed: float, stop_at: float | None = None) -> None:
        """Start travelling along `points` (from its first point, which is where the agent is) at `speed`."""
        pts = [(float(x), float(y)) for x, y in points]
        cum = [0.0]
        for p, q in zip(pts, pts[1:], strict=False):
            cum.append(cum[-1] + math.dist(p, q))
        self.points, self.cum = pts, cum
        self.s, self.speed = 0.0, speed
        self.stop_at = self.length if stop_at is None else min(stop_at, self.length)
        self.moving = self.stop_at > 1e-9  # a leg to where it stands (the next phase at the same place) is over

    def resume(self, stop_at: float | None = None) -> None:
        """Go on along the current route (after a pause at a waiting place)."""
        self.stop_at = self.length if stop_at is None else min(stop_at, self.length)
        self.moving = self.stop_at > self.s + 1e-9

    def at(self, s: float) -> Point:
        """The point at arc length `s` of the current route."""
        cum, pts = self.cum, self.points
        if s <= 0 or len(cum) == 1:
            return pts[0]
        if s >= cum[-1]:
            return pts[-1]
        i = bisect.bisect_right(cum, s) - 1
        (x0, y0), (x1, y1) = pts[i], pts[i + 1]
        f = (s - cum[i]) / (cum[i + 1] - cum[i])
        return (x0 + f * (x1 - x0), y0 + f * (y1 - y0))

    @property
    def remaining(self) -> float:
        return max(0.0, self.stop_at - self.s)


class Floor:
    """The world with both agents' discs; `advance` moves them by the rules of the module docstring."""

    def __init__(self, task: Task, slowdown: float = 0.0) -> None:
        self.task = task
        self.world = World(task.workspace)
        self.margin = task.safety_margin
        self.slowdown = slowdown
        human = next(a for a in task.agents if a.is_human)
        robot = next(a for a in task.agents if not a.is_human)
        self.human = add_mover(self.world, task, human)
        self.robot = add_mover(self.world, task, robot)
        self._radii = human.radius + robot.radius
        self.min_free = math.inf
        self.overlaps = 0
        self.cowork = False  # the person and the standing robot co-work at a joint spot (module docstring)
        self.cowork_time = 0.0
        self._pair_filter = pymunk.ShapeFilter()
        self._unsynced: tuple[Point, Point] | None = None  # where the bodies go before pymunk is next used
        self.ssm = None if task.safety is None else SsmTally(task.safety)
        if task.safety is not None:  # the robot keeps S_p(0) at least; driving, the band up to S_p at its speed
            self.margin = protective_separation(task.safety, 0.0).total
            self._band = protective_separation(task.safety, self.robot.agent.speed).total - self.margin

    def free(self, a: Point | None = None, b: Point | None = None) -> float:
        """Free distance (m) between the discs (at `a` / `b` instead of where they are, if given)."""
        if not self.human.present:
            return math.inf
        p, q = a or self.human.xy, b or self.robot.xy
        return math.hypot(p[0] - q[0], p[1] - q[1]) - self._radii

    @staticmethod
    def time_to_stop(m: Mover) -> float:
        """Seconds until `m` reaches its stop at full pace (inf when it is not moving)."""
        return time_to_stop(m)

    def safe_step(self) -> float:
        """A step (s) short enough that neither agent can come near the other in it unseen.

        While both move, half the time their joint pace takes to close the gap (at least `MIN_STEP`): each
        is walked against where the other stands at that moment, so steps must be short for the two
        moves to stand for simultaneous ones. While one moves, `MAX_STEP`: its walk stops exactly where it
        would come too near the standing co-worker (`_walk`) and measures its closest approach on the way,
        so a longer step misses nothing (a person held up in front of a working robot for seconds costs a
        few steps, not hundreds) - unless the robot slows down near the person (`slowdown` > 0), which
        is a rule of the gap at each step's start and so is sampled as when both move."""
        hm, rm = self.human, self.robot
        if self.cowork or (not (hm.present and hm.moving and rm.moving) and self.slowdown == 0 and self.ssm is None):
            return MAX_STEP
        if not hm.present:  # no gap to close (`free` is inf)
            return MAX_STEP
        (px, py), (qx, qy) = hm.xy, rm.xy  # (`free`, inlined)
        gap = math.hypot(px - qx, py - qy) - self._radii - self.margin - (self.slowdown if self.ssm is None
                                                                            else self._band)
        closing = hm.agent.speed + rm.agent.speed
        return max(MIN_STEP, min(MAX_STEP, gap / closing / 2)) if math.isfinite(gap) else MAX_STEP

    def advance(self, h: float) -> None:
        """Move both agents for `h` seconds (person first, then the robot's response). (`free` and
        `Mover.remaining` are written out here: this runs at every step of every run, and the same
        expressions give the same floats.)"""
        hm, rm = self.human, self.robot
        radii = self._radii
        if self.cowork:
            self._cowork_step(h)
            return
        ssm = self.ssm
        if hm.present and hm.moving:
            want = min(hm.speed * h, max(0.0, hm.stop_at - hm.s))
            (px, py), (qx, qy) = hm.xy, rm.xy
            free_before = math.hypot(px - qx, py - qy) - radii
            floor = min(CONTACT, free_before) - 1e-12  # the free distance the person keeps (`free`, inlined)
            got = self._walk(hm, want, rm.xy, radii + floor)
            if ssm is not None:
                ssm.person_step(not rm.moving or ssm.stopped, free_before, self.free())
            tally(hm, h, want, got, got)
        if rm.moving:
            want = min(rm.speed * h, max(0.0, rm.stop_at - rm.s))
            present = hm.present
            if present:
                (px, py), (qx, qy) = hm.xy, rm.xy
                before = math.hypot(px - qx, py - qy) - radii
                ax, ay = rm.at(rm.s + min(want, 1e-3) if want > 0 else rm.s)
                closing = math.hypot(px - ax, py - ay) - radii < before
            else:
                before, closing = math.inf, False
            allowed = rm.speed
            limit = min(self.margin, before)
            if ssm is not None:  # towards the person at the speed the rule allows, up to exactly S_p of it
                allowed, limit = ssm_limit(ssm.safety, before, rm.speed, closing, self.margin)
                want = min(want, allowed * h)
            elif closing and before < self.margin + self.slowdown and self.slowdown > 0:
                want *= max(0.0, min(1.0, (before - self.margin) / self.slowdown))
            got = self._walk(rm, want, hm.xy if present else None, radii + limit - 1e-12)
            if ssm is not None:
                ssm.robot_step(h, rm.speed, allowed, closing, max(0.0, got), self.free())
            if got <= 1e-12 and closing and before < self.margin and rm.s > 0:
                self._back_off(rm, rm.speed * h / 2)  # the person keeps coming: make room
            tally(rm, h, min(rm.speed * h, max(0.0, rm.stop_at - rm.s) + max(0.0, got)), got, max(0.0, got))
        self._sync(h)

    def _cowork_step(self, h: float) -> None:
        """`advance` in co-work (module docstring): the person walks on at their pace with no regard to the
        standing robot; nothing is measured but the time, the bodies are moved."""
        hm, rm = self.human, self.robot
        assert not rm.moving, "the robot drives in co-work"
        if hm.present and hm.moving:
            hm.s = min(hm.s + hm.speed * h, hm.stop_at)
            if hm.s >= hm.stop_at - 1e-9:
                hm.s, hm.moving = hm.stop_at, False
            hm.xy = hm.at(hm.s)
            hm.travelled += h
            hm.blocked_for = 0.0
        self.cowork_time += h
        self._flush()
        for m in (hm, rm):
            m.body.position = m.xy

    def _walk(self, m: Mover, want: float, centre: Point | None, reach: float) -> float:
        """Advance `m` by up to `want` metres, stopping where its centre would first come closer than
        `reach` to `centre` (no limit when `centre` is None); returns the distance advanced. `min_free`
        takes the closest approach to `centre` (as a free distance) on the way.

        A step whose end keeps `reach` is taken whole (the discs pass within one short step only when both
        move, which `Floor.safe_step` keeps from happening unseen); otherwise the agent stops where its route
        enters the disc of radius `reach` round `centre`: on each route segment ``|a + u d - c| = reach`` is
        a quadratic in `u`, and its smaller root is the first point of the segment inside (exact where a
        bisection would take a dozen probes of the route)."""
        if want <= 0:
            return 0.0
        target = m.s + want
        got = want
        end = None  # the point at `target`, where the step is taken whole (asked of the route once)
        if centre is not None:
            cx, cy = centre
            end = ex, ey = m.at(target)
            if (ex - cx) * (ex - cx) + (ey - cy) * (ey - cy) < reach * reach:
                got = _entry(m, target, cx, cy, reach) - m.s
                end = None
            if math.dist(m.xy, centre) - got - self._radii < self.min_free:  # else it cannot come closer
                self.min_free = min(self.min_free, _closest(m, m.s + got, cx, cy) - self._radii)
        m.s += got  # (taken whole: `target` itself, the same float)
        if m.s >= m.stop_at - 1e-9:
            m.s = m.stop_at
            m.moving = False
            end = None
        m.xy = m.at(m.s) if end is None else end
        return got

    def _back_off(self, m: Mover, distance: float) -> None:
        """Move `m` back along its route by up to `distance` m (not past its start), if that opens the gap."""
        s = max(0.0, m.s - distance)
        p = m.at(s)
        if self.free(self.human.xy, p) > self.free():
            m.s, m.xy = s, p

    def _sync(self, h: float) -> None:
        """Move the pymunk bodies to the agents' positions and ask pymunk whether the discs touch (only when
        they are closer than `QUERY_GAP`: farther apart they cannot, and the bodies are only moved)."""
        hm = self.human
        if hm.present:
            (px, py), (qx, qy) = hm.xy, self.robot.xy
            free = math.hypot(px - qx, py - qy) - self._radii  # (`free`, inlined)
            if free < self.min_free:
                self.min_free = free
            if free > QUERY_GAP:  # the bodies are moved when pymunk is next stepped or asked (`_flush`)
                self._unsynced = (self.human.xy, self.robot.xy)
                return
        self._flush()
        for m in (self.human, self.robot):
            old = m.body.position
            m.body.velocity = ((m.xy[0] - old.x) / h, (m.xy[1] - old.y) / h) if h > 0 else (0.0, 0.0)
        self.world.space.step(h if h > 0 else 1e-9)
        for m in (self.human, self.robot):
            m.body.position = m.xy
            m.body.velocity = (0.0, 0.0)
        if self.human.present:
            self.world.space.reindex_shapes_for_body(self.human.body)
            self.world.space.reindex_shapes_for_body(self.robot.body)
            hits = self.world.space.shape_query(self.robot.shape)
            if any(hit.shape is self.human.shape and any(p.distance < -1e-6 for p in hit.contact_point_set.points)
                   for hit in hits):
                self.overlaps += 1

    def _flush(self) -> None:
        """The bodies where the last step left the agents, if `_sync` has not moved them there yet (pymunk
        reads their positions only when it is stepped and asked for contacts: setting them at every step
        cost more than the rest of a far step)."""
        if self._unsynced is not None:
            self.human.body.position, self.robot.body.position = self._unsynced
            self._unsynced = None

    def place(self, m: Mover, xy: Point) -> None:
        """Put `m` at `xy`, standing (the start of a run, or back on the floor)."""
        self._flush()
        place_mover(m, xy)


# -- a disc's mechanics, the same on the one-pair floor and the team's (`hrc.sim.team_floor`) ----------------

def place_mover(m: Mover, xy: Point) -> None:
    """Put `m` at `xy`, standing."""
    m.xy = xy
    m.points, m.cum, m.s, m.moving = [xy], [0.0], 0.0, False
    m.body.position = xy


def add_mover(world: World, task: Task, agent: Agent) -> Mover:
    """`agent`'s disc, added to `world` at its start."""
    xy = task.workspace.location(agent.start).xy
    body = world.add_agent(agent, *xy)
    shape = next(iter(body.shapes))
    assert isinstance(shape, pymunk.Circle)
    return Mover(agent, body, shape, xy)


def time_to_stop(m: Mover) -> float:
    """Seconds until `m` reaches its stop at full pace (inf when it is not moving)."""
    if not m.moving or m.speed <= 0:
        return math.inf
    return m.remaining / m.speed


def tally(m: Mover, h: float, want: float, got: float, moved: float) -> None:
    """A step of `h` s in which `m` wanted to go `want` m and got `got` (`moved`: of it, what counts as
    moved forward): its time under way, the share of the step it was held up, and how long it has been
    blocked (under half of what it wanted)."""
    m.travelled += h
    if want > 0 and got < want - 1e-9:
        m.held += h * (1 - moved / want)
    m.blocked_for = m.blocked_for + h if want > 0 and got < want / 2 else 0.0


def _entry(m: Mover, target: float, cx: float, cy: float, reach: float) -> float:
    """The arc length in ``[m.s, target]`` at which `m`'s route first comes within `reach` of ``(cx, cy)``
    (`target` is inside; `m.s`, where the agent stands, is not, up to rounding: then `m.s`)."""
    cum, pts = m.cum, m.points
    s = m.s
    i = max(0, bisect.bisect_right(cum, s) - 1)
    r2 = reach * reach
    while i < len(pts) - 1 and cum[i] < target:
        (x0, y0), (x1, y1) = pts[i], pts[i + 1]
        seg = cum[i + 1] - cum[i]
        if seg > 0:
            dx, dy = (x1 - x0) / seg, (y1 - y0) / seg
            ax, ay = x0 - cx, y0 - cy
            b = dx * ax + dy * ay
            disc = b * b - (ax * ax + ay * ay - r2)
            if disc >= 0:
                u = -b - math.sqrt(disc)  # entering the disc along this segment, from its first point
                lo, hi = max(s, cum[i]) - cum[i], min(target, cum[i + 1]) - cum[i]
                if u <= hi and -b + math.sqrt(disc) >= lo:  # the segment's part in [s, target] meets the disc
                    return cum[i] + u if u > lo else max(s, cum[i])  # inside from the start: stay
        i += 1
    return s


def _closest(m: Mover, end: float, cx: float, cy: float) -> float:
    """The smallest distance from ``(cx, cy)`` to `m`'s route between `m.s` and `end`."""
    cum, pts = m.cum, m.points
    x, y = m.at(m.s)
    best = math.hypot(x - cx, y - cy)
    i = max(0, bisect.bisect_right(cum, m.s) - 1)
    while i < len(pts) - 1 and cum[i] < end:
        seg = cum[i + 1] - cum[i]
        if seg > 0:
            (x0, y0), (x1, y1) = pts[i], pts[i + 1]
            dx, dy = (x1 - x0) / seg, (y1 - y0) / seg
            u = min(max(dx * (cx - x0) + dy * (cy - y0), max(m.s, cum[i]) - cum[i]), min(end, cum[i + 1]) - cum[i])
            best = min(best, math.hypot(x0 + u * dx - cx, y0 + u * dy - cy))
        i += 1
    return best
