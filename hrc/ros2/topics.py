"""What ``hrc ros2`` speaks on ROS 2: its node's name, its topics (relative to the namespace, default
``/hrc``), their types and QoS. Plain data, no ROS import: docs/ros2.md lists the same, and the node
(`hrc.ros2.node`) builds its publishers and subscriptions from it.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ANSWERS", "DEFAULT_NAMESPACE", "GOAL", "INPUT", "LATEST", "NODE_NAME", "OBSERVATIONS", "POSE", "Qos",
           "ROBOT_ACKS", "ROUTE", "SEPARATION", "TOPICS", "Topic"]

NODE_NAME = "hrc_dispatcher"
DEFAULT_NAMESPACE = "/hrc"


@dataclass(frozen=True, slots=True)
class Qos:
    """A QoS profile in words: reliable (else best effort), transient local (a late subscriber gets the
    last `depth` messages; else volatile), keep last `depth`."""

    reliable: bool
    transient_local: bool
    depth: int

    def __str__(self) -> str:
        return (f"{'reliable' if self.reliable else 'best effort'}, "
                f"{'transient local' if self.transient_local else 'volatile'}, keep last {self.depth}")


INPUT = Qos(reliable=True, transient_local=False, depth=1000)
"""What the node reads: reliable (a reliable publisher, rclpy's default, is needed to match), volatile
(a restarted node does not take old messages again), a deep queue so that a burst is not dropped."""
LATEST = Qos(reliable=True, transient_local=True, depth=1)
"""What the node says: reliable and transient local, so that a subscriber that comes late gets the latest."""


@dataclass(frozen=True, slots=True)
class Topic:
    """A topic of the node: `name` relative to its namespace, ROS `type`, `direction` ("in"/"out"), QoS."""

    name: str
    type: str
    direction: str
    qos: Qos
    what: str


OBSERVATIONS = Topic("observations", "std_msgs/msg/String", "in", INPUT,
                     "one line of `hrc dispatch`'s protocol per message: the person's observations, away/back, "
                     "ticks, undo (the robot's acknowledgements too)")
ROBOT_ACKS = Topic("robot/acks", "std_msgs/msg/String", "in", INPUT,
                   "the robot controller's acknowledgements, the same lines (a topic of its own for the controller)")
POSE = Topic("human/pose", "geometry_msgs/msg/PoseStamped", "in", INPUT,
             "the person's tracked position, for the motion detector (--detect motion); refused in one line "
             "without it")
ANSWERS = Topic("answers", "std_msgs/msg/String", "out", LATEST,
                "every answer, exactly as `hrc dispatch` prints it (one JSON object)")
GOAL = Topic("robot/goal", "geometry_msgs/msg/PoseStamped", "out", LATEST,
             "the destination of the robot's next drive, in the map frame (a NavigateToPose goal)")
ROUTE = Topic("robot/route", "geometry_msgs/msg/PoseArray", "out", LATEST,
              "the points of that drive's planned route (its detour, if any), for NavigateThroughPoses")
SEPARATION = Topic("robot/separation", "std_msgs/msg/String", "out", LATEST,
                   "with each drive, the speed and separation limits its plan assumed of the robot's safety "
                   "controller (JSON: the step's ``separation`` and the drive's ``drive_speed`` and "
                   "``drive_separation``); only for a task with safety:")
TOPICS = (OBSERVATIONS, ROBOT_ACKS, POSE, ANSWERS, GOAL, ROUTE, SEPARATION)
