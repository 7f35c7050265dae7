"""Load and write the workspace map (YAML, optionally with a DXF floor plan); see docs/task-format.md.

    name: workshop
    bounds: [0, 0, 10, 8]                  # xmin, ymin, xmax, ymax (m)
    floorplan: workshop.dxf                # optional; closed polylines become obstacles
    obstacles:
      - {id: table, rect: [4.3, 3.0, 5.7, 3.8]}          # or polygon: [[x, y], ...]
    locations:
      T: [5.0, 4.4]
"""

from __future__ import annotations

import os
import re
from typing import Any

import shapely
from shapely.geometry import Point, Polygon

from hrc.errors import MapFileError
from hrc.io.atomic import write_text_atomic
from hrc.io.yamldoc import Doc, read_yaml
from hrc.model import Location, Obstacle, Workspace

__all__ = ["clearance", "dump_workspace", "load_workspace", "workspace_to_dict"]

_DXF_ID = re.compile(r"dxf[0-9]+")

MAX_COORDINATE = 1e5  # m: a coordinate of a shop floor's map at most this far from its origin (100 km). The
# geometry (shapely, FCL, OMPL) works in doubles; a coordinate near 1e154 overflows in a buffer (found by
# tests/test_io_errors.py's fuzz) and one of 1e15 leaves no room for millimetres.


def load_workspace(path: str | os.PathLike[str]) -> Workspace:
    """Read and validate a map file; raises `MapFileError` naming file, line and key on bad input."""
    doc = read_yaml(path, MapFileError)
    top = doc.mapping(doc.value, (), required=("bounds", "locations"),
                      optional=("name", "obstacles", "floorplan"))
    name = doc.text(top.get("name", os.path.splitext(os.path.basename(doc.file))[0]), ("name",))
    bounds = _bounds(doc, top["bounds"])
    obstacles = [_obstacle(doc, raw, ("obstacles", i)) for i, raw in
                 enumerate(doc.sequence(top.get("obstacles", []), ("obstacles",)))]
    doc.unique([o.id for o in obstacles], ("obstacles",), "obstacle")
    floorplan = None
    if "floorplan" in top:
        floorplan = doc.text(top["floorplan"], ("floorplan",))
        for i, o in enumerate(obstacles):
            if _DXF_ID.fullmatch(o.id):
                doc.fail(("obstacles", i, "id"), f"ids dxf1, dxf2, ... are reserved for the floor plan's "
                                                 f"obstacles, found '{o.id}'")
        dxf = os.path.join(os.path.dirname(doc.file), floorplan)
        obstacles += _dxf_obstacles(doc, dxf)
    raw = top["locations"]
    raw_locs = doc.mapping(raw, ("locations",), optional=tuple(raw) if isinstance(raw, dict) else ())
    if not raw_locs:
        doc.fail(("locations",), "expected at least one location")
    locations = [_location(doc, key, value) for key, value in raw_locs.items()]
    ws = Workspace(name=name, bounds=bounds, obstacles=tuple(obstacles), locations=tuple(locations),
                   floorplan=floorplan, source=doc.file)
    _check_geometry(doc, ws)
    return ws


def _bounds(doc: Doc, raw: Any) -> tuple[float, float, float, float]:
    seq = doc.sequence(raw, ("bounds",))
    if len(seq) != 4:
        doc.fail(("bounds",), f"expected [xmin, ymin, xmax, ymax], found a list of {len(seq)}")
    xmin, ymin, xmax, ymax = (doc.number(v, ("bounds", i), maximum=MAX_COORDINATE, unit=" m")
                              for i, v in enumerate(seq))
    if xmin >= xmax or ymin >= ymax:
        doc.fail(("bounds",), f"empty area: need xmin < xmax and ymin < ymax, found {seq}")
    return (xmin, ymin, xmax, ymax)


def _point(doc: Doc, raw: Any, path: tuple) -> tuple[float, float]:
    seq = doc.sequence(raw, path)
    if len(seq) != 2:
        doc.fail(path, f"expected [x, y], found a list of {len(seq)}")
    return (doc.number(seq[0], path + (0,), maximum=MAX_COORDINATE, unit=" m"),
            doc.number(seq[1], path + (1,), maximum=MAX_COORDINATE, unit=" m"))


def _obstacle(doc: Doc, raw: Any, path: tuple) -> Obstacle:
    m = doc.mapping(raw, path, required=("id",), optional=("polygon", "rect"))
    oid = doc.ident(m["id"], path + ("id",))
    if ("polygon" in m) == ("rect" in m):
        doc.fail(path, "give exactly one of 'polygon' or 'rect'")
    if "rect" in m:
        seq = doc.sequence(m["rect"], path + ("rect",))
        if len(seq) != 4:
            doc.fail(path + ("rect",), f"expected [xmin, ymin, xmax, ymax], found a list of {len(seq)}")
        x0, y0, x1, y1 = (doc.number(v, path + ("rect", i), maximum=MAX_COORDINATE, unit=" m")
                          for i, v in enumerate(seq))
        if x0 >= x1 or y0 >= y1:
            doc.fail(path + ("rect",), "empty rectangle: need xmin < xmax and ymin < ymax")
        pts: tuple[tuple[float, float], ...] = ((x0, y0), (x1, y0), (x1, y1), (x0, y1))
    else:
        seq = doc.sequence(m["polygon"], path + ("polygon",), min_len=3)
        pts = tuple(_point(doc, p, path + ("polygon", i)) for i, p in enumerate(seq))
        if pts[0] == pts[-1]:  # a closing point repeating the first is allowed, and dropped
            pts = pts[:-1]
        if len(pts) < 3:
            doc.fail(path + ("polygon",), f"expected at least 3 corners, found {len(pts)}")
    poly = Polygon(pts)
    if not poly.is_valid or poly.area <= 0:
        doc.fail(path, f"obstacle '{oid}' is not a simple polygon with positive area")
    return Obstacle(id=oid, polygon=pts)


def _location(doc: Doc, key: Any, value: Any) -> Location:
    path = ("locations", key)
    lid = doc.ident(key, path)
    x, y = _point(doc, value, path)
    return Location(id=lid, x=x, y=y)


def _dxf_obstacles(doc: Doc, dxf: str) -> list[Obstacle]:
    """Closed polylines of a DXF floor plan, as obstacles ``dxf1``, ``dxf2``, ... (trimesh reads DXF).

    Errors name the map file and its ``floorplan`` key (where the user can act), and the DXF file.
    """
    import trimesh  # heavy; only when a map has a floor plan

    if not os.path.isfile(dxf):
        doc.fail(("floorplan",), f"DXF floor plan '{dxf}' does not exist")
    try:
        # open it ourselves: trimesh.load_path(name) leaves the file open (a ResourceWarning)
        with open(dxf, "rb") as fh:
            path2d = trimesh.load_path(fh, file_type="dxf")
        polys = list(path2d.polygons_closed)
    except Exception as err:  # trimesh raises many kinds on a bad DXF, and IndexError on an empty one
        if _looks_like_dxf_without_polylines(dxf):
            raise MapFileError(doc.file, "floorplan", f"DXF floor plan '{dxf}' has no closed polylines",
                               doc.line(("floorplan",))) from err
        reason = " ".join(str(err).split()) or type(err).__name__
        raise MapFileError(doc.file, "floorplan", f"cannot read DXF floor plan '{dxf}': {reason}",
                           doc.line(("floorplan",))) from err
    out: list[Obstacle] = []
    for poly in polys:
        if poly is None or poly.area <= 0:
            continue
        coords = tuple((round(float(x), 9), round(float(y), 9)) for x, y in poly.exterior.coords[:-1])
        out.append(Obstacle(id=f"dxf{len(out) + 1}", polygon=coords))
    if not out:
        doc.fail(("floorplan",), f"DXF floor plan '{dxf}' has no closed polylines")
    return out


def _looks_like_dxf_without_polylines(dxf: str) -> bool:
    """A text DXF (ends with the EOF group) with no (LW)POLYLINE entity at all."""
    try:
        with open(dxf, encoding="utf-8", errors="replace") as fh:
            lines = [line.strip() for line in fh]
    except OSError:
        return False
    return bool(lines) and lines[-1] == "EOF" and not any(line.endswith("POLYLINE") for line in lines)


def _check_geometry(doc: Doc, ws: Workspace) -> None:
    xmin, ymin, xmax, ymax = ws.bounds
    polys = [(o.id, Polygon(o.polygon)) for o in ws.obstacles]
    for loc in ws.locations:
        path = ("locations", loc.id)
        if not (xmin < loc.x < xmax and ymin < loc.y < ymax):
            doc.fail(path, f"location ({loc.x:g}, {loc.y:g}) is outside the bounds {list(ws.bounds)}")
        pt = Point(loc.x, loc.y)
        for oid, poly in polys:
            if poly.covers(pt):
                doc.fail(path, f"location ({loc.x:g}, {loc.y:g}) is inside obstacle '{oid}'")


def clearance(ws: Workspace, x: float, y: float) -> tuple[float, str]:
    """Distance (m) from ``(x, y)`` to the nearest obstacle or bound, and what that is (for messages)."""
    xmin, ymin, xmax, ymax = ws.bounds
    best, what = min((x - xmin, "the west bound"), (xmax - x, "the east bound"),
                     (y - ymin, "the south bound"), (ymax - y, "the north bound"))
    pt = Point(x, y)
    for o in ws.obstacles:
        d = shapely.distance(Polygon(o.polygon), pt)
        if d < best:
            best, what = float(d), f"obstacle '{o.id}'"
    return best, what


def workspace_to_dict(ws: Workspace, floorplan: str | None = None) -> dict[str, Any]:
    """The YAML-ready form of `ws`; floor-plan obstacles are written back as the floor plan reference.

    `floorplan` overrides the reference as written (`dump_workspace` makes it relative to the new file).
    """
    out: dict[str, Any] = {"name": ws.name, "bounds": list(ws.bounds)}
    if ws.floorplan is not None:
        out["floorplan"] = floorplan or ws.floorplan
    out["obstacles"] = [{"id": o.id, "polygon": [list(p) for p in o.polygon]}
                        for o in ws.obstacles if not (ws.floorplan and _DXF_ID.fullmatch(o.id))]
    out["locations"] = {loc.id: [loc.x, loc.y] for loc in ws.locations}
    return out


def dump_workspace(ws: Workspace, path: str | os.PathLike[str]) -> None:
    """Write `ws` as a map YAML file, atomically, its `floorplan` made relative to the new file's folder."""
    import yaml

    floorplan = ws.floorplan
    if floorplan is not None and ws.source:
        dxf = os.path.join(os.path.dirname(os.path.abspath(ws.source)), floorplan)
        floorplan = os.path.relpath(dxf, os.path.dirname(os.path.abspath(os.fspath(path))))
    write_text_atomic(path, yaml.safe_dump(workspace_to_dict(ws, floorplan), sort_keys=False))
