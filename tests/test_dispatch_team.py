"""Issue 37, the dispatcher for any team: every robot told its next step and every person their hint, by id.

An independent client (tests/team_client.py) plays every person and every robot controller over the
JSON-lines protocol with random valid histories on kitting_2robots cut to three picks (two robots, one
person) and two_workers (two people, one robot, a joint action): every run ends with every phase done, and a
run that ends on a DC plan breaks no link of that plan's STNU (the compile's GraphML, read back). A
hand-worked robot-robot crossing says who is told to go first and when the other may follow. `hrc
dispatch` serves a team folder, logs the team and replays it byte for byte; a bad agent id is refused in one
line and changes nothing.
"""

from __future__ import annotations

import json
import math
import random
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from conftest import ROOT
from dispatch_client import broken_links
from hypothesis import given, settings
from hypothesis import strategies as st
from team_client import TeamRun, timepoint
from test_team import CROSS, CROSS_MAP, write_task

from hrc.cli import main
from hrc.compile.compiler import compile_task
from hrc.dispatch import Dispatcher
from hrc.dispatch.protocol import handle_line
from hrc.io.task_file import load_task
from hrc.model import Task
from hrc.temporal.graphml import read_graphml


class Team:
    def __init__(self, task: Task) -> None:
        self.task = task
        cps = compile_task(task, seed=0, jobs=1)
        self.stnus = {cp.plan.id: read_graphml(cp.graphml.encode()) for cp in cps.plans}
        self.plans = {cp.plan.id: cp for cp in cps.plans}
        self.dispatcher = Dispatcher.from_compiled(cps)
        self.robots = tuple(a.id for a in task.agents if not a.is_human)
        self.people = tuple(a.id for a in task.agents if a.is_human)

    def run(self, seed: int) -> TeamRun:
        run = TeamRun(self.dispatcher.fork(), self.stnus, self.robots, self.people, random.Random(seed))
        run.play()
        return run


@pytest.fixture(scope="module")
def kitting3() -> Team:
    full = load_task(ROOT / "tasks" / "kitting_2robots.yaml")
    return Team(replace(full, actions=full.actions[:3]))  # 60 plans: 3! C(5, 2)


@pytest.fixture(scope="module")
def workers() -> Team:
    return Team(load_task(ROOT / "tasks" / "two_workers.yaml"))  # 120 plans


def _check(team: Team, run: TeamRun) -> None:
    """Every answer names every robot and every person; the run did every phase of the task (its end seen);
    a run ending on a DC plan broke no link of that plan's STNU; no robot was told to start a joint action
    before every other agent of it was seen arriving there."""
    task = team.task
    for answer in run.answers:
        assert answer["ok"] is True and "robot" not in answer and "human" not in answer
        assert tuple(answer["robots"]) == team.robots and tuple(answer["people"]) == team.people
        assert set(answer.get("ahead", {})) <= {h for h, s in answer["people"].items() if s is None}
    ends = {(k[1], k[2]) for k in run.times if k[3] == "end"}
    assert ends == {(a.id, p.id) for a in task.actions for p in a.phases}
    last = run.answers[-1]
    assert all(s is None for s in (*last["robots"].values(), *last["people"].values()))
    if last["class"] == "DC":
        assert broken_links(team.stnus[last["plan"]], run.times) == []
    joint = {a.id: a.agents for a in task.actions if a.joint}
    seen: set[tuple[str, ...]] = set()
    for line, answer in zip(run.sent[1:], run.answers[1:], strict=True):
        m = json.loads(line)
        seen.add((m["agent"], m["action"], m["phase"], m["event"]))
        for r, step in answer["robots"].items():
            if step and step.get("event") == "start" and step["action"] in joint:
                for other in joint[step["action"]]:
                    assert other == r or (other, step["action"], step["phase"], "arrive") in seen


@settings(max_examples=12, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1))
def test_two_robots_and_a_person_random_runs(kitting3: Team, seed: int) -> None:
    _check(kitting3, kitting3.run(seed))


@settings(max_examples=12, deadline=None, derandomize=True)
@given(seed=st.integers(0, 2**32 - 1))
def test_two_people_and_a_robot_random_runs(workers: Team, seed: int) -> None:
    _check(workers, workers.run(seed))


def test_both_robots_work_in_some_runs_and_every_agent_keeps_apart(kitting3: Team) -> None:
    """Over 20 seeded runs: both robots act in most (the client is not only ever serving one robot), every
    run ends on a DC plan (the client keeps to every window and bound), and in the first 6 of those with both
    robots, every robot stays ``r_a + r_b + margin`` from every other agent at every instant (each agent
    moved along its compiled routes at the run's times: tests/referee.py, no conflict model)."""
    from test_team import _closest

    from hrc.motion.conflicts import floor_pairs

    task = kitting3.task
    pairs = [(r.id, o.id, r.radius + o.radius + task.safety_margin) for r, o in floor_pairs(task)]
    both = classes = refereed = 0
    for seed in range(20):
        run = kitting3.run(seed)
        _check(kitting3, run)
        two = {"robot", "robot2"} <= {k[0] for k in run.times}
        both += two
        last = run.answers[-1]
        classes += last["class"] == "DC"
        if two and last["class"] == "DC" and refereed < 6:
            refereed += 1
            times = {timepoint(k): t for k, t in run.times.items()}
            for a, b, reach in pairs:
                assert _closest(task, kitting3.plans[last["plan"]], times, a, b, "even", dt=0.02) >= reach - 1e-3
    assert classes == 20 and both >= 10 and refereed == 6


# ------------------------------------------------------------------------------ a crossing, by hand
@pytest.fixture(scope="module")
def crossing(tmp_path_factory: pytest.TempPathFactory) -> Dispatcher:
    task = load_task(write_task(tmp_path_factory.mktemp("cross"), CROSS, CROSS_MAP))
    return Dispatcher.from_compiled(compile_task(task, seed=0, jobs=1))


def _ask(d: Dispatcher, message: dict[str, Any]) -> dict[str, Any]:
    return json.loads(handle_line(d, json.dumps(message)))


def test_two_robots_at_a_crossing_who_goes_first(crossing: Dispatcher) -> None:
    """tests/test_team.py's crossing (r1 W -> E, r2 S -> N, 8 m at 1 m/s, then a 1 s step; deadline 10.5 s):
    the plan lets r1 pass first, r2 leaving at least the gap g = 0.8 sqrt 2 (1.131, 1.16 on the sampled
    routes) after r1 left. By hand: r2 must leave by 10.5 - 8 - 1 = 1.5 s, so r1 by 1.5 - g = 0.34 s; r2 is
    told to wait for r1's departure; r1 leaving at 0.1 s, r2's window is [0.1 + g, 1.5] and r1's arrival is
    due at 8.1 s exactly."""
    d = crossing.fork()
    gap = 1.16
    assert 0.8 * math.sqrt(2) <= gap <= 0.8 * math.sqrt(2) + 0.06
    a = _ask(d, {"t": 0, "event": "tick"})
    assert a["class"] == "DC"
    assert a["robots"]["r1"] == {"action": "east", "phase": "go", "event": "depart", "earliest": 0.0,
                                 "latest": round(1.5 - gap, 3)}
    assert a["robots"]["r2"] == {"wait_for": "r1.east.go.depart"}
    a = _ask(d, {"t": 0.1, "agent": "r1", "action": "east", "phase": "go", "event": "depart"})
    assert "ack" not in a  # what r1 was told, in its window
    assert a["robots"]["r1"] == {"action": "east", "phase": "go", "event": "arrive", "earliest": 8.1, "latest": 8.1}
    assert a["robots"]["r2"] == {"action": "north", "phase": "go", "event": "depart", "earliest": round(0.1 + gap, 3),
                                 "latest": 1.5}
    # r2 leaving too early is a fact: accepted, and its acknowledgement says how it stood to r2's window
    a = _ask(d, {"t": 0.5, "agent": "r2", "action": "north", "phase": "go", "event": "depart"})
    assert a["ok"] is True and a["ack"] == {"early": round(0.1 + gap - 0.5, 3), "window": [round(0.1 + gap, 3), 1.5]}


def test_a_robot_out_of_turn_is_told_it_was_unasked(crossing: Dispatcher) -> None:
    d = crossing.fork()
    _ask(d, {"t": 0, "event": "tick"})
    a = _ask(d, {"t": 0.0, "agent": "r2", "action": "north", "phase": "go", "event": "depart"})
    assert a["ack"] == {"unasked": True, "told": {"wait_for": "r1.east.go.depart"}}


def test_a_bad_agent_id_is_refused_in_one_line_and_changes_nothing(crossing: Dispatcher) -> None:
    d = crossing.fork()
    before = handle_line(d, json.dumps({"t": 0, "event": "tick"}))
    for agent, why in (("robot", "unknown agent 'robot' (agents: human, r1, r2)"),
                       ("r3", "unknown agent 'r3'"), ("human", "human cannot do east")):
        got = json.loads(handle_line(d, json.dumps({"t": 0.2, "agent": agent, "action": "east", "phase": "go",
                                                     "event": "depart"})))
        assert got["ok"] is False and why in got["error"] and "\n" not in got["error"]
    assert len(d.accepted) == 1 and d.decision.to_json() == json.loads(before)


# ------------------------------------------------------------------------------ the command
def test_hrc_dispatch_serves_a_team_logs_it_and_replays_it(tmp_path: Path) -> None:
    out = tmp_path / "cross"
    task = write_task(tmp_path, CROSS, CROSS_MAP)
    assert main(["compile", str(task), "--out", str(out), "--no-report", "-q"]) == 0
    messages = [{"t": 0, "event": "tick"},
                {"t": 0.1, "agent": "r1", "action": "east", "phase": "go", "event": "depart"},
                {"t": 0.2, "agent": "robot", "action": "east", "phase": "go", "event": "arrive"},
                {"t": 1.3, "agent": "r2", "action": "north", "phase": "go", "event": "depart"}]
    log = tmp_path / "run.log"
    cmd = [sys.executable, "-m", "hrc", "dispatch", str(out)]
    done = subprocess.run([*cmd, "--log", str(log)], input="".join(json.dumps(m) + "\n" for m in messages),
                          capture_output=True, text=True, check=False, cwd=ROOT)
    assert done.returncode == 0 and done.stderr == ""
    answers = [json.loads(x) for x in done.stdout.splitlines()]
    assert [a["ok"] for a in answers] == [True, True, False, True]
    assert answers[3]["robots"]["r2"]["event"] == "arrive" and "ack" not in answers[3]
    header = json.loads(log.read_text("ascii").splitlines()[0])
    assert header["team"] == {"human": "human", "r1": "robot", "r2": "robot"}
    again = subprocess.run([*cmd, "--replay", str(log)], capture_output=True, text=True, check=False, cwd=ROOT)
    assert again.returncode == 0 and again.stdout == done.stdout


def test_each_person_has_their_own_buttons_and_may_leave(workers: Team) -> None:
    """`human_options(agent)`: at the start, each person's departures are exactly for the first actions some
    compiled plan gives them (read from the plans, not the dispatcher), and their starts those of them the
    task graph does not hold back. Alice away: the plans left give her nothing more (checked against the
    compiled plans) and she is told nothing; a person's events are refused in one line while away."""
    d = workers.dispatcher.fork()
    task = workers.task
    for person in workers.people:
        firsts = {cp.plan.sequence(person)[0] for cp in workers.plans.values() if cp.plan.sequence(person)}
        waits = {p.after.action for p in task.precedence}  # a start the task graph holds back at the start
        expected = {(a, task.action(a).phases[0].id, e) for a in firsts for e in ("depart", "start")
                    if e == "depart" or a not in waits}
        assert {(o.action, o.phase, o.event) for o in d.human_options(person)} == expected
    got = json.loads(handle_line(d, json.dumps({"t": 0.5, "agent": "alice", "event": "away"})))
    free = {cp.plan.id for cp in workers.plans.values() if not cp.plan.sequence("alice")}
    assert got["ok"] is True and got["away"] == ["alice"] and got["people"]["alice"] is None
    assert got["plan"] in free and sum(got["candidates"].values()) == len(free) > 0
    assert d.human_options("alice") == () and d.human_options("bob") != ()
    # bob too: no plan does without him (the load is his and the robot's), so the set stays as it was
    got = json.loads(handle_line(d, json.dumps({"t": 1.0, "agent": "bob", "event": "away"})))
    assert got["away"] == ["alice", "bob"] and got["people"] == {"alice": None, "bob": None}
    assert sum(got["candidates"].values()) == len(free)
    assert json.loads(handle_line(d, json.dumps({"t": 1.2, "agent": "alice", "event": "back"})))["away"] == ["bob"]
    for message, why in (({"t": 1.5, "agent": "bob", "action": "pick_a", "phase": "fetch", "event": "depart"},
                          "bob is away: send 'back' before pick_a.fetch depart"),
                         ({"t": 1.5, "agent": "bob", "event": "away"}, "bob is already away"),
                         ({"t": 1.5, "agent": "alice", "event": "back"}, "alice is not away"),
                         ({"t": 1.5, "event": "back"}, "alice is not away"),
                         ({"t": 1.5, "agent": "robot", "event": "away"},
                          "only a person (alice, bob) can be away or back, not 'robot'")):
        assert json.loads(handle_line(d, json.dumps(message))) == {"t": 1.5, "ok": False, "error": why}
    back = json.loads(handle_line(d, json.dumps({"t": 2.0, "agent": "bob", "event": "back"})))
    assert back["away"] == [] and sum(back["candidates"].values()) == len(workers.plans)


def test_hrc_dispatch_resumes_a_team_run_as_it_went(tmp_path: Path) -> None:
    """A team's run cut after two messages and resumed from its log answers the rest as the whole run did."""
    out = tmp_path / "cross"
    assert main(["compile", str(write_task(tmp_path, CROSS, CROSS_MAP)), "--out", str(out), "--no-report",
                 "-q"]) == 0
    lines = [json.dumps(m) + "\n" for m in (
        {"t": 0, "event": "tick"}, {"t": 0.1, "agent": "r1", "action": "east", "phase": "go", "event": "depart"},
        {"t": 1.3, "agent": "r2", "action": "north", "phase": "go", "event": "depart"},
        {"t": 1.5, "agent": "human", "action": "tidy", "phase": "do", "event": "depart"},
        {"t": 8.1, "agent": "r1", "action": "east", "phase": "go", "event": "arrive"})]
    cmd = [sys.executable, "-m", "hrc", "dispatch", str(out)]

    def run(*args: str, given: list[str]) -> str:
        done = subprocess.run([*cmd, *args], input="".join(given), capture_output=True, text=True, check=False,
                              cwd=ROOT)
        assert done.returncode == 0, done.stderr
        return done.stdout

    whole = run("--log", str(tmp_path / "whole.log"), given=lines).splitlines()
    first = run("--log", str(tmp_path / "cut.log"), given=lines[:2]).splitlines()
    rest = run("--resume", str(tmp_path / "cut.log"), given=lines[2:]).splitlines()
    assert first + rest == whole and all(json.loads(x)["ok"] for x in whole)
    assert "robots" in json.loads(whole[-1])
