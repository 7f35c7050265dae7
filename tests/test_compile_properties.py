"""Properties of the compiler on random variants of the workshop (random durations, deadline, constraint).

The map and agents stay those of the workshop, so the path library is planned once; each example
draws new manipulation bounds, a new deadline and maybe a temporal constraint, compiles every plan and
checks what the compiler claims against independent truth: an LP for consistency of the written STNU,
a MILP over every passing order for "inconsistent" (no order at all would do), the second DC algorithm
for controllability, and the ASAP schedule for the makespan bounds.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from oracles import lp_consistent, orders_schedulable

from hrc.compile.classify import PlanClass
from hrc.compile.compiler import compile_plan, rank_key
from hrc.compile.temporal_net_creator import ORIGIN
from hrc.io.task_file import load_task
from hrc.model import Event, Interval, Phase, TemporalConstraint
from hrc.motion import plan_paths
from hrc.plans import generate_plans
from hrc.temporal import check_dc
from hrc.temporal.graphml import read_graphml

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def workshop():
    task = load_task(ROOT / "tasks" / "cube_stacking.yaml")
    return task, plan_paths(task, seed=0)


@st.composite
def variants(draw, task):
    def bounds(lo: int, hi: int) -> Interval:
        a = draw(st.integers(lo, hi))
        return Interval(float(a), float(a + draw(st.integers(0, 4))))

    actions = []
    for action in task.actions:
        phases = tuple(Phase(p.id, p.location, (("human", bounds(1, 5)), ("robot", bounds(2, 8))))
                       for p in action.phases)
        actions.append(replace(action, phases=phases))
    constraints: tuple[TemporalConstraint, ...] = ()
    if draw(st.booleans()):
        a, b = draw(st.sampled_from([("cube1", "cube3"), ("cube2", "cube4"), ("cube1", "triangle")]))
        lo = float(draw(st.integers(0, 10)))
        constraints = (TemporalConstraint(Event(a, "put", "end"), Event(b, "put", "end"),
                                          Interval(lo, lo + draw(st.integers(5, 60)))),)
    return replace(task, actions=tuple(actions), constraints=constraints,
                   deadline=float(draw(st.integers(40, 140))))


def _check_variant(task, paths) -> None:  # noqa: ANN001
    compiled = sorted((compile_plan(task, plan, paths) for plan in generate_plans(task)), key=rank_key)
    for cp in compiled:
        stnu = read_graphml(cp.graphml.encode())
        consistent = lp_consistent(stnu, ORIGIN)
        assert consistent == (cp.plan_class is not PlanClass.INCONSISTENT), cp.plan.id
        if not consistent:  # no order of passing at all, on the shortest routes, would have done
            assert not orders_schedulable(task, cp.plan, paths), cp.plan.id
        if consistent:  # the second, independent DC algorithm agrees
            other = check_dc(stnu, algorithm="morris2014").verdict.value
            assert (other == "DC") == (cp.plan_class is PlanClass.DC), cp.plan.id
        ms = cp.classification.makespan
        if ms is None:  # the co-workers would block each other whatever they do
            assert cp.plan_class is PlanClass.INCONSISTENT
            continue
        assert 0 < ms[0] <= ms[1] + 1e-9
        if consistent:  # some schedule meets the deadline, so the earliest one does
            assert ms[0] <= task.deadline + 1e-6, cp.plan.id
        if cp.plan_class is PlanClass.DC:
            # the robot can guarantee the deadline, so even the human's slowest ASAP run meets it
            assert ms[1] <= task.deadline + 1e-6, cp.plan.id
    orders = [cp.plan_class.order for cp in compiled]
    assert orders == sorted(orders)


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                HealthCheck.too_slow])
@given(data=st.data())
def test_classes_makespans_and_ranks_hold_on_random_variants(workshop, data):
    base, paths = workshop
    _check_variant(data.draw(variants(base)), paths)


@pytest.mark.slow
@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                 HealthCheck.too_slow])
@given(data=st.data())
def test_classes_makespans_and_ranks_hold_on_many_random_variants(workshop, data):
    base, paths = workshop
    _check_variant(data.draw(variants(base)), paths)
