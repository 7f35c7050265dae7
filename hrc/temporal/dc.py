"""Dynamic controllability of STNUs: `check_dc`, its algorithms, and the explaining negative cycle.

Three algorithms are registered in `ALGORITHMS` (the tests run each against an exhaustive game oracle,
each other and the outside instances): ``"rul2021"`` (default; `hrc.temporal.rul`, the RUL family of
Cairo, Hunsberger & Rizzi 2018: one back-propagation per contingent link under a potential, its verdict
also in C; the fastest in every size class of scripts/bench_dc.py), ``"bypass"`` (`hrc.temporal.bypass`,
lower-case bypass closure with Dijkstra under a potential, a few searches per contingent link) and
``"morris2014"`` (this module, described below), slower on large networks because it runs one search per
negative node.

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

The verdict comes first from consistency (contingent links read as requirements, `check_consistency`;
``rul2021`` decides it with its own potential): ``INCONSISTENT`` with a negative cycle of the distance
graph; otherwise ``NOT_DC`` with a negative cycle of the labelled graph whose derived edges are expanded
back to original edges, or ``DC`` with the edges the algorithm added (``added``).

>>> from hrc.temporal.network import STNU, ContingentLink as CL, RequirementLink as RL
>>> check_dc(STNU(("A", "C", "X"), (RL("X", "C", 1, 2),), (CL("A", "C", 1, 10),))).verdict
<Verdict.NOT_DC: 'not DC'>
"""

from __future__ import annotations

import enum
import heapq
import sys
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from functools import cached_property

from hrc.temporal.bypass import bypass_closure
from hrc.temporal.graph import Edge, EdgeKind, labelled_edges
from hrc.temporal.network import STNU
from hrc.temporal.rul import RulOutcome, rul2021, rul2021_check
from hrc.temporal.stn import check_consistency

__all__ = ["ALGORITHMS", "DEFAULT_ALGORITHM", "DCResult", "Verdict", "check_dc"]

_BIG = float("inf")
_EXPAND_LIMIT = 100_000  # derived edges are expanded into original edges up to this many edges


class Verdict(enum.Enum):
    DC = "DC"
    NOT_DC = "not DC"
    INCONSISTENT = "inconsistent"


@dataclass(frozen=True)
class DCResult:
    """``verdict``; ``consistent`` (of the STN with contingent links as requirements); ``cycle``: the
    negative cycle that explains a ``NOT_DC`` / ``INCONSISTENT`` verdict, in path order, ``()`` when DC
    (built on first access when the algorithm decided without it, as ``rul2021``'s C core does).

    ``added`` (DC only): the edges the algorithm derived, which the original links imply for every dynamic
    execution: waits a dispatcher must respect. ``morris2014`` gives non-negative ordinary edges (its
    dispatchable extension, Morris 2014, section 5); ``bypass`` and ``rul2021`` give ordinary edges
    (``DERIVED``) and conditional waits (``UPPER``, labelled with the contingent timepoint whose occurrence
    releases them). Built on first access, as there can be O(n^2) of them.
    """

    verdict: Verdict
    consistent: bool
    _cycle: tuple[Edge, ...] | Callable[[], tuple[Edge, ...]] = field(default=(), repr=False, compare=False)
    _added: Callable[[], tuple[Edge, ...]] | None = field(default=None, repr=False, compare=False)

    @property
    def is_dc(self) -> bool:
        return self.verdict is Verdict.DC

    @cached_property
    def cycle(self) -> tuple[Edge, ...]:
        return self._cycle() if callable(self._cycle) else self._cycle

    @cached_property
    def added(self) -> tuple[Edge, ...]:
        return self._added() if self._added is not None else ()


class _NotDC(Exception):
    def __init__(self, cycle: list[int]) -> None:
        self.cycle = cycle


class _Morris2014:
    """State of one run: in-edges by target, negative nodes, per-node status, derived-edge provenance.

    Edges are ids into ``self.table``: an original `Edge`, or for a derived edge the tuple
    ``(u, src, w, pred, start)`` from which its path u ~> src is rebuilt lazily (``pred`` is the
    predecessor list of the Dijkstra run that derived it; entries of settled nodes never change).
    """

    UNSEEN, ACTIVE, DONE = 0, 1, 2

    def __init__(self, stnu: STNU) -> None:
        self.names = stnu.timepoints
        n = len(self.names)
        self.index = index = {v: i for i, v in enumerate(self.names)}
        self.table: list[Edge | tuple[int, int, int, dict[int, int], int]] = []
        best: dict[tuple[int, int], int] = {}
        self.neg_in: list[list[tuple[int, int, int]]] = [[] for _ in range(n)]  # negative ordinary
        self.uc_in: list[list[tuple[int, int, int, int]]] = [[] for _ in range(n)]  # upper-case (+label)
        # non-negative in-edges: (source, weight, edge id, lower-case label index or -1)
        self.pos_in: list[list[tuple[int, int, int]]] = [[] for _ in range(n)]  # ordinary and derived
        self.lc_in: list[list[tuple[int, int, int, int]]] = [[] for _ in range(n)]  # lower-case (+label)
        for e in labelled_edges(stnu):
            s, t = index[e.source], index[e.target]
            eid = len(self.table)
            self.table.append(e)
            if e.kind is EdgeKind.UPPER:
                self.uc_in[t].append((s, e.value, eid, index[e.label]))
            elif e.kind is EdgeKind.LOWER:
                self.lc_in[t].append((s, e.value, eid, index[e.label]))
            elif s != t and ((s, t) not in best or e.value < self.table[best[(s, t)]].value):  # type: ignore[union-attr]
                best[(s, t)] = eid
        self.best_in: list[dict[int, int]] = [{} for _ in range(n)]  # shortest ordinary u->t, w >= 0
        for (s, t), eid in best.items():
            w = self.table[eid].value  # type: ignore[union-attr]
            if w >= 0:
                self.best_in[t][s] = w
                self.pos_in[t].append((s, w, eid))
            else:
                self.neg_in[t].append((s, w, eid))
        self.negative = [bool(self.neg_in[i] or self.uc_in[i]) for i in range(n)]
        self.status = [self.UNSEEN] * n
        self.added: list[int] = []
        # (caller, caller's predecessor list, node reached) for each active recursive call
        self.frames: list[tuple[int, dict[int, int], int]] = []

    def run(self) -> None:
        for v in range(len(self.names)):
            if self.negative[v] and self.status[v] == self.UNSEEN:
                self.backprop(v)

    def backprop(self, src: int) -> None:
        self.status[src] = self.ACTIVE
        new_edges: dict[int, tuple[int, dict[int, int]]] = {}
        if self.neg_in[src]:
            self._dijkstra(src, [(s, w, eid) for s, w, eid in self.neg_in[src]], -2, new_edges)
        for s, w, eid, label in self.uc_in[src]:
            self._dijkstra(src, [(s, w, eid)], label, new_edges)
        for u, (w, pred) in new_edges.items():
            eid = len(self.table)
            self.table.append((u, src, w, pred, u))
            self.pos_in[src].append((u, w, eid))
            self.best_in[src][u] = w
            self.added.append(eid)
        self.status[src] = self.DONE

    def _dijkstra(
        self, src: int, initial: list[tuple[int, int, int]], banned: int,
        new_edges: dict[int, tuple[int, dict[int, int]]]
    ) -> None:
        dist: dict[int, int] = {}  # only the nodes this search touches: memory follows the search
        pred: dict[int, int] = {}  # node -> id of the first edge of its shortest path towards src
        heap: list[tuple[int, int]] = []
        push, pop = heapq.heappush, heapq.heappop
        negative, status, pos_in, lc_in = self.negative, self.status, self.pos_in, self.lc_in
        for s, w, eid in initial:
            if w < dist.get(s, _BIG):
                dist[s] = w
                pred[s] = eid
                push(heap, (w, s))
        moat: list[int] = []  # nodes reached with a non-negative distance: never expanded, never queued
        while heap:
            d, u = pop(heap)
            if d > dist[u]:
                continue
            if negative[u]:
                if status[u] == self.ACTIVE:
                    raise _NotDC(self._cycle(pred, u, src))
                if status[u] == self.UNSEEN:
                    self.frames.append((src, pred, u))
                    self.backprop(u)
                    self.frames.pop()
            for s, w, eid in pos_in[u]:
                nd = d + w
                old = dist.get(s, _BIG)
                if nd < old:
                    if nd < 0:
                        push(heap, (nd, s))
                    elif old == _BIG:
                        moat.append(s)
                    dist[s] = nd
                    pred[s] = eid
            for s, w, eid, label in lc_in[u]:
                nd = d + w
                old = dist.get(s, _BIG)
                if nd < old and label != banned:
                    if nd < 0:
                        push(heap, (nd, s))
                    elif old == _BIG:
                        moat.append(s)
                    dist[s] = nd
                    pred[s] = eid
        # the moat: bypass each negative path ending there with a non-negative ordinary edge, unless
        # an ordinary edge at least as short is already there
        best = self.best_in[src]
        for u in moat:
            du = dist[u]
            if du >= 0 and u != src and du < best.get(u, _BIG):
                known = new_edges.get(u)
                if known is None or du < known[0]:
                    new_edges[u] = (du, pred)

    def _endpoints(self, eid: int) -> tuple[int, int]:
        e = self.table[eid]
        if isinstance(e, Edge):
            return self.index[e.source], self.index[e.target]
        return e[0], e[1]

    def _path(self, pred: dict[int, int], u: int, src: int) -> list[int]:
        path: list[int] = []
        v = u
        while v != src or not path:
            eid = pred[v]
            path.append(eid)
            v = self._endpoints(eid)[1]
        return path

    def _cycle(self, pred: dict[int, int], u: int, src: int) -> list[int]:
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

    def edge(self, eid: int) -> Edge:
        e = self.table[eid]
        if isinstance(e, Edge):
            return e
        u, src, w, _pred, _start = e
        return Edge(self.names[u], self.names[src], w, EdgeKind.DERIVED)

    def expand(self, eids: list[int]) -> list[Edge]:
        """Replace derived edges by the paths they stand for (up to `_EXPAND_LIMIT` edges)."""
        out: list[Edge] = []
        stack = list(reversed(eids))
        while stack:
            eid = stack.pop()
            e = self.table[eid]
            if not isinstance(e, Edge) and len(out) + len(stack) < _EXPAND_LIMIT:
                u, src, _w, pred, start = e
                stack.extend(reversed(self._path(pred, start, src)))
            else:
                out.append(self.edge(eid))
        return out


def _morris2014(stnu: STNU) -> tuple[list[Edge], list[Edge] | None]:
    algo = _Morris2014(stnu)
    limit = sys.getrecursionlimit()
    sys.setrecursionlimit(max(limit, 4 * len(stnu.timepoints) + 1000))
    try:
        algo.run()
    except _NotDC as found:
        return algo.expand(found.cycle), None
    finally:
        sys.setrecursionlimit(limit)
    return [], [algo.edge(eid) for eid in algo.added]


ALGORITHMS: dict[str, Callable[[STNU], tuple[list[Edge], list[Edge] | None]]] = {
    "bypass": bypass_closure,  # hrc.temporal.bypass: lower-case bypass closure, a few Dijkstras per round
    "morris2014": _morris2014,  # this module: Morris 2014 DCbackprop from every negative node
    "rul2021": rul2021,  # hrc.temporal.rul: RUL family, one back-propagation per contingent link
}
"""The DC algorithms, by name: each maps a *consistent* STNU to ``(cycle, None)`` (not DC, with a
semi-reducible negative cycle) or ``([], added)`` (DC, with the edges it derived)."""

DEFAULT_ALGORITHM = "rul2021"

_FULL_CHECKS: dict[str, Callable[[STNU], RulOutcome]] = {"rul2021": rul2021_check}
"""Algorithms that decide consistency themselves, on the way (`check_dc` then skips its own check)."""


def check_dc(stnu: STNU, algorithm: str = DEFAULT_ALGORITHM) -> DCResult:
    """Decide whether ``stnu`` is dynamically controllable.

    First the STN (contingent links as requirements) must be consistent, else ``INCONSISTENT``; then the
    named algorithm of `ALGORITHMS` decides DC / not DC (``rul2021`` settles both questions with one
    potential, `hrc.temporal.rul.rul2021_check`). Returns a `DCResult`; raises `KeyError` for an unknown
    algorithm name only. O(n^3) worst case.
    """
    run = ALGORITHMS[algorithm]
    full = _FULL_CHECKS.get(algorithm)
    if full is not None:
        verdict, cycle, built = full(stnu)
        if verdict == "inconsistent":
            return DCResult(Verdict.INCONSISTENT, False, cycle)
        if verdict == "not DC":
            return DCResult(Verdict.NOT_DC, True, cycle)
        return DCResult(Verdict.DC, True, (), None if built is None else lambda: _dedup(built()))
    cons = check_consistency(stnu)
    if not cons.consistent:
        return DCResult(Verdict.INCONSISTENT, False, cons.cycle)
    if not stnu.contingents:
        return DCResult(Verdict.DC, True)
    found, added = run(stnu)
    if added is None:
        return DCResult(Verdict.NOT_DC, True, tuple(found))
    return DCResult(Verdict.DC, True, (), lambda: _dedup(added))


def _dedup(edges: Iterable[Edge]) -> tuple[Edge, ...]:
    """The shortest edge per (source, target, label), in a fixed order."""
    best: dict[tuple[str, str, str], Edge] = {}
    for e in edges:
        key = (e.source, e.target, e.label)
        if key not in best or e.value < best[key].value:
            best[key] = e
    return tuple(best[k] for k in sorted(best))
