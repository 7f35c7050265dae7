"""What the workshop's cold compile was made faster with (issue 38, fourth pass), each held to the
library it replaces or to the slow way it takes a short cut from:

- the 8-connected components of a route pair's close cells, labelled on their bounding box
  (`hrc.motion.conflicts._components`), and the runs of a mask without scipy (`_runs`), against
  ``scipy.ndimage.label`` on the whole grid;
- the swept-disc test called straight into Chipmunk (`hrc.motion.world.World.segment_clear`) against
  pymunk's public ``Shape.segment_query`` on random segments, grazing ones included;
- the acyclicity check of plan generation and of the task reader against networkx (no longer imported
  by a compile);
- the roadmaps planned in two processes (`hrc.compile.executors.run_apart`) against one process.
"""

from __future__ import annotations

import math
import os
import random

import numpy as np
import pytest
from conftest import WORKSHOP_TASK
from hypothesis import given, settings
from hypothesis import strategies as st

from hrc.io.task_file import load_task


@settings(max_examples=150, deadline=None)
@given(st.integers(1, 24), st.integers(1, 24), st.floats(0.0, 0.7), st.integers(0, 2**32 - 1))
def test_components_number_as_ndimage_label(h, w, density, seed):
    from scipy import ndimage

    from hrc.motion.conflicts import _components

    rng = np.random.default_rng(seed)
    grid = rng.random((h, w)) < density
    rows, cols = np.nonzero(grid)
    if not len(rows):
        return
    perm = rng.permutation(len(rows))  # the close pairs come in any order
    rows, cols = rows[perm], cols[perm]
    labels, n = _components(rows, cols)
    want, m = ndimage.label(grid, structure=np.ones((3, 3), dtype=int))
    assert n == m
    assert (labels == want[rows, cols]).all()


@settings(max_examples=150, deadline=None)
@given(st.lists(st.booleans(), min_size=1, max_size=60))
def test_runs_are_ndimage_label_runs(bits):
    from scipy import ndimage

    from hrc.motion.conflicts import _runs

    mask = np.array(bits)
    labels, n = ndimage.label(mask)
    want = [(int(i[0]), int(i[-1])) for i in (np.flatnonzero(labels == k) for k in range(1, n + 1))]
    assert _runs(mask) == want


def test_segment_clear_answers_as_pymunk_segment_query():
    from hrc.motion.world import World

    task = load_task(WORKSHOP_TASK)
    world = World(task.workspace)
    xmin, ymin, xmax, ymax = task.workspace.bounds
    rng = random.Random(7)
    checked = blocked = 0
    for _ in range(4000):
        a = (rng.uniform(xmin, xmax), rng.uniform(ymin, ymax))
        b = (rng.uniform(xmin, xmax), rng.uniform(ymin, ymax))
        c = rng.choice([0.0, 0.25, 0.31, 0.45, 1.0])
        want = all(sh.segment_query(a, b, c) is None for sh, _ in world._static)
        assert world.segment_clear(a, b, c) == want, (a, b, c)
        blocked += not want
        checked += 1
    # grazing: the clearance just below, at and above the distance of the segment's start to the shapes
    for _ in range(300):
        a = (rng.uniform(xmin, xmax), rng.uniform(ymin, ymax))
        b = (a[0] + rng.uniform(-1, 1), a[1] + rng.uniform(-1, 1))
        d = abs(min(sh.point_query(a).distance for sh, _ in world._static))  # the disc at `a` touches then
        for c in (math.nextafter(d, 0.0), d, math.nextafter(d, math.inf)):
            want = all(sh.segment_query(a, b, c) is None for sh, _ in world._static)
            assert world.segment_clear(a, b, c) == want
    assert 0 < blocked < checked


def test_acyclic_checks_agree_with_networkx():
    import networkx as nx

    from hrc.model import is_acyclic
    from hrc.plans import _edge

    rng = random.Random(3)
    for _ in range(500):
        n = rng.randint(1, 8)
        edges = [(str(rng.randrange(n)), str(rng.randrange(n))) for _ in range(rng.randint(0, 12))]
        edges = [(u, v) for u, v in edges if u != v]
        g = nx.DiGraph(edges)
        mine: dict[str, list[str]] = {}
        for u, v in edges:
            _edge(mine, u, v)
        assert is_acyclic(mine) == nx.is_directed_acyclic_graph(g), edges


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="one core: nothing is planned apart")
def test_roadmaps_planned_apart_are_those_planned_here():
    from hrc.compile.executors import run_apart
    from hrc.motion.paths import plan_paths

    task = load_task(WORKSHOP_TASK)
    here = plan_paths(task, seed=3, cache=False)
    apart = plan_paths(task, seed=3, cache=False, apart=run_apart)
    assert here.stats["apart"] == 0 and apart.stats["apart"] == 1
    assert apart.paths == here.paths
    for c, roadmap in here.roadmaps.items():
        assert (apart.roadmaps[c].points, apart.roadmaps[c].edges) == (roadmap.points, roadmap.edges)


def test_a_failed_process_apart_is_planned_here():
    from hrc.compile.executors import run_apart

    def boom() -> None:
        raise RuntimeError("no")

    assert run_apart(boom)() is None
    assert run_apart(lambda: (1, "two"))() == (1, "two")
    slow = run_apart(lambda: __import__("time").sleep(30))
    slow.cancel()  # stopped and reaped at once
    assert slow.pid == 0


def test_the_imports_done_before_the_forks_are_what_a_cold_compile_imports(tmp_path):
    """`hrc.compile.stream.FORKED_IMPORTS` (imported once before a local pool's forks, issue 38) are each
    imported on first use by a cold compile (paths planned, plans compiled: their conflicts, preferences),
    not before: a stale name would cost every compile an import for nothing."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from hrc.compile.stream import FORKED_IMPORTS, compile_records\n"
        "from hrc.compile.compiler import CompileOptions\n"
        "from hrc.io.task_file import load_task\n"
        "from hrc.motion import plan_paths\n"
        "from hrc.plans import plan_families\n"
        "task = load_task(sys.argv[1])\n"
        "assert not [m for m in FORKED_IMPORTS if m in sys.modules], 'imported at start-up'\n"
        "paths = plan_paths(task, seed=0)\n"
        "compile_records(CompileOptions(), 'graphml', task, paths, list(plan_families(task)))\n"
        "missing = [m for m in FORKED_IMPORTS if m not in sys.modules]\n"
        "assert not missing, missing\n")
    env = {**os.environ, "HRC_CACHE_DIR": str(tmp_path / "cache")}  # the roadmaps planned, not read
    subprocess.run([sys.executable, "-c", code, str(WORKSHOP_TASK)], check=True, env=env)
