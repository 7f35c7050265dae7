"""Plan generation against an independent brute-force oracle; the workshop's 32 plans; stable ids."""

from __future__ import annotations

import hashlib
import itertools
from collections.abc import Iterable

from conftest import ROOT, WORKSHOP_TASK
from hypothesis import given, settings
from hypothesis import strategies as st

from hrc.io.task_file import load_task
from hrc.model import (
    Action,
    Agent,
    AgentKind,
    Interval,
    Location,
    Phase,
    PhaseRef,
    Plan,
    Precedence,
    Task,
    Workspace,
)
from hrc.plans import agent_legs, allocations, count_plans, generate_plans, must_precede, phase_graph

# --- the oracle: all allocations x all permutations, filtered by an acyclicity check of its own -------


def _acyclic(nodes: Iterable[str], edges: Iterable[tuple[str, str]]) -> bool:
    """Kahn's algorithm: True when every node can be removed in topological order."""
    succ: dict[str, list[str]] = {n: [] for n in nodes}
    indeg = dict.fromkeys(succ, 0)
    for u, v in edges:
        succ[u].append(v)
        indeg[v] += 1
    ready = [n for n, d in indeg.items() if d == 0]
    removed = 0
    while ready:
        n = ready.pop()
        removed += 1
        for m in succ[n]:
            indeg[m] -= 1
            if indeg[m] == 0:
                ready.append(m)
    return removed == len(succ)


def oracle_plans(task: Task) -> list[tuple[tuple, tuple]]:
    """Every (allocation, sequences) whose phase graph is acyclic, in the documented enumeration order."""
    nodes = [f"{a.id}.{p.id}" for a in task.actions for p in a.phases]
    base = [(f"{a.id}.{p.id}", f"{a.id}.{q.id}") for a in task.actions for p, q in itertools.pairwise(a.phases)]
    base += [(f"{pr.before.action}.{pr.before.phase}", f"{pr.after.action}.{pr.after.phase}")
             for pr in task.precedence]
    first = {a.id: f"{a.id}.{a.phases[0].id}" for a in task.actions}
    last = {a.id: f"{a.id}.{a.phases[-1].id}" for a in task.actions}
    out = []
    choices = [[ag for ag in task.agent_ids if ag in a.agents] for a in task.actions]
    for combo in itertools.product(*choices):
        allocation = tuple(zip(task.action_ids, combo, strict=True))
        mine = [tuple(a for a, ag in allocation if ag == agent) for agent in task.agent_ids]
        for perms in itertools.product(*(itertools.permutations(m) for m in mine)):
            edges = list(base)
            for seq in perms:
                edges += [(last[a], first[b]) for a, b in itertools.pairwise(seq)]
            if _acyclic(nodes, edges):
                out.append((allocation, tuple(zip(task.agent_ids, perms, strict=True))))
    return out


# --- random small tasks --------------------------------------------------------------------------------

WS = Workspace(name="empty", bounds=(0, 0, 10, 10), obstacles=(), locations=(Location("L", 5, 5),))


@st.composite
def small_tasks(draw) -> Task:
    agents = [Agent("human", AgentKind.HUMAN, 0.3, 1.2, "L"), Agent("robot", AgentKind.ROBOT, 0.35, 0.6, "L")]
    if draw(st.booleans()):
        agents.reverse()
    n = draw(st.integers(1, 5))
    n_phases = [draw(st.integers(1, 2)) for _ in range(n)]
    actions = []
    for i in range(n):
        who = draw(st.sampled_from([("human",), ("robot",), ("human", "robot"), ("robot", "human")]))
        phases = tuple(Phase(f"p{j}", "L", tuple((ag, Interval(1, 2)) for ag in who)) for j in range(n_phases[i]))
        actions.append(Action(f"a{i}", f"a{i}", who, phases))
    # a random interleaving of all phases that keeps each action's own order; edges only go forward in it,
    # so the task graph is acyclic but actions may still depend on each other both ways (a.p0 -> b.p1 and
    # b.p0 -> a.p1), which forbids one agent from doing both
    slots = draw(st.permutations([i for i in range(n) for _ in range(n_phases[i])]))
    order, seen = [], [0] * n
    for i in slots:
        order.append(PhaseRef(f"a{i}", f"p{seen[i]}"))
        seen[i] += 1
    pairs = [(x, y) for k, x in enumerate(order) for y in order[k + 1:] if x.action != y.action]
    chosen = draw(st.lists(st.sampled_from(pairs), unique=True, max_size=5)) if pairs else []
    return Task(name="random", agents=tuple(agents), actions=tuple(actions),
                precedence=tuple(Precedence(b, a) for b, a in chosen), constraints=(), deadline=None,
                preferences=(), map_path="none.yaml", workspace=WS)


@settings(max_examples=100, deadline=None)
@given(small_tasks())
def test_generate_plans_matches_the_oracle(task):
    expected = oracle_plans(task)
    plans = list(generate_plans(task))
    assert [(p.allocation, p.sequences) for p in plans] == expected  # same plans, same (documented) order
    assert count_plans(task) == len(expected)
    assert len({p.id for p in plans}) == len(plans)
    for p in plans:
        assert _acyclic(phase_graph(task, p).nodes, phase_graph(task, p).edges)


@settings(max_examples=50, deadline=None)
@given(small_tasks())
def test_must_precede_forces_the_order_within_one_agent(task):
    before = must_precede(task)
    for plan in generate_plans(task):
        for _, seq in plan.sequences:
            for i, a in enumerate(seq):
                assert all((b, a) not in before for b in seq[i + 1:])


def test_interleaved_dependencies_forbid_one_agent_doing_both():
    """a.p0 -> b.p1 and b.p0 -> a.p1: acyclic, but whoever does a and b alone would need both first."""
    phases = tuple(Phase(f"p{j}", "L", (("human", Interval(1, 2)), ("robot", Interval(1, 2)))) for j in range(2))
    actions = tuple(Action(i, i, ("human", "robot"), phases) for i in ("a", "b"))
    agents = (Agent("human", AgentKind.HUMAN, 0.3, 1, "L"), Agent("robot", AgentKind.ROBOT, 0.3, 1, "L"))
    precedence = (Precedence(PhaseRef("a", "p0"), PhaseRef("b", "p1")),
                  Precedence(PhaseRef("b", "p0"), PhaseRef("a", "p1")))
    task = Task(name="x", agents=agents, actions=actions, precedence=precedence,
                constraints=(), deadline=None, preferences=(), map_path="none.yaml", workspace=WS)
    assert must_precede(task) == {("a", "b"), ("b", "a")}
    plans = list(generate_plans(task))
    assert [p.allocation for p in plans] == [(("a", "human"), ("b", "robot")), (("a", "robot"), ("b", "human"))]
    assert count_plans(task) == 2 == len(oracle_plans(task))


# --- the workshop ---------------------------------------------------------------------------------------


def test_workshop_has_32_plans():
    task = load_task(WORKSHOP_TASK)
    plans = list(generate_plans(task))
    assert count_plans(task) == len(plans) == 32
    assert len(list(allocations(task))) == 32  # 2^5 allocations, and the pile order fixes each sequence
    assert [(p.allocation, p.sequences) for p in plans] == oracle_plans(task)


def test_floorplan_demo_has_4_plans():
    task = load_task(ROOT / "tasks" / "floorplan_demo.yaml")
    assert count_plans(task) == 4
    assert [(p.allocation, p.sequences) for p in generate_plans(task)] == oracle_plans(task)


def test_plan_ids_are_unique_stable_and_derived_from_the_plan():
    task = load_task(WORKSHOP_TASK)
    first = list(generate_plans(task))
    second = list(generate_plans(load_task(WORKSHOP_TASK)))
    assert first == second  # deterministic order
    assert [p.id for p in first] == [p.id for p in second]
    assert len({p.id for p in first}) == 32
    for p in first:
        rebuilt = Plan(allocation=tuple(p.allocation), sequences=tuple((a, tuple(s)) for a, s in p.sequences))
        assert rebuilt.id == p.id and rebuilt == p and hash(rebuilt) == hash(p)
        assert len(p.id) == 10 and int(p.id, 16) >= 0
    # the id is a function of what the plan is: the human doing everything, computed independently
    human_alone = next(p for p in first if all(ag == "human" for _, ag in p.allocation))
    text = "human:cube1,cube2,cube3,cube4,triangle;robot:"
    assert human_alone.id == hashlib.sha256(text.encode()).hexdigest()[:10]
    assert human_alone.sequence("robot") == ()
    assert human_alone.agent_of("cube3") == "human"


def test_agent_legs_follow_the_sequence_from_the_start():
    task = load_task(WORKSHOP_TASK)
    plan = next(p for p in generate_plans(task) if p.sequence("robot") == ("cube2", "cube4"))
    legs = agent_legs(task, plan, "robot")
    assert [(leg.origin, leg.location, leg.action, leg.phase) for leg in legs] == [
        ("R", "S2", "cube2", "fetch"), ("S2", "T", "cube2", "put"),
        ("T", "S4", "cube4", "fetch"), ("S4", "T", "cube4", "put"),
    ]
    assert [leg.index for leg in legs] == [0, 1, 2, 3]


def test_remembered_legs_belong_to_their_task():
    """`agent_legs` is remembered per plan (`hrc.plans.per_plan`): the same plan of two tasks that differ
    (here only in the robot's start) gets each task's own legs, however the calls interleave."""
    from dataclasses import replace
    from pathlib import Path

    from hrc.io.task_file import load_task

    task = load_task(Path(__file__).resolve().parents[1] / "tasks" / "kitting.yaml")
    robot = next(a for a in task.agents if not a.is_human)
    other = next(loc.id for loc in task.workspace.locations if loc.id != robot.start)
    moved = replace(task, agents=tuple(replace(a, start=other) if a is robot else a for a in task.agents))
    plan = next(p for p in generate_plans(task) if p.sequence(robot.id))
    for _ in range(2):
        assert agent_legs(task, plan, robot.id)[0].origin == robot.start
        assert agent_legs(moved, plan, robot.id)[0].origin == other
        assert agent_legs(task, plan, robot.id) is agent_legs(task, plan, robot.id)  # remembered
