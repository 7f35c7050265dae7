"""``hrc ros2``: the dispatcher as a ROS 2 node, driven by real rclpy nodes over loopback (tests/ros2_client.py:
a ROS_DOMAIN_ID per test, discovery limited to this machine, Fast DDS over UDP).

- a whole workshop run, the test's node playing the person's detector and the robot controller (bad
  lines among its messages): the same answers as the same lines through ``hrc dispatch``, a log that
  replays byte for byte, the same MCAP recording, goals and routes for Nav2 in the frame asked for, the
  latest answer and goal for a subscriber that comes late, a clean stop on SIGTERM;
- SIGINT in the middle, then ``--resume``: the whole run answered as uninterrupted (and recorded whole);
  poses refused in one line (no motion detector asked for; a pose in another frame) and never in the log;
- ``--detect motion``: a recorded noisy run's poses drive the detector as they drive ``hrc dispatch``;
- ``--use-sim-time``: ticks from ``/clock``, goals stamped with it;
- without the extra, one line that says how to install it; bad options in one line.

These skip with the reason where rclpy cannot be imported (``pip install -e '.[test,ros2]'``), and fail
instead under HRC_REQUIRE_ROS2=1 (as .ci/run sets).
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT, compiled_folder
from dispatch_client import Run
from mcap_check import read_mcap

from hrc.cli import main
from hrc.compile.output import read_header
from hrc.dispatch import Dispatcher
from hrc.dispatch.limits import MAX_LINE
from hrc.dispatch.messages import Observation
from hrc.dispatch.plan_set import load_plan_set
from hrc.dispatch.protocol import answer
from hrc.motion import plan_paths
from hrc.ros2.drive import HOME, MapFrame, home_drive, next_drive

ORIGIN = (2.0, -1.0, math.pi / 2)  # hrc's map in the ROS frame: a quarter turn, shifted


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return compiled_folder(tmp_path_factory.mktemp("ros2") / "ws")


def _dispatch(folder: Path, *args: str, stdin: bytes = b"") -> subprocess.CompletedProcess[bytes]:
    return subprocess.run([sys.executable, "-m", "hrc", "dispatch", str(folder), *args], input=stdin,
                          capture_output=True, timeout=120, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)))


def test_without_the_extra_it_says_how_to_install_it(folder: Path) -> None:
    code = ("import sys; sys.modules['rclpy'] = None; from hrc.cli import main; "
            f"sys.exit(main(['ros2', {str(folder)!r}]))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=ROOT,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert done.returncode == 2 and done.stdout == "", done
    assert done.stderr.count("\n") == 1 and "pip install 'hrc[ros2]'" in done.stderr, done.stderr


def test_bad_options_get_one_line(folder: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["ros2", str(folder), "--tick", "2"]) == 2
    assert "--tick needs --use-sim-time" in capsys.readouterr().err
    assert main(["ros2", str(folder), "--log", "a", "--resume", "b"]) == 2
    assert "cannot be used together" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:
        main(["ros2", str(folder), "--map-origin", "1", "nan", "0"])
    assert stop.value.code == 2 and capsys.readouterr().err.count("\n") == 1


def test_a_refused_namespace_leaves_no_log_nor_recording(folder: Path, tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    from ros2_client import rclpy_or_skip

    rclpy_or_skip()
    assert main(["ros2", str(folder), "--namespace", "bad name", "--log", str(tmp_path / "run.log"), "--record",
                 str(tmp_path / "run.mcap")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Invalid namespace" in err, err
    assert list(tmp_path.iterdir()) == []


def test_map_frame_and_next_drive(folder: Path) -> None:
    frame = MapFrame("map", *ORIGIN)
    for p in [(0.0, 0.0), (3.5, 6.7), (-1.0, 2.5)]:
        q = frame.from_frame(*frame.to_frame(*p))
        assert math.dist(p, q) < 1e-12
    assert all(math.isclose(a, b, abs_tol=1e-12) for a, b in zip(frame.to_frame(1.0, 0.0), (2.0, 0.0), strict=True))
    task = load_plan_set(folder).task
    step = {"action": "cube2", "phase": "fetch", "event": "depart", "earliest": 3.0, "latest": None}
    drive = next_drive(task, {"ok": True, "robot": step})
    assert drive is not None and drive.location == "S2" and drive.target == (3.5, 6.7) and drive.points == ()
    legs = {"robot": [{"action": "cube2", "phase": "fetch", "points": [[9.0, 1.0], [8.0, 6.0], [3.5, 6.7]],
                       "park": None}]}
    drive = next_drive(task, {"ok": True, "robot": step}, legs)
    assert drive is not None and drive.points[0] == (9.0, 1.0) and drive.points[-1] == drive.target
    parked = {"robot": [{"action": "cube2", "phase": "fetch", "points": [[8.0, 3.0], [9.0, 1.0], [3.5, 6.7]],
                         "park": "R"}]}
    first = next_drive(task, {"ok": True, "robot": step}, parked)
    then = next_drive(task, {"ok": True, "robot": dict(step, event="unpark")}, parked)
    assert first is not None and first.location == "R" and first.points == ((8.0, 3.0), (9.0, 1.0))
    assert then is not None and then.location == "S2" and then.points == ((9.0, 1.0), (3.5, 6.7))
    for told in ({"wait_for": "human.cube1.fetch.depart"}, dict(step, event="start"), None):
        assert next_drive(task, {"ok": True, "robot": told}) is None
    assert next_drive(task, {"ok": False, "error": "x"}) is None


def test_home_drive_after_the_last_phase_only(folder: Path) -> None:
    """Hand-worked on the workshop (robot starts at R (9, 1)): the robot is sent home when its step is null
    after the end of a phase, along the way it is given; never when it was stopped, while a fallback holds
    it, before it ended a phase, or when it still has a step; while the person is away it is (the robot
    finished alone: it clears the floor, as in the simulator)."""
    task = load_plan_set(folder).task
    done = (*(Observation(t, e, "robot", "cube2", "fetch") for t, e in ((3.0, "depart"), (9.0, "arrive"),
                                                                          (9.5, "start"), (12.0, "end"))),
            Observation(13.0, "end", "human", "cube1", "fetch"))
    out = {"t": 13.0, "ok": True, "plan": "p", "robot": None, "human": None, "human_away": False, "stopped": False}
    ways: list[tuple[str, str, str]] = []

    def way(agent: str, origin: str, target: str) -> list[list[float]]:
        ways.append((agent, origin, target))
        return [[3.5, 6.7], [8.0, 3.0], [9.0, 1.0]]

    home = home_drive(task, out, done, None, way)
    assert home is not None and ways == [("robot", "S2", "R")]  # from cube2.fetch's place to its start
    assert (home.event, home.location, home.target, home.leg) == (HOME, "R", (9.0, 1.0), ("cube2", "fetch", HOME))
    assert home.points == ((3.5, 6.7), (8.0, 3.0), (9.0, 1.0)) and home.earliest == 13.0 and home.latest is None
    assert math.isclose(home.heading, math.atan2(-2.0, 1.0))
    bare = home_drive(task, out, done)  # no ways known: the pose alone
    assert bare is not None and bare.target == (9.0, 1.0) and bare.points == () and bare.heading == 0.0
    assert home_drive(task, out | {"human_away": True}, done, None, way) == home
    for held in ({"stopped": True}, {"fallback": "wait"}, {"ok": False},
                 {"robot": {"wait_for": "human.cube3.fetch.depart"}}):
        assert home_drive(task, out | held, done, None, way) is None, held
    assert home_drive(task, out, done[:3], None, way) is None  # its phase under way: not done
    assert home_drive(task, out, (), None, way) is None  # it never left its start
    # a team's robot: its own entry of robots; a person away does not hold it
    team = {"t": 13.0, "ok": True, "plan": "p", "robots": {"robot": None}, "people": {"human": None}, "away": [],
            "stopped": False}
    assert home_drive(task, team, done, "robot", way) is not None
    assert home_drive(task, team | {"away": ["human"]}, done, "robot", way) is not None
    assert home_drive(task, team | {"robots": {}}, done, "robot", way) is None


def _bad_lines() -> list[str]:
    return ["not json", "x" * (MAX_LINE + 10), '{"t": 0.1, "agent": "human", "action": "cube9", "phase": "fetch", '
            '"event": "start"}']


def test_a_whole_workshop_run_over_ros2_answers_as_hrc_dispatch(folder: Path, tmp_path: Path) -> None:
    from ros2_client import Client, NodeProcess, ros_env

    env = ros_env(tmp_path)
    log, path = tmp_path / "ros.log", tmp_path / "ros.mcap"
    node = NodeProcess(folder, env, "--log", str(log), "--record", str(path), "--map-origin",
                       *(str(v) for v in ORIGIN))
    task = load_plan_set(folder).task
    frame = MapFrame("map", *ORIGIN)
    home = frame.to_frame(*task.workspace.location(task.agent("robot").start).xy)
    client = late = None
    try:
        client = Client(env)
        client.wait_matched()
        bad = iter(_bad_lines())

        def send(line: str) -> str:
            if len(client.sent) % 7 == 3:
                extra = next(bad, None)
                if extra is not None:
                    assert not json.loads(client.send(extra))["ok"]
            return client.send(line)

        Run(load_plan_set(folder), send, 7, human_choice="plan", timing="hinted").play()
        assert len(client.sent) > 40 and len(client.answers) == len(client.sent)
        assert all(b in client.sent for b in _bad_lines())
        # after its last phase the robot is sent home, once (its start R, in the frame asked for)
        client.spin_until(lambda: client.goals and _at(client.goals[-1], home) and len(client.routes) ==
                          len(client.goals), 20, "the robot's home goal")
        client.spin_for(0.5)
        # a subscriber that comes late gets the latest answer and goal (the way home)
        late = Client(env)
        late.spin_until(lambda: late.answers and late.goals, 20, "the latest answer and goal")
        assert late.answers == client.answers[-1:]
        assert late.goals[-1].pose == client.goals[-1].pose
        assert node.stop(signal.SIGTERM) == 0
    finally:
        for c in (client, late):
            if c is not None:
                c.close()
        node.kill()
    assert f"stopped by SIGTERM after {len(client.sent)} messages" in node.stderr(), node.stderr()
    # the same lines through hrc dispatch: the same answers, byte for byte, and the same recording
    stdin = "".join(line + "\n" for line in client.sent).encode()
    plain = _dispatch(folder, "--record", str(tmp_path / "dispatch.mcap"), stdin=stdin)
    assert plain.returncode == 0 and plain.stdout.decode().splitlines() == client.answers
    assert path.read_bytes() == (tmp_path / "dispatch.mcap").read_bytes()
    # the node's log replays byte for byte
    replayed = _dispatch(folder, "--replay", str(log))
    assert replayed.returncode == 0 and replayed.stdout == plain.stdout, replayed.stderr
    # the goals: where the robot departed for, in the frame asked for; each route ends at its goal; then
    # home, along the compile's planned way from the robot's last phase (the end it acknowledged last)
    drives = [json.loads(x) for x in client.sent if '"agent": "robot"' in x and '"depart"' in x]
    assert len(client.goals) == len(drives) + 1 == len(client.routes) >= 3
    last = [json.loads(x) for x in client.sent if '"agent": "robot"' in x][-1]
    assert last["event"] == "end"
    there = task.action(last["action"]).phase(last["phase"]).location
    way = [frame.to_frame(*p) for p in plan_paths(task, seed=int(read_header(folder)["seed"])).get(
        "robot", there, "R").points]
    assert len(client.routes[-1].poses) == len(way) >= 2
    assert all(math.dist((q.position.x, q.position.y), w) < 2e-3 for q, w in zip(client.routes[-1].poses, way,
                                                                               strict=True))
    assert _at(client.goals[-1], home) and client.goals[-1].header.stamp.sec >= int(last["t"])
    for goal, route, d in zip(client.goals, client.routes, drives, strict=False):
        want = frame.to_frame(*task.workspace.location(task.action(d["action"]).phase(d["phase"]).location).xy)
        got = (goal.pose.position.x, goal.pose.position.y)
        assert goal.header.frame_id == "map" and math.dist(got, want) < 1e-9
        assert route.header.frame_id == "map" and len(route.poses) >= 2
        assert math.dist((route.poses[-1].position.x, route.poses[-1].position.y), want) < 1e-6
    # stamped with the run time of the answer that named the drive, never the wall clock
    goal_times = [g.header.stamp.sec + g.header.stamp.nanosec / 1e9 for g in client.goals]
    assert all(t < 600 for t in goal_times) and goal_times == sorted(goal_times)
    # the recording: the answers' drives, then the way home (the goal the node sent last, in hrc's map)
    recorded = read_mcap(path).of("/hrc/robot/goal")
    assert len(recorded) == len(drives) + 1
    start = task.workspace.location(task.agent("robot").start).xy
    assert math.dist((recorded[-1].pose.position.x, recorded[-1].pose.position.y), start) < 1e-9


def _at(goal: object, xy: tuple[float, float]) -> bool:
    p = goal.pose.position  # type: ignore[attr-defined]
    return math.dist((p.x, p.y), xy) < 1e-9


def test_sigint_then_resume_and_poses_refused(folder: Path, tmp_path: Path) -> None:
    from ros2_client import Client, NodeProcess, ros_env

    fresh = Dispatcher.from_folder(folder)
    lines: list[str] = []
    expected: list[str] = []

    def send(line: str) -> str:
        lines.append(line)
        expected.append(answer(fresh, line.encode()))
        return expected[-1]

    Run(load_plan_set(folder), send, 8, human_choice="plan", timing="hinted").play()
    half = len(lines) // 2
    env = ros_env(tmp_path)
    log = tmp_path / "run.log"
    got: list[str] = []
    task = load_plan_set(folder).task
    start = task.workspace.location(task.agent("robot").start).xy
    node = NodeProcess(folder, env, "--log", str(log))
    client = Client(env)
    try:
        client.wait_matched()
        got += [client.send(line) for line in lines[:half]]
        for frame_id in ("odom", "map"):  # refused in one line here, never given to the dispatcher
            pose = client.PoseStamped()
            pose.header.frame_id = frame_id
            pose.header.stamp.sec = 30
            pose.pose.position.x = 1.0
            before = len(client.answers)
            client.poses.publish(pose)
            client.spin_until(lambda b=before: len(client.answers) > b, 20, "the pose's refusal")
            refusal = json.loads(client.answers[-1])
            assert refusal == {"t": 30.0, "ok": False, "error": refusal["error"]}
            assert ("frame 'odom'" in refusal["error"]) == (frame_id == "odom")
            assert ("motion detector" in refusal["error"]) == (frame_id == "map")
        client.spin_for(0.5)
        assert client.goals and not _at(client.goals[-1], start)  # stopped half way: no way home
        assert node.stop(signal.SIGINT) == 0
    finally:
        client.close()
        node.kill()
    assert "stopped by SIGINT" in node.stderr() and node.stderr().count("motion detector") == 1, node.stderr()
    resumed = NodeProcess(folder, env, "--resume", str(log), "--record", str(tmp_path / "whole.mcap"))
    client = Client(env)
    try:
        client.wait_matched()
        got += [client.send(line) for line in lines[half:]]
        client.spin_until(lambda: client.goals and _at(client.goals[-1], start), 20, "the way home after the run")
        assert resumed.stop(signal.SIGTERM) == 0
    finally:
        client.close()
        resumed.kill()
    assert f"resumed {log} after {half} messages" in resumed.stderr()
    assert got == expected
    replayed = _dispatch(folder, "--replay", str(log), "--record", str(tmp_path / "replayed.mcap"))
    assert replayed.returncode == 0 and replayed.stdout.decode().splitlines() == expected
    # the resumed node's recording holds the whole run, as the one made from the log
    assert (tmp_path / "whole.mcap").read_bytes() == (tmp_path / "replayed.mcap").read_bytes()
    assert read_mcap(tmp_path / "whole.mcap").counts["/hrc/in"] == len(lines)


def test_poses_drive_the_motion_detector_as_they_drive_hrc_dispatch(folder: Path, tmp_path: Path) -> None:
    """A recorded noisy workshop run (tests/data/detect): the person's positions as poses in a rotated,
    shifted frame, the robot's messages as strings; the answers are those of ``hrc dispatch --detect
    motion`` on the same stream, and the node's log replays there byte for byte."""
    from ros2_client import Client, NodeProcess, ros_env

    frame = MapFrame("map", *ORIGIN)
    trace = ROOT / "tests" / "data" / "detect" / "workshop_015_5hz_drop5.trace.jsonl"
    stream = []  # what the node makes of each: positions in mm (as it rounds them), other messages as they are
    for msg in map(json.loads, trace.read_text().splitlines()):
        if "event" not in msg:
            msg = {"t": msg["t"], "agent": "human", "event": "position", "x": round(msg["x"], 3),
                   "y": round(msg["y"], 3)}
        stream.append(msg)
    detect = ("--detect", "motion", "--sensor-sigma", "0.15")
    expected = _dispatch(folder, *detect, stdin="".join(json.dumps(m) + "\n" for m in stream).encode())
    assert expected.returncode == 0, expected.stderr
    env = ros_env(tmp_path)
    log = tmp_path / "run.log"
    node = NodeProcess(folder, env, "--log", str(log), "--map-origin", *(str(v) for v in ORIGIN), *detect)
    client = Client(env)
    got = []
    try:
        client.wait_matched()
        for msg in stream:
            if msg.get("event") != "position":
                got.append(client.send(json.dumps(msg)))
                continue
            pose = client.PoseStamped()
            pose.header.frame_id = "map"
            pose.header.stamp.sec = int(msg["t"])
            pose.header.stamp.nanosec = round((msg["t"] - int(msg["t"])) * 1e9)
            pose.pose.position.x, pose.pose.position.y = frame.to_frame(msg["x"], msg["y"])
            before = len(client.answers)
            client.poses.publish(pose)
            client.spin_until(lambda b=before: len(client.answers) > b, 20, f"the answer to the pose at {msg['t']}")
            got.append(client.answers[-1])
        assert node.stop(signal.SIGTERM) == 0
    finally:
        client.close()
        node.kill()
    assert got == expected.stdout.decode().splitlines()
    assert any(json.loads(a).get("detect", {}).get("events") for a in got)  # the detector gave events
    replayed = _dispatch(folder, *detect, "--replay", str(log))
    assert replayed.returncode == 0 and replayed.stdout == expected.stdout


def test_sim_time_ticks_from_clock_and_stamps_goals_with_it(folder: Path, tmp_path: Path) -> None:
    from ros2_client import Client, NodeProcess, ros_env
    from rosgraph_msgs.msg import Clock

    env = ros_env(tmp_path)
    node = NodeProcess(folder, env, "--log", str(tmp_path / "run.log"), "--use-sim-time", "--tick", "2")
    client = Client(env)
    try:
        clock = client.node.create_publisher(Clock, "/clock", 10)
        client.wait_matched()
        client.spin_until(lambda: clock.get_subscription_count() >= 1, 20, "the node's /clock subscription")
        published = []
        for k in range(1, 13):  # /clock from 0.5 to 6.0 run seconds
            msg = Clock()
            msg.clock.sec, msg.clock.nanosec = divmod(k * 500_000_000, 1_000_000_000)
            clock.publish(msg)
            published.append(k * 0.5)
            client.spin_for(0.15)
        client.spin_until(lambda: any(json.loads(a)["t"] >= 4.0 for a in client.answers), 20, "ticks up to 4 s")
        ticks = [json.loads(a) for a in client.answers]
        assert all(a["ok"] for a in ticks) and ticks[0]["t"] >= 2.0
        assert all(t["t"] in published for t in ticks)
        assert all(b["t"] - a["t"] >= 2.0 for a, b in zip(ticks, ticks[1:], strict=False))
        # a drive named now is stamped with /clock (7.0), not with its message's time (6.5)
        msg = Clock()
        msg.clock.sec = 7
        clock.publish(msg)
        client.spin_for(0.5)
        ok = client.send('{"t": 6.5, "agent": "human", "action": "cube1", "phase": "fetch", "event": "depart"}')
        assert json.loads(ok)["ok"], ok
        client.spin_until(lambda: client.goals, 20, "a goal")
        stamp = client.goals[-1].header.stamp
        assert (stamp.sec, stamp.nanosec) == (7, 0)
        assert node.stop() == 0
    finally:
        client.close()
        node.kill()
    log = _dispatch(folder, "--replay", str(tmp_path / "run.log"))
    assert log.returncode == 0
    logged = log.stdout.decode().splitlines()
    rest = iter(logged)  # every answer the client saw is in the log, in order (ticks come unasked: the
    assert all(any(a == b for b in rest) for a in client.answers)  # writer keeps the last one only)
    from hrc.dispatch.logfile import read_log

    ticks_logged = [json.loads(m.data) for m in read_log(tmp_path / "run.log").messages
                    if json.loads(m.data).get("event") == "tick"]
    assert len(ticks_logged) >= 2 and all(t["t"] in published for t in ticks_logged)


def test_the_robots_first_goal_is_there_before_any_message(mini, write_mini, tmp_path: Path) -> None:
    """A robot controller whose first message is its own departure learns where to drive from the goal the
    node publishes at its start: the dispatcher's decision before any message (the same step ``hrc
    dispatch`` names in its first answer, whatever the message); that departure names no new drive."""
    from ros2_client import Client, NodeProcess, ros_env

    task, map_ = mini
    a1 = task["actions"][0]
    a1["agents"] = ["robot"]  # the robot leaves first
    for phase in a1["phases"]:
        del phase["duration"]["human"]
    folder = compiled_folder(tmp_path / "out", write_mini(task, map_))
    step = Dispatcher.from_folder(folder).decision.to_json()["robot"]
    assert step["event"] == "depart"
    task = load_plan_set(folder).task
    want = MapFrame("map", *ORIGIN).to_frame(
        *task.workspace.location(task.action(step["action"]).phase(step["phase"]).location).xy)
    env = ros_env(tmp_path)
    node = NodeProcess(folder, env, "--map-origin", *(str(v) for v in ORIGIN))
    client = None
    try:
        client = Client(env)
        client.wait_matched()
        client.spin_until(lambda: client.goals and client.routes, 20, "the first goal, before any message")
        goal = client.goals[-1]
        assert math.dist((goal.pose.position.x, goal.pose.position.y), want) < 1e-9
        assert goal.header.stamp.sec == goal.header.stamp.nanosec == 0  # the run's start
        depart = {"t": round(step["earliest"], 3), "agent": "robot", "action": step["action"],
                  "phase": step["phase"], "event": "depart"}
        assert json.loads(client.send(json.dumps(depart)))["ok"]
        client.spin_for(0.5)
        assert len(client.goals) == 1
        assert node.stop(signal.SIGTERM) == 0
    finally:
        if client is not None:
            client.close()
        node.kill()
