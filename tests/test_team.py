"""Issue 37, the offline half: any number of people and robots, from the task file through compile.

Plan generation against a brute-force oracle of its own on random tasks of one to four agents (joint
actions included); a hand-worked robot-robot passing order (two robots whose straight drives cross) with
its gap, its classes and a continuous check of the discs on the compiled schedule; the bundled team
tasks; the online commands' one-line refusal.
"""

from __future__ import annotations

import itertools
import json
import math
import re
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
import yaml
from conftest import ROOT
from hypothesis import given, settings
from hypothesis import strategies as st

from hrc.cli import main
from hrc.compile.classify import PlanClass
from hrc.compile.compiler import compile_plan
from hrc.compile.motion_pattern import pattern_network
from hrc.io.task_file import load_task
from hrc.model import Action, Agent, AgentKind, Interval, Location, Phase, PhaseRef, Plan, Precedence, Task, Workspace
from hrc.motion import find_conflicts, plan_paths
from hrc.motion.conflicts import floor_pairs, people_meetings
from hrc.plans import count_plans, generate_plans, plan_code, plan_count_bound, plan_from_code

ERROR_LINE = re.compile(r"^error: [^\n]+: [^\n]+\n$")


# ------------------------------------------------------------------------------ plans, by brute force
def _acyclic(nodes: list[str], edges: list[tuple[str, str]]) -> bool:
    """Kahn's algorithm (not networkx, which the generator uses)."""
    succ: dict[str, list[str]] = {n: [] for n in nodes}
    indeg = dict.fromkeys(nodes, 0)
    for u, v in edges:
        succ[u].append(v)
        indeg[v] += 1
    ready = [n for n, d in indeg.items() if d == 0]
    seen = 0
    while ready:
        n = ready.pop()
        seen += 1
        for m in succ[n]:
            indeg[m] -= 1
            if indeg[m] == 0:
                ready.append(m)
    return seen == len(nodes)


def oracle(task: Task) -> set[Plan]:
    """Every allocation (a joint action to the first robot of it, its lead by the task format) times every
    order of each agent's actions (a joint action in the order of every agent of it), kept when the phase
    graph (phases in order, each agent's order, precedence) is acyclic: the orders then agree on the joint
    actions."""
    nodes = [f"{a.id}.{p.id}" for a in task.actions for p in a.phases]
    base = [(f"{a.id}.{p.id}", f"{a.id}.{q.id}") for a in task.actions for p, q in itertools.pairwise(a.phases)]
    base += [(str(pr.before), str(pr.after)) for pr in task.precedence]
    first = {a.id: f"{a.id}.{a.phases[0].id}" for a in task.actions}
    last = {a.id: f"{a.id}.{a.phases[-1].id}" for a in task.actions}
    robots = [ag.id for ag in task.agents if not ag.is_human]
    choices = [[next(r for r in robots if r in a.agents)] if a.joint else list(a.agents) for a in task.actions]
    out = set()
    for combo in itertools.product(*choices):
        allocation = tuple(zip(task.action_ids, combo, strict=True))
        mine = [tuple(a.id for a, who in zip(task.actions, combo, strict=True)
                      if who == ag or (a.joint and ag in a.agents)) for ag in task.agent_ids]
        for perms in itertools.product(*(itertools.permutations(m) for m in mine)):
            edges = base + [(last[a], first[b]) for seq in perms for a, b in itertools.pairwise(seq)]
            if _acyclic(nodes, edges):
                out.add(Plan(allocation, tuple(zip(task.agent_ids, perms, strict=True))))
    return out


WS = Workspace(name="empty", bounds=(0, 0, 10, 10), obstacles=(), locations=(Location("L", 5, 5),))


@st.composite
def team_tasks(draw: Any) -> Task:
    """One to four agents of random kinds; up to four actions, each by a random non-empty set of them or
    (when there is a robot) a joint action of two or more including one; random forward precedence."""
    kinds = draw(st.lists(st.sampled_from([AgentKind.HUMAN, AgentKind.ROBOT]), min_size=1, max_size=4))
    agents = [Agent(f"{k.value}{i}", k, 0.3, 1.0, "L") for i, k in enumerate(kinds)]
    ids = [a.id for a in agents]
    robots = [a.id for a in agents if not a.is_human]
    n = draw(st.integers(1, 4))
    actions = []
    for i in range(n):
        n_phases = draw(st.integers(1, 2))
        if robots and len(agents) > 1 and draw(st.integers(0, 3)) == 0:
            lead = draw(st.sampled_from(robots))
            others = draw(st.lists(st.sampled_from([x for x in ids if x != lead]), min_size=1, unique=True))
            who = tuple(x for x in ids if x == lead or x in others)  # task order
            roles = tuple((f"role_{x}", x) for x in who)
        else:
            who = tuple(draw(st.lists(st.sampled_from(ids), min_size=1, unique=True)))
            roles = ()
        phases = tuple(Phase(f"p{j}", "L", tuple((x, Interval(1, 2)) for x in who)) for j in range(n_phases))
        actions.append(Action(f"a{i}", f"a{i}", who, phases, roles))
    refs = [PhaseRef(a.id, p.id) for a in actions for p in a.phases]
    pairs = [(x, y) for x, y in itertools.combinations(refs, 2) if x.action != y.action]
    chosen = draw(st.lists(st.sampled_from(pairs), unique=True, max_size=4)) if pairs else []
    return Task(name="team", agents=tuple(agents), actions=tuple(actions),
                precedence=tuple(Precedence(b, a) for b, a in chosen), constraints=(), deadline=None,
                preferences=(), map_path="none.yaml", workspace=WS)


@settings(max_examples=150, deadline=None)
@given(team_tasks())
def test_plans_of_any_team_match_the_brute_force_oracle(task: Task) -> None:
    expected = oracle(task)
    streamed = list(generate_plans(task))
    assert len(streamed) == len(set(streamed)) and set(streamed) == expected
    assert count_plans(task) == len(expected) <= plan_count_bound(task)
    if not task.precedence:
        assert plan_count_bound(task) == len(expected) or task.has_joint
    for plan in streamed[:20]:
        assert plan_from_code(task, plan_code(task, plan)) == plan


def test_three_agents_with_independent_actions_by_hand() -> None:
    """Two actions, three agents who may each do both, no precedence: an action to each of two agents
    (3 x 2 = 6 allocations, one order each) or both to one agent (3 allocations, 2 orders each): 12."""
    agents = tuple(Agent(x, k, 0.3, 1.0, "L") for x, k in (("h", AgentKind.HUMAN), ("r1", AgentKind.ROBOT),
                                                          ("r2", AgentKind.ROBOT)))
    acts = tuple(Action(a, a, ("h", "r1", "r2"), (Phase("p", "L", tuple((x, Interval(1, 2)) for x in
                                                                        ("h", "r1", "r2"))),)) for a in ("x", "y"))
    task = Task("three", agents, acts, (), (), None, (), "none.yaml", WS)
    assert count_plans(task) == len(list(generate_plans(task))) == plan_count_bound(task) == 12


# ------------------------------------------------------------------ the robot-robot passing order by hand
CROSS_MAP: dict[str, Any] = {
    "name": "cross", "bounds": [0, 0, 12, 10],
    "obstacles": [{"id": "sw", "rect": [0, 0, 4.4, 4.4]}, {"id": "se", "rect": [5.6, 0, 10, 4.4]},
                  {"id": "nw", "rect": [0, 5.6, 4.4, 10]}, {"id": "ne", "rect": [5.6, 5.6, 10, 10]}],
    "locations": {"W": [1, 5], "E": [9, 5], "S": [5, 1], "N": [5, 9], "H": [11, 1], "T": [11, 2.5]}}
"""Two corridors 1.2 m wide crossing at (5, 5): r1 drives W -> E along y = 5, r2 drives S -> N along
x = 5, 8 m each at 1 m/s, their routes crossing 4 m along each (no way round: the walls leave none). The
person walks H -> T in the strip east of the walls, far from both."""

CROSS: dict[str, Any] = {
    "name": "cross", "map": "map.yaml", "safety_margin": 0.1, "deadline": 10.5,
    "agents": [{"id": "human", "kind": "human", "radius": 0.3, "speed": 1.2, "start": "H"},
               {"id": "r1", "kind": "robot", "radius": 0.35, "speed": 1.0, "start": "W"},
               {"id": "r2", "kind": "robot", "radius": 0.35, "speed": 1.0, "start": "S"}],
    "actions": [{"id": "east", "agents": ["r1"], "phases": [{"id": "go", "location": "E", "duration": {"r1": [1, 1]}}]},
                {"id": "north", "agents": ["r2"], "phases": [{"id": "go", "location": "N",
                                                             "duration": {"r2": [1, 1]}}]},
                {"id": "tidy", "agents": ["human"], "phases": [{"id": "do", "location": "T",
                                                               "duration": {"human": [1, 2]}}]}],
}
REACH = 0.35 + 0.35 + 0.1  # the two robots' radii and the margin: no protective separation between robots


def write_task(tmp: Path, task: dict[str, Any], map_: dict[str, Any]) -> Path:
    (tmp / "map.yaml").write_text(yaml.safe_dump(map_, sort_keys=False), "utf-8")
    path = tmp / "task.yaml"
    path.write_text(yaml.safe_dump(task, sort_keys=False), "utf-8")
    return path


@pytest.fixture(scope="module")
def cross(tmp_path_factory: pytest.TempPathFactory) -> Task:
    return load_task(write_task(tmp_path_factory.mktemp("cross"), CROSS, CROSS_MAP))


def _position(start: tuple[float, float], end: tuple[float, float], depart: float, t: float) -> tuple[float, float]:
    """Where a robot driving the straight line `start` -> `end` at 1 m/s, leaving at `depart`, is at `t`."""
    length = math.dist(start, end)
    s = min(max(t - depart, 0.0), length) / length
    return (start[0] + s * (end[0] - start[0]), start[1] + s * (end[1] - start[1]))


def test_two_robots_crossing_by_hand(cross: Task) -> None:
    """The one conflict of the two robots: their drives within 0.8 m of each other, the disc of radius 0.8
    round (4, 4) in arc lengths (s along r1's, u along r2's). r1 first needs r2 to leave at least
    ``max(s - u) = 0.8 sqrt 2`` s after r1 (a few cm more: the sampled routes, `STEP`); r2 first the same
    the other way, ``T(r1 depart) - T(r2 arrive) >= max(u - s) - 8``. Without it both would be at (5, 5)
    at 4 s. With it the best makespan is 9 s (8 s drive, 1 s step) plus the gap: about 10.13 s."""
    assert [(r.id, o.id) for r, o in floor_pairs(cross)] == [("r1", "human"), ("r2", "human"), ("r1", "r2")]
    (plan,) = list(generate_plans(cross))
    paths = plan_paths(cross, seed=0)
    assert paths.get("r1", "W", "E").length == pytest.approx(8.0, abs=1e-9)
    conflicts = find_conflicts(cross, plan, paths)
    assert [(c.robot.agent, c.human.agent, c.robot.kind, c.human.kind) for c in conflicts] == [
        ("r1", "r2", "travel", "travel")]
    (c,) = conflicts
    low = REACH * math.sqrt(2)
    assert c.robot_first.earlier.agent == "r1" and c.robot_first.later.agent == "r2"
    assert (c.robot_first.earlier.what, c.robot_first.later.what) == ("depart", "depart")
    assert low <= c.robot_first.gap <= low + 0.06
    assert (c.human_first.earlier.what, c.human_first.later.what) == ("arrive", "depart")
    assert low - 8 <= c.human_first.gap <= low - 8 + 0.06
    assert c.point[0] == pytest.approx(5, abs=0.9) and c.point[1] == pytest.approx(5, abs=1e-9)
    cp = compile_plan(cross, plan, paths)
    assert cp.plan_class is PlanClass.DC  # robots only but for the person's walk and tidy, far away
    (order,) = cp.pattern.orders
    assert order.how == "chosen" and order.first in ("robot", "human") and not cp.pattern.detours
    assert 9 + low <= cp.classification.makespan[0] <= 9 + low + 0.07
    # the STNU carries the chosen order as a requirement link between the two robots' departures or
    # arrival and departure; no link of a robot is contingent
    net = pattern_network(cross, plan, cp.pattern)
    sep = order.separation
    assert any(r.lb == math.ceil(sep.gap * 1000 - 1e-9) and r.ub is None and r.source.startswith(sep.earlier.agent)
               and r.target.startswith(sep.later.agent) for r in net.stnu.requirements)
    assert all(c_.source.startswith("human.") for c_ in net.stnu.contingents)
    # a continuous check on the earliest schedule: the discs are never closer than the reach
    times = dict(cp.classification.schedule)
    d1, d2 = times["r1.go.east.depart"], times["r2.go.north.depart"]
    closest = min(math.dist(_position((1, 5), (9, 5), d1, t / 100), _position((5, 1), (5, 9), d2, t / 100))
                  for t in range(0, 1300))
    assert closest >= REACH - 1e-6
    assert min(math.dist(_position((1, 5), (9, 5), 0, t / 100), _position((5, 1), (5, 9), 0, t / 100))
               for t in range(0, 1300)) == 0  # leaving together, they would meet at (5, 5)


def test_two_robots_crossing_classes_by_deadline(tmp_path: Path) -> None:
    """The same plan under three deadlines: 10.5 s (room for the gap: DC), 10 s (one robot must wait
    0.8 sqrt 2 = 1.13 s for the other, 10.13 s at best: inconsistent) and 9.5 s (still inconsistent)."""
    classes = {}
    for deadline in (10.5, 10, 9.5):
        task = load_task(write_task(tmp_path, CROSS | {"deadline": deadline}, CROSS_MAP))
        (plan,) = list(generate_plans(task))
        classes[deadline] = compile_plan(task, plan, plan_paths(task, seed=0)).plan_class
    assert classes == {10.5: PlanClass.DC, 10: PlanClass.INCONSISTENT, 9.5: PlanClass.INCONSISTENT}


def test_the_robot_person_pair_is_as_before_and_two_people_are_only_reported(cross: Task) -> None:
    """A person in the place of r2: the one pair is a robot and a person (the protective separation would
    apply there); two people crossing are a meeting reported (`people_meetings`), never a conflict."""
    agents = (replace(cross.agents[0], start="S", speed=1.0), cross.agents[1],
              replace(cross.agents[0], id="pat", start="W"))
    actions = (replace(cross.actions[1], agents=("human",), phases=(Phase("go", "N", (("human", Interval(1, 1)),)),)),
               replace(cross.actions[0], agents=("pat",), phases=(Phase("go", "E", (("pat", Interval(1, 1)),)),)))
    people = replace(cross, agents=agents, actions=actions, deadline=None)
    (plan,) = list(generate_plans(people))
    paths = plan_paths(people, seed=0)
    assert find_conflicts(people, plan, paths) == ()  # r1 does nothing; the two people are left to themselves
    met = people_meetings(people, plan, paths)
    assert [(m.robot.agent, m.human.agent, m.robot.kind, m.human.kind) for m in met] == [
        ("human", "pat", "travel", "travel")]
    cp = compile_plan(people, plan, paths)
    assert cp.pattern.meetings == met and cp.pattern.orders == ()


def test_a_joint_action_of_two_robots_and_a_person(tmp_path: Path) -> None:
    """tests/test_joint.py's lift (J 4 m from the person, who walks 1 m/s, and from the robot, which drives
    0.5 m/s) with a second robot r2 steadying it, from B (9, 3.5), 4.27 m away: one start and one end for
    all three, the phase contingent (a person takes part: the roles' maxima, 3-5 s). Co-work at the spot
    is per pair (`_coworking`): every robot's drive in keeps its separation from whoever already stands
    there, so the first robot in task order arrives first, then r2, then the person, each order forced."""
    from test_joint import LIFT, _write

    raw = LIFT | {"agents": [*LIFT["agents"], {"id": "r2", "kind": "robot", "radius": 0.35, "speed": 0.5,
                                               "start": "B"}]}
    lift = dict(LIFT["actions"][0], roles={**LIFT["actions"][0]["roles"], "steady": "r2"})
    lift["phases"] = [dict(lift["phases"][0], duration={**lift["phases"][0]["duration"], "steady": [2, 3]})]
    task = load_task(_write(tmp_path, raw | {"actions": [lift]}))
    (plan,) = list(generate_plans(task))
    assert plan.sequences == (("human", ("lift",)), ("robot", ("lift",)), ("r2", ("lift",)))
    assert plan.allocation == (("lift", "robot"),)  # its lead: the first robot
    cp = compile_plan(task, plan, plan_paths(task, seed=0))
    assert cp.plan_class is PlanClass.DC
    orders = {(o.conflict.robot.agent, o.conflict.robot.kind, o.conflict.human.agent, o.conflict.human.kind): o
              for o in cp.pattern.orders}
    assert set(orders) == {("robot", "travel", "human", "travel"), ("robot", "travel", "human", "stay"),
                           ("r2", "travel", "human", "travel"), ("r2", "travel", "human", "stay"),
                           ("robot", "travel", "r2", "travel"), ("robot", "travel", "r2", "stay")}
    assert all(o.first == "robot" and o.how == "forced" for o in orders.values())
    net = pattern_network(task, plan, cp.pattern).stnu
    assert sorted((c.source, c.target, c.lb, c.ub) for c in net.contingents) == [
        ("human.hold.lift.depart", "human.hold.lift.arrive", 4000, 5000),
        ("robot.hold.lift.start", "robot.hold.lift.end", 3000, 5000)]
    times = dict(cp.classification.schedule)
    start = times["robot.hold.lift.start"]
    assert times["robot.hold.lift.arrive"] <= times["r2.hold.lift.arrive"] <= times["human.hold.lift.arrive"] <= start


# --------------------------------------------------------------------------- an independent referee
def _closest(task: Task, cp: Any, times: dict[str, float], a: str, b: str, pace: str, dt: float = 0.01) -> float:
    """The smallest distance between agents `a` and `b` over a dispatched run (every `dt` s), each moved
    along its routes as the run's times say (tests/referee.py's `trajectory`: no conflict model)."""
    from referee import trajectory

    pa = trajectory(task, cp.plan, cp.motions, times, a, pace)
    pb = trajectory(task, cp.plan, cp.motions, times, b, pace)
    best = math.inf
    for k in range(int(max(times.values()) / dt) + 2):
        x, y = pa(k * dt), pb(k * dt)
        if x is not None and y is not None:
            best = min(best, math.dist(x, y))
    return best


def test_two_robots_and_a_person_keep_apart_in_dispatched_runs() -> None:
    """kitting_2robots cut to three picks (60 plans): the DC plans in which both robots work, each
    dispatched by its STNU's real-time execution strategy (tests/referee.py: nature's durations at the
    bounds or random, the strategy's ticks early, late or random), every agent moved along its routes:
    every robot stays ``r_a + r_b + margin`` from every other agent at every instant (the person at an
    even pace, rushing or dawdling), and no task constraint is broken. Nothing here reads the passing
    orders or the conflict model."""
    import random

    from referee import broken_constraints, sampled_run

    from hrc.compile.compiler import compile_task
    from hrc.temporal.graphml import read_graphml

    full = load_task(ROOT / "tasks" / "kitting_2robots.yaml")
    task = replace(full, actions=full.actions[:3])
    cps = compile_task(task, seed=0, jobs=1)
    assert len(cps.plans) == 60  # 3! C(5, 2)
    both = [cp for cp in cps.plans if cp.plan_class is PlanClass.DC and cp.plan.sequence("robot")
            and cp.plan.sequence("robot2")]
    assert len(both) >= 6
    rng = random.Random(0)
    picks = [lambda e, hi: e, lambda e, hi: e if hi is None else hi,
             lambda e, hi: rng.randint(e, e + 3000 if hi is None else hi)]
    pairs = [(r.id, o.id, r.radius + o.radius + task.safety_margin) for r, o in floor_pairs(task)]
    robot_pairs = 0
    for cp in both[:6]:
        stnu = read_graphml(cp.graphml.encode())
        for run in range(3):
            times = sampled_run(stnu, rng, picks[run])
            assert broken_constraints(task, cp.plan, times) == [], cp.plan.id
            for a, b, reach in pairs:
                person = task.agent(b).is_human
                for pace in ("even", "rush", "dawdle") if person else ("even",):
                    d = _closest(task, cp, times, a, b, pace)
                    assert d >= reach - 1e-3, (cp.plan.id, a, b, pace, d)
                robot_pairs += not person
    assert robot_pairs == 18


# ------------------------------------------------------------------------------------ the bundled tasks
def test_the_team_tasks_load_and_count() -> None:
    k2 = load_task(ROOT / "tasks" / "kitting_2robots.yaml")
    assert [a.kind.value for a in k2.agents] == ["human", "robot", "robot"]
    assert count_plans(k2) == 2520  # 5 picks over 3 agents, no precedence: 5! * C(7, 2)
    tw = load_task(ROOT / "tasks" / "two_workers.yaml")
    assert [a.kind.value for a in tw.agents] == ["human", "human", "robot"]
    assert count_plans(tw) == len(list(generate_plans(tw))) == 120
    assert tw.lead("load") == "robot"


def test_a_team_task_round_trips(tmp_path: Path) -> None:
    import shutil

    from hrc.io.task_file import dump_task

    (tmp_path / "tasks").mkdir()
    (tmp_path / "maps").mkdir()
    shutil.copy(ROOT / "maps" / "kitting_cell.yaml", tmp_path / "maps")  # the tasks/ + maps/ layout
    for name in ("two_workers", "kitting_2robots"):
        shutil.copy(ROOT / "tasks" / f"{name}.yaml", tmp_path / "tasks")
        task = load_task(tmp_path / "tasks" / f"{name}.yaml")
        out = tmp_path / "tasks" / f"{name}-again.yaml"
        dump_task(task, out)
        assert load_task(out) == task


def test_two_workers_compiles_with_people_meetings_in_its_record_and_report(tmp_path: Path, capsys) -> None:
    out = tmp_path / "tw"
    assert main(["compile", str(ROOT / "tasks" / "two_workers.yaml"), "--out", str(out), "-q", "--stnu", "none"]) == 0
    import json

    data = json.loads((out / "compiled.json").read_text("utf-8"))
    assert data["counts"] == {"DC": 96, "consistent": 0, "inconsistent": 24}
    assert data["task"]["agents"] == {"alice": "human", "bob": "human", "robot": "robot"}
    plans = data["plans"]
    assert all("people_meet" in p for p in plans) and any(p["people_meet"] for p in plans)
    for p in plans:
        for o in p["passing"]:  # whose each occupancy is, for more than two agents
            assert o["robot"]["agent"] == "robot" and o["human"]["agent"] in ("alice", "bob")
        for m in p["people_meet"]:
            assert {m["first"]["agent"], m["second"]["agent"]} == {"alice", "bob"}
    report = (out / "report.md").read_text("utf-8")
    assert "**Where the people may meet**" in report and "- alice " in report
    best = plans[0]
    assert main(["show", str(out), "--plan", best["id"]]) == 0
    shown = capsys.readouterr().out
    assert f"where two people may meet ({len(best['people_meet'])}; left to them" in shown
    assert re.search(r"\n    robot first \((forced|chosen)\) at \([^)]*\): robot ", shown)  # names, not slots


def test_a_joint_action_of_people_alone_is_refused_in_one_line(tmp_path: Path, capsys) -> None:
    """Its start would be a person's event (contingent), which the net creator does not make yet: the
    loader refuses it, now that a task may have two people."""
    task = yaml.safe_load((ROOT / "tasks" / "two_workers.yaml").read_text("utf-8"))
    task["map"] = str(ROOT / "maps" / "kitting_cell.yaml")
    task["actions"][-1]["roles"] = {"lifter": "bob", "carrier": "alice"}
    path = tmp_path / "people.yaml"
    path.write_text(yaml.safe_dump(task, sort_keys=False), "utf-8")
    assert main(["show", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and ERROR_LINE.match(err), err
    assert "actions[4].roles: a joint action needs a robot among its agents" in err


# ------------------------------------------------------------------------------ the online side
# every online command serves a team: the console's and hrc ros2's motion detector too, one per person
# (tests/test_console_detect_team.py, tests/test_ros2_team.py)
def test_simulate_runs_a_team_with_buttons_and_with_the_motion_detector(tmp_path: Path, capsys) -> None:
    """`hrc simulate` takes a team (tests/test_sim_team.py), with the motion detector too (a detector per
    person: tests/test_detect_team.py, tests/test_sim_team.py)."""
    for n, option in enumerate(([], ["--detector", "motion"])):
        assert main(["simulate", str(ROOT / "tasks" / "two_workers.yaml"), "--runs", "1", "--policy", "hrc",
                     "--no-figures", "--out", str(tmp_path / f"sim{n}"), "-q", *option]) == 0
        doc = json.loads((tmp_path / f"sim{n}" / "simulation.json").read_text("utf-8"))
        run = doc["policies"]["hrc"]["runs"][0]
        assert run["finished"] and ("detection" in run) == bool(option)
    capsys.readouterr()
