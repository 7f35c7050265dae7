"""One plan's residual evaluation on the dispatch form's arrays, in Python: the twin of the C core
(``hrc/dispatch/_dispatchcore.c``, `hrc.dispatch.native`), used where the core is not built and by the
tests as a second implementation.

`PlanNet.evaluate` computes what `hrc.dispatch.ranking.reference_evaluate` computes from the residual
network (`hrc.temporal.execution.residual_network`) — class, finish and idle time — without building
`STNU` values: the residual is the plan's own network with its origin (timepoint 0 of the form) as the
residual's origin, executed at 0, so its distance edges are the plan's edges minus those between two
executed timepoints, plus one pin per executed timepoint and one "at now or later" edge per unexecuted
executable. The DC verdict comes from the C verdict of RUL2021 (`hrc.temporal.rul.core_verdict`) when
that is built, else from `check_dc` on the residual network. The earliest schedule is a longest-path
computation over the same constraints read as ``T(v) >= T(u) + L``, swept in the form's topological
numbering (one or two sweeps on plan networks; a sweep limit finds a positive cycle, i.e. no schedule);
when no schedule keeps every bound, the orderings and lower bounds still to come alone, as
`hrc.temporal.execution.ExecutionMode.EARLIEST` reads them.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hrc.compile.dispatch_form import PlanArrays
from hrc.temporal.rul import core_verdict

__all__ = ["PlanNet"]

_VERDICT_CLASS = {"DC": "DC", "not DC": "consistent", "inconsistent": "inconsistent"}


class PlanNet:
    """A plan's network as lists (see the module docstring), from its `PlanArrays`."""

    __slots__ = ("conts", "contingent", "edges", "executables", "legs", "n")

    def __init__(self, arrays: PlanArrays) -> None:
        self.n = n = arrays.n
        self.edges = [tuple(int(x) for x in row) for row in arrays.edges.tolist()]  # (u, v, w): T(v) - T(u) <= w
        self.conts = [tuple(int(x) for x in row) for row in arrays.conts.tolist()]  # (a, c, lb, ub)
        self.contingent = frozenset(c for _, c, _, _ in self.conts)
        self.executables = [x for x in range(1, n) if x not in self.contingent]
        # per agent, each leg's (depart, park, unpark, arrive, start, end) timepoints (-1: none)
        self.legs = [[tuple(int(x) for x in leg) for leg in agent if leg[0] >= 0] for agent in arrays.nodes.tolist()]

    def executed(self, seen: np.ndarray, legs_seen: np.ndarray) -> list[int | None]:
        """The executed timepoints' ticks (None: not executed) under the state `seen`, `legs_seen` (see
        `hrc.dispatch.native.NativeForm.evaluate`): each seen event at its tick, an unseen earlier event
        of a seen leg at the tick of the next seen one."""
        ex: list[int | None] = [None] * self.n
        ex[0] = 0
        for g, legs in enumerate(self.legs):
            for k in range(min(int(legs_seen[g]), len(legs))):
                pending: list[int] = []
                for x, t in zip(legs[k], seen[g, k].tolist(), strict=True):
                    if x < 0:
                        continue
                    if t < 0:
                        pending.append(x)
                        continue
                    for y in pending:
                        ex[y] = t
                    pending.clear()
                    ex[x] = t
        return ex

    def ranges(self, ex: list[int | None], now: int) -> list[tuple[int, int]]:
        """Each contingent link's range now: shortened by what it has lasted when in progress."""
        out = []
        for a, c, lb, ub in self.conts:
            ta = ex[a]
            if ta is not None and ex[c] is None:
                e = now - ta
                lb, ub = max(lb, e), max(ub, e)
            out.append((lb, ub))
        return out

    def verdict(self, ex: list[int | None], now: int, check: Callable[[], str]) -> str:
        """The residual's class name: the C verdict, else `check` (the residual network's DC check)."""
        edges = [(u, v, w) for u, v, w in self.edges if ex[u] is None or ex[v] is None]
        src = [u for u, _, _ in edges]
        dst = [v for _, v, _ in edges]
        wt = [w for _, _, w in edges]
        pinned = [(x, tx) for x, tx in enumerate(ex) if tx is not None and x != 0]
        waiting = [x for x in self.executables if ex[x] is None]
        src += [0] * len(pinned) + [x for x, _ in pinned] + waiting
        dst += [x for x, _ in pinned] + [0] * (len(pinned) + len(waiting))
        wt += [tx for _, tx in pinned] + [-tx for _, tx in pinned] + [-now] * len(waiting)
        links = [(a, c, lb, ub) for (a, c, _, _), (lb, ub) in zip(self.conts, self.ranges(ex, now), strict=True)
                 if ex[c] is None]
        found = core_verdict(self.n, src, dst, wt, [x[0] for x in links], [x[1] for x in links],
                             [x[2] for x in links], [x[3] for x in links])
        return check() if found is None else _VERDICT_CLASS[found]

    def schedule(self, ex: list[int | None], now: int, rank_by: str) -> list[int] | None:
        """Earliest times (ticks) with unrevealed durations read as `rank_by` says; the fallback on the
        orderings and lower bounds still to come; None if even that has none."""
        fixed = [lb if rank_by == "earliest" else (lb + ub) // 2 if rank_by == "nominal" else ub
                 for lb, ub in self.ranges(ex, now)]
        for strict in (True, False):
            times = self._longest(ex, now, fixed, strict)
            if times is not None:
                return times
        return None

    def _longest(self, ex: list[int | None], now: int, fixed: list[int], strict: bool) -> list[int] | None:
        n = self.n
        contingent = self.contingent
        t = [tx if tx is not None else 0 if x in contingent else now for x, tx in enumerate(ex)]
        t[0] = 0
        # longest-path edges u -> v: T(v) >= T(u) + length; links history closed go; an edge into history
        # is a check (strict) or nothing (the fallback keeps orderings and lower bounds into what is left)
        out: list[list[tuple[int, int]]] = [[] for _ in range(n)]
        for u, v, w in self.edges:  # T(v) - T(u) <= w: T(u) >= T(v) - w
            if ex[u] is not None and ex[v] is not None:
                continue
            if strict or (ex[u] is None and -w >= 0):
                out[v].append((u, -w))
        for (a, c, _, _), d in zip(self.conts, fixed, strict=True):
            if ex[a] is not None and ex[c] is not None:
                continue
            if strict or ex[c] is None:
                out[a].append((c, d))
            if strict:
                out[c].append((a, -d))
        # Bellman-Ford in index order (the form's topological numbering): one sweep settles it unless an
        # edge moved a timepoint whose outgoing edges that sweep had already visited (v <= u)
        for _sweep in range(n + 1):
            again = False
            for u in range(n):
                tu = t[u]
                for v, length in out[u]:
                    val = tu + length
                    if val > t[v]:
                        if ex[v] is not None or v == 0:
                            return None  # a pinned timepoint would have to move: no schedule
                        t[v] = val
                        again = again or v <= u
            if not again:
                return t
        return None

    def idle(self, times: list[int]) -> int:
        """Ticks the agents stand still between the start and their last end, summed over agents."""
        total = 0
        for legs in self.legs:
            if not legs:
                continue
            busy = 0
            for dep, park, unpark, arr, start, end in legs:
                busy += times[arr] - times[dep]
                if end >= 0:  # (a joint phase another agent leads has none of this agent's: `_dispatchcore.c`)
                    busy += times[end] - times[start]
                if park >= 0:
                    busy -= times[unpark] - times[park]
            last = legs[-1]
            total += max(0, times[last[5] if last[5] >= 0 else last[3]] - busy)
        return total
