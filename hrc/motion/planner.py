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
(``solve`` would start a helper thread, which deadlocks with Python callbacks). Half its samples come
from a bridge-test sampler (Hsu et al., ICRA 2003) so narrow passages get milestones. The locations are
linked to their nearest visible milestones, and one Dijkstra per location (scipy.sparse.csgraph) over
OMPL's roadmap (read through ``PlannerData``) gives every pair's route, plus up to two alternative
routes via milestones away from it (other ways round obstacles, which a sparse roadmap may misrank).
`plan_points` is the single-query fallback when the roadmap does not join a pair: BIT* (Gammell,
Srinivasa & Barfoot, ICRA 2015) with an iteration budget, then OMPL's ``simplifyMax``.

Either route is then shortened by `shorten` (our own, deterministic): greedy farthest-visible vertex
skipping and "corner pulling" (each interior vertex moved toward its neighbours' chord as far as the
exact swept-disc check allows, by bisection), repeated with resampling. It only ever shortens and keeps
every segment clear; it converges to the taut string in the roadmap route's homotopy class (touching the
obstacles inflated by ``c``), which is what brings a sampled route within 2 % of the optimum.

Determinism: ``ompl.util.RNG.setSeed`` runs before any OMPL object of the roadmap/query exists and all
of them are released (reference counting) before returning, so a result depends only on its own seed,
not on what was planned before in the process; the termination conditions count calls, not seconds.
Cost (workshop, 10 m x 8 m, idle machine): a 300-milestone roadmap ~0.1 s, a pair's routes +
shortening ~5-10 ms; all 42 workshop queries ~0.5 s.
"""

from __future__ import annotations

import math

import numpy as np

from hrc.motion.world import World

__all__ = ["FALLBACK_ITERATIONS", "ROADMAP_ITERATIONS", "Roadmap", "plan_points", "shorten"]

ROADMAP_ITERATIONS = 600  # PRM* growRoadmap termination-condition calls (~300 milestones)
FALLBACK_ITERATIONS = 3000  # BIT* iterations of the single-query fallback
LINKS = 30  # nearest milestones tried when linking a query point to the roadmap
ALTERNATIVES = 2  # extra candidate routes per pair (other ways round obstacles), see Roadmap._alternatives
ALT_SLACK = 1.25  # ... whose roadmap length is within this factor of the best roadmap route
ALT_AWAY = 0.6  # m, ... and whose via milestone is at least this far from the routes already taken
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


_SAMPLER: list[type] = []


def _sampler_class(ob, ou) -> type:  # noqa: ANN001
    """A valid-state sampler mixing uniform samples with bridge-test samples (created once).

    Bridge test (Hsu, Jiang, Reif & Sun, "The bridge test for sampling narrow passages with
    probabilistic roadmap planners", ICRA 2003): two nearby invalid states whose midpoint is valid
    mark a narrow passage. Half the samples are drawn that way, so the roadmap finds the 0.2 m wide
    corridor the robot's centre has through the workshop's passage (uniform sampling alone missed
    it in 3 of 60 seeds at the same budget). Random numbers come from OMPL's seeded RNG.
    """
    if not _SAMPLER:
        class BridgeTestSampler(ob.ValidStateSampler):
            def __init__(self, si, world: World, clearance: float) -> None:  # noqa: ANN001
                super().__init__(si)
                self.rng = ou.RNG()
                self.world, self.c = world, clearance
                xmin, ymin, xmax, ymax = world.workspace.bounds
                self.box = (xmin, ymin, xmax, ymax)
                self.sigma = clearance + 0.25

            def _uniform(self, state) -> bool:  # noqa: ANN001
                xmin, ymin, xmax, ymax = self.box
                for _ in range(1000):
                    x = self.rng.uniformReal(xmin + self.c, xmax - self.c)
                    y = self.rng.uniformReal(ymin + self.c, ymax - self.c)
                    if self.world.point_clear(x, y, self.c):
                        state[0], state[1] = x, y
                        return True
                return False

            def sample(self, state) -> bool:  # noqa: ANN001
                if self.rng.uniformBool():
                    return self._uniform(state)
                xmin, ymin, xmax, ymax = self.box
                for _ in range(100):
                    x1, y1 = self.rng.uniformReal(xmin, xmax), self.rng.uniformReal(ymin, ymax)
                    if self.world.point_clear(x1, y1, self.c):
                        continue
                    x2 = x1 + self.rng.gaussian(0.0, self.sigma)
                    y2 = y1 + self.rng.gaussian(0.0, self.sigma)
                    if self.world.point_clear(x2, y2, self.c):
                        continue
                    xm, ym = (x1 + x2) / 2, (y1 + y2) / 2
                    if self.world.point_clear(xm, ym, self.c):
                        state[0], state[1] = xm, ym
                        return True
                return self._uniform(state)

            def sampleNear(self, state, near, distance) -> bool:  # noqa: ANN001, N802 (OMPL's name)
                for _ in range(100):
                    x = near[0] + self.rng.uniformReal(-distance, distance)
                    y = near[1] + self.rng.uniformReal(-distance, distance)
                    if self.world.point_clear(x, y, self.c):
                        state[0], state[1] = x, y
                        return True
                return False

        _SAMPLER.append(BridgeTestSampler)
    return _SAMPLER[0]


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

    def __init__(self, clearance: float, points: list[Point], edges: list[tuple[int, int, float]]) -> None:
        self.clearance = clearance
        self.points = points
        self.edges = edges

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
        samplers: list = []  # keeps the Python samplers alive while OMPL uses them

        def allocate(s):  # noqa: ANN001, ANN202
            samplers.append(_sampler_class(ob, ou)(s, world, c))
            return samplers[-1]

        si.setValidStateSamplerAllocator(allocate)
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
        edges = [(i, int(j), math.dist(points[i], points[int(j)]))
                 for i in range(len(points)) for j in sorted(data.getEdges(i)) if i < int(j)]
        del data, planner, pdef, validator, si, space, allocate
        samplers.clear()
        return cls(clearance, points, edges)

    def _links(self, world: World, p: Point) -> list[tuple[int, float]]:
        c = self.clearance + _EPS
        order = sorted(range(len(self.points)), key=lambda i: (math.dist(self.points[i], p), i))
        return [(i, math.dist(self.points[i], p)) for i in order[:LINKS]
                if world.segment_clear(p, self.points[i], c)]

    def routes(self, world: World, ends: list[Point]) -> dict[tuple[int, int], list[Point] | None]:
        """Shortened routes between every pair ``i < j`` of `ends` (None: not joined by the roadmap).

        The ends are linked to their nearest visible milestones; one multi-source Dijkstra
        (scipy.sparse.csgraph) over the roadmap serves every pair.
        """
        c = self.clearance + _EPS
        n, k = len(self.points), len(ends)
        rows, cols, weights = [], [], []
        for i, j, w in self.edges:
            rows.append(i)
            cols.append(j)
            weights.append(w)
        for e, p in enumerate(ends):
            for i, d in self._links(world, p):
                rows.append(n + e)
                cols.append(i)
                weights.append(max(d, 1e-12))
        from scipy.sparse import csr_matrix  # here: a roadmap read from the cache is never searched again
        from scipy.sparse.csgraph import dijkstra

        graph = csr_matrix((weights, (rows, cols)), shape=(n + k, n + k))
        dist, pred = dijkstra(graph, directed=False, indices=list(range(n, n + k)), return_predecessors=True)
        out: dict[tuple[int, int], list[Point] | None] = {}
        for a in range(k):
            for b in range(a + 1, k):
                if world.segment_clear(ends[a], ends[b], c):
                    out[(a, b)] = [ends[a], ends[b]]
                    continue
                if not np.isfinite(dist[a, n + b]):
                    out[(a, b)] = None
                    continue
                best = self._trace(pred, a, n + b, ends)
                candidates = [best] + self._alternatives(dist, pred, a, b, best, ends)
                seen = _Remembered(world)  # the candidates' shortenings ask much the same
                shortened = [shorten(seen, route, c) for route in candidates]  # type: ignore[arg-type]
                out[(a, b)] = min(shortened, key=_length)
        return out

    def _trace(self, pred: np.ndarray, a: int, target: int, ends: list[Point]) -> list[Point]:
        """The route from end `a` to node `target` along Dijkstra's predecessors (from end `a`)."""
        n = len(self.points)
        nodes = []
        v = target
        while v != n + a and v >= 0:
            nodes.append(v)
            v = int(pred[a, v])
        return [ends[a]] + [self._point(v, ends) for v in reversed(nodes)]

    def _alternatives(self, dist: np.ndarray, pred: np.ndarray, a: int, b: int, best: list[Point],
                      ends: list[Point]) -> list[list[Point]]:
        """Up to `ALTERNATIVES` routes via milestones away from the best route (other homotopy classes).

        A sparse roadmap stretches routes by a few per cent, enough to rank a slightly longer way round
        an obstacle first; the via-milestone routes ``a -> v -> b`` within `ALT_SLACK` of the best,
        each at least `ALT_AWAY` from the routes already taken, are shortened too and the shortest wins.
        """
        n = len(self.points)
        total = dist[a, :n] + dist[b, :n]
        limit = dist[a, n + b] * ALT_SLACK
        taken = [np.asarray(best)]
        out: list[list[Point]] = []
        for v in np.argsort(total, kind="stable"):
            if total[v] > limit or len(out) >= ALTERNATIVES:
                break
            p = np.asarray(self.points[v])
            if min(_to_polyline(p, r) for r in taken) < ALT_AWAY:
                continue
            there = self._trace(pred, a, int(v), ends)
            back = self._trace(pred, b, int(v), ends)[::-1]
            route = there + back[1:]
            out.append(route)
            taken.append(np.asarray(route))
        return out

    def _point(self, v: int, ends: list[Point]) -> Point:
        return self.points[v] if v < len(self.points) else ends[v - len(self.points)]

    def query(self, world: World, start: Point, goal: Point) -> list[Point] | None:
        """The shortened roadmap route from `start` to `goal`, or None."""
        return self.routes(world, [start, goal])[(0, 1)]


def _to_polyline(p: np.ndarray, line: np.ndarray) -> float:
    """Distance from point `p` to the polyline `line` (k x 2)."""
    a, b = line[:-1], line[1:]
    ab = b - a
    denom = np.maximum((ab * ab).sum(axis=1), 1e-18)
    t = np.clip(((p - a) * ab).sum(axis=1) / denom, 0.0, 1.0)
    q = a + ab * t[:, None]
    return float(np.sqrt(((q - p) ** 2).sum(axis=1)).min())


def shorten(world: World, points: list[Point], clearance: float, rounds: int = 12) -> list[Point]:
    """Shorten a clear polyline without losing clearance (exact swept-disc checks only).

    Never lengthens the path; endpoints are kept. O(rounds * n * log) pymunk queries for n vertices, of
    which about three in four ask again what an earlier round asked (the points settle): answered from
    a memo of this shortening's queries (`_Remembered`).
    """
    if not isinstance(world, _Remembered):
        world = _Remembered(world)  # type: ignore[assignment]
    pts = _skip(world, list(points), clearance)
    for _ in range(rounds):
        before = _length(pts)
        pts = _pull(world, _resample(pts, 0.25), clearance)
        pts = _skip(world, pts, clearance)
        if before - _length(pts) < 1e-6:
            break
    return pts


class _Remembered:
    """A world's `World.segment_clear`, each query answered once (a pure function of its arguments)."""

    def __init__(self, world: World) -> None:
        self._world = world
        self._seen: dict[tuple[Point, Point, float], bool] = {}

    def segment_clear(self, a: Point, b: Point, clearance: float) -> bool:
        key = (a, b, clearance)
        found = self._seen.get(key)
        if found is None:
            found = self._seen[key] = self._world.segment_clear(a, b, clearance)
        return found


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
