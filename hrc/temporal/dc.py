"""Dynamic controllability of STNUs: Morris (2014), with the explaining negative cycle.

Source: P. Morris, "Dynamic controllability and dispatchability relationships", CPAIOR 2014,
Algorithms 1-2 (``determineDC`` / ``DCbackprop``). An STNU is DC iff its labelled distance graph has no
*semi-reducible negative cycle* (Morris 2006, Theorem 1). For every *negative node* (target of a negative
ordinary edge or of an upper-case edge) the algorithm back-propagates from the node over non-negative
edges with Dijkstra, stopping at the "moat" where the distance becomes non-negative, and adds there a
non-negative ordinary edge to the node; a negative node met inside the moat is processed first
(recursively); meeting a negative node that is still being processed closes a semi-reducible negative
cycle, so the network is not DC. Each negative node is processed once: O(n^3) worst case, O(k (m + n log n))
with k negative nodes on sparse graphs.

Lower-case edges are "unsuitable" after an upper-case edge with the same label (that pair is not a
reduction, Morris & Muscettola 2005). Morris keeps one distance per node; to stay exact we run one
Dijkstra per *kind* of starting edge: one over the negative ordinary edges into the node, and one per
upper-case edge into it, in which the lower-case edge of that same contingent link is skipped.

The verdict comes first from consistency (contingent links read as requirements, `check_consistency`):
``INCONSISTENT`` with a negative cycle of the distance graph; otherwise ``NOT_DC`` with a negative cycle
of the labelled graph whose derived edges are expanded back to original edges, or ``DC`` with the
ordinary edges the algorithm added (``added``), which with the original links form the network Morris
shows dispatchable in his extended sense.

>>> from hrc.temporal.network import STNU, ContingentLink as CL, RequirementLink as RL
>>> check_dc(STNU(("A", "C", "X"), (RL("X", "C", 1, 2),), (CL("A", "C", 1, 10),))).verdict
<Verdict.NOT_DC: 'not DC'>
"""

from __future__ import annotations

import enum
import heapq
import sys
from dataclasses import dataclass, field

from hrc.temporal.graph import Edge, EdgeKind, labelled_edges
from hrc.temporal.network import STNU
from hrc.temporal.stn import check_consistency

__all__ = ["DCResult", "Verdict", "check_dc"]

_INF = float("inf")
_EXPAND_LIMIT = 100_000  # derived edges are expanded into original edges up to this many edges


class Verdict(enum.Enum):
    DC = "DC"
    NOT_DC = "not DC"
    INCONSISTENT = "inconsistent"


@dataclass(frozen=True)
class DCResult:
    """``verdict``; ``consistent`` (of the STN with contingent links as requirements); ``cycle``: the
    negative cycle that explains a ``NOT_DC`` / ``INCONSISTENT`` verdict, ``()`` when DC; ``added``: the
    non-negative ordinary edges Morris's algorithm derived (the dispatchable extension, for DC)."""

    verdict: Verdict
    consistent: bool
    cycle: tuple[Edge, ...] = ()
    added: tuple[Edge, ...] = field(default=(), repr=False)

    @property
    def is_dc(self) -> bool:
        return self.verdict is Verdict.DC


class _NotDC(Exception):
    def __init__(self, cycle: list[Edge]) -> None:
        self.cycle = cycle


class _Morris2014:
    """State of one run: adjacency by target, negative nodes, per-node status, derived-edge provenance."""

    UNSEEN, ACTIVE, DONE = 0, 1, 2

    def __init__(self, stnu: STNU) -> None:
        self.names = stnu.timepoints
        n = len(self.names)
        self.index = index = {v: i for i, v in enumerate(self.names)}
        # non-negative in-edges (ordinary, derived, lower-case), keyed by target: (source, w, edge)
        best: dict[tuple[int, int], Edge] = {}
        self.neg_in: list[list[tuple[int, int, Edge]]] = [[] for _ in range(n)]  # negative ordinary
        self.uc_in: list[list[tuple[int, int, Edge]]] = [[] for _ in range(n)]  # upper-case
        self.lc_in: list[list[tuple[int, int, Edge]]] = [[] for _ in range(n)]  # lower-case
        for e in labelled_edges(stnu):
            s, t = index[e.source], index[e.target]
            if e.kind is EdgeKind.UPPER:
                self.uc_in[t].append((s, e.value, e))
            elif e.kind is EdgeKind.LOWER:
                self.lc_in[t].append((s, e.value, e))
            elif s != t and ((s, t) not in best or e.value < best[(s, t)].value):
                best[(s, t)] = e
        self.pos_in: list[dict[int, tuple[int, Edge]]] = [{} for _ in range(n)]
        for (s, t), e in best.items():
            if e.value >= 0:
                self.pos_in[t][s] = (e.value, e)
            else:
                self.neg_in[t].append((s, e.value, e))
        self.negative = [bool(self.neg_in[i] or self.uc_in[i]) for i in range(n)]
        self.status = [self.UNSEEN] * n
        self.derived_from: dict[Edge, list[Edge]] = {}
        self.added: dict[tuple[int, int], Edge] = {}
        # (caller's predecessor map, node reached) for each active recursive call, to rebuild cycles
        self.frames: list[tuple[int, dict[int, Edge], int]] = []

    def run(self) -> None:
        for v in range(len(self.names)):
            if self.negative[v] and self.status[v] == self.UNSEEN:
                self.backprop(v)

    def backprop(self, src: int) -> None:
        self.status[src] = self.ACTIVE
        new_edges: dict[int, tuple[int, list[Edge]]] = {}
        starts: list[tuple[list[tuple[int, int, Edge]], str]] = []
        if self.neg_in[src]:
            starts.append((self.neg_in[src], ""))
        for s, w, e in self.uc_in[src]:
            starts.append(([(s, w, e)], e.label))
        for initial, banned_label in starts:
            self._dijkstra(src, initial, banned_label, new_edges)
        for u, (w, path) in new_edges.items():
            e = Edge(self.names[u], self.names[src], w, EdgeKind.DERIVED)
            self.derived_from[e] = path
            old = self.pos_in[src].get(u)
            if old is None or w < old[0]:
                self.pos_in[src][u] = (w, e)
                self.added[(u, src)] = e
        self.status[src] = self.DONE

    def _dijkstra(
        self,
        src: int,
        initial: list[tuple[int, int, Edge]],
        banned_label: str,
        new_edges: dict[int, tuple[int, list[Edge]]],
    ) -> None:
        dist: dict[int, int] = {}
        pred: dict[int, Edge] = {}  # node -> first edge of its shortest path towards src
        heap: list[tuple[int, int]] = []
        for s, w, e in initial:
            if w < dist.get(s, _INF):
                dist[s] = w
                pred[s] = e
                heapq.heappush(heap, (w, s))
        done: set[int] = set()
        while heap:
            d, u = heapq.heappop(heap)
            if u in done or d > dist[u]:
                continue
            done.add(u)
            if d >= 0:  # the moat: bypass the negative path with a non-negative ordinary edge
                if u != src:
                    old = new_edges.get(u)
                    if old is None or d < old[0]:
                        new_edges[u] = (d, self._path(pred, u, src))
                continue
            if self.negative[u]:
                if self.status[u] == self.ACTIVE:
                    raise _NotDC(self._cycle(pred, u, src))
                if self.status[u] == self.UNSEEN:
                    self.frames.append((src, pred, u))
                    self.backprop(u)
                    self.frames.pop()
            for s, (w, e) in self.pos_in[u].items():
                nd = d + w
                if nd < dist.get(s, _INF):
                    dist[s] = nd
                    pred[s] = e
                    heapq.heappush(heap, (nd, s))
            for s, w, e in self.lc_in[u]:
                if e.label == banned_label:
                    continue
                nd = d + w
                if nd < dist.get(s, _INF):
                    dist[s] = nd
                    pred[s] = e
                    heapq.heappush(heap, (nd, s))

    def _path(self, pred: dict[int, Edge], u: int, src: int) -> list[Edge]:
        index = self.index
        path, v = [], u
        while v != src or not path:
            e = pred[v]
            path.append(e)
            v = index[e.target]
        return path

    def _cycle(self, pred: dict[int, Edge], u: int, src: int) -> list[Edge]:
        """``u`` is active: its call is on the stack below ``src``'s. Chain the negative paths
        u ~> src ~> caller(src) ~> ... ~> u recorded in the call frames."""
        cycle = self._path(pred, u, src)
        for caller, caller_pred, reached in reversed(self.frames):
            if reached == u:
                break
            cycle.extend(self._path(caller_pred, reached, caller))
            if caller == u:
                break
        return cycle

    def expand(self, edges: list[Edge]) -> list[Edge]:
        out: list[Edge] = []
        stack = list(reversed(edges))
        while stack:
            e = stack.pop()
            if e.kind is EdgeKind.DERIVED and len(out) + len(stack) < _EXPAND_LIMIT:
                stack.extend(reversed(self.derived_from[e]))
            else:
                out.append(e)
        return out


def check_dc(stnu: STNU) -> DCResult:
    """Decide whether ``stnu`` is dynamically controllable (Morris 2014; see the module docstring).

    Returns a `DCResult`; never raises for a well-formed network. O(n^3) worst case.
    """
    cons = check_consistency(stnu)
    if not cons.consistent:
        return DCResult(Verdict.INCONSISTENT, False, cons.cycle)
    if not stnu.contingents:
        return DCResult(Verdict.DC, True)
    algo = _Morris2014(stnu)
    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 4 * len(stnu.timepoints) + 1000))
    try:
        algo.run()
    except _NotDC as found:
        return DCResult(Verdict.NOT_DC, True, tuple(algo.expand(found.cycle)))
    finally:
        sys.setrecursionlimit(limit)
    return DCResult(Verdict.DC, True, (), tuple(algo.added[k] for k in sorted(algo.added)))
