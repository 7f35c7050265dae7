"""Crews (issue 37) online: the console, hrc ros2 and the motion detector follow a joint action whose crew
is a choice of the plan (`hrc.model.Action.crew_choice`); the MCAP recording holds the robot's home goal.

The hand-worked case of tests/test_crews.py (alice and bob, one robot; carry by either person, the lift at
J by the robot with alice or bob holding; 4 plans, worked out there by hand). What each person may do is
worked out by hand from those 4 plans: a joint action is offered to every candidate who is in its crew in
some remaining plan; a candidate's press keeps only the plans whose crew has them, and the other candidate
is not offered it afterwards; the robot waits for the crew that came.

- the console: its session (by hand, either holder) and two_workers_joint in Chromium (both people's pages
  to the end of a run, each page's buttons a fresh dispatcher's, the log replayed byte for byte);
- hrc ros2: a real rclpy node, alice taking the lift the best plan gave bob (bob refused, the robot told to
  wait for alice), its goals J then home, and its ``--record`` holding every goal it sent (the home goal
  last, the same pose and time); two_workers_joint played to its end by tests/team_client.py;
- the motion detector: hand-made traces (tests/test_detect_team.py's `Walker`), a candidate seen walking
  to the joint spot, and one seen staying there, read as joining; the same lines through ``hrc dispatch
  --detect motion``, ``hrc detect``, the console's session and a real ``hrc ros2 --detect motion`` node.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import pytest
from test_crews import HAND, hand_out  # noqa: F401 - the fixture: the hand-worked case, compiled

from hrc.compile.output import read_header
from hrc.console.clock import RunClock
from hrc.console.session import ConsoleSession
from hrc.dispatch import Dispatcher, RobotStep
from hrc.dispatch.durable import LoggedDispatcher
from hrc.dispatch.messages import WaitFor
from hrc.dispatch.plan_set import load_plan_set
from hrc.dispatch.routes import PlanRoutes, plan_motions
from hrc.motion import plan_paths

assert HAND["actions"][1]["id"] == "lift"


def _session(out: Path) -> ConsoleSession:
    plan_set = load_plan_set(out)
    header = read_header(out)
    routes = PlanRoutes(plan_motions(out, plan_set), plan_paths(plan_set.task, seed=int(header.get("seed", 0))))
    session = ConsoleSession(LoggedDispatcher(Dispatcher(plan_set)), header, routes, RunClock(1.0))
    session.clock.now = lambda: session.dispatcher.now + 0.5  # type: ignore[method-assign]  # run time moves
    return session


def _offered(state: dict[str, Any], person: str) -> set[tuple[str, str, str]]:
    return {(o["action"], o["phase"], o["event"]) for o in state["persons"][person]["options"]}


def _press(s: ConsoleSession, person: str, action: str, phase: str, event: str) -> dict[str, Any]:
    reply = s.page_message({"type": "press", "hseq": s.hseqs[person], "action": action, "phase": phase,
                            "event": event}, person)
    assert reply["ok"], reply
    return s.state()


def _ack(s: ConsoleSession, action: str, phase: str, event: str) -> dict[str, Any]:
    reply = s.robot_message({"type": "ack", "action": action, "phase": phase, "event": event}, robot="robot")
    assert reply["ok"], reply
    return s.state()


LIFT = ("lift", "hold", "depart")
CARRY = ("carry", "put", "depart")


@pytest.mark.parametrize("holder", ["alice", "bob"])
def test_the_console_offers_a_joint_action_to_every_candidate_until_one_joins(hand_out: Path,  # noqa: F811
                                                                              holder: str) -> None:
    """alice carries; then the lift is offered to both (a plan with either holding remains); the one who
    departs for it holds it: the other is not offered it again, the robot waits for the holder's arrival,
    and the shared view draws the lift under the holder and the robot only."""
    other = "bob" if holder == "alice" else "alice"
    s = _session(hand_out)
    state = s.state()
    # by hand: either may carry (4 plans); either may go straight to the lift (a plan where the other carries)
    assert {CARRY, LIFT} <= _offered(state, "alice") and {CARRY, LIFT} <= _offered(state, "bob")
    state = _press(s, "alice", *CARRY)  # carry: alice's (2 plans left: the lift's crew alice's or bob's)
    assert LIFT in _offered(state, "bob") and LIFT not in _offered(state, "alice")  # alice carries first
    for event in ("arrive", "start", "end"):
        state = _press(s, "alice", "carry", "put", event)
    assert LIFT in _offered(state, "alice") and LIFT in _offered(state, "bob")  # either may still hold it
    assert sum(state["decision"]["candidates"].values()) == 2
    state = _press(s, holder, *LIFT)
    assert sum(state["decision"]["candidates"].values()) == 1  # the plan whose crew has the holder
    assert not any(o["action"] == "lift" for o in state["persons"][other]["options"])
    assert s.crews()["lift"] == tuple(a for a in ("alice", "bob", "robot") if a in (holder, "robot"))
    step = s.robot_step("robot")
    assert isinstance(step, RobotStep) and step.action == "lift"
    state = _ack(s, "lift", "hold", "depart")
    state = _ack(s, "lift", "hold", "arrive")
    wait = s.dispatcher.decision.robots["robot"]  # type: ignore[index]
    assert isinstance(wait, WaitFor) and (wait.agent, wait.event) == (holder, "arrive")  # the crew that came
    state = _press(s, holder, "lift", "hold", "arrive")
    assert not any(o["action"] == "lift" for o in state["persons"][other]["options"])
    state = _ack(s, "lift", "hold", "start")
    assert state["persons"][holder]["under_way"] == [["lift", "hold"]]
    assert state["persons"][other]["under_way"] == []
    work = {b["agent"] for b in state["gantt"]["actual"] if b["action"] == "lift" and b["kind"] == "work"}
    assert work == {holder, "robot"}
    assert s.lead("lift") == "robot"
    state = _ack(s, "lift", "hold", "end")
    assert state["finished"] and state["persons"][other]["options"] == []


def test_a_candidate_who_goes_straight_to_the_joint_action_takes_it_from_the_other(hand_out: Path) -> None:  # noqa: F811
    """bob departs for the lift first thing: the plans left are those where alice carries and bob holds
    (the one DC plan of the four, by hand); alice is offered the carry, never the lift."""
    s = _session(hand_out)
    state = _press(s, "bob", *LIFT)
    assert state["decision"]["candidates"] == {"DC": 1, "consistent": 0, "inconsistent": 0}
    assert _offered(state, "alice") == {CARRY, ("carry", "put", "start")}
    assert _offered(state, "bob") == {("lift", "hold", "arrive")}  # the robot starts the joint action
    for event in ("depart", "arrive", "start", "end"):
        state = _press(s, "alice", "carry", "put", event)
        assert not any(o["action"] == "lift" for o in state["persons"]["alice"]["options"])
    assert json.loads(json.dumps(s.crews())) == {"lift": ["bob", "robot"]}


# --------------------------------------------------------------------------- the console in a browser

@pytest.fixture(scope="module")
def joint_workers(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """tasks/two_workers_joint.yaml compiled (240 plans: the load's holder is alice or bob)."""
    from conftest import ROOT, compiled_folder
    from console_harness import browser_or_skip

    browser_or_skip()
    return compiled_folder(tmp_path_factory.mktemp("twj") / "out", ROOT / "tasks" / "two_workers_joint.yaml",
                           "--jobs", "1")


@pytest.mark.parametrize("seed", [3, 8])
def test_two_candidates_press_on_their_own_pages_and_one_holds(joint_workers: Path, tmp_path: Path,
                                                               seed: int) -> None:
    """two_workers_joint in a real headless Chromium, the robot simulated: alice and bob each press their
    own offered buttons (seeded) to the end of the run. Each page's buttons were the dispatcher's options
    for that person at that point (the log replayed into a fresh dispatcher); the load was offered to both
    at some point; once one departed for it the other's page never offered it again; the crew that did it
    (the holder who pressed, the robot) is the crew of the one plan left (`Task.crew`), and the log replays
    byte for byte."""
    from console_harness import ConsoleProcess, chromium
    from test_console_team import SPEED, _options_after_each, _play, _replays, person_urls

    from hrc.compile.output import iter_plans
    from hrc.io.task_file import load_task
    from hrc.plans import generate_plans

    console = ConsoleProcess(joint_workers, tmp_path / "run.jsonl", "--speed", str(SPEED), "--simulate-robot")
    try:
        with chromium() as ctx:
            pages = {}
            for person, url in person_urls(console, ("alice", "bob")).items():
                page = pages[person] = ctx.browser.new_context().new_page()
                page.goto(url)
            for page in pages.values():
                page.wait_for_function("() => window.hrcConsole && window.hrcConsole.state !== null "
                                       "&& window.hrcConsole.connected", timeout=15_000)
            seen, pressed = _play(pages, joint_workers, seed=seed)
        state = console.state()
    finally:
        console.stop()
    assert state["finished"] and state["decision"]["robots"] == {"robot": None}
    lines = console.log_lines()
    ins, outs = lines[0::2], lines[1::2]
    assert all(o["ok"] for o in outs), [o for o in outs if not o["ok"]]
    holders = {p for p, (action, _, _) in pressed if action == "load"}
    assert len(holders) == 1, pressed
    holder = holders.pop()
    other = "bob" if holder == "alice" else "alice"
    # pressed by the holder: the load was offered to both at some point before, and never to the other after
    loads = [(p, snap["seq"]) for p, snap in seen if any(b[0] == "load" and not b[3] for b in snap["buttons"])]
    assert {p for p, _ in loads} == {"alice", "bob"}, loads
    first_in = next(k for k, m in enumerate(ins) if m.get("agent") == holder and m.get("action") == "load")
    seq_joined = sum(1 for o in outs[:first_in + 1] if o["ok"] and not o.get("unchanged"))
    assert all(s < seq_joined for p, s in loads if p == other), (loads, seq_joined)
    # each page's buttons were that person's options in a fresh dispatcher at that point
    options = _options_after_each(joint_workers, console.log, ("alice", "bob"))
    checked = 0
    for person, snap in seen:
        if not snap["finished"] and snap["connected"]:
            assert sorted(b[:3] for b in snap["buttons"]) == options[snap["seq"]][person], (person, snap)
            checked += 1
    assert checked > 20
    # the one plan left does the load with the holder and the robot
    task = load_task(joint_workers / "input" / "task.yaml")
    plan = next(p for p in generate_plans(task) if p.id == outs[-1]["plan"])
    assert task.crew("load", plan) == tuple(a for a in ("alice", "bob", "robot") if a in (holder, "robot"))
    assert {m["agent"] for m in ins if m.get("action") == "load"} == {holder, "robot"}
    assert outs[-1]["plan"] in {p["id"] for p in iter_plans(joint_workers)}
    _replays(joint_workers, console.log, outs)


# ------------------------------------------------------------------------------------------- hrc ros2

def _line(t: float, agent: str, action: str, event: str) -> dict[str, Any]:
    phase = {"carry": "put", "lift": "hold"}[action]
    return {"t": t, "agent": agent, "action": action, "phase": phase, "event": event}


# alice carries, then departs for the lift though the best plan had bob hold it; bob's departure for it
# afterwards is refused (no remaining plan's crew has him); the robot, at J, waits for alice's arrival
ROS_SCRIPT = [_line(0.5, "alice", "carry", "depart"), _line(2.0, "alice", "carry", "arrive"),
              _line(2.1, "alice", "carry", "start"), _line(3.5, "alice", "carry", "end"),
              _line(3.6, "alice", "lift", "depart"), _line(3.7, "bob", "lift", "depart"),
              _line(3.8, "robot", "lift", "depart"), _line(6.9, "robot", "lift", "arrive"),
              _line(8.0, "alice", "lift", "arrive"), _line(8.1, "robot", "lift", "start"),
              _line(11.5, "robot", "lift", "end")]


def test_ros2_follows_the_crew_that_came(hand_out: Path, tmp_path: Path) -> None:  # noqa: F811
    """The hand-worked case over a real rclpy node (tests/ros2_client.py's `TeamClient`), each line on
    its agent's own topic: the node is no longer refused; the best plan first has bob hold the lift, alice
    departs for it instead: the candidates narrow to her crew's plan, bob's departure for it is refused
    (by hand: no plan has both carry and the lift's hold by alice and bob holding too), the robot at J is
    told to wait for alice's arrival (not bob's), then starts; its goals are J, then home (its start S).
    The answers are those of the same lines through ``hrc dispatch``, byte for byte."""
    import signal
    import subprocess
    import sys

    from conftest import ROOT
    from ros2_client import NodeProcess, TeamClient, rclpy_or_skip, ros_env

    rclpy_or_skip()
    env = ros_env(tmp_path)
    node = NodeProcess(hand_out, env, "--log", str(tmp_path / "ros.log"), "--record", str(tmp_path / "ros.mcap"))
    client = None
    try:
        client = TeamClient(env, ("robot",), ("alice", "bob"))
        client.wait_matched()
        # the goal at the node's start (transient local: here before any message): the lift's spot J
        client.base.spin_until(lambda: len(client.goals["robot"]) == 1, 20, "the goal at the node's start")
        raw = [client.send(json.dumps(line)) for line in ROS_SCRIPT]
        client.base.spin_until(lambda: len(client.goals["robot"]) >= 2, 20, "the robot's home goal")
        client.base.spin_for(0.3)
        assert node.stop(signal.SIGTERM) == 0
    finally:
        if client is not None:
            client.close()
        node.kill()
    answers = [json.loads(a) for a in raw]
    ok = [a["ok"] for a in answers]
    assert ok == [True] * 5 + [False] + [True] * 5, answers
    assert "no remaining plan allows bob lift.hold depart" in answers[5]["error"]
    assert answers[3]["candidates"] == {"DC": 2, "consistent": 0, "inconsistent": 0}  # either may hold it
    assert answers[4]["candidates"] == {"DC": 1, "consistent": 0, "inconsistent": 0}  # alice's crew's plan
    assert answers[7]["robots"]["robot"] == {"wait_for": "alice.lift.hold.arrive"}
    assert answers[8]["robots"]["robot"]["event"] == "start"
    goals = [(round(g.pose.position.x, 6), round(g.pose.position.y, 6)) for g in client.goals["robot"]]
    assert goals == [(5.0, 2.0), (5.0, 0.5)]  # J, then home at S (the map of tests/test_crews.py)
    # the recording holds every goal the node sent, the home goal last, the same pose (the frame is hrc's map)
    from mcap_check import read_mcap

    pose = ("foxglove.PoseInFrame", "protobuf", "protobuf")
    rec = read_mcap(tmp_path / "ros.mcap", {f"/hrc/{a}/pose": pose for a in ("alice", "bob", "robot")}
                    | {"/hrc/robot/goal": pose})
    recorded = rec.of("/hrc/robot/goal")
    assert len(recorded) == len(client.goals["robot"]) == 2
    for r, g in zip(recorded, client.goals["robot"], strict=True):
        assert math.dist((r.pose.position.x, r.pose.position.y), (g.pose.position.x, g.pose.position.y)) < 1e-9
        q, w = r.pose.orientation, g.pose.orientation
        assert max(abs(q.x - w.x), abs(q.y - w.y), abs(q.z - w.z), abs(q.w - w.w)) < 1e-9
    stamp = client.goals["robot"][-1].header.stamp
    assert rec.times("/hrc/robot/goal")[-1] == pytest.approx(stamp.sec + stamp.nanosec / 1e9, abs=1e-6)
    stdin = "".join(json.dumps(line) + "\n" for line in ROS_SCRIPT).encode()
    plain = subprocess.run([sys.executable, "-m", "hrc", "dispatch", str(hand_out)], input=stdin,
                           capture_output=True, timeout=120, cwd=ROOT, env=dict(env, PYTHONPATH=str(ROOT)))
    assert plain.returncode == 0 and plain.stdout.decode().splitlines() == raw, plain.stderr


@pytest.mark.parametrize("seed", [5])
def test_ros2_runs_two_workers_joint_to_its_end(tmp_path_factory: pytest.TempPathFactory, tmp_path: Path,
                                                seed: int) -> None:
    """two_workers_joint over a real rclpy node, tests/team_client.py playing both people and the robot
    (random valid histories, nature's durations from the named plan's STNU): every answer accepted and
    byte for byte ``hrc dispatch``'s, the load done by one candidate and the robot (the crew of the plan
    left, `Task.crew`), the robot's goals the drives its answers name (`next_drive`), then home."""
    import random
    import signal
    import subprocess
    import sys

    from conftest import ROOT, compiled_folder
    from ros2_client import NodeProcess, TeamClient, rclpy_or_skip, ros_env
    from test_ros2_team import _OverRos

    from hrc.io.task_file import load_task
    from hrc.plans import generate_plans
    from hrc.ros2.drive import next_drive
    from hrc.temporal.graphml import read_graphml

    rclpy_or_skip()
    out = tmp_path_factory.getbasetemp() / "twj-ros" / "out"
    if not out.exists():
        out.parent.mkdir(exist_ok=True)
        compiled_folder(out, ROOT / "tasks" / "two_workers_joint.yaml", "--jobs", "1")
    task = load_task(out / "input" / "task.yaml")
    stnus = {p.stem: read_graphml(p.read_bytes()) for p in (out / "stnu").glob("*.graphml")}
    env = ros_env(tmp_path)
    node = NodeProcess(out, env, "--log", str(tmp_path / "ros.log"))
    client = None
    try:
        client = TeamClient(env, ("robot",), ("alice", "bob"))
        client.wait_matched()
        client.base.spin_until(lambda: len(client.goals["robot"]) == 1, 20, "the goal at the node's start")
        run = _OverRos(None, stnus, ("robot",), ("alice", "bob"), random.Random(seed))
        run.client = client
        run.play()
        home = task.workspace.location(task.agent("robot").start).xy
        client.base.spin_until(lambda: math.dist(_xy(client.goals["robot"][-1]), home) < 1e-9, 20, "home goal")
        client.base.spin_for(0.3)
        assert node.stop(signal.SIGTERM) == 0
    finally:
        if client is not None:
            client.close()
        node.kill()
    answers = client.answers
    assert len(answers) == len(run.sent) and all(json.loads(a)["ok"] for a in answers)
    stdin = "".join(line + "\n" for line in run.sent).encode()
    plain = subprocess.run([sys.executable, "-m", "hrc", "dispatch", str(out)], input=stdin, capture_output=True,
                           timeout=120, cwd=ROOT, env=dict(env, PYTHONPATH=str(ROOT)))
    assert plain.returncode == 0 and plain.stdout.decode().splitlines() == answers
    last = json.loads(answers[-1])
    plan = next(p for p in generate_plans(task) if p.id == last["plan"])
    crew = task.crew("load", plan)
    assert len(crew) == 2 and crew[1] == "robot"
    assert {json.loads(s)["agent"] for s in run.sent if json.loads(s).get("action") == "load"} == set(crew)
    expected, leg = [], None
    from hrc.compile.output import read_header as header_of
    from hrc.dispatch.plan_set import load_plan_set as plan_set_of

    routes = PlanRoutes(plan_motions(out, plan_set_of(out)), plan_paths(task, seed=int(header_of(out)["seed"])))
    for a in map(json.loads, answers):
        drive = next_drive(task, a, routes.routes(a["plan"]), "robot")
        if drive is not None and drive.leg != leg:
            leg = drive.leg
            expected.append(drive.target)
    got = [_xy(g) for g in client.goals["robot"]]
    assert len(got) == len(expected) + 1
    assert all(math.dist(g, e) < 1e-9 for g, e in zip(got[:-1], expected, strict=True))
    assert math.dist(got[-1], home) < 1e-9


def _xy(goal: Any) -> tuple[float, float]:
    return (goal.pose.position.x, goal.pose.position.y)


# ------------------------------------------------------------------------------- the motion detector

def _hand_folder(where: Path, change: Any = None) -> Path:
    """The hand-worked task (changed by `change`, if any) compiled by ``hrc compile`` into a folder."""
    import copy

    import yaml
    from test_crews import _write

    from hrc.cli import main

    task = copy.deepcopy(HAND)
    if change is not None:
        change(task)
    path = _write(where, task)
    assert main(["compile", str(path), "--out", str(where / "out"), "--no-report", "-q"]) == 0
    assert yaml.safe_load(path.read_text())["name"] == "hand"
    return where / "out"


def _walkers(out: Path, plan: dict[str, list[tuple[str, ...]]]) -> dict[str, Any]:
    """Each person's hand-made trace (tests/test_detect_team.py's `Walker`: the compile's own routes walked
    at 1 m/s, 5 cm of seeded noise, 10 Hz), from `plan`: per person, steps ``("stand", s)``, ``("walk",
    place)`` or ``("leg", action, phase, place, s)``; each stands on to the last one's end."""
    from types import SimpleNamespace

    from test_detect_team import Walker

    from hrc.io.task_file import load_task

    task = load_task(out / "input" / "task.yaml")
    cps = SimpleNamespace(paths=plan_paths(task, seed=int(read_header(out).get("seed", 0))))
    walkers = {p: Walker(cps, p, task.agent(p).start, 1.0, seed=k + 1) for k, p in enumerate(plan)}  # type: ignore[arg-type]
    for p, steps in plan.items():
        for step in steps:
            if step[0] == "stand":
                walkers[p].stand(float(step[1]))
            elif step[0] == "walk":
                walkers[p].walk(str(step[1]))
            else:
                walkers[p].leg(str(step[1]), str(step[2]), str(step[3]), float(step[4]))
    end = max(w.t for w in walkers.values()) + 1.0
    for w in walkers.values():
        w.stand(end - w.t)
    return walkers


def _tracked_run(out: Path, walkers: dict[str, Any]) -> tuple[Any, list[str], list[str]]:
    """Both people's positions in one stream by time, as JSON lines of ``hrc dispatch --detect motion``'s
    protocol, with the robot's controller acknowledging its steps in between (each event at the start of
    its window; a joint phase's end 3.5 s after its start, inside its bounds); every line through a
    `DetectingDispatcher` as `hrc.dispatch.protocol.handle_line` reads it. The dispatcher, the lines and
    their answers."""
    from hrc.detect import DetectingDispatcher, DetectParams
    from hrc.dispatch.protocol import handle_line

    d = DetectingDispatcher.from_folder(out, params=DetectParams())
    lines: list[str] = []
    answers: list[str] = []

    def send(msg: dict[str, Any]) -> dict[str, Any]:
        lines.append(json.dumps(msg))
        answers.append(handle_line(d, lines[-1]))
        out = json.loads(answers[-1])
        assert out["ok"] and not out.get("detect", {}).get("refused"), out
        return out

    def robot(t: float) -> None:
        while True:
            step = d.decision.robots["robot"]  # type: ignore[index]
            if isinstance(step, RobotStep) and step.earliest <= t:
                at, event = round(max(step.earliest, d.now), 3), step.event
            elif isinstance(step, WaitFor) and (step.agent, step.event) == ("robot", "end"):
                at, event = round(max(d.seen.times[("robot", step.action, step.phase, "start")] + 3.5, d.now), 3), "end"
                if at > t:
                    return
            else:
                return
            send({"t": at, "agent": "robot", "action": step.action, "phase": step.phase, "event": event})

    stream = sorted((t, k, p, x, y) for k, (p, w) in enumerate(walkers.items()) for t, x, y in w.samples)
    for t, _, person, x, y in stream:
        robot(t)
        send({"t": t, "agent": person, "event": "position", "x": x, "y": y})
    return d, lines, answers


def _given(lines: list[str], answers: list[str]) -> dict[str, list[tuple[float, str, str, str]]]:
    out: dict[str, list[tuple[float, str, str, str]]] = {"alice": [], "bob": []}
    for line, answer in zip(lines, answers, strict=True):
        detect = json.loads(answer).get("detect")
        if detect:
            who = json.loads(line)["agent"]
            out[who] += [(e["t"], e["event"], e["action"], e["phase"]) for e in detect["events"]]
    return out


def _same_through_the_cli(out: Path, lines: list[str], answers: list[str]) -> None:
    import subprocess
    import sys

    from conftest import ROOT

    run = subprocess.run([sys.executable, "-m", "hrc", "dispatch", str(out), "--detect", "motion"],
                         input="".join(x + "\n" for x in lines), capture_output=True, text=True, timeout=300,
                         cwd=ROOT)
    assert run.returncode == 0 and run.stdout.splitlines() == answers, run.stderr[-2000:]


def test_a_candidate_seen_walking_to_the_joint_spot_joins(tmp_path: Path) -> None:
    """The hand-worked case: alice carries at A, then walks to J and stands there while the lift is done;
    bob stands at B all along. The best plan has bob hold the lift until alice is seen leaving A for J:
    alice's departure and arrival are hers (within their stated spans of the truth), the plans narrow to
    her crew, the robot starts the lift after her arrival (not waiting for bob), and nothing is ever given
    as bob's. The same lines through ``hrc dispatch --detect motion``: the same answers, byte for byte."""
    out = _hand_folder(tmp_path)
    walkers = _walkers(out, {"alice": [("stand", 1.0), ("leg", "carry", "put", "A", 1.5),
                                       ("leg", "lift", "hold", "J", 5.0), ("walk", "H")],
                             "bob": []})
    d, lines, answers = _tracked_run(out, walkers)
    given = _given(lines, answers)
    truth = walkers["alice"].truth
    assert given["bob"] == []
    assert [g[1:] for g in given["alice"]] == [(e, a, p) for _, e, a, p in truth
                                               if not (a == "lift" and e in ("start", "end"))]  # the robot's
    for (t, e, a, p), g in zip(truth, given["alice"], strict=False):
        assert abs(g[0] - t) <= 1.0, (e, a, p, g[0], t)
    before = next(k for k, a in enumerate(answers) if any(e["action"] == "lift" for e in
                                                            json.loads(a).get("detect", {}).get("events", ())))
    from hrc.io.task_file import load_task
    from hrc.plans import generate_plans

    task = load_task(out / "input" / "task.yaml")
    plans = {p.id: p for p in generate_plans(task)}
    last = json.loads(answers[before - 1])
    assert sum(last["candidates"].values()) == 2  # both crews still open, and the best plan's is bob's
    assert task.crew("lift", plans[last["plan"]]) == ("bob", "robot")
    assert sum(json.loads(answers[before])["candidates"].values()) == 1  # alice's crew's plan alone
    times = d.seen.times
    assert times[("robot", "lift", "hold", "start")] >= times[("alice", "lift", "hold", "arrive")]
    assert not any(who == "bob" for (who, *_) in times)
    assert d.best is not None and dict(d.best.sequences)["alice"] == ("carry", "lift")
    _same_through_the_cli(out, lines, answers)
    # `hrc detect` on alice's positions alone (no robot, bob never seen): her same events, the lift's walk
    import contextlib
    import io

    from hrc.cli import main

    trace = tmp_path / "alice.jsonl"
    trace.write_text("".join(json.dumps({"t": t, "agent": "alice", "x": x, "y": y}) + "\n"
                             for t, x, y in walkers["alice"].samples))
    with contextlib.redirect_stdout(io.StringIO()) as printed:
        assert main(["detect", str(out), str(trace)]) == 0
    seen = [json.loads(x) for x in printed.getvalue().splitlines()]
    assert [(e["agent"], e["event"], e["action"], e["phase"]) for e in seen] == \
        [("alice", *g[1:]) for g in given["alice"]]


def test_a_candidate_seen_staying_at_the_joint_spot_joins(tmp_path: Path) -> None:
    """The hand-worked case with the carry at J (the part is put where it is lifted): bob walks from B to
    J, carries, and stays there; alice stands at H all along. Once bob's carry has ended, his staying at J
    is read as joining the lift (his departure and arrival given at once, no earlier than that end), the
    plans narrow to his crew, the robot starts the lift, and nothing is ever given as alice's."""
    def carry_at_j(task: dict[str, Any]) -> None:
        task["actions"][0]["phases"][0]["location"] = "J"

    out = _hand_folder(tmp_path, carry_at_j)
    walkers = _walkers(out, {"alice": [], "bob": [("stand", 0.5), ("leg", "carry", "put", "J", 1.5), ("stand", 12.0),
                                                   ("walk", "B")]})
    d, lines, answers = _tracked_run(out, walkers)
    given = _given(lines, answers)
    assert given["alice"] == []
    assert [g[1:] for g in given["bob"]] == [("depart", "carry", "put"), ("arrive", "carry", "put"),
                                             ("start", "carry", "put"), ("end", "carry", "put"),
                                             ("depart", "lift", "hold"), ("arrive", "lift", "hold")]
    end, depart, arrive = (g[0] for g in given["bob"][3:])
    assert end <= depart == arrive <= end + 1.0
    times = d.seen.times
    assert times[("robot", "lift", "hold", "start")] >= times[("bob", "lift", "hold", "arrive")]
    assert not any(who == "alice" for (who, *_) in times)
    assert d.best is not None and dict(d.best.sequences)["bob"] == ("carry", "lift")
    assert times[("robot", "lift", "hold", "end")] > times[("robot", "lift", "hold", "start")]
    _same_through_the_cli(out, lines, answers)


def test_the_console_with_the_motion_detector_follows_the_crew_seen(tmp_path: Path) -> None:
    """``hrc console --detect motion``'s session fed the lines of the walking run above as a tracker and
    the robot's controller send them (positions on the robot's link, each naming its person; acks): the
    console logs the same messages with the same answers, byte for byte; once alice was seen leaving for
    J, bob's page is never offered the lift, and the lift is drawn under alice and the robot."""
    from hrc.detect import DetectingDispatcher, DetectParams
    from hrc.dispatch.logfile import read_log

    out = _hand_folder(tmp_path)
    walkers = _walkers(out, {"alice": [("stand", 1.0), ("leg", "carry", "put", "A", 1.5),
                                       ("leg", "lift", "hold", "J", 5.0), ("walk", "H")],
                             "bob": []})
    _, lines, answers = _tracked_run(out, walkers)
    plan_set = load_plan_set(out)
    d = DetectingDispatcher(plan_set, params=DetectParams())
    s = ConsoleSession(LoggedDispatcher.create(d, tmp_path / "console.jsonl"), read_header(out),
                       PlanRoutes(plan_motions(out, plan_set), plan_paths(plan_set.task, seed=0)), RunClock(1.0))
    clock = [0.0]
    s.clock.now = lambda: clock[0]  # type: ignore[method-assign]  # the run's time: the stream's
    joined = False
    offered_after: list[str] = []
    for line in lines:
        msg = json.loads(line)
        clock[0] = max(clock[0], msg["t"])
        if msg["event"] == "position":
            reply = s.robot_message({"type": "position", **{k: msg[k] for k in ("agent", "t", "x", "y")}},
                                    robot="robot")
        else:
            reply = s.robot_message({"type": "ack", **{k: msg[k] for k in ("t", "action", "phase", "event")}},
                                    robot="robot")
        assert reply["ok"], reply
        state = s.state()
        joined = joined or ("alice", "lift", "hold", "depart") in s.dispatcher.seen.times
        if joined:
            offered_after += [o["action"] for o in state["persons"]["bob"]["options"]]
    s.logged.close()
    logged = read_log(tmp_path / "console.jsonl").messages
    assert [json.loads(m.data) for m in logged] == [json.loads(x) for x in lines]
    assert [m.answer for m in logged] == answers  # byte for byte
    assert joined and "lift" not in offered_after
    assert s.crews()["lift"] == ("alice", "robot")
    work = {b["agent"] for b in state["gantt"]["actual"] if b["action"] == "lift" and b["kind"] == "work"}
    assert work == {"alice", "robot"} and state["finished"]
    assert ("lift", "hold", "arrive") in {(e["action"], e["phase"], e["event"]) for e in
                                          state["persons"]["alice"]["detected"]}


def test_ros2_with_the_motion_detector_follows_the_crew_seen(tmp_path: Path) -> None:
    """``hrc ros2 --detect motion`` over a real rclpy node: the walking run above, each person's tracked
    poses on their own ``PERSON/pose`` and the robot's acks on ``robot/acks``: every answer is the
    protocol's on the same lines, byte for byte (alice joins the lift, bob is never given anything), and
    the node's log replays through ``hrc dispatch --detect motion`` to the same answers."""
    import signal
    import subprocess
    import sys

    from conftest import ROOT
    from ros2_client import NodeProcess, TeamClient, rclpy_or_skip, ros_env

    rclpy_or_skip()
    out = _hand_folder(tmp_path)
    walkers = _walkers(out, {"alice": [("stand", 1.0), ("leg", "carry", "put", "A", 1.5),
                                       ("leg", "lift", "hold", "J", 5.0), ("walk", "H")],
                             "bob": []})
    for w in walkers.values():  # a pose's position as the node reads it (to the millimetre)
        w.samples = [(t, round(x, 3), round(y, 3)) for t, x, y in w.samples]
    _, lines, answers = _tracked_run(out, walkers)
    env = ros_env(tmp_path)
    log = tmp_path / "ros.log"
    node = NodeProcess(out, env, "--log", str(log), "--detect", "motion")
    client = None
    try:
        client = TeamClient(env, ("robot",), ("alice", "bob"))
        client.wait_matched()
        got = []
        for line in lines:
            msg = json.loads(line)
            if msg["event"] == "position":
                got.append(client.send_pose(msg["agent"], msg["t"], msg["x"], msg["y"]))
            else:
                got.append(client.send(line))
        assert node.stop(signal.SIGTERM) == 0
    finally:
        if client is not None:
            client.close()
        node.kill()
    assert got == answers
    assert {e[1:] for e in _given(lines, got)["alice"]} >= {("depart", "lift", "hold"), ("arrive", "lift", "hold")}
    assert _given(lines, got)["bob"] == []
    replayed = subprocess.run([sys.executable, "-m", "hrc", "dispatch", str(out), "--detect", "motion", "--replay",
                               str(log)], capture_output=True, text=True, timeout=300, cwd=ROOT,
                              env=dict(env, PYTHONPATH=str(ROOT)))
    assert replayed.returncode == 0 and replayed.stdout.splitlines() == answers, replayed.stderr[-2000:]
