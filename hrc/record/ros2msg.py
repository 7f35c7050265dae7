"""A recording in ROS 2 message types (``--record-format ros2``): what `hrc.record.scene` draws for
Foxglove, as messages that ``ros2 bag info`` / ``ros2 bag play`` and RViz read, written with the
``ros2msg`` schema encoding and CDR messages (MCAP's ``ros2`` profile) by `mcap_ros2` in pure Python: no
ROS install is needed to write one.

Topics and types (the same names as the Foxglove recording, where a ROS type fits):

| topic | type | what |
|---|---|---|
| ``/hrc/in`` | ``std_msgs/msg/String`` | each message given to the dispatcher, its JSON text as received |
| ``/hrc/out`` | ``std_msgs/msg/String`` | each answer, its JSON line as given out |
| ``/hrc/decision`` | ``std_msgs/msg/String`` | the best plan, class and robot step after an accepted message (JSON) |
| ``/hrc/human/pose``, ``/hrc/robot/pose`` | ``geometry_msgs/msg/PoseStamped`` | where each agent is |
| ``/hrc/robot/goal`` | ``geometry_msgs/msg/PoseStamped`` | where the robot drives next (`hrc.ros2.drive`) |
| ``/hrc/map`` | ``visualization_msgs/msg/MarkerArray`` | the floor, walls, obstacles and named places, once |
| ``/hrc/routes`` | ``visualization_msgs/msg/MarkerArray`` | the best plan's routes (DELETEALL, then a line a leg) |
| ``/hrc/agents`` | ``visualization_msgs/msg/MarkerArray`` | each agent's cylinder and label |

Every header's frame is ``map`` (`scene.FRAME`: hrc's map coordinates, m, z up) and its stamp the run's
time (seconds from the task's start, as nanoseconds from the epoch), as in the Foxglove recording; the
shapes, sizes and colours are `hrc.record.scene`'s. The message definitions below are those of ROS 2's
``std_msgs``, ``geometry_msgs`` and ``visualization_msgs`` 5.5 (Kilted Kaiju and Jazzy share them), in the
concatenated form rosbag2 stores (the type, then ``MSG: pkg/Type`` sections for what it uses).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, BinaryIO

import shapely
from mcap_ros2.writer import Writer

from hrc.model import Task
from hrc.record import scene

__all__ = ["DEFINITIONS", "Ros2Out", "agents_markers", "map_markers", "pose_stamped", "routes_markers"]

_SEP = "=" * 80
_TIME = "int32 sec\nuint32 nanosec"
_HEADER = "builtin_interfaces/Time stamp\nstring frame_id"
_POINT = "float64 x\nfloat64 y\nfloat64 z"
_QUATERNION = "float64 x\nfloat64 y\nfloat64 z\nfloat64 w"
_POSE = "Point position\nQuaternion orientation"
_COLOR = "float32 r\nfloat32 g\nfloat32 b\nfloat32 a"
_MARKER = """int32 ARROW=0
int32 CUBE=1
int32 SPHERE=2
int32 CYLINDER=3
int32 LINE_STRIP=4
int32 LINE_LIST=5
int32 CUBE_LIST=6
int32 SPHERE_LIST=7
int32 POINTS=8
int32 TEXT_VIEW_FACING=9
int32 MESH_RESOURCE=10
int32 TRIANGLE_LIST=11
int32 ARROW_STRIP=12
int32 ADD=0
int32 MODIFY=0
int32 DELETE=2
int32 DELETEALL=3
std_msgs/Header header
string ns
int32 id
int32 type
int32 action
geometry_msgs/Pose pose
geometry_msgs/Vector3 scale
std_msgs/ColorRGBA color
builtin_interfaces/Duration lifetime
bool frame_locked
geometry_msgs/Point[] points
std_msgs/ColorRGBA[] colors
string texture_resource
sensor_msgs/CompressedImage texture
UVCoordinate[] uv_coordinates
string text
string mesh_resource
MeshFile mesh_file
bool mesh_use_embedded_materials"""


def _definition(main: str, *parts: tuple[str, str]) -> str:
    return "\n".join([main, *(f"{_SEP}\nMSG: {name}\n{text}" for name, text in parts)]) + "\n"


DEFINITIONS: dict[str, str] = {
    "std_msgs/msg/String": "string data\n",
    "geometry_msgs/msg/PoseStamped": _definition(
        "std_msgs/Header header\nPose pose",
        ("std_msgs/Header", _HEADER), ("builtin_interfaces/Time", _TIME), ("geometry_msgs/Pose", _POSE),
        ("geometry_msgs/Point", _POINT), ("geometry_msgs/Quaternion", _QUATERNION)),
    "visualization_msgs/msg/MarkerArray": _definition(
        "Marker[] markers",
        ("visualization_msgs/Marker", _MARKER), ("std_msgs/Header", _HEADER), ("builtin_interfaces/Time", _TIME),
        ("geometry_msgs/Pose", _POSE), ("geometry_msgs/Point", _POINT), ("geometry_msgs/Quaternion", _QUATERNION),
        ("geometry_msgs/Vector3", _POINT), ("std_msgs/ColorRGBA", _COLOR),
        ("builtin_interfaces/Duration", _TIME),
        ("sensor_msgs/CompressedImage", "std_msgs/Header header\nstring format\nuint8[] data"),
        ("visualization_msgs/UVCoordinate", "float32 u\nfloat32 v"),
        ("visualization_msgs/MeshFile", "string filename\nuint8[] data")),
}
"""ROS 2 message definitions by type name, as the schemas of a ROS-typed recording."""

CUBE, CYLINDER, LINE_STRIP, TEXT, TRIANGLES = 1, 3, 4, 9, 11  # Marker.type
ADD, DELETEALL = 0, 3  # Marker.action


def _stamp(t: float) -> dict[str, int]:
    ns = round(t * 1e9)
    return {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}


def _header(t: float) -> dict[str, Any]:
    return {"stamp": _stamp(t), "frame_id": scene.FRAME}


def _pose(x: float, y: float, z: float, yaw: float = 0.0) -> dict[str, Any]:
    q = (0.0, 0.0, 0.0, 1.0) if yaw == 0 else (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))
    return {"position": {"x": x, "y": y, "z": z}, "orientation": dict(zip("xyzw", q, strict=True))}


def _rgba(hex_color: str, alpha: float) -> dict[str, float]:
    r, g, b = (int(hex_color[k:k + 2], 16) / 255 for k in (1, 3, 5))
    return {"r": round(r, 4), "g": round(g, 4), "b": round(b, 4), "a": alpha}


_OBSTACLE = {"r": 0.45, "g": 0.45, "b": 0.5, "a": 0.85}
_FLOOR = {"r": 0.93, "g": 0.93, "b": 0.9, "a": 1.0}
_WALL = {"r": 0.2, "g": 0.2, "b": 0.2, "a": 1.0}
_PLACE = {"r": 0.25, "g": 0.55, "b": 0.3, "a": 0.9}
_INK = {"r": 0.1, "g": 0.1, "b": 0.1, "a": 1.0}


def _marker(t: float, ns: str, mid: int, kind: int, pose: dict[str, Any], scale: tuple[float, float, float],
            color: dict[str, float], points: Sequence[tuple[float, float, float]] = (), text: str = "",
            action: int = ADD) -> dict[str, Any]:
    return {"header": _header(t), "ns": ns, "id": mid, "type": kind, "action": action, "pose": pose,
            "scale": dict(zip("xyz", scale, strict=True)), "color": color,
            "lifetime": {"sec": 0, "nanosec": 0}, "frame_locked": False,
            "points": [{"x": x, "y": y, "z": z} for x, y, z in points], "colors": [], "texture_resource": "",
            "texture": {"header": _header(0.0), "format": "", "data": b""}, "uv_coordinates": [], "text": text,
            "mesh_resource": "", "mesh_file": {"filename": "", "data": b""}, "mesh_use_embedded_materials": False}


def _prism_points(polygon: Sequence[tuple[float, float]]) -> list[tuple[float, float, float]]:
    """`scene._prism`'s triangles (top and sides of an upright prism over the polygon), as points."""
    ring = [(float(x), float(y)) for x, y in polygon]
    h = scene.OBSTACLE_HEIGHT
    points = []
    for tri in shapely.get_parts(shapely.constrained_delaunay_triangles(shapely.Polygon(ring))):
        points += [(x, y, h) for x, y in list(tri.exterior.coords)[:3]]
    for (x0, y0), (x1, y1) in zip(ring, ring[1:] + ring[:1], strict=True):
        points += [(x0, y0, 0.0), (x1, y1, 0.0), (x1, y1, h), (x0, y0, 0.0), (x1, y1, h), (x0, y0, h)]
    return points


def map_markers(task: Task) -> dict[str, Any]:
    """The shop floor (`scene.map_update`): ns ``map`` (floor slab 0, walls 1, each obstacle from 2) and
    ``places`` (a disc 2k and the name 2k+1 of the k-th location)."""
    ws = task.workspace
    x0, y0, x1, y1 = ws.bounds
    markers = [_marker(0.0, "map", 0, CUBE, _pose((x0 + x1) / 2, (y0 + y1) / 2, -0.01), (x1 - x0, y1 - y0, 0.02),
                       _FLOOR),
               _marker(0.0, "map", 1, LINE_STRIP, _pose(0.0, 0.0, 0.0), (0.06, 0.0, 0.0), _WALL,
                       [(x, y, 0.0) for x, y in ((x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0))])]
    for k, ob in enumerate(ws.obstacles, 2):
        rect = scene._rectangle(ob.polygon)
        if rect is not None:
            a, b, c, d = rect
            markers.append(_marker(0.0, "map", k, CUBE, _pose((a + c) / 2, (b + d) / 2, scene.OBSTACLE_HEIGHT / 2),
                                   (c - a, d - b, scene.OBSTACLE_HEIGHT), _OBSTACLE))
        else:
            markers.append(_marker(0.0, "map", k, TRIANGLES, _pose(0.0, 0.0, 0.0), (1.0, 1.0, 1.0), _OBSTACLE,
                                   _prism_points(ob.polygon)))
    for k, loc in enumerate(ws.locations):
        markers.append(_marker(0.0, "places", 2 * k, CYLINDER, _pose(loc.x, loc.y, 0.005), (0.3, 0.3, 0.01), _PLACE))
        markers.append(_marker(0.0, "places", 2 * k + 1, TEXT, _pose(loc.x, loc.y, 0.3), (0.0, 0.0, 0.25), _INK,
                               text=loc.id))
    return {"markers": markers}


def agents_markers(task: Task, t: float, where: Mapping[str, tuple[float, float]], labels: Mapping[str, str],
                   present: Mapping[str, bool]) -> dict[str, Any]:
    """Each agent (`scene.agents_update`): ns ``agent/ID``, its cylinder (id 0) and label (id 1), replaced
    by the next message."""
    markers = []
    for agent in task.agents:
        if agent.id not in where:
            continue
        x, y = where[agent.id]
        h = scene.AGENT_HEIGHT[agent.is_human]
        color = _rgba(scene.agent_color(task, agent.id), 0.9 if present.get(agent.id, True) else 0.2)
        markers.append(_marker(t, f"agent/{agent.id}", 0, CYLINDER, _pose(x, y, h / 2),
                               (2 * agent.radius, 2 * agent.radius, h), color))
        markers.append(_marker(t, f"agent/{agent.id}", 1, TEXT, _pose(x, y, h + 0.3), (0.0, 0.0, 0.22), _INK,
                               text=labels.get(agent.id, agent.id)))
    return {"markers": markers}


def routes_markers(task: Task, t: float, routes: Mapping[str, Sequence[Mapping[str, Any]]]) -> dict[str, Any]:
    """The plan's routes (`scene.routes_update`): a DELETEALL (the last plan's routes go), then ns
    ``route/ID``, one line strip per leg of at least two points."""
    markers = [_marker(t, "route", 0, LINE_STRIP, _pose(0.0, 0.0, 0.0), (0.0, 0.0, 0.0), _INK, action=DELETEALL)]
    for agent in task.agents:
        z = 0.03 if agent.is_human else 0.05
        color = _rgba(scene.agent_color(task, agent.id), 0.8)
        legs = [leg.get("points") or [] for leg in routes.get(agent.id, ())]
        for k, pts in enumerate(p for p in legs if len(p) >= 2):
            markers.append(_marker(t, f"route/{agent.id}", k, LINE_STRIP, _pose(0.0, 0.0, 0.0), (0.05, 0.0, 0.0),
                                   color, [(float(x), float(y), z) for x, y in pts]))
    return {"markers": markers}


def pose_stamped(t: float, x: float, y: float, yaw: float = 0.0) -> dict[str, Any]:
    return {"header": _header(t), "pose": _pose(x, y, 0.0, yaw)}


class Ros2Out:
    """The writing end of `hrc.record.recorder.RunRecorder` in ROS 2 types (the module docstring), the
    same calls as its Foxglove end. Deterministic: MCAP's Python writer, zstd chunks, no clock read."""

    def __init__(self, sink: BinaryIO, task: Task) -> None:
        self.task = task
        self._writer = Writer(sink)
        self._schemas = {name: self._writer.register_msgdef(name, text) for name, text in DEFINITIONS.items()}
        self._pose_topic = {a.id: scene.pose_topic(task, a.id) for a in task.agents}

    def _write(self, topic: str, type_name: str, message: Any, ns: int) -> None:
        self._writer.write_message(topic, self._schemas[type_name], message, log_time=ns, publish_time=ns)

    def _text(self, topic: str, data: bytes, ns: int) -> None:
        self._write(topic, "std_msgs/msg/String", {"data": data.decode("utf-8", "replace")}, ns)

    def metadata(self, info: Mapping[str, str]) -> None:
        self._writer.add_metadata("hrc", dict(info))

    def map(self) -> None:
        self._write("/hrc/map", "visualization_msgs/msg/MarkerArray", map_markers(self.task), 0)

    def message(self, data: bytes, ns: int) -> None:
        self._text("/hrc/in", data, ns)

    def answer(self, data: bytes, ns: int) -> None:
        self._text("/hrc/out", data, ns)

    def log(self, t: float, ok: bool, text: str, name: str, ns: int) -> None:
        """Foxglove's /hrc/log has no ROS counterpart here: /hrc/in and /hrc/out carry the same."""

    def decision(self, data: bytes, ns: int) -> None:
        self._text("/hrc/decision", data, ns)

    def routes(self, t: float, legs: Mapping[str, Sequence[Mapping[str, Any]]], ns: int) -> None:
        self._write("/hrc/routes", "visualization_msgs/msg/MarkerArray", routes_markers(self.task, t, legs), ns)

    def pose(self, agent: str, t: float, x: float, y: float, ns: int) -> None:
        self._write(self._pose_topic[agent], "geometry_msgs/msg/PoseStamped", pose_stamped(t, x, y), ns)

    def goal(self, t: float, x: float, y: float, heading: float, ns: int, robot: str | None = None) -> None:
        self._write(scene.goal_topic(robot), "geometry_msgs/msg/PoseStamped", pose_stamped(t, x, y, heading), ns)

    def agents(self, t: float, where: Mapping[str, tuple[float, float]], labels: Mapping[str, str],
               present: Mapping[str, bool], ns: int) -> None:
        self._write("/hrc/agents", "visualization_msgs/msg/MarkerArray",
                    agents_markers(self.task, t, where, labels, present), ns)

    def close(self) -> None:
        self._writer.finish()
