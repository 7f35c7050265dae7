"""Helpers of the ROS 2 tests: an ``hrc ros2`` process on a domain of its own, and a real rclpy node that
plays the person's detector and the robot controller against it over loopback.

Every test gets a fresh ``ROS_DOMAIN_ID`` (`domain_id`: from the test's process id, so that parallel
runs and other projects on this machine do not meet), discovery limited to this machine
(``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``) and Fast DDS's UDP transport only
(``FASTDDS_BUILTIN_TRANSPORTS=UDPv4``: the traffic goes over the loopback interface, not shared memory),
and ``ROS_LOG_DIR`` in its temporary folder. Every wait is bounded.
"""

from __future__ import annotations

import itertools
import json
import os
import queue
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
START_TIMEOUT = 90.0  # s: the node loads the plans and plans the map's paths first
ANSWER_TIMEOUT = 20.0  # s for one answer
_DOMAINS = itertools.count()


def rclpy_or_skip() -> Any:
    """``rclpy``, or skip (fail under HRC_REQUIRE_ROS2=1, as in CI) saying how to install it."""
    try:
        import rclpy
    except ImportError as err:
        if os.environ.get("HRC_REQUIRE_ROS2") == "1":
            pytest.fail(f"ROS 2 tests required (HRC_REQUIRE_ROS2=1) but rclpy cannot be imported: {err}")
        pytest.skip(f"ROS 2 tests skipped: rclpy cannot be imported ({err}); pip install -e '.[test,ros2]'")
    return rclpy


def ros_env(tmp: Path) -> dict[str, str]:
    """The environment of one test's ROS 2 traffic (see the module docstring)."""
    domain = 1 + (os.getpid() * 7 + next(_DOMAINS)) % 100  # 1..100: Fast DDS's ports stay in range
    log_dir = tmp / "ros-log"
    log_dir.mkdir(exist_ok=True)
    return {"ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "FASTDDS_BUILTIN_TRANSPORTS": "UDPv4", "ROS_LOG_DIR": str(log_dir), "RCUTILS_COLORIZED_OUTPUT": "0"}


class NodeProcess:
    """``python -m hrc ros2 OUT_DIR ARGS`` with `env`; `ready` once it printed that it serves."""

    def __init__(self, out_dir: Path, env: dict[str, str], *args: str) -> None:
        full = dict(os.environ, PYTHONPATH=str(ROOT), **env)
        self.proc = subprocess.Popen([sys.executable, "-m", "hrc", "ros2", str(out_dir), *args], cwd=ROOT, env=full,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.lines: queue.Queue[str] = queue.Queue()
        self._err: list[str] = []
        threading.Thread(target=lambda: [self.lines.put(x) for x in self.proc.stdout or ()], daemon=True).start()
        threading.Thread(target=lambda: [self._err.append(x) for x in self.proc.stderr or ()], daemon=True).start()
        try:
            self.first = self.lines.get(timeout=START_TIMEOUT)
        except queue.Empty:
            self.kill()
            raise AssertionError(f"hrc ros2 did not start within {START_TIMEOUT} s: {self.stderr()}") from None
        assert "serving" in self.first, (self.first, self.stderr())

    def stderr(self) -> str:
        return "".join(self._err)

    def stop(self, sig: int = signal.SIGTERM, timeout: float = 30.0) -> int:
        """Send `sig`, wait for the end; the exit status."""
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
        code = self.proc.wait(timeout=timeout)
        time.sleep(0.1)  # the reader threads take the last lines
        return code

    def kill(self) -> None:
        """Kill it if it still runs; close its pipes (the reader threads end)."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=30)
        for pipe in (self.proc.stdout, self.proc.stderr):
            if pipe is not None:
                try:
                    pipe.close()
                except (OSError, ValueError):  # a reader thread may be in it
                    pass


class Client:
    """A real rclpy node in this process, on the domain of `env`: publishes lines on the node's input
    topics and reads its answers, goals and routes (QoS as docs/ros2.md asks of clients)."""

    def __init__(self, env: dict[str, str], namespace: str = "/hrc", robots: tuple[str, ...] = ()) -> None:
        rclpy = rclpy_or_skip()
        from geometry_msgs.msg import PoseArray, PoseStamped
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
        from rclpy.signals import SignalHandlerOptions
        from std_msgs.msg import String

        self._saved = {k: os.environ.get(k) for k in env}
        os.environ.update(env)  # rclpy reads the discovery range and the transports at init
        self.context = Context()
        rclpy.init(context=self.context, domain_id=int(env["ROS_DOMAIN_ID"]),
                   signal_handler_options=SignalHandlerOptions.NO)
        self.node = Node("hrc_test_client", namespace=namespace, context=self.context)
        inq = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
        latest = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                            durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.String, self.PoseStamped = String, PoseStamped
        self.observations = self.node.create_publisher(String, "observations", inq)
        self.acks = self.node.create_publisher(String, "robot/acks", inq)
        self.poses = self.node.create_publisher(PoseStamped, "human/pose", inq)
        self.answers: list[str] = []
        self.goals: list[Any] = []
        self.routes: list[Any] = []
        # a team's robots' goals and routes (kept whole: a deep queue, so that no goal is missed between
        # spins), made before the answers' subscription: discovery announces a node's endpoints in the
        # order they were made, in one reliable stream, so once an answer has come the node knows these
        # too and each goal published from then on reaches them (a goal topic keeps only its latest for a
        # subscriber it learns of later: the test once missed a robot's first goal that way)
        kept = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                          durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.team_goals: dict[str, list[Any]] = {r: [] for r in robots}
        self.team_routes: dict[str, list[Any]] = {r: [] for r in robots}
        self.goal_subs: list[Any] = []
        for r in robots:
            self.goal_subs.append(self.node.create_subscription(PoseStamped, f"{r}/goal", self.team_goals[r].append,
                                                                kept))
            self.goal_subs.append(self.node.create_subscription(PoseArray, f"{r}/route", self.team_routes[r].append,
                                                                kept))
        if not robots:
            self.goal_subs.append(self.node.create_subscription(PoseStamped, "robot/goal", self.goals.append, latest))
            self.goal_subs.append(self.node.create_subscription(PoseArray, "robot/route", self.routes.append, latest))
        self.node.create_subscription(String, "answers", lambda m: self.answers.append(m.data), latest)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.sent: list[str] = []

    def spin_until(self, done: Any, timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        while not done():
            assert time.monotonic() < deadline, f"no {what} within {timeout} s"
            self.executor.spin_once(timeout_sec=0.05)

    def spin_for(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=max(0.0, min(0.05, deadline - time.monotonic())))

    def wait_matched(self, timeout: float = 30.0) -> float:
        """Until the node's subscriptions and publishers are matched with ours (discovery); seconds taken."""
        start = time.monotonic()
        self.spin_until(lambda: self.observations.get_subscription_count() >= 1 and self.acks.get_subscription_count()
                        >= 1 and self.node.count_publishers(f"{self.node.get_namespace()}/answers") >= 1
                        and all(s.get_publisher_count() >= 1 for s in self.goal_subs),
                        timeout, "discovery of the hrc ros2 node")
        return time.monotonic() - start

    def send(self, line: str) -> str:
        """Publish one protocol line (a robot acknowledgement on robot/acks, anything else on observations)
        and wait for its answer."""
        obj: Any
        try:
            obj = json.loads(line)
        except ValueError:
            obj = None
        topic = self.acks if isinstance(obj, dict) and obj.get("agent") == "robot" else self.observations
        before = len(self.answers)
        self.sent.append(line)
        topic.publish(self.String(data=line))
        self.spin_until(lambda: len(self.answers) > before, ANSWER_TIMEOUT, f"answer to {line[:80]}")
        assert len(self.answers) == before + 1, "more answers than messages"
        return self.answers[-1]

    def close(self) -> None:
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        if self.context.ok():
            rclpy.shutdown(context=self.context)
        for k, v in self._saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class TeamClient:
    """A real rclpy node for a team's ``hrc ros2`` (issue 37): each person's lines on ``PERSON/observations``,
    each robot's on ``ROBOT/acks``, anything else (ticks) on the shared ``observations``, each person's tracked
pose on ``PERSON/pose``; it reads the
    answers and each robot's goals and routes from ``ROBOT/goal`` and ``ROBOT/route`` (kept whole: a deep
    queue, so that no goal is missed between spins)."""

    def __init__(self, env: dict[str, str], robots: tuple[str, ...], people: tuple[str, ...]) -> None:
        self.base = Client(env, robots=robots)
        from geometry_msgs.msg import PoseStamped
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        node = self.base.node
        inq = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
        String = self.base.String
        self.own = {r: node.create_publisher(String, f"{r}/acks", inq) for r in robots}
        self.own.update({h: node.create_publisher(String, f"{h}/observations", inq) for h in people})
        self.poses = {h: node.create_publisher(PoseStamped, f"{h}/pose", inq) for h in people}  # each tracker's
        self.goals, self.routes = self.base.team_goals, self.base.team_routes

    @property
    def answers(self) -> list[str]:
        return self.base.answers

    def wait_matched(self, timeout: float = 30.0) -> None:
        ns = self.base.node.get_namespace()
        self.base.spin_until(lambda: all(p.get_subscription_count() >= 1 for p in (*self.own.values(),
                                                                                  *self.poses.values()))
                             and self.base.observations.get_subscription_count() >= 1
                             and self.base.node.count_publishers(f"{ns}/answers") >= 1
                             and all(s.get_publisher_count() >= 1 for s in self.base.goal_subs),
                             timeout, "discovery of the hrc ros2 node")

    def send(self, line: str, topic: str | None = None) -> str:
        """Publish one line on `topic`'s own input (an agent id), or by the line's agent (None: the shared
        ``observations``); wait for its answer."""
        agent = topic if topic is not None else json.loads(line).get("agent")
        publisher = self.own.get(agent, self.base.observations)
        before = len(self.answers)
        publisher.publish(self.base.String(data=line))
        self.base.spin_until(lambda: len(self.answers) > before, ANSWER_TIMEOUT, f"answer to {line[:80]}")
        assert len(self.answers) == before + 1, "more answers than messages"
        return self.answers[-1]

    def send_pose(self, person: str, t: float, x: float, y: float, frame_id: str = "map") -> str:
        """Publish `person`'s tracked pose (x, y in `frame_id`, stamped `t` run seconds) on their own
        ``PERSON/pose``; wait for its answer."""
        pose = self.base.PoseStamped()
        pose.header.frame_id = frame_id
        pose.header.stamp.sec = int(t)
        pose.header.stamp.nanosec = round((t - int(t)) * 1e9)
        pose.pose.position.x, pose.pose.position.y = x, y
        before = len(self.answers)
        self.poses[person].publish(pose)
        self.base.spin_until(lambda: len(self.answers) > before, ANSWER_TIMEOUT, f"answer to {person}'s pose at {t}")
        assert len(self.answers) == before + 1, "more answers than messages"
        return self.answers[-1]

    def close(self) -> None:
        self.base.close()
