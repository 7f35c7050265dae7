"""Classify and measure one plan's STNU: DC > consistent > inconsistent (Strassmair & Taylor, V.B).

What the classes promise (the report says it in the same words):

- **DC**: the robot alone can meet every constraint (deadline, temporal constraints, passing orders)
  whatever the human's durations within their bounds, deciding as it observes them;
- **consistent**: some timing of the team meets every constraint, but the robot cannot guarantee it
  alone: it depends on the human's durations (the explanation names the ones that matter);
- **inconsistent**: no timing meets every constraint even with every duration at its best; the plan is
  still the instruction for finishing the task (late), so it is kept and ranked last.

Besides the class, ranking needs the plan's makespan and idle times, computed without the task's limits
(deadline, temporal constraints: a plan that breaks them still has a makespan) but with every structural
link and passing order, from the schedule in which every timepoint is as early as possible:

- ``makespan[0]``, the earliest: every human duration as short as allowed;
- ``makespan[1]``, the worst case: every human duration at its upper bound, the robot as early as it can;
- ``nominal``: every human duration at the middle of its bounds.

If the structural links alone conflict (the co-workers would block each other whatever they do) there
is no schedule: makespans are None. Idle time of an agent, in the earliest schedule: the part of
``[0, makespan]`` in which it is neither travelling nor manipulating (waiting for the co-worker or for a
passing order, or done early).
"""

from __future__ import annotations

import enum
import functools
import operator
from array import array
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Literal

from hrc.caches import make_room
from hrc.compile.temporal_net_creator import ORIGIN, TICKS_PER_SECOND, PlanNetwork
from hrc.model import Task
from hrc.temporal import STNU, DCResult, RequirementLink, Verdict, check_dc
from hrc.temporal.native_stn import MAX_NODES, MAX_WEIGHT, native_distances
from hrc.temporal.network import lineage
from hrc.temporal.rul import bound_edges, edge_arrays, spliced

__all__ = ["CLASSES", "Classification", "EarliestStart", "PlanClass", "classify", "distance_graph", "earliest_start",
           "explain", "measure", "packed_graph", "packed_lower_bounds", "renamed",
           "slowest_makespan"]


class PlanClass(enum.Enum):
    """The three classes of section V.B, best first."""

    DC = "DC"
    CONSISTENT = "consistent"
    INCONSISTENT = "inconsistent"

    @property
    def order(self) -> int:
        """0, 1, 2: best first (a lookup: listing an enum's members costs microseconds, and every rank key
        and search leaf asks)."""
        return _CLASS_ORDER[self]


_CLASS_ORDER = {c: i for i, c in enumerate(PlanClass)}
CLASSES = tuple(PlanClass)
"""The classes best first (``CLASSES[c.order] is c``)."""


@dataclass(frozen=True, slots=True)
class Classification:
    plan_class: PlanClass
    explanation: str  # "" for DC plans
    makespan: tuple[float, float] | None  # s, (earliest, worst case); None when there is no schedule
    idle: tuple[tuple[str, float], ...]  # (agent, s) in the earliest schedule
    schedule: tuple[tuple[str, float], ...]  # earliest time (s) of every timepoint, in STNU order
    worst_schedule: tuple[tuple[str, float], ...] = ()  # the same with every human duration at its maximum
    nominal: float | None = None  # makespan (s) with every human duration at its midpoint
    class_at_delay_0: PlanClass | None = None  # under a stated sensing (`hrc.compile.sensing`): the class at 0


Fix = Literal["", "ub", "mid"]


def _into(stnu: STNU, fix: Fix = "", requirements: tuple[RequirementLink, ...] | None = None,
          with_origin: bool = True) -> dict[str, list[tuple[str, int]]]:
    """The distance graph by target: ``target -> [(source, weight)]`` (``T(target) - T(source) <= w``),
    contingent durations free (``fix=""``) or fixed at their upper bound or midpoint (``//2``); with
    `with_origin` an edge ``x -> origin`` of weight 0 for every timepoint (each comes at or after it)."""
    into: dict[str, list[tuple[str, int]]] = {t: [] for t in stnu.timepoints}
    for r in stnu.requirements if requirements is None else requirements:
        if r.ub is not None:
            into[r.target].append((r.source, r.ub))
        if r.lb is not None:
            into[r.source].append((r.target, -r.lb))
    if requirements is None:
        for c in stnu.contingents:
            lb, ub = c.lb, c.ub
            if fix:
                lb = ub = c.ub if fix == "ub" else (c.lb + c.ub) // 2
            into[c.target].append((c.source, ub))
            into[c.source].append((c.target, -lb))
    if with_origin:
        into[ORIGIN].extend((t, 0) for t in stnu.timepoints if t != ORIGIN)
    return into


def _relax(into: dict[str, list[tuple[str, int]]], extra: dict[str, list[tuple[str, int]]], n: int,
           dist: dict[str, int], hops: dict[str, int], queue: deque[str]) -> bool:
    """Queue-based Bellman-Ford towards the origin (`dist`: ``d(x, origin)``, updated in place) from the
    queued timepoints; False on a negative cycle (a shortest walk of `n` or more edges)."""
    queued = set(queue)
    while queue:
        v = queue.popleft()
        queued.discard(v)
        dv = dist[v]
        hv = hops[v] + 1
        for edges in (into[v], extra.get(v, ())):
            for u, w in edges:  # edge u -> v of weight w: d(u, origin) <= w + d(v, origin)
                du = dist.get(u)
                if du is None or w + dv < du:
                    dist[u] = w + dv
                    hops[u] = hv
                    if hv >= n:
                        return False
                    if u not in queued:
                        queued.add(u)
                        queue.append(u)
    return True


def _earliest(stnu: STNU, fix: Fix = "") -> dict[str, int] | None:
    """Earliest time (ticks) of every timepoint of `stnu` after its origin, or None if inconsistent, with
    every contingent duration free (``fix=""``) or fixed at its upper bound or midpoint (``//2``).

    ``-d(x, origin)`` by a queue-based Bellman-Ford, every timepoint at or after the origin (the algorithm
    of `hrc.temporal.stn.earliest_times`), in the native core (`hrc.temporal.native_stn`) on the network's
    index arrays (`edge_arrays`); without the core, `_earliest_python`. The distances are unique, so both
    give the same numbers (a test compares them).
    """
    times = _earliest_values(stnu, fix)
    return None if times is None else dict(zip(stnu.timepoints, times, strict=True))


def _earliest_values(stnu: STNU, fix: Fix = "") -> list[int] | None:
    """`_earliest`'s times in timepoint order."""
    graph = packed_graph(stnu, fix, after_origin=True)
    found = None if graph is None else native_distances(len(stnu.timepoints), *graph, stnu.timepoints.index(ORIGIN))
    if found is None:
        times = _earliest_python(stnu, fix)
        return None if times is None else [times[t] for t in stnu.timepoints]
    ok, dist = found
    return [-d for d in dist] if ok else None


def slowest_makespan(stnu: STNU, agents: Sequence[str], robots: frozenset[str] | set[str]) -> float | None:
    """The makespan (s) of `stnu`'s earliest schedule with *every* duration at its maximum: the human's
    (contingent links) as in ``makespan[1]``, and also each robot's travel and manipulation (its requirement
    links ``R.PHASE.ACTION.depart -> .arrive`` and ``.start -> .end`` of robot ``R``, bounded both ways),
    which ``makespan[1]`` takes at their minimum ("the robot as early as it can"). A robot that works and
    drives anywhere within its bounds, dispatched as early as its windows allow, ends by then: the longest
    paths from the origin only grow with any link's lower bound. The task's deadline (links from the origin
    with no lower bound) is left out, as ``without_limits`` does; None when the rest conflicts.

    Timepoints are named as `create_stnu` names them or as the GraphML writes them (``_`` for ``.``):
    `agents` (every agent id) tell whose a timepoint is, the longest id first. Read by the simulator's
    summary (`hrc.sim.montecarlo.separation_summary`): a run whose robots drew their durations within their
    bounds may end after ``makespan[1]`` with every link kept (run 33 of kitting_2robots_iso: robot2's
    fetch 0.48 s over its minimum, the person's passing order after it)."""
    ids = sorted(agents, key=len, reverse=True)

    def split(name: str) -> tuple[str | None, str, str]:
        owner = next((a for a in ids if name[len(a):len(a) + 1] in (".", "_") and name.startswith(a)), None)
        cut = max(name.rfind("."), name.rfind("_"))
        return owner, name[:cut], name[cut + 1:]

    def duration(a: str, b: str) -> bool:  # a robot's depart -> arrive or start -> end
        (agent, base_a, what_a), (_, base_b, what_b) = split(a), split(b)
        return agent in robots and base_a == base_b and (what_a, what_b) in (("depart", "arrive"), ("start", "end"))

    # the bounds may come as one link or as two one-sided ones (``T(end) - T(start) <= u`` and
    # ``T(start) - T(end) <= -l``, as the GraphML has them): the maximum first, then every lower bound on it
    most: dict[tuple[str, str], int] = {}
    for r in stnu.requirements:
        if r.ub is not None and duration(r.source, r.target):
            most[r.source, r.target] = min(r.ub, most.get((r.source, r.target), r.ub))
    reqs = []
    for r in stnu.requirements:
        if r.source == ORIGIN and (r.lb is None or r.lb <= 0) and r.ub is not None:
            continue  # a deadline
        if (r.source, r.target) in most:
            r = RequirementLink(r.source, r.target, most[r.source, r.target], r.ub)
        elif (r.target, r.source) in most and r.ub is not None:
            r = RequirementLink(r.source, r.target, r.lb, -most[r.target, r.source])
        reqs.append(r)
    times = _earliest_values(STNU(stnu.timepoints, tuple(reqs), stnu.contingents, stnu.name), "ub")
    if times is None:
        return None
    ends = [t for name, t in zip(stnu.timepoints, times, strict=True) if split(name)[2] == "end"]
    return max(ends, default=0) / TICKS_PER_SECOND


def distance_graph(stnu: STNU, fix: Fix = "", after_origin: bool = False) -> tuple[list[int], list[int], list[int]]:
    """`stnu`'s distance graph as index arrays (``T(dst[i]) - T(src[i]) <= wt[i]``, timepoints by position,
    from `edge_arrays`), contingent durations free (``fix=""``) or fixed at their upper bound or midpoint;
    with `after_origin` an edge ``x -> origin`` of weight 0 for every timepoint (each comes at or after
    it). What the native core's shortest paths take (`hrc.temporal.native_stn`)."""
    src, dst, wt, act, ctg, xs, ys = edge_arrays(stnu)
    if fix:
        xs = ys = ys if fix == "ub" else [(x + y) // 2 for x, y in zip(xs, ys, strict=True)]
    src, dst, wt = src + act + ctg, dst + ctg + act, wt + ys + [-x for x in xs]
    if after_origin:
        n = len(stnu.timepoints)
        src, dst, wt = src + list(range(n)), dst + [stnu.timepoints.index(ORIGIN)] * n, wt + [0] * n
    return src, dst, wt


_Packed = tuple[array, array, array, array, array, array, array, array]  # src dst wt act ctg -xs ys -ys
_PACKED: dict[int, tuple[STNU, _Packed | None]] = {}  # by identity, the last few (each kept alive here)


def packed_graph(stnu: STNU, fix: Fix = "", after_origin: bool = False) -> tuple[array, array, array] | None:
    """`distance_graph` as the native core's typed arrays (`hrc.temporal.native_stn`), without the
    origin's edge to itself (which changes no distance); None when the network has a requirement link
    from a timepoint to itself or numbers too large for the core (the caller then takes the lists).

    A network is read several times over (consistency, schedules, distance matrices): its links are
    packed once (the last few networks are kept, by identity) and each reading is a few array copies."""
    packed = _packed(stnu)
    if packed is None:
        return None
    src, dst, wt, act, ctg, neg_xs, ys, neg_ys = packed
    if fix == "mid":
        xs, ys_list = edge_arrays(stnu)[5:7]
        mid = [(x + y) // 2 for x, y in zip(xs, ys_list, strict=True)]
        up, down = array("q", mid), array("q", [-m for m in mid])
    else:
        up, down = ys, (neg_ys if fix == "ub" else neg_xs)
    src, dst, wt = src + act + ctg, dst + ctg + act, wt + up + down
    if after_origin:
        others, origin, zeros = _to_origin(len(stnu.timepoints), stnu.timepoints.index(ORIGIN))
        src, dst, wt = src + others, dst + origin, wt + zeros
    return src, dst, wt


def packed_lower_bounds(stnu: STNU) -> tuple[array, array, array] | None:
    """`packed_graph`'s edges with each contingent duration bounded below only (at least its lower
    bound, however long: what holds even if the human breaks the plan's upper bounds); None as for
    `packed_graph`."""
    packed = _packed(stnu)
    if packed is None:
        return None
    src, dst, wt, act, ctg, neg_xs, _, _ = packed
    return src + ctg, dst + act, wt + neg_xs


@functools.lru_cache(maxsize=64)
def _to_origin(n: int, z: int) -> tuple[array, array, array]:
    """The edges ``x -> z`` of weight 0 for every other x (never changed: only ever concatenated)."""
    others = array("i", [i for i in range(n) if i != z])
    return others, array("i", [z]) * len(others), array("q", bytes(8 * len(others)))


def _packed(stnu: STNU) -> _Packed | None:
    """`_pack` of `stnu`, kept for the last few networks (by identity); for a network derived from a kept
    one (`lineage`), the parent's arrays cut and spliced (`_derived_pack`)."""
    hit = _PACKED.get(id(stnu))
    if hit is None or hit[0] is not stnu:
        packed = _derived_pack(stnu)
        hit = _keep_packed(stnu, _pack(stnu) if packed is None else packed)
    return hit[1]


def _keep_packed(stnu: STNU, packed: _Packed | None) -> tuple[STNU, _Packed | None]:
    make_room(_PACKED, 16)
    hit = _PACKED[id(stnu)] = (stnu, packed)
    return hit


def _derived_pack(stnu: STNU) -> _Packed | None:
    """`_pack` of a network derived from one whose packing is kept (`lineage`): the parent's edges up to
    the cut, the new links' edges (checked as `_pack` checks all), then the parent's others if kept; None
    when there is no such parent or a new edge is one `_pack` refuses (it then decides)."""
    origin = lineage(stnu)
    if origin is None:
        return None
    parent, at, links, rest = origin
    hit = _PACKED.get(id(parent))
    if hit is None or hit[0] is not parent:  # the parent itself derived from a kept one (or not)
        derived = _derived_pack(parent)
        if derived is None:
            return None
        _keep_packed(parent, derived)
        hit = (parent, derived)
    if hit[1] is None:
        return None
    new = bound_edges(links, {v: i for i, v in enumerate(stnu.timepoints)} if links else {})
    try:
        added = (array("i", new[0]), array("i", new[1]), array("q", new[2]))
    except OverflowError:  # beyond 64 bits
        return None
    if not _core_takes(*added):
        return None
    return (*spliced(hit[1][:3], parent, at, added, rest), *hit[1][3:])  # type: ignore[return-value]


def _core_takes(src: array, dst: array, wt: array) -> bool:
    """Whether the native core takes these edges: no edge from a timepoint to itself, every weight
    within `MAX_WEIGHT`. (Plain Python: a network has a few dozen to a few hundred links, where numpy's
    calls cost more than the loops.)"""
    if wt and (max(wt) >= MAX_WEIGHT or min(wt) <= -MAX_WEIGHT):
        return False
    return not any(map(operator.eq, src, dst))


def _pack(stnu: STNU) -> _Packed | None:
    src, dst, wt, act, ctg, xs, ys = edge_arrays(stnu)
    if len(stnu.timepoints) >= MAX_NODES:
        return None
    try:
        packed = (array("i", src), array("i", dst), array("q", wt), array("i", act), array("i", ctg),
                  array("q", [-x for x in xs]), array("q", ys), array("q", [-y for y in ys]))
    except OverflowError:  # beyond 64 bits
        return None
    if not _core_takes(*packed[:3]) or max(ys, default=0) >= MAX_WEIGHT:
        return None
    return packed


def _earliest_python(stnu: STNU, fix: Fix = "") -> dict[str, int] | None:
    """`_earliest` in Python (the reference, and the fallback without the native core): read straight off
    the links instead of building edge objects and a fixed copy of the network."""
    dist, hops = {ORIGIN: 0}, {ORIGIN: 0}
    if not _relax(_into(stnu, fix), {}, len(stnu.timepoints), dist, hops, deque([ORIGIN])):
        return None
    return {t: -dist[t] for t in stnu.timepoints}


@dataclass(frozen=True, slots=True)
class EarliestStart:
    """A network's distances to the origin, per way of reading the human's durations (`Fix`), from which
    the same network with more requirement links is measured incrementally (`measure`'s `start`).

    A search classifies many networks that differ from one base only by a few passing orders; adding
    links only shortens distances, so Bellman-Ford started from the base's distances with the new
    links' targets queued ends at the same (unique) shortest distances, or finds the negative cycle,
    after a few relaxations instead of a whole run. Read only after `earliest_start` builds it.
    """

    stnu: STNU
    into: tuple[tuple[str, dict[str, list[tuple[str, int]]]], ...]
    dist: tuple[tuple[str, dict[str, int] | None], ...]
    hops: tuple[tuple[str, dict[str, int]], ...]

    def earliest(self, net: PlanNetwork, fix: Fix) -> dict[str, int] | None:
        """`_earliest` of ``net.without_limits()`` (built only if it does not extend this base by
        requirement links at its end: a search's networks do, and are measured without building it)."""
        base = self.stnu
        s = net.stnu
        reqs = s.requirements[:len(s.requirements) - net.n_limits]
        k = len(base.requirements)
        dists = dict(self.dist)
        same = (fix in dists and s.timepoints == base.timepoints and s.contingents == base.contingents
                and len(reqs) >= k and all(map(operator.is_, reqs, base.requirements)))
        if not same:  # not an extension of the base (checked by identity of the links: cheap)
            return _earliest(net.without_limits(), fix)
        d0 = dists[fix]
        if d0 is None:
            return None  # the base is inconsistent already, and more links cannot mend it
        extra = _into(s, fix, reqs[k:], with_origin=False)
        dist, hops = dict(d0), dict(dict(self.hops)[fix])
        queue = deque(t for t in s.timepoints if extra[t])
        if not _relax(dict(self.into)[fix], extra, len(s.timepoints), dist, hops, queue):
            return None
        return {t: -dist[t] for t in s.timepoints}


def earliest_start(free: STNU, fixes: tuple[Fix, ...] = ("", "ub")) -> EarliestStart:
    """The `EarliestStart` of `free` (a network without the task's limits) for the readings `fixes`."""
    into, dist, hops = [], [], []
    for fix in fixes:
        adj = _into(free, fix)
        d, h = {ORIGIN: 0}, {ORIGIN: 0}
        ok = _relax(adj, {}, len(free.timepoints), d, h, deque([ORIGIN]))
        into.append((fix, adj))
        dist.append((fix, d if ok else None))
        hops.append((fix, h))
    return EarliestStart(free, tuple(into), tuple(dist), tuple(hops))


def _controlled(stnu: STNU, names: set[tuple[str, str]]) -> STNU:
    """`stnu` with the contingent links in `names` turned into requirement links (the robot decides)."""
    keep = tuple(c for c in stnu.contingents if (c.source, c.target) not in names)
    extra = tuple(RequirementLink(c.source, c.target, c.lb, c.ub) for c in stnu.contingents
                  if (c.source, c.target) in names)
    return STNU(stnu.timepoints, stnu.requirements + extra, keep, stnu.name)


def _links_that_matter(stnu: STNU, cycle: tuple) -> list[tuple[str, str]]:
    """A minimal set of contingent links whose control by the robot would make `stnu` DC.

    Starts from the contingent links the negative cycle runs through; while the network with those under
    control is still not DC, adds the links of the cycle its check finds next (a plan may fail in more
    than one way). Then a deletion filter: a link stays only if the network is not DC without it under
    control. So the links named are enough, and none of them can be left out. O(k) DC checks for k links.
    """
    def on(cyc: tuple) -> set[tuple[str, str]]:
        return {(e.source, e.target) for e in cyc} | {(e.target, e.source) for e in cyc}

    order = [(c.source, c.target) for c in stnu.contingents]
    chosen: set[tuple[str, str]] = set()
    found = on(cycle)
    while True:
        more = {k for k in order if k in found} - chosen
        if not more:
            break  # the cycle runs through no link left to control: keep what we have
        chosen |= more
        result = check_dc(_controlled(stnu, chosen))
        if result.is_dc:
            break
        found = on(result.cycle)
    if not chosen or not check_dc(_controlled(stnu, chosen)).is_dc:
        return [k for k in order if k in chosen]
    needed = [k for k in order if k in chosen]
    for link in list(needed):
        trial = [x for x in needed if x != link]
        if check_dc(_controlled(stnu, set(trial))).is_dc:
            needed = trial
    return needed


def explain(net: PlanNetwork, cycle: tuple, inconsistent: bool) -> str:
    """Say in words what a negative cycle (from the DC or consistency check) runs through.

    Not DC: which limits cannot be guaranteed, and the few human durations that matter (those whose
    control by the robot would make it DC). Inconsistent: which limits cannot be met even with every
    duration at its shortest, and what the cycle runs through.
    """
    meaning = dict(net.meaning)
    position = {t: i for i, t in enumerate(net.stnu.timepoints)}
    seen: dict[str, set[tuple[int, str]]] = {"human": set(), "robot": set(), "limit": set(), "order": set(),
                                             "space": set()}
    for edge in cycle:
        key = (edge.source, edge.target) if (edge.source, edge.target) in meaning else (edge.target, edge.source)
        if key in meaning:
            kind, text = meaning[key]
            seen[kind].add((min(position[key[0]], position[key[1]]), text))
    # in timeline order (STNU order), whatever node the checker's cycle happened to start from
    found = {kind: list(dict.fromkeys(text for _, text in sorted(items))) for kind, items in seen.items()}
    limits = "; ".join(found["limit"]) or "the plan's ordering"
    if not inconsistent:
        matter = _links_that_matter(net.stnu, cycle)
        texts = [meaning[k][1] for k in sorted(matter, key=lambda k: (position[k[0]], position[k[1]]))]
        durations = "; ".join(texts) or "the human's durations"
        return f"{limits} cannot be guaranteed by the robot alone if the human takes long on: {durations}"
    durations = "; ".join(found["human"] + found["robot"] + found["space"]) or "the plan's durations"
    return f"{limits} cannot be met even at the shortest: {durations}"


def classify(task: Task, net: PlanNetwork, explained: bool = True, full: bool = True,
             start: EarliestStart | None = None, known: DCResult | None = None) -> Classification:
    """Class (DC check), explanation, makespans, idle times and the earliest and worst-case schedules.

    `explained=False` leaves the explanation empty (it costs a few more DC checks for a consistent plan);
    `full=False` only the class and the makespans (`measure`): a search over candidate networks
    explains and measures in full only the one it keeps; `start` makes measuring incremental (`measure`).
    `known`: the DC check's result on ``net.stnu``, if already known (the check is then not run again).
    """
    result = known if known is not None else check_dc(net.stnu)
    explanation = ""
    if result.verdict is Verdict.DC:
        plan_class = PlanClass.DC
    elif result.verdict is Verdict.NOT_DC:
        plan_class = PlanClass.CONSISTENT
        if explained:
            explanation = explain(net, result.cycle, inconsistent=False)
    else:
        plan_class = PlanClass.INCONSISTENT
        if explained:
            explanation = explain(net, result.cycle, inconsistent=True)

    out = measure(task, net, plan_class, explanation, full, start)
    if out.makespan is None and explained and not explanation.startswith("the plan's ordering"):
        out = Classification(plan_class, _BLOCKED + explanation, None, (), ())
    return out


_NO_FIT = " (no schedule fits every human duration at its maximum)"  # `measure` adds it to an explanation
_BLOCKED = "the co-workers would block each other: no timing keeps them apart; "  # `classify` puts it first


def renamed(c: Classification, names: Mapping[str, str], net: PlanNetwork, result: DCResult) -> Classification:
    """What ``classify(task, net, known=result)`` gives for `net`, a network that the one `c` classifies
    (in full, explained) renames by `names`, and `result` the DC check's result on `net`: the same class
    and numbers (the checks and schedules work on timepoints in network order, which renaming keeps),
    the schedules renamed, and the explanation said again in `net`'s words (its links' meanings name
    actions). `measure`'s note on the worst case is read off `c`'s explanation, which ends with it
    exactly when `measure` added it (no link's meaning ends so)."""
    explanation = ""
    if c.plan_class is not PlanClass.DC:
        explanation = explain(net, result.cycle, inconsistent=c.plan_class is PlanClass.INCONSISTENT)
    if c.makespan is None:
        if not explanation.startswith("the plan's ordering"):
            explanation = _BLOCKED + explanation
        return Classification(c.plan_class, explanation, None, (), ())
    if explanation and c.explanation.endswith(_NO_FIT):
        explanation += _NO_FIT
    return Classification(c.plan_class, explanation, c.makespan, c.idle,
                          tuple((names[t], v) for t, v in c.schedule),
                          tuple((names[t], v) for t, v in c.worst_schedule), c.nominal)


def measure(task: Task, net: PlanNetwork, plan_class: PlanClass, explanation: str = "",
            full: bool = True, start: EarliestStart | None = None) -> Classification:
    """The makespans, idle times and schedules of `net` (see the module docstring), with the class given.

    `full=False`: the earliest and worst-case makespans only (no nominal one, idle times or schedules).
    `start`: the `EarliestStart` of a network that ``net.without_limits()`` extends by requirement links
    at its end (the same numbers, found incrementally).
    """
    names = net.stnu.timepoints
    if start is not None:  # a search's leaf (`full` False): by name, from the search's start
        got = start.earliest(net, "")
        early = None if got is None else [got[t] for t in names]
    else:
        early = _earliest_values(net.without_limits(), "")
    if early is None:
        return Classification(plan_class, explanation, None, (), ())
    # with the human's durations fixed the rest may not fit (a passing order that a slow person breaks):
    # the worst case then falls back to the earliest schedule, and the explanation says so
    if start is not None:
        got = start.earliest(net, "ub")
        late = None if got is None else [got[t] for t in names]
    else:
        late = _earliest_values(net.without_limits(), "ub")
    if late is None:
        late = early
        if explanation:
            explanation += _NO_FIT
    layout = _layout(names, net.last_ends, tuple(a.id for a in task.agents))

    def span(times: list[int]) -> int:
        return max((times[i] for i in layout.ends), default=0)

    end = span(early)
    makespan = (end / TICKS_PER_SECOND, span(late) / TICKS_PER_SECOND)
    if not full:
        return Classification(plan_class, explanation, makespan, (), ())
    middle = _earliest_values(net.without_limits(), "mid") or early
    idle = tuple((agent, (end - sum(early[b] - early[a] for a, b in pairs)) / TICKS_PER_SECOND)
                 for agent, pairs in layout.busy)
    return Classification(plan_class, explanation, makespan, idle, _seconds(early, names), _seconds(late, names),
                          span(middle) / TICKS_PER_SECOND)


def _seconds(times: list[int], names: tuple[str, ...]) -> tuple[tuple[str, float], ...]:
    return tuple(zip(names, [t / TICKS_PER_SECOND for t in times], strict=True))


@dataclass(frozen=True, slots=True)
class _Layout:
    """Where `measure` reads a network's schedule: the positions of the agents' last ends, and per agent
    the (from, to) positions of its travels (depart -> arrive) and manipulations (start -> end)."""

    ends: tuple[int, ...]
    busy: tuple[tuple[str, tuple[tuple[int, int], ...]], ...]


@functools.lru_cache(maxsize=256)
def _layout(names: tuple[str, ...], last_ends: tuple[str, ...], agents: tuple[str, ...]) -> _Layout:
    """`_Layout` of a network's timepoints (remembered: a plan's route choices mostly share them).

    An agent is busy from each of its ``.depart`` to the matching ``.arrive`` and from each ``.start``
    to its ``.end`` (timepoints named ``AGENT.PHASE.ACTION.WHAT``, `leg_timepoint`): its idle time is
    the makespan less those."""
    position = {t: i for i, t in enumerate(names)}
    busy = []
    for agent in agents:
        pairs = []
        for name in names:
            if not name.startswith(agent + "."):
                continue
            base, what = name.rsplit(".", 1)
            if what == "arrive":
                pairs.append((position[base + ".depart"], position[name]))
            elif what == "end":
                pairs.append((position[base + ".start"], position[name]))
        busy.append((agent, tuple(pairs)))
    return _Layout(tuple(position[t] for t in last_ends), tuple(busy))
