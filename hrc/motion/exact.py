"""Exact shortest paths for a disc among polygons: the *oracle* for tests and the benchmark only.

The centre of a disc that keeps clearance ``c`` moves in the free region ``F = shrink(bounds, c) \\
union(buffer(obstacle, c))``. A shortest path in a polygonal domain bends only at reflex vertices of
``F`` (Lozano-Pérez & Wesley, "An algorithm for planning collision-free paths among polyhedral
obstacles", CACM 1979), so it is a shortest path in the visibility graph over those vertices plus start
and goal (de Berg et al., *Computational Geometry*, 3rd ed., ch. 15). Inflated corners are arcs; shapely
approximates them by polygons whose vertices lie on the arc, so the oracle's length is a hair *below*
the true optimum (by less than ``c * (1 - cos(pi / (4 * quad_segs)))`` per corner), i.e. it is strict.

Never used by the planner (issue 4: OMPL plans; this only checks it). Cost: O(V^2) segment tests
(vectorised shapely) to build the graph for V vertices, then Dijkstra (networkx) per query.
"""

from __future__ import annotations

import itertools
import math

import networkx as nx
import numpy as np
import shapely
from shapely.geometry import LineString, Point, Polygon, box

from hrc.model import Workspace

__all__ = ["ExactPlanner"]


class ExactPlanner:
    """Visibility-graph shortest paths for one clearance on one workspace."""

    def __init__(self, workspace: Workspace, clearance: float, quad_segs: int = 8) -> None:
        xmin, ymin, xmax, ymax = workspace.bounds
        c = clearance
        inflated = [Polygon(o.polygon).buffer(c, quad_segs=quad_segs) for o in workspace.obstacles]
        inner = box(xmin + c, ymin + c, xmax - c, ymax - c)
        blocked = shapely.union_all(inflated) if inflated else Polygon()
        self.free = inner.difference(blocked)
        self._free_tol = self.free.buffer(1e-9)
        shapely.prepare(self._free_tol)
        verts = []
        for poly in inflated:
            for x, y in list(poly.exterior.coords)[:-1]:
                pt = Point(x, y)
                if inner.covers(pt) and not any(o.contains(pt) for o in inflated):
                    verts.append((float(x), float(y)))
        self.vertices = verts
        g: nx.Graph = nx.Graph()
        g.add_nodes_from(range(len(verts)))
        pairs = list(itertools.combinations(range(len(verts)), 2))
        if pairs:
            lines = shapely.linestrings([[verts[i], verts[j]] for i, j in pairs])
            ok = shapely.covers(self._free_tol, lines)
            for (i, j), good in zip(pairs, ok, strict=True):
                if good:
                    g.add_edge(i, j, weight=math.dist(verts[i], verts[j]))
        self.graph = g

    def _visible(self, p: tuple[float, float]) -> list[int]:
        if not self.vertices:
            return []
        lines = shapely.linestrings([[p, v] for v in self.vertices])
        return [int(i) for i in np.flatnonzero(shapely.covers(self._free_tol, lines))]

    def shortest(self, start: tuple[float, float], goal: tuple[float, float]) -> tuple[float, list]:
        """``(length, points)`` of the shortest path, ``(inf, [])`` when there is none."""
        if self._free_tol.covers(LineString([start, goal])):
            return math.dist(start, goal), [start, goal]
        g = self.graph.copy()
        for name, p in (("s", start), ("g", goal)):
            g.add_node(name)
            for i in self._visible(p):
                g.add_edge(name, i, weight=math.dist(p, self.vertices[i]))
        try:
            length, nodes = nx.single_source_dijkstra(g, "s", "g")
        except nx.NetworkXNoPath:
            return math.inf, []
        pts = [start if n == "s" else goal if n == "g" else self.vertices[n] for n in nodes]
        return float(length), pts
