"""Route signatures: which route a plan sends an agent along on each of its legs, as set validation reads
it (Strassmair & Taylor 2014, section V.B: a plan stays a candidate only while it agrees with what was
seen; `hrc.dispatch.validation`, "Routes").

Plans that agree on who does what in which order may still send an agent along different routes on the
same leg: straight, round a detour, or with a stop at a waiting place (the compile's motion pattern). A
route is told by its signature ``(stops, first, second)``: whether it stops at a waiting place (0/1), the
upper bound (ticks) of its first stretch of travel (to the stop, or to the location) and of its second
(from the stop on; -1: none). A detour takes longer than the straight route, so the bounds tell them
apart.

`route_signature` is the definition, on a plan's STNU; `route_signatures` the same for many plans at
once from the dispatch form's arrays (`hrc.compile.dispatch_form`), vectorised over their edges and
contingent links. The compile computes them once per network shape (plans of one shape have the same
arrays, hence the same routes) and stores them with the form (``routes.npy``), so the dispatcher only
reads them: making them for the 20,160 plans of a six-pick two-robot kitting at a first departure cost
26 ms a message, twice a run (issue 37).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from hrc.temporal.network import STNU

__all__ = ["RouteSig", "route_signature", "route_signatures"]

RouteSig = tuple[int, int, int]
"""A leg's route: stops at a waiting place (0/1), the upper bound (ticks) of its first stretch of travel
(to the stop, or to the location), of its second (from the stop on; -1: none)."""


def route_signature(stnu: STNU, points: Mapping[str, str]) -> RouteSig:
    """The route of one leg of a plan from its STNU (`points`: the leg's event -> its timepoint, as
    ``PlanEntry.leg_points`` gives them): the tightest bound of ``T(stop) - T(depart)`` its requirement
    links (and contingent links of one fixed duration) give, else its contingent link's upper bound, else
    -1; the same for ``T(arrive) - T(unpark)`` after a waiting place."""

    def stretch(a: str, b: str) -> int:
        found: list[int] = []
        for r in stnu.requirements:
            if (r.source, r.target) == (a, b) and r.ub is not None:
                found.append(r.ub)
            if (r.source, r.target) == (b, a) and r.lb is not None:
                found.append(-r.lb)
        for c in stnu.contingents:
            if (c.source, c.target) == (a, b) and c.lb == c.ub:
                found.append(c.ub)
        if found:
            return min(found)
        return next((c.ub for c in stnu.contingents if (c.source, c.target) == (a, b)), -1)

    if "park" in points:
        return (1, stretch(points["depart"], points["park"]), stretch(points["unpark"], points["arrive"]))
    return (0, stretch(points["depart"], points["arrive"]), -1)


def route_signatures(nodes: np.ndarray, edges: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                     conts: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                     plans: np.ndarray) -> np.ndarray:
    """``(len(plans), G, L, 3)`` int64: `route_signature` of every leg position of `plans` (indices),
    from the form's arrays: `nodes` (P, G, L, 6), `edges` its ``(edges_ptr, edges_u, edges_v, edges_w)``
    and `conts` its ``(conts_ptr, conts_a, conts_c, conts_ub)``. A form's edges are its STNU's bounds
    merged to the tightest per ordered pair, contingent links of one fixed duration among them, so the
    definition's "tightest bound" is the edge, else the contingent link's upper bound. One pass per
    stretch over the plans' rows, each row's leg found through the inverse of ``nodes`` (a timepoint
    starts at most one stretch). Cost: O(plans x timepoints + their edges and links)."""
    plans = np.asarray(plans, dtype=np.int64)
    node = np.asarray(nodes[plans], dtype=np.int64)  # (n, G, L, 6)
    n, G, L, _ = node.shape
    dep, park, unpark, arr = (node[..., e].reshape(n, G * L) for e in (0, 1, 2, 3))
    out = np.full((n, G * L, 3), -1, dtype=np.int64)
    out[..., 0] = (park >= 0).astype(np.int64)
    width = int(node.max(initial=0)) + 1
    rows = np.repeat(np.arange(n), G * L).reshape(n, G * L)
    legs = np.tile(np.arange(G * L), n).reshape(n, G * L)
    for col, (a, b) in enumerate(((dep, np.where(park >= 0, park, arr)), (unpark, arr)), start=1):
        ok = (a >= 0) & (b >= 0)
        inverse = np.full((n, width), -1, dtype=np.int64)  # plan, timepoint -> the leg it starts a stretch of
        inverse[rows[ok], a[ok]] = legs[ok]
        for (ptr, us, vs, ws), tightest in ((conts, False), (edges, True)):
            start = np.asarray(ptr[plans], dtype=np.int64)
            count = np.asarray(ptr[plans + 1], dtype=np.int64) - start
            total = int(count.sum())
            if not total:
                continue
            owner = np.repeat(np.arange(n), count)
            idx = np.arange(total) - np.repeat(np.cumsum(count) - count, count) + np.repeat(start, count)
            u = np.asarray(us[idx], dtype=np.int64)
            v = np.asarray(vs[idx], dtype=np.int64)
            j = inverse[owner, np.minimum(u, width - 1)]
            j = np.where(u < width, j, -1)
            hit = j >= 0
            hit[hit] = b[owner[hit], j[hit]] == v[hit]
            o, jj, w = owner[hit], j[hit], np.asarray(ws[idx[hit]], dtype=np.int64)
            if tightest:  # edges over contingent links: the tightest fixed bound wins
                best = np.full((n, G * L), np.iinfo(np.int64).max, dtype=np.int64)
                np.minimum.at(best, (o, jj), w)
                out[o, jj, col] = best[o, jj]
            else:
                out[o, jj, col] = w
    return out.reshape(n, G, L, 3)
