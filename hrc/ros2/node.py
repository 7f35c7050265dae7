"""The ROS 2 node of ``hrc ros2``: one dispatcher behind ROS 2 topics (docs/ros2.md; names and QoS in
`hrc.ros2.topics`). The only module of hrc that imports ``rclpy``.

**In.** Each ``std_msgs/String`` on ``observations`` or ``robot/acks`` is one message of ``hrc dispatch``'s
protocol (its bytes, UTF-8), handed to the same `hrc.dispatch.durable.LoggedDispatcher` as ``hrc
dispatch``'s: in the log (fsync'd when accepted) before the state changes or the answer goes out, so
that the log replays byte for byte (``hrc dispatch OUT_DIR --replay LOG``) and ``--resume`` goes on
after a crash. A ``geometry_msgs/PoseStamped`` on ``human/pose`` becomes the motion detector's position
message (``{"t", "agent", "event": "position", "x", "y"}``, in hrc's map: `MapFrame.from_frame`) for the
motion detector in front of the dispatcher (``hrc ros2 --detect motion``, `hrc.detect`); without it each
pose is refused in one line, here, and never logged.

**Out.** Each answer, exactly as ``hrc dispatch`` prints it, on ``answers``; when an answer names a new
drive of the robot (`hrc.ros2.drive.next_drive`), its destination on ``robot/goal`` and its planned
points on ``robot/route``, in the frame `MapFrame.frame_id`; at the start, the drive of the dispatcher's
decision before any message (after ``--resume``, its last). Once a robot's part is done (its step null
after the end of a phase, no stop, no fallback; a person away does not hold it: `hrc.ros2.drive.home_drive`),
one more goal: its start location, along the planned way there (`PlanRoutes.way`). Both are reliable and transient
local: a late subscriber gets the latest.

**A team** (issue 37: other than one person and one robot): each robot has its own ``ROBOT/acks`` in and
``ROBOT/goal``, ``ROBOT/route`` (and ``ROBOT/separation``) out, under its id (`hrc.ros2.topics.robot_topics`),
each goal from that robot's entry of the answer's ``robots``; each person has ``PERSON/observations``
and ``PERSON/pose`` (`person_topics`): a pose there becomes that person's position message (``"agent":
PERSON``) for their own motion detector, as ``human/pose`` is the one person's (a team has no
``human/pose``). A line on an agent's own topic must name that agent (``"agent": ID``): any other is
refused in one line on ``answers`` and never reaches the log, so that one agent's detector or controller
cannot speak for another. The shared ``observations`` topic takes any line, as for one of each.

**Time.** The run's time is the messages' own ``t`` (seconds from the task's start), as in ``hrc
dispatch``. A pose's ``t`` is its header's stamp read as run seconds; a goal's stamp is the run time of
the answer that named it. With ``use_sim_time`` the node's clock is ``/clock`` (run seconds): goals are
stamped with it, and ``tick`` (if > 0) tells the dispatcher that that much ``/clock`` time has passed
with nothing said. The wall clock is never read (`rclpy`'s own log lines aside), so a run replays.

**Stop.** SIGINT and SIGTERM set a flag that the loop reads between callbacks: the message being
handled is finished (in the log and answered), then the node is destroyed and the log closed.
"""

from __future__ import annotations

import json
import math
import signal
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import rclpy
from geometry_msgs.msg import Pose, PoseArray, PoseStamped
from rclpy.context import Context
from rclpy.exceptions import InvalidNamespaceException, InvalidNodeNameException
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.validate_namespace import validate_namespace
from std_msgs.msg import String

from hrc.detect import DetectingDispatcher
from hrc.dispatch.durable import LoggedDispatcher
from hrc.dispatch.limits import MAX_LINE, parse_message
from hrc.errors import HrcError, MessageError
from hrc.model import Task
from hrc.ros2.drive import Drive, MapFrame, Ways, home_drive, next_drive
from hrc.ros2.topics import (
    ANSWERS,
    GOAL,
    NODE_NAME,
    OBSERVATIONS,
    POSE,
    ROBOT_ACKS,
    ROUTE,
    SEPARATION,
    Qos,
    person_topics,
    robot_topics,
)

__all__ = ["POSITION", "DispatcherNode", "Stopped", "qos_profile", "serve"]

POSITION = "position"
"""The motion detector's event (`hrc.detect`): what a pose becomes."""
Routes = Callable[[str], Any]
_IDENTITY = MapFrame()


def qos_profile(q: Qos) -> QoSProfile:
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=q.depth,
                      reliability=ReliabilityPolicy.RELIABLE if q.reliable else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if q.transient_local else DurabilityPolicy.VOLATILE)


def _refusal(t: Any, reason: str) -> str:
    if isinstance(t, bool) or not isinstance(t, int | float) or not math.isfinite(t):
        t = None
    return json.dumps({"t": t, "ok": False, "error": reason}, ensure_ascii=False)


class DispatcherNode:
    """An rclpy node around `logged` (see the module docstring). `routes` gives a plan's legs by id (the
    goal's points and waiting places; None: goals at the phases' locations, no route); `ways` the planned
    way between two locations (a robot's way home; None: its home goal has no route). `tick`: run seconds
    of ``/clock`` without a message after which the node sends a tick (0: never; only with sim time).
    `report` takes one-line notes for the operator (stderr)."""

    def __init__(self, logged: LoggedDispatcher, *, context: Context, namespace: str, frame: MapFrame,
                 routes: Routes | None = None, use_sim_time: bool = False, tick: float = 0.0,
                 report: Callable[[str], None] | None = None, ways: Ways | None = None) -> None:
        self.logged = logged
        self.ways = ways
        self.task: Task = logged.dispatcher.task
        self.frame = frame
        self.routes = routes
        self.tick = tick
        self.report = report or (lambda _text: None)
        self.handled = 0
        self.last_leg: tuple[str, str, str] | None = None
        self.human = next(a.id for a in self.task.agents if a.is_human)
        people = tuple(a.id for a in self.task.agents if a.is_human)
        robots = tuple(a.id for a in self.task.agents if not a.is_human)
        self.team = robots if (len(people), len(robots)) != (1, 1) else ()  # issue 37: per robot
        self.last_legs: dict[str, tuple[str, str, str]] = {}  # a team's robot -> its last drive
        overrides = [Parameter("use_sim_time", value=True)] if use_sim_time else []
        self.node = Node(NODE_NAME, namespace=namespace, context=context, parameter_overrides=overrides)
        self.sim_time = bool(self.node.get_parameter("use_sim_time").value)
        node = self.node
        self.answers = node.create_publisher(String, ANSWERS.name, qos_profile(ANSWERS.qos))
        # a team's robots have their own topics (below; a robot named "robot" has the one robot's names)
        one = not self.team
        self.goal: Any = node.create_publisher(PoseStamped, GOAL.name, qos_profile(GOAL.qos)) if one else None
        self.route: Any = node.create_publisher(PoseArray, ROUTE.name, qos_profile(ROUTE.qos)) if one else None
        self.separation = None if self.task.safety is None or not one else \
            node.create_publisher(String, SEPARATION.name, qos_profile(SEPARATION.qos))
        for topic in (OBSERVATIONS, ROBOT_ACKS) if one else (OBSERVATIONS,):
            node.create_subscription(String, topic.name, self._supervised(self._on_line), qos_profile(topic.qos))
        if one:  # a team's people have a pose topic each (below)
            node.create_subscription(PoseStamped, POSE.name, self._supervised(self._on_pose(self.human, POSE.name)),
                                     qos_profile(POSE.qos))
        self._pose_refused = False
        self.faults = 0
        self._fault_said = -math.inf
        self.per_robot: dict[str, tuple[Any, Any, Any]] = {}  # a team's robot -> (goal, route, separation)
        try:
            for r in self.team:
                t = robot_topics(r)
                self.per_robot[r] = (node.create_publisher(PoseStamped, t["goal"].name, qos_profile(t["goal"].qos)),
                                     node.create_publisher(PoseArray, t["route"].name, qos_profile(t["route"].qos)),
                                     None if self.task.safety is None else node.create_publisher(
                                         String, t["separation"].name, qos_profile(t["separation"].qos)))
                node.create_subscription(String, t["acks"].name, self._supervised(self._own_line(r)),
                                         qos_profile(t["acks"].qos))
            for h in people if self.team else ():
                t = person_topics(h)
                node.create_subscription(String, t["observations"].name, self._supervised(self._own_line(h)),
                                         qos_profile(t["observations"].qos))
                node.create_subscription(PoseStamped, t["pose"].name,
                                         self._supervised(self._on_pose(h, t["pose"].name)), qos_profile(t["pose"].qos))
        except (ValueError, TypeError, RuntimeError) as err:  # an id that is no ROS 2 name
            node.destroy_node()
            raise HrcError(f"hrc ros2: an agent's id cannot name its topics ({' '.join(str(err).split())[:200]}); "
                           "a team's ids must be ROS 2 names (letters, digits, _)") from err
        if self.tick > 0 and self.sim_time:
            node.create_timer(self.tick, self._supervised(self._on_tick))  # on the node's clock: /clock
        # the drive the dispatcher has in mind before any message (at the start, or where --resume left it):
        # a robot whose first message is its own departure knows where to (before, its first goal came
        # with the answer to a message, that departure's own included)
        self._drives(self.logged.dispatcher.decision.to_json())

    def _supervised(self, callback: Callable[[Any], None] | Callable[[], None]) -> Callable[..., None]:
        """`callback`, whatever goes wrong in it answered with a one-line refusal on ``answers`` and
        said to the operator at most once a second (issue 34): an exception out of a callback would end
        ``spin_once`` and the node with it. The log is as `LoggedDispatcher` left it (a message is in
        the log with its answer, or not at all)."""
        def run(*args: Any) -> None:
            try:
                callback(*args)
            except Exception as err:  # noqa: BLE001 - one message must not stop the node
                self.faults += 1
                why = " ".join(f"internal error ({type(err).__name__}: {err}); nothing changed".split())[:300]
                now = time.monotonic()
                if now - self._fault_said >= 1.0:
                    self._fault_said = now
                    self.report(f"hrc ros2: {why} ({self.faults} in all)")
                try:
                    self._say(_refusal(None, why))
                except Exception:  # noqa: BLE001, S110 - nothing more can be said if publishing fails
                    pass
        return run

    # -- in ----------------------------------------------------------------------------------------
    def _submit(self, data: bytes) -> str:
        if len(data) > MAX_LINE:  # streamed into the log in parts, and refused
            answer = self.logged.take_long(iter([data]))
        else:
            answer = self.logged.submit(data)
        self.handled += 1
        return answer

    def _on_line(self, msg: String) -> None:
        data = msg.data.encode("utf-8", "surrogatepass")
        if data.endswith(b"\n"):  # a publisher's line end is no part of the message
            data = data[:-1]
        self._answer(self._submit(data))

    def _own_line(self, agent: str) -> Callable[[String], None]:
        """The callback of `agent`'s own input topic (a team's): a line naming another agent, or none, is
        refused here (one line on ``answers``), never logged; the rest go in as on ``observations``."""
        def take(msg: String) -> None:
            data = msg.data.encode("utf-8", "surrogatepass")
            if data.endswith(b"\n"):
                data = data[:-1]
            try:
                obj = parse_message(data) if len(data) <= MAX_LINE else None
            except MessageError:
                obj = None
            named = obj.get("agent") if isinstance(obj, dict) else None
            if named != agent:
                t = obj.get("t") if isinstance(obj, dict) else None
                which = f"names {str(named)[:40]!r}" if named is not None else "names no agent"
                self._say(_refusal(t, f"a line on {agent}'s own topic must be {agent}'s (\"agent\": \"{agent}\"); "
                                      f"this one {which}; nothing changed"))
                return
            self._answer(self._submit(data))
        return take

    def _on_pose(self, person: str, topic: str) -> Callable[[PoseStamped], None]:
        """The callback of `person`'s pose `topic` (the one person's ``human/pose``; a team's person's
        ``PERSON/pose``, issue 37): each pose becomes `person`'s position message, which goes to their own
        detector (`DetectingDispatcher.answer_position`)."""
        def take(msg: PoseStamped) -> None:
            t = msg.header.stamp.sec + msg.header.stamp.nanosec / 1e9
            if msg.header.frame_id != self.frame.frame_id:
                self._say(_refusal(t, f"{topic}: a pose in frame {msg.header.frame_id!r}, expected "
                                      f"{self.frame.frame_id!r}; ignored"))
                return
            if not isinstance(self.logged.dispatcher, DetectingDispatcher):
                if not self._pose_refused:
                    self._pose_refused = True
                    self.report(f"{topic}: the person's pose needs the motion detector (hrc ros2 --detect "
                                "motion): each pose is refused")
                self._say(_refusal(t, f"{topic}: the person's pose needs the motion detector, which this "
                                      "node was not started with (--detect motion); ignored"))
                return
            x, y = self.frame.from_frame(msg.pose.position.x, msg.pose.position.y)
            line = json.dumps({"t": round(t, 3), "agent": person, "event": POSITION, "x": round(x, 3),
                               "y": round(y, 3)})
            self._answer(self._submit(line.encode("ascii")))
        return take

    def _on_tick(self) -> None:
        now = self.node.get_clock().now().nanoseconds / 1e9
        if now - self.logged.dispatcher.now >= self.tick:
            self._answer(self._submit(json.dumps({"t": round(now, 3), "event": "tick"}).encode("ascii")))

    # -- out ---------------------------------------------------------------------------------------
    def _say(self, answer: str) -> None:
        self.answers.publish(String(data=answer))

    def _answer(self, answer: str) -> None:
        self._say(answer)
        out = json.loads(answer)
        if out.get("ok"):
            self._drives(out)

    def _drives(self, out: dict[str, Any]) -> None:
        """Each robot's goal and route where the accepted answer `out` names a drive new to it; its way
        home once, when its part is done (`home_drive`)."""
        legs = self.routes(out["plan"]) if self.routes is not None and out.get("plan") else None
        history = self.logged.dispatcher.history
        for r in self.team:  # a team: each robot's drive on its own topics
            drive = next_drive(self.task, out, legs, r) or home_drive(self.task, out, history, r, self.ways)
            if drive is not None and drive.leg != self.last_legs.get(r):
                self.last_legs[r] = drive.leg
                goal, route, separation = self.per_robot[r]
                self._drive(drive, float(out["t"]), goal, route)
                self._limits(out, legs, drive, r, separation)
        if self.team:
            return
        drive = next_drive(self.task, out, legs) or home_drive(self.task, out, history, None, self.ways)
        if drive is not None and drive.leg != self.last_leg:
            self.last_leg = drive.leg
            self._drive(drive, float(out["t"]))
            self._limits(out, legs, drive)

    def _limits(self, out: dict[str, Any], legs: Any, drive: Drive, robot: str | None = None,
                publisher: Any = None) -> None:
        """The limits the drive's plan assumed (`SEPARATION`), for a task with safety: only (a team's
        `robot`: its own step, on its own `publisher`)."""
        step = (out.get("robot") if robot is None else (out.get("robots") or {}).get(robot)) or {}
        limits = step.get("separation")
        publisher = self.separation if robot is None else publisher
        if publisher is None or not isinstance(limits, dict):
            return
        robot = robot or next(a.id for a in self.task.agents if not a.is_human)
        leg = next((lg for lg in (legs or {}).get(robot, ()) if (lg["action"], lg["phase"]) == drive.leg[:2]), None)
        slow = leg.get("speed") if leg is not None else None
        msg = {"t": out["t"], "action": drive.action, "phase": drive.phase, "event": drive.event, **limits,
               "drive_speed": slow or limits["speed"],
               "drive_separation": limits.get("reduced_separation") if slow else limits["separation"]}
        publisher.publish(String(data=json.dumps(msg)))

    def _stamp(self, t: float) -> Any:
        if self.sim_time:
            return self.node.get_clock().now().to_msg()
        from builtin_interfaces.msg import Time

        ns = round(t * 1e9)
        return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def _pose(self, x: float, y: float, heading: float) -> Pose:
        pose = Pose()
        pose.position.x, pose.position.y = self.frame.to_frame(x, y)
        qx, qy, qz, qw = self.frame.orientation(heading)
        pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w = qx, qy, qz, qw
        return pose

    def _drive(self, drive: Drive, t: float, goal_topic: Any = None, route_topic: Any = None) -> None:
        goal = PoseStamped()
        goal.header.stamp = self._stamp(t)
        goal.header.frame_id = self.frame.frame_id
        goal.pose = self._pose(*drive.target, drive.heading)
        (goal_topic or self.goal).publish(goal)
        route = PoseArray()
        route.header = goal.header
        pts = drive.points
        for k, (x, y) in enumerate(pts):
            nxt = pts[k + 1] if k + 1 < len(pts) else None
            heading = math.atan2(nxt[1] - y, nxt[0] - x) if nxt is not None and nxt != (x, y) else drive.heading
            route.poses.append(self._pose(x, y, heading))
        (route_topic or self.route).publish(route)

    def destroy(self) -> None:
        self.node.destroy_node()


@dataclass(frozen=True, slots=True)
class Stopped:
    """How `serve` ended: the signal's name, and how many messages the node handled."""

    signal: str
    messages: int


def serve(open_log: Callable[[], LoggedDispatcher], *, ros_args: Sequence[str] = (), namespace: str = "/hrc",
          frame: MapFrame = _IDENTITY, routes: Routes | None = None, use_sim_time: bool = False,
          tick: float = 0.0, ready: Callable[[DispatcherNode], None] | None = None,
          report: Callable[[str], None] | None = None, ways: Ways | None = None) -> Stopped:
    """Serve the dispatcher `open_log()` gives on ROS 2 until SIGINT or SIGTERM (see the module docstring);
    `ros_args` are ``--ros-args ...`` for rclpy (remappings, parameters). `open_log` is called once ROS 2
    has taken the arguments and the namespace, so that a refused one leaves no log behind. `ready(node)`
    once the topics exist.

    Raises `hrc.errors.HrcError` with one line when rclpy refuses the arguments or the namespace."""
    from hrc.errors import HrcError

    stop: list[int] = []
    previous = {s: signal.signal(s, lambda signum, _frame: stop.append(signum)) for s in (signal.SIGINT,
                                                                                            signal.SIGTERM)}
    context = Context()
    node: DispatcherNode | None = None
    try:
        try:
            namespace = namespace if namespace.startswith("/") else "/" + namespace
            validate_namespace(namespace)
            rclpy.init(args=["hrc-ros2", *ros_args], context=context, signal_handler_options=SignalHandlerOptions.NO)
        except (ValueError, TypeError, RuntimeError, InvalidNamespaceException, InvalidNodeNameException) as err:
            raise HrcError(f"hrc ros2: ROS 2 refused to start the node: {' '.join(str(err).split())[:300]}") from err
        node = DispatcherNode(open_log(), context=context, namespace=namespace, frame=frame, routes=routes,
                              use_sim_time=use_sim_time, tick=tick, report=report, ways=ways)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node.node)
        if ready is not None:
            ready(node)
        while not stop:
            executor.spin_once(timeout_sec=0.1)
        return Stopped(signal.Signals(stop[0]).name, node.handled)
    finally:
        if node is not None:
            node.destroy()
        if context.ok():
            rclpy.shutdown(context=context)
        for s, handler in previous.items():
            signal.signal(s, handler)
