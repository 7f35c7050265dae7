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
from typing import Any

import shapely
from shapely.geometry import Point, Polygon

from hrc.errors import MapFileError
from hrc.io.atomic import write_text_atomic
from hrc.io.yamldoc import Doc, read_yaml
from hrc.model import Location, Obstacle, Workspace

__all__ = ["dump_workspace", "load_workspace", "workspace_to_dict"]


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
        dxf = os.path.join(os.path.dirname(doc.file), floorplan)
        obstacles += _dxf_obstacles(doc, dxf, {o.id for o in obstacles})
    raw_locs = doc.mapping(top["locations"], ("locations",), optional=tuple(top["locations"] or ()))
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
    xmin, ymin, xmax, ymax = (doc.number(v, ("bounds", i)) for i, v in enumerate(seq))
    if xmin >= xmax or ymin >= ymax:
        doc.fail(("bounds",), f"empty area: need xmin < xmax and ymin < ymax, found {seq}")
    return (xmin, ymin, xmax, ymax)


def _point(doc: Doc, raw: Any, path: tuple) -> tuple[float, float]:
    seq = doc.sequence(raw, path)
    if len(seq) != 2:
        doc.fail(path, f"expected [x, y], found a list of {len(seq)}")
    return (doc.number(seq[0], path + (0,)), doc.number(seq[1], path + (1,)))


def _obstacle(doc: Doc, raw: Any, path: tuple) -> Obstacle:
    m = doc.mapping(raw, path, required=("id",), optional=("polygon", "rect"))
    oid = doc.ident(m["id"], path + ("id",))
    if ("polygon" in m) == ("rect" in m):
        doc.fail(path, "give exactly one of 'polygon' or 'rect'")
    if "rect" in m:
        seq = doc.sequence(m["rect"], path + ("rect",))
        if len(seq) != 4:
            doc.fail(path + ("rect",), f"expected [xmin, ymin, xmax, ymax], found a list of {len(seq)}")
        x0, y0, x1, y1 = (doc.number(v, path + ("rect", i)) for i, v in enumerate(seq))
        if x0 >= x1 or y0 >= y1:
            doc.fail(path + ("rect",), "empty rectangle: need xmin < xmax and ymin < ymax")
        pts = ((x0, y0), (x1, y0), (x1, y1), (x0, y1))
    else:
        seq = doc.sequence(m["polygon"], path + ("polygon",), min_len=3)
        pts = tuple(_point(doc, p, path + ("polygon", i)) for i, p in enumerate(seq))
    poly = Polygon(pts)
    if not poly.is_valid or poly.area <= 0:
        doc.fail(path, f"obstacle '{oid}' is not a simple polygon with positive area")
    return Obstacle(id=oid, polygon=pts)


def _location(doc: Doc, key: Any, value: Any) -> Location:
    path = ("locations", key)
    lid = doc.ident(key, path)
    x, y = _point(doc, value, path)
    return Location(id=lid, x=x, y=y)


def _dxf_obstacles(doc: Doc, dxf: str, taken: set[str]) -> list[Obstacle]:
    """Closed polylines of a DXF floor plan, as obstacles ``dxf1``, ``dxf2``, ... (trimesh reads DXF)."""
    import trimesh  # heavy; only when a map has a floor plan

    if not os.path.isfile(dxf):
        doc.fail(("floorplan",), f"DXF floor plan '{dxf}' does not exist")
    try:
        path2d = trimesh.load_path(dxf)
        polys = list(path2d.polygons_closed)
    except Exception as err:  # trimesh raises many kinds on a bad DXF
        raise MapFileError(dxf, "", f"cannot read DXF floor plan: {err}") from err
    out = []
    for poly in polys:
        if poly is None or poly.area <= 0:
            continue
        coords = tuple((round(float(x), 9), round(float(y), 9)) for x, y in poly.exterior.coords[:-1])
        n = len(out) + 1
        while f"dxf{n}" in taken:
            n += 1
        out.append(Obstacle(id=f"dxf{n}", polygon=coords))
        taken.add(f"dxf{n}")
    if not out:
        raise MapFileError(dxf, "", "DXF floor plan has no closed polylines")
    return out


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


def workspace_to_dict(ws: Workspace) -> dict[str, Any]:
    """The YAML-ready form of `ws`; floor-plan obstacles are written back as the floor plan reference."""
    out: dict[str, Any] = {"name": ws.name, "bounds": list(ws.bounds)}
    if ws.floorplan is not None:
        out["floorplan"] = ws.floorplan
    out["obstacles"] = [{"id": o.id, "polygon": [list(p) for p in o.polygon]}
                        for o in ws.obstacles if not (ws.floorplan and o.id.startswith("dxf"))]
    out["locations"] = {loc.id: [loc.x, loc.y] for loc in ws.locations}
    return out


def dump_workspace(ws: Workspace, path: str | os.PathLike[str]) -> None:
    """Write `ws` as a map YAML file, atomically."""
    import yaml

    write_text_atomic(path, yaml.safe_dump(workspace_to_dict(ws), sort_keys=False))
