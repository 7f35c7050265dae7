"""What a recording draws, as Foxglove's well-known messages (``foxglove.messages``): the shop floor, the
agents, their routes, the robot's goal.

Everything is in one frame, `FRAME` (``map``): hrc's map coordinates in metres, z up, the floor at
z = 0. The shop floor (`map_update`) is a thin slab over the map's bounds, its outline as the walls,
each obstacle (shelf, table, rack) an upright block of `OBSTACLE_HEIGHT` (a box for an axis-aligned
rectangle, a prism of triangles for any other polygon), each named location a flat disc with its name.
An agent (`agents_update`) is an upright cylinder of its radius in its colour (the person orange, the
robot blue, as in every figure: `agent_color` gives what `hrc.report.figures.agent_color` gives, without
loading matplotlib; a test holds the two equal) with a label above it; a route
(`routes_update`) a line per leg a little above the floor.

Each function returns a message; nothing here writes (`hrc.record.recorder` does).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import shapely
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    LinePrimitive,
    LinePrimitiveLineType,
    Point3,
    Pose,
    PoseInFrame,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    TextPrimitive,
    Timestamp,
    TriangleListPrimitive,
    Vector3,
)

from hrc.model import Obstacle, Task

__all__ = ["AGENT_COLORS", "AGENT_HEIGHT", "FRAME", "OBSTACLE_HEIGHT", "agent_color", "agents_update", "goal_topic",
           "map_update", "pose_in_frame", "pose_topic", "routes_update", "stamp", "team_robots"]

FRAME = "map"
"""The frame every entity and pose is in: hrc's map coordinates (m)."""
OBSTACLE_HEIGHT = 1.0
"""m: how tall obstacles are drawn (the map is 2-D)."""
AGENT_HEIGHT = {True: 1.7, False: 0.6}
"""m: a person's cylinder, a robot's (by ``Agent.is_human``)."""
_IDENTITY = Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)
AGENT_COLORS = ("#d9731a", "#1f6fb2", "#00897b", "#6d4c41")
"""The first person, the first robot, then a second of either kind (`hrc.report.figures.AGENT_COLORS`)."""


def team_robots(task: Task) -> tuple[str, ...]:
    """A team's robots (issue 37: other than one person and one robot), each recorded on channels of its
    own; () for one person and one robot, whose channels are as they always were."""
    people = sum(a.is_human for a in task.agents)
    robots = tuple(a.id for a in task.agents if not a.is_human)
    return robots if (people, len(robots)) != (1, 1) else ()


def pose_topic(task: Task, agent_id: str) -> str:
    """An agent's pose channel: ``/hrc/human/pose`` and ``/hrc/robot/pose`` for one of each, else
    ``/hrc/ID/pose`` (a team: issue 37)."""
    agent = task.agent(agent_id)
    if not team_robots(task):
        return f"/hrc/{'human' if agent.is_human else 'robot'}/pose"
    return f"/hrc/{agent_id}/pose"


def goal_topic(robot: str | None = None) -> str:
    """A robot's goal channel: ``/hrc/robot/goal`` for the one robot (`robot` None), ``/hrc/ID/goal`` for a
    team's (issue 37)."""
    return "/hrc/robot/goal" if robot is None else f"/hrc/{robot}/goal"


def agent_color(task: Task, agent_id: str) -> str:
    """`agent_id`'s colour by its kind and rank among its kind (`hrc.report.figures.agent_color`)."""
    agent = task.agent(agent_id)
    k = [a.id for a in task.agents if a.is_human == agent.is_human].index(agent_id)
    return AGENT_COLORS[0 if agent.is_human else 1] if k == 0 else AGENT_COLORS[2 + (k - 1) % 2]


def stamp(t: float) -> Timestamp:
    """Run seconds (from the task's start) as a timestamp (the epoch is the task's start)."""
    ns = round(t * 1e9)
    return Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


def _pose(x: float, y: float, z: float, yaw: float = 0.0) -> Pose:
    q = _IDENTITY if yaw == 0 else Quaternion(x=0.0, y=0.0, z=math.sin(yaw / 2), w=math.cos(yaw / 2))
    return Pose(position=Vector3(x=x, y=y, z=z), orientation=q)


def _color(hex_color: str, alpha: float = 1.0) -> Color:
    r, g, b = (int(hex_color[k:k + 2], 16) / 255 for k in (1, 3, 5))
    return Color(r=round(r, 4), g=round(g, 4), b=round(b, 4), a=alpha)


_OBSTACLE = Color(r=0.45, g=0.45, b=0.5, a=0.85)
_FLOOR = Color(r=0.93, g=0.93, b=0.9, a=1.0)
_WALL = Color(r=0.2, g=0.2, b=0.2, a=1.0)
_PLACE = Color(r=0.25, g=0.55, b=0.3, a=0.9)
_INK = Color(r=0.1, g=0.1, b=0.1, a=1.0)


def _rectangle(polygon: Sequence[tuple[float, float]]) -> tuple[float, float, float, float] | None:
    """``(xmin, ymin, xmax, ymax)`` when the polygon is an axis-aligned rectangle, else None."""
    pts = list(dict.fromkeys((float(x), float(y)) for x, y in polygon))
    if len(pts) != 4:
        return None
    xs, ys = sorted({p[0] for p in pts}), sorted({p[1] for p in pts})
    if len(xs) != 2 or len(ys) != 2:
        return None
    return (xs[0], ys[0], xs[1], ys[1])


def _prism(obstacle: Obstacle) -> TriangleListPrimitive:
    """An upright prism over any simple polygon: its top (constrained Delaunay triangles, holes none) and
    its sides, as a triangle list."""
    ring = [(float(x), float(y)) for x, y in obstacle.polygon]
    poly = shapely.Polygon(ring)
    h = OBSTACLE_HEIGHT
    points: list[Point3] = []
    for tri in shapely.get_parts(shapely.constrained_delaunay_triangles(poly)):
        for x, y in list(tri.exterior.coords)[:3]:
            points.append(Point3(x=x, y=y, z=h))
    for (x0, y0), (x1, y1) in zip(ring, ring[1:] + ring[:1], strict=True):
        for x, y, z in ((x0, y0, 0.0), (x1, y1, 0.0), (x1, y1, h), (x0, y0, 0.0), (x1, y1, h), (x0, y0, h)):
            points.append(Point3(x=x, y=y, z=z))
    return TriangleListPrimitive(pose=_pose(0.0, 0.0, 0.0), points=points, color=_OBSTACLE)


def map_update(task: Task) -> SceneUpdate:
    """The shop floor as scene entities (at time 0, for good): ``map/floor`` (slab and walls),
    ``map/OBSTACLE`` per obstacle, ``map/locations`` (a disc and the name of each)."""
    ws = task.workspace
    x0, y0, x1, y1 = ws.bounds
    at = stamp(0.0)
    floor = SceneEntity(
        timestamp=at, frame_id=FRAME, id="map/floor",
        cubes=[CubePrimitive(pose=_pose((x0 + x1) / 2, (y0 + y1) / 2, -0.01),
                             size=Vector3(x=x1 - x0, y=y1 - y0, z=0.02), color=_FLOOR)],
        lines=[LinePrimitive(type=LinePrimitiveLineType.LineLoop, pose=_pose(0.0, 0.0, 0.0), thickness=0.06,
                             points=[Point3(x=x, y=y, z=0.0) for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))],
                             color=_WALL)])
    entities = [floor]
    for ob in ws.obstacles:
        rect = _rectangle(ob.polygon)
        if rect is not None:
            a, b, c, d = rect
            shape: dict[str, Any] = {"cubes": [CubePrimitive(pose=_pose((a + c) / 2, (b + d) / 2, OBSTACLE_HEIGHT / 2),
                                                             size=Vector3(x=c - a, y=d - b, z=OBSTACLE_HEIGHT),
                                                             color=_OBSTACLE)]}
        else:
            shape = {"triangles": [_prism(ob)]}
        entities.append(SceneEntity(timestamp=at, frame_id=FRAME, id=f"map/{ob.id}", **shape))
    discs, names = [], []
    for loc in ws.locations:
        discs.append(CylinderPrimitive(pose=_pose(loc.x, loc.y, 0.005), size=Vector3(x=0.3, y=0.3, z=0.01),
                                       color=_PLACE))
        names.append(TextPrimitive(pose=_pose(loc.x, loc.y, 0.3), billboard=True, font_size=14.0,
                                   scale_invariant=True, color=_INK, text=loc.id))
    entities.append(SceneEntity(timestamp=at, frame_id=FRAME, id="map/locations", cylinders=discs, texts=names))
    return SceneUpdate(entities=entities)


def agents_update(task: Task, t: float, where: Mapping[str, tuple[float, float]], labels: Mapping[str, str],
                  present: Mapping[str, bool]) -> SceneUpdate:
    """Each agent at `where` (hrc's map, m) as a cylinder of its radius, with its label above; an absent
    agent (the person away) faint. Entities ``agent/ID``, replaced by the next update."""
    entities = []
    for agent in task.agents:
        if agent.id not in where:
            continue
        x, y = where[agent.id]
        h = AGENT_HEIGHT[agent.is_human]
        alpha = 0.9 if present.get(agent.id, True) else 0.2
        entities.append(SceneEntity(
            timestamp=stamp(t), frame_id=FRAME, id=f"agent/{agent.id}",
            cylinders=[CylinderPrimitive(pose=_pose(x, y, h / 2), size=Vector3(x=2 * agent.radius, y=2 * agent.radius,
                                                                               z=h),
                                         bottom_scale=1.0, top_scale=1.0, color=_color(agent_color(task, agent.id),
                                                                                       alpha))],
            texts=[TextPrimitive(pose=_pose(x, y, h + 0.3), billboard=True, font_size=13.0, scale_invariant=True,
                                 color=_INK, text=labels.get(agent.id, agent.id))]))
    return SceneUpdate(entities=entities)


def routes_update(task: Task, t: float, routes: Mapping[str, Sequence[Mapping[str, Any]]]) -> SceneUpdate:
    """Each agent's route in a plan (`routes`: agent -> legs, each with ``points``, as
    `hrc.dispatch.routes.PlanRoutes` gives them), one line strip per leg in the agent's colour. Entities
    ``route/ID``; an agent with no leg gets an empty entity (its old route goes)."""
    entities = []
    for agent in task.agents:
        lines = []
        for leg in routes.get(agent.id, ()):
            pts = leg.get("points") or []
            if len(pts) < 2:
                continue
            z = 0.03 if agent.is_human else 0.05
            lines.append(LinePrimitive(type=LinePrimitiveLineType.LineStrip, pose=_pose(0.0, 0.0, 0.0),
                                       thickness=0.05, points=[Point3(x=float(x), y=float(y), z=z) for x, y in pts],
                                       color=_color(agent_color(task, agent.id), 0.8)))
        entities.append(SceneEntity(timestamp=stamp(t), frame_id=FRAME, id=f"route/{agent.id}", lines=lines))
    return SceneUpdate(entities=entities)


def pose_in_frame(t: float, x: float, y: float, yaw: float = 0.0) -> PoseInFrame:
    """A position (and heading) on the floor at `t`, in `FRAME`."""
    return PoseInFrame(timestamp=stamp(t), frame_id=FRAME, pose=_pose(x, y, 0.0, yaw))
