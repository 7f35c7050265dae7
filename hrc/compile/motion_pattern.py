"""A plan's motion pattern: the robot's routes and, wherever the co-workers would meet, who goes first.

Strassmair & Taylor 2014, section V.A: a plan "implies a motion pattern of the co-workers in the shared
workspace", and what they cost each other (waits, detours, shared spots) belongs to *that* plan. Motion
acquisition (`hrc.motion.conflicts`) finds every place where the robot's and the human's occupancies
would overlap and, for each, the two difference constraints that keep them apart (robot first, human
first). Which one holds is part of the plan: this module chooses, per plan, the routes (shortest, or a
detour round the human, `hrc.motion.detours`) and a passing order at every conflict, so that the plan's
STNU gets the best class and then the best makespan. The choice is made offline for every human timing at
once, so the class is a guarantee about the chosen pattern:

- a conflict whose order the plan already *implies* whatever anybody does (task graph, sequences, lower
  bounds of durations: the "robust" network of `_robust`) needs no constraint;
- otherwise, if only one order can still hold (the other closes a negative cycle with what is decided),
  that order is *forced*; if both can, the search *chooses*, trying first the order the earliest schedule
  suggests. The order is added to the STNU as a requirement link.

Search: depth-first over the undecided conflicts in time order, with the all-pairs distance matrix of the
network without the task's limits updated incrementally per added edge (O(n^2) each), so dead branches
(co-workers blocking each other) are cut at once. Each complete pattern is built (`create_stnu`) and
classified (`classify`); the best by (class, makespan as ranked, the other makespan, detours used) wins.
Bounds stop the search early: adding constraints never improves a class or a makespan, so the network
with no passing order at all bounds every pattern; a pattern that reaches that bound ends the search.
The same holds at every node (branch and bound, `_node_bound`): a node that cannot beat the best
pattern so far, of this route choice or an earlier one, is cut.
At most `LEAF_CAP` complete patterns per route choice and `NODE_CAP` search nodes are visited (the
result says whether the search was exhaustive). Other routes (`_route_trials`: detours, stops at a
waiting place) are tried most promising first by their bound, each only while its bound can beat the
best pattern so far, at most `TRIAL_CAP` of them once there is a pattern at all; while there is none,
every one (on kitting, a person whose two phases at Q enclose the robot's label there finds a pattern
only by stepping back to a waiting place between them, which the bound ranks behind six detours: with
the cap, 648 of the 2,880 plans were declared blocked, "the co-workers would block each other").

Cost (kitting_7picks, 40,320 plans): the search is most of a plan's time, and most of it goes to the
fifth of the plans whose search hits its caps. So a leaf is measured off matrices the search carries and
classified by the C verdict on index arrays (no `STNU` per leaf); the depth-first search runs in C
(``hrc/compile/_patterncore.c``, with this module's Python search as its reference and fallback); and
plans that differ only by swapping identical actions share one search (`apply_pattern`,
`hrc.plans.plan_families`). Each step leaves every plan's record as it was (tests compare them).
"""

from __future__ import annotations

import ctypes
import functools
import itertools
import math
import operator
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from hrc.compile.classify import (
    CLASSES,
    Classification,
    EarliestStart,
    Fix,
    PlanClass,
    classify,
    distance_graph,
    earliest_start,
    measure,
    packed_graph,
    packed_lower_bounds,
)
from hrc.compile.temporal_net_creator import (
    ORIGIN,
    TICKS_PER_SECOND,
    PlanNetwork,
    create_stnu,
    leg_names,
    ref_namer,
)
from hrc.model import Plan, Task
from hrc.motion import Conflict, Motion, PathLibrary, Separation, TimeRef, detour, find_conflicts, plan_motions
from hrc.motion.conflicts import joint_spot_starts, people_meetings
from hrc.motion.motions import Route, Routes
from hrc.plans import agent_legs, per_plan
from hrc.temporal import STNU, DCResult, RequirementLink, Verdict, check_consistency, check_dc
from hrc.temporal.native_stn import native_apsp, native_distances
from hrc.temporal.rul import core_verdict, edge_arrays, native_library

__all__ = ["LEAF_CAP", "NODE_CAP", "RANK_BY", "TRIAL_CAP", "MotionPattern", "PassingOrder", "PlanChoice",
           "apply_pattern", "choose_pattern", "pattern_key", "pattern_network"]

LEAF_CAP = 24
NODE_CAP = 4000
TRIAL_CAP = 6
RANK_BY = ("worst", "earliest", "nominal")


@dataclass(frozen=True, slots=True)
class PassingOrder:
    """At `conflict`, `first` ("robot" | "human") goes first; `how` it was decided: "implied" (the plan
    orders them anyway), "forced" (the other order cannot hold) or "chosen" (by the search). For two
    robots (`hrc.motion.conflicts.floor_pairs`), "robot" is the conflict's `robot` slot and "human" its
    other slot, the second robot."""

    conflict: Conflict
    first: str
    how: str

    def __getstate__(self) -> list:
        return [self.conflict, self.first, self.how]  # see `hrc.motion.conflicts.TimeRef.__getstate__`

    @property
    def separation(self) -> Separation:
        return self.conflict.robot_first if self.first == "robot" else self.conflict.human_first

    def describe(self) -> str:
        c = self.conflict
        a, b = (c.robot, c.human) if self.first == "robot" else (c.human, c.robot)
        x, y = c.point
        return f"{a.describe()} before {b.describe()} at ({x:.1f}, {y:.1f})"


@dataclass(frozen=True, slots=True)
class MotionPattern:
    """The routes (`motions`), the passing order at every conflict, and how the search went; `meetings`:
    where two people may meet on these routes (`hrc.motion.conflicts.people_meetings`: reported, never
    constrained; none with fewer than two people)."""

    motions: tuple[Motion, ...]
    orders: tuple[PassingOrder, ...]
    candidates: int  # complete patterns classified
    exhaustive: bool  # False when a cap stopped the search
    meetings: tuple[Conflict, ...] = ()

    @property
    def detours(self) -> tuple[Motion, ...]:
        return tuple(m for m in self.motions if m.via)

    @property
    def constrained(self) -> tuple[PassingOrder, ...]:
        """The orders that are in the STNU (everything not implied)."""
        return tuple(o for o in self.orders if o.how != "implied")


@dataclass(frozen=True, slots=True)
class PlanChoice:
    pattern: MotionPattern
    net: PlanNetwork
    classification: Classification
    check: DCResult | None = None  # the DC check of ``net.stnu`` behind the class, when one was run here


def pattern_key(c: Classification, rank_by: str = "worst") -> tuple:
    """Class first, then the makespan `rank_by` names (worst / earliest / nominal), then the others."""
    if c.makespan is None:
        return (c.plan_class.order, math.inf, math.inf, math.inf)
    early, worst = c.makespan
    nominal = c.nominal if c.nominal is not None else early
    first = {"worst": worst, "earliest": early, "nominal": nominal}[rank_by]
    return (c.plan_class.order, round(first, 6), round(worst, 6), round(early, 6))


def _apsp(stnu: STNU, fix: Fix = "", after_origin: bool = False) -> np.ndarray | None:
    """Dense shortest distances (ticks as float64, exact below 2**52); None if the STN is inconsistent.

    Contingent links are read as requirements (``fix=""``) or fixed at their upper bound (``"ub"``);
    `after_origin` adds ``T(x) >= T(origin)`` for every timepoint (the reading of `classify`'s earliest
    schedules). Floyd-Warshall in the native core (`hrc.temporal.native_stn`); without it, scipy's
    (`_apsp_scipy`, the reference: a test compares them)."""
    packed = packed_graph(stnu, fix, after_origin)
    found = None if packed is None else native_apsp(len(stnu.timepoints), *packed)
    if found is None:
        return _apsp_scipy(len(stnu.timepoints), *_distance_graph(stnu, fix, after_origin))
    ok, mat = found
    return mat if ok else None


def _distance_graph(stnu: STNU, fix: Fix, after_origin: bool) -> tuple[list[int], list[int], list[int]]:
    """`_apsp`'s edges: `distance_graph` without self-loops (a node's distance to itself starts at 0)."""
    src, dst, wt = distance_graph(stnu, fix, after_origin)
    keep = [e for e in range(len(src)) if src[e] != dst[e]]
    if len(keep) < len(src):
        src, dst, wt = [src[e] for e in keep], [dst[e] for e in keep], [wt[e] for e in keep]
    return src, dst, wt


def _apsp_scipy(n: int, src: list[int], dst: list[int], wt: list[int]) -> np.ndarray | None:
    """`_apsp` by scipy's Floyd-Warshall."""
    mat = np.full((n, n), np.inf)
    if src:
        np.minimum.at(mat, (np.asarray(src), np.asarray(dst)), np.asarray(wt, dtype=np.float64))
    # a dense 0 means "no edge" to scipy: go through csgraph_from_dense with inf as the null value
    from scipy.sparse.csgraph import NegativeCycleError, csgraph_from_dense, floyd_warshall  # a cached compile: none

    try:
        return floyd_warshall(csgraph_from_dense(mat, null_value=np.inf), directed=True)
    except NegativeCycleError:
        return None


def _robust(net: PlanNetwork) -> STNU:
    """What holds in every execution, even one that breaks the plan's limits: the task graph, waiting and
    sequencing links, the robot's own durations, and the human's lower bounds (a person cannot be faster)."""
    free = net.without_limits()
    lows = tuple(RequirementLink(c.source, c.target, c.lb, None) for c in free.contingents)
    return STNU(free.timepoints, free.requirements + lows, (), free.name)


def _text(order: PassingOrder) -> str:
    return f"passing order: {order.describe()}"


def _network(base: PlanNetwork, namer: Callable[[TimeRef], str], orders: list[PassingOrder]) -> PlanNetwork:
    """`base` with the passing orders that are not implied as requirement links (before the limits)."""
    added = tuple(RequirementLink(namer(o.separation.earlier), namer(o.separation.later),
                                  math.ceil(o.separation.gap * TICKS_PER_SECOND - 1e-9), None)
                  for o in orders if o.how != "implied")
    return _with_links(base, added)


def _with_links(base: PlanNetwork, added: tuple[RequirementLink, ...]) -> PlanNetwork:
    """`base` with the requirement links `added` before its limits."""
    s = base.stnu
    return PlanNetwork(stnu=s.inserted(len(s.requirements) - base.n_limits, added), meaning=base.meaning,
                       last_ends=base.last_ends, n_limits=base.n_limits)


def _evaluate(task: Task, base: PlanNetwork, namer: Callable[[TimeRef], str], orders: list[PassingOrder],
              rank_by: str, start: EarliestStart | None = None) -> tuple[PlanNetwork, Classification]:
    """The pattern's network and its class and makespans, without the passing orders' words (a search
    classifies many patterns and explains one: `_worded` adds them to the one it keeps)."""
    net = _network(base, namer, orders)
    return net, classify(task, net, explained=False, full=rank_by == "nominal", start=start)


def _worded(task: Task, plan: Plan, net: PlanNetwork, orders: tuple[PassingOrder, ...]) -> PlanNetwork:
    """`net` (from `_evaluate`) with each passing order's meaning in words, as `with_separations` gives
    it: the same links, so the same STNU; the words explain a class."""
    namer = ref_namer(task, plan)
    meaning = dict(net.meaning)
    for o in orders:
        if o.how != "implied":
            meaning.setdefault((namer(o.separation.earlier), namer(o.separation.later)), ("space", _text(o)))
    return PlanNetwork(stnu=net.stnu, meaning=tuple(sorted(meaning.items())), last_ends=net.last_ends,
                       n_limits=net.n_limits)


class _Routing:
    """One choice of routes for a plan, with what the search and the bound read of it, each built once
    when first asked for (a plan's shortest routes are read by the bound, the search and the route
    trials alike)."""

    def __init__(self, task: Task, plan: Plan, paths: PathLibrary, routes: Routes, human_waits: bool) -> None:
        self.task, self.plan, self.paths, self.routes, self.human_waits = task, plan, paths, routes, human_waits

    @functools.cached_property
    def motions(self) -> tuple[Motion, ...]:
        return plan_motions(self.task, self.plan, self.paths, self.routes)

    @functools.cached_property
    def base(self) -> PlanNetwork:
        """The plan's network with these routes and no passing order."""
        return create_stnu(self.task, self.plan, self.motions, (), self.human_waits)

    @functools.cached_property
    def conflicts(self) -> tuple[Conflict, ...]:
        return find_conflicts(self.task, self.plan, self.paths, self.routes)

    def chain_bound(self, rank_by: str) -> float:
        """A lower bound (s) on the makespan `rank_by` names of every pattern with these routes, read off
        the agents' own chains of travels and steps alone, without building the network: each agent's
        travel times and durations in turn, at their lower bounds (the human's at the upper bounds for
        the worst case, which a DC pattern must fit: `_beyond`), a tick per link less for rounding."""
        motion = {(m.agent, m.leg): m.time for m in self.motions}
        longest = 0.0
        for agent, slack, terms, links in _chain_terms(self.task, self.plan, rank_by):
            total = 0.0
            for leg, bound in terms:
                total += motion[(agent, leg)] * slack + bound
            longest = max(longest, total - links / TICKS_PER_SECOND)
        return longest

    @functools.cached_property
    def robust(self) -> np.ndarray:
        """`_apsp` of `_robust`: what holds in every execution (from the network without limits, read
        with the human's durations bounded below only, when the native core takes it)."""
        packed_graph(self.base.stnu)  # the search reads it next: packed first, the free network's is derived
        free = self.base.without_limits()
        packed = packed_lower_bounds(free)
        found = None if packed is None else native_apsp(len(free.timepoints), *packed)
        if found is not None and found[0]:
            return found[1]
        robust = _apsp(_robust(self.base))
        assert robust is not None  # lower bounds and the robot's own durations along an acyclic phase graph
        return robust

    @functools.cached_property
    def index(self) -> dict[str, int]:
        """Each timepoint's position in `base`."""
        return {v: i for i, v in enumerate(self.base.stnu.timepoints)}

    @functools.cached_property
    def orders(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Per conflict and order (0: robot first, 1: human first) the constraint ``T(later) - T(earlier)
        >= gap`` as ``(earlier, later, gap)`` (k x 2 each: timepoints by position in `base`, the gap in
        ticks, rounded up), and whether it holds in every execution (`robust`, k x 2)."""
        index = self.index
        at = {(ORIGIN, 0, ""): index[ORIGIN]}  # a reference's key (`_constraints`) -> its position in `base`
        for agent, legs in leg_names(self.task, self.plan).items():
            for leg, names in enumerate(legs):
                at.update(((agent, leg, what), index[name]) for what, name in names.items() if name in index)
        k = len(self.conflicts)
        rows = [_constraints(c) for c in self.conflicts]
        # each row's four keys (earlier, earlier, later, later) looked up in one C call
        ends = np.array(operator.itemgetter(*itertools.chain.from_iterable(r[0] for r in rows))(at) if k else (),
                        dtype=int).reshape(k, 2, 2)
        earlier, later = ends[:, 0, :], ends[:, 1, :]
        gap = np.array(list(itertools.chain.from_iterable(r[1] for r in rows)), dtype=float).reshape(k, 2)
        implied = np.asarray(self.robust[later, earlier] <= -gap, dtype=bool).reshape(k, 2)
        return earlier, later, gap, implied

    @functools.cached_property
    def settled(self) -> list[bool]:
        """Per conflict, whether one of its orders holds in every execution (`orders`' `implied`): the
        search never branches on it, and a route trial does not try to avoid it."""
        implied = self.orders[3]
        return (implied[:, 0] | implied[:, 1]).tolist()


_Chain = tuple[str, float, tuple[tuple[int, float], ...], int]  # agent, slack, (leg, bound) per leg, links


@per_plan(64)
def _chain_terms(task: Task, plan: Plan, rank_by: str) -> tuple[_Chain, ...]:
    """What `_Routing.chain_bound` reads of a plan besides its routes, per agent: the travel slack its
    travel times are scaled by, each leg's duration bound (the lower one; the upper one for the human in
    the worst case) and the number of links. The same for every route choice of the plan."""
    out = []
    for agent in task.agents:
        late = agent.is_human and rank_by == "worst"
        legs = agent_legs(task, plan, agent.id)
        terms = []
        for leg in legs:
            bounds = task.action(leg.action).phase(leg.phase).duration(agent.id)
            terms.append((leg.index, bounds.ub if late else bounds.lb))
        out.append((agent.id, agent.travel_slack if late else 1.0, tuple(terms), 3 * len(legs)))
    return tuple(out)


_Key = tuple[str, int, str]
_Keys = tuple[tuple[_Key, _Key, _Key, _Key], tuple[int, int]]  # earlier, earlier, later, later; the gaps
_CONSTRAINTS: dict[int, tuple[Conflict, _Keys]] = {}
_CONSTRAINTS_CAP = 50_000  # conflicts kept per process


def _constraints(c: Conflict) -> _Keys:
    """A conflict's two orders as ``T(later) - T(earlier) >= gap`` (robot first, then human first): the
    earlier and later timepoints as plain keys ``(agent, leg, what)`` (the origin's: ``(ORIGIN, 0, "")``)
    and the gaps in ticks, rounded up. Kept per conflict, by identity (the entry holds the conflict):
    conflicts recur across a task's plans (`hrc.motion.find_conflicts`), and a search reads every one."""
    hit = _CONSTRAINTS.get(id(c))
    if hit is not None and hit[0] is c:
        return hit[1]

    def key(ref: TimeRef) -> tuple[str, int, str]:
        return (ORIGIN, 0, "") if ref.agent == "" else (ref.agent, ref.leg, ref.what)

    seps = (c.robot_first, c.human_first)
    keys: _Keys = ((key(seps[0].earlier), key(seps[1].earlier), key(seps[0].later), key(seps[1].later)),
                   (math.ceil(seps[0].gap * TICKS_PER_SECOND - 1e-9), math.ceil(seps[1].gap * TICKS_PER_SECOND - 1e-9)))
    if len(_CONSTRAINTS) >= _CONSTRAINTS_CAP:
        _CONSTRAINTS.clear()
    _CONSTRAINTS[id(c)] = (c, keys)
    return keys


_CLASS_OF = {"DC": PlanClass.DC, "not DC": PlanClass.CONSISTENT, "inconsistent": PlanClass.INCONSISTENT}
_VERDICT_CLASS = {Verdict.DC: PlanClass.DC, Verdict.NOT_DC: PlanClass.CONSISTENT,
                  Verdict.INCONSISTENT: PlanClass.INCONSISTENT}

Leaf = Callable[[], PlanChoice]  # builds a classified pattern's choice (only the kept one is ever built)


class _Edges:
    """`base`'s network as index arrays for the C core's DC verdict (`hrc.temporal.rul.core_verdict`), to
    which a leaf's passing orders are appended without building an `STNU` per leaf."""

    def __init__(self, stnu: STNU) -> None:
        self.n = len(stnu.timepoints)
        self.src, self.dst, self.wt, self.act, self.ctg, self.xs, self.ys = edge_arrays(stnu)

    def verdict(self, later: list[int], earlier: list[int], gaps: list[int]) -> str | None:
        """The verdict with ``T(later) - T(earlier) >= gap`` added per order (None: no C core here)."""
        return core_verdict(self.n, self.src + later, self.dst + earlier, self.wt + [-g for g in gaps],
                            self.act, self.ctg, self.xs, self.ys)


def _native_search() -> Callable[..., int] | None:
    lib = native_library()
    fn = getattr(lib, "hrc_pattern_search", None) if lib is not None else None
    if fn is not None:
        p = ctypes.c_void_p
        fn.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int, p, p, p, p, p, p, ctypes.c_int, p,
                       ctypes.c_int, p, p, p, ctypes.c_int, p, p, p, p,
                       ctypes.c_int, ctypes.c_int, ctypes.c_int, p, ctypes.c_int, ctypes.c_int, p, p, p, p, p]
        fn.restype = ctypes.c_int
    return fn


_NATIVE = _native_search()
_INF_TICKS = np.iinfo(np.int64).max


class _NativeSearch:
    """`_search`'s depth-first search in C (``hrc/compile/_patterncore.c``): the same steps, leaves and
    keys as the Python `dfs` (tested leaf for leaf), for the ``worst`` and ``earliest`` readings."""

    def __init__(self, fn: Callable[..., int], k: int, z: int, earlier: np.ndarray, later: np.ndarray,
                 gap: np.ndarray, settled: list[bool], ends: np.ndarray, edges: _Edges, bound: tuple | None,
                 rank_by: str) -> None:
        self.fn, self.k, self.z, self.n, self.rank_by = fn, k, z, edges.n, rank_by
        self.arrays: dict[str, np.ndarray] = {
            "earlier": np.ascontiguousarray(earlier, dtype=np.int32),
            "later": np.ascontiguousarray(later, dtype=np.int32),
            "gap": np.ascontiguousarray(gap, dtype=np.float64),
            "settled": np.asarray(settled, dtype=np.uint8),
            "ends": np.ascontiguousarray(ends, dtype=np.int32),
            "src": np.asarray(edges.src, dtype=np.int32), "dst": np.asarray(edges.dst, dtype=np.int32),
            "wt": np.asarray(edges.wt, dtype=np.int64), "act": np.asarray(edges.act, dtype=np.int32),
            "ctg": np.asarray(edges.ctg, dtype=np.int32), "xs": np.asarray(edges.xs, dtype=np.int64),
            "ys": np.asarray(edges.ys, dtype=np.int64),
            "bound": np.array([_ticks_key(bound) if bound is not None else (0, 0, 0, 0)], dtype=np.int64).reshape(4),
        }
        self.has_bound = bound is not None
        self.leaves: list[tuple[np.ndarray, np.ndarray, Classification]] = []
        self._pointers: dict[str, int] | None = None

    @classmethod
    def make(cls, k: int, z: int, earlier: np.ndarray, later: np.ndarray, gap: np.ndarray, settled: list[bool],
             ends: np.ndarray, edges: _Edges | None, bound: tuple | None, rank_by: str) -> _NativeSearch | None:
        """The native search, or None when the library is not built or the numbers are too large for it."""
        if _NATIVE is None or edges is None or rank_by not in ("worst", "earliest"):
            return None
        biggest = max(max(map(abs, edges.wt), default=0), max(edges.ys, default=0), int(np.abs(gap).max(initial=0)))
        if biggest >= 1 << 40 or (bound is not None and any(math.isnan(b) for b in bound)):
            return None
        return cls(_NATIVE, k, z, earlier, later, gap, settled, ends, edges, bound, rank_by)

    def run(self, start: np.ndarray, readings: tuple[np.ndarray | None, np.ndarray | None], state: dict,
            prune: bool) -> bool:
        """One pass from `start` (`state` read and updated as the Python search does); its leaves in
        `leaves`. False if the C search failed (out of memory): the caller searches in Python instead."""
        n, k, a = self.n, self.k, self.arrays
        mats = np.empty((3, n, n))
        mats[0] = start
        alive = np.array([readings[0] is not None, readings[1] is not None], dtype=np.int32)
        for r, m in enumerate(readings):
            if m is not None:
                mats[r + 1] = m
        st = np.array([state["nodes"], state["leaves"], int(state["stop"]), int(state["exhaustive"])], dtype=np.int32)
        before = st.copy()
        cap = LEAF_CAP
        dec = np.full((cap, max(k, 1)), -1, dtype=np.int8)
        how = np.zeros((cap, max(k, 1)), dtype=np.uint8)
        keys = np.zeros((cap, 4), dtype=np.int64)
        best = np.array(_ticks_key(state["best"]) if state["best"] != _NO_KEY else (_INF_TICKS,) * 4, dtype=np.int64)

        def ptr(x: np.ndarray) -> int:
            return int(x.ctypes.data)

        p = self._pointers
        if p is None:  # the search's own arrays, the same for every pass
            p = self._pointers = {name: ptr(x) for name, x in a.items()}
        rc = self.fn(n, k, self.z, ptr(mats), ptr(alive), p["earlier"], p["later"], p["gap"],
                     p["settled"], len(a["ends"]), p["ends"], len(a["src"]), p["src"], p["dst"],
                     p["wt"], len(a["act"]), p["act"], p["ctg"], p["xs"], p["ys"],
                     NODE_CAP, LEAF_CAP, int(self.has_bound), p["bound"], int(self.rank_by == "worst"),
                     int(prune), ptr(best), ptr(st), ptr(dec), ptr(how), ptr(keys))
        if rc != 0:
            return False
        state.update(nodes=int(st[0]), leaves=int(st[1]), stop=bool(st[2]), exhaustive=bool(st[3]))
        self.leaves = [(dec[i], how[i], _class_of_ticks(keys[i])) for i in range(int(before[1]), int(st[1]))]
        state["best"] = min([state["best"], *(pattern_key(cls, self.rank_by) for _, _, cls in self.leaves)])
        return True


def _ticks_key(key: tuple) -> tuple[int, ...]:
    """A `pattern_key` in integer ticks (infinite: the largest int64), as the C search compares keys."""
    return (int(key[0]), *(int(_INF_TICKS) if math.isinf(v) else round(v * TICKS_PER_SECOND) for v in key[1:4]))


def _class_of_ticks(row: np.ndarray) -> Classification:
    """The class and makespans of a C leaf, as the Python leaf (and ``classify(..., explained=False,
    full=False)``) gives them: its `pattern_key` is the key the Python leaf computes."""
    makespan = None if int(row[1]) == _INF_TICKS else (int(row[3]) / TICKS_PER_SECOND, int(row[2]) / TICKS_PER_SECOND)
    return Classification(CLASSES[int(row[0])], "", makespan, (), ())


def _search(task: Task, plan: Plan, routing: _Routing, rank_by: str, bound: tuple | None,
            incumbent: tuple | None = None, prune: bool = True) -> tuple[list[tuple[tuple, Leaf]], bool]:
    """Classified complete patterns for one choice of routes (best first; each with the function that
    builds its `PlanChoice`), and whether the search was exhaustive.

    Depth-first with propagation: at every node the conflicts whose order the network already implies
    are settled, those with one order left get it (and its edge), repeatedly, and a conflict with no
    order left ends the branch; only then does the search branch, on the first open conflict.

    A leaf is measured from the search's own matrices: beside the all-pairs distances of the network
    with the task's limits (which prune), it carries those of the network without them, with the human's
    durations free and fixed at their upper bounds (`classify`'s earliest and worst-case readings), each
    updated per added edge; the makespans are read off them and the class comes from the C core on index
    arrays. The same numbers as `classify` on the leaf's `STNU` (which ``rank_by="nominal"`` still uses,
    for its third reading), without building one per leaf.

    Branch and bound (`prune`): a node's matrices bound every leaf below it (adding edges only lengthens
    distances, and a DC leaf has a schedule with every human duration at its maximum), so a node whose
    bound (`_node_bound`) is no better than the best leaf so far, or than `incumbent` (the best pattern
    of another route choice), is cut without counting it towards the caps, and such a leaf is not
    classified. The best pattern is the one the search without pruning finds (ties keep the first
    found, which pruning never passes over); with the caps, it is reached within them more often.
    """
    motions, conflicts, base, index = routing.motions, routing.conflicts, routing.base, routing.index
    z = index[ORIGIN]
    namer = ref_namer(task, plan)
    fast = rank_by != "nominal"
    free = base.without_limits()
    warm = None if fast else earliest_start(free)  # each leaf's makespans: from here, incrementally
    edges = _Edges(base.stnu) if fast else None
    ends = np.array([index[t] for t in base.last_ends], dtype=int)
    k = len(conflicts)
    earlier, later, gap, implied = routing.orders  # per conflict and order; implied: holds in every execution
    settled = routing.settled
    first_of: list[int] = np.where(implied[:, 0], 0, 1).tolist()
    results: list[tuple[tuple, Leaf]] = []
    state: dict[str, Any] = {"nodes": 0, "leaves": 0, "stop": False, "exhaustive": True,
             "best": incumbent if incumbent is not None and prune and fast else _NO_KEY}
    # a node's matrices: with the limits (prunes), then without them, human durations free / at their
    # upper bounds (None once that reading has no schedule: more edges never give it one)
    Mats = tuple[np.ndarray, np.ndarray | None, np.ndarray | None]

    def add_one(mat: np.ndarray | None, e: int, lt: int, g: float, check: bool) -> np.ndarray | None:
        if mat is None or (check and mat[e, lt] - g < 0):
            return None  # the edge lt -> e of weight -g closes a negative cycle
        return np.minimum(mat, mat[:, lt:lt + 1] - g + mat[e:e + 1, :])

    def add(mats: Mats, j: int, o: int) -> Mats:
        e, lt, g = earlier[j, o], later[j, o], gap[j, o]
        top = add_one(mats[0], e, lt, g, False)
        assert top is not None
        if not fast:
            return top, None, None
        return top, add_one(mats[1], e, lt, g, True), add_one(mats[2], e, lt, g, True)

    def orders_of(how: dict[int, tuple[int, str]]) -> list[PassingOrder]:
        return [PassingOrder(c, ("robot", "human")[first_of[j] if settled[j] else how[j][0]],
                             "implied" if settled[j] else how[j][1]) for j, c in enumerate(conflicts)]

    def choice(how: dict[int, tuple[int, str]], cls: Classification) -> Leaf:
        """The leaf's `PlanChoice` with its class and makespans as the search measured them (what
        ``classify(..., explained=False, full=False)`` gives; `choose_pattern` classifies the one it keeps
        in full)."""
        def build() -> PlanChoice:
            # the links `_network` gives these orders, from the search's arrays (the same names and ticks)
            names = base.stnu.timepoints
            added = []
            for j in range(k):
                if not settled[j]:
                    o = how[j][0]
                    added.append(RequirementLink(names[earlier[j, o]], names[later[j, o]], int(gap[j, o]), None))
            return PlanChoice(MotionPattern(motions, tuple(orders_of(how)), 0, True), _with_links(base, tuple(added)),
                              cls)
        return build

    def native_choice(dec: np.ndarray, codes: np.ndarray, cls: Classification) -> Leaf:
        def build() -> PlanChoice:
            how = {int(j): (int(dec[j]), ("", "forced", "chosen")[codes[j]]) for j in np.flatnonzero(dec >= 0)}
            return choice(how, cls)()
        return build

    def span(mat: np.ndarray | None) -> int | None:
        if mat is None:
            return None
        return int(-mat[ends, z].min()) if len(ends) else 0

    def cut(mats: Mats) -> bool:
        """Whether no leaf below this node can beat the best so far (`_node_bound`)."""
        return prune and fast and _node_bound(span(mats[1]), span(mats[2]), rank_by) >= state["best"]

    def leaf(mats: Mats, how: dict[int, tuple[int, str]]) -> None:
        if cut(mats):
            return
        state["leaves"] += 1
        if fast:
            chosen = [(j, o) for j, (o, _) in how.items()]
            verdict = edges.verdict([int(later[j, o]) for j, o in chosen],  # type: ignore[union-attr]
                                    [int(earlier[j, o]) for j, o in chosen], [int(gap[j, o]) for j, o in chosen])
            if verdict is None:  # no C core: the whole check on the leaf's STNU
                plan_class = _VERDICT_CLASS[check_dc(_network(base, namer, orders_of(how)).stnu).verdict]
            else:
                plan_class = _CLASS_OF[verdict]
            early, late = span(mats[1]), span(mats[2])
            makespan = None if early is None else (early / TICKS_PER_SECOND,
                                                   (early if late is None else late) / TICKS_PER_SECOND)
            cls = Classification(plan_class, "", makespan, (), ())
            build = choice(how, cls)
        else:
            net, cls = _evaluate(task, base, namer, orders_of(how), rank_by, warm)
            build = choice(how, cls)
        key = pattern_key(cls, rank_by)
        results.append((key, build))
        if fast and key < state["best"]:
            state["best"] = key
        if bound is not None and key <= bound:
            state["stop"] = True  # nothing can beat the network without passing orders

    def dfs(mats: Mats, how: dict[int, tuple[int, str]]) -> None:
        if state["stop"]:
            return
        if state["nodes"] >= NODE_CAP or state["leaves"] >= LEAF_CAP:
            state["exhaustive"] = False
            return
        if cut(mats):
            return
        state["nodes"] += 1
        how = dict(how)
        while True:
            mat = mats[0]
            open_ = [j for j in range(k) if not settled[j] and j not in how]
            if not open_:
                leaf(mats, how)
                return
            idx = np.array(open_)
            holds = mat[later[idx], earlier[idx]] <= -gap[idx]  # (m, 2): already implied by what is decided
            fits = mat[earlier[idx], later[idx]] - gap[idx] >= 0  # (m, 2): adding it closes no negative cycle
            held, n_fit = holds.any(axis=1), fits.sum(axis=1)
            if np.any(~held & (n_fit == 0)):
                return  # they would block each other whatever is chosen: dead end
            for pos in np.flatnonzero(held):
                how[open_[pos]] = (0 if holds[pos, 0] else 1, "forced")
            unit = [(open_[pos], int(np.argmax(fits[pos]))) for pos in np.flatnonzero(~held & (n_fit == 1))]
            if unit:
                j, o = unit[0]  # one at a time: each edge may settle or forbid others
                mats = add(mats, j, o)
                how[j] = (o, "forced")
                continue
            rest = [j for j in open_ if j not in how]
            if rest:
                break
        j = rest[0]
        early = -mats[0][:, z]
        options = sorted((0, 1), key=lambda o: -(early[later[j, o]] - early[earlier[j, o]] - gap[j, o]))
        for o in options:  # first the order the earliest schedule is closer to
            dfs(add(mats, j, o), how | {j: (o, "chosen")})  # noqa: F821 (the name is emptied after the search)
            if state["stop"]:
                return

    # first among the patterns that meet the task's limits (pruned by them: a consistent plan is never
    # missed for a cap); only if there is none, among those that keep the two apart at all (inconsistent)
    readings: tuple[np.ndarray | None, np.ndarray | None] = (None, None)
    if fast:
        readings = (_apsp(free, "", after_origin=True), _apsp(free, "ub", after_origin=True))
    native = _NativeSearch.make(k, z, earlier, later, gap, settled, ends, edges, bound, rank_by) if fast else None
    for network in (base.stnu, free):  # the second pass's matrix only when the first found nothing
        start = _apsp(network)
        if start is not None:
            if native is not None and native.run(start, readings, state, prune):
                results += [(pattern_key(cls, rank_by), native_choice(dec, codes, cls))
                            for dec, codes, cls in native.leaves]
            else:
                native = None  # not built, or it failed: the Python search, from the same state
                dfs((start, *readings), {})
        if results or state["stop"] or not state["exhaustive"]:
            break
    # `dfs` refers to itself through its closure: a reference cycle that only the garbage collector would
    # free, holding the search's networks and arrays until then; emptying the name breaks it
    del dfs
    results.sort(key=lambda r: r[0])
    return results, bool(state["exhaustive"] or state["stop"])  # reaching the bound is as good as exhaustive


_NO_KEY = (math.inf,)  # worse than every key


def _node_bound(early: int | None, late: int | None, rank_by: str) -> tuple:
    """A key no leaf below a search node beats, from the node's spans (ticks) of the network without the
    task's limits with the human's durations free (`early`) and at their maxima (`late`; None once that
    reading has no schedule). Edges only lengthen distances, so a leaf's spans are at least the node's;
    a leaf whose upper-bound reading has no schedule is not DC (the human at maximum would break it) and
    measures its worst case as its earliest (`measure`), so it is bounded by class 1 and `early`."""
    if early is None:
        return (0, math.inf, math.inf, math.inf)
    e = round(early / TICKS_PER_SECOND, 6)
    if late is None:
        return (1, e, e, e)
    w = round(late / TICKS_PER_SECOND, 6)
    return (0, w if rank_by == "worst" else e, w, e)


def _bound(task: Task, routing: _Routing, rank_by: str, beat: tuple | None = None) -> tuple:
    """The key of the plan with these routes and no passing order at all: no pattern does better.

    With `beat`, the DC check is skipped when the makespans alone already show that the bound cannot
    beat that key (the class part of the returned key is then the best possible, 0)."""
    net = routing.base
    full = rank_by == "nominal"
    if beat is None:
        return pattern_key(classify(task, net, explained=False, full=full), rank_by)
    best_class = PlanClass.DC if _consistent(net.stnu) else PlanClass.INCONSISTENT
    measured = measure(task, net, best_class, full=full)
    cheap = pattern_key(measured, rank_by)
    if cheap >= beat:
        return cheap
    # what `classify(task, net, explained=False, full=full)` gives: the DC check's class, the same numbers
    return pattern_key(replace(measured, plan_class=_VERDICT_CLASS[check_dc(net.stnu).verdict]), rank_by)


def _beyond(routing: _Routing, rank_by: str, best: tuple) -> bool:
    """Whether the agents' chains alone (`_Routing.chain_bound`) show that no pattern with these routes
    beats `best`, a DC key (the check `_bound` would make, without building the network). For the worst
    case: a DC pattern fits every human duration at its maximum, so its worst-case makespan is at least
    the human's chain at maxima; a pattern that does not fit them is not DC, and loses to `best`."""
    return best[0] == 0 and round(routing.chain_bound(rank_by), 6) > best[1]


def _consistent(stnu: STNU) -> bool:
    """`check_consistency(stnu).consistent`, from the native core when it is built."""
    packed = packed_graph(stnu)
    found = None if packed is None else native_distances(len(stnu.timepoints), *packed, None)
    return check_consistency(stnu).consistent if found is None else found[0]


def _route_trials(task: Task, plan: Plan, paths: PathLibrary, human_waits: bool,
                  shortest: _Routing | None = None) -> list[Routes]:
    """Route choices to try besides the shortest routes, from the conflicts the plan does not settle
    anyway (those of the "robust" network):

    - detours: for each robot travel that meets the human, the way round those places, and round the
      places where the human stands only (a walking person passes, a standing one stays); then every
      leg's first way round together;
    - waiting places: where an agent would wait in the co-worker's way (a stay that meets the other), a
      stop at its own start instead, on each leg that leaves that stay (the human's only when the robot
      may time the human's steps, ``human_waits``); then every such leg of that agent together;
    - a reduced-speed zone, where the task's `safety` allows one: each robot travel that meets the human
      driven at the reduced speed (a smaller protective separation, so fewer and shorter conflicts, for
      a longer drive: ISO/TS 15066, 5.5.4), then every such leg together.
    """
    shortest = shortest or _Routing(task, plan, paths, {}, human_waits)
    motions = shortest.motions
    open_conflicts = [c for c, done in zip(shortest.conflicts, shortest.settled, strict=True) if not done]
    trials: list[Routes] = []
    # detours
    places: dict[tuple[str, int], list[Conflict]] = {}  # by robot (one per task but for issue 37's) and leg
    for c in open_conflicts:
        if c.robot.kind == "travel":
            places.setdefault((c.robot.agent, c.robot.leg), []).append(c)
    order = {a.id: n for n, a in enumerate(task.agents)}
    firsts: Routes = {}
    for (robot_id, leg), found in sorted(places.items(), key=lambda p: (order[p[0][0]], p[0][1])):
        m = next(m for m in motions if m.agent == robot_id and m.leg == leg)
        seen: set[tuple] = set()
        for group in (found, [c for c in found if c.human.kind == "stay"]):
            shapes = tuple(dict.fromkeys(c.shape for c in group))
            if not shapes or shapes in seen:
                continue
            seen.add(shapes)
            label = ", ".join(dict.fromkeys(c.human.describe() for c in group))
            path = detour(task, paths, robot_id, m.origin, m.target, shapes, label)
            if path is not None:
                trials.append({(robot_id, leg): Route(path)})
                firsts.setdefault((robot_id, leg), Route(path))
    if len(firsts) > 1:
        trials.append(firsts)
    reduced = task.safety.reduced_speed if task.safety is not None else None
    if reduced:
        slow: Routes = {(robot_id, leg): Route(paths.get(robot_id, m.origin, m.target), speed=reduced)
                        for robot_id, leg in sorted(places, key=lambda p: (order[p[0]], p[1]))
                        for m in motions if m.agent == robot_id and m.leg == leg}
        trials.extend({key: route} for key, route in slow.items())
        if len(slow) > 1:
            trials.append(slow)
    # waiting places
    every_park: Routes = {}
    for agent in task.agents:
        if agent.is_human and not human_waits:
            continue
        legs = agent_legs(task, plan, agent.id)
        stays = {(o.leg, o.finish.leg) for c in open_conflicts for o in (c.robot, c.human)
                 if o.agent == agent.id and o.kind == "stay" and o.finish.what == "depart"}
        parked: Routes = {}
        for stay_leg, depart_leg in sorted(stays):
            for j in range(stay_leg + 1, depart_leg + 1):
                lg = legs[j]
                if lg.origin == agent.start or lg.location == agent.start:
                    continue
                route = Route(paths.get(agent.id, lg.origin, agent.start), agent.start,
                              paths.get(agent.id, agent.start, lg.location))
                trials.append({(agent.id, j): route})
                parked[(agent.id, j)] = route
        if len(parked) > 1:
            trials.append(parked)
        every_park.update(parked)
    if len(every_park) > 1 and every_park not in trials:
        trials.append(every_park)  # both make way at once
    return trials


_BLOCKED = Classification(PlanClass.INCONSISTENT, "the co-workers would block each other: no order of passing "
                          "keeps them apart; its STNU file says so: it puts the plan's first event before the "
                          "start (Z), so that file alone checks inconsistent", None, (), ())


def _blocked(task: Task, plan: Plan) -> Classification:
    """`_BLOCKED`, naming the cause when it is a co-worker standing at a joint action's spot from the start
    (`hrc.motion.conflicts.joint_spot_starts`: the robot may not drive in to them, and they cannot leave
    before the joint phase, docs/motion.md, "Joint actions"); the first such pair, the plan's other
    blocks aside. Every other blocked plan keeps the words it had."""
    found = joint_spot_starts(task, plan)
    if not found:
        return _BLOCKED
    s = found[0]
    why = (f"the co-workers would block each other: {s.agent} stands at {s.spot} from the start until "
           f"{s.action}.{s.phase} ends, and {s.robot} must drive to {s.spot} for that joint action; at a joint spot "
           f"the robot arrives first and never drives within reach of someone standing there, so no order of "
           f"passing lets {s.robot} in (with a start out of reach of {s.robot}'s way to {s.spot}, {s.agent} would "
           f"walk up after it); its STNU file says so: it puts the plan's first event before the start (Z), so "
           f"that file alone checks inconsistent")
    return replace(_BLOCKED, explanation=why)


def choose_pattern(task: Task, plan: Plan, paths: PathLibrary, human_waits: bool = True,
                   rank_by: str = "worst") -> PlanChoice:
    """The plan's best motion pattern, its STNU and its classification (see the module docstring). The
    network's words (`PlanNetwork.meaning`) name its passing orders only when the plan is not DC: they
    are read only to explain a class, and a DC plan has none to explain."""
    if rank_by not in RANK_BY:
        raise ValueError(f"rank_by must be one of {RANK_BY}, got {rank_by!r}")
    shortest = _Routing(task, plan, paths, {}, human_waits)
    bound = _bound(task, shortest, rank_by)
    results, exhaustive = _search(task, plan, shortest, rank_by, bound)
    count = len(results)
    best_key, best = results[0] if results else ((math.inf,), None)  # best: builds the kept choice
    if best_key > bound:  # a detour or a waiting place may do better than waiting in the way
        trials = [_Routing(task, plan, paths, routes, human_waits)
                  for routes in _route_trials(task, plan, paths, human_waits, shortest)]
        bounded = [(_bound(task, routing, rank_by, best_key), i, routing) for i, routing in enumerate(trials)
                   if not _beyond(routing, rank_by, best_key)]  # those would sort after every one tried
        bounded.sort(key=lambda b: (b[0], b[1]))  # the most promising first
        tried = 0
        for bound, _, routing in bounded:
            if bound >= best_key:
                break  # neither this nor any later one can beat what we have
            if any(r.speed for r in routing.routes.values()):
                tried -= 1  # a reduced-speed trial does not take a detour's or a waiting place's turn
            tried += 1
            if tried > TRIAL_CAP and best is not None:  # the cap bounds the search for a better pattern;
                exhaustive = False                      # while there is none at all, every route is tried
                break
            more, full = _search(task, plan, routing, rank_by, bound, best_key if best is not None else None)
            count += len(more)
            exhaustive = exhaustive and full
            if more and more[0][0] < best_key:
                best_key, best = more[0]
    if best is None:
        # the co-workers block each other whatever the order and route: no schedule keeps them apart
        return PlanChoice(MotionPattern(shortest.motions, (), count, exhaustive), shortest.base, _blocked(task, plan))
    kept = best()
    pattern = kept.pattern
    found = MotionPattern(pattern.motions, pattern.orders, count, exhaustive, _meetings(task, plan, paths, pattern))
    if kept.classification.plan_class is PlanClass.DC:
        # the search's verdict (on the same links): measured in full, nothing to explain, so no words
        return PlanChoice(found, kept.net, classify(task, kept.net, known=DCResult(Verdict.DC, True)))
    net = _worded(task, plan, kept.net, pattern.orders)
    check = check_dc(net.stnu)  # again, for the negative cycle that the explanation reads
    return PlanChoice(found, net, classify(task, net, known=check), check)


def _meetings(task: Task, plan: Plan, paths: PathLibrary, pattern: MotionPattern) -> tuple[Conflict, ...]:
    """`people_meetings` on the pattern's routes (a person's are the shortest, or a stop at a waiting
    place, `_route_trials`); () with fewer than two people, without looking."""
    if sum(a.is_human for a in task.agents) < 2:
        return ()
    humans = {a.id for a in task.agents if a.is_human}
    routes: Routes = {(m.agent, m.leg): Route(paths.get(m.agent, m.origin, m.park), m.park,
                                              paths.get(m.agent, m.park, m.target))
                      for m in pattern.motions if m.agent in humans and m.park}
    return people_meetings(task, plan, paths, routes)


def apply_pattern(task: Task, plan: Plan, pattern: MotionPattern, human_waits: bool = True,
                  known: DCResult | None = None) -> PlanChoice:
    """`plan` carried out with another plan's `pattern`, classified in full: for a plan of the same family
    (`hrc.plans.plan_families`: the same up to the names of identical actions), whose search would find
    that very pattern, since motion patterns name legs and places, never actions. `known`: the DC check's
    result on the plan's STNU, if known (`classify`)."""
    net = pattern_network(task, plan, pattern, human_waits)
    if pattern.candidates == 0:  # no pattern at all: the co-workers block each other (`choose_pattern`)
        return PlanChoice(pattern, net, _blocked(task, plan))
    return PlanChoice(pattern, net, classify(task, net, known=known))


def pattern_network(task: Task, plan: Plan, pattern: MotionPattern, human_waits: bool = True) -> PlanNetwork:
    """`plan`'s network with `pattern` (`apply_pattern`'s, before classifying): its passing orders with
    their words; without any when the pattern has none at all (the co-workers block each other)."""
    base = create_stnu(task, plan, pattern.motions, (), human_waits)
    if pattern.candidates == 0:
        return base
    return _worded(task, plan, _network(base, ref_namer(task, plan), list(pattern.orders)), pattern.orders)
