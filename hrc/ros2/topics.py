"""What ``hrc ros2`` speaks on ROS 2: its node's name, its topics (relative to the namespace, default
``/hrc``), their types and QoS. Plain data, no ROS import: docs/ros2.md lists the same, and the node
(`hrc.ros2.node`) builds its publishers and subscriptions from it.

A team (issue 37: other than one person and one robot) has a goal, a route and an acknowledgement topic
per robot and an observation and a pose topic per person, each under the agent's id (`robot_topics`,
`person_topics`): ``/hrc/robot2/goal``, ``/hrc/alice/observations``, ``/hrc/alice/pose``. The shared
``observations`` and ``answers`` stay.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ANSWERS", "DEFAULT_NAMESPACE", "GOAL", "INPUT", "LATEST", "NODE_NAME", "OBSERVATIONS", "POSE", "Qos",
           "ROBOT_ACKS", "ROUTE", "SEPARATION", "TOPICS", "Topic", "person_topics", "robot_topics"]

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


def robot_topics(robot: str) -> dict[str, Topic]:
    """A team's robot's own topics under its id (issue 37): ``acks`` in (its controller's lines, each naming
    this robot), ``goal``, ``route`` and ``separation`` out, as `ROBOT_ACKS`, `GOAL`, `ROUTE` and
    `SEPARATION` are the one robot's."""
    return {"acks": Topic(f"{robot}/acks", ROBOT_ACKS.type, "in", INPUT,
                          f"{robot}'s controller's acknowledgements (each line's agent must be {robot})"),
            "goal": Topic(f"{robot}/goal", GOAL.type, "out", LATEST, f"the destination of {robot}'s next drive"),
            "route": Topic(f"{robot}/route", ROUTE.type, "out", LATEST, f"the points of {robot}'s next drive"),
            "separation": Topic(f"{robot}/separation", SEPARATION.type, "out", LATEST,
                                f"the limits {robot}'s drive's plan assumed (a task with safety: only)")}


def person_topics(person: str) -> dict[str, Topic]:
    """A team's person's own topics under their id (issue 37): ``observations`` in, the lines of that
    person's detector or buttons (each naming this person), and ``pose`` in, their tracked pose for their
    own motion detector (``--detect motion``), as `POSE` is the one person's."""
    return {"observations": Topic(f"{person}/observations", OBSERVATIONS.type, "in", INPUT,
                                  f"{person}'s observations, away and back (each line's agent must be {person})"),
            "pose": Topic(f"{person}/pose", POSE.type, "in", INPUT,
                          f"{person}'s tracked position, for their motion detector (--detect motion)")}
