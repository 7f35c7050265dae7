"""Walking distances on the shop floor: one geodesic distance field per named location.

A person walking to a location takes a shortest route through the free space (the routes motion
acquisition plans for them are such routes, `hrc.motion.paths`). Over a grid of the map (`RESOLUTION`
metres), the cells where the person's disc fits (outside every obstacle grown by the person's radius)
form a 16-connected graph; Dijkstra's algorithm from each location gives the walking distance from
every free cell to it (`scipy.sparse.csgraph.dijkstra`). `GeodesicMap.distance` reads a field at any
point, bilinearly inside free space; a point inside an obstacle (a noisy position) is read at the
nearest free cell, plus the straight distance to it.

The detector's destination filter (`hrc.detect.filter`) reads these fields: a person who heads for
location G lowers the walking distance to G as fast as they walk (Ziebart et al. 2009, Dragan &
Srinivasa 2013: goal inference from the progress of a near-optimal walker).

Cost: O(C log C) per location for C grid cells (the workshop: 8,000 cells, ten locations, about
30 ms); a read is O(1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import shapely
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra

from hrc.model import Workspace

__all__ = ["RESOLUTION", "GeodesicMap", "geodesic_map"]

RESOLUTION = 0.1
"""Metres per grid cell of the distance fields."""


@dataclass(frozen=True, slots=True, eq=False)
class GeodesicMap:
    """Walking distance fields (m) to each location over a grid: ``fields[k]`` is location
    ``locations[k]``'s, shape (ny, nx), cell (i, j) centred at ``(x0 + j * res, y0 + i * res)``; inf where
    the person cannot stand or the location cannot be reached. `near` maps each cell to the nearest
    free cell (flat index)."""

    locations: tuple[str, ...]
    x0: float
    y0: float
    res: float
    free: np.ndarray
    fields: np.ndarray
    near: np.ndarray

    def index(self, location: str) -> int:
        return self.locations.index(location)

    def distance(self, k: int, x: float, y: float) -> float:
        """Walking distance (m) from (x, y) to location `k` (an index into `locations`)."""
        ny, nx = self.free.shape
        fx = (x - self.x0) / self.res
        fy = (y - self.y0) / self.res
        j = min(max(int(math.floor(fx)), 0), nx - 2)
        i = min(max(int(math.floor(fy)), 0), ny - 2)
        ax = min(max(fx - j, 0.0), 1.0)
        ay = min(max(fy - i, 0.0), 1.0)
        f = self.fields[k]
        a, b, c, d = f[i, j], f[i, j + 1], f[i + 1, j], f[i + 1, j + 1]
        if math.isfinite(a + b + c + d):
            return float((a * (1 - ax) + b * ax) * (1 - ay) + (c * (1 - ax) + d * ax) * ay)
        # at the edge of free space, or inside an obstacle: the nearest free cell
        ci = min(max(int(round(fy)), 0), ny - 1)
        cj = min(max(int(round(fx)), 0), nx - 1)
        flat = int(self.near[ci, cj])
        fi, fj = divmod(flat, nx)
        step = math.hypot(self.x0 + fj * self.res - x, self.y0 + fi * self.res - y)
        return float(f[fi, fj]) + step


def geodesic_map(workspace: Workspace, radius: float, res: float = RESOLUTION) -> GeodesicMap:
    """The walking distance fields of every location of `workspace` for a disc of `radius` (m).

    A location whose cell is not free (it lies closer to an obstacle than `radius`) is joined to the
    grid at its nearest free cell."""
    xmin, ymin, xmax, ymax = workspace.bounds
    nx = int(math.floor((xmax - xmin) / res)) + 1
    ny = int(math.floor((ymax - ymin) / res)) + 1
    xs = xmin + res * np.arange(nx)
    ys = ymin + res * np.arange(ny)
    gx, gy = np.meshgrid(xs, ys)
    inside = (gx >= xmin + radius) & (gx <= xmax - radius) & (gy >= ymin + radius) & (gy <= ymax - radius)
    blocked = np.zeros_like(inside)
    if workspace.obstacles:
        grown = shapely.union_all([shapely.Polygon(o.polygon).buffer(radius, quad_segs=4)
                                   for o in workspace.obstacles])
        blocked = shapely.contains_xy(grown, gx, gy)
    free = inside & ~blocked
    # a graph over the free cells: 16 neighbours (the knight's moves too, whose two cells on the way must
    # be free), so that a straight walk in any direction is measured within 2 % of its length
    ii, jj = np.nonzero(free)
    rows: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    wts: list[np.ndarray] = []
    for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1), (1, 2), (2, 1), (1, -2), (2, -1)):
        ti, tj = ii + di, jj + dj
        ok = (ti < ny) & (tj >= 0) & (tj < nx)
        ok[ok] = free[ti[ok], tj[ok]]
        for mi, mj in {(di // 2, dj // 2), (-(-di // 2), -(-dj // 2))} - {(0, 0), (di, dj)}:
            ok[ok] = free[ii[ok] + mi, jj[ok] + mj]
        rows.append(ii[ok] * nx + jj[ok])
        cols.append(ti[ok] * nx + tj[ok])
        wts.append(np.full(int(ok.sum()), res * math.hypot(di, dj)))
    r = np.concatenate(rows)
    c = np.concatenate(cols)
    w = np.concatenate(wts)
    graph = coo_matrix((np.concatenate([w, w]), (np.concatenate([r, c]), np.concatenate([c, r]))),
                       shape=(nx * ny, nx * ny)).tocsr()
    _, (ni, nj) = ndimage.distance_transform_edt(~free, return_indices=True)
    near = ni * nx + nj
    names = workspace.location_ids
    sources = []
    offsets = []
    for loc in workspace.locations:
        cj = min(max(int(round((loc.x - xmin) / res)), 0), nx - 1)
        ci = min(max(int(round((loc.y - ymin) / res)), 0), ny - 1)
        flat = int(near[ci, cj])
        fi, fj = divmod(flat, nx)
        sources.append(flat)
        offsets.append(math.hypot(xs[fj] - loc.x, ys[fi] - loc.y))
    dist = dijkstra(graph, directed=False, indices=sources) if sources else np.zeros((0, nx * ny))
    fields = np.asarray(dist, dtype=np.float64).reshape(len(names), ny, nx) + np.array(offsets)[:, None, None]
    fields[:, ~free] = np.inf
    return GeodesicMap(names, float(xmin), float(ymin), float(res), free, fields, near)
