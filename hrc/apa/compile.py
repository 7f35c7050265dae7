"""APACompilePlan (Wilcox, Nikolaidis & Shah 2012, Fig. 5): from an STPP to its *dispatchably optimal*
(DO) form, a flexible scheduling policy every choice of which maximises the global preference value.

The paper's steps and what this module does for each:

1-2. APSP of the STP, then prune redundant edges: the APSP exposes implicit constraints, the pruned
     network is handed to the solver. Here the solver gets the original interval constraints, which
     have the same feasible set and (measured, docs/apa.md) 4-8 times fewer rows than the pruned APSP
     network; consistency is the QP's feasibility (an infeasible QP is confirmed, and its negative
     cycle found, by exact Bellman-Ford), and each event's window comes from two Dijkstra runs on
     weights made non-negative by an exact schedule (Johnson's reweighting), so no n x n matrix is
     built. `prune_report` does lines 1-2 as the
     paper does (APSP, then MMT 1998 dominance pruning) to report how many edges pruning removes.
3.   Solve the QP (`hrc.apa.qp`: piqp, or clarabel as the cross-check).
4-9. Tighten every preferred interval to its optimal value, **except** one whose preference is constant:
     every value of it is optimal, so it keeps its original bounds (a deviation from Fig. 5, which
     tightens every preferred interval: it only adds schedules, each of the same optimal value; the
     paper's flexibility, section V, gains 6-9 points by it on the random problems, docs/apa.md).
     **Tolerance**: the temporal core is exact
     in integer ticks (`ticks_per_second`, a microsecond by default), the QP is in floats; an optimal
     difference ``d*`` (in ticks) within `SNAP` ticks of an integer ``r``, or whose neighbouring tick
     ``r`` that its preference likes better costs at most `VALUE_SNAP` of the global value (relative),
     becomes the rigid ``[r, r]``;
     any other becomes ``[floor d*, ceil d*]`` (one tick wide), always within its original bounds.
     Every schedule of the DO form is then within ``value_tolerance`` (the sum over preferred
     intervals of ``max |f'| * max |d - d*|`` over the tightened interval) of the optimum; the
     tightened network is checked to be consistent (exactly), and widened a tick at a time if the
     solver's own error made it not.
10.  APSP again = the DO form. The tightened network (`CompileResult.do_network`) *is* the DO form in
     constraint form; `do_apsp` gives its APSP matrix and `do_form` its minimal dispatchable network
     (the compact list of constraints the CLI prints). The DO windows (each event's window relative
     to the reference event) and the flexibility ratio are computed sparsely.

The steps run on the STPP's constraints as arrays (`Rows`: one row per constraint, bounds in ticks;
`compile_rows`), so that a caller holding a network as arrays (the dispatcher, recompiling a plan's DO
form on its residual network: Fig. 8, line 7) builds no objects; `compile_stpp` is the same on an `STPP`.

Flexibility (section V, Fig. 11): the summed widths of the events' windows relative to the reference
event in the DO form, over the same in the original STPP (events whose original window is unbounded
are left out); 1.0 when the original has no flexibility to lose.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from hrc.apa.model import STPP, Constraint, PreferenceFunction
from hrc.apa.qp import QuadraticProgram, solve_qp
from hrc.errors import ApaError
from hrc.temporal.graph import distance_edges
from hrc.temporal.network import STNU, RequirementLink
from hrc.temporal.stn import Window, all_pairs_shortest_paths, find_negative_cycle, minimal_dispatchable_network
from hrc.temporal.ticks import to_ticks

__all__ = [
    "SNAP",
    "TICKS_PER_SECOND",
    "VALUE_SNAP",
    "CompileResult",
    "PruneReport",
    "Rows",
    "RowsResult",
    "build_qp",
    "compile_rows",
    "compile_stpp",
    "do_apsp",
    "do_form",
    "interval_flexibility",
    "prune_report",
    "rows_apsp",
    "stpp_network",
    "stpp_rows",
]

TICKS_PER_SECOND = 1_000_000
"""APA's default resolution: a microsecond (the plans' STNUs use milliseconds; pass theirs)."""

SNAP = 0.05
"""Ticks: an optimal difference this close to an integer is taken to be that integer (the QP is
solved to about 1e-10 s, far below a tick)."""

VALUE_SNAP = 1e-9
"""Relative: an optimal difference is also rounded to the neighbouring tick its preference likes
better when that lowers the global preference value by no more than this (the QP's own accuracy is
about 1e-10 relative). An interior-point solver stops a little inside a bound that is active at a
preference's peak (the spar's "fresh sealant" at 0 s came out 0.13-0.6 ms late), where the value is
flat, so its exact place there is noise."""


def _ticks(seconds: float, tps: int) -> int | None:
    return None if math.isinf(seconds) else to_ticks(seconds, tps)


def stpp_network(stpp: STPP, ticks_per_second: int = TICKS_PER_SECOND) -> STNU:
    """The STP of `stpp` in integer ticks (preferences dropped), timepoints in event order."""
    links = tuple(RequirementLink(c.source, c.target, _ticks(c.lb, ticks_per_second), _ticks(c.ub, ticks_per_second))
                  for c in stpp.constraints)
    return STNU(stpp.events, links, (), stpp.name)


@dataclass(frozen=True, slots=True)
class Rows:
    """An STPP's constraints as arrays: row k is ``lb[k] <= T(dst[k]) - T(src[k]) <= ub[k]`` in ticks
    (float64 holding integers; ``-inf`` / ``inf`` for an open side) over `n` events, the first the
    reference; `prefs` the rows that carry a preference, with its function, in row order."""

    n: int
    src: np.ndarray
    dst: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    prefs: tuple[tuple[int, PreferenceFunction], ...]

    def edges(self, lb: np.ndarray | None = None, ub: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The distance graph's edges ``(src, dst, w)``: ``src -> dst`` with the upper bound, ``dst -> src``
        with the lower bound negated, finite ones only; of other bounds `lb`, `ub` where given."""
        lb = self.lb if lb is None else lb
        ub = self.ub if ub is None else ub
        up, lo = np.isfinite(ub), np.isfinite(lb)
        return (np.concatenate([self.src[up], self.dst[lo]]), np.concatenate([self.dst[up], self.src[lo]]),
                np.concatenate([ub[up], -lb[lo]]))


def stpp_rows(stpp: STPP, ticks_per_second: int = TICKS_PER_SECOND) -> Rows:
    """`stpp` as `Rows` (the bounds of `stpp_network`, exactly)."""
    cons = stpp.constraints
    index = stpp.index
    lb = np.array([-math.inf if math.isinf(c.lb) else float(to_ticks(c.lb, ticks_per_second)) for c in cons])
    ub = np.array([math.inf if math.isinf(c.ub) else float(to_ticks(c.ub, ticks_per_second)) for c in cons])
    return Rows(len(stpp.events), np.array([index(c.source) for c in cons], dtype=np.int64),
                np.array([index(c.target) for c in cons], dtype=np.int64), lb.reshape(-1), ub.reshape(-1),
                tuple((k, c.preference) for k, c in enumerate(cons) if c.preference is not None))


def _cycle(stnu: STNU) -> tuple[str, ...]:
    """The events of a negative cycle of `stnu` (exact Bellman-Ford), or ``()`` if it is consistent."""
    _, cycle = find_negative_cycle(stnu.timepoints, distance_edges(stnu))
    return tuple(e.source for e in cycle)


def _repair(n: int, edges: tuple[np.ndarray, np.ndarray, np.ndarray], start: np.ndarray) -> np.ndarray | None:
    """A feasible schedule (ticks) of the network of `edges` grown from the nearly feasible `start` (the
    QP's optimum rounded to ticks), or None if it has a negative cycle.

    Bellman-Ford relaxation from arbitrary finite labels converges to labels with
    ``p[v] - p[u] <= w`` for every edge iff there is no negative cycle; each pass here touches only the
    violated edges, and rounded optimal times violate almost none (if ``x`` meets integer difference
    bounds exactly, so does ``floor(x)``; ``x`` is off by ~1e-10 s), so a few passes suffice where a
    cold start takes ``O(n m)``.
    """
    src, dst, w = edges
    p = start.astype(np.float64).copy()
    for _ in range(n + 1):
        cand = p[src] + w
        bad = cand < p[dst]
        if not bad.any():
            return p
        np.minimum.at(p, dst[bad], cand[bad])
    return None


def _distances(n: int, src: np.ndarray, dst: np.ndarray, w: np.ndarray, p: np.ndarray, ref: int,
               reverse: bool) -> np.ndarray:
    """Shortest distances from `ref` (to `ref` when `reverse`), by Dijkstra on the weights reduced by
    the feasible potential `p` (Johnson 1977), which are non-negative. Exact: integers in float64."""
    rw = w + p[src] - p[dst]
    a, b = (dst, src) if reverse else (src, dst)
    key = a * n + b
    order = np.lexsort((rw, key))
    key, rw = key[order], rw[order]
    first = np.ones(len(key), dtype=bool)
    first[1:] = key[1:] != key[:-1]
    key, rw = key[first], rw[first]  # parallel edges: keep the tightest (csr_matrix would add them)
    graph = sp.csr_matrix((rw, (key // n, key % n)), shape=(n, n))
    d = dijkstra(graph, directed=True, indices=ref)
    return d + p[ref] - p if reverse else d - p[ref] + p


def _windows(n: int, edges: tuple[np.ndarray, np.ndarray, np.ndarray], p: np.ndarray,
             ref: int) -> tuple[Window, ...]:
    src, dst, w = edges
    hi = _distances(n, src, dst, w, p, ref, reverse=False)
    lo = -_distances(n, src, dst, w, p, ref, reverse=True)
    return tuple(Window(None if math.isinf(a) else int(round(a)), None if math.isinf(b) else int(round(b)))
                 for a, b in zip(lo, hi, strict=True))


def _width(win: Window) -> int | None:
    return None if win.lo is None or win.hi is None else win.hi - win.lo


def _flexibility(original: tuple[Window, ...], do: tuple[Window, ...], ref: int) -> float:
    total = kept = 0
    for k, (a, b) in enumerate(zip(original, do, strict=True)):
        wa, wb = _width(a), _width(b)
        if k == ref or wa is None or wb is None:
            continue
        total += wa
        kept += wb
    return 1.0 if total == 0 else kept / total


@dataclass(frozen=True, slots=True)
class CompileResult:
    """What `compile_stpp` found. Times and windows are aligned with ``stpp.events``.

    * `consistent`: False when the hard constraints admit no schedule (`cycle` then names events of a
      negative cycle and nothing else is set);
    * `value`: the optimal global preference value ``F`` (of the QP's optimal times `qp_times`, s);
    * `times`: one optimal schedule (s), read from the DO form in exact ticks, so it meets every hard
      constraint exactly; its value is within `value_tolerance` of `value`;
    * `do_network`: the tightened network in ticks (Fig. 5 line 9): its APSP is the DO form;
    * `windows` / `original_windows`: each event's window (ticks) relative to the reference event
      (the first) in the DO form and in the original STPP; `flexibility` the ratio of their widths;
    * `seconds`: the time each step took (wall clock, for benchmarks).
    """

    stpp: STPP
    ticks_per_second: int
    consistent: bool
    cycle: tuple[str, ...] = ()
    value: float | None = None
    qp_times: tuple[float, ...] = ()
    times: tuple[float, ...] = ()
    do_network: STNU | None = None
    windows: tuple[Window, ...] = ()
    original_windows: tuple[Window, ...] = ()
    flexibility: float | None = None
    value_tolerance: float = 0.0
    solver: str = ""
    widened: int = 0
    seconds: tuple[tuple[str, float], ...] = ()

    def schedule(self) -> dict[str, float]:
        """`times` as ``{event: seconds}``."""
        return dict(zip(self.stpp.events, self.times, strict=True))

    def window(self, event: str) -> tuple[float | None, float | None]:
        """The DO window of `event` in seconds relative to the reference event."""
        win = self.windows[self.stpp.index(event)]
        tps = self.ticks_per_second
        return (None if win.lo is None else win.lo / tps, None if win.hi is None else win.hi / tps)


def build_qp(stpp: STPP, stnu: STNU, tps: int) -> QuadraticProgram:
    """Fig. 5 line 3's problem: `stpp`'s QP over the bounds of its tick network `stnu` (in seconds),
    one anchor event per connected part (see `hrc.apa.qp`)."""
    return _qp(stpp_rows(stpp, tps), tps)


def _qp(rows: Rows, tps: int) -> QuadraticProgram:
    n = rows.n
    pi = np.array([rows.src[k] for k, _ in rows.prefs], dtype=np.int64)
    pj = np.array([rows.dst[k] for k, _ in rows.prefs], dtype=np.int64)
    c1 = np.array([f.c[1] for _, f in rows.prefs])
    c2 = np.array([f.c[2] for _, f in rows.prefs])
    return QuadraticProgram(n, rows.src, rows.dst, rows.lb / tps, rows.ub / tps, pi, pj, c1.reshape(-1),
                            c2.reshape(-1), _anchors(n, rows.src, rows.dst))


def _anchors(n: int, src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """The first event of each weakly connected part of the graph of rows ``src -> dst`` over `n` events,
    ascending (event 0 leads its own): union-find with each part's root its lowest event (the roots are
    the answer). The dispatcher's DO forms ask this of a network of a hundred rows at every recompile,
    where a sparse matrix and `connected_components` cost ten times as much."""
    parent = list(range(n))

    def root(v: int) -> int:
        while parent[v] != v:
            parent[v] = parent[parent[v]]
            v = parent[v]
        return v

    for a, b in zip(src.tolist(), dst.tolist(), strict=True):
        ra, rb = root(a), root(b)
        if ra < rb:
            parent[rb] = ra
        elif rb < ra:
            parent[ra] = rb
    return np.array([v for v in range(n) if parent[v] == v], dtype=np.intp)


def _tighten(rows: Rows, x: np.ndarray, tps: int, widen: int, total: float) -> tuple[np.ndarray, np.ndarray, float]:
    """Fig. 5 lines 4-9: preferred intervals set to their optimal differences (see the module's
    tolerance), `widen` extra ticks each side; `total` is the optimal value. Returns the network's bounds
    (`Rows` lb, ub) and its value tolerance."""
    lb, ub = rows.lb.copy(), rows.ub.copy()
    slack = 0.0
    for k, f in rows.prefs:
        if f.c[1] == 0 and f.c[2] == 0:  # constant: every difference is optimal, the interval stays free
            continue
        d = (x[rows.dst[k]] - x[rows.src[k]]) * tps
        r = round(d)
        if abs(d - r) > SNAP:  # of the two ticks around d*, the one its preference likes better
            r = max((math.floor(d), math.ceil(d)), key=lambda k: (f.value(k / tps), -abs(k - d)))
        flat = f.value(r / tps) >= f.value(d / tps) - VALUE_SNAP * max(1.0, abs(total))
        lo, hi = (r, r) if abs(d - r) <= SNAP or flat else (math.floor(d), math.ceil(d))
        lo = max(lo - widen, int(rows.lb[k]) if math.isfinite(rows.lb[k]) else lo - widen)
        hi = min(hi + widen, int(rows.ub[k]) if math.isfinite(rows.ub[k]) else hi + widen)
        lo, hi = min(lo, hi), max(lo, hi)
        lb[k], ub[k] = lo, hi
        a, b = min(lo, d), max(hi, d)  # every DO choice of this difference, and the optimum
        slack += f.max_slope_on(a / tps, b / tps) * (b - a) / tps
    return lb, ub, float(slack)


@dataclass(frozen=True, slots=True)
class RowsResult:
    """`compile_rows`' result: `consistent` (False: the hard constraints admit no schedule, nothing else
    set); the QP's optimum `x` (s) and its value; `p` an exact schedule of the original rows (ticks);
    `do_lb`, `do_ub` the tightened rows' bounds (Fig. 5 line 9: their APSP is the DO form) and `q` an exact
    schedule of them; the value tolerance, the ticks the tightening was widened by, and the seconds each
    step took."""

    consistent: bool
    x: np.ndarray | None = None
    value: float | None = None
    p: np.ndarray | None = None
    do_lb: np.ndarray | None = None
    do_ub: np.ndarray | None = None
    q: np.ndarray | None = None
    tolerance: float = 0.0
    widened: int = 0
    seconds: tuple[tuple[str, float], ...] = ()


def compile_rows(rows: Rows, *, solver: str = "piqp", ticks_per_second: int = TICKS_PER_SECOND) -> RowsResult:
    """APACompilePlan (Fig. 5) on `rows`: the QP, its optimum made an exact schedule, the preferred
    intervals tightened (the module docstring). Raises `ApaError` if the solver fails on a consistent
    problem; an inconsistent one is a result (``consistent=False``)."""
    tps = ticks_per_second
    clock = time.perf_counter()
    seconds: list[tuple[str, float]] = []

    def lap(step: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        seconds.append((step, now - clock))
        clock = now

    qp = _qp(rows, tps)
    edges = rows.edges()
    lap("stp")
    try:
        x = solve_qp(qp, solver)
    except ApaError:
        if _repair(rows.n, edges, np.zeros(rows.n)) is None:  # an infeasible QP is an inconsistent STP
            return RowsResult(False)
        raise
    value = sum(f.value(x[rows.dst[k]] - x[rows.src[k]]) for k, f in rows.prefs)
    lap("qp")
    start = np.round((x - x[0]) * tps)
    p = _repair(rows.n, edges, start)
    if p is None:  # the solver called an inconsistent problem solved
        return RowsResult(False)
    for widen in range(4):
        lb, ub, tolerance = _tighten(rows, x, tps, widen, value)
        q = _repair(rows.n, rows.edges(lb, ub), start)
        if q is not None:
            break
    else:
        raise ApaError(f"the {solver} solution is too inaccurate to tighten the STPP consistently")
    lap("tighten")
    return RowsResult(True, x, float(value), p, lb, ub, q, tolerance, widen, tuple(seconds))


def rows_apsp(rows: Rows, lb: np.ndarray, ub: np.ndarray) -> np.ndarray:
    """The APSP matrix (ticks, float64, ``inf`` where there is no path) of `rows` with bounds `lb`, `ub`,
    a consistent network: the DO form of `compile_rows`' tightened bounds (Fig. 5 line 10). In the native
    core when it is built (Floyd-Warshall in C), else by `all_pairs_shortest_paths`; the same numbers."""
    from hrc.temporal.native_stn import native_apsp

    src, dst, w = rows.edges(lb, ub)
    loop = src == dst
    if not (w[loop] < 0).any() and np.all(np.abs(w) < 2 ** 40):
        found = native_apsp(rows.n, src[~loop].tolist(), dst[~loop].tolist(), w[~loop].astype(np.int64).tolist())
        if found is not None and found[0]:
            return found[1]
    names = tuple(str(i) for i in range(rows.n))
    links = tuple(RequirementLink(names[a], names[b], None if math.isinf(lo) else int(lo),
                                  None if math.isinf(hi) else int(hi))
                  for a, b, lo, hi in zip(rows.src.tolist(), rows.dst.tolist(), lb.tolist(), ub.tolist(), strict=True))
    return np.asarray(all_pairs_shortest_paths(STNU(names, links)), dtype=float)


def compile_stpp(stpp: STPP, *, solver: str = "piqp", ticks_per_second: int = TICKS_PER_SECOND) -> CompileResult:
    """APACompilePlan (Fig. 5; see the module docstring for each step and the tolerance), on `stpp`'s
    `Rows` (`compile_rows`), with the windows of the original and the DO form.

    Cost: the QP (piqp: sparse interior point; its factorisations dominate), a few vectorised
    Bellman-Ford passes to make its optimum an exact schedule, and four Dijkstra runs. Raises
    `ApaError` if the solver fails. An inconsistent STPP is a result (``consistent=False``), not an
    exception.

    >>> from hrc.apa.model import Constraint as C, PreferenceFunction as F
    >>> r = compile_stpp(STPP(("a", "b"), (C("a", "b", 0, 8, F.quadratic(0, 8, -1)),)))
    >>> round(r.value, 6), r.schedule()
    (16.0, {'a': 0.0, 'b': 4.0})
    """
    tps = ticks_per_second
    rows = stpp_rows(stpp, tps)
    found = compile_rows(rows, solver=solver, ticks_per_second=tps)
    if not found.consistent:
        return CompileResult(stpp, tps, False, _cycle(stpp_network(stpp, tps)))
    assert found.x is not None and found.p is not None and found.q is not None
    assert found.do_lb is not None and found.do_ub is not None
    clock = time.perf_counter()
    original = _windows(rows.n, rows.edges(), found.p, 0)
    laps = [*found.seconds[:2], ("original_windows", time.perf_counter() - clock), *found.seconds[2:]]
    clock = time.perf_counter()
    do_net = STNU(stpp.events, tuple(
        RequirementLink(c.source, c.target, None if math.isinf(lo) else int(lo), None if math.isinf(hi) else int(hi))
        for c, lo, hi in zip(stpp.constraints, found.do_lb.tolist(), found.do_ub.tolist(), strict=True)), (),
        stpp.name)
    windows = _windows(rows.n, rows.edges(found.do_lb, found.do_ub), found.q, 0)
    q = found.q
    times = tuple(float(v) / tps for v in (q - q[0]))
    laps.append(("do_windows", time.perf_counter() - clock))
    return CompileResult(stpp, tps, True, (), float(found.value or 0.0), tuple(float(v) for v in found.x), times,
                         do_net, windows, original, _flexibility(original, windows, 0), found.tolerance, solver,
                         found.widened, tuple(laps))


def do_apsp(result: CompileResult) -> np.ndarray:
    """The DO form itself (Fig. 5 line 10): the APSP matrix of the tightened network, in ticks
    (``D[i, j]`` bounds ``T(j) - T(i)``). Dense: O(n^2) memory, O(n^3) time (temporal core)."""
    if result.do_network is None:
        raise ApaError("an inconsistent STPP has no DO form")
    return all_pairs_shortest_paths(result.do_network)


def do_form(result: CompileResult) -> tuple[Constraint, ...]:
    """The DO form as interval constraints (s): the minimal dispatchable network of the tightened
    network (Muscettola, Morris & Tsamardinos 1998, via the temporal core), one constraint per related
    pair in event order, dispatchable on its own by one-step propagation over these constraints.
    Dense: O(n^3).

    MMT's network collapses each rigid component onto its earliest member (its leader) and chains the
    others behind it: a member at a positive offset from the one before it in the chain is ordered by
    that chain link, but one at offset 0 (the two at the same time) has only ``[0, 0]`` to it, no
    negative edge, so a dispatcher that reads only these constraints (MMT section 3: an event is
    enabled when the events its negative edges point to are done) would find it enabled from the start
    and could execute it before its leader's predecessors. So each member at offset 0 from the head of
    its run gets that head's other constraints as well (the same bounds: they are at the same time),
    which are implied constraints (APSP values): dispatchability is kept and nothing is tightened."""
    if result.do_network is None:
        raise ApaError("an inconsistent STPP has no DO form")
    mdn = minimal_dispatchable_network(result.do_network)
    order = {v: i for i, v in enumerate(result.stpp.events)}
    bounds: dict[tuple[str, str], list[float]] = {}
    tps = result.ticks_per_second
    weight = {(e.source, e.target): e.value for e in mdn.edges}
    head: dict[str, str] = {}  # a member at offset 0 -> the first of its run of zero offsets
    for later, earlier in mdn.chained:  # in chain order: (b, a) for each link a -> b of a chain
        if weight[(earlier, later)] == 0:
            head[later] = head.get(earlier, earlier)
    same = {h: {h} for h in head.values()}
    for member, h in head.items():
        same[h].add(member)
    edges = [(e.source, e.target, e.value) for e in mdn.edges]
    if head:
        for e in mdn.edges:
            for member in same.get(e.source, ()):
                if member != e.source and e.target not in same[e.source]:
                    edges.append((member, e.target, e.value))
            for member in same.get(e.target, ()):
                if member != e.target and e.source not in same[e.target]:
                    edges.append((e.source, member, e.value))
    for a, b, w in edges:
        if order[a] < order[b]:
            box = bounds.setdefault((a, b), [-math.inf, math.inf])
            box[1] = min(box[1], w / tps)
        else:
            box = bounds.setdefault((b, a), [-math.inf, math.inf])
            box[0] = max(box[0], -w / tps)
    return tuple(Constraint(a, b, lb, ub) for (a, b), (lb, ub) in
                 sorted(bounds.items(), key=lambda kv: (order[kv[0][0]], order[kv[0][1]])))


def interval_flexibility(result: CompileResult) -> float | None:
    """Flexibility the paper's way (section V, Fig. 11: "compared the resulting interval durations to the
    original problems' interval durations"): for each constraint of the original STPP with a finite
    width ``ub - lb > 0``, the width its pair of events keeps in the DO form (``D[i, j] + D[j, i]`` of the
    DO form's APSP), over that width; the mean over those constraints (None: there are none). Dense:
    O(n^3). `CompileResult.flexibility` is the project's own measure (event windows from the reference).
    Raises `ApaError` for an inconsistent STPP."""
    if result.do_network is None:
        raise ApaError("an inconsistent STPP has no DO form")
    d = np.asarray(do_apsp(result), dtype=float)
    index = {e: i for i, e in enumerate(result.stpp.events)}
    ratios = []
    for c in result.stpp.constraints:
        width = c.ub - c.lb
        if math.isfinite(width) and width > 0:
            i, j = index[c.source], index[c.target]
            ratios.append(min(1.0, (d[i, j] + d[j, i]) / result.ticks_per_second / width))
    return float(np.mean(ratios)) if ratios else None


@dataclass(frozen=True, slots=True)
class PruneReport:
    """Fig. 5 lines 1-2 counted: directed distance-graph edges of the original STP, of its APSP form
    (every finite pair) and of that form pruned of dominated edges (the minimal dispatchable network)."""

    original_edges: int
    apsp_edges: int
    pruned_edges: int

    @property
    def pruned_fraction(self) -> float:
        """The share of the APSP form's edges that pruning removes (the paper: 40-50 %)."""
        return 0.0 if self.apsp_edges == 0 else 1 - self.pruned_edges / self.apsp_edges


def prune_report(stpp: STPP, ticks_per_second: int = TICKS_PER_SECOND) -> PruneReport:
    """APSP then dominance pruning of the original STP, as Fig. 5 lines 1-2 do, counted. Dense:
    O(n^3) time, O(n^2) memory; raises `ApaError` when the STPP is inconsistent."""
    stnu = stpp_network(stpp, ticks_per_second)
    if _cycle(stnu):
        raise ApaError("an inconsistent STPP has no APSP form")
    d = all_pairs_shortest_paths(stnu)
    finite = np.isfinite(d.astype(float))
    np.fill_diagonal(finite, False)
    original = len({(e.source, e.target) for e in distance_edges(stnu)})
    return PruneReport(original, int(finite.sum()), len(minimal_dispatchable_network(stnu).edges))
