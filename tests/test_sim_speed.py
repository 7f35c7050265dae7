"""Issue 38 (1,000 simulated runs in less time): the shortcuts give what the long way gives.

Each shortcut is checked against an independent computation: the QP's anchors against scipy's connected
components, the best plan against a brute-force minimum of the rank key, the give-way roadmap search
against networkx's Dijkstra, the cached world geometry against a fresh one, the floor's deferred pymunk
positions against the movers, and a dispatcher forked after other runs (its caches filled by them)
against a fresh one on the same messages.
"""

from __future__ import annotations

import math
from dataclasses import replace

import networkx as nx
import numpy as np
import pytest
import scipy.sparse as sp
from conftest import WORKSHOP_TASK
from hypothesis import given
from hypothesis import strategies as st
from scipy.sparse.csgraph import connected_components

from hrc.apa.compile import _anchors
from hrc.compile.compiler import compile_task
from hrc.dispatch import Dispatcher, Observation
from hrc.io.task_file import load_task
from hrc.motion.planner import LINKS
from hrc.motion.world import World, _fcl_object, _pieces
from hrc.sim.floor import Floor
from hrc.sim.giveway import Disc, Ways
from hrc.sim.run import SimContext, SimSettings, make_controller, simulate_run


@pytest.fixture(scope="module")
def workshop():
    return load_task(WORKSHOP_TASK)


@pytest.fixture(scope="module")
def compiled(workshop):
    return compile_task(workshop, seed=0, jobs=1)


@given(st.integers(1, 12).flatmap(lambda n: st.tuples(
    st.just(n), st.lists(st.tuples(st.integers(0, n - 1), st.integers(0, n - 1)), max_size=20))))
def test_the_qps_anchors_are_each_parts_first_event(case):
    n, rows = case
    src = np.array([a for a, _ in rows], dtype=np.int64)
    dst = np.array([b for _, b in rows], dtype=np.int64)
    graph = sp.csr_matrix((np.ones(len(src)), (src, dst)), shape=(n, n))
    _, labels = connected_components(graph, directed=True, connection="weak")
    _, first = np.unique(labels, return_index=True)
    assert _anchors(n, src, dst).tolist() == sorted(first.tolist())


@pytest.fixture(scope="module")
def ranker(compiled):
    return Dispatcher.from_compiled(compiled, threads=1).ranker


@given(st.lists(st.tuples(st.integers(0, 2), st.integers(0, 1), st.integers(0, 3), st.integers(0, 3),
                          st.sampled_from([0.5, -1.0, math.inf])), min_size=1, max_size=80),
       st.booleans())
def test_the_best_plan_is_the_first_smallest_rank_key(ranker, compiled, rows, with_lead):
    """`Ranker.best` (one stable sort for a few plans, successive minima beyond) against the smallest key
    found by brute force, the earlier candidate on a tie."""
    n = len(rows)
    plans = np.arange(n, dtype=np.int64) % len(compiled.plans)
    cls = np.array([r[0] for r in rows], dtype=np.int8)
    lead = np.array([r[1] for r in rows], dtype=np.int8) if with_lead else None
    finish = np.array([r[2] for r in rows], dtype=np.int64)
    idle = np.array([r[3] for r in rows], dtype=np.int64)
    columns = [c.tolist() for c in ranker._columns(plans, cls, finish, idle, lead)]
    truth = min(range(n), key=lambda i: (*(c[i] for c in columns), i))
    assert ranker.best(plans, cls, finish, idle, lead) == truth


def test_a_give_way_search_is_dijkstra_on_the_roadmap_without_the_blocked_edges(workshop, compiled):
    """`Ways._search` against networkx's Dijkstra over the roadmap edges the disc leaves (the segment's
    distance to its centre, computed here) and the ends' links to their nearest clear milestones."""
    paths = compiled.paths
    clearance = min(paths.roadmaps)
    ways = Ways(World(workshop.workspace), paths, {})
    pts, ij, w = ways._roadmap(clearance)
    start, goal = tuple(map(float, pts[3])), tuple(map(float, pts[-4]))
    avoid = Disc(tuple(map(float, pts[len(pts) // 2])), 0.5)
    nodes, dist, pred, n = ways._search(clearance, start, avoid, goal)
    g = nx.Graph()
    g.add_nodes_from(range(n + 2))
    blocked = 0
    for (i, j), d in zip(ij.tolist(), w.tolist(), strict=True):
        a, b = pts[i], pts[j]
        t = min(1.0, max(0.0, float(np.dot(np.subtract(avoid.xy, a), b - a) / max(np.dot(b - a, b - a), 1e-300))))
        if math.dist(a + t * (b - a), avoid.xy) >= avoid.reach:
            g.add_edge(i, j, weight=d)
        else:
            blocked += 1
    assert blocked > 0  # the disc does block some edges
    free = math.dist(start, avoid.xy)
    for e, p in ((0, start), (1, goal)):
        near = sorted(range(n), key=lambda k: (math.hypot(pts[k, 0] - p[0], pts[k, 1] - p[1]), k))[:LINKS]
        for k in near:
            q = (float(pts[k, 0]), float(pts[k, 1]))
            if ways._clear(p, q, clearance, avoid, free if e == 0 else math.inf):
                g.add_edge(n + e, k, weight=max(math.dist(p, q), 1e-12))
    truth = nx.single_source_dijkstra_path_length(g, n)
    assert len(truth) > n // 2  # most of the roadmap is reached
    for k in range(n + 2):
        assert dist[k] == pytest.approx(truth.get(k, math.inf), abs=1e-9)


def test_world_geometry_is_made_once_and_is_the_same(workshop):
    a, b = World(workshop.workspace), World(workshop.workspace)
    assert all(x is y for x, y in zip(a._fcl_obstacles, b._fcl_obstacles, strict=True))  # made once, shared
    for ob in workshop.workspace.obstacles:  # the kept pieces are those made afresh
        assert _pieces(tuple(ob.polygon)) == _pieces.__wrapped__(tuple(ob.polygon))
    fresh = World.__new__(World)
    _pieces.cache_clear()
    _fcl_object.cache_clear()
    fresh.__init__(workshop.workspace)  # type: ignore[misc]
    assert not any(x is y for x, y in zip(a._fcl_obstacles, fresh._fcl_obstacles, strict=True))
    for x, y in ((1.0, 1.0), (3.2, 2.1), (5.5, 4.0), (2.0, 3.5)):
        assert a.clearance(x, y) == b.clearance(x, y) == fresh.clearance(x, y)
        assert a.point_clear(x, y, 0.3) == fresh.point_clear(x, y, 0.3)


def test_the_floor_moves_the_bodies_before_pymunk_reads_them(workshop):
    floor = Floor(workshop)
    h, r = floor.human, floor.robot
    far = (r.xy[0] + 3.0, r.xy[1])
    h.set_route((h.xy, far), 1.0)
    floor.advance(0.1)  # far apart: the bodies wait
    assert floor._unsynced == (h.xy, r.xy)
    floor.place(h, (r.xy[0] + h.agent.radius + r.agent.radius - 0.05, r.xy[1]))  # overlapping the robot
    assert floor._unsynced is None and tuple(h.body.position) == h.xy and tuple(r.body.position) == r.xy
    floor.advance(0.1)  # near: pymunk stepped and asked
    assert floor._unsynced is None and tuple(h.body.position) == h.xy and tuple(r.body.position) == r.xy
    assert floor.overlaps == 1


def test_a_fork_after_other_runs_decides_as_a_fresh_dispatcher(workshop, compiled):
    """The dispatcher's caches shared by forks (shapes of a candidate list, the person's part kept, a
    drive's bounds, DO forms) hold nothing of one run that changes another's decisions."""
    ctx = SimContext(workshop, {"motion": compiled}, SimSettings(), 3)
    messages = []
    for i in range(3):
        ctls: list = []
        simulate_run(ctx, "hrc", i, controller=lambda c, p, ctls=ctls: ctls.append(make_controller(c, p)) or ctls[-1])
        messages.append(ctls[0].d.accepted)
    assert all(len(m) > 10 for m in messages) and messages[0] != messages[1]
    for accepted in reversed(messages):
        fresh = Dispatcher.from_compiled(compiled, threads=1)
        forked = ctx.cache[("dispatcher", "hrc", False)].fork()
        for obs in accepted:
            assert forked.observe(obs).to_json() == fresh.observe(obs).to_json()


def test_a_runs_first_messages_are_decided_once_and_as_a_fresh_dispatcher_decides(workshop, compiled):
    """`Dispatcher._answered`: the same first messages to forks of one dispatcher lead to the very same
    state objects (decided once), each decision as a fresh dispatcher (its own states: nothing to reuse)
    gives it; a message at another time, or past `ANSWERED_DEPTH`, is decided again."""
    from hrc.dispatch.dispatcher import ANSWERED_DEPTH

    ctx = SimContext(workshop, {"motion": compiled}, SimSettings(), 5)
    ctls: list = []
    simulate_run(ctx, "hrc", 0, controller=lambda c, p: ctls.append(make_controller(c, p)) or ctls[-1])
    accepted = ctls[0].d.accepted
    assert len(accepted) > ANSWERED_DEPTH + 2
    pristine = ctx.cache[("dispatcher", "hrc", False)]
    a, b, fresh = pristine.fork(), pristine.fork(), Dispatcher.from_compiled(compiled, threads=1)
    for k, obs in enumerate(accepted):
        da, db, df = a.observe(obs), b.observe(obs), fresh.observe(obs)
        assert da.to_json() == db.to_json() == df.to_json()
        assert (a._state is b._state) == (k < ANSWERED_DEPTH)  # decided once for the first messages only
        assert fresh._state is not a._state
    other = pristine.fork()
    later = Observation(accepted[0].t + 0.25, accepted[0].event, accepted[0].agent, accepted[0].action,
                        accepted[0].phase)
    first = pristine.fork()
    first.observe(accepted[0])
    assert other.observe(later).to_json() == Dispatcher.from_compiled(compiled, threads=1).observe(later).to_json()
    assert other._state is not first._state


def test_the_step_loops_shortcuts_agree_with_the_long_way(workshop, compiled, monkeypatch):
    """At every step of real runs of each policy: `_Run.next_time` (the soonest kept as the candidates
    come) against the minimum of the filtered list of every candidate, as it was computed; and where
    `_home_or_aside` answers at once (None), the long way (`_home_reached`, `_give_way`) decides nothing."""
    from hrc.sim import run as run_mod
    from hrc.sim.floor import time_to_stop
    from hrc.sim.policies import DispatchedController
    from hrc.sim.standoff import ASIDE_AFTER, WAIT_STEP

    def listed(self) -> float:  # the list version (no sensor here)
        t = self.t
        cands = [self.detector.next_due()]
        step = None
        for ag in (self.h, self.r):
            if ag.mover.moving:
                cands.append(t + time_to_stop(ag.mover))
                step = self.floor.safe_step() if step is None else step
                cands.append(t + step)
                if ag.mover.blocked_for > 0:
                    cands.append(t + max(ASIDE_AFTER - ag.mover.blocked_for, run_mod.MIN_STEP))
            if ag.mode == "work":
                cands.append(ag.work_end)
        if self.h.mode == "away" and self.h.back_at is not None:
            cands.append(max(self.h.back_at, t + 0.1))
        if self.draws.absence is not None and not self.absence_done:
            cands.append(self.draws.absence[0])
        if self.h.mode in ("free", "parked", "arrived") and self.model.choice == "follow" and not self.ctl.stopped:
            cands += self._guide_times()
        if any(ag.mode == "aside_wait" and ag.held_up for ag in (self.h, self.r)):
            cands.append(t + WAIT_STEP)
        o = self.ctl.order()
        if o is not None and o.event in ("depart", "unpark", "start"):
            cands.append(o.earliest)
        due = self.ctl.due() if isinstance(self.ctl, DispatchedController) else None
        if due is not None:
            cands.append(due)
        future = [c for c in cands if c > t + 1e-9 and math.isfinite(c)]
        return min(min(future), self.cap) if future else math.inf

    fast_next, fast_home = run_mod._Run.next_time, run_mod._Run._home_or_aside
    counts = {"steps": 0, "at_once": 0}

    def next_time(self):
        got = fast_next(self)
        assert got == listed(self)
        counts["steps"] += 1
        return got

    def home_or_aside(self, a, other):
        got = fast_home(self, a, other)
        if got is None:
            counts["at_once"] += 1
            mode, xy = a.mode, a.mover.xy
            assert not self._home_reached(a) and not self._give_way(a, (other,))
            assert (a.mode, a.mover.xy) == (mode, xy)
        return got

    monkeypatch.setattr(run_mod._Run, "next_time", next_time)
    monkeypatch.setattr(run_mod._Run, "_home_or_aside", home_or_aside)
    from hrc.sim.blind import blind_compile

    ctx = SimContext(workshop, {"motion": compiled, "blind": blind_compile(workshop, seed=0, jobs=1)},
                     SimSettings(), 11)
    for policy in ("hrc", "motion-blind", "fixed"):
        for i in range(3):
            simulate_run(ctx, policy, i)
    assert counts["steps"] > 500 and counts["at_once"] > 500


def test_the_simulators_compiles_kept_on_disk_give_the_same_runs(mini_task, tmp_path, monkeypatch):
    """`hrc.sim.compile_cache`: a second simulation of the same task takes both compiles from the disk
    cache (not compiled again: `make` fails the test), equal plan by plan to the first's, and writes the
    same ``simulation.json``; another seed or another map is a miss; no cache folder, no file."""
    from hrc.sim.blind import blind_compile
    from hrc.sim.compile_cache import kept_compile
    from hrc.sim.montecarlo import simulate, simulation_json

    monkeypatch.setenv("HRC_CACHE_DIR", str(tmp_path / "cache"))
    first = simulate(mini_task, 3, 4, jobs=1)
    assert len(list((tmp_path / "cache" / "results").glob("*.pickle"))) == 2  # motion and blind
    again = simulate(mini_task, 3, 4, jobs=1)
    assert simulation_json(again) == simulation_json(first)
    for kind in ("motion", "blind"):
        kept = kept_compile(kind, mini_task, 0, None, lambda: pytest.fail("compiled again"))
        assert kept == first.context.compiles[kind]  # every field: task, digest, paths, plans, options
    made: list[int] = []
    other = kept_compile("blind", mini_task, 1, None,
                         lambda: made.append(1) or blind_compile(mini_task, seed=1, jobs=1))
    assert made == [1] and other.seed == 1
    moved = replace(mini_task, deadline=mini_task.deadline + 1)
    kept_compile("blind", moved, 0, None, lambda: made.append(2) or blind_compile(moved, seed=0, jobs=1))
    assert made == [1, 2]
    monkeypatch.setenv("HRC_CACHE_DIR", "")
    kept_compile("blind", mini_task, 0, None, lambda: made.append(3) or blind_compile(mini_task, seed=0, jobs=1))
    assert made == [1, 2, 3]
