"""Free-space path queries: an OMPL PRM* roadmap (BIT* as fallback) + exact shortcutting.

For a disc of clearance ``c`` (agent radius + safety margin; the planner adds 1 µm so rounding never
makes it less) the configuration space is the plane over the bounds shrunk by ``c`` (the bounds are
walls). With OMPL 2.x (PyPI ``ompl``, nanobind bindings; facts in /work/shared/notes/ompl-python.md):

- state validity: an FCL sphere of radius ``c`` collides with no obstacle or wall (`World.point_clear`);
- motion validity: a Python ``MotionValidator`` that checks each straight motion *exactly* with
  Chipmunk's swept-disc query (`World.segment_clear`), so no edge can cut an obstacle corner between
  sampled states (OMPL's default validator samples states along the edge and can).

`Roadmap` (the multi-query path, used by `plan_paths`): a PRM* roadmap (Karaman & Frazzoli,
"Sampling-based algorithms for optimal motion planning", IJRR 2011) grown with
``PRMstar.growRoadmapPtc`` for a fixed number of termination-condition calls, in the calling thread
(``solve`` would start a helper thread, which deadlocks with Python callbacks). A query links start and
goal to their nearest visible milestones and runs Dijkstra over OMPL's roadmap (read through
``PlannerData``). `plan_points` is the single-query fallback when the roadmap has no route: BIT*
(Gammell, Srinivasa & Barfoot, ICRA 2015) with an iteration budget, then OMPL's ``simplifyMax``.

Either route is then shortened by `shorten` (our own, deterministic): greedy farthest-visible vertex
skipping and "corner pulling" (each interior vertex moved toward its neighbours' chord as far as the
exact swept-disc check allows, by bisection), repeated with resampling. It only ever shortens and keeps
every segment clear; it converges to the taut string in the roadmap route's homotopy class (touching the
obstacles inflated by ``c``), which is what brings a sampled route within 2 % of the optimum.

Determinism: ``ompl.util.RNG.setSeed`` runs before any OMPL object of the roadmap/query exists and all
of them are released (reference counting) before returning, so a result depends only on its own seed,
not on what was planned before in the process; the termination conditions count calls, not seconds.
Cost (workshop, 10 m x 8 m): a 500-milestone roadmap ~60 ms, a query + shortening ~5-10 ms.
"""

from __future__ import annotations

import math

import networkx as nx

from hrc.motion.world import World

__all__ = ["FALLBACK_ITERATIONS", "ROADMAP_ITERATIONS", "Roadmap", "plan_points", "shorten"]

ROADMAP_ITERATIONS = 1000  # PRM* growRoadmap termination-condition calls (~500 milestones)
FALLBACK_ITERATIONS = 3000  # BIT* iterations of the single-query fallback
LINKS = 30  # nearest milestones tried when linking a query point to the roadmap
_EPS = 1e-6  # m, planned clearance above the required one, so float rounding never makes it less

Point = tuple[float, float]


def _length(points: list[Point]) -> float:
    return sum(math.dist(a, b) for a, b in zip(points, points[1:], strict=False))


def plan_points(world: World, start: Point, goal: Point, clearance: float, seed: int,
                iterations: int = FALLBACK_ITERATIONS) -> list[Point] | None:
    """A collision-free polyline from `start` to `goal` keeping `clearance`, or None if none was found.

    Raises nothing on an unreachable goal (the caller names the agent and locations in its error).
    """
    import ompl.base as ob
    import ompl.geometric as og
    import ompl.util as ou

    ou.setLogLevel(ou.LogLevel.LOG_NONE)
    c = clearance + _EPS
    if not (world.point_clear(*start, c) and world.point_clear(*goal, c)):
        return None
    if world.segment_clear(start, goal, c):
        return [start, goal]
    # every OMPL object of earlier queries is gone (released in `_solve` by reference counting), so
    # this seed takes effect (notes: seeding while an OMPL RNG is alive is ignored)
    ou.RNG.setSeed(seed)
    points = _solve(ob, og, world, start, goal, c, iterations)
    if points is None:
        return None
    return shorten(world, points, c)


_VALIDATOR: list[type] = []


def _validator_class(ob) -> type:  # noqa: ANN001
    """A module-level (created once) OMPL motion validator doing exact swept-disc checks."""
    if not _VALIDATOR:
        class ExactMotionValidator(ob.MotionValidator):
            world: World
            clearance: float

            def checkMotion(self, s1, s2, *rest) -> bool:  # noqa: ANN001, N802 (OMPL's name)
                return self.world.segment_clear((s1[0], s1[1]), (s2[0], s2[1]), self.clearance)

        _VALIDATOR.append(ExactMotionValidator)
    return _VALIDATOR[0]


def _space(ob, world: World, c: float):  # noqa: ANN001, ANN202
    """The plane over the bounds shrunk by `c` (a disc centre there keeps `c` from the walls)."""
    xmin, ymin, xmax, ymax = world.workspace.bounds
    space = ob.RealVectorStateSpace(2)
    bounds = ob.RealVectorBounds(2)
    bounds.setLow(0, xmin + c)
    bounds.setLow(1, ymin + c)
    bounds.setHigh(0, xmax - c)
    bounds.setHigh(1, ymax - c)
    space.setBounds(bounds)
    return space


def _checkers(ob, si, world: World, c: float):  # noqa: ANN001, ANN202
    """Install FCL state validity and the exact swept-disc motion validator on `si`."""
    si.setStateValidityChecker(lambda s: world.point_clear(s[0], s[1], c))
    validator = _validator_class(ob)(si)
    validator.world, validator.clearance = world, c
    si.setMotionValidator(validator)
    return validator


def _counter(n: int):  # noqa: ANN202
    """A termination condition function that says "stop" after `n` calls (reproducible, unlike time)."""
    calls = [0]

    def done() -> bool:
        calls[0] += 1
        return calls[0] > n

    return done


def _solve(ob, og, world: World, start: Point, goal: Point, c: float, iterations: int) -> list[Point] | None:  # noqa: ANN001
    space = _space(ob, world, c)
    ss = og.SimpleSetup(space)
    si = ss.getSpaceInformation()
    validator = _checkers(ob, si, world, c)
    a = space.allocState()
    a[0], a[1] = start
    b = space.allocState()
    b[0], b[1] = goal
    ss.setStartAndGoalStates(a, b)
    ss.setOptimizationObjective(ob.PathLengthOptimizationObjective(si))
    ss.setPlanner(og.BITstar(si))
    solved = ss.solve(ob.PlannerTerminationCondition(_counter(iterations)))
    points = None
    if solved and ss.haveExactSolutionPath():
        path = ss.getSolutionPath()
        simplifier = og.PathSimplifier(si)
        simplifier.simplifyMax(path)
        points = [(float(s[0]), float(s[1])) for s in path.getStates()]
    del ss, si, space, validator, a, b
    return points


class Roadmap:
    """A PRM* roadmap for one clearance on one world: milestones, edges (plain data) and queries.

    Built by `Roadmap.build`; `query` returns a shortened clear polyline or None (no route in the
    roadmap: the caller may fall back to `plan_points`).
    """

    def __init__(self, clearance: float, points: list[Point], graph: nx.Graph) -> None:
        self.clearance = clearance
        self.points = points
        self.graph = graph

    @classmethod
    def build(cls, world: World, clearance: float, seed: int, iterations: int = ROADMAP_ITERATIONS) -> Roadmap:
        import ompl.base as ob
        import ompl.geometric as og
        import ompl.util as ou

        ou.setLogLevel(ou.LogLevel.LOG_NONE)
        c = clearance + _EPS
        ou.RNG.setSeed(seed)  # nothing of OMPL is alive here: see the module docstring
        space = _space(ob, world, c)
        si = ob.SpaceInformation(space)
        validator = _checkers(ob, si, world, c)
        si.setup()
        pdef = ob.ProblemDefinition(si)
        planner = og.PRMstar(si)
        planner.setProblemDefinition(pdef)
        planner.setup()
        planner.growRoadmapPtc(ob.PlannerTerminationCondition(_counter(iterations)))
        data = ob.PlannerData(si)
        planner.getPlannerData(data)
        points = []
        for i in range(data.numVertices()):
            st = data.getVertex(i).getState()
            points.append((float(st[0]), float(st[1])))
        graph: nx.Graph = nx.Graph()
        graph.add_nodes_from(range(len(points)))
        for i in range(len(points)):
            for j in sorted(data.getEdges(i)):
                graph.add_edge(i, int(j), weight=math.dist(points[i], points[int(j)]))
        del data, planner, pdef, validator, si, space
        return cls(clearance, points, graph)

    def _links(self, world: World, p: Point) -> list[tuple[int, float]]:
        c = self.clearance + _EPS
        order = sorted(range(len(self.points)), key=lambda i: (math.dist(self.points[i], p), i))
        return [(i, math.dist(self.points[i], p)) for i in order[:LINKS]
                if world.segment_clear(p, self.points[i], c)]

    def query(self, world: World, start: Point, goal: Point) -> list[Point] | None:
        """The shortened roadmap route from `start` to `goal`, or None."""
        c = self.clearance + _EPS
        if world.segment_clear(start, goal, c):
            return [start, goal]
        g = self.graph  # the two query nodes are added for this query and removed afterwards
        g.add_edges_from(("s", i, {"weight": d}) for i, d in self._links(world, start))
        g.add_edges_from(("g", i, {"weight": d}) for i, d in self._links(world, goal))
        try:
            if "s" not in g or "g" not in g:
                return None
            nodes = nx.dijkstra_path(g, "s", "g")
        except nx.NetworkXNoPath:
            return None
        finally:
            g.remove_nodes_from(["s", "g"])
        route = [start] + [self.points[n] for n in nodes[1:-1]] + [goal]
        return shorten(world, route, c)


def shorten(world: World, points: list[Point], clearance: float, rounds: int = 12) -> list[Point]:
    """Shorten a clear polyline without losing clearance (exact swept-disc checks only).

    Never lengthens the path; endpoints are kept. O(rounds * n * log) pymunk queries for n vertices.
    """
    pts = _skip(world, list(points), clearance)
    for _ in range(rounds):
        before = _length(pts)
        pts = _pull(world, _resample(pts, 0.25), clearance)
        pts = _skip(world, pts, clearance)
        if before - _length(pts) < 1e-6:
            break
    return pts


def _skip(world: World, pts: list[Point], c: float) -> list[Point]:
    """Greedy: from each kept vertex jump to the farthest later vertex it sees."""
    out = [pts[0]]
    i = 0
    while i < len(pts) - 1:
        j = len(pts) - 1
        while j > i + 1 and not world.segment_clear(pts[i], pts[j], c):
            j -= 1
        out.append(pts[j])
        i = j
    return out


def _resample(pts: list[Point], step: float) -> list[Point]:
    out = [pts[0]]
    for a, b in zip(pts, pts[1:], strict=False):
        n = max(1, math.ceil(math.dist(a, b) / step))
        out += [(a[0] + (b[0] - a[0]) * k / n, a[1] + (b[1] - a[1]) * k / n) for k in range(1, n)]
        out.append(b)  # exactly: the endpoints are the locations
    return out


def _pull(world: World, pts: list[Point], c: float) -> list[Point]:
    """Move each interior vertex toward its neighbours' chord midpoint as far as stays clear."""
    pts = list(pts)
    for i in range(1, len(pts) - 1):
        p, v, n = pts[i - 1], pts[i], pts[i + 1]
        m = ((p[0] + n[0]) / 2, (p[1] + n[1]) / 2)
        lo, hi = 0.0, 1.0
        cand = m
        if not (world.segment_clear(p, cand, c) and world.segment_clear(cand, n, c)):
            for _ in range(20):
                mid = (lo + hi) / 2
                cand = (v[0] + (m[0] - v[0]) * mid, v[1] + (m[1] - v[1]) * mid)
                if world.segment_clear(p, cand, c) and world.segment_clear(cand, n, c):
                    lo = mid
                else:
                    hi = mid
            cand = (v[0] + (m[0] - v[0]) * lo, v[1] + (m[1] - v[1]) * lo)
        pts[i] = cand
    return pts
