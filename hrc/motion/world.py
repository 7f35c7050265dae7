"""The workspace world: a pymunk space and FCL collision objects built from the map.

The shop floor is 2D. Obstacles and the four bounds (walls) are static geometry; each agent is a disc.

- **pymunk** (Chipmunk2D) holds the static shapes on ``space.static_body`` and one kinematic circle body
  per agent. Its ``segment_query_first(a, b, radius)`` is an *exact* swept-disc test, used to check a
  straight motion at a clearance (no sampling, so a segment cannot cut an obstacle corner).
- **FCL** (python-fcl) holds the same geometry extruded to 3D: obstacles as prism meshes (or boxes for
  axis-aligned rectangles) centred at z = 0, walls as thick boxes outside the bounds; an agent disc is
  an ``fcl.Sphere`` at z = 0, so sphere-prism distance equals the 2D disc-polygon distance
  (/work/shared/notes/fcl-pymunk.md: cylinders are inaccurate against boxes, spheres exact).

`World.clearance(x, y)` is the distance from the point to the nearest obstacle or wall, so an agent
disc of radius r centred there keeps ``clearance - r`` free; `World.agent_distance` is the distance
between two agent discs. Construction is O(obstacles); a clearance query is O(obstacles) FCL calls
(a few µs each), a segment test one pymunk query (~10 µs).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from typing import Any

import fcl
import numpy as np
import pymunk
import pymunk.autogeometry
from shapely.geometry import Polygon

from hrc.model import Agent, Task, Workspace

try:  # Chipmunk's swept-disc query called directly (`World.segment_clear`): the same C function pymunk's
    # ``Shape.segment_query`` calls, without its Python wrapper (half the compile's path-planning time)
    from pymunk._chipmunk_cffi import ffi as _ffi
    from pymunk._chipmunk_cffi import lib as _cp
except ImportError:  # pragma: no cover - pymunk 7 has it; another layout falls back to the public method
    _ffi = _cp = None

__all__ = ["World"]

_WALL = 1.0  # m, thickness of the FCL wall boxes outside the bounds
_Z = 1.0  # m, height of the extruded prisms (any positive value: the sphere sits at z = 0)


def _is_axis_rect(poly: Sequence[tuple[float, float]]) -> bool:
    if len(poly) != 4:
        return False
    xs = sorted({round(p[0], 12) for p in poly})
    ys = sorted({round(p[1], 12) for p in poly})
    return len(xs) == 2 and len(ys) == 2


def _convex_pieces(poly: Sequence[tuple[float, float]]) -> tuple[tuple[tuple[float, float], ...], ...]:
    """`poly` as convex pieces (pymunk's ``Poly`` takes the convex hull of what it is given). Kept per
    polygon (the simulator builds a world per run: `hrc.sim.floor`); read-only."""
    return _pieces(tuple((x, y) for x, y in poly))


@functools.lru_cache(maxsize=1024)
def _pieces(poly: tuple[tuple[float, float], ...]) -> tuple[tuple[tuple[float, float], ...], ...]:
    pts = [(float(x), float(y)) for x, y in poly]
    shp = Polygon(pts)
    if shp.convex_hull.area - shp.area <= 1e-12 * max(shp.area, 1.0):
        return (tuple(pts),)
    if shp.exterior.is_ccw is False:  # Chipmunk's decomposition wants counter-clockwise winding
        pts = pts[::-1]
    closed = pts + [pts[0]]
    pieces = pymunk.autogeometry.convex_decomposition(closed, 0.0)
    return tuple(tuple((float(v.x), float(v.y)) for v in piece[:-1]) for piece in pieces)


def _fcl_polygon(poly: Sequence[tuple[float, float]]) -> fcl.CollisionObject:
    """A polygon as an FCL object: a box for an axis-aligned rectangle, else a prism mesh. Kept per polygon
    and shared by every world with it (never moved: obstacles stand still)."""
    return _fcl_object(tuple((x, y) for x, y in poly))


@functools.lru_cache(maxsize=1024)
def _fcl_object(poly: tuple[tuple[float, float], ...]) -> fcl.CollisionObject:
    if _is_axis_rect(poly):
        xs = [p[0] for p in poly]
        ys = [p[1] for p in poly]
        box = fcl.Box(max(xs) - min(xs), max(ys) - min(ys), _Z)
        centre = np.array([(max(xs) + min(xs)) / 2, (max(ys) + min(ys)) / 2, 0.0])
        return fcl.CollisionObject(box, fcl.Transform(centre))
    verts: list[list[float]] = []
    tris: list[list[int]] = []
    for piece in _convex_pieces(poly):  # each convex piece a closed prism: side walls and fan caps
        n, o = len(piece), len(verts)
        verts += [[x, y, -_Z / 2] for x, y in piece] + [[x, y, _Z / 2] for x, y in piece]
        for i in range(n):
            j = (i + 1) % n
            tris += [[o + i, o + j, o + n + j], [o + i, o + n + j, o + n + i]]
        for i in range(1, n - 1):
            tris += [[o, o + i + 1, o + i], [o + n, o + n + i, o + n + i + 1]]
    model = fcl.BVHModel()
    model.beginModel(len(verts), len(tris))
    model.addSubModel(np.array(verts, dtype=float), np.array(tris, dtype=int))
    model.endModel()
    return fcl.CollisionObject(model, fcl.Transform())


class World:
    """A workspace as a pymunk space plus FCL objects, with clearance and swept-disc queries.

    >>> from hrc.model import Workspace
    >>> w = World(Workspace("w", (0, 0, 4, 2), (), ()))
    >>> round(w.clearance(1.0, 1.0), 6)
    1.0
    """

    def __init__(self, workspace: Workspace) -> None:
        self.workspace = workspace
        xmin, ymin, xmax, ymax = workspace.bounds
        self.space = pymunk.Space()
        static = self.space.static_body
        shapes: list[pymunk.Shape] = []
        for ob in workspace.obstacles:
            shapes += [pymunk.Poly(static, piece) for piece in _convex_pieces(ob.polygon)]
        # walls: segments along the bounds, extended past the corners so end caps never matter
        ext = max(xmax - xmin, ymax - ymin)
        for a, b in (((xmin - ext, ymin), (xmax + ext, ymin)), ((xmin - ext, ymax), (xmax + ext, ymax)),
                     ((xmin, ymin - ext), (xmin, ymax + ext)), ((xmax, ymin - ext), (xmax, ymax + ext))):
            shapes.append(pymunk.Segment(static, a, b, 0.0))
        self.space.add(*shapes)
        self._static = [(sh, tuple(sh.cache_bb())) for sh in shapes]
        self._swept = _Swept(self._static)
        self._filter = pymunk.ShapeFilter()
        self.bodies: dict[str, pymunk.Body] = {}

        self._fcl_obstacles = [_fcl_polygon(ob.polygon) for ob in workspace.obstacles]
        w, h = xmax - xmin, ymax - ymin
        walls = [((xmin + xmax) / 2, ymin - _WALL / 2, w + 2 * _WALL, _WALL),
                 ((xmin + xmax) / 2, ymax + _WALL / 2, w + 2 * _WALL, _WALL),
                 (xmin - _WALL / 2, (ymin + ymax) / 2, _WALL, h + 2 * _WALL),
                 (xmax + _WALL / 2, (ymin + ymax) / 2, _WALL, h + 2 * _WALL)]
        self._fcl_walls = [fcl.CollisionObject(fcl.Box(bw, bh, _Z), fcl.Transform(np.array([cx, cy, 0.0])))
                           for cx, cy, bw, bh in walls]
        self._fcl_all = self._fcl_obstacles + self._fcl_walls
        self._point = fcl.CollisionObject(fcl.Sphere(1e-9), fcl.Transform())
        self._request = fcl.DistanceRequest()
        self._manager = fcl.DynamicAABBTreeCollisionManager()
        self._manager.registerObjects(self._fcl_all)
        self._manager.setup()
        self._discs: dict[float, fcl.CollisionObject] = {}

    @classmethod
    def from_task(cls, task: Task) -> World:
        """The task's workspace with each agent's circle body at its start location."""
        world = cls(task.workspace)
        for agent in task.agents:
            world.add_agent(agent, *task.workspace.location(agent.start).xy)
        return world

    def _static_within(self, p: tuple[float, float], distance: float) -> bool:
        """True when a static shape (obstacle or wall, never an agent) is within `distance` of `p`. Only
        shapes whose bounding box, grown by `distance`, holds `p` are asked (no other shape can be that
        close): the roadmap's sampling asks this of every sample."""
        x, y = p
        for shape, (left, bottom, right, top) in self._static:
            if (left - distance <= x <= right + distance and bottom - distance <= y <= top + distance
                    and shape.point_query(p).distance <= distance):
                return True
        return False

    def add_agent(self, agent: Agent, x: float, y: float) -> pymunk.Body:
        """Add `agent` as a kinematic circle body at ``(x, y)`` (for simulation; queries ignore agents)."""
        body = pymunk.Body(body_type=pymunk.Body.KINEMATIC)
        body.position = (x, y)
        shape = pymunk.Circle(body, agent.radius)
        self.space.add(body, shape)
        self.bodies[agent.id] = body  # pymunk shapes hold their body weakly: keep it here
        return body

    def clearance(self, x: float, y: float) -> float:
        """Distance (m) from ``(x, y)`` to the nearest obstacle or wall (FCL); 0 or less inside one."""
        if self._static_within((x, y), 0.0):
            return 0.0  # inside (or on) an obstacle: FCL reports -1 or a mesh's surface distance
        self._point.setTranslation(np.array([x, y, 0.0]))
        best = math.inf
        for obj in self._fcl_all:
            d = fcl.distance(self._point, obj, self._request, fcl.DistanceResult())
            if d < best:
                best = d
        return max(float(best) + 1e-9, 0.0)  # the probe sphere has radius 1e-9

    def disc_clearance(self, x: float, y: float, radius: float) -> float:
        """Free distance (m) between an agent disc of `radius` at ``(x, y)`` and the nearest obstacle."""
        return self.clearance(x, y) - radius

    def point_clear(self, x: float, y: float, clearance: float) -> bool:
        """True when a disc of radius `clearance` at ``(x, y)`` is inside the bounds and touches nothing.

        One FCL broad-phase collision query of a sphere against every obstacle and wall (~3 µs), the
        state validity test of the planner.
        """
        xmin, ymin, xmax, ymax = self.workspace.bounds
        if not (xmin + clearance <= x <= xmax - clearance and ymin + clearance <= y <= ymax - clearance):
            return False
        disc = self._discs.get(clearance)
        if disc is None:
            disc = self._discs[clearance] = fcl.CollisionObject(fcl.Sphere(clearance), fcl.Transform())
        disc.setTranslation(np.array([x, y, 0.0]))
        data = fcl.CollisionData()
        self._manager.collide(disc, data, fcl.defaultCollisionCallback)
        if data.result.is_collision:
            return False
        # a point deep inside a concave obstacle's mesh touches no triangle: ask pymunk as well
        return not self._static_within((x, y), 0.0)

    def segment_clear(self, a: tuple[float, float], b: tuple[float, float], clearance: float) -> bool:
        """True when a disc of radius `clearance` swept from `a` to `b` touches nothing (exact, pymunk).

        Uses each static shape's own ``segment_query(a, b, radius)`` (Chipmunk's exact swept-disc
        narrow phase) after a bounding-box test: ``Space.segment_query_first`` is *not* usable here,
        because its broad phase tests the bare segment against the shapes' boxes, not inflated by the
        radius, and so misses a disc that grazes a shape the segment itself does not reach.
        """
        if a == b:
            return not self._static_within(a, clearance)
        return self._swept.clear(a, b, clearance)

    @staticmethod
    def agent_distance(a: tuple[float, float], ra: float, b: tuple[float, float], rb: float) -> float:
        """Free distance (m) between two agent discs (negative when they overlap)."""
        return math.hypot(a[0] - b[0], a[1] - b[1]) - ra - rb


class _Swept:
    """`World.segment_clear`'s test over the static shapes: each shape whose bounding box, grown by the
    clearance, meets the segment's is asked Chipmunk's exact ``cpShapeSegmentQuery`` (through pymunk's
    own cffi handle, the answer its ``Shape.segment_query`` gives, without building a query-info object
    per call)."""

    def __init__(self, static: list[tuple[pymunk.Shape, tuple[float, ...]]]) -> None:
        self.static = static
        # each shape's box and handle in one flat tuple: the loop below is the compile's hottest in motion
        self.handles: list[tuple[Any, ...]] | None = (None if _cp is None else
                                                      [(*bb, sh._shape) for sh, bb in static])
        self.info = None if _ffi is None else _ffi.new("cpSegmentQueryInfo *")  # written by Chipmunk, unread

    def clear(self, a: tuple[float, float], b: tuple[float, float], clearance: float) -> bool:
        (ax, ay), (bx, by) = a, b
        left, right = (ax - clearance, bx + clearance) if ax < bx else (bx - clearance, ax + clearance)
        bottom, top = (ay - clearance, by + clearance) if ay < by else (by - clearance, ay + clearance)
        if self.handles is None:  # pragma: no cover - see the import of `_cp`
            for shape, (sl, sb, sr, st) in self.static:
                if not (sr < left or sl > right or st < bottom or sb > top) and \
                        shape.segment_query(a, b, clearance) is not None:
                    return False
            return True
        query, info = _cp.cpShapeSegmentQuery, self.info
        for sl, sb, sr, st, handle in self.handles:
            if sr < left or sl > right or st < bottom or sb > top:
                continue
            if query(handle, a, b, clearance, info):
                return False
        return True
