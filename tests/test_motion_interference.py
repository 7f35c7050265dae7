"""Motion acquisition, co-worker interference on the workshop's 32 plans (issue 4)."""

from __future__ import annotations

import pickle
import time
from pathlib import Path as FsPath

import pytest

from hrc.io.task_file import load_task
from hrc.model import Plan, Task
from hrc.motion import Motion, PathLibrary, plan_motions, plan_paths
from hrc.motion.interference import DT, nominal_schedule
from hrc.plans import agent_legs, generate_plans, phase_graph

TASK = FsPath(__file__).resolve().parents[1] / "tasks" / "cube_stacking.yaml"


@pytest.fixture(scope="module")
def task() -> Task:
    return load_task(TASK)


@pytest.fixture(scope="module")
def library(task: Task) -> PathLibrary:
    return plan_paths(task, seed=0)


@pytest.fixture(scope="module")
def plans(task: Task) -> list[Plan]:
    return list(generate_plans(task))


@pytest.fixture(scope="module")
def motions(task: Task, plans: list[Plan], library: PathLibrary) -> dict[str, tuple[Motion, ...]]:
    return {p.id: plan_motions(task, p, library) for p in plans}


def test_one_motion_per_leg_in_order(task: Task, plans: list[Plan], library: PathLibrary,
                                     motions: dict[str, tuple[Motion, ...]]) -> None:
    for plan in plans:
        legs = [lg for a in task.agent_ids for lg in agent_legs(task, plan, a)]
        ms = motions[plan.id]
        assert [(m.agent, m.leg, m.origin, m.target) for m in ms] == \
               [(lg.agent, lg.index, lg.origin, lg.location) for lg in legs]
        for m in ms:
            assert m.free_time == library.get(m.agent, m.origin, m.target).duration
            assert m.max_time >= m.free_time
            if task.agent(m.agent).is_human or m.origin == m.target:
                assert m.max_time == m.free_time and m.interference == ()
            if m.interference:
                assert m.max_time == pytest.approx(m.free_time + max(i.extra_time for i in m.interference))


def test_workshop_has_plans_with_and_without_interference(task: Task, plans: list[Plan],
                                                          motions: dict[str, tuple[Motion, ...]]) -> None:
    """Issue 4, must show: some plan has a robot motion slowed by a named human motion; some has none."""
    with_inter = [pid for pid, ms in motions.items() if any(m.max_time > m.free_time for m in ms)]
    assert 1 <= len(with_inter) < len(plans)
    for pid in with_inter:
        plan = next(p for p in plans if p.id == pid)
        human_legs = {lg.index: lg for lg in agent_legs(task, plan, "human")}
        for m in motions[pid]:
            for i in m.interference:
                assert m.agent == "robot" and i.other_agent == "human" and i.kind == "wait"
                lg = human_legs[i.other_leg]
                assert (i.other_origin, i.other_target) == (lg.origin, lg.location)
                assert i.extra_time > 0


def test_passage_crossing_makes_the_robot_wait(task: Task, plans: list[Plan],
                                               motions: dict[str, tuple[Motion, ...]]) -> None:
    """The robot fetching cube 1 while the human brings cube 2 down the passage: the map's designed case."""
    plan = next(p for p in plans if p.sequence("robot") == ("cube1",))
    first = motions[plan.id][[m.agent for m in motions[plan.id]].index("robot")]
    assert (first.origin, first.target) == ("R", "S1")
    assert first.max_time > first.free_time + 1.0
    assert any((i.other_origin, i.other_target) == ("S2", "T") for i in first.interference)


def test_single_agent_plans_have_no_interference(plans: list[Plan], motions: dict[str, tuple[Motion, ...]]) -> None:
    for plan in plans:
        if not plan.sequence("human") or not plan.sequence("robot"):
            assert all(m.max_time == m.free_time for m in motions[plan.id])


def test_nominal_schedule_respects_the_phase_graph(task: Task, plans: list[Plan], library: PathLibrary) -> None:
    for plan in plans[:8]:
        sched = nominal_schedule(task, plan, library)
        end = {f"{n.leg.action}.{n.leg.phase}": n for legs in sched.values() for n in legs}
        g = phase_graph(task, plan)
        for u, v in g.edges:
            assert end[v].start >= end[u].end - 1e-9
        for legs in sched.values():
            for a, b in zip(legs, legs[1:], strict=False):
                assert b.depart == a.end and b.arrive >= b.depart and b.start >= b.arrive


def test_deterministic_and_picklable(task: Task, plans: list[Plan], library: PathLibrary,
                                     motions: dict[str, tuple[Motion, ...]]) -> None:
    shipped = pickle.loads(pickle.dumps(library))
    for plan in plans:
        assert plan_motions(task, plan, shipped) == motions[plan.id]
    assert DT > 0


@pytest.mark.slow  # a timing check: opt-in, the figures themselves come from scripts/bench_motion.py
def test_fast_enough_for_the_compiler(task: Task, plans: list[Plan]) -> None:
    lib = plan_paths(task, seed=0)
    t0 = time.perf_counter()
    for plan in plans:
        plan_motions(task, plan, lib)
    per_plan = (time.perf_counter() - t0) / len(plans)
    assert per_plan < 0.02  # a few ms expected; generous for a loaded CI machine
