"""``hrc ros2`` for a team (issue 37): one goal topic per robot under its id, each person's observations on
their own topic, driven by a real rclpy node over loopback (tests/ros2_client.py's `TeamClient`).

kitting_2robots cut to three picks (one person, two robots): an independent client (tests/team_client.py)
plays the person and both robot controllers with random valid histories, every line on its agent's own
topic (``/hrc/human/observations``, ``/hrc/robot/acks``, ``/hrc/robot2/acks``); the answers are those of
the same lines through ``hrc dispatch``, byte for byte, the log replays, and each robot's goals on
``/hrc/ROBOT/goal`` are exactly the drives its entries of the answers name (`next_drive`), in the frame asked
for; its ``--record`` is the same bytes as ``hrc dispatch --record``'s. A line on an agent's own topic that
names another agent is refused in one line and never logged.

With ``--detect motion`` (two people, one robot): each person's tracked poses on their own
``/hrc/PERSON/pose`` feed their own detector, the answers those of ``hrc dispatch --detect motion`` and each
person's events exactly their truth (tests/test_detect_team.py's hand-made traces).

Skipped with the reason where rclpy cannot be imported (as tests/test_ros2.py).
"""

from __future__ import annotations

import json
import math
import os
import random
import signal
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest
from conftest import ROOT, compiled_folder
from team_client import TeamRun
from test_console_team import kitting3_task

from hrc.compile.output import read_header
from hrc.dispatch import Dispatcher
from hrc.dispatch.plan_set import load_plan_set
from hrc.dispatch.protocol import answer as answer_line
from hrc.dispatch.routes import PlanRoutes, plan_motions
from hrc.motion import plan_paths
from hrc.ros2.drive import MapFrame, next_drive
from hrc.temporal.graphml import read_graphml

ORIGIN = (2.0, -1.0, math.pi / 2)


@pytest.fixture(scope="module")
def kitting3(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from ros2_client import rclpy_or_skip

    rclpy_or_skip()
    where = tmp_path_factory.mktemp("k3")
    return compiled_folder(where / "out", kitting3_task(where), "--jobs", "1")


def _dispatch(folder: Path, *args: str, stdin: bytes = b"") -> subprocess.CompletedProcess[bytes]:
    return subprocess.run([sys.executable, "-m", "hrc", "dispatch", str(folder), *args], input=stdin,
                          capture_output=True, timeout=120, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)))


class _OverRos(TeamRun):
    """The team client's run, each line published on its agent's own topic of the node."""

    client: object = None

    def send(self, message: dict) -> dict:
        line = json.dumps(message)
        self.sent.append(line)
        out = json.loads(self.client.send(line))  # type: ignore[attr-defined]
        self.answers.append(out)
        return out


def test_a_team_run_over_ros2_has_a_goal_topic_per_robot(kitting3: Path, tmp_path: Path) -> None:
    from ros2_client import NodeProcess, TeamClient, ros_env

    plan_set = load_plan_set(kitting3)
    task = plan_set.task
    robots = tuple(a.id for a in task.agents if not a.is_human)
    people = tuple(a.id for a in task.agents if a.is_human)
    assert robots == ("robot", "robot2") and people == ("human",)
    stnus = {p.stem: read_graphml(p.read_bytes()) for p in (kitting3 / "stnu").glob("*.graphml")}
    env = ros_env(tmp_path)
    frame = MapFrame("map", *ORIGIN)
    log, recording = tmp_path / "ros.log", tmp_path / "ros.mcap"
    node = NodeProcess(kitting3, env, "--log", str(log), "--record", str(recording), "--map-origin",
                       *(str(v) for v in ORIGIN))
    client = None
    refused: list[str] = []
    try:
        client = TeamClient(env, robots, people)
        client.wait_matched()
        # an agent's own topic takes that agent's lines only: refused in one line, never logged
        for topic, line in (("robot2", {"t": 0, "agent": "robot", "action": "pick_a", "phase": "fetch",
                                        "event": "depart"}),
                            ("human", {"t": 0, "event": "tick"}), ("robot", "not json")):
            text = line if isinstance(line, str) else json.dumps(line)
            out = json.loads(client.send(text, topic))
            assert not out["ok"] and f"must be {topic}'s" in out["error"], out
            refused.append(text)
        # a person's own pose topic without --detect motion: refused in one line, never logged
        out = json.loads(client.send_pose("human", 0.5, 1.0, 1.0))
        assert not out["ok"] and out["error"].startswith("human/pose: the person's pose needs the motion detector")
        refused.append("pose")
        # the goals the node published at its start are here before any message (transient local): the
        # client's goal subscriptions are matched on the node's side too (tests/ros2_client.py)
        start = Dispatcher(plan_set).decision.to_json()
        first = {r for r in robots if next_drive(task, start, None, r) is not None}
        client.base.spin_until(lambda: all(client.goals[r] for r in first), 20, "the goals at the node's start")
        run = _OverRos(None, stnus, robots, people, random.Random(5))
        run.client = client
        run.play()
        # after its last phase each robot is sent home: one goal at its start (then nothing more)
        homes = {r: frame.to_frame(*task.workspace.location(task.agent(r).start).xy) for r in robots}
        client.base.spin_until(lambda: all(client.goals[r] and _at(client.goals[r][-1], homes[r]) and client.routes[r]
                                           and len(client.routes[r]) == len(client.goals[r]) for r in robots),
                               20, "each robot's home goal")
        client.base.spin_for(0.5)
        assert node.stop(signal.SIGTERM) == 0
    finally:
        if client is not None:
            client.close()
        node.kill()
    answers = client.answers[len(refused):]
    assert len(answers) == len(run.sent) and all(json.loads(a)["ok"] for a in answers)
    assert f"stopped by SIGTERM after {len(run.sent)} messages" in node.stderr(), node.stderr()
    # the same lines through hrc dispatch: the same answers, byte for byte; the log holds those alone
    stdin = "".join(line + "\n" for line in run.sent).encode()
    plain = _dispatch(kitting3, "--record", str(tmp_path / "dispatch.mcap"), stdin=stdin)
    assert plain.returncode == 0 and plain.stdout.decode().splitlines() == answers
    assert recording.read_bytes() == (tmp_path / "dispatch.mcap").read_bytes()  # the same recording
    replayed = _dispatch(kitting3, "--replay", str(log))
    assert replayed.returncode == 0 and replayed.stdout == plain.stdout, replayed.stderr
    # each robot's goals: the drives its entries of the answers name, one per new drive, in the frame asked,
    # and last the way home from its last phase's location (the compile's planned path, read here directly)
    paths = plan_paths(task, seed=int(read_header(kitting3)["seed"]))
    routes = PlanRoutes(plan_motions(kitting3, plan_set), paths)
    done = Dispatcher(plan_set)
    for line in run.sent:
        assert json.loads(answer_line(done, line.encode()))["ok"]
    for r in robots:
        expected, last = [], None
        for a in map(json.loads, answers):
            drive = next_drive(task, a, routes.routes(a["plan"]), r)
            if drive is not None and drive.leg != last:
                last = drive.leg
                expected.append(drive)
        got, home, way = client.goals[r][:-1], client.goals[r][-1], client.routes[r][-1]
        assert len(got) == len(expected) == len(client.routes[r]) - 1 >= 1, (r, len(got), len(expected))
        last = [o for o in done.history if o.agent == r and o.action is not None][-1]
        assert last.event == "end"  # the run ended every phase of the robot's
        there = task.action(last.action).phase(last.phase).location
        want_way = [frame.to_frame(*p) for p in paths.get(r, there, task.agent(r).start).points]
        assert _at(home, homes[r]) and home.header.frame_id == way.header.frame_id == "map"
        assert len(way.poses) == len(want_way) >= 1
        assert all(math.dist((q.position.x, q.position.y), w) < 2e-3 for q, w in zip(way.poses, want_way, strict=True))
        assert home.header.stamp.sec + home.header.stamp.nanosec / 1e9 >= last.t  # named when it was done
        for goal, drive in zip(got, expected, strict=True):
            want = frame.to_frame(*drive.target)
            assert goal.header.frame_id == "map"
            assert math.dist((goal.pose.position.x, goal.pose.position.y), want) < 1e-9
    # both robots drove: the run gave each some pick
    assert all(client.goals[r] for r in robots)


def _at(goal: object, xy: tuple[float, float]) -> bool:
    p = goal.pose.position  # type: ignore[attr-defined]
    return math.dist((p.x, p.y), xy) < 1e-9


# ------------------------------------------------------------------------------ the motion detector per person
@pytest.fixture(scope="module")
def two(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """tests/test_detect_team.py's two people (Alice, Bob) and one robot on the kitting cell, compiled."""
    import yaml
    from ros2_client import rclpy_or_skip
    from test_detect_team import TASK

    rclpy_or_skip()
    where = tmp_path_factory.mktemp("two")
    (where / "task.yaml").write_text(yaml.safe_dump(TASK, sort_keys=False), "utf-8")
    return compiled_folder(where / "out", where / "task.yaml", "--jobs", "1")


def test_each_persons_pose_topic_feeds_their_own_detector(two: Path, tmp_path: Path) -> None:
    """tests/test_detect_team.py's hand-made traces (Alice and Bob walking at once, 5 cm of noise; here 5 a
    second each), each person's as poses on their own ``/hrc/PERSON/pose`` in a rotated, shifted frame,
    published by a real rclpy node: every answer is that of ``hrc dispatch --detect motion`` on the same
    positions (each naming its person) byte for byte, each answer's events are the person's whose pose it
    was and, put together, exactly their true events in order; the node's log replays to the same
    answers. A pose in another frame is refused in one line and never logged."""
    from ros2_client import NodeProcess, TeamClient, ros_env
    from test_detect_team import interleaved, traces

    task = load_plan_set(two).task
    walkers = traces(SimpleNamespace(paths=plan_paths(task, seed=int(read_header(two).get("seed", 0)))))
    frame = MapFrame("map", *ORIGIN)
    stream = [(t, p, round(x, 3), round(y, 3)) for t, _, p, x, y in interleaved(walkers) if round(t * 10) % 2 == 0]
    lines = [json.dumps({"t": t, "agent": p, "event": "position", "x": x, "y": y}) for t, p, x, y in stream]
    detect = ("--detect", "motion")
    expected = _dispatch(two, *detect, stdin="".join(x + "\n" for x in lines).encode())
    assert expected.returncode == 0, expected.stderr
    env = ros_env(tmp_path)
    log = tmp_path / "run.log"
    node = NodeProcess(two, env, "--log", str(log), "--map-origin", *(str(v) for v in ORIGIN), *detect)
    client = None
    got: list[str] = []
    try:
        client = TeamClient(env, ("robot",), ("alice", "bob"))
        client.wait_matched()
        refusal = json.loads(client.send_pose("bob", 0.0, 1.0, 1.0, frame_id="odom"))
        assert not refusal["ok"] and refusal["error"].startswith("bob/pose: a pose in frame 'odom'"), refusal
        for t, p, x, y in stream:
            got.append(client.send_pose(p, t, *frame.to_frame(x, y)))
        assert node.stop(signal.SIGTERM) == 0
    finally:
        if client is not None:
            client.close()
        node.kill()
    assert got == expected.stdout.decode().splitlines()
    events: dict[str, list[tuple[str, str, str]]] = {"alice": [], "bob": []}
    for (_, p, _, _), answer in zip(stream, map(json.loads, got), strict=True):
        assert answer["ok"] and answer["detect"]["agent"] == p
        events[p] += [(e["event"], e["action"], e["phase"]) for e in answer["detect"]["events"] if e["event"] != "undo"]
    for p, w in walkers.items():
        assert events[p] == [(e, a, ph) for _, e, a, ph in w.truth], p
    replayed = _dispatch(two, *detect, "--replay", str(log))
    assert replayed.returncode == 0 and replayed.stdout == expected.stdout, replayed.stderr
