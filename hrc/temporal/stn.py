"""Simple Temporal Networks: consistency, shortest paths, dispatchable form, one-step propagation.

Sources: Dechter, Meiri & Pearl (1991), "Temporal constraint networks" (an STN is consistent iff its
distance graph has no negative cycle; the shortest-path matrix is its minimal network); Muscettola,
Morris & Tsamardinos (1998), "Reformulating temporal plans for efficient execution", section 4
(dominated-edge removal giving the minimal dispatchable network) and section 3 (the dispatcher, which
propagates each execution to the neighbours only: APA Fig. 8 lines 19-27).

Contingent links are read as requirement links here (the STN of an STNU). Everything is exact:
integers in, integers out; `math.inf` only stands for "no path".
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

from hrc.temporal.graph import Edge, distance_edges
from hrc.temporal.network import STNU, NetworkError
from hrc.temporal.potential import feasible_potential

if TYPE_CHECKING:
    import numpy as np

__all__ = [
    "earliest_times",
    "ConsistencyResult",
    "DispatchableSTN",
    "Window",
    "all_pairs_shortest_paths",
    "check_consistency",
    "find_negative_cycle",
    "minimal_dispatchable_network",
    "propagate_execution",
    "time_windows",
]

_FLOAT_EXACT = 2**52  # float64 holds every integer below this exactly


@dataclass(frozen=True, slots=True)
class ConsistencyResult:
    """``consistent`` and, when not, a negative ``cycle`` of distance-graph edges (in path order);
    when consistent, ``solution`` is one schedule (timepoint -> integer time) meeting every link."""

    consistent: bool
    cycle: tuple[Edge, ...] = ()
    solution: Mapping[str, int] | None = None


def find_negative_cycle(nodes: Iterable[str], edges: Iterable[Edge]) -> tuple[dict[str, int], tuple[Edge, ...]]:
    """A potential of the graph, from a virtual source joined to every node by a 0 edge, or a negative cycle.

    Returns ``(potential, ())`` where ``potential[v] - potential[u] <= w`` for every edge, or
    ``({}, cycle)`` with a negative cycle in path order. Goldberg-Radzik (`hrc.temporal.potential`):
    O(n m) worst case, one or two linear passes on plan networks and chains.
    """
    names = list(nodes)
    index = {v: i for i, v in enumerate(names)}
    n = len(names)
    table = list(edges)
    out: list[list[tuple[int, int, int]]] = [[] for _ in range(n)]
    for eid, e in enumerate(table):
        out[index[e.source]].append((index[e.target], e.value, eid))
    dist = [0] * n
    cycle = feasible_potential(n, out, dist)
    if cycle is not None:
        return {}, tuple(table[eid] for eid in cycle)
    return {names[i]: dist[i] for i in range(n)}, ()


def check_consistency(stnu: STNU) -> ConsistencyResult:
    """Is the STN of ``stnu`` (contingent links as requirements) consistent?

    When it is, ``solution`` is the schedule ``T(v) = -d(v)`` with ``d`` the shortest distances from
    a virtual source, shifted so that the earliest timepoint is at 0. O(n m) worst case.

    >>> from hrc.temporal.network import RequirementLink as R
    >>> check_consistency(STNU(("A", "B", "C"), (R("A", "B", 3, 5), R("B", "C", 0, 1),
    ...                                          R("A", "C", None, 2)))).consistent
    False
    """
    potential, cycle = find_negative_cycle(stnu.timepoints, distance_edges(stnu))
    if cycle:
        return ConsistencyResult(False, cycle)
    # the potential p satisfies p[v] - p[u] <= w for u->v; so T = p is a solution already
    low = min(potential.values(), default=0)
    return ConsistencyResult(True, (), {v: p - low for v, p in potential.items()})


def all_pairs_shortest_paths(stnu: STNU) -> np.ndarray:
    """``D[i, j]`` = shortest distance from timepoint i to j (the minimal network: the tightest
    ``T(j) - T(i) <= D[i, j]``), ``inf`` where there is no path. Floyd-Warshall (scipy), O(n^3).

    Raises `NetworkError` on an inconsistent network. Values are integers held in float64; networks
    whose absolute weights sum to 2**52 or more fall back to an exact pure-Python Floyd-Warshall.
    """
    import numpy as np  # here, not at module level: `hrc check` needs neither numpy nor scipy
    from scipy.sparse.csgraph import csgraph_from_dense, floyd_warshall

    n = len(stnu.timepoints)
    index = {v: i for i, v in enumerate(stnu.timepoints)}
    edges = distance_edges(stnu)
    if any(e.source == e.target and e.value < 0 for e in edges) or not check_consistency(stnu).consistent:
        raise NetworkError("all-pairs shortest paths of an inconsistent network")
    best: dict[tuple[int, int], int] = {}
    for e in edges:
        key = (index[e.source], index[e.target])
        if key[0] != key[1] and (key not in best or e.value < best[key]):
            best[key] = e.value
    if sum(abs(w) for w in best.values()) < _FLOAT_EXACT:
        mat = np.full((n, n), np.inf)
        for (i, j), w in best.items():
            mat[i, j] = w
        # a dense 0 would mean "no edge" to scipy: convert with inf as the null value to keep 0 weights
        return floyd_warshall(csgraph_from_dense(mat, null_value=np.inf), directed=True)
    d = [[math.inf] * n for _ in range(n)]
    for i in range(n):
        d[i][i] = 0
    for (i, j), w in best.items():
        d[i][j] = w
    for k in range(n):
        dk = d[k]
        for i in range(n):
            dik = d[i][k]
            if dik == math.inf:
                continue
            di = d[i]
            for j in range(n):
                if dik + dk[j] < di[j]:
                    di[j] = dik + dk[j]
    return np.array(d, dtype=object)


@dataclass(frozen=True, slots=True)
class Window:
    """``lo <= T(x) <= hi`` relative to the origin; ``None`` for an unbounded side."""

    lo: int | None
    hi: int | None


def earliest_times(stnu: STNU, origin: str) -> dict[str, int] | None:
    """Earliest time of every timepoint after `origin` (at 0) in the STN of `stnu`, every timepoint
    taken to come at or after `origin`; None if that is inconsistent.

    Earliest(x) = -d(x, origin) in the distance graph with ``x -> origin`` edges of weight 0 added
    (Dechter, Meiri & Pearl 1991): one single-target Bellman-Ford (queue-based), O(n m) worst case and
    near-linear on plan networks, where `time_windows` needs all pairs. In the native core
    (`hrc.temporal.native_stn.native_distances`) when it is built, else here in Python: the same numbers.

    >>> from hrc.temporal.network import RequirementLink as R
    >>> earliest_times(STNU(("Z", "A", "B"), (R("Z", "A", 2, 5), R("A", "B", 1, None))), "Z")
    {'Z': 0, 'A': 2, 'B': 3}
    """
    edges = distance_edges(stnu)
    if origin not in stnu.timepoints:
        raise NetworkError(f"unknown origin {origin!r}")
    from hrc.temporal.native_stn import native_distances

    index = {t: i for i, t in enumerate(stnu.timepoints)}
    z = index[origin]
    others = [i for i in range(len(index)) if i != z]
    found = native_distances(len(index), [index[e.source] for e in edges] + others,
                             [index[e.target] for e in edges] + [z] * len(others),
                             [e.value for e in edges] + [0] * len(others), z)
    if found is not None:
        consistent, d = found
        return {t: -d[i] for t, i in index.items()} if consistent else None
    into: dict[str, list[tuple[str, int]]] = {t: [] for t in stnu.timepoints}  # target -> (source, w)
    for e in edges:
        into[e.target].append((e.source, e.value))
    for t in stnu.timepoints:
        if t != origin:
            into[origin].append((t, 0))
    dist = {origin: 0}
    hops = {origin: 0}  # edges on the current shortest path; n or more means a negative cycle
    queue, queued = deque([origin]), {origin}
    n = len(stnu.timepoints)
    while queue:
        v = queue.popleft()
        queued.discard(v)
        dv = dist[v]
        for u, w in into[v]:  # edge u -> v of weight w: d(u, origin) <= w + d(v, origin)
            if u not in dist or w + dv < dist[u]:
                dist[u] = w + dv
                hops[u] = hops[v] + 1
                if hops[u] >= n:
                    return None  # a negative cycle
                if u not in queued:
                    queued.add(u)
                    queue.append(u)
    return {t: -dist[t] for t in stnu.timepoints}


def time_windows(stnu: STNU, origin: str) -> dict[str, Window]:
    """Earliest and latest times of every timepoint relative to ``origin`` (at time 0):
    earliest(X) = -D[X, origin], latest(X) = D[origin, X] (Dechter et al. 1991)."""
    if origin not in stnu.timepoints:
        raise NetworkError(f"unknown origin {origin!r}")
    d = all_pairs_shortest_paths(stnu)
    o = stnu.timepoints.index(origin)
    out = {}
    for i, v in enumerate(stnu.timepoints):
        lo, hi = d[i, o], d[o, i]
        out[v] = Window(None if lo == math.inf else int(-lo), None if hi == math.inf else int(hi))
    return out


@dataclass(frozen=True, slots=True)
class DispatchableSTN:
    """A minimal dispatchable network: ``edges`` (ordinary, ``T(target) - T(source) <= value``) over
    ``timepoints``, such that propagating each execution to the neighbours only
    (`propagate_execution`) never leads to a dead end (Muscettola, Morris & Tsamardinos 1998)."""

    timepoints: tuple[str, ...]
    edges: tuple[Edge, ...]
    chained: tuple[tuple[str, str], ...] = ()  # (member, predecessor) along each rigid component's chain

    def must_follow(self, x: str) -> frozenset[str]:
        """Timepoints that must be executed before `x` is enabled: targets of `x`'s negative edges and,
        for a non-leading member of a rigid component, its predecessor in the chain (even at offset 0,
        where the chain edge is not negative; MMT 1998 execute such members with their leader)."""
        out = {e.target for e in self.edges if e.source == x and e.value < 0 and e.target != x}
        out.update(p for m, p in self.chained if m == x)
        return frozenset(out)


def minimal_dispatchable_network(stnu: STNU) -> DispatchableSTN:
    """Muscettola, Morris & Tsamardinos (1998), section 4: compute the APSP graph, collapse rigid
    components (pairs with ``D[a,b] + D[b,a] == 0``) into a chain in time order led by the earliest member,
    and keep only the edges between leaders that are not dominated:

    * a non-negative edge A->B is upper-dominated by a non-negative C->B if D[A,C] + D[C,B] == D[A,B];
    * a negative edge A->B is lower-dominated by a negative A->C if D[A,C] + D[C,B] == D[A,B].

    Without rigid components no two edges dominate each other, so removing every dominated edge at
    once is sound. O(n^3) with numpy. Raises `NetworkError` if the network is inconsistent.
    """
    import numpy as np

    names = stnu.timepoints
    n = len(names)
    d = all_pairs_shortest_paths(stnu)
    if d.dtype == object:  # huge weights: exact but slow path
        d = np.array(d, dtype=object)
    # rigid components: leader = lowest index; members ordered by their offset from the leader
    leader = list(range(n))
    for i in range(n):
        if leader[i] != i:
            continue
        for j in range(i + 1, n):
            if leader[j] == j and d[i, j] + d[j, i] == 0:
                leader[j] = i
    edges: list[Edge] = []
    chained: list[tuple[str, str]] = []
    members: dict[int, list[int]] = {}
    for j in range(n):
        members.setdefault(leader[j], []).append(j)
    leaders = []
    for first, group in members.items():
        # the component is represented by its earliest member, then chained in time order
        chain = sorted(group, key=lambda j: (d[first, j], j))
        leaders.append(chain[0])
        for a, b in zip(chain, chain[1:], strict=False):
            w = int(d[a, b])
            edges.append(Edge(names[a], names[b], w))
            edges.append(Edge(names[b], names[a], -w))
            chained.append((names[b], names[a]))
    leaders.sort()
    sub = d[np.ix_(leaders, leaders)]
    k = len(leaders)
    finite = np.isfinite(sub.astype(float))
    keep = finite & ~np.eye(k, dtype=bool)
    for c in range(k):
        # via[a, b] = sub[a, c] + sub[c, b]; equality marks paths through c
        via = sub[:, c][:, None] + sub[c, :][None, :]
        tight = finite & np.isfinite(via.astype(float)) & (via == sub)
        tight[c, :] = False
        tight[:, c] = False
        upper = tight & (sub >= 0) & (sub[c, :] >= 0)[None, :]
        lower = tight & (sub < 0) & (sub[:, c] < 0)[:, None]
        keep &= ~(upper | lower)
    for a, b in zip(*np.nonzero(keep), strict=True):
        edges.append(Edge(names[leaders[a]], names[leaders[b]], int(sub[a, b])))
    return DispatchableSTN(names, tuple(edges), tuple(chained))


def propagate_execution(
    windows: Mapping[str, Window], edges: Iterable[Edge], executed: str, time: int
) -> dict[str, Window]:
    """One dispatcher step: ``executed`` happened at ``time``; tighten the windows of its
    neighbours through the (dispatchable) ``edges`` incident to it (APA Fig. 8 lines 19-27;
    Muscettola et al. 1998, section 3): for ``executed --w--> Y``, ``hi(Y) <= time + w``; for
    ``Y --w--> executed``, ``lo(Y) >= time - w``. Returns a new dict; ``executed`` gets ``[time, time]``.
    """
    out = dict(windows)
    out[executed] = Window(time, time)
    for e in edges:
        if e.source == executed and e.target != executed:
            win = out.get(e.target, Window(None, None))
            hi = time + e.value if win.hi is None else min(win.hi, time + e.value)
            out[e.target] = Window(win.lo, hi)
        elif e.target == executed and e.source != executed:
            win = out.get(e.source, Window(None, None))
            lo = time - e.value if win.lo is None else max(win.lo, time - e.value)
            out[e.source] = Window(lo, win.hi)
    return out
