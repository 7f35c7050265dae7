"""``hrc dispatch --record`` for a team (issue 37): each robot's goals and each agent's poses on channels of
their own, read back with MCAP's own reader (tests/mcap_check.py).

kitting_2robots cut to three picks (one person, two robots) and two_workers (two people, one robot): an
independent client (tests/team_client.py) plays every agent with random valid histories through the JSON
lines protocol; the same lines through ``hrc dispatch --record`` give a file whose ``/hrc/out`` is the
answers printed, whose ``/hrc/ROBOT/goal`` holds exactly the drives that robot's entries of the answers name
(`next_drive`, one per new drive), whose ``/hrc/ID/pose`` has one channel per agent, and whose
``/hrc/decision`` names every robot's step; ``--replay LOG --record`` gives the same bytes, in both formats.
"""

from __future__ import annotations

import json
import math
import os
import random
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT, compiled_folder
from mcap_check import read_mcap, read_ros2_mcap
from team_client import TeamRun
from test_console_team import kitting3_task

from hrc.compile.output import read_header
from hrc.dispatch import Dispatcher
from hrc.dispatch.plan_set import load_plan_set
from hrc.dispatch.routes import PlanRoutes, plan_motions
from hrc.motion import plan_paths
from hrc.ros2.drive import next_drive
from hrc.temporal.graphml import read_graphml

POSE = ("foxglove.PoseInFrame", "protobuf", "protobuf")
POSE_ROS2 = ("geometry_msgs/msg/PoseStamped", "ros2msg", "cdr")


@pytest.fixture(scope="module", params=["kitting3", pytest.param("two_workers", marks=pytest.mark.slow)])
def team(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    where = tmp_path_factory.mktemp(request.param)
    task = kitting3_task(where) if request.param == "kitting3" else ROOT / "tasks" / "two_workers.yaml"
    return compiled_folder(where / "out", task, "--jobs", "1")


def _dispatch(folder: Path, *args: str, stdin: bytes = b"") -> subprocess.CompletedProcess[bytes]:
    return subprocess.run([sys.executable, "-m", "hrc", "dispatch", str(folder), *args], input=stdin,
                          capture_output=True, timeout=120, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)))


def test_a_team_run_is_recorded_with_a_channel_per_robot_and_agent(team: Path, tmp_path: Path) -> None:
    plan_set = load_plan_set(team)
    task = plan_set.task
    robots = tuple(a.id for a in task.agents if not a.is_human)
    people = tuple(a.id for a in task.agents if a.is_human)
    stnus = {p.stem: read_graphml(p.read_bytes()) for p in (team / "stnu").glob("*.graphml")}
    run = TeamRun(Dispatcher.from_folder(team), stnus, robots, people, random.Random(11))
    run.play()
    stdin = "".join(line + "\n" for line in run.sent).encode()
    live, log = tmp_path / "run.mcap", tmp_path / "run.log"
    done = _dispatch(team, "--record", str(live), "--log", str(log), stdin=stdin)
    assert done.returncode == 0, done.stderr
    answers = done.stdout.decode().splitlines()
    assert [json.loads(a) for a in answers] == run.answers  # the client's answers, through the CLI
    ids = [a.id for a in task.agents]
    expected = {f"/hrc/{i}/pose": POSE for i in ids} | {f"/hrc/{r}/goal": POSE for r in robots}
    rec = read_mcap(live, expected)
    assert set(rec.channels) == {"/hrc/map", "/hrc/routes", "/hrc/agents", "/hrc/in", "/hrc/out", "/hrc/decision",
                                 "/hrc/log", *expected}
    assert [json.dumps(o, separators=(",", ":")) for o in rec.of("/hrc/out")] == \
        [json.dumps(json.loads(a), separators=(",", ":")) for a in answers]
    # each robot's goals: the drives its entries of the answers name, one per new drive
    routes = PlanRoutes(plan_motions(team, plan_set), plan_paths(task, seed=int(read_header(team)["seed"])))
    for r in robots:
        want, last = [], None
        for a in run.answers:
            drive = next_drive(task, a, routes.routes(a["plan"]), r)
            if drive is not None and drive.leg != last:
                last = drive.leg
                want.append((a["t"], drive.target))
        got = [(round(m.timestamp.seconds + m.timestamp.nanos / 1e9, 3), (m.pose.position.x, m.pose.position.y))
               for m in rec.of(f"/hrc/{r}/goal")]
        assert len(got) == len(want) + 1 >= 2, (r, got, want)
        for (t, xy), (t0, xy0) in zip(got, want + [got[-1]], strict=True):
            assert t == pytest.approx(t0, abs=1e-6) and math.dist(xy, xy0) < 1e-9
        # then, once its part is done, its way home (its start), as hrc ros2 sends it
        ended = max(json.loads(x)["t"] for x in run.sent if json.loads(x).get("agent") == r
                    and json.loads(x).get("event") == "end")
        assert math.dist(got[-1][1], task.workspace.location(task.agent(r).start).xy) < 1e-9 and got[-1][0] >= ended
    # every agent's pose after each accepted message; the decision names every robot's step
    accepted = sum(1 for a in run.answers if a["ok"])
    assert all(rec.counts[f"/hrc/{i}/pose"] == accepted for i in ids)
    decisions = rec.of("/hrc/decision")
    assert len(decisions) == accepted and all(set(d["robots"]) == set(robots) for d in decisions)
    assert decisions[-1]["robots"] == dict.fromkeys(robots, "nothing left")
    # the log recorded afterwards: the same bytes; and the ROS 2 format has the same channels
    again = tmp_path / "again.mcap"
    assert _dispatch(team, "--replay", str(log), "--record", str(again)).returncode == 0
    assert again.read_bytes() == live.read_bytes()
    ros = tmp_path / "ros.mcap"
    assert _dispatch(team, "--replay", str(log), "--record", str(ros), "--record-format", "ros2").returncode == 0
    ros_rec = read_ros2_mcap(ros, {t: POSE_ROS2 for t in expected})
    assert all(ros_rec.counts[f"/hrc/{r}/goal"] == rec.counts[f"/hrc/{r}/goal"] for r in robots)
