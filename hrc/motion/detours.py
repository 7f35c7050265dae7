"""Detours: the robot's way round the places where the co-worker would be in its way.

Strassmair & Taylor 2014, section V.A: "in a particular plan one worker might block the other's way and
cause a detour". Where a robot route meets the human's occupancies (`hrc.motion.conflicts`), the robot
may wait (one of the two passing orders) or go round. `detour` plans that other route: the places the
human would occupy there become obstacles (the human's positions inflated by the human's radius plus a
sampling allowance, so that a robot keeping its own clearance from them keeps ``reach`` from the human),
the task's roadmap for the robot's clearance (`PathLibrary.roadmaps`, OMPL PRM*) loses the edges they
block, and the route is found and shortened as every other (`Roadmap.routes`: Dijkstra, exact swept-disc
shortcutting). The result lies in another homotopy class round the obstacles whenever the blocked places
cut the shortest one; it is ``None`` when the blocked places enclose the robot's origin or target or
leave no way through.

Cached per ``(origin, target, blocked places)`` in the library's per-process cache and on disk
(`hrc.caches.cache_folder` ``detours``, beside the roadmaps), keyed by everything a detour is computed
from: a compile of the same map and agents (an edited duration, another deadline) plans none again,
and a worker reads what another worker of the same compile planned first (issue 38).

Deterministic (the roadmap is fixed per seed; no sampling here). Cost: one world (pymunk + FCL) with the
blocked places, one edge filter (shapely, vectorized) and one roadmap query: a few tens of ms, cached per
``(origin, target, blocked places)`` in the library's per-process cache.
"""

from __future__ import annotations

import functools
import hashlib
import math
from collections.abc import Sequence

import numpy as np
import shapely
from shapely.geometry import LineString, MultiPolygon, Point, Polygon

from hrc.caches import cache_folder, disk_load, disk_store, source_digest
from hrc.model import Obstacle, Task, Workspace
from hrc.motion.conflicts import STEP
from hrc.motion.paths import Path, PathLibrary
from hrc.motion.planner import Roadmap
from hrc.motion.world import World

__all__ = ["blocked_region", "detour"]

_QUAD_SEGS = 4  # buffer polygons: segments per quarter circle (circumscribed, see `blocked_region`)

Shape = tuple[tuple[float, float], ...]  # a polyline, or a single point


def blocked_region(shapes: Sequence[Shape], radius: float) -> list[Polygon]:
    """The union of `shapes` (polylines or points) inflated by `radius`, as simple polygons.

    Buffers are polygons inscribed in the true round buffer; the radius is scaled so that they
    circumscribe it instead (``r / cos(pi / (4 * quad_segs))``) and never cut a corner off the region.
    Holes are filled (a detour never goes through a ring of blocked places).
    """
    r = radius / math.cos(math.pi / (4 * _QUAD_SEGS))
    parts = []
    for shape in shapes:
        geom = Point(shape[0]) if len(shape) == 1 else LineString(shape)
        parts.append(geom.buffer(r, quad_segs=_QUAD_SEGS))
    union = shapely.union_all(parts)
    polys = list(union.geoms) if isinstance(union, MultiPolygon) else [union]
    return [Polygon(p.exterior) for p in polys if not p.is_empty]


@functools.lru_cache(maxsize=64)
def _world(workspace: Workspace, extra: tuple[tuple[tuple[float, float], ...], ...]) -> World:
    obstacles = workspace.obstacles + tuple(Obstacle(f"blocked{i}", poly) for i, poly in enumerate(extra))
    return World(Workspace(workspace.name, workspace.bounds, obstacles, workspace.locations))


def _without(roadmap: Roadmap, region: list[Polygon]) -> Roadmap:
    """The roadmap without the edges whose swept disc meets `region`."""
    if not roadmap.edges:
        return roadmap
    pts = np.asarray(roadmap.points)
    ij = np.array([(i, j) for i, j, _ in roadmap.edges])
    lines = shapely.linestrings(np.stack([pts[ij[:, 0]], pts[ij[:, 1]]], axis=1))
    zone = shapely.union_all([p.buffer(roadmap.clearance) for p in region])
    hit = shapely.intersects(lines, zone)
    return Roadmap(roadmap.clearance, roadmap.points, [e for e, h in zip(roadmap.edges, hit, strict=True) if not h])


def _within(p: tuple[float, float], shapes: Sequence[Shape], reach: float) -> bool:
    """Whether `p` is closer than `reach` to a point or segment of `shapes`."""
    x, y = p
    for shape in shapes:
        if len(shape) == 1:
            if math.hypot(x - shape[0][0], y - shape[0][1]) < reach:
                return True
            continue
        for (x0, y0), (x1, y1) in zip(shape, shape[1:], strict=False):
            dx, dy = x1 - x0, y1 - y0
            den = dx * dx + dy * dy
            t = 0.0 if den == 0 else min(1.0, max(0.0, ((x - x0) * dx + (y - y0) * dy) / den))
            if math.hypot(x - x0 - t * dx, y - y0 - t * dy) < reach:
                return True
    return False


def detour(task: Task, paths: PathLibrary, agent_id: str, origin: str, target: str,
           shapes: Sequence[Shape], label: str) -> Path | None:
    """The route of `agent_id` from `origin` to `target` that keeps the agent's clearance from the
    places `shapes` inflated by the other agent's radius (see the module docstring), or None.

    `label` names what the detour goes round (``Path.via``). Cached per process.
    """
    key = ("detour", agent_id, origin, target, tuple(shapes))
    if key in paths.samples:
        return paths.samples[key]
    agent = task.agent(agent_id)
    # the co-worker whose places these are: the widest of the others (the one other agent of a 1+1 task)
    other = max((a for a in task.agents if a.id != agent_id), key=lambda a: a.radius)
    clearance = agent.radius + task.safety_margin
    roadmap = paths.roadmaps.get(clearance)
    result = None
    a, b = paths.locations[origin], paths.locations[target]
    # most detours asked for start or end inside the blocked places: said without building them (the
    # zone below holds every point within the radius plus its inscribed buffer's clearance of a shape)
    reach = other.radius + STEP + clearance * math.cos(math.pi / 32) - 1e-9
    if _within(a, shapes, reach) or _within(b, shapes, reach):
        paths.samples[key] = None
        return None
    folder = cache_folder("detours")
    dkey = ""
    if folder is not None and roadmap is not None:  # on disk, by everything it is computed from (`_disk_key`)
        dkey = _disk_key(task, paths, roadmap, agent_id, origin, target, tuple(shapes), label)
        found = disk_load(folder, dkey)
        if found is not None:
            result = found[0]
            paths.samples[key] = result
            return result
    region = blocked_region(shapes, other.radius + STEP)
    zone = shapely.union_all([p.buffer(clearance) for p in region])
    if roadmap is not None and not (zone.intersects(Point(a)) or zone.intersects(Point(b))):
        extra = tuple(tuple((float(x), float(y)) for x, y in poly.exterior.coords[:-1]) for poly in region)
        world = _world(task.workspace, extra)
        if world.point_clear(*a, clearance) and world.point_clear(*b, clearance):
            pts = _without(roadmap, region).routes(world, [a, b])[(0, 1)]
            if pts is not None:
                length = sum(math.dist(p, q) for p, q in zip(pts, pts[1:], strict=False))
                result = Path(agent_id, origin, target, tuple(pts), length, length / agent.speed, label)
    paths.samples[key] = result
    if dkey:
        disk_store(folder, dkey, (result,))
    return result


def _disk_key(task: Task, paths: PathLibrary, roadmap: Roadmap, agent_id: str, origin: str, target: str,
              shapes: tuple[Shape, ...], label: str) -> str:
    """What a detour is computed from: the code, the map's bounds and obstacles, the roadmap (its points
    and edges, by digest), both agents (radius, speed, margin), the two ends and the blocked shapes
    (floats by their exact ``repr``)."""
    ws = task.workspace
    agents = tuple((a.id, a.radius, a.speed) for a in task.agents)
    return repr(("detour-1", _code_digest(), ws.bounds, [(o.id, o.polygon) for o in ws.obstacles],
                 _roadmap_digest(roadmap), task.safety_margin, agents, agent_id, origin, paths.locations[origin],
                 target, paths.locations[target], shapes, label))


_ROADMAP_DIGESTS: dict[int, tuple[Roadmap, str]] = {}  # id -> (the roadmap, kept alive for its id; digest)


def _roadmap_digest(roadmap: Roadmap) -> str:
    held = _ROADMAP_DIGESTS.get(id(roadmap))
    if held is None or held[0] is not roadmap:
        digest = hashlib.sha256(repr((roadmap.clearance, roadmap.points, roadmap.edges)).encode()).hexdigest()
        held = _ROADMAP_DIGESTS[id(roadmap)] = (roadmap, digest)
    return held[1]


@functools.cache
def _code_digest() -> str:
    return source_digest("hrc.motion.detours", "hrc.motion.planner", "hrc.motion.world", "hrc.motion.paths",
                         "hrc.motion.conflicts")
