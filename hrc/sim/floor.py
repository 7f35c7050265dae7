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

A route that ends where it starts (the next phase at the same place) is over at once (`moving` False).

Each step moves the bodies in the pymunk space (velocity set, ``space.step``, position set exactly
on the route) and asks pymunk for contacts between the two discs: `overlaps` counts the steps in which
they touched, an independent check of the rule above. `min_free` is the smallest free distance seen.
Cost: O(1) per step and agent (a few bisection steps when the agents are close), plus one pymunk step
and shape query.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field

import pymunk

from hrc.model import Agent, Task
from hrc.motion.world import World

__all__ = ["CONTACT", "Floor", "Mover"]

Point = tuple[float, float]

CONTACT = 0.02
"""m: the smallest free distance a walking person leaves to the robot (they stop rather than touch it)."""

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
        self.human = self._mover(human)
        self.robot = self._mover(robot)
        self._radii = human.radius + robot.radius
        self.min_free = math.inf
        self.overlaps = 0
        self._pair_filter = pymunk.ShapeFilter()

    def _mover(self, agent: Agent) -> Mover:
        xy = self.task.workspace.location(agent.start).xy
        body = self.world.add_agent(agent, *xy)
        shape = next(iter(body.shapes))
        assert isinstance(shape, pymunk.Circle)
        return Mover(agent, body, shape, xy)

    def free(self, a: Point | None = None, b: Point | None = None) -> float:
        """Free distance (m) between the discs (at `a` / `b` instead of where they are, if given)."""
        if not self.human.present:
            return math.inf
        p, q = a or self.human.xy, b or self.robot.xy
        return math.hypot(p[0] - q[0], p[1] - q[1]) - self._radii

    def time_to_stop(self, m: Mover) -> float:
        """Seconds until `m` reaches its stop at full pace (inf when it is not moving)."""
        if not m.moving or m.speed <= 0:
            return math.inf
        return m.remaining / m.speed

    def safe_step(self) -> float:
        """A step (s) short enough that neither agent can come near the other in it unseen."""
        gap = self.free() - self.margin - self.slowdown
        closing = self.human.agent.speed + self.robot.agent.speed
        return max(0.02, min(0.5, gap / closing / 2)) if math.isfinite(gap) else 0.5

    def advance(self, h: float) -> None:
        """Move both agents for `h` seconds (person first, then the robot's response)."""
        hm, rm = self.human, self.robot
        radii = self._radii
        if hm.present and hm.moving:
            want = min(hm.speed * h, hm.remaining)
            rx, ry = rm.xy
            floor = min(CONTACT, self.free()) - 1e-12  # the free distance the person keeps (`free`, inlined)
            got = self._walk(hm, want, lambda p: math.hypot(p[0] - rx, p[1] - ry) - radii >= floor)
            hm.travelled += h
            if want > 0 and got < want - 1e-9:
                hm.held += h * (1 - got / want)
            hm.blocked_for = hm.blocked_for + h if want > 0 and got < want / 2 else 0.0
        if rm.moving:
            want = min(rm.speed * h, rm.remaining)
            before = self.free()
            ahead = rm.at(rm.s + min(want, 1e-3) if want > 0 else rm.s)
            closing = self.free(hm.xy, ahead) < before
            if closing and before < self.margin + self.slowdown and self.slowdown > 0:
                want *= max(0.0, min(1.0, (before - self.margin) / self.slowdown))
            limit = min(self.margin, before)
            if hm.present:
                hx, hy = hm.xy
                got = self._walk(rm, want, lambda p: math.hypot(hx - p[0], hy - p[1]) - radii >= limit - 1e-12)
            else:
                got = self._walk(rm, want, lambda p: True)
            if got <= 1e-12 and closing and before < self.margin and rm.s > 0:
                self._back_off(rm, rm.speed * h / 2)  # the person keeps coming: make room
            rm.travelled += h
            full = min(rm.speed * h, rm.remaining + max(0.0, got))
            if full > 0 and got < full - 1e-9:
                rm.held += h * (1 - max(0.0, got) / full)
            rm.blocked_for = rm.blocked_for + h if full > 0 and got < full / 2 else 0.0
        self._sync(h)

    def _walk(self, m: Mover, want: float, ok) -> float:  # noqa: ANN001 - a predicate on points
        """Advance `m` by up to `want` metres while `ok(position)` holds; returns the distance advanced."""
        if want <= 0:
            return 0.0
        target = m.s + want
        if ok(m.at(target)):
            got = want
        else:
            lo, hi = 0.0, want  # largest advance that keeps ok (ok holds at 0 by construction)
            for _ in range(12):
                mid = (lo + hi) / 2
                if ok(m.at(m.s + mid)):
                    lo = mid
                else:
                    hi = mid
            got = lo
        m.s += got
        m.xy = m.at(m.s)
        if m.s >= m.stop_at - 1e-9:
            m.s = m.stop_at
            m.xy = m.at(m.s)
            m.moving = False
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
        if self.human.present:
            free = self.free()
            self.min_free = min(self.min_free, free)
            if free > QUERY_GAP:
                for m in (self.human, self.robot):
                    m.body.position = m.xy
                return
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

    def place(self, m: Mover, xy: Point) -> None:
        """Put `m` at `xy`, standing (the start of a run, or back on the floor)."""
        m.xy = xy
        m.points, m.cum, m.s, m.moving = [xy], [0.0], 0.0, False
        m.body.position = xy
