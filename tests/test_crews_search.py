"""The search compile and compile on demand over crew choices (issue 37): which agents do a joint action is part
of a plan's allocation (`hrc.model.Action.crews`), so the search's tree branches over crews, its bounds hold
for every crew below a node, and plans compiled on demand keep the crew the dispatcher saw.

Truth here is independent of the code under test: the exhaustive compile (`compile_task`: every plan of
`hrc.plans.generate_plans`, itself checked against a brute force in tests/test_crews.py) and each plan's own
compiled `rank_key`. On small random crew tasks (hypothesis, the tasks tests/test_crews.py draws, with a
deadline drawn so that classes differ), the tree's leaves are exactly the canonical plans, each once, no
node's bound beats a plan below it, and a closed search's first K plans are the exhaustive compile's; on
tasks/two_workers_joint.yaml and the hand-worked case of tests/test_crews.py, ``hrc compile --plans best:K``
ranks as the exhaustive compile does. Compile on demand: the extension of a prefix in which bob is seen at
the joint action holds exactly the exhaustive plans that extend it (all with bob's crew), and a JSON-lines
run in which bob, not the compiled plans' holder, starts the joint action gets plans with bob's crew.
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import pytest
from conftest import ROOT
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_crews import HAND, HAND_CLASSES, _write, small_tasks

from hrc.cli import main
from hrc.compile.bounds import Node, NodeBounds
from hrc.compile.compiler import compile_plan, compile_task, rank_key
from hrc.compile.extend import Prefix, extend_plans
from hrc.compile.search import DIVE_NODES, _dive, _plan, compile_search
from hrc.dispatch.fallback import fallback_step
from hrc.dispatch.messages import Observation, RobotStep, WaitFor
from hrc.dispatch.validation import History
from hrc.io.task_file import load_task
from hrc.model import Interval, Phase, Plan, Task
from hrc.motion import plan_paths
from hrc.plans import count_plans, generate_plans, identical_actions, is_canonical

TWJ = ROOT / "tasks" / "two_workers_joint.yaml"


def _leaves(nb: NodeBounds, node, below: dict, path: list) -> None:  # noqa: ANN001
    """Every leaf under `node` (the whole tree, nothing pruned but cycles), with the nodes on its way."""
    if nb.is_leaf(node):
        assert node not in below  # one path per leaf
        below[node] = path
        return
    b = nb.bound(node)
    if b is None:
        return
    for child in nb.children(node, b.ends):
        _leaves(nb, child, below, [*path, node])


def _check_tree(task: Task, paths, most: int = 80) -> None:  # noqa: ANN001
    """The tree's leaves are the canonical plans (each once, the crew and lead the plan's), and every node's
    bound is at most the compiled key of each leaf below it (on `most` leaves spread over the tree)."""
    nb = NodeBounds(task, paths)
    below: dict = {}
    _leaves(nb, nb.root(), below, [])
    groups = identical_actions(task)
    canonical = sorted(p.id for p in generate_plans(task) if not groups or is_canonical(task, p, groups))
    found = [_plan(task, leaf) for leaf in below]
    assert sorted(p.id for p in found) == canonical
    plans = {p.id: p for p in generate_plans(task)}
    for plan in found:
        assert plan == plans[plan.id]  # the allocation too: a joint action's lead is its crew's first robot
    items = list(below.items())
    for leaf, path in items[::max(1, len(items) // most)]:
        key = rank_key(compile_plan(task, _plan(task, leaf), paths, graphml=False))[:4]
        for node in [*path, leaf]:
            b = nb.bound(node)
            assert b is not None and b.key <= key, (node, b, key)


@st.composite
def crew_tasks(draw) -> Task:  # noqa: ANN001
    """tests/test_crews.py's small crew tasks, with a deadline (or none) so that the classes differ (and every
    action with an agent: that strategy may draw one with none, which no task file can hold)."""
    task = draw(small_tasks().filter(lambda t: all(a.agents for a in t.actions)))
    if draw(st.booleans()):  # each agent's own durations (a crew's phase lasts as its slowest role)
        def drawn(phase: Phase) -> Phase:
            lbs = [draw(st.integers(1, 4)) for _ in phase.durations]
            return replace(phase, durations=tuple((ag, Interval(lb, lb + draw(st.integers(0, 3))))
                                                  for (ag, _), lb in zip(phase.durations, lbs, strict=True)))
        task = replace(task, actions=tuple(replace(a, phases=tuple(drawn(p) for p in a.phases)) for a in task.actions))
    return replace(task, deadline=draw(st.sampled_from([None, 9.0, 14.0, 20.0])))


@st.composite
def twin_tasks(draw) -> Task:  # noqa: ANN001
    """`crew_tasks` with a twin of one of its joint actions with a crew choice (the same shape, another id) and
    no precedence: identical actions (`hrc.plans.identical_actions`) whose crews are chosen."""
    task = draw(crew_tasks().filter(lambda t: t.has_crew_choice))
    twin = replace(draw(st.sampled_from([a for a in task.actions if a.crew_choice])), id="twin", name="twin")
    return replace(task, actions=(*task.actions, twin), precedence=())


@settings(max_examples=25, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(crew_tasks())
def test_the_tree_is_the_plan_set_and_its_bounds_hold_on_random_crew_tasks(task: Task) -> None:
    _check_tree(task, plan_paths(task, seed=0))


@settings(max_examples=15, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(twin_tasks().filter(lambda t: count_plans(t) <= 1500))  # 4 agents, 5 actions, no precedence: 30,000 plans
def test_the_tree_holds_each_family_once_with_identical_crew_choices(task: Task) -> None:
    assert any(task.action(g[0]).crew_choice for g in identical_actions(task))
    _check_tree(task, plan_paths(task, seed=0), most=20)


@settings(max_examples=12, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(crew_tasks(), st.integers(1, 4))
def test_a_closed_search_ranks_as_the_exhaustive_compile_on_random_crew_tasks(task: Task, k: int) -> None:
    if count_plans(task) > 400:
        return  # the exhaustive compile would take too long here (the tree test covers such tasks)
    paths = plan_paths(task, seed=0)
    exhaustive = compile_task(task, seed=0, jobs=1)
    with tempfile.TemporaryDirectory() as tmp:
        result = compile_search(task, Path(tmp) / "out", k, families=10**6, cover=0, paths=paths)
        head = json.loads((Path(tmp) / "out" / "compiled.json").read_text("utf-8"))
    assert result.outcome.closed
    want = exhaustive.plans[:k]
    assert [p["id"] for p in head["plans"]][:k] == [cp.plan.id for cp in want]
    assert [p["class"] for p in head["plans"]][:k] == [cp.plan_class.value for cp in want]


def test_a_quick_and_a_slow_holder_by_hand() -> None:
    """By hand, on the bare floor: one joint action at J, held by p1 (1 s) or p2 (9 s), lifted by the robot
    (1 s); both people start at H (4 m from J, 1 m/s, their walks up to x1.25), the robot at S (1.5 m, 0.5 m/s:
    3 s). Crew p1: starts when p1 is there, 4-5 s, lasts 1 s: worst case 6 s. Crew p2: 14 s. Before the crew is
    chosen, the bound may not take the slow holder's 9 s (the root's bound is at most 6 s), and the search's
    best is p1's crew."""
    from hrc.model import Action, Agent, AgentKind, Location, Workspace

    places = {"H": (1, 2), "S": (5, 0.5), "J": (5, 2)}
    ws = Workspace("bare", (0, 0, 10, 4), (), tuple(Location(k, x, y) for k, (x, y) in places.items()))
    agents = (Agent("p1", AgentKind.HUMAN, 0.3, 1.0, "H"), Agent("p2", AgentKind.HUMAN, 0.3, 1.0, "H"),
              Agent("r1", AgentKind.ROBOT, 0.35, 0.5, "S"))
    lift = Action("j", "j", ("p1", "p2", "r1"), (Phase("p", "J", (("p1", Interval(1, 1)), ("p2", Interval(9, 9)),
                                                                  ("r1", Interval(1, 1)))),),
                  roles=(("h", ("p1", "p2")), ("r", ("r1",))), needed=2)
    task = Task("quick_and_slow", agents, (lift,), (), (), None, (), "map.yaml", ws)
    paths = plan_paths(task, seed=0)
    nb = NodeBounds(task, paths)
    root = nb.bound(nb.root())
    assert root is not None and root.key[3] <= 6.0
    keys = {task.crew("j", p): rank_key(compile_plan(task, p, paths, graphml=False)) for p in generate_plans(task)}
    assert keys[("p1", "r1")][3] == pytest.approx(6.0, abs=0.01)
    assert keys[("p2", "r1")][3] == pytest.approx(14.0, abs=0.01)
    _check_tree(task, paths)
    with tempfile.TemporaryDirectory() as tmp:
        result = compile_search(task, Path(tmp) / "out", 1, families=10**6, cover=0, paths=paths)
    assert result.outcome.closed and result.plan_set.plans[0].plan.sequence("p1") == ("j",)


@pytest.mark.parametrize("k", [1, 5, 10, 20])
def test_two_workers_joint_best_k_is_the_exhaustive_top_k(tmp_path: Path, k: int) -> None:
    exhaustive = tmp_path / "all"
    assert main(["compile", str(TWJ), "--out", str(exhaustive), "--no-report", "-q"]) == 0
    out = tmp_path / "best"
    budget = ["--search-budget", "1000"] if k != 10 else []  # enough to close (the default budget does at 10)
    assert main(["compile", str(TWJ), "--out", str(out), "--no-report", "-q", "--plans", f"best:{k}", *budget]) == 0
    every = json.loads((exhaustive / "compiled.json").read_text("utf-8"))["plans"]
    head = json.loads((out / "compiled.json").read_text("utf-8"))
    assert len(every) == 240 and head["search"]["closed"]
    assert head["search"]["plans_compiled"] < len(every)
    top = [(p["id"], p["class"], p["makespan"]) for p in every[:k]]
    assert [(p["id"], p["class"], p["makespan"]) for p in head["plans"][:k]] == top
    crews = {tuple(sorted(a for a, seq in p["sequences"].items() if "load" in seq)) for p in head["plans"]}
    assert crews == {("alice", "robot"), ("bob", "robot")}  # both crews searched (the coverage dives too)


def test_the_hand_worked_case_searched(tmp_path: Path) -> None:
    """tests/test_crews.py's hand-worked case: its two DC plans (carry by alice, either crew) are the best two,
    and the search's classes are the hand-worked ones."""
    task_file = _write(tmp_path, HAND)
    out = tmp_path / "out"
    assert main(["compile", str(task_file), "--out", str(out), "--no-report", "-q", "--plans", "best:2"]) == 0
    head = json.loads((out / "compiled.json").read_text("utf-8"))
    task = load_task(task_file)
    plans = {p.id: p for p in generate_plans(task)}
    seen = {(plans[p["id"]].agent_of("carry"), task.crew("lift", plans[p["id"]])[0]): p["class"]
            for p in head["plans"]}
    assert all(HAND_CLASSES[who] == cls for who, cls in seen.items())
    best = {(plans[p["id"]].agent_of("carry"), task.crew("lift", plans[p["id"]])[0]) for p in head["plans"][:2]}
    assert best == {("alice", "alice"), ("alice", "bob")} and head["search"]["closed"]


def test_coverage_dives_take_a_joint_action_with_the_persons_crew(tmp_path: Path) -> None:
    """By hand (tests/test_crews.py's case): either person may start with the lift, in its crew, when the
    other carries (carry must precede the lift, so whoever lifts first carries nothing); or with the carry."""
    task = load_task(_write(tmp_path, HAND))
    nb = NodeBounds(task, plan_paths(task, seed=0))
    for person in ("alice", "bob"):
        h = task.agent_ids.index(person)
        for i, action in enumerate(task.action_ids):
            leaf = _dive(task, nb, h, (i,), DIVE_NODES)
            assert isinstance(leaf, Node), (person, action)
            plan = _plan(task, leaf)
            assert plan.sequence(person)[0] == action
            if action == "lift":
                assert task.crew("lift", plan) == (person, "robot") and plan.sequence(person) == ("lift",)
                assert plan.agent_of("carry") != person


# -------------------------------------------------------------------------------------- compile on demand

@pytest.fixture(scope="module")
def twj():
    task = load_task(TWJ)
    return task, plan_paths(task, seed=0)


@pytest.mark.parametrize("seen", [{"bob": ("load",)}, {"bob": ("pick_d", "load"), "alice": ("pick_a",)},
                                  {"alice": ("inspect", "load")},
                                  {"alice": ("pick_a", "inspect"), "bob": ("pick_d", "load"), "robot": ("pick_e",)}])
def test_an_extension_keeps_the_crew_seen(twj, seen: dict[str, tuple[str, ...]]) -> None:
    """The extension of a prefix with a person seen at the joint action: exactly the plans of the exhaustive
    plan set that extend it (so all with that person in the crew), best first."""
    task, paths = twj
    prefix = Prefix(tuple((a, seen.get(a, ())) for a in task.agent_ids))
    ext = extend_plans(task, paths, prefix, k=300, families=300)
    want = {p.id for p in generate_plans(task) if all(p.sequence(a)[:len(s)] == s for a, s in seen.items())}
    assert want and {cp.plan.id for cp in ext.plans} == want
    (who,) = [a for a, s in seen.items() if "load" in s]
    assert all(task.crew("load", cp.plan) == (who, "robot") for cp in ext.plans)
    keys = [rank_key(cp) for cp in ext.plans]
    assert keys == sorted(keys)
    # within the dispatcher's budget, no family is spent on a crew that leaves the person seen out
    ext = extend_plans(task, paths, prefix)
    assert ext.plans and ext.outcome.found == len(ext.plans)


def test_the_fallback_starts_a_joint_action_only_with_a_whole_crew(twj) -> None:
    """Off every plan (no plan to say the crew), the robot at the joint action: held with no step while it is
    there alone (either person may join it), then waiting for bob once bob set out for it, then the start."""
    task, _ = twj
    h = History.start(task)
    t = 0.0
    for agent, action, phase in (("alice", "pick_a", "fetch"), ("alice", "pick_a", "place"),
                                 ("bob", "pick_d", "fetch"), ("bob", "pick_d", "place"),
                                 ("robot", "pick_e", "fetch"), ("robot", "pick_e", "place"),
                                 ("alice", "inspect", "check")):
        for event in ("depart", "arrive", "start", "end"):
            t += 1
            h = h.add(Observation(t, event, agent, action, phase))
    h = h.add(Observation(t + 1, "depart", "robot", "load", "lift")).add(Observation(t + 2, "arrive", "robot", "load",
                                                                                    "lift"))
    assert fallback_step(h, "robot", None) is None  # no crew yet: no start
    h = h.add(Observation(t + 3, "depart", "bob", "load", "lift"))
    step = fallback_step(h, "robot", None)
    assert isinstance(step, WaitFor) and (step.agent, step.event) == ("bob", "arrive")
    h = h.add(Observation(t + 4, "arrive", "bob", "load", "lift"))
    step = fallback_step(h, "robot", None)
    assert isinstance(step, RobotStep) and step.event == "start"
    h = h.add(Observation(t + 5, "start", "robot", "load", "lift"))
    step = fallback_step(h, "robot", None)
    assert isinstance(step, WaitFor) and (step.agent, step.event) == ("robot", "end")  # a person's in it: nature's


def _messages(task: Task, plan: Plan) -> list[tuple[str, str, str, str]]:
    """`plan`'s run as (agent, action, phase, event) in an order the task allows: each phase whose agents are
    all at it and whose task-graph predecessors ended, the first agent's (task order) first; a joint action's
    crew each depart and arrive, then its lead starts and ends it."""
    queue = {a: list(plan.sequence(a)) for a in task.agent_ids}
    phase_of = {a: 0 for a in task.agent_ids}
    ended: set[tuple[str, str]] = set()
    out = []
    while any(queue.values()):
        for agent in task.agent_ids:
            if not queue[agent]:
                continue
            action = task.action(queue[agent][0])
            phase = action.phases[phase_of[agent]]
            crew = task.crew(action.id, plan)
            if any(not queue[x] or queue[x][0] != action.id or phase_of[x] != phase_of[agent] for x in crew):
                continue
            if any((p.before.action, p.before.phase) not in ended for p in task.precedence
                   if (p.after.action, p.after.phase) == (action.id, phase.id)):
                continue
            out.extend((x, action.id, phase.id, e) for x in crew for e in ("depart", "arrive"))
            lead = plan.agent_of(action.id)
            out.extend((lead, action.id, phase.id, e) for e in ("start", "end"))
            ended.add((action.id, phase.id))
            for x in crew:
                phase_of[x] += 1
                if phase_of[x] == len(action.phases):
                    phase_of[x] = 0
                    queue[x].pop(0)
            break
    return out


def test_json_lines_a_non_default_crew_member_starts_the_joint_action(tmp_path: Path) -> None:
    """``hrc dispatch`` (JSON lines) on a searched two_workers_joint whose one plan has alice hold the load: bob
    sets out for it instead. Accepted from the fallback, then plans compiled on demand for every agent's
    prefix (bob's with the load) are adopted, all with bob's crew; the run finishes on one of them, and its
    log replays byte for byte."""
    out = tmp_path / "out"
    assert main(["compile", str(TWJ), "--out", str(out), "--no-report", "-q", "--plans", "best:1",
                 "--search-budget", "1", "--cover", "0"]) == 0
    task = load_task(TWJ)
    plans = {p.id: p for p in generate_plans(task)}
    compiled = [plans[p["id"]] for p in json.loads((out / "compiled.json").read_text("utf-8"))["plans"]]
    assert all(task.crew("load", p) == ("alice", "robot") for p in compiled)
    ran = Plan(allocation=compiled[0].allocation, sequences=tuple(
        (a, tuple(x for x in seq if x != "load") + (("load",) if a in ("bob", "robot") else ()))
        for a, seq in compiled[0].sequences))
    assert ran.id in plans and task.crew("load", ran) == ("bob", "robot")
    log = tmp_path / "run.log"
    p = subprocess.Popen([sys.executable, "-m", "hrc", "dispatch", str(out), "--log", str(log)],
                         stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         bufsize=1, cwd=ROOT)
    assert p.stdin is not None and p.stdout is not None
    answers: list[dict] = []

    def send(msg: dict) -> dict:
        p.stdin.write(json.dumps(msg) + "\n")
        p.stdin.flush()
        answers.append(json.loads(p.stdout.readline()))
        return answers[-1]

    try:
        t = 0.0
        for agent, action, phase, event in _messages(task, ran):
            t = round(t + 1, 3)
            answer = send({"t": t, "agent": agent, "action": action, "phase": phase, "event": event})
            started = time.monotonic()
            while answer.get("fallback") is not None and time.monotonic() - started < 300:
                time.sleep(0.3)
                t = round(t + 0.1, 3)
                answer = send({"t": t, "event": "tick"})
                if answer.get("new_plans"):
                    break
    finally:
        p.stdin.close()
        err = p.stderr.read() if p.stderr else ""
        status = p.wait(timeout=60)
        p.stdout.close()
        if p.stderr:
            p.stderr.close()
    assert status == 0, err
    assert all(a["ok"] for a in answers), [a for a in answers if not a["ok"]]
    miss = next(i for i, a in enumerate(answers) if a.get("fallback"))
    assert answers[miss]["plan"] is None
    came = next(i for i, a in enumerate(answers) if a.get("new_plans"))
    assert came > miss and all("fallback" not in a for a in answers[came:])
    records = [json.loads(line) for line in log.read_text().splitlines()[1:]]
    added = [r["plans"] for r in records if "plans" in r]
    assert len(added) == 1 and added[0]["for"]["bob"] == ["pick_d", "load"]  # the crew seen, in bob's prefix
    assert added[0]["ids"] and all(task.crew("load", plans[i]) == ("bob", "robot") for i in added[0]["ids"])
    assert answers[-1]["plan"] in added[0]["ids"]
    run = subprocess.run([sys.executable, "-m", "hrc", "dispatch", str(out), "--replay", str(log)],
                         capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert run.returncode == 0, run.stderr
    assert run.stdout.splitlines() == [r["out"] for r in records if "out" in r]
