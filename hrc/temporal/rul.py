"""DC checking with the RUL family: one back-propagation per contingent link under a potential function.

Sources: M. Cairo, L. Hunsberger & R. Rizzi, "Faster dynamic controllability checking for simple temporal
networks with uncertainty", TIME 2018 (the RUL^- algorithm: rules Relax^-, Upper^-, Lower^- over the
LO-graph, O(mn + k^2 n + kn log n)); L. Hunsberger & R. Posenato, "Speeding up the RUL^- dynamic-
controllability-checking algorithm for simple temporal networks with uncertainty", AAAI 2022 (the
"RUL2021" organisation: one back-propagation per upper-case edge, run first for any link whose activation
a back-propagation meets, plus a forward check for the lower-case edge of the link itself). Written from
the papers' description; the code is this project's own.

Vocabulary. A contingent link (A, x, y, C) has Delta = y - x. The **LO-graph** holds the ordinary edges of
the requirement links and each link's lower-case edge A --x--> C read as an ordinary edge (the world in
which nature picks every minimum duration). A **potential** p with ``p(v) <= p(u) + w`` for every edge
u --w--> v makes the reduced weights ``w + p(u) - p(v)`` non-negative, so Dijkstra's algorithm computes
exact distances in a graph with negative edges (Johnson's reweighting).

Algorithm:

1. One potential for the LO-graph plus each link's ordinary pair (A --y--> C, C --(-x)--> A), by
   Goldberg-Radzik (`hrc.temporal.potential`). Its existence proves the STN consistent and the LO-graph
   free of negative cycles; a negative cycle without lower-case edge is an inconsistency, one with a
   lower-case edge (and a consistent STN) is not DC, as nature may pick the minima.
2. For each link L, back-propagate from C: Dijkstra over the *in*-edges of the LO-graph and the derived
   edges, skipping L's own lower-case edge (an LC edge followed by the UC edge of its own link is not a
   reduction, Morris & Muscettola 2005). The ordinary pair is not searched: the upper-case edge takes its
   role, and leaving it out keeps a search within the part of the network that precedes C. A node V
   popped at distance d = D(V, C) < Delta is *internal* (the wait V --C:(d - y)--> A) and is expanded;
   at d >= Delta it is a *moat* node, which gets the ordinary edge V --(d - y)--> A (Upper^- with label
   removal, d - y >= -x) and is not expanded. Every LC edge met inside is followed by a negative path to
   A, so every path used is semi-reducible.
3. Expanding a node is only final once every edge into it is known. Derived edges only enter activation
   timepoints, so expanding the activation of a link that has not run yet suspends L: that link runs
   first (an explicit stack, not recursion; L then searches again). Meeting the activation of a link on
   the stack (L's own included) closes a cycle of pieces act ~> C --UC--> A, each shorter than -x: a
   semi-reducible negative cycle, not DC. So is a moat self-loop A --(d - y)--> A with d < y.
4. The forward check for L's own lower-case edge (AAAI 2022): if an internal node X has D(C, X) < 0 along
   internal nodes at non-negative distance from C, then A --c:x--> C ~> X bypasses the lower-case edge and
   X ~> C --C:-y--> A closes a negative cycle.
5. The moat edges join the graph and p is repaired by one Dijkstra from A (Cairo et al.'s
   UpdatePotential); a negative cycle found there is not DC. When every link has run the network is DC:
   no semi-reducible negative cycle is left (Morris 2006, Theorem 1).

Links run in order of decreasing potential of their activation (later activations first, which a
back-propagation meets before earlier ones), so suspensions are rare on plan-like networks. Each link runs
to completion once and each suspension is one push: at most 2k back-propagations. Time O(nm) for the
potential (one or two linear passes in practice) plus O(k (m + n log n)); memory O(n + m + derived
edges): a search keeps its labels in dicts over the nodes it touched, and nothing of it is kept after it
ends. Explanations are rebuilt on demand: a derived edge is replaced by the path it stands for by running
its link's search again over the edges that existed when it was derived (so the rebuilt path is never
longer, and the expansion terminates).
"""

from __future__ import annotations

import ctypes
import importlib.machinery
import os
from array import array
from collections.abc import Callable, Sequence
from heapq import heappop, heappush
from pathlib import Path
from typing import Any

from hrc.caches import make_room
from hrc.temporal.graph import Edge, EdgeKind
from hrc.temporal.network import STNU, RequirementLink, bound_count, lineage
from hrc.temporal.potential import feasible_potential

__all__ = ["RulOutcome", "bound_edges", "core_verdict", "edge_arrays", "native_library", "rul2021", "rul2021_check",
           "spliced"]

_INF = float("inf")
_UNSTARTED, _STARTED, _DONE = 0, 1, 2
_ORD, _LC, _DERIVED, _PAIR = 0, 1, 2, 3  # kinds of edges in the table
_EXPAND_LIMIT = 100_000  # explanations: stop replacing derived edges beyond this many edges
_EXPAND_SEARCHES = 2_000  # ... or beyond this many re-run searches

# One search: (outcome, distances D(V, C), first edge of V's path to C, internal nodes, moat nodes or link).
_Search = tuple[str, dict[int, int], dict[int, int], list[int], list[int]]
RulOutcome = tuple[str, tuple[Edge, ...] | Callable[[], tuple[Edge, ...]], Callable[[], tuple[Edge, ...]] | None]
"""``(verdict, cycle, added)``: verdict ``"DC"``, ``"not DC"`` or ``"inconsistent"``; the explaining cycle,
or a function building it; for DC a function building the derived edges (``None`` otherwise)."""


class _NotDC(Exception):
    """Raised inside a run with the explaining cycle as edge ids (``-1 - link`` for a link's UC edge)."""

    def __init__(self, cycle: list[int]) -> None:
        self.cycle = cycle


class _Rul:
    """One run over integer nodes. Edge ids index the parallel lists ``e_src, e_dst, e_w, e_kind,
    e_epoch``; ``e_link`` gives the link of an LC, pair or derived edge. ``inn`` holds the searched graph
    (LO and derived edges), ``out`` the same plus the ordinary pairs (the potential covers both). An
    upper-case edge has no id: ``-1 - link`` stands for it in cycles."""

    def __init__(self, stnu: STNU) -> None:
        self.names = names = stnu.timepoints
        n = len(names)
        index = {v: i for i, v in enumerate(names)}
        src: list[int] = []
        dst: list[int] = []
        wt: list[int] = []
        for r in stnu.requirements:
            s, t = index[r.source], index[r.target]
            if r.ub is not None:
                src.append(s)
                dst.append(t)
                wt.append(r.ub)
            if r.lb is not None:
                src.append(t)
                dst.append(s)
                wt.append(-r.lb)
        n_req = len(src)
        contingents = stnu.contingents
        k = len(contingents)
        self.act = act = [index[c.source] for c in contingents]
        self.ctg = ctg = [index[c.target] for c in contingents]
        self.x = [c.lb for c in contingents]
        self.y = [c.ub for c in contingents]
        # ids: requirements, then per link its LC edge, then the pairs A --y--> C and C --(-x)--> A
        src += act + act + ctg
        dst += ctg + ctg + act
        wt += self.x + self.y + [-c.lb for c in contingents]
        self.lc_eid = list(range(n_req, n_req + k))
        self.e_src, self.e_dst, self.e_w = src, dst, wt
        self.e_kind = [_ORD] * n_req + [_LC] * k + [_PAIR] * (2 * k)
        self.e_epoch = [0] * len(src)
        self.e_link: dict[int, int] = {n_req + i: i % k for i in range(3 * k)} if k else {}
        self.inn: list[list[tuple[int, int, int]]] = [[] for _ in range(n)]  # v -> [(u, w, eid)], u -> v
        self.out: list[list[tuple[int, int, int]]] = [[] for _ in range(n)]  # u -> [(v, w, eid)]
        inn, out = self.inn, self.out
        searched = n_req + k
        for eid, (s, t, w) in enumerate(zip(src, dst, wt, strict=True)):
            out[s].append((t, w, eid))
            if eid < searched:
                inn[t].append((s, w, eid))
        self.act_links: dict[int, list[int]] = {}
        for i, a in enumerate(act):
            self.act_links.setdefault(a, []).append(i)
        # shortest searched ordinary edge into each activation (derived edges only go there)
        self.best: dict[tuple[int, int], int] = {}
        for a in self.act_links:
            for u, w, eid in inn[a]:
                if eid < n_req and w < self.best.get((u, a), _INF):
                    self.best[(u, a)] = w
        self.p = [0] * n
        self.status = [_UNSTARTED] * k
        self.epoch = 0  # links completed; derived edges carry the epoch at which they were added

    def _add_derived(self, s: int, t: int, w: int, link: int) -> bool:
        """Add the derived edge s --w--> t unless an ordinary edge at least as short is there."""
        if w >= self.best.get((s, t), _INF):
            return False
        self.best[(s, t)] = w
        eid = len(self.e_src)
        self.e_src.append(s)
        self.e_dst.append(t)
        self.e_w.append(w)
        self.e_kind.append(_DERIVED)
        self.e_epoch.append(self.epoch)
        self.e_link[eid] = link
        self.inn[t].append((s, w, eid))
        self.out[s].append((t, w, eid))
        return True

    # ------------------------------------------------------------------------------ back-propagation
    def backprop(self, link: int, explain: bool = False, target: int = -1, epoch_below: int = 0) -> _Search:
        """Dijkstra from C over in-edges. Returns ``(outcome, dist, pred, internal, extra)``.

        ``outcome``: "ok" (``extra``: the moat nodes); "need" (the activation of an unstarted link was
        reached inside: ``extra`` = [that link]); "started" (the activation of a link on the stack, this
        one included: ``extra`` = [that link]). ``dist``: D(V, C) of the popped nodes; ``pred``: the id
        of the first edge of V's path to C. With ``explain`` the search never stops early except at
        ``target``, and with ``epoch_below`` it uses only edges added before that epoch.
        """
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
                break
            if d >= delta:
                moat.append(v)
                continue
            if not explain and v in act_links:
                for other in act_links[v]:
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
        """Step 4: from C over out-edges through internal nodes at non-negative distance from C; an
        internal node at negative distance closes the cycle A --c:x--> C ~> X ~> C --C:-y--> A."""
        c = self.ctg[link]
        delta = self.y[link] - self.x[link]
        p, out = self.p, self.out
        if not any(back.get(v, delta) < delta for v, _w, _eid in out[c] if v != c):
            return None  # no internal node next to C: the search could not expand anything but C
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
            if kv + p[v] - pc < 0:
                forward = self._forward_path(pred, c, v)
                return [self.lc_eid[link], *forward, *self._back_path(back_pred, v, c), -1 - link]
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
        """Repair p after edges into ``a`` were added: a Dijkstra from ``a`` over the decreases (Cairo et
        al. 2018, UpdatePotential), committed only on success. Returns a negative cycle (edge ids)."""
        p, out, inn = self.p, self.out, self.inn
        start = p[a]
        for u, w, _eid in inn[a]:
            if p[u] + w < start:
                start = p[u] + w
        if start == p[a]:
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
                        path = [eid]
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
        """Steps 2-5 for every link (the potential must be in place); raises `_NotDC`."""
        status, act, p = self.status, self.act, self.p
        for first in sorted(range(len(act)), key=lambda link: (-p[act[link]], link)):
            if status[first] != _UNSTARTED:
                continue
            stack = [first]
            status[first] = _STARTED
            while stack:
                link = stack[-1]
                outcome, dist, pred, _internal, extra = self.backprop(link)
                if outcome == "need":
                    status[extra[0]] = _STARTED
                    stack.append(extra[0])
                    continue
                if outcome == "started":
                    raise _NotDC(self._stack_cycle(stack, extra[0], pred))
                cycle = self.forward_check(link, dist, pred)
                if cycle is not None:
                    raise _NotDC(cycle)
                self._finish(link, dist, pred, extra)
                status[link] = _DONE
                stack.pop()

    def _finish(self, link: int, dist: dict[int, int], pred: dict[int, int], moat: list[int]) -> None:
        """Step 5: add the moat edges V --(D(V, C) - y)--> A, then repair the potential."""
        a, c, y = self.act[link], self.ctg[link], self.y[link]
        self.epoch += 1
        added = False
        for v in moat:
            w = dist[v] - y
            if v == a:
                if w < 0:
                    raise _NotDC([*self._back_path(pred, a, c), -1 - link])
                continue
            if self._add_derived(v, a, w, link):
                added = True
        if added:
            cycle = self.update_potential(a)
            if cycle is not None:
                raise _NotDC(cycle)

    def _stack_cycle(self, stack: list[int], closing: int, pred: dict[int, int]) -> list[int]:
        """The search of the top link met act(closing), a link on the stack: chain the pieces
        act(next) ~> C --UC--> A of the links from ``closing`` up to the top."""
        link = stack[-1]
        cycle = [*self._back_path(pred, self.act[closing], self.ctg[link]), -1 - link]
        for i in range(len(stack) - 2, stack.index(closing) - 1, -1):
            prev, target = stack[i], self.act[stack[i + 1]]
            ppred = self.backprop(prev, explain=True, target=target)[2]
            cycle.extend([*self._back_path(ppred, target, self.ctg[prev]), -1 - prev])
        return cycle

    # ------------------------------------------------------------------------------ explanations
    def edge(self, eid: int) -> Edge:
        names = self.names
        if eid < 0:
            link = -1 - eid
            c = names[self.ctg[link]]
            return Edge(c, names[self.act[link]], -self.y[link], EdgeKind.UPPER, c)
        s, t, w = names[self.e_src[eid]], names[self.e_dst[eid]], self.e_w[eid]
        kind = self.e_kind[eid]
        if kind == _LC:
            return Edge(s, t, w, EdgeKind.LOWER, t)
        if kind == _DERIVED:
            return Edge(s, t, w, EdgeKind.DERIVED)
        return Edge(s, t, w)

    def expand(self, eids: list[int]) -> tuple[Edge, ...]:
        """Replace derived edges by the paths they stand for (within `_EXPAND_LIMIT` edges and
        `_EXPAND_SEARCHES` searches; beyond that derived edges stay as they are)."""
        out: list[Edge] = []
        stack = list(reversed(eids))
        budget = _EXPAND_SEARCHES
        while stack:
            eid = stack.pop()
            if eid >= 0 and self.e_kind[eid] == _DERIVED and budget > 0 and len(out) + len(stack) < _EXPAND_LIMIT:
                budget -= 1
                link, v = self.e_link[eid], self.e_src[eid]
                pred = self.backprop(link, explain=True, target=v, epoch_below=self.e_epoch[eid])[2]
                stack.extend(reversed([*self._back_path(pred, v, self.ctg[link]), -1 - link]))
            else:
                out.append(self.edge(eid))
        return tuple(out)

    def added(self) -> tuple[Edge, ...]:
        """DC only: the derived ordinary edges, then per link the waits V --C:(D(V, C) - y)--> A of its
        internal nodes (searched again over the final graph)."""
        names = self.names
        found = [self.edge(eid) for eid, kind in enumerate(self.e_kind) if kind == _DERIVED]
        for link in range(len(self.act)):
            a, c, y = self.act[link], self.ctg[link], self.y[link]
            _, dist, _, internal, _ = self.backprop(link, explain=True)
            found.extend(Edge(names[v], names[a], dist[v] - y, EdgeKind.UPPER, names[c]) for v in internal if v != c)
        return tuple(found)

    def stn_cycle(self) -> list[int] | None:
        """A negative cycle of the STN alone (requirements and ordinary pairs), or None."""
        n = len(self.names)
        out: list[list[tuple[int, int, int]]] = [[] for _ in range(n)]
        for u, edges in enumerate(self.out):
            out[u] = [e for e in edges if self.e_kind[e[2]] != _LC]
        return feasible_potential(n, out, [0] * n)


def _python_check(stnu: STNU) -> tuple[str, tuple[Edge, ...], _Rul]:
    """Steps 1-5 in Python, with the explaining cycle."""
    run = _Rul(stnu)
    cycle = feasible_potential(len(run.names), run.out, run.p)
    if cycle is not None:
        if all(run.e_kind[eid] != _LC for eid in cycle):
            return "inconsistent", run.expand(cycle), run
        stn = run.stn_cycle()
        if stn is not None:
            return "inconsistent", run.expand(stn), run
        return "not DC", run.expand(cycle), run
    try:
        run.run()
    except _NotDC as found:
        return "not DC", run.expand(found.cycle), run
    return "DC", (), run


NATIVE_LIBRARY_VARIABLE = "HRC_NATIVE_LIBRARY"
"""The environment variable naming another build of the native core to load instead (a path): the fuzz
job's build with AddressSanitizer and UndefinedBehaviorSanitizer (``scripts/fuzz.py``, docs/fuzzing.md).
A developer's setting, read once: a path that does not load raises `OSError` (a sanitizer run must not
go on silently without its library)."""


def native_library() -> ctypes.CDLL | None:
    """The native core (``_rulcore.c``, ``_stncore.c``, ``hrc/compile/_patterncore.c`` and
    ``hrc/dispatch/_dispatchcore.c``, built into ``_native/`` by ``pip install`` when a C compiler is
    there, or the build `NATIVE_LIBRARY_VARIABLE` names), or None. Loaded once."""
    if not _LIBRARY:
        chosen = os.environ.get(NATIVE_LIBRARY_VARIABLE)
        if chosen:
            _LIBRARY.append(ctypes.CDLL(chosen))  # OSError when it does not load
            return _LIBRARY[0]
        here = Path(__file__).resolve().parent / "_native"
        found = None
        for suffix in importlib.machinery.EXTENSION_SUFFIXES:
            path = here / f"_rulcore{suffix}"
            if path.is_file():
                try:
                    found = ctypes.CDLL(str(path))
                except OSError:
                    found = None
                break
        _LIBRARY.append(found)
    return _LIBRARY[0]


_LIBRARY: list[ctypes.CDLL | None] = []  # filled once by `native_library`


def _load_core() -> Callable[..., int] | None:
    """The C verdict (`native_library`'s ``hrc_rul_verdict``), or None."""
    lib = native_library()
    if lib is None:
        return None
    fn = lib.hrc_rul_verdict
    fn.argtypes = [ctypes.c_int, ctypes.c_int, *[ctypes.c_void_p] * 4, ctypes.c_int, *[ctypes.c_void_p] * 6]
    fn.restype = ctypes.c_int
    return fn  # type: ignore[no-any-return]


_CORE = _load_core()
_VERDICTS = {0: "DC", 1: "not DC", 2: "inconsistent"}
_LOW = (1 << 64) - 1


EdgeArrays = tuple[list[int], list[int], list[int], list[int], list[int], list[int], list[int]]
_EDGE_ARRAYS: dict[int, tuple[STNU, EdgeArrays]] = {}  # by identity, the last few (each kept alive here)


def edge_arrays(stnu: STNU) -> EdgeArrays:
    """`stnu` as `core_verdict`'s index arrays (timepoints by position): the ordinary edges ``src, dst,
    wt`` of its requirement links, then its contingent links ``act, ctg, xs, ys``.

    The compiler reads one network several times over (DC verdict, consistency, schedules, distance
    matrices), so the last few results are kept, by identity (callers must not change the lists); a
    network derived from a kept one (`hrc.temporal.network.lineage`) gets the parent's arrays, cut and
    spliced, in the same order as read in full."""
    hit = _EDGE_ARRAYS.get(id(stnu))
    if hit is not None and hit[0] is stnu:
        return hit[1]
    arrays = _derived_arrays(stnu) or _edge_arrays(stnu)
    make_room(_EDGE_ARRAYS, 8)
    _EDGE_ARRAYS[id(stnu)] = (stnu, arrays)
    return arrays


def _edge_arrays(stnu: STNU) -> EdgeArrays:
    index = {v: i for i, v in enumerate(stnu.timepoints)}
    src, dst, wt = bound_edges(stnu.requirements, index)
    conts = stnu.contingents
    return (src, dst, wt, [index[c.source] for c in conts], [index[c.target] for c in conts],
            [c.lb for c in conts], [c.ub for c in conts])


def bound_edges(links: Sequence[RequirementLink], index: dict[str, int]) -> tuple[list[int], list[int], list[int]]:
    """The edges of requirement `links`, in order: per link, its upper bound's, then its lower bound's."""
    src: list[int] = []
    dst: list[int] = []
    wt: list[int] = []
    for r in links:
        s, t = index[r.source], index[r.target]
        if r.ub is not None:
            src.append(s)
            dst.append(t)
            wt.append(r.ub)
        if r.lb is not None:
            src.append(t)
            dst.append(s)
            wt.append(-r.lb)
    return src, dst, wt


def _derived_arrays(stnu: STNU) -> EdgeArrays | None:
    """`_edge_arrays` of a network derived from one whose arrays are kept (`lineage`), or None."""
    origin = lineage(stnu)
    if origin is None:
        return None
    parent, at, links, rest = origin
    hit = _EDGE_ARRAYS.get(id(parent))
    if hit is None or hit[0] is not parent:
        return None
    new = bound_edges(links, {v: i for i, v in enumerate(stnu.timepoints)} if links else {})
    src, dst, wt = spliced(hit[1][:3], parent, at, new, rest)
    return (src, dst, wt, *hit[1][3:])


def spliced(edges: Sequence[Any], parent: STNU, at: int, new: Sequence[Any], rest: bool) -> tuple[Any, ...]:
    """A derived network's (`lineage`) requirement edges from its parent's `edges` (parallel sequences,
    as `edge_arrays` orders them: lists or typed arrays): the parent's first `at` links' edges, then
    `new` (the inserted links' edges, in the same layout), then, if `rest`, the parent's other edges."""
    cut = len(edges[0]) - bound_count(parent.requirements[at:])
    return tuple((x[:cut] + y + x[cut:]) if rest else (x[:cut] + y) for x, y in zip(edges, new, strict=True))


def _core_verdict(stnu: STNU) -> str | None:
    """The verdict from the C core, or None when it is not built or the numbers are too large for it."""
    if _CORE is None:
        return None
    return core_verdict(len(stnu.timepoints), *edge_arrays(stnu))


def core_verdict(n: int, src: list[int], dst: list[int], wt: list[int], act: list[int], ctg: list[int],
                 xs: list[int], ys: list[int]) -> str | None:
    """The C core's verdict ("DC", "not DC", "inconsistent") for a network given as index arrays: the
    ordinary edges ``src[i] --wt[i]--> dst[i]`` (T(dst) - T(src) <= wt) and the contingent links
    ``act[j] --[xs[j], ys[j]]--> ctg[j]``; None when the core is not built or the numbers are too large
    for it (the caller falls back to `check_dc`). For callers that check many networks of one shape
    (the dispatcher) without building `STNU` values."""
    core = _CORE
    if core is None:
        return None
    biggest = max(max(wt, default=0), -min(wt, default=0), max(ys, default=0))
    if biggest * (n + 2) >= 1 << 120:
        return None
    keep = [array("i", src), array("i", dst), array("i", act), array("i", ctg)]
    if biggest < 1 << 62:  # signed 64-bit words
        w, x, y = array("q", wt), array("q", xs), array("q", ys)
        keep += [w, x, y]
        words = [w.buffer_info()[0], None, x.buffer_info()[0], None, y.buffer_info()[0], None]
    else:  # (low, high) word pairs
        words = []
        for values in (wt, xs, ys):
            lo, hi = array("Q", [v & _LOW for v in values]), array("q", [v >> 64 for v in values])
            keep += [lo, hi]
            words += [lo.buffer_info()[0], hi.buffer_info()[0]]
    a = [arr.buffer_info()[0] for arr in keep[:4]]
    code = core(n, len(src), a[0], a[1], words[0], words[1], len(act), a[2], a[3], *words[2:])
    return _VERDICTS.get(code)  # -1 (out of memory in C): fall back to Python


def rul2021_check(stnu: STNU, *, accelerated: bool = True) -> RulOutcome:
    """The whole check, consistency included (step 1 decides it): see the module docstring.

    The verdict comes from the C core when it is built (``accelerated``); the cycle and the derived edges
    then come from the Python implementation when first asked for (`RulOutcome`).
    """
    verdict = _core_verdict(stnu) if accelerated else None
    if verdict is None:
        verdict, cycle, run = _python_check(stnu)
        return verdict, cycle, (run.added if verdict == "DC" else None)

    def explain() -> tuple[Edge, ...]:
        again, cycle, _run = _python_check(stnu)
        if again != verdict:
            raise RuntimeError(f"rul2021: the C core says {verdict}, the Python implementation {again}")
        return cycle

    if verdict == "DC":
        return "DC", (), lambda: _python_check(stnu)[2].added()
    return verdict, explain, None


def rul2021(stnu: STNU) -> tuple[list[Edge], list[Edge] | None]:
    """The `hrc.temporal.dc.ALGORITHMS` entry, for a consistent STNU: ``(cycle, None)`` when not DC (a
    semi-reducible negative cycle of the labelled graph, derived edges expanded) or ``([], added)``."""
    verdict, cycle, run = _python_check(stnu)
    if verdict != "DC":
        return list(cycle), None
    return [], list(run.added())
