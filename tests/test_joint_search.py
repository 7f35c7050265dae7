"""The search compile on tasks with joint actions (issue 37): a joint action is not allocated, it is in the
sequence of every agent of it (`hrc.compile.bounds`, `hrc.compile.search`).

Checked against the exhaustive compile: on random small joint tasks (hypothesis) and on a hand-made one, the
plan tree's leaves are exactly the plans `hrc.plans.generate_plans` streams (itself checked against brute
force in tests/test_joint.py), each once, and no node's bound beats a plan below it (each leaf compiled); a
closed search's first K plans are the exhaustive compile's; the coverage dives and the on-demand extension
take a person's joint action as one of their choices.
"""

from __future__ import annotations

import itertools
import json
from dataclasses import replace
from pathlib import Path

import pytest
from conftest import ROOT
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from joint_tasks import lift_task, write_lift

from hrc.cli import main
from hrc.compile.bounds import NodeBounds
from hrc.compile.compiler import compile_plan, compile_task, rank_key
from hrc.compile.extend import Prefix, extend_plans
from hrc.compile.search import DIVE_NODES, _dive, _plan, compile_search
from hrc.io.task_file import load_task
from hrc.model import Action, Interval, Phase, PhaseRef, Precedence, Task
from hrc.motion import plan_paths
from hrc.plans import generate_plans, identical_actions, is_canonical

LIFT = lift_task(set_down=True, deadline=40)
"""Two fetches, a joint lift of two phases (held at J, set down at A: both agents go on together), a place."""


@pytest.fixture(scope="module")
def lift(tmp_path_factory):
    path = write_lift(tmp_path_factory.mktemp("lift"), LIFT)
    task = load_task(path)
    return path, task, plan_paths(task, seed=0)


def _leaves(nb: NodeBounds, node, below: dict, path: list) -> None:  # noqa: ANN001
    """Every leaf under `node` (the whole tree, nothing pruned but cycles), with the nodes on its way."""
    if nb.is_leaf(node):
        below.setdefault(node, []).extend(path)
        return
    b = nb.bound(node)
    if b is None:
        return
    for child in nb.children(node, b.ends):
        _leaves(nb, child, below, [*path, node])


def _check_tree(task: Task, paths, compile_leaves: bool = True) -> None:  # noqa: ANN001
    nb = NodeBounds(task, paths)
    below: dict = {}
    _leaves(nb, nb.root(), below, [])
    groups = identical_actions(task)
    canonical = sorted(p.id for p in generate_plans(task) if not groups or is_canonical(task, p, groups))
    found = [_plan(task, leaf) for leaf in below]
    assert sorted(p.id for p in found) == canonical  # every plan once, nothing else
    for plan in found:  # each joint action in the sequence of each agent of it, allocated to its lead
        for action in task.actions:
            if action.joint:
                assert plan.agent_of(action.id) == task.lead(action.id)
                assert all(action.id in plan.sequence(ag) for ag in action.agents)
    if not compile_leaves:
        return
    for leaf, path in below.items():
        key = rank_key(compile_plan(task, _plan(task, leaf), paths, graphml=False))[:4]
        for node in [*path, leaf]:
            b = nb.bound(node)
            assert b is not None and b.key <= key, (node, b, key)


_ONE_TWO = (("human", Interval(1, 2)), ("robot", Interval(2, 3)))


@st.composite
def joint_tasks(draw, base: Task) -> Task:  # noqa: ANN001
    """`base` (the bare floor) with two to four actions of one or two phases at A, B or J, some joint (their
    roles' durations drawn), some precedence (acyclic by index), and a deadline."""
    n = draw(st.integers(2, 4))
    actions = []
    for i in range(n):
        locs = draw(st.lists(st.sampled_from(["A", "B", "J"]), min_size=1, max_size=2))
        if draw(st.booleans()):
            def dur() -> tuple:
                lo = draw(st.integers(1, 4))
                return tuple((ag, Interval(lo + k, lo + k + draw(st.integers(0, 3)))) for k, ag in
                             enumerate(("human", "robot")))
            phases = tuple(Phase(f"p{k}", loc, dur()) for k, loc in enumerate(locs))
            actions.append(Action(f"j{i}", f"j{i}", ("human", "robot"), phases, roles=(("h", "human"), ("r", "robot"))))
        else:
            who = draw(st.sampled_from([("human",), ("robot",), ("human", "robot")]))
            phases = tuple(Phase(f"p{k}", loc, tuple(x for x in _ONE_TWO if x[0] in who)) for k, loc in enumerate(locs))
            actions.append(Action(f"a{i}", f"a{i}", who, phases))
    edges = [Precedence(PhaseRef(actions[i].id, actions[i].phases[-1].id), PhaseRef(actions[j].id, "p0"))
             for i, j in itertools.combinations(range(n), 2) if draw(st.booleans())]
    return replace(base, actions=tuple(actions), precedence=tuple(edges), deadline=float(draw(st.integers(15, 60))))


@settings(max_examples=12, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
@given(data=st.data())
def test_the_tree_is_the_exhaustive_plan_set_and_its_bounds_hold_on_random_joint_tasks(lift, data) -> None:
    _, base, paths = lift
    _check_tree(data.draw(joint_tasks(base)), paths)


def test_the_tree_and_bounds_on_a_two_phase_joint_action(lift) -> None:
    _, task, paths = lift
    _check_tree(task, paths)


def test_a_closed_search_finds_the_exhaustive_best(lift, tmp_path: Path) -> None:
    path, task, paths = lift
    exhaustive = compile_task(task, seed=0, jobs=1)
    k = 3
    result = compile_search(task, tmp_path / "out", k, families=10**6, cover=0, paths=paths)
    assert result.outcome.closed
    head = json.loads((tmp_path / "out" / "compiled.json").read_text("utf-8"))
    assert [p["id"] for p in head["plans"]][:k] == [cp.plan.id for cp in exhaustive.plans[:k]]
    assert head["search"]["plans_compiled"] < len(exhaustive.plans)
    # and from the command line
    assert main(["compile", str(path), "--out", str(tmp_path / "cli"), "--no-report", "-q", "--plans", "best:2"]) == 0
    cli = json.loads((tmp_path / "cli" / "compiled.json").read_text("utf-8"))
    assert [p["id"] for p in cli["plans"]][:2] == [cp.plan.id for cp in exhaustive.plans[:2]]


def test_coverage_takes_the_persons_joint_action_as_a_first_choice(lift) -> None:
    """By hand: the person may start with a or b (a fetch), or with the lift (the robot fetches both and the
    person walks to J meanwhile); never with c, which comes after the lift they take part in."""
    _, task, paths = lift
    nb = NodeBounds(task, paths)
    human = task.agent_ids.index("human")
    for i, action in enumerate(task.actions):
        leaf = _dive(task, nb, human, (i,), DIVE_NODES)
        assert leaf is not False, action.id
        assert (leaf is not None) == (action.id != "c"), action.id
        if leaf is not None:
            assert leaf.seqs[human][0] == i


def test_compile_on_demand_extends_a_history_through_a_joint_action(lift) -> None:
    """The person walked to the lift first: the extension's plans are exactly those of the exhaustive plan set
    whose person's order starts with it (the robot fetches both), best first."""
    _, task, paths = lift
    ext = extend_plans(task, paths, Prefix((("human", ("lift",)),)), k=50, families=50)
    want = {p.id for p in generate_plans(task) if p.sequence("human")[:1] == ("lift",)}
    assert want and {cp.plan.id for cp in ext.plans} == want
    assert all(cp.plan.sequence("robot")[:2] in (("a", "b"), ("b", "a")) for cp in ext.plans)


@pytest.mark.slow
def test_the_joint_workshop_searched(tmp_path: Path) -> None:
    task = load_task(ROOT / "tasks" / "cube_stacking_joint.yaml")
    paths = plan_paths(task, seed=0)
    _check_tree(task, paths)
    exhaustive = compile_task(task, seed=0, jobs=1)
    result = compile_search(task, tmp_path / "out", 5, families=10**6, cover=0, paths=paths)
    assert result.outcome.closed
    head = json.loads((tmp_path / "out" / "compiled.json").read_text("utf-8"))
    assert [p["id"] for p in head["plans"]][:5] == [cp.plan.id for cp in exhaustive.plans[:5]]
