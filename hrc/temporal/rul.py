"""DC checking with the RUL family: one back-propagation per contingent link under a potential function.

Sources: M. Cairo, L. Hunsberger & R. Rizzi, "Faster dynamic controllability checking for simple temporal
networks with uncertainty", TIME 2018 (the RUL^- algorithm: rules Relax^-, Upper^-, Lower^-, an
O(mn + k^2 n + kn log n) check); L. Hunsberger & R. Posenato, "Speeding up the RUL^- dynamic-controllability-
checking algorithm for simple temporal networks with uncertainty", AAAI 2022 (the "RUL2021" organisation:
one back-propagation per upper-case edge, started recursively when it meets another link's activation
timepoint, plus a forward check for the lower-case edge of the link itself). Written from the papers'
description; the code is this project's own.

Vocabulary. A contingent link (A, x, y, C) has Delta = y - x. The **LO-graph** holds the ordinary edges of
the requirement links and each link's lower-case edge A --x--> C read as an ordinary edge (what happens
when nature picks every minimum duration); the link's ordinary pair (A --y--> C, C --(-x)--> A) is *not*
in it (the upper-case edge takes its role, and leaving it out keeps the searches local). A **potential**
p with ``p(v) <= p(u) + w`` for every edge u --w--> v makes the reduced weights ``w + p(u) - p(v)``
non-negative, so Dijkstra's algorithm computes exact distances in a graph with negative edges.

Algorithm, for a network that is consistent (`check_dc` checks that first):

1. Bellman-Ford on the LO-graph gives p; a negative cycle there is not DC (nature picks the minima).
2. For each link L = (A, x, y, C), back-propagate from C: Dijkstra over in-edges (LO and derived edges),
   without L's own lower-case edge (an LC edge followed by the UC edge of the same link is not a
   reduction, Morris & Muscettola 2005). A node V popped at distance d = D(V, C) < Delta is *internal*
   (V must wait for C: the wait V --C:(d - y)--> A) and is expanded; at d >= Delta it is a *moat* node and
   gets the ordinary edge V --(d - y)--> A (Upper^- with label removal, d - y >= -x), and is not
   expanded. Every lower-case edge met inside is followed by a negative path to A, so every path used
   is semi-reducible.
3. Expanding a node is only final once every edge into it is known. Derived edges only enter activation
   timepoints, so expanding the activation A' of a link L' that has not run yet suspends L: L' runs first
   (an explicit stack, not recursion; L then starts again). Meeting the activation of a link still on the
   stack closes a cycle of back-propagations whose pieces each end with an upper-case edge and are each
   shorter than -x: a semi-reducible negative cycle, not DC. Reaching L's own A inside (d < Delta) is the
   same with one piece. A moat self-loop A --(d - y)--> A with d < y is also a negative cycle.
4. The forward check for L's own lower-case edge (AAAI 2022): if some internal node X has D(C, X) < 0
   along internal nodes whose distance from C stays non-negative, then A --c:x--> C ~> X bypasses the
   lower-case edge and X ~> C --C:-y--> A closes a negative cycle.
5. The moat edges join the graph and p is repaired by one Dijkstra from A (Cairo et al.'s UpdatePotential);
   a negative cycle found there is not DC. When every link has run, the network is DC (no semi-reducible
   negative cycle remains, Morris 2006, Theorem 1).

Each link runs to completion once and each suspension corresponds to one push, so there are at most 2k
back-propagations. Time O(nm) for Bellman-Ford plus O(k (m + n log n)) for the searches; memory O(n + m
+ derived edges): a search keeps its distances in dicts over the nodes it touched and nothing of it is
kept after it ends. Explanations are rebuilt on demand: a derived edge is replaced by the path it stands
for by running its link's search again over the edges that existed when it was derived (so a rebuilt
path is never longer, and the expansion terminates).
"""

from __future__ import annotations

from collections.abc import Callable
from heapq import heappop, heappush

from hrc.temporal.graph import Edge, EdgeKind
from hrc.temporal.network import STNU
from hrc.temporal.potential import feasible_potential

__all__ = ["RulOutcome", "rul2021", "rul2021_check"]

_INF = float("inf")
_UNSTARTED, _STARTED, _DONE = 0, 1, 2
_ORD, _LC, _DERIVED = 0, 1, 2  # kinds of edges in the table
_EXPAND_LIMIT = 100_000  # explanations: stop replacing derived edges beyond this many edges
_EXPAND_SEARCHES = 2_000  # ... or beyond this many re-run searches

# One search: (outcome, distances D(V, C), first edge of V's path to C, internal nodes, moat nodes or link).
_Search = tuple[str, dict[int, int], dict[int, int], list[int], list[int]]
# A RulOutcome: (verdict code, cycle, lazily built added edges). Codes: "inconsistent", "not DC", "DC".
RulOutcome = tuple[str, tuple[Edge, ...], Callable[[], tuple[Edge, ...]] | None]


class _NotDC(Exception):
    """Raised inside a run with the explaining cycle as a list of edge ids (negative ids: UC edges)."""

    def __init__(self, cycle: list[int]) -> None:
        self.cycle = cycle


class _Rul:
    """One run. Edge ids index the parallel lists ``e_src, e_dst, e_w, e_kind, e_tag, e_epoch``; the tag
    of an ordinary original edge is its requirement index, of an LC edge its link, of a derived edge the
    link that derived it. An upper-case edge has no id of its own: ``-1 - link`` stands for it."""

    def __init__(self, stnu: STNU) -> None:
        self.names = names = stnu.timepoints
        n = len(names)
        index = {v: i for i, v in enumerate(names)}
        self.e_src: list[int] = []
        self.e_dst: list[int] = []
        self.e_w: list[int] = []
        self.e_kind: list[int] = []
        self.e_epoch: list[int] = []
        self.inn: list[list[tuple[int, int, int]]] = [[] for _ in range(n)]  # v -> [(u, w, eid)] for u -> v
        self.out: list[list[tuple[int, int, int]]] = [[] for _ in range(n)]  # u -> [(v, w, eid)]
        self.best: dict[tuple[int, int], int] = {}  # ordinary (incl. derived) edge weight per pair
        for r in stnu.requirements:
            s, t = index[r.source], index[r.target]
            if r.ub is not None:
                self._add(s, t, r.ub, _ORD, 0)
            if r.lb is not None:
                self._add(t, s, -r.lb, _ORD, 0)
        k = len(stnu.contingents)
        self.act = [0] * k
        self.ctg = [0] * k
        self.x = [0] * k
        self.y = [0] * k
        self.lc_eid = [0] * k
        self.act_links: dict[int, list[int]] = {}
        for i, c in enumerate(stnu.contingents):
            a, t = index[c.source], index[c.target]
            self.act[i], self.ctg[i], self.x[i], self.y[i] = a, t, c.lb, c.ub
            self.lc_eid[i] = self._add(a, t, c.lb, _LC, 0, force=True)
            self.act_links.setdefault(a, []).append(i)
        self.e_tag_link = {}  # derived / LC edge id -> link (ordinary originals are absent)
        for i, eid in enumerate(self.lc_eid):
            self.e_tag_link[eid] = i
        self.p = [0] * n
        self.status = [_UNSTARTED] * k
        self.epoch = 0  # completed links so far; derived edges carry epoch = 1 + links completed before
        self.reason: dict[int, tuple[int, int]] = {}  # pushed link -> (link whose search needed it, node)
        self.searches = 0

    # ----------------------------------------------------------------------------------------- graph
    def _add(self, s: int, t: int, w: int, kind: int, epoch: int, force: bool = False) -> int:
        """Add edge s --w--> t; ordinary edges dominated by an existing one are skipped (returns -1)."""
        if kind != _LC and not force:
            old = self.best.get((s, t))
            if old is not None and old <= w:
                return -1
            self.best[(s, t)] = w
        eid = len(self.e_src)
        self.e_src.append(s)
        self.e_dst.append(t)
        self.e_w.append(w)
        self.e_kind.append(kind)
        self.e_epoch.append(epoch)
        self.inn[t].append((s, w, eid))
        self.out[s].append((t, w, eid))
        return eid

    # ------------------------------------------------------------------------------ initial potential
    def bellman_ford(self) -> list[int] | None:
        """A potential of the LO-graph (`hrc.temporal.potential`, Goldberg-Radzik); a negative cycle
        (edge ids) or None."""
        return feasible_potential(len(self.names), self.out, self.p)

    # ------------------------------------------------------------------------------ back-propagation
    def backprop(self, link: int, explain: bool = False, target: int = -1, epoch_below: int = 0) -> _Search:
        """Dijkstra from C over in-edges. Returns ``(kind, dist, pred, internal, moat)``.

        ``kind``: "ok"; "need" (an unstarted link's activation was reached inside: ``moat`` holds the
        link); "started" (an activation of a link on the stack, this one included, was reached inside:
        ``moat`` holds that link). ``dist``: true distance D(V, C) of popped nodes; ``pred``:
        the id of the first edge of V's path to C. With ``explain`` the search never stops early except at
        ``target`` and, if ``epoch_below``, uses only edges of an earlier epoch.
        """
        self.searches += 1
        c, y = self.ctg[link], self.y[link]
        delta = y - self.x[link]
        lc = self.lc_eid[link]
        p, inn = self.p, self.inn
        pc = p[c]
        key: dict[int, int] = {c: 0}
        pred: dict[int, int] = {}
        dist: dict[int, int] = {}
        internal: list[int] = []
        moat: list[int] = []
        heap = [(0, c)]
        act_links, status, e_epoch = self.act_links, self.status, self.e_epoch
        while heap:
            kv, v = heappop(heap)
            if v in dist:
                continue
            d = kv - p[v] + pc
            dist[v] = d
            if v == target:
                return "ok", dist, pred, internal, moat
            if d >= delta:
                moat.append(v)
                continue
            if not explain:  # (the link itself is on the stack: reaching its own A inside is a cycle)
                for other in act_links.get(v, ()):
                    st = status[other]
                    if st == _STARTED:
                        return "started", dist, pred, internal, [other]
                    if st == _UNSTARTED:
                        return "need", dist, pred, internal, [other]
            internal.append(v)
            pv = p[v]
            for u, w, eid in inn[v]:
                if eid == lc or (epoch_below and e_epoch[eid] >= epoch_below):
                    continue
                nk = kv + w + p[u] - pv
                if nk < key.get(u, _INF):
                    key[u] = nk
                    pred[u] = eid
                    heappush(heap, (nk, u))
        return "ok", dist, pred, internal, moat

    def forward_check(self, link: int, back: dict[int, int], back_pred: dict[int, int]) -> list[int] | None:
        """AAAI 2022's forward check: from C over out-edges, through internal nodes at non-negative
        distance from C; an internal node at negative distance gives the cycle (edge ids)."""
        c = self.ctg[link]
        delta = self.y[link] - self.x[link]
        p, out = self.p, self.out
        pc = p[c]
        key: dict[int, int] = {c: 0}
        pred: dict[int, int] = {}
        done: set[int] = set()
        heap = [(0, c)]
        while heap:
            kv, v = heappop(heap)
            if v in done:
                continue
            done.add(v)
            dv = back.get(v)
            if dv is None or dv >= delta:
                continue  # not internal
            d = kv + p[v] - pc
            if d < 0:
                path = self._forward_path(pred, c, v)
                return [self.lc_eid[link], *path, *self._back_path(back_pred, v, c), -1 - link]
            pv = p[v]
            for u, w, eid in out[v]:
                nk = kv + w + pv - p[u]
                if nk < key.get(u, _INF):
                    key[u] = nk
                    pred[u] = eid
                    heappush(heap, (nk, u))
        return None

    def _forward_path(self, pred: dict[int, int], c: int, v: int) -> list[int]:
        path: list[int] = []
        e_src = self.e_src
        while v != c:
            eid = pred[v]
            path.append(eid)
            v = e_src[eid]
        path.reverse()
        return path

    def _back_path(self, back_pred: dict[int, int], v: int, c: int) -> list[int]:
        path: list[int] = []
        e_dst = self.e_dst
        while v != c:
            eid = back_pred[v]
            path.append(eid)
            v = e_dst[eid]
        return path

    # ------------------------------------------------------------------------------ potential update
    def update_potential(self, a: int) -> list[int] | None:
        """Repair p after edges into ``a`` were added (a Dijkstra from ``a`` over decreases, Cairo et al.
        2018's UpdatePotential); commits only on success. Returns a negative cycle (edge ids) or None."""
        p, out, inn = self.p, self.out, self.inn
        start = p[a]
        first = -1
        for u, w, eid in inn[a]:
            if p[u] + w < start:
                start = p[u] + w
                first = eid
        if first < 0:
            return None
        delta: dict[int, int] = {a: start - p[a]}
        pred: dict[int, int] = {}
        done: set[int] = set()
        heap = [(delta[a], a)]
        e_src = self.e_src
        while heap:
            dv, v = heappop(heap)
            if v in done:
                continue
            done.add(v)
            pv = p[v]
            for u, w, eid in out[v]:
                nd = dv + w + pv - p[u]
                if u == a:
                    if nd < delta[a]:  # a ~> v -> a is negative
                        path: list[int] = [eid]
                        while v != a:
                            e = pred[v]
                            path.append(e)
                            v = e_src[e]
                        path.reverse()
                        return path
                    continue
                if nd < delta.get(u, 0):
                    delta[u] = nd
                    pred[u] = eid
                    heappush(heap, (nd, u))
        for v, dv in delta.items():
            p[v] += dv
        return None

    # ------------------------------------------------------------------------------ main loop
    def run(self) -> None:
        """Process every link; raises `_NotDC` with a cycle of edge ids."""
        cycle = self.bellman_ford()
        if cycle is not None:
            raise _NotDC(cycle)
        status = self.status
        for first in range(len(self.act)):
            if status[first] != _UNSTARTED:
                continue
            stack = [first]
            status[first] = _STARTED
            while stack:
                link = stack[-1]
                kind, dist, pred, internal, extra = self.backprop(link)
                if kind == "need":
                    other = extra[0]
                    self.reason[other] = (link, self.act[other])
                    status[other] = _STARTED
                    stack.append(other)
                    continue
                if kind == "started":
                    raise _NotDC(self._stack_cycle(stack, extra[0], pred))
                cycle = self.forward_check(link, dist, pred)
                if cycle is not None:
                    raise _NotDC(cycle)
                self._finish(link, dist, pred, extra)
                status[link] = _DONE
                stack.pop()

    def _finish(self, link: int, dist: dict[int, int], pred: dict[int, int], moat: list[int]) -> None:
        """Add the moat edges V --(D(V, C) - y)--> A and repair the potential."""
        a, c, y = self.act[link], self.ctg[link], self.y[link]
        self.epoch += 1
        added = False
        for v in moat:
            w = dist[v] - y
            if v == a:
                if w < 0:
                    raise _NotDC([*self._back_path(pred, a, c), -1 - link])
                continue
            if self._add(v, a, w, _DERIVED, self.epoch) >= 0:
                self.e_tag_link[len(self.e_src) - 1] = link
                added = True
        if added:
            cycle = self.update_potential(a)
            if cycle is not None:
                raise _NotDC(cycle)

    def _stack_cycle(self, stack: list[int], closing: int, pred: dict[int, int]) -> list[int]:
        """The current link's search met the activation of ``closing`` (on the stack): chain the pieces
        act(next) ~> C --UC--> A of each link from ``closing`` up to the current one."""
        link = stack[-1]
        node = next(v for v in self.act_links if closing in self.act_links[v])
        cycle = [*self._back_path(pred, node, self.ctg[link]), -1 - link]
        at = stack.index(closing)
        for i in range(len(stack) - 2, at - 1, -1):
            prev, target = stack[i], self.act[stack[i + 1]]
            _, _, ppred, _, _ = self.backprop(prev, explain=True, target=target)
            cycle.extend([*self._back_path(ppred, target, self.ctg[prev]), -1 - prev])
        return cycle

    # ------------------------------------------------------------------------------ explanations
    def edge(self, eid: int) -> Edge:
        names = self.names
        if eid < 0:
            link = -1 - eid
            return Edge(names[self.ctg[link]], names[self.act[link]], -self.y[link], EdgeKind.UPPER,
                        names[self.ctg[link]])
        s, t, w = names[self.e_src[eid]], names[self.e_dst[eid]], self.e_w[eid]
        kind = self.e_kind[eid]
        if kind == _LC:
            return Edge(s, t, w, EdgeKind.LOWER, t)
        if kind == _DERIVED:
            return Edge(s, t, w, EdgeKind.DERIVED)
        return Edge(s, t, w)

    def expand(self, eids: list[int]) -> list[Edge]:
        """Replace derived edges by the paths they stand for (bounded by `_EXPAND_LIMIT` edges and
        `_EXPAND_SEARCHES` searches; beyond that derived edges stay as they are)."""
        out: list[Edge] = []
        stack = list(reversed(eids))
        budget = _EXPAND_SEARCHES
        while stack:
            eid = stack.pop()
            if eid >= 0 and self.e_kind[eid] == _DERIVED and budget > 0 and len(out) + len(stack) < _EXPAND_LIMIT:
                budget -= 1
                link = self.e_tag_link[eid]
                v = self.e_src[eid]
                _, _, pred, _, _ = self.backprop(link, explain=True, target=v, epoch_below=self.e_epoch[eid])
                piece = [*self._back_path(pred, v, self.ctg[link]), -1 - link]
                stack.extend(reversed(piece))
            else:
                out.append(self.edge(eid))
        return out

    def waits_and_derived(self) -> tuple[Edge, ...]:
        """DC only: the derived ordinary edges and, per link, the waits V --C:(D(V, C) - y)--> A of its
        internal nodes (searched again over the final graph)."""
        names = self.names
        found = [self.edge(eid) for eid in range(len(self.e_src)) if self.e_kind[eid] == _DERIVED]
        for link in range(len(self.act)):
            a, c, y = self.act[link], self.ctg[link], self.y[link]
            _, dist, _, internal, _ = self.backprop(link, explain=True)
            for v in internal:
                if v != c:
                    found.append(Edge(names[v], names[a], dist[v] - y, EdgeKind.UPPER, names[c]))
        return tuple(found)


def rul2021(stnu: STNU) -> tuple[list[Edge], list[Edge] | None]:
    """The `hrc.temporal.dc.ALGORITHMS` entry: for a *consistent* STNU, ``(cycle, None)`` when not DC
    (a semi-reducible negative cycle of the labelled graph, derived edges expanded) or ``([], added)``."""
    run = _Rul(stnu)
    try:
        run.run()
    except _NotDC as found:
        return run.expand(found.cycle), None
    return [], list(run.waits_and_derived())


def rul2021_check(stnu: STNU) -> RulOutcome:
    """Placeholder for the full check (consistency included); see `hrc.temporal.dc.check_dc`."""
    cycle, added = rul2021(stnu)
    if added is None:
        return "not DC", tuple(cycle), None
    return "DC", (), lambda: tuple(added)
