"""Real-time execution of an STNU: where a partial execution stands, and when a timepoint may go next.

Given an STNU, the timepoints executed so far with their times and the current time ``now`` (integer
ticks), `real_time_state` tells whether the rest is still DC (its *residual network*, below, checked by
`check_dc`) and, for an unexecuted executable timepoint X (`RealTimeState.step`), either

* an `ExecutionWindow` ``[earliest, latest]``: if nothing else is executed or observed before tick t,
  executing X at any t in the window keeps the rest DC; or
* `MustWait`: X cannot go before the named timepoints have happened (a contingent timepoint the agent
  has to see first, or an executable one that has to go first).

**The residual network** (`residual_network`): the rest of the execution as an STNU with a new origin O
(``RESIDUAL_ORIGIN``) at time 0, whose links mean:

* every executed X is pinned: ``t(X) <= T(X) - T(O) <= t(X)``;
* a link between two executed timepoints is history, left out (`violated_links` lists those history
  broke); so is a contingent link whose contingent timepoint has been observed;
* a contingent link in progress (activation executed at ``a``, contingent timepoint not observed yet)
  has already lasted ``e = now - a``: its range shrinks to ``[max(lb, e), max(ub, e)]``; past its upper
  bound it is an overrun that "occurs any moment now" (``[e, e]``), not an error;
* every other unexecuted executable comes at ``now`` or later: ``now <= T(X) - T(O)``.

**The strategy**: Hunsberger's real-time execution decisions (RTEDs; L. Hunsberger, "Fixing the
semantics for dynamic controllability and providing a more practical characterization of dynamic
execution strategies", TIME 2009, section 4; the RTE* algorithm, "Efficient execution of dynamically
controllable simple temporal networks with uncertainty", Acta Informatica 53, 2016): at every moment a
DC network's strategy either waits for a contingent timepoint or decides "(t, X): if nothing happens
before t, execute X at t", with t at least X's lower bound (its waits included) and at most the least
upper bound of every unexecuted executable. RTE* keeps those bounds by local propagation over a
dispatchable ESTNU; here each state's residual network is closed afresh by the bypass DC check
(`hrc.temporal.bypass`: ordinary and upper-case bypass edges), which a dispatcher that ranks plans runs
anyway, and the bounds are its shortest paths ("full propagation"). With ``d`` the distances in the
graph of the residual's ordinary edges, the derived edges and every upper-case edge read as ordinary
(the waits of Morris & Muscettola 2005: the AllMax projection), without the upper bound ``A -> C`` of a
contingent link in progress (its C may still overrun: it comes at ``now`` or later, no later bound):

* ``latest = min d(O, V)`` over every unexecuted V, executable or contingent: the last tick at which the
  agent may still be waiting with nothing executed (RTE*'s upper bound t_U);
* ``earliest(X) = max(now, -d(X, O))``; when upper-case edges raise it, `ExecutionWindow.waits_on` names
  their contingent timepoints (if one of them is observed first, the window moves: ask again);
* X must wait (`MustWait`) for each unexecuted V with ``d(X, V) < 0`` (V must come before X), with
  ``d(X, V) <= 0`` when V is contingent or not the caller's to execute (``uncontrolled``: a co-worker's
  own starts; X would otherwise be executed together with something it cannot make happen). This covers
  a V whose deadline comes before X's earliest tick: ``d(X, V) <= d(X, O) + d(O, V) < 0``.

Two weaker readings serve plans that are no longer DC (`ExecutionMode`): ``STN`` reads contingent links as
requirements (the team controls every duration, as when a human keeps to the plan: Muscettola, Morris &
Tsamardinos 1998 dispatching with full propagation), with the same bounds computed on the residual
network's distance graph, upper bounds of links in progress included (so a window ends where a
co-worker keeping to the plan would be overdue); ``EARLIEST`` keeps only the orderings and lower bounds
(edges of weight <= 0, whichever way a file wrote the link; deadlines and other upper bounds go) that
still bind what is to come (finish as early as possible when no schedule meets every bound; an ordering
history already broke says nothing about what to do next): a window of one tick, its earliest.

The windows are exact: tests/test_temporal_execution.py checks on random small STNUs and random partial
executions that a tick is in X's window iff a brute-force DC check of the residual network at that tick,
with X pinned there, says DC and so does the residual network at every tick before it (waiting is
safe); and that executing inside the windows never violates a constraint. Each state costs one DC check
and a few Bellman-Ford searches (O(n m) worst case, near linear on plan networks).

>>> from hrc.temporal.network import RequirementLink as R, ContingentLink as C
>>> net = STNU(("A", "C", "X"), (R("C", "X", 0, 2),), (C("A", "C", 1, 10),))
>>> state = real_time_state(net, {"A": 0}, 3)
>>> state.verdict.value, state.step("X")
('DC', MustWait(timepoint='X', until=('C',)))
>>> real_time_state(net, {"A": 0, "C": 4}, 5).step("X")
ExecutionWindow(timepoint='X', earliest=5, latest=6, waits_on=())
"""

from __future__ import annotations

import enum
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType

from hrc.temporal.dc import DCResult, Verdict, check_dc
from hrc.temporal.graph import EdgeKind
from hrc.temporal.network import STNU, ContingentLink, NetworkError, RequirementLink

__all__ = ["RESIDUAL_ORIGIN", "ExecutionMode", "ExecutionWindow", "MustWait", "RealTimeState", "real_time_state",
           "residual_network", "residual_origin", "violated_links"]

RESIDUAL_ORIGIN = "__now__"
"""Name of the residual network's origin (underscores are appended while it clashes with a timepoint)."""

_INF = float("inf")
_Paths = tuple[list[float], list[tuple[int, str] | None]]  # distances, and the edge each node was reached by


class ExecutionMode(enum.Enum):
    """How `RealTimeState.step` reads the network (see the module docstring)."""

    DC = "DC"  # contingent durations anywhere in their bounds, seen only when they end
    STN = "STN"  # contingent links read as requirement links
    EARLIEST = "earliest"  # lower bounds only: as early as possible


@dataclass(frozen=True, slots=True)
class ExecutionWindow:
    """Execute `timepoint` at any tick in ``[earliest, latest]`` (``latest`` None: no bound) if nothing
    else is executed or observed first. `waits_on`: contingent timepoints whose upper-case waits set
    `earliest`; observing one of them may move the window earlier."""

    timepoint: str
    earliest: int
    latest: int | None
    waits_on: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class MustWait:
    """`timepoint` cannot be executed before the unexecuted timepoints `until` have happened."""

    timepoint: str
    until: tuple[str, ...]


def residual_origin(stnu: STNU) -> str:
    """The name of `stnu`'s residual networks' origin: `RESIDUAL_ORIGIN`, with underscores appended while
    it clashes with a timepoint of `stnu`."""
    name = RESIDUAL_ORIGIN
    known = set(stnu.timepoints)
    while name in known:
        name += "_"
    return name


def _check_execution(stnu: STNU, executed: Mapping[str, int], now: int, ahead: bool = False) -> None:
    known = set(stnu.timepoints)
    if isinstance(now, bool) or not isinstance(now, int):
        raise NetworkError(f"now must be an integer number of ticks, got {now!r}")
    for x, t in executed.items():
        if x not in known:
            raise NetworkError(f"executed timepoint {x!r} is not in the network")
        if isinstance(t, bool) or not isinstance(t, int):
            raise NetworkError(f"time of {x!r} must be an integer number of ticks, got {t!r}")
        if t > now and not ahead:
            raise NetworkError(f"{x!r} executed at {t}, after now ({now})")
    for c in stnu.contingents:
        if c.target in executed:
            if c.source not in executed:
                raise NetworkError(f"contingent {c.target!r} observed before its activation {c.source!r}")
            if executed[c.target] < executed[c.source]:
                raise NetworkError(f"contingent {c.target!r} observed before its activation {c.source!r}")


def residual_network(stnu: STNU, executed: Mapping[str, int], now: int, *, ahead: bool = False) -> STNU:
    """The rest of an execution as an STNU with origin ``timepoints[0]`` (see the module docstring).

    `executed` maps timepoints to their execution (or observation) ticks, all ``<= now`` unless `ahead`:
    a reading of when a sensed event may have happened, which can be after the message that told it
    (`hrc.dispatch.Dispatcher._estimates`; the clock stays at `now`, and a contingent link whose
    activation is read after `now` has lasted nothing yet). Raises `NetworkError` on an unknown
    timepoint, a time after `now` (without `ahead`), or a contingent timepoint observed before its
    activation. O(links).
    """
    _check_execution(stnu, executed, now, ahead)
    origin = residual_origin(stnu)
    reqs = [r for r in stnu.requirements if not (r.source in executed and r.target in executed)]
    reqs.extend(RequirementLink(origin, x, t, t) for x, t in executed.items())
    conts: list[ContingentLink] = []
    for c in stnu.contingents:
        if c.target in executed:
            continue
        if c.source in executed:
            elapsed = now - executed[c.source]
            conts.append(ContingentLink(c.source, c.target, max(c.lb, elapsed), max(c.ub, elapsed)))
        else:
            conts.append(c)
    contingent = stnu.contingent_timepoints
    reqs.extend(RequirementLink(origin, x, now, None) for x in stnu.timepoints
                if x not in executed and x not in contingent)
    return STNU((origin, *stnu.timepoints), tuple(reqs), tuple(conts), stnu.name)


def violated_links(stnu: STNU, executed: Mapping[str, int]) -> tuple[RequirementLink | ContingentLink, ...]:
    """The links between two executed timepoints that their times break (history the residual network
    leaves out), in network order: requirement links, then contingent links (an over- or underrun)."""
    out: list[RequirementLink | ContingentLink] = []
    links: list[RequirementLink | ContingentLink] = [*stnu.requirements, *stnu.contingents]
    for link in links:
        if link.source in executed and link.target in executed:
            d = executed[link.target] - executed[link.source]
            if (link.lb is not None and d < link.lb) or (link.ub is not None and d > link.ub):
                out.append(link)
    return tuple(out)


class _Graph:
    """Integer-weighted digraph over timepoint indices; edges carry the contingent label of a wait."""

    def __init__(self, names: tuple[str, ...], edges: Iterable[tuple[str, str, int, str]]) -> None:
        self.names = names
        self.index = {v: i for i, v in enumerate(names)}
        n = len(names)
        self.out: list[list[tuple[int, int, str]]] = [[] for _ in range(n)]
        self.into: list[list[tuple[int, int, str]]] = [[] for _ in range(n)]
        for s, t, w, label in edges:
            i, j = self.index[s], self.index[t]
            self.out[i].append((j, w, label))
            self.into[j].append((i, w, label))

    def distances(self, node: str, *, to: bool = False) -> _Paths | None:
        """Shortest distances from `node` (to it with ``to=True``) by queue-based Bellman-Ford, and for each
        node the edge ``(next node, label)`` it was reached by; None if a negative cycle is reachable."""
        n = len(self.names)
        adj = self.into if to else self.out
        src = self.index[node]
        dist: list[float] = [_INF] * n
        hops = [0] * n
        via: list[tuple[int, str] | None] = [None] * n
        dist[src] = 0
        queue, queued = deque([src]), [False] * n
        queued[src] = True
        while queue:
            u = queue.popleft()
            queued[u] = False
            du = dist[u]
            for v, w, label in adj[u]:
                if du + w < dist[v]:
                    dist[v] = du + w
                    via[v] = (u, label)
                    hops[v] = hops[u] + 1
                    if hops[v] >= n:
                        return None
                    if not queued[v]:
                        queued[v] = True
                        queue.append(v)
        return dist, via


@dataclass(frozen=True)
class RealTimeState:
    """A partial execution of `network` at tick `now`: its `residual` network and that network's DC check
    (`dc`, by the bypass closure, whose derived edges the windows use). Build with `real_time_state`."""

    network: STNU
    executed: Mapping[str, int]
    now: int
    residual: STNU
    dc: DCResult
    _graphs: dict[ExecutionMode | None, _Graph] = field(default_factory=dict, repr=False, compare=False)
    _paths: dict[tuple[ExecutionMode, str, bool], _Paths | None] = field(default_factory=dict, repr=False,
                                                                         compare=False)

    @property
    def verdict(self) -> Verdict:
        """DC, not DC (but consistent), or inconsistent: the class of what is left to do."""
        return self.dc.verdict

    @property
    def origin(self) -> str:
        return self.residual.timepoints[0]

    @property
    def pending(self) -> tuple[str, ...]:
        """Unexecuted executable timepoints, in network order."""
        contingent = self.network.contingent_timepoints
        return tuple(x for x in self.network.timepoints if x not in self.executed and x not in contingent)

    def default_mode(self) -> ExecutionMode:
        """DC when the rest is DC, STN when it is consistent, EARLIEST otherwise."""
        if self.verdict is Verdict.DC:
            return ExecutionMode.DC
        return ExecutionMode.STN if self.verdict is Verdict.NOT_DC else ExecutionMode.EARLIEST

    def _graph(self, mode: ExecutionMode) -> _Graph:
        graph = self._graphs.get(mode)
        if graph is not None:
            return graph
        res = self.residual
        in_progress = {c.target for c in res.contingents if c.source in self.executed}
        origin = self.origin
        edges: list[tuple[str, str, int, str]] = []
        for r in res.requirements:
            pin = r.source == origin and r.target in self.executed
            for u, v, w in ((r.source, r.target, r.ub), (r.target, r.source, None if r.lb is None else -r.lb)):
                if w is None:
                    continue
                if mode is ExecutionMode.EARLIEST and not pin and (w > 0 or (u in self.executed and
                                                                             v not in self.executed)):
                    # EARLIEST keeps orderings and lower bounds (edges of weight <= 0: "v no later than u
                    # minus something"), whichever way the file wrote the link, and drops deadlines
                    # (positive weights); an ordering that history already broke (an executed u) says
                    # nothing about what to do next and would only close a negative cycle
                    continue
                edges.append((u, v, w, ""))
        for c in res.contingents:
            edges.append((c.target, c.source, -c.lb, ""))
            # DC: no upper bound for a link in progress, its C may overrun (its lower bound says C >= now)
            if mode is ExecutionMode.STN or (mode is ExecutionMode.DC and c.target not in in_progress):
                edges.append((c.source, c.target, c.ub, ""))
            if mode is ExecutionMode.DC:
                edges.append((c.target, c.source, -c.ub, c.target))
        if mode is ExecutionMode.DC:
            for e in self.dc.added:
                edges.append((e.source, e.target, e.value, e.label if e.kind is EdgeKind.UPPER else ""))
        graph = _Graph(res.timepoints, edges)
        self._graphs[mode] = graph
        return graph

    def _distances(self, mode: ExecutionMode, node: str, to: bool) -> _Paths | None:
        key = (mode, node, to)
        if key not in self._paths:
            self._paths[key] = self._graph(mode).distances(node, to=to)
        return self._paths[key]

    def latest(self, mode: ExecutionMode | None = None) -> int | None:
        """The last tick at which nothing need have been executed yet (None: no bound; the same for every
        enabled timepoint)."""
        mode = mode or self.default_mode()
        if mode is ExecutionMode.EARLIEST:
            return None
        found = self._distances(mode, self.origin, False)
        if found is None:
            raise NetworkError("the residual network has a negative cycle")
        dist, graph = found[0], self._graph(mode)
        best = min((dist[graph.index[v]] for v in self.network.timepoints if v not in self.executed), default=_INF)
        return None if best == _INF else int(best)

    def step(self, x: str, mode: ExecutionMode | None = None, *,
             uncontrolled: Iterable[str] = ()) -> ExecutionWindow | MustWait:
        """When `x` may be executed (see the module docstring); `mode` defaults to `default_mode`.

        Raises `NetworkError` if `x` is unknown, contingent or executed, or if `mode` needs more than the
        residual network offers (DC mode on a network that is not DC, STN mode on an inconsistent one).
        """
        mode = mode or self.default_mode()
        if x not in self.network.timepoints:
            raise NetworkError(f"unknown timepoint {x!r}")
        if x in self.network.contingent_timepoints:
            raise NetworkError(f"{x!r} is contingent: nature executes it")
        if x in self.executed:
            raise NetworkError(f"{x!r} has been executed already")
        if mode is ExecutionMode.DC and self.verdict is not Verdict.DC:
            raise NetworkError(f"the rest is {self.verdict.value}: no DC strategy")
        if mode is ExecutionMode.STN and self.verdict is Verdict.INCONSISTENT:
            raise NetworkError("the rest is inconsistent: no STN schedule")
        graph = self._graph(mode)
        contingent = self.network.contingent_timepoints
        weak = contingent | frozenset(uncontrolled)
        origin = self.origin
        to_origin = self._distances(mode, origin, True)
        from_x = self._distances(mode, x, False)
        if to_origin is None or from_x is None:  # only EARLIEST can have a negative cycle
            return ExecutionWindow(x, self.now, self.now)
        dist_x = from_x[0]
        until = [v for v in self.network.timepoints if v != x and v not in self.executed
                 and (dist_x[graph.index[v]] < 0 or (v in weak and dist_x[graph.index[v]] <= 0))]
        earliest = max(self.now, int(-to_origin[0][graph.index[x]]))
        if mode is ExecutionMode.EARLIEST:
            if until:
                return MustWait(x, tuple(until))
            return ExecutionWindow(x, earliest, earliest)
        if until:
            return MustWait(x, tuple(until))
        latest = self.latest(mode)
        return ExecutionWindow(x, earliest, latest, self._waits(mode, x, earliest) if mode is ExecutionMode.DC else ())

    def _waits(self, mode: ExecutionMode, x: str, earliest: int) -> tuple[str, ...]:
        """The contingent timepoints of the upper-case edges on a shortest path x ~> origin, if without
        upper-case edges the lower bound of `x` would be below `earliest` (and `earliest` is above now)."""
        if earliest <= self.now:
            return ()
        plain = self._graphs.get(None)
        if plain is None:
            full = self._graph(mode)
            plain = _Graph(full.names, ((full.names[i], full.names[j], w, "") for j, into in enumerate(full.into)
                                        for i, w, label in into if not label))
            self._graphs[None] = plain
        without = plain.distances(self.origin, to=True)
        if without is not None and -without[0][plain.index[x]] >= earliest:
            return ()
        found = self._distances(mode, self.origin, True)
        assert found is not None  # a DC residual network has no negative cycle in this graph
        graph, via = self._graph(mode), found[1]
        labels: list[str] = []
        node, target = graph.index[x], graph.index[self.origin]
        for _ in graph.names:  # a shortest path has fewer edges than nodes
            hop = via[node]
            if node == target or hop is None:
                break
            node, label = hop
            if label and label not in labels:
                labels.append(label)
        return tuple(labels)


def real_time_state(network: STNU, executed: Mapping[str, int], now: int, *, ahead: bool = False) -> RealTimeState:
    """Build the `RealTimeState` of `network` executed as `executed` (timepoint -> tick) at tick `now`:
    the residual network and its DC check (bypass algorithm). Raises `NetworkError` as
    `residual_network` does (`ahead`: executed times may be after `now`, as there). Cost: one DC check."""
    frozen = MappingProxyType(dict(executed))
    residual = residual_network(network, frozen, now, ahead=ahead)
    return RealTimeState(network, frozen, now, residual, check_dc(residual, "bypass"))
