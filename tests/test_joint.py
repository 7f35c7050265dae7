"""Joint actions (issue 37): an action every agent of it does at once ("support the pile", Strassmair &
Taylor 2014, section IV, left out there).

A hand-worked case on a bare floor (one joint action, nothing else) checks the task format, the plan,
every link of the STNU by hand, the passing orders motion acquisition keeps and drops at the joint spot,
and the class in both readings of the person; the plan counts against brute force on random tasks; the
real-time execution (hypothesis) never lets the robot start the joint action before the person's arrival
is observed; the workshop with "support the pile" compiles and the CSTNU Tool agrees on every STNU (slow).
"""

from __future__ import annotations

import copy
import itertools
import random
import re
from dataclasses import replace
from pathlib import Path
from typing import Any

import networkx as nx
import pytest
import yaml
from conftest import ROOT
from dispatch_client import broken_links
from hypothesis import given, settings
from hypothesis import strategies as st
from joint_client import JointRun

from hrc.cli import main
from hrc.compile.classify import PlanClass
from hrc.compile.compiler import CompileOptions, compile_plan, compile_task
from hrc.compile.motion_pattern import pattern_network
from hrc.compile.temporal_net_creator import ORIGIN
from hrc.dispatch import Dispatcher
from hrc.dispatch.messages import Observation, RobotStep, WaitFor
from hrc.errors import DispatchError
from hrc.io.task_file import dump_task, load_task
from hrc.model import Action, Interval, Phase, PhaseRef, Plan, Precedence, Task
from hrc.motion import plan_paths
from hrc.plans import count_plans, generate_plans, phase_graph, plan_code, plan_count_bound, plan_from_code
from hrc.report.gantt import gantt_bars
from hrc.temporal import ContingentLink, ExecutionMode, real_time_state
from hrc.temporal.execution import ExecutionWindow

ERROR_LINE = re.compile(r"^error: [^\n]+: [^\n]+\n$")

BARE_MAP: dict[str, Any] = {"name": "bare", "bounds": [0, 0, 10, 4], "obstacles": [],
                            "locations": {"H": [1, 2], "R": [9, 2], "J": [5, 2], "A": [1, 3.5], "B": [9, 3.5]}}
"""A floor with nothing on it: every route is the straight line, so every travel time is by hand."""

LIFT: dict[str, Any] = {
    "name": "lift", "map": "map.yaml", "safety_margin": 0.1,
    "agents": [{"id": "human", "kind": "human", "radius": 0.3, "speed": 1.0, "start": "H"},
               {"id": "robot", "kind": "robot", "radius": 0.35, "speed": 0.5, "start": "R"}],
    "actions": [{"id": "lift", "name": "lift the frame together", "roles": {"holder": "human", "lifter": "robot"},
                 "phases": [{"id": "hold", "location": "J", "duration": {"holder": [3, 5], "lifter": [2, 4]}}]}],
}
"""One joint action at J, 4 m from each start: the person walks it in 4-5 s (1 m/s, travel slack 1.25), the
robot drives it in exactly 8 s (0.5 m/s); the step ends when both roles are done: 3-5 s, contingent."""


def _write(tmp: Path, task: dict[str, Any], map_: dict[str, Any] | None = None) -> Path:
    (tmp / "map.yaml").write_text(yaml.safe_dump(map_ or BARE_MAP, sort_keys=False), "utf-8")
    path = tmp / "task.yaml"
    path.write_text(yaml.safe_dump(task, sort_keys=False), "utf-8")
    return path


@pytest.fixture
def lift(tmp_path: Path):
    return load_task(_write(tmp_path, LIFT))


# ------------------------------------------------------------------------------------------ task format
def test_roles_load_as_a_joint_action_with_durations_by_agent(lift) -> None:
    action = lift.action("lift")
    assert action.joint and action.roles == (("holder", ("human",)), ("lifter", ("robot",)))
    assert action.needed == 2 and action.crews == (("human", "robot"),) and not action.crew_choice
    assert action.agents == ("human", "robot")
    phase = action.phase("hold")
    assert (phase.duration("human").lb, phase.duration("human").ub) == (3, 5)
    assert (phase.duration("robot").lb, phase.duration("robot").ub) == (2, 4)
    assert lift.lead("lift") == "robot" and lift.has_joint


def test_agents_needed_is_every_agent_in_a_role_named_for_it(tmp_path: Path) -> None:
    task = copy.deepcopy(LIFT)
    task["actions"][0] = {"id": "lift", "agents": ["human", "robot"], "agents_needed": 2, "phases": [
        {"id": "hold", "location": "J", "duration": {"human": [3, 5], "robot": [2, 4]}}]}
    loaded = load_task(_write(tmp_path, task))
    assert loaded.action("lift").roles == (("human", ("human",)), ("robot", ("robot",)))
    task["actions"][0]["agents_needed"] = 1  # one agent: as without the key
    assert not load_task(_write(tmp_path, task)).action("lift").joint


def test_show_says_who_plays_which_role(tmp_path: Path, capsys) -> None:
    assert main(["show", str(_write(tmp_path, LIFT))]) == 0
    assert "(by all at once: holder human, lifter robot)" in capsys.readouterr().out


def test_a_joint_task_round_trips_and_a_plain_one_is_written_as_before(lift, tmp_path: Path) -> None:
    out = tmp_path / "again" / "task.yaml"
    out.parent.mkdir()
    dump_task(lift, out)
    assert load_task(out).actions == lift.actions
    assert "roles:" in out.read_text("utf-8")
    plain = load_task(ROOT / "tasks" / "cube_stacking.yaml")
    dump_task(plain, out)
    assert "roles:" not in out.read_text("utf-8") and load_task(out).actions == plain.actions


BAD = [
    ("roles is a list", lambda a: a.update(roles=["human", "robot"]), "actions[0].roles"),
    ("one role", lambda a: a.update(roles={"holder": "human"}), "actions[0].roles"),
    ("unknown agent", lambda a: a["roles"].update(lifter="crane"), "actions[0].roles.lifter"),
    ("one agent in two roles", lambda a: a["roles"].update(lifter="human"), "actions[0].roles.lifter"),
    ("roles and agents", lambda a: a.update(agents=["human", "robot"]), "actions[0].agents"),
    ("a role without duration", lambda a: a["phases"][0]["duration"].pop("lifter"),
     "actions[0].phases[0].duration.lifter"),
    ("a duration of no role", lambda a: a["phases"][0]["duration"].update(pusher=[1, 2]),
     "actions[0].phases[0].duration.pusher"),
    ("a bad duration", lambda a: a["phases"][0]["duration"].update(holder=[5, 3]),
     "actions[0].phases[0].duration.holder"),
    ("agents_needed not a number", lambda a: (a.pop("roles"), a.update(agents=["human", "robot"],
                                                                        agents_needed="two")),
     "actions[0].agents_needed"),
    ("agents_needed of three", lambda a: (a.pop("roles"), a.update(agents=["human", "robot"], agents_needed=3)),
     "actions[0].agents_needed"),
]


@pytest.mark.parametrize(("why", "edit", "key"), BAD, ids=[b[0] for b in BAD])
def test_a_bad_joint_action_is_one_line_naming_file_and_key(why, edit, key, tmp_path: Path, capsys) -> None:
    task = copy.deepcopy(LIFT)
    edit(task["actions"][0])
    path = _write(tmp_path, task)
    assert main(["show", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and ERROR_LINE.match(err), err
    assert str(path) in err and f" {key}: " in err, err


def test_two_people_cannot_share_a_joint_action_without_a_robot_to_start_it(tmp_path: Path, capsys) -> None:
    # (a role given twice to the one person; two people alone: tests/test_team.py)
    task = copy.deepcopy(LIFT)
    task["actions"][0]["roles"] = {"holder": "human", "second": "human"}
    assert main(["show", str(_write(tmp_path, task))]) == 2
    assert "actions[0].roles" in capsys.readouterr().err


# ------------------------------------------------------------------------------------------------ plans
def test_a_joint_action_is_in_both_orders_and_allocated_to_its_lead(lift) -> None:
    (plan,) = list(generate_plans(lift))
    assert plan.sequences == (("human", ("lift",)), ("robot", ("lift",)))
    assert plan.allocation == (("lift", "robot"),)
    assert plan_from_code(lift, plan_code(lift, plan)) == plan


def _random_task(data: st.DataObject, base: Task) -> Task:
    """`base` with a few single-phase actions at A, B or J, some joint, and some precedence (acyclic by index)."""
    n = data.draw(st.integers(2, 4))
    actions = []
    for i in range(n):
        loc = data.draw(st.sampled_from(["A", "B", "J"]))
        if data.draw(st.booleans()):
            actions.append(Action(f"j{i}", f"j{i}", ("human", "robot"), (Phase("p", loc, _ONE_TWO),),
                                  roles=(("h", "human"), ("r", "robot"))))
        else:
            who = data.draw(st.sampled_from([("human",), ("robot",), ("human", "robot")]))
            actions.append(Action(f"a{i}", f"a{i}", who, (Phase("p", loc, tuple(x for x in _ONE_TWO if x[0] in who)),)))
    edges = [Precedence(PhaseRef(actions[i].id, "p"), PhaseRef(actions[j].id, "p"))
             for i, j in itertools.combinations(range(n), 2) if data.draw(st.booleans())]
    return replace(base, actions=tuple(actions), precedence=tuple(edges))


_ONE_TWO = (("human", Interval(1, 2)), ("robot", Interval(1, 2)))


@settings(max_examples=100, deadline=None)
@given(data=st.data())
def test_plan_counts_and_orders_against_brute_force(data, lift_task) -> None:
    """Every (allocation, pair of orders) enumerated by brute force; a plan is valid iff each joint action
    is in both orders and the phase graph is acyclic (the orders agree on their joint actions). The
    stream is exactly those, and the memoized count and the bound agree with it."""
    task = _random_task(data, lift_task)
    valid = set()
    choices = [[task.lead(a.id)] if a.joint else list(a.agents) for a in task.actions]
    for combo in itertools.product(*choices):
        mine = {ag: [a.id for a, who in zip(task.actions, combo, strict=True)
                     if who == ag or (a.joint and ag in a.agents)] for ag in task.agent_ids}
        for hs in itertools.permutations(mine["human"]):
            for rs in itertools.permutations(mine["robot"]):
                plan = Plan(tuple(zip(task.action_ids, combo, strict=True)), (("human", hs), ("robot", rs)))
                if nx.is_directed_acyclic_graph(phase_graph(task, plan)):
                    valid.add(plan)
    streamed = list(generate_plans(task))
    assert len(streamed) == len(set(streamed)) and set(streamed) == valid
    assert count_plans(task) == len(valid) <= plan_count_bound(task)


@pytest.fixture(scope="module")
def lift_task(tmp_path_factory) -> Task:
    return load_task(_write(tmp_path_factory.mktemp("lift"), LIFT))


# ------------------------------------------------------------------------------------------------- STNU
H, R = "human.hold.lift", "robot.hold.lift"


def _links(net) -> dict[tuple[str, str], tuple[int | None, int | None]]:
    out = {}
    for r in net.stnu.requirements:
        out.setdefault((r.source, r.target), []).append((r.lb, r.ub))
    return out


def test_the_joint_start_by_hand(lift) -> None:
    """Every link of the one plan's STNU, by hand (module docstring of the temporal net creator)."""
    paths = plan_paths(lift, seed=0)
    assert paths.get("human", "H", "J").length == pytest.approx(4.0, abs=1e-9)
    assert paths.get("robot", "R", "J").length == pytest.approx(4.0, abs=1e-9)
    (plan,) = list(generate_plans(lift))
    cp = compile_plan(lift, plan, paths)
    net = pattern_network(lift, plan, cp.pattern)
    s = net.stnu
    # one start and one end for both: the person's leg has no start or end of its own
    assert set(s.timepoints) == {ORIGIN, f"{H}.depart", f"{H}.arrive", f"{R}.depart", f"{R}.arrive", f"{R}.start",
                                 f"{R}.end"}
    assert set(s.contingents) == {ContingentLink(f"{H}.depart", f"{H}.arrive", 4000, 5000),  # 4 m at 1 m/s, x1.25
                                  ContingentLink(f"{R}.start", f"{R}.end", 3000, 5000)}  # max of the roles' bounds
    links = _links(net)
    assert links[(ORIGIN, f"{H}.depart")] == [(0, None)]
    assert links[(ORIGIN, f"{R}.depart")] == [(0, None)]
    assert links[(f"{R}.depart", f"{R}.arrive")] == [(8000, 8000)]  # 4 m at 0.5 m/s, rigid
    assert links[(f"{H}.arrive", f"{R}.start")] == [(0, None)]  # the synchronisation: the start waits for both
    assert links[(f"{R}.arrive", f"{R}.start")] == [(0, None)]
    # the passing orders: the robot's drive in keeps the separation from the person standing at J, so the
    # robot is there first (the person arrives no earlier than 8 s, its whole drive, after it left);
    # the person walking up to the standing robot and the two standing there together are the co-work
    orders = {(o.conflict.robot.kind, o.conflict.human.kind): o for o in cp.pattern.orders}
    assert ("stay", "stay") not in orders and ("stay", "travel") not in orders
    drive_in = orders[("travel", "stay")]
    assert drive_in.first == "robot" and drive_in.how == "forced"
    assert links[(f"{R}.depart", f"{H}.arrive")][0][0] == 8000
    assert cp.plan_class is PlanClass.DC
    # the Gantt draws the one phase on both rows, over the same span
    bars = gantt_bars(lift, cp)
    work = {agent: [(a, b) for kind, a, b, _ in rows if kind == "work"] for agent, rows in bars.items()}
    assert work["human"] == work["robot"] and len(work["robot"]) == 1
    # with the person leaving at once (--human-waits no), they are at J by 5 s, before the robot can be:
    # no order keeps the separation, and the plan is inconsistent
    strict = compile_plan(lift, plan, paths, CompileOptions(human_waits=False))
    assert strict.plan_class is PlanClass.INCONSISTENT


@settings(max_examples=60, deadline=None)
@given(walk=st.integers(4000, 5000), leave=st.integers(0, 6000), seen_after=st.integers(0, 6000),
       look=st.integers(0, 30000))
def test_the_robot_is_never_told_to_start_before_the_arrival_is_observed(lift_net, walk, leave, seen_after,
                                                                         look) -> None:
    """Random valid histories of the hand-worked plan (the robot drives in at 0, the person leaves when
    the robot says and walks 4-5 s): at any moment, the real-time execution (the dispatcher's DC mode)
    gives the joint start a window only once the person's arrival has been observed, and that window
    opens no earlier than the arrival."""
    s = lift_net
    state = real_time_state(s, {ORIGIN: 0, f"{R}.depart": 0}, 0)
    depart = state.step(f"{H}.depart", ExecutionMode.DC)
    assert isinstance(depart, ExecutionWindow)
    t_leave = depart.earliest + min(leave, (depart.latest or 10**6) - depart.earliest)
    arrive = t_leave + walk
    done = {ORIGIN: 0, f"{R}.depart": 0, f"{R}.arrive": 8000, f"{H}.depart": t_leave}
    now = max(8000, t_leave) + look
    if now < arrive:  # not yet there: the robot must wait for the arrival
        step = real_time_state(s, done, now).step(f"{R}.start", ExecutionMode.DC)
        assert not isinstance(step, ExecutionWindow)
        assert f"{H}.arrive" in step.until
    else:
        done[f"{H}.arrive"] = arrive
        now = max(now, arrive + seen_after)
        step = real_time_state(s, done, now).step(f"{R}.start", ExecutionMode.DC)
        assert isinstance(step, ExecutionWindow) and step.earliest >= arrive


@pytest.fixture(scope="module")
def lift_net(lift_task):
    task = lift_task
    (plan,) = list(generate_plans(task))
    cp = compile_plan(task, plan, plan_paths(task, seed=0))
    return pattern_network(task, plan, cp.pattern).stnu


# --------------------------------------------------------------------------------- the workshop, jointly
def test_the_joint_workshop_has_its_plans(tmp_path: Path) -> None:
    task = load_task(ROOT / "tasks" / "cube_stacking_joint.yaml")
    plans = list(generate_plans(task))
    assert len(plans) == count_plans(task) == 32  # the workshop's 32: support is in both orders, always
    for plan in plans:
        for _, seq in plan.sequences:
            assert seq.index("support") > max((seq.index(c) for c in ("cube1", "cube2", "cube3", "cube4")
                                               if c in seq), default=-1)


# ------------------------------------------------------------------------------------------ dispatching
LIFT2: dict[str, Any] = copy.deepcopy(LIFT)
LIFT2["actions"] = [
    {"id": "a", "agents": ["human", "robot"], "phases": [
        {"id": "fetch", "location": "A", "duration": {"human": [1, 2], "robot": [2, 3]}}]},
    {"id": "b", "agents": ["human", "robot"], "phases": [
        {"id": "fetch", "location": "B", "duration": {"human": [1, 2], "robot": [2, 3]}}]},
    *LIFT["actions"],
]
LIFT2["precedence"] = [["a", "lift"], ["b", "lift"]]
"""Two fetches (either agent, at A and B) before the joint lift at J: plans in every class."""


@pytest.fixture(scope="module")
def lift2_dispatcher(tmp_path_factory):
    task = load_task(_write(tmp_path_factory.mktemp("lift2"), LIFT2))
    return Dispatcher.from_compiled(compile_task(task, jobs=1))


def _check_run(run: JointRun, joint: str, phase: str) -> None:
    """The joint start is never told before the person's arrival there was seen, and happens after it;
    a run that ends on a DC plan has done every event and broken no link of its STNU."""
    arrive = ("human", joint, phase, "arrive")
    for dec, seen in run.answers:
        step = dec.robot
        if isinstance(step, RobotStep) and (step.action, step.phase, step.event) == (joint, phase, "start"):
            assert arrive in seen, (dec, sorted(seen))
            assert step.earliest >= run.times[arrive]
    start = ("robot", joint, phase, "start")
    assert start in run.times and run.times[start] >= run.times[arrive]
    last = run.answers[-1][0]
    if last.plan_class == "DC":
        d = run.dispatcher
        assert broken_links(d.plan_set.entry(d.plan_set.index(last.plan)).stnu, run.times) == []


@settings(max_examples=30, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1))
def test_the_dispatcher_starts_the_lift_only_once_the_person_is_seen_there(lift2_dispatcher, seed) -> None:
    """Random valid histories (the person and the robot played by `joint_client`, durations and times drawn
    inside the windows and contingent bounds) against the real dispatcher, from its first answer."""
    run = JointRun(lift2_dispatcher.fork(), random.Random(seed))
    run.play()
    _check_run(run, "lift", "hold")


def test_a_person_cannot_start_or_end_a_joint_action(lift2_dispatcher) -> None:
    d = lift2_dispatcher.fork()
    for obs in (Observation(0.0, "start", "human", "lift", "hold"), Observation(0.0, "end", "human", "lift", "hold")):
        with pytest.raises(DispatchError, match="joint action, the robot starts and ends it"):
            d.observe(obs)
    assert d.history == ()


@pytest.mark.slow
@settings(max_examples=40, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1))
def test_the_dispatcher_on_the_joint_workshop(joint_workshop, seed) -> None:
    run = JointRun(joint_workshop.fork(), random.Random(seed))
    run.play()
    _check_run(run, "support", "hold")


def test_seed_186_of_the_joint_workshop_finishes(joint_workshop) -> None:
    """Regression (issue 37's 200 histories): with seed 186 the deadline left no slack, forcing the robot's
    end of the put of cube 3 and the person's start of the put of cube 4 at one instant; the robot waited
    for the person's start (a co-worker's own start, `uncontrolled`) while the person was told to wait
    for the robot's end, and the run stalled. The robot now goes first (`Dispatcher._unlock`): the run
    ends, on a DC plan, every link of its STNU kept."""
    run = JointRun(joint_workshop.fork(), random.Random(186))
    run.play()
    assert ("robot", "support", "hold", "end") in run.times
    assert run.times[("human", "cube4", "put", "start")] >= run.times[("robot", "cube3", "put", "end")]
    assert run.answers[-1][0].plan_class == "DC"
    _check_run(run, "support", "hold")
    for dec, _ in run.answers:  # never the robot waiting for the person's own step while they wait for it
        r, h = dec.robot, dec.human
        assert not (isinstance(r, WaitFor) and r.agent == "human" and r.event in ("depart", "start")
                    and isinstance(h, WaitFor) and h.agent == "robot"), dec


@pytest.fixture(scope="module")
def joint_workshop():
    return Dispatcher.from_compiled(compile_task(load_task(ROOT / "tasks" / "cube_stacking_joint.yaml"), jobs=1))
