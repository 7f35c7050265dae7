"""Where to go when the two co-workers stand in each other's way: a spot off the co-worker's way, or a
way round the co-worker.

The run loop's standoff rules (`hrc.sim.run`) decide *who* gives way; this module finds *where*, on the
roadmap motion acquisition plans on (`PathLibrary.roadmaps`: OMPL PRM* milestones and edges for one
clearance, `hrc.motion.planner.Roadmap`), with the co-worker as a standing disc to keep clear of:

- `Ways.route`: a route from any point to any point keeping the agent's clearance from obstacles
  (`World.segment_clear`) and ``reach`` (the sum of the radii plus the safety margin) from the
  co-worker's centre: roadmap edges closer than that are dropped, as `hrc.motion.detours` drops the
  edges a co-worker blocks;
- `Ways.spot`: the way to the nearest milestone (by route length) that lies at least `away` from every
  point of the co-worker's way (its position, the rest of its route, its goal): where a person or a
  robot steps to let the other pass, as co-workers do.

A team's loop passes the other agents on the floor as more discs to keep clear of (`also`: no roadmap edge
within their reach, no spot within it); the one pair passes none.

A start closer to the co-worker than ``reach`` (the discs stand nearer than that when one has been
stopped by the other) may be left along any segment that does not bring the two closer still.
Deterministic (ties go to the lower milestone index). Cost: one Dijkstra over the roadmap (a few hundred
milestones, a few thousand edges) plus O(milestones x way samples) distances, only when a standoff is
resolved; the per-clearance edge arrays are built once per process.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from hrc.motion import PathLibrary
from hrc.motion.planner import LINKS
from hrc.motion.world import World

__all__ = ["Disc", "Ways", "polyline_length", "samples"]

Point = tuple[float, float]
_EPS = 1e-9


@dataclass(frozen=True, slots=True)
class Disc:
    """The co-worker to keep clear of: its centre and how far from it a route's centre line must stay."""

    xy: Point
    reach: float


def polyline_length(points: Sequence[Point]) -> float:
    return sum(math.dist(p, q) for p, q in zip(points, points[1:], strict=False))


def samples(points: Sequence[Point], step: float = 0.25) -> np.ndarray:
    """Points every `step` metres along a polyline, its vertices included (an (n, 2) array)."""
    out: list[Point] = [points[0]]
    for p, q in zip(points, points[1:], strict=False):
        d = math.dist(p, q)
        k = max(1, math.ceil(d / step))
        out += [(p[0] + (q[0] - p[0]) * i / k, p[1] + (q[1] - p[1]) * i / k) for i in range(1, k + 1)]
    return np.asarray(out, dtype=float)


def _seg_dist(a: np.ndarray, b: np.ndarray, c: Point) -> np.ndarray:
    """Distances from point `c` to the segments ``a[i] - b[i]`` (arrays of shape (m, 2))."""
    ab = b - a
    ac = np.asarray(c) - a
    den = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.divide(np.einsum("ij,ij->i", ac, ab), den, out=np.zeros_like(den), where=den > 0), 0.0, 1.0)
    return np.hypot(*(a + t[:, None] * ab - np.asarray(c)).T)


def _point_seg_dist(a: Point, b: Point, c: Point) -> float:
    """`_seg_dist` for one segment (no arrays: it is asked once per candidate link)."""
    abx, aby = b[0] - a[0], b[1] - a[1]
    den = abx * abx + aby * aby
    t = 0.0 if den <= 0 else min(1.0, max(0.0, ((c[0] - a[0]) * abx + (c[1] - a[1]) * aby) / den))
    return math.hypot(a[0] + t * abx - c[0], a[1] + t * aby - c[1])


class Ways:
    """Routes and spots on the task's roadmaps (see the module docstring); one per run, sharing a
    per-process `cache` of edge arrays."""

    def __init__(self, world: World, paths: PathLibrary, cache: dict) -> None:
        self.world, self.paths, self.cache = world, paths, cache
        self._last: tuple[tuple, object] | None = None  # the last search and its result (`spot` asks twice)

    def _roadmap(self, clearance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Milestones, edge index pairs and edge lengths of the roadmap for `clearance` (None: none)."""
        roadmap = self.paths.roadmaps.get(clearance)
        if roadmap is None:
            roadmap = next((r for c, r in sorted(self.paths.roadmaps.items()) if abs(c - clearance) < 1e-6), None)
        if roadmap is None or not roadmap.edges:
            return None
        key = ("giveway-roadmap", roadmap.clearance)
        got = self.cache.get(key)
        if got is None:
            pts = np.asarray(roadmap.points, dtype=float)
            ij = np.array([(i, j) for i, j, _ in roadmap.edges], dtype=int)
            w = np.array([d for _, _, d in roadmap.edges], dtype=float)
            got = self.cache[key] = (pts, ij, w)
        return got

    def _clear(self, a: Point, b: Point, clearance: float, avoid: Disc | None, start_free: float,
               also: tuple[Disc, ...] = (), start: bool = False) -> bool:
        if not self.world.segment_clear(a, b, clearance):
            return False
        for d in also:  # (a segment from the start may leave a disc it stands within, as from `avoid`)
            free = math.dist(a, d.xy) if start else math.inf
            if _point_seg_dist(a, b, d.xy) < min(d.reach, free) - 1e-6:
                return False
        if avoid is None:
            return True
        return _point_seg_dist(a, b, avoid.xy) >= min(avoid.reach, start_free) - 1e-6

    def _search(self, clearance: float, start: Point, avoid: Disc | None, goal: Point | None = None,
                also: tuple[Disc, ...] = ()) -> tuple[np.ndarray, np.ndarray, np.ndarray, int] | None:
        """Dijkstra from `start` (node n) over the roadmap without the edges `avoid` (and `also`) blocks;
        `goal`, if given, is node n + 1. Returns milestones (goal appended), distances, predecessors, n."""
        key = (clearance, start, avoid, goal, also)
        if self._last is not None and self._last[0] == key:
            return self._last[1]  # type: ignore[return-value]
        found = self._dijkstra(clearance, start, avoid, goal, also)
        self._last = (key, found)
        return found

    def _dijkstra(self, clearance: float, start: Point, avoid: Disc | None, goal: Point | None,
                  also: tuple[Disc, ...] = ()) -> tuple[np.ndarray, np.ndarray, np.ndarray, int] | None:
        rm = self._roadmap(clearance)
        if rm is None:
            return None
        pts, ij, w = rm
        n = len(pts)
        keep = np.ones(len(ij), dtype=bool)
        free = math.inf if avoid is None else math.dist(start, avoid.xy)
        if avoid is not None:
            keep = _seg_dist(pts[ij[:, 0]], pts[ij[:, 1]], avoid.xy) >= avoid.reach
        for d in also:
            keep &= _seg_dist(pts[ij[:, 0]], pts[ij[:, 1]], d.xy) >= d.reach
        rows: list[int] = []  # the links from the start (and goal) to their nearest clear milestones
        cols: list[int] = []
        weights: list[float] = []
        ends = [start] + ([goal] if goal is not None else [])
        for e, p in enumerate(ends):
            order = np.lexsort((np.arange(n), np.hypot(pts[:, 0] - p[0], pts[:, 1] - p[1])))[:LINKS]
            for i in order.tolist():
                q = (float(pts[i, 0]), float(pts[i, 1]))
                if self._clear(p, q, clearance, avoid, free if e == 0 else math.inf, also, e == 0):
                    rows.append(n + e)
                    cols.append(i)
                    weights.append(max(math.dist(p, q), 1e-12))
        size = n + len(ends)
        # the kept roadmap edges, then those links, as arrays (the same matrix as from lists, without
        # converting thousands of numpy scalars one by one)
        graph = csr_matrix((np.concatenate([w[keep], np.array(weights, dtype=float)]),
                            (np.concatenate([ij[keep, 0], np.array(rows, dtype=ij.dtype)]),
                             np.concatenate([ij[keep, 1], np.array(cols, dtype=ij.dtype)]))), shape=(size, size))
        dist, pred = dijkstra(graph, directed=False, indices=n, return_predecessors=True)
        nodes = np.vstack([pts, np.asarray(ends, dtype=float)])
        return nodes, dist, pred, n

    def _trace(self, nodes: np.ndarray, pred: np.ndarray, n: int, target: int, clearance: float,
               avoid: Disc | None, start: Point, also: tuple[Disc, ...] = ()) -> tuple[Point, ...]:
        """The route from the start to node `target`, shortened: from each point, straight on to the
        farthest later point that is clear."""
        chain = []
        v = target
        while v != n and v >= 0:
            chain.append(v)
            v = int(pred[v])
        raw = [start] + [(float(nodes[v, 0]), float(nodes[v, 1])) for v in reversed(chain)]
        free = math.inf if avoid is None else math.dist(start, avoid.xy)
        out = [raw[0]]
        i = 0
        while i < len(raw) - 1:
            j = len(raw) - 1
            while j > i + 1 and not self._clear(raw[i], raw[j], clearance, avoid, free if i == 0 else math.inf,
                                                also, i == 0):
                j -= 1
            out.append(raw[j])
            i = j
        return tuple(out)

    def route(self, clearance: float, start: Point, goal: Point, avoid: Disc | None = None,
              also: tuple[Disc, ...] = ()) -> tuple[Point, ...] | None:
        """A route from `start` to `goal` (see the module docstring), or None: no way on the roadmap, or
        the goal within `avoid`'s reach. `also`: more discs to keep clear of (a team's other agents)."""
        if avoid is not None and math.dist(goal, avoid.xy) < avoid.reach:
            return None
        free = math.inf if avoid is None else math.dist(start, avoid.xy)
        if math.dist(start, goal) < 1e-9:
            return (start,)
        if self._clear(start, goal, clearance, avoid, free, also, True):
            return (start, goal)
        found = self._search(clearance, start, avoid, goal, also)
        if found is None:
            return None
        nodes, dist, pred, n = found
        if not np.isfinite(dist[n + 1]):
            return None
        return self._trace(nodes, pred, n, n + 1, clearance, avoid, start, also)

    def spot(self, clearance: float, start: Point, avoid: Disc | None, way: np.ndarray,
             away: float, also: tuple[Disc, ...] = ()) -> tuple[Point, ...] | None:
        """The way from `start` to the nearest milestone at least `away` from every point of `way` (an
        (m, 2) array: the co-worker's position and the rest of its way), keeping clear of `avoid` (and of
        `also`: a team's other agents, which the milestone keeps their reach from); None if no such
        milestone is reachable. No `avoid`: nothing in the way but `also`."""
        found = self._search(clearance, start, avoid, None, also)
        if found is None:
            return None
        nodes, dist, pred, n = found
        pts = nodes[:n]
        gap = np.min(np.hypot(pts[:, None, 0] - way[None, :, 0], pts[:, None, 1] - way[None, :, 1]), axis=1)
        fine = np.isfinite(dist[:n]) & (gap >= away)
        for d in also:
            fine &= np.hypot(pts[:, 0] - d.xy[0], pts[:, 1] - d.xy[1]) >= d.reach
        ok = np.flatnonzero(fine)
        if not len(ok):
            return None
        best = int(ok[np.lexsort((ok, dist[ok]))[0]])
        return self._trace(nodes, pred, n, best, clearance, avoid, start, also)
