"""DC checking by lower-case bypass closure over the OU-graph, with Dijkstra under a potential function.

Theory: an STNU is DC iff its labelled distance graph has no semi-reducible negative cycle (Morris 2006,
Theorem 1); a path is semi-reducible when reductions can remove all its lower-case edges. A lower-case
edge ``A --c:x--> C`` is removed by following it with a path Q from C whose proper prefixes are all
non-negative and whose total is negative (Morris 2014, section 3: the "extension"); reducing Q front to
back gives one negative edge, ordinary if Q ends with an ordinary edge, upper-case ``L`` if Q ends with an
upper-case edge labelled L. The lower-case rule (ordinary) or the cross-case rule (L != C) then yields the
*bypass* ``A --(x + |Q|)--> W``, labelled L in the second case unless label removal applies (weight >= -x_L,
Morris & Muscettola 2005); L == C is not a reduction. Bypasses can extend other lower-case edges' Q paths,
so the closure is computed in rounds, as in the RUL family (Cairo, Hunsberger & Rizzi 2018) though
without their ordering refinements. With the OU-graph (ordinary + upper-case edges, no lower-case edge)
closed under bypasses, the network is DC iff that graph, upper-case edges read as ordinary, has no
negative cycle: such a cycle has no lower-case edge, hence is semi-reducible.

Each round: Bellman-Ford (queue-based, warm-started) gives a potential p with ``p(v) <= p(u) + w``, so the
reduced weights ``w + p(u) - p(v)`` are non-negative; from each contingent timepoint C one Dijkstra finds
the moat paths Q (nodes are expanded only while the true distance from C is non-negative). A round costs
O(k (m + n log n) + n m). Searches run one lower-case edge at a time and their results join the graph at
once; a search is repeated only if an edge was added out of a node it expanded. Each search is exact for
the current graph, so the number of passes follows the nesting depth of lower-case edges rather than the
size of the numbers (we have not proved a bound; on the 501-node DC instance there are 125 searches for
22 contingent links).
"""

from __future__ import annotations

import heapq
from collections import deque

from hrc.temporal.graph import Edge, EdgeKind, labelled_edges
from hrc.temporal.network import STNU

__all__ = ["bypass_closure"]

_BIG = float("inf")
_EXPAND_LIMIT = 100_000


class _Closure:
    def __init__(self, stnu: STNU) -> None:
        self.names = stnu.timepoints
        n = len(self.names)
        self.index = index = {v: i for i, v in enumerate(self.names)}
        # edge table: original Edge, or a derived bypass (A, W, w, label, lc_eid, (pred, C, u, last eid))
        self.table: list[Edge | tuple] = []
        self.out: list[list[tuple[int, int, int, int]]] = [[] for _ in range(n)]  # (v, w, eid, UC label or -1)
        self.lower: list[tuple[int, int, int, int]] = []  # lower-case edges: (A, C, x, eid)
        self.min_lb = [0] * n  # lower bound x_L of the contingent link whose contingent timepoint is L
        self.best: dict[tuple[int, int, int], int] = {}  # (u, v, label) -> best weight present
        for e in labelled_edges(stnu):
            s, t = index[e.source], index[e.target]
            eid = len(self.table)
            self.table.append(e)
            if e.kind is EdgeKind.LOWER:
                self.lower.append((s, t, e.value, eid))
                self.min_lb[t] = e.value
            else:
                label = index[e.label] if e.kind is EdgeKind.UPPER else -1
                self._add(s, t, e.value, label, eid)
        self.potential = [0] * n
        self.added: list[int] = []

    def _add(self, s: int, t: int, w: int, label: int, eid: int) -> bool:
        key = (s, t, label)
        if w >= self.best.get(key, _BIG) or w >= self.best.get((s, t, -1), _BIG):
            return False  # an edge at least as strong is present (an ordinary one dominates a labelled one)
        self.best[key] = w
        self.out[s].append((t, w, eid, label))
        return True

    def relax_potential(self, dirty: list[int]) -> list[int] | None:
        """Queue-based Bellman-Ford from the current potential; returns a negative cycle (edge ids)
        if there is one, else None. ``dirty``: nodes whose out-edges changed."""
        n = len(self.names)
        dist = self.potential
        pred = [-1] * n
        length = [0] * n
        queue = deque(dict.fromkeys(dirty))
        queued = [False] * n
        for u in queue:
            queued[u] = True
        while queue:
            u = queue.popleft()
            queued[u] = False
            du = dist[u]
            for v, w, eid, _label in self.out[u]:
                if du + w < dist[v]:
                    dist[v] = du + w
                    pred[v] = eid
                    length[v] = length[u] + 1
                    if length[v] >= n:
                        cycle = self._parent_cycle(v, pred)
                        if cycle is not None:
                            return cycle
                        length[v] = 0
                    if not queued[v]:
                        queued[v] = True
                        queue.append(v)
        return None

    def _parent_cycle(self, v: int, pred: list[int]) -> list[int] | None:
        seen: dict[int, int] = {}
        chain: list[int] = []
        while v not in seen:
            seen[v] = len(chain)
            eid = pred[v]
            if eid < 0:
                return None
            chain.append(eid)
            v = self._ends(eid)[0]
        cycle = chain[seen[v]:]
        cycle.reverse()
        return cycle

    def _ends(self, eid: int) -> tuple[int, int]:
        e = self.table[eid]
        if isinstance(e, Edge):
            return self.index[e.source], self.index[e.target]
        return e[0], e[1]

    def bypasses_from(self, c: int, x: int) -> tuple[list[tuple[int, int, int, dict[int, int], int, int]], set[int]]:
        """Dijkstra from C on reduced weights, expanding only nodes at a non-negative true distance.

        Returns the bypasses of a lower-case edge ``A --c:x--> C`` as ``(W, weight, label, pred, u, eid)``:
        Q is the predecessor path from C to ``u`` followed by edge ``eid`` (rebuilt only when a cycle is
        explained), and the set of expanded nodes (new edges out of others cannot change the result).
        """
        p = self.potential
        pc = p[c]
        dist: dict[int, int] = {c: 0}  # reduced distance from C, over the nodes this search touches
        pred: dict[int, int] = {}
        heap = [(0, c)]
        push, pop = heapq.heappush, heapq.heappop
        uc_best: dict[tuple[int, int], tuple[int, int, int]] = {}  # (W, L) -> (true dist, last eid, from u)
        found: list[int] = []
        expanded: set[int] = set()
        out = self.out
        while heap:
            d, u = pop(heap)
            if d > dist[u]:
                continue
            true_u = d - pc + p[u]
            if true_u < 0:
                found.append(u)  # Q ends here (ordinary last edge): not expanded
                continue
            expanded.add(u)
            for v, w, eid, label in out[u]:
                if label >= 0:
                    t = true_u + w
                    if t < 0:  # a negative upper-case ending: cross-case candidate, never expanded
                        if label != c:
                            key = (v, label)
                            if key not in uc_best or t < uc_best[key][0]:
                                uc_best[key] = (t, eid, u)
                        continue
                nd = d + w + p[u] - p[v]
                if nd < dist.get(v, _BIG):
                    dist[v] = nd
                    pred[v] = eid
                    push(heap, (nd, v))
        result = []
        for v in found:
            result.append((v, x + dist[v] - pc + p[v], -1, pred, self._ends(pred[v])[0], pred[v]))
        for (v, label), (t, eid, u) in uc_best.items():
            weight = x + t
            final = -1 if weight >= -self.min_lb[label] else label  # label removal
            result.append((v, weight, final, pred, u, eid))
        return result, expanded

    def _path(self, pred: dict[int, int], c: int, v: int) -> list[int]:
        path: list[int] = []
        while v != c:
            eid = pred[v]
            path.append(eid)
            v = self._ends(eid)[0]
        path.reverse()
        return path

    def run(self) -> list[int] | None:
        """Close under bypasses; a negative cycle (edge ids) means not DC.

        Searches run one lower-case edge at a time and their bypasses join the graph at once (the
        potential is repaired before the next search), so later searches see earlier results; a search
        is repeated only when an edge was added out of a node it expanded since it last ran.
        """
        cycle = self.relax_potential(list(range(len(self.names))))
        if cycle is not None:
            return cycle
        k = len(self.lower)
        regions: list[set[int]] = [set() for _ in range(k)]
        searched = [-1] * k  # clock of each search
        touched = [0] * len(self.names)  # clock of the last edge added out of each node
        clock = 0
        again = True
        while again:
            again = False
            for i, (a, c, x, lc_eid) in enumerate(self.lower):
                if searched[i] >= 0 and all(touched[v] <= searched[i] for v in regions[i]):
                    continue
                clock += 1
                searched[i] = clock
                bypasses, regions[i] = self.bypasses_from(c, x)
                changed = False
                for v, w, label, pred, u, last in bypasses:
                    if v == a and w >= 0:
                        continue
                    key = (a, v, label)
                    if w >= self.best.get(key, _BIG) or w >= self.best.get((a, v, -1), _BIG):
                        continue
                    eid = len(self.table)
                    self.table.append((a, v, w, label, lc_eid, (pred, c, u, last)))
                    self._add(a, v, w, label, eid)
                    self.added.append(eid)
                    changed = True
                if changed:
                    clock += 1
                    touched[a] = clock
                    again = True
                    cycle = self.relax_potential([a])
                    if cycle is not None:
                        return cycle
        return None

    def edge(self, eid: int) -> Edge:
        e = self.table[eid]
        if isinstance(e, Edge):
            return e
        a, v, w, label, _lc, _path = e
        if label >= 0:
            return Edge(self.names[a], self.names[v], w, EdgeKind.UPPER, self.names[label])
        return Edge(self.names[a], self.names[v], w, EdgeKind.DERIVED)

    def expand(self, eids: list[int]) -> list[Edge]:
        """Replace bypasses by their lower-case edge and Q path (up to `_EXPAND_LIMIT` edges)."""
        out: list[Edge] = []
        stack = list(reversed(eids))
        while stack:
            eid = stack.pop()
            e = self.table[eid]
            if not isinstance(e, Edge) and len(out) + len(stack) < _EXPAND_LIMIT:
                pred, c, u, last = e[5]
                stack.extend(reversed([e[4], *self._path(pred, c, u), last]))
            else:
                out.append(self.edge(eid))
        return out


def bypass_closure(stnu: STNU) -> tuple[list[Edge], list[Edge] | None]:
    """Run the closure on a consistent STNU: ``(cycle, None)`` with a semi-reducible negative cycle
    (bypasses expanded) when not DC, else ``([], added)`` with the derived bypass edges."""
    algo = _Closure(stnu)
    cycle = algo.run()
    if cycle is not None:
        return algo.expand(cycle), None
    return [], [algo.edge(eid) for eid in algo.added]
