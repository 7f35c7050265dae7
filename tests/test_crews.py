"""Crews (issue 37, "teams and joint actions"): a joint action whose role names candidates, or ``agents:
[...]`` with ``agents_needed: k`` (any k of them); which agents do it is a choice of the plan, part of its
allocation (`hrc.model.Action.crews`, `hrc.model.Task.crew`).

A hand-worked case on a bare floor (plan count, crews and classes worked out by hand); a brute force on
small random tasks against an enumeration written here (every subset of agents that fills the roles, every
order of every agent's actions, acyclicity of the phase graph by networkx); the CSTNU Tool on every STNU of
the hand-worked case and of tasks/two_workers_joint.yaml; the task format's refusals; and the online parts
that cannot follow a crew refusing such a task in one line (the search compile and compile on demand follow
crews: tests/test_crews_search.py).
"""

from __future__ import annotations

import copy
import itertools
import re
from pathlib import Path
from typing import Any

import networkx as nx
import pytest
import test_cstnu_tool
import yaml
from conftest import ROOT
from hypothesis import given, settings
from hypothesis import strategies as st
from test_cstnu_tool import _agree, _compiled_classes

from hrc.cli import main
from hrc.compile.compiler import compile_plan
from hrc.compile.output import iter_plans
from hrc.io.task_file import dump_task, load_task
from hrc.model import Action, Agent, AgentKind, Interval, Phase, PhaseRef, Precedence, Task
from hrc.motion import plan_paths
from hrc.plans import (
    allocation_count,
    count_plans,
    generate_plans,
    plan_code,
    plan_count_bound,
    plan_from_code,
)

cstnu_tool = test_cstnu_tool.tool
"""The CSTNU Tool, as tests/test_cstnu_tool.py finds it (skipped, saying why, without it)."""

ERROR_LINE = re.compile(r"^error: [^\n]+: [^\n]+\n$")

BARE_MAP: dict[str, Any] = {"name": "bare", "bounds": [0, 0, 10, 4], "obstacles": [],
                            "locations": {"H": [1, 2], "S": [5, 0.5], "J": [5, 2], "A": [1, 3.5], "B": [9, 3.5]}}

HAND: dict[str, Any] = {
    "name": "hand", "map": "map.yaml", "safety_margin": 0.1, "deadline": 15,
    "agents": [{"id": "alice", "kind": "human", "radius": 0.3, "speed": 1.0, "start": "H"},
               {"id": "bob", "kind": "human", "radius": 0.3, "speed": 1.0, "start": "B"},
               {"id": "robot", "kind": "robot", "radius": 0.35, "speed": 0.5, "start": "S"}],
    "actions": [
        {"id": "carry", "name": "carry the part to A", "agents": ["alice", "bob"],
         "phases": [{"id": "put", "location": "A", "duration": {"alice": [1, 2], "bob": [1, 2]}}]},
        {"id": "lift", "name": "lift the frame at J", "roles": {"holder": {"agents": ["alice", "bob"]},
                                                                 "lifter": "robot"},
         "phases": [{"id": "hold", "location": "J", "duration": {"holder": [3, 5], "lifter": [2, 4]}}]}],
    "precedence": [["carry", "lift"]],
}
"""Worked by hand. Plans: carry by alice or bob (2) x the lift's crew {alice, robot} or {bob, robot} (2) =
4 allocations, one order each (an agent with both actions does carry first): 4 plans. Straight routes on
the bare floor, people 1 m/s (travel up to x1.25), the robot 0.5 m/s: S->J 1.5 m, 3 s; H->A 1.5 m,
1.5-1.875 s; A->J and B->J 4.272 m, 4.272-5.340 s; B->A 8 m, 8-10 s; H->J 4 m, 4-5 s. The lift starts
when its crew is at J and carry is done, and lasts 3-5 s (the slower role, contingent). Deadline 15 s:
- carry alice, crew alice: alice at J after 1.5-1.875 + 1-2 + 4.272-5.340 = 6.77-9.22 s: ends by 14.22 s
  in the worst case: DC;
- carry alice, crew bob: bob at J by 5.34 s, carry done by 3.875 s, the robot there at 3 s: ends by
  10.34 s: DC;
- carry bob, crew alice: carry done 9-12 s (bob B->A, then 1-2 s): ends 12-17 s; the worst case misses
  the deadline, the best meets it: consistent (not DC);
- carry bob, crew bob: bob at J after 8 + 1 + 4.272 = 13.27 s at the earliest: ends at 16.27 s at best:
  inconsistent.
"""
HAND_CLASSES = {("alice", "alice"): "DC", ("alice", "bob"): "DC", ("bob", "alice"): "consistent",
                ("bob", "bob"): "inconsistent"}  # (who carries, who holds) -> class


def _write(tmp: Path, task: dict[str, Any], name: str = "task.yaml") -> Path:
    (tmp / "map.yaml").write_text(yaml.safe_dump(BARE_MAP, sort_keys=False), "utf-8")
    path = tmp / name
    path.write_text(yaml.safe_dump(task, sort_keys=False), "utf-8")
    return path


@pytest.fixture(scope="module")
def hand_out(tmp_path_factory) -> Path:
    """The hand-worked case, compiled."""
    tmp = tmp_path_factory.mktemp("hand")
    out = tmp / "out"
    assert main(["compile", str(_write(tmp, HAND)), "--out", str(out), "--no-report", "-q"]) == 0
    return out


# ----------------------------------------------------------------------------------------- the model

def test_candidates_load_as_roles_with_crews(tmp_path: Path) -> None:
    task = load_task(_write(tmp_path, HAND))
    lift = task.action("lift")
    assert lift.roles == (("holder", ("alice", "bob")), ("lifter", ("robot",))) and lift.needed == 2
    assert lift.agents == ("alice", "bob", "robot") and lift.crew_choice and task.has_crew_choice
    assert lift.crews == (("alice", "robot"), ("bob", "robot"))
    assert [lift.phase("hold").duration(a) for a in lift.agents] == [Interval(3, 5), Interval(3, 5), Interval(2, 4)]
    again = load_task(dump_task(task, tmp_path / "again.yaml") or tmp_path / "again.yaml")
    assert again == task  # the candidates' form round-trips


def test_agents_needed_k_of_n_is_every_k_subset_once(tmp_path: Path) -> None:
    task = copy.deepcopy(HAND)
    task["agents"].append({"id": "r2", "kind": "robot", "radius": 0.35, "speed": 0.5, "start": "B"})
    task["agents"][1]["start"] = "A"
    task["actions"][1] = {"id": "lift", "agents": ["alice", "robot", "r2"], "agents_needed": 2, "phases": [
        {"id": "hold", "location": "J", "duration": {"alice": [3, 5], "robot": [2, 4], "r2": [2, 3]}}]}
    loaded = load_task(_write(tmp_path, task))
    lift = loaded.action("lift")
    assert lift.needed == 2 and lift.crew_choice
    assert lift.crews == (("alice", "robot"), ("alice", "r2"), ("robot", "r2"))  # 3 = C(3, 2), none twice
    assert load_task(dump_task(loaded, tmp_path / "again.yaml") or tmp_path / "again.yaml") == loaded


def test_hand_worked_plans_and_crews(tmp_path: Path) -> None:
    task = load_task(_write(tmp_path, HAND))
    plans = list(generate_plans(task))
    assert len(plans) == 4 == count_plans(task) and allocation_count(task) == 4
    assert plan_count_bound(task) == 6  # without the precedence: a person doing both has 2 orders (2 + 1 + 1 + 2)
    got = {(p.agent_of("carry"), task.crew("lift", p)) for p in plans}
    assert got == {(c, (h, "robot")) for c in ("alice", "bob") for h in ("alice", "bob")}
    assert all(p.agent_of("lift") == "robot" == task.lead("lift", p) for p in plans)
    assert all(plan_from_code(task, plan_code(task, p)) == p for p in plans)
    with pytest.raises(KeyError):
        task.lead("lift")  # no one lead without a plan: the plan chooses the crew


def test_hand_worked_classes(hand_out: Path) -> None:
    task = load_task(hand_out / "input" / "task.yaml")
    seen = {}
    for p in iter_plans(hand_out):
        plan = next(q for q in generate_plans(task) if q.id == p["id"])
        seen[(plan.agent_of("carry"), task.crew("lift", plan)[0])] = p["class"]
    assert seen == HAND_CLASSES


def test_the_stnu_synchronises_over_the_crew_only(tmp_path: Path) -> None:
    """The crew {bob, robot}: the lift waits for bob's and the robot's arrivals, never alice's, and lasts as
    the holder's and lifter's roles (3-5 s, contingent)."""
    task = load_task(_write(tmp_path, HAND))
    plan = next(p for p in generate_plans(task) if task.crew("lift", p) == ("bob", "robot")
                and p.agent_of("carry") == "alice")
    cp = compile_plan(task, plan, plan_paths(task, seed=0))
    text = cp.graphml
    assert "alice_hold_lift" not in text and "bob_hold_lift_arrive" in text and "robot_hold_lift_start" in text
    assert "bob_hold_lift_start" not in text  # one start for the crew: its lead's


# ------------------------------------------------------------------------------------- task format errors

@pytest.mark.parametrize(("what", "change", "key"), [
    ("a candidate in two roles", lambda a: a["roles"].update(lifter={"agents": ["robot", "bob"]}),
     "actions[1].roles.lifter.agents[1]"),
    ("an unknown candidate", lambda a: a["roles"].update(holder={"agents": ["alice", "carol"]}),
     "actions[1].roles.holder.agents[1]"),
    ("no candidates", lambda a: a["roles"].update(holder={"agents": []}), "actions[1].roles.holder.agents"),
    ("a crew of people only", lambda a: a["roles"].update(lifter={"agents": ["robot", "bob"]},
                                                          holder="alice"), "actions[1].roles"),
    ("k of n without a robot in every crew", lambda a: (a.pop("roles"), a.update(
        agents=["alice", "bob", "robot"], agents_needed=2)), "actions[1].agents_needed"),
])
def test_bad_candidates_are_one_line_naming_the_key(tmp_path: Path, capsys, what: str, change, key: str) -> None:
    task = copy.deepcopy(HAND)
    change(task["actions"][1])
    assert main(["show", str(_write(tmp_path, task))]) == 2, what
    err = capsys.readouterr().err
    assert ERROR_LINE.match(err) and f"{key}:" in err, err


# -------------------------------------------------------------------------------- brute force (hypothesis)

PEOPLE, ROBOTS = ("p1", "p2"), ("r1", "r2")


@st.composite
def small_tasks(draw) -> Task:
    """2 people and 1-2 robots; 2-4 one-phase actions, some joint (named roles with candidates, or any k
    of n), some precedence (acyclic by index)."""
    robots = ROBOTS[:draw(st.integers(1, 2))]
    agents = tuple(Agent(a, AgentKind.HUMAN, 0.3, 1.0, "H") for a in PEOPLE) + tuple(
        Agent(r, AgentKind.ROBOT, 0.35, 0.5, "S") for r in robots)
    ids = tuple(a.id for a in agents)
    actions = []
    for i in range(draw(st.integers(2, 4))):
        kind = draw(st.sampled_from(["one", "roles", "k_of_n"]))
        loc = draw(st.sampled_from(["A", "J"]))
        if kind == "roles":
            robot_cands = draw(st.lists(st.sampled_from(robots), min_size=1, max_size=len(robots), unique=True))
            people_cands = draw(st.lists(st.sampled_from(PEOPLE), min_size=1, max_size=2, unique=True))
            roles = (("h", tuple(a for a in ids if a in people_cands)),
                     ("r", tuple(a for a in ids if a in robot_cands)))
            who = tuple(a for a in ids if a in people_cands or a in robot_cands)
            actions.append(Action(f"j{i}", f"j{i}", who, (Phase("p", loc, tuple((a, Interval(1, 2)) for a in who)),),
                                  roles=roles, needed=2))
        elif kind == "k_of_n" and len(robots) == 2:
            who = ids  # 4 agents, any 3 of them: every crew holds a robot (2 people only)
            actions.append(Action(f"j{i}", f"j{i}", who, (Phase("p", loc, tuple((a, Interval(1, 2)) for a in who)),),
                                  roles=tuple((a, (a,)) for a in who), needed=3))
        else:
            chosen = draw(st.lists(st.sampled_from(ids), min_size=1, unique=True))  # once, not once per agent
            who = tuple(a for a in ids if a in chosen)
            actions.append(Action(f"a{i}", f"a{i}", who, (Phase("p", loc, tuple((a, Interval(1, 2)) for a in who)),)))
    precedence = tuple(Precedence(PhaseRef(actions[i].id, "p"), PhaseRef(actions[j].id, "p"))
                       for i, j in itertools.combinations(range(len(actions)), 2) if draw(st.booleans()))
    from hrc.model import Location, Workspace
    ws = Workspace("bare", (0, 0, 10, 4), (), tuple(Location(k, x, y) for k, (x, y) in BARE_MAP["locations"].items()))
    return Task("random", agents, tuple(actions), precedence, (), None, (), "map.yaml", ws)


def _crews_by_hand(task: Task, action: Action) -> list[frozenset[str]]:
    """Every set of agents that may do `action`: for a joint one, each subset of its agents of the crew's
    size that fills as many roles, one agent per role; else each one agent."""
    if not action.roles:
        return [frozenset([a]) for a in action.agents]
    out = []
    for subset in itertools.combinations(action.agents, action.needed):
        filled = [r for r, cands in action.roles if any(a in cands for a in subset)]
        per_role = all(sum(a in cands for a in subset) <= 1 for _, cands in action.roles)
        if len(filled) == action.needed and per_role:
            out.append(frozenset(subset))
    return out


def _plans_by_hand(task: Task) -> set[tuple[tuple[str, tuple[str, ...]], ...]]:
    """Every (sequences) of a valid plan: each action to one of its crews, every order of each agent's
    actions, the phase graph (phases in order, each agent's sequence, the task graph) acyclic."""
    out = set()
    for crews in itertools.product(*(_crews_by_hand(task, a) for a in task.actions)):
        mine = {ag.id: [a.id for a, c in zip(task.actions, crews, strict=True) if ag.id in c] for ag in task.agents}
        for orders in itertools.product(*(itertools.permutations(mine[ag.id]) for ag in task.agents)):
            g = nx.DiGraph()
            g.add_nodes_from(f"{a.id}.p" for a in task.actions)
            g.add_edges_from((str(p.before), str(p.after)) for p in task.precedence)
            for seq in orders:
                g.add_edges_from((f"{x}.p", f"{y}.p") for x, y in itertools.pairwise(seq))
            if nx.is_directed_acyclic_graph(g):
                out.add(tuple((ag.id, tuple(seq)) for ag, seq in zip(task.agents, orders, strict=True)))
    return out


@settings(max_examples=60, deadline=None)
@given(small_tasks())
def test_plans_and_their_count_match_a_brute_force(task: Task) -> None:
    plans = list(generate_plans(task))
    assert len(plans) == len(set(plans))  # no crew counted twice
    assert {p.sequences for p in plans} == _plans_by_hand(task)
    assert count_plans(task) == len(plans) <= plan_count_bound(task)
    for p in plans:
        assert plan_from_code(task, plan_code(task, p)) == p
        for a in task.actions:
            if a.roles:
                crew = task.crew(a.id, p)
                assert frozenset(crew) in _crews_by_hand(task, a)
                assert p.agent_of(a.id) == next(x for x in crew if x in ROBOTS) == task.lead(a.id, p)


# ------------------------------------------------------------------------------------------- CSTNU Tool

def test_the_tool_agrees_on_the_hand_worked_case(cstnu_tool: Path, hand_out: Path) -> None:
    classes = _compiled_classes(hand_out)
    assert len(classes) == 4
    assert _agree(cstnu_tool, classes) == {"DC": 2, "NOT_DC": 2}


@pytest.mark.slow
def test_the_tool_agrees_on_every_two_workers_joint_stnu(cstnu_tool: Path, tmp_path: Path) -> None:
    out = tmp_path / "twj"
    assert main(["compile", str(ROOT / "tasks" / "two_workers_joint.yaml"), "--out", str(out), "--no-report",
                 "-q"]) == 0
    classes = _compiled_classes(out)
    assert len(classes) == 240
    counts = _agree(cstnu_tool, classes)
    assert counts["DC"] and counts["NOT_DC"]


# ------------------------------------------------------------------------------- the online parts

def test_dispatch_follows_the_crew(hand_out: Path) -> None:
    """JSON lines: bob arriving at the lift keeps only the plans whose crew is bob's, and the robot waits
    for bob's arrival (the crew's), not alice's."""
    from hrc.dispatch import Dispatcher
    from hrc.dispatch.messages import Observation, WaitFor

    d = Dispatcher.from_folder(hand_out)
    dec = d.observe(Observation(0.5, "depart", "alice", "carry", "put"))
    assert sum(dec.candidates.values()) == 2  # carry alice: the crews {alice, robot} and {bob, robot}
    dec = d.observe(Observation(0.6, "depart", "bob", "lift", "hold"))
    assert dict(dec.candidates) == {"DC": 1, "consistent": 0, "inconsistent": 0}  # bob's crew alone
    d.observe(Observation(1.0, "depart", "robot", "lift", "hold"))
    dec = d.observe(Observation(4.0, "arrive", "robot", "lift", "hold"))
    assert isinstance(dec.robot, WaitFor) and (dec.robot.agent, dec.robot.event) == ("bob", "arrive")


def test_best_per_allocation_tells_crews_apart(tmp_path: Path) -> None:
    """The hand case's 4 plans are 4 allocations (the crew is part of one), though only 2 differ in
    `Plan.allocation`'s names (the lift's lead is the robot in all): --best-per-allocation 1 keeps all 4."""
    out = tmp_path / "out"
    assert main(["compile", str(_write(tmp_path, HAND)), "--out", str(out), "--no-report", "-q",
                 "--best-per-allocation", "1"]) == 0
    assert len(list(iter_plans(out))) == 4


def test_show_plan_names_every_agent_of_the_crew(hand_out: Path, capsys) -> None:
    """`hrc show OUT --plan ID`: the allocation line lists a joint action under every agent of the plan's
    crew (marked joint), not under its lead alone; read against the plan's own crew."""
    task = load_task(hand_out / "input" / "task.yaml")
    for p in iter_plans(hand_out):
        plan = next(q for q in generate_plans(task) if q.id == p["id"])
        assert main(["show", str(hand_out), "--plan", p["id"]]) == 0
        line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("  allocation: "))
        parts = dict(part.split(": ", 1) for part in line.removeprefix("  allocation: ").split("; "))
        crew = task.crew("lift", plan)
        assert {a for a, acts in parts.items() if "lift (joint)" in acts.split(", ")} == set(crew)
        assert [a for a, acts in parts.items() if "carry" in acts.split(", ")] == [plan.agent_of("carry")]
