"""Joint actions online (issue 37): ``hrc console`` and ``hrc ros2`` on a task with a joint action.

- the console, a real process with its simulated robot: a person (a websocket client with the page's token,
  following the hints) plays a whole run of a small joint task; the person is never offered the start or
  end of the joint lift, the robot starts it only after the person's arrival and ends it (the simulated
  robot at the earliest the step can end), the page's Gantt draws the lift for both agents over the same
  span, and the run's log replays through ``hrc dispatch`` answer for answer;
- ``hrc ros2``, a real node over loopback (tests/ros2_client.py): the lines of an in-process run of the same
  task (tests/joint_client.py) get the same answers as through ``hrc dispatch``, and the robot's goal for the
  joint lift is the joint spot.
"""

from __future__ import annotations

import json
import math
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import ROOT
from joint_client import JointRun
from joint_tasks import lift_task, write_lift

from hrc.cli import main
from hrc.dispatch import Dispatcher
from hrc.dispatch.plan_set import load_plan_set

LIFT = lift_task(place=False)

pytestmark = pytest.mark.filterwarnings("ignore::ResourceWarning")


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("joint")
    write_lift(tmp, LIFT)
    out = tmp / "out"
    assert main(["compile", str(tmp / "task.yaml"), "--out", str(out), "--no-report", "-q", "--jobs", "1"]) == 0
    return out


def _dispatch(folder: Path, *args: str, stdin: bytes = b"") -> subprocess.CompletedProcess[bytes]:
    return subprocess.run([sys.executable, "-m", "hrc", "dispatch", str(folder), *args], input=stdin,
                          capture_output=True, timeout=120, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)))


def test_the_console_runs_a_joint_task_with_its_simulated_robot(folder: Path, tmp_path: Path) -> None:
    pytest.importorskip("websockets")
    from console_harness import ConsoleProcess
    from websockets.sync.client import connect

    log = tmp_path / "run.log"
    console = ConsoleProcess(folder, log, "--simulate-robot", "--speed", "8")
    offered: set[tuple[str, str, str]] = set()
    try:
        with connect(console.ws + "ws", open_timeout=10, close_timeout=5,
                     additional_headers=console.page_headers()) as page:
            deadline = time.monotonic() + 60
            n, last = 0, 0.0
            while not (state := console.state())["finished"]:
                heard = [e["in"] for e in state["log"] if e["in"].get("event") != "tick"]
                assert time.monotonic() < deadline, json.dumps((state["decision"], heard))
                options = [(o["action"], o["phase"], o["event"]) for o in state["options"]]
                offered.update(options)
                hint = state["decision"].get("human") or {}
                due = (hint.get("action"), hint.get("phase"), hint.get("event"))
                press = due if due in options and state["now"] >= hint.get("earliest", 0) else next(
                    (o for o in options if o[2] in ("arrive", "end") and state["now"] >= last + 4), None)
                if press is None:  # (the person's own walk or step is done 4 s after they began it)
                    time.sleep(0.05)
                    continue
                n += 1
                page.send(json.dumps({"type": "press", "hseq": state["hseq"], "id": n,
                                      "action": press[0], "phase": press[1], "event": press[2]}))
                while (msg := json.loads(page.recv(timeout=10)))["type"] != "reply":
                    pass
                assert msg["ok"], msg
                last = state["now"]
        gantt = state["gantt"]["actual"]
    finally:
        console.stop()
    assert not {o for o in offered if o[0] == "lift" and o[2] in ("start", "end")}  # never the person's
    lines = console.log_lines()
    seen = [(m["agent"], m["event"], m["t"]) for m in lines[0::2] if m.get("action") == "lift"]
    (h_arrive,) = [t for a, e, t in seen if (a, e) == ("human", "arrive")]
    (start,) = [t for a, e, t in seen if (a, e) == ("robot", "start")]
    (end,) = [t for a, e, t in seen if (a, e) == ("robot", "end")]
    assert start >= h_arrive and end - start == pytest.approx(3.0, abs=2e-3)  # the roles' shortest: max(3, 2)
    lift = {b["agent"]: (b["from"], b["to"]) for b in gantt if b["action"] == "lift" and b["kind"] == "work"}
    assert lift == {"human": (start, end), "robot": (start, end)}
    replayed = _dispatch(folder, "--replay", str(log))
    assert replayed.returncode == 0, replayed.stderr
    assert [json.loads(x) for x in replayed.stdout.decode().splitlines()] == lines[1::2]


def test_ros2_answers_a_joint_run_as_hrc_dispatch(folder: Path, tmp_path: Path) -> None:
    pytest.importorskip("rclpy")
    from ros2_client import Client, NodeProcess, ros_env

    run = JointRun(Dispatcher(load_plan_set(folder)), random.Random(3))
    run.play()
    sent = [json.dumps(o.to_json()) for o in run.dispatcher.history]
    assert any('"lift"' in line and '"start"' in line for line in sent)
    env = ros_env(tmp_path)
    node = NodeProcess(folder, env)
    client = None
    try:
        client = Client(env)
        client.wait_matched()
        for line in sent:
            client.send(line)
        home = load_plan_set(folder).task
        home_xy = home.workspace.location(home.agent("robot").start).xy
        client.spin_until(lambda: client.goals and math.dist((client.goals[-1].pose.position.x,
                                                              client.goals[-1].pose.position.y), home_xy) < 1e-9,
                          20, "the robot's way home after its last phase")
        assert node.stop(signal.SIGTERM) == 0
    finally:
        if client is not None:
            client.close()
        node.kill()
    plain = _dispatch(folder, stdin="".join(line + "\n" for line in sent).encode())
    assert plain.returncode == 0 and plain.stdout.decode().splitlines() == client.answers
    task = load_plan_set(folder).task
    robot_departs = [json.loads(x) for x in sent if '"robot"' in x and '"depart"' in x]
    assert [d["action"] for d in robot_departs][-1] == "lift" and client.goals
    goal = client.goals[-2].pose.position  # the last drive named: to the lift (then home)
    assert math.dist((goal.x, goal.y), task.workspace.location("J").xy) < 1e-9
