"""The robot's next drive, from a dispatcher's answer: where to, along which points, in which frame.

A navigation stack (Nav2's ``NavigateToPose``) needs a goal pose in its map frame; hrc's dispatcher says
which event of which leg the robot does next and when (`hrc.dispatch.Decision`). `next_drive` reads the
answer (as JSON, the protocol's shape) and the plan's routes (`hrc.dispatch.routes.PlanRoutes`: each leg's
points, its detour, its waiting place) and gives the `Drive`: its destination and the route's points in
hrc's map coordinates. A leg that stops at a waiting place is two drives: ``depart`` to the waiting place
(the plan's ``park``), ``unpark`` from there to the phase's location. `MapFrame` places hrc's map in a
ROS frame (its origin's pose there). `home_drive` is the one drive no answer names: a robot whose part is
done goes back to its start, out of the way.

Pure: no ROS import, so that the MCAP recorder (`hrc.record`) draws the same goal the node publishes.

>>> MapFrame("map", 1.0, 2.0, 0.0).to_frame(0.5, 0.5)
(1.5, 2.5)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from hrc.dispatch.messages import Observation
from hrc.model import Task

__all__ = ["DRIVE_EVENTS", "HOME", "Drive", "MapFrame", "Ways", "home_drive", "next_drive"]

DRIVE_EVENTS = ("depart", "unpark")
"""The robot's events that start a drive (the others end one, or are work at a location)."""

HOME = "home"
"""The `Drive.event` of a robot's way back to its start after its last phase (`home_drive`)."""

Point = tuple[float, float]
Ways = Callable[[str, str, str], Sequence[Sequence[float]]]
"""``(agent, from, to) -> points``: the planned free-space way between two locations (`PlanRoutes.way`)."""


@dataclass(frozen=True, slots=True)
class MapFrame:
    """hrc's map (metres, its own origin) in the ROS frame `frame_id`: the pose of hrc's origin there,
    ``(x, y)`` metres and `yaw` radians (counter-clockwise). The identity by default."""

    frame_id: str = "map"
    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0

    def to_frame(self, px: float, py: float) -> Point:
        """hrc's map coordinates to the frame's."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return (self.x + c * px - s * py, self.y + s * px + c * py)

    def from_frame(self, fx: float, fy: float) -> Point:
        """The frame's coordinates to hrc's map coordinates."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        dx, dy = fx - self.x, fy - self.y
        return (c * dx + s * dy, -s * dx + c * dy)

    def orientation(self, heading: float = 0.0) -> tuple[float, float, float, float]:
        """The quaternion ``(x, y, z, w)`` of a heading (radians, in hrc's map) in the frame."""
        half = (self.yaw + heading) / 2
        return (0.0, 0.0, math.sin(half), math.cos(half))


@dataclass(frozen=True, slots=True)
class Drive:
    """The robot's next drive: `event` (``depart`` or ``unpark``) of `action`.`phase`, to `location` at
    `target` (hrc's map, m), along `points` (from where it starts to `target`; empty when the routes are
    not known), in the window ``[earliest, latest]`` (run seconds; `latest` None: no bound). `heading`:
    the direction of the route's last stretch (radians), 0 when unknown."""

    action: str
    phase: str
    event: str
    location: str
    target: Point
    earliest: float
    latest: float | None
    points: tuple[Point, ...] = ()
    heading: float = 0.0

    @property
    def leg(self) -> tuple[str, str, str]:
        """What the drive is: ``(action, phase, event)`` (a new one is a new goal)."""
        return (self.action, self.phase, self.event)


def _split(points: Sequence[Point], at: Point) -> int | None:
    """The index of the route's point at `at` (within 1 mm), or None."""
    for k, p in enumerate(points):
        if math.dist(p, at) < 1e-3:
            return k
    return None


def next_drive(task: Task, answer: Mapping[str, Any], routes: Mapping[str, Sequence[Mapping[str, Any]]] | None = None,
               robot: str | None = None) -> Drive | None:
    """The drive the answer tells the robot to make next, or None (it is told to wait, to do work at a
    location, to end a drive under way, or nothing; or the answer is a refusal).

    `routes`: the best plan's legs per agent (``PlanRoutes.routes(answer["plan"])``): the drive's points
    and its waiting place. Without them the destination is the phase's location and there are no points.
    `robot`: a team's robot (issue 37), whose step is its entry of the answer's ``robots``; None: the one
    robot's ``robot``.
    """
    if robot is None:
        step = answer.get("robot") if answer.get("ok") else None
    else:
        steps = answer.get("robots") if answer.get("ok") else None
        step = steps.get(robot) if isinstance(steps, Mapping) else None
    if not isinstance(step, Mapping) or step.get("event") not in DRIVE_EVENTS:
        return None
    action, phase, event = str(step["action"]), str(step["phase"]), str(step["event"])
    try:
        location = task.action(action).phase(phase).location
    except KeyError:
        return None
    ws = task.workspace
    robot = robot if robot is not None else next(a.id for a in task.agents if not a.is_human)
    leg = next((lg for lg in (routes or {}).get(robot, ()) if (lg["action"], lg["phase"]) == (action, phase)), None)
    points: tuple[Point, ...] = tuple((float(x), float(y)) for x, y in leg["points"]) if leg else ()
    park = leg.get("park") if leg else None
    if park and event == "depart":  # to the waiting place first
        location = str(park)
    target = ws.location(location).xy
    if park and points:
        cut = _split(points, ws.location(str(park)).xy)
        if cut is not None:
            points = points[:cut + 1] if event == "depart" else points[cut:]
    latest = step.get("latest")
    return Drive(action, phase, event, location, target, float(step["earliest"]),
                 None if latest is None else float(latest), points, _heading(points))


def _heading(points: Sequence[Point]) -> float:
    if len(points) >= 2 and math.dist(points[-2], points[-1]) > 0:
        return math.atan2(points[-1][1] - points[-2][1], points[-1][0] - points[-2][0])
    return 0.0


def home_drive(task: Task, answer: Mapping[str, Any], history: Sequence[Observation], robot: str | None = None,
               ways: Ways | None = None) -> Drive | None:
    """The robot's way home (`HOME`) once its part is done, or None. Done: the accepted `answer` tells
    the robot nothing more (its step is null) and the robot's last event in `history` (the dispatcher's
    observations that stand) is the `end` of a phase. Not for a robot that was stopped or is held: the
    answer says ``stopped`` (no plan left with ``--feasible-only``), is a fallback of compile on demand
    (``fallback``: the person left every compiled plan, plans are being compiled); nor for a robot that
    never ended a phase (it stands at its start). A person away does not hold it: the robot finishes
    alone and clears the floor, as the simulator's robot does (a plan that gives it work again when they
    are back is a drive as any other).

    The destination is the robot's start location (`Agent.start`); the points are the planned way from
    the last phase's location there (`ways`: the compile's free-space paths, as the simulator's robot
    drives home, `hrc.sim.agents`), none when `ways` is None or has no such way. The leg
    ``(action, phase, "home")`` names the last phase, so one ending is one home drive. `robot`: a team's
    robot (its entry of ``robots``); None: the one robot."""
    if not answer.get("ok") or answer.get("stopped") or answer.get("fallback") is not None:
        return None
    if robot is None:
        robot = next(a.id for a in task.agents if not a.is_human)
        if answer.get("robot", True) is not None:
            return None
    else:
        steps = answer.get("robots")
        if not isinstance(steps, Mapping) or robot not in steps or steps[robot] is not None:
            return None
    last = next((o for o in reversed(history) if o.agent == robot and o.action is not None), None)
    if last is None or last.event != "end" or last.action is None or last.phase is None:
        return None
    action, phase = last.action, last.phase
    try:
        start = task.agent(robot).start
        there = task.action(action).phase(phase).location
        target = task.workspace.location(start).xy
    except KeyError:
        return None
    points: tuple[Point, ...] = ()
    if ways is not None:
        try:
            points = tuple((float(p[0]), float(p[1])) for p in ways(robot, there, start))
        except KeyError:  # no way planned between the two: the pose alone
            points = ()
    return Drive(action, phase, HOME, start, target, float(answer["t"]), None, points, _heading(points))
