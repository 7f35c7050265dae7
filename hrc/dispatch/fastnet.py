"""One plan's STNU in the shape the dispatcher re-checks it at every message: index arrays, no objects.

`PlanNet.evaluate` computes what `hrc.dispatch.ranking.reference_evaluate` computes from the residual
network (`hrc.temporal.execution.residual_network`) — class, finish and idle time — without building
`STNU` values: the residual is the plan's own network with its origin ``Z`` as the residual's origin
(``Z`` is executed at 0), so its distance edges are the plan's edges minus the links history closed,
plus one pin per executed timepoint and one "at ``now`` or later" edge per unexecuted executable. The
DC verdict comes from the C core of RUL2021 (`hrc.temporal.rul.core_verdict`; without it, from
`check_dc` on the residual network). The earliest schedule is a longest-path computation over the same
constraints read as ``T(v) >= T(u) + L``, edges visited in a topological order of the plan's orderings
(one or two passes on plan networks; a pass limit finds a positive cycle, i.e. no schedule); when no
schedule keeps every bound, the orderings and lower bounds still to come alone, as
`hrc.temporal.execution.ExecutionMode.EARLIEST` reads them. tests/test_dispatch_fastnet.py checks that
both ways agree on random histories.
"""

from __future__ import annotations

from collections.abc import Mapping

from hrc.temporal.rul import core_verdict

__all__ = ["PlanNet"]

_VERDICT_CLASS = {"DC": "DC", "not DC": "consistent", "inconsistent": "inconsistent"}


class PlanNet:
    """A plan's network as arrays (see the module docstring). `legs`: per agent, the indices of each
    leg's ``(depart, arrive, park or -1, unpark or -1, start, end)`` timepoints, for idle time."""

    __slots__ = ("cont", "contingent", "dist", "executables", "index", "legs", "lp", "lp_all", "n",
                 "names", "req", "z")

    def __init__(self, names: tuple[str, ...], requirements, contingents, origin: str,  # noqa: ANN001
                 legs: Mapping[str, list[tuple[int, int, int, int, int, int]]]) -> None:
        self.names = names
        self.index = {v: i for i, v in enumerate(names)}
        self.n = len(names)
        self.z = self.index[origin]
        ix = self.index
        self.req = [(ix[r.source], ix[r.target], r.lb, r.ub) for r in requirements]
        self.cont = [(ix[c.source], ix[c.target], c.lb, c.ub) for c in contingents]
        self.contingent = frozenset(c for _, c, _, _ in self.cont)
        self.executables = [x for x in range(self.n) if x not in self.contingent and x != self.z]
        self.legs = legs
        # longest-path edges (u, v, L, link): T(v) >= T(u) + L, from requirement link `link` (>= 0) or from
        # contingent link -1 - k; in a topological order of the non-negative ones (ties: index order)
        lp: list[tuple[int, int, int, int, int]] = []  # (u, v, sign, link, which) resolved at evaluation
        for k, (s, t, lb, ub) in enumerate(self.req):
            if lb is not None:
                lp.append((s, t, 1, k, 0))  # T(t) >= T(s) + lb
            if ub is not None:
                lp.append((t, s, -1, k, 1))  # T(s) >= T(t) - ub
        for k, (a, c, _lb, _ub) in enumerate(self.cont):
            lp.append((a, c, 1, -1 - k, 0))
            lp.append((c, a, -1, -1 - k, 1))
        order = self._order(lp)
        lp.sort(key=lambda e: (order[e[0]], order[e[1]]))
        self.lp = lp
        # the same, resolved once: distance edges (s, t, w, link endpoints) for the verdict, and
        # longest-path edges (u, v, length or None, contingent k or -1, link endpoints) for the schedule
        self.dist = [(s, t, ub, s, t) for s, t, _lb, ub in self.req if ub is not None] + \
                    [(t, s, -lb, s, t) for s, t, lb, _ub in self.req if lb is not None]
        # (u, v, length, j, sign, a, b) in that order: a requirement edge has j = -1 and its length; the edge
        # of contingent link j has length sign * (its duration, fixed at evaluation); a, b: the link's ends
        # back: v comes no later than u in that order, so a move of v needs another sweep
        self.lp_all: list[tuple[int, int, int, int, int, int, int, bool]] = []
        for u, v, sign, k, which in lp:
            back = order[v] <= order[u]
            if k >= 0:
                s, t, lb, ub = self.req[k]
                bound = lb if which == 0 else ub
                if bound is not None:
                    self.lp_all.append((u, v, bound * sign, -1, sign, s, t, back))
            else:
                j = -1 - k
                a, c = self.cont[j][:2]
                self.lp_all.append((u, v, 0, j, sign, a, c, back))

    def _order(self, lp: list[tuple[int, int, int, int, int]]) -> list[int]:
        """Position of each node in a topological order of the orderings (edges whose length is >= 0
        whatever the bounds: lower bounds >= 0, upper bounds <= 0); nodes on zero cycles keep index order."""
        succ: list[list[int]] = [[] for _ in range(self.n)]
        indeg = [0] * self.n
        for u, v, sign, k, which in lp:
            if k >= 0:
                bound = self.req[k][2 + which]
                length = bound if sign > 0 else -bound  # type: ignore[operator]
            else:
                length = self.cont[-1 - k][2] if which == 0 else -1
            if length is not None and length >= 0:
                succ[u].append(v)
                indeg[v] += 1
        ready = [i for i in range(self.n) if indeg[i] == 0]
        seen: list[int] = []
        while ready:
            u = ready.pop(0)
            seen.append(u)
            for v in succ[u]:
                indeg[v] -= 1
                if indeg[v] == 0:
                    ready.append(v)
        rest = [i for i in range(self.n) if i not in set(seen)]
        pos = [0] * self.n
        for p, i in enumerate(seen + rest):
            pos[i] = p
        return pos

    # ------------------------------------------------------------------------------------------------
    def verdict(self, ex: list[int | None], now: int) -> str | None:
        """The residual's class name, or None when the C core cannot say (not built, huge numbers)."""
        z = self.z
        edges = [e for e in self.dist if ex[e[3]] is None or ex[e[4]] is None]  # links history closed go
        src = [e[0] for e in edges]
        dst = [e[1] for e in edges]
        wt = [e[2] for e in edges]
        pinned = [(x, tx) for x, tx in enumerate(ex) if tx is not None and x != z]
        waiting = [x for x in self.executables if ex[x] is None]
        src += [z] * len(pinned) + [x for x, _ in pinned] + waiting
        dst += [x for x, _ in pinned] + [z] * (len(pinned) + len(waiting))
        wt += [tx for _, tx in pinned] + [-tx for _, tx in pinned] + [-now] * len(waiting)
        ca: list[int] = []
        cc: list[int] = []
        xs: list[int] = []
        ys: list[int] = []
        for a, c, lb, ub in self.cont:
            if ex[c] is not None:
                continue
            ta = ex[a]
            if ta is not None:
                e = now - ta
                lb, ub = max(lb, e), max(ub, e)
            ca.append(a)
            cc.append(c)
            xs.append(lb)
            ys.append(ub)
        found = core_verdict(self.n, src, dst, wt, ca, cc, xs, ys)
        return None if found is None else _VERDICT_CLASS[found]

    def _durations(self, ex: list[int | None], now: int) -> list[tuple[int, int]]:
        """Each contingent link's range now: shortened by what it has lasted when in progress."""
        out = []
        for a, c, lb, ub in self.cont:
            ta = ex[a]
            if ta is not None and ex[c] is None:
                e = now - ta
                lb, ub = max(lb, e), max(ub, e)
            out.append((lb, ub))
        return out

    def schedule(self, ex: list[int | None], now: int, rank_by: str) -> list[int] | None:
        """Earliest times (ticks) with unrevealed durations read as `rank_by` says; the fallback on the
        orderings and lower bounds still to come; None if even that has none."""
        fixed = [lb if rank_by == "earliest" else (lb + ub) // 2 if rank_by == "nominal" else ub
                 for lb, ub in self._durations(ex, now)]
        for strict in (True, False):
            times = self._longest(ex, now, fixed, fixed, strict)
            if times is not None:
                return times
        return None

    def _longest(self, ex: list[int | None], now: int, fwd: list[int], bwd: list[int],
                 strict: bool) -> list[int] | None:
        n, z = self.n, self.z
        contingent = self.contingent
        t = [tx if tx is not None else 0 if x in contingent else now for x, tx in enumerate(ex)]
        t[z] = 0
        # links history closed go; an edge into history is a check (strict) or nothing (the fallback: an
        # ordering history broke says nothing about what comes next, and it keeps lengths >= 0 only)
        if strict:
            edges = [(u, v, length if j < 0 else fwd[j] if sign > 0 else -bwd[j], back)
                     for u, v, length, j, sign, a, b, back in self.lp_all if ex[a] is None or ex[b] is None]
        else:
            edges = [(u, v, length if j < 0 else fwd[j], back) for u, v, length, j, sign, a, b, back in self.lp_all
                     if (ex[a] is None or ex[b] is None) and ex[v] is None and (length >= 0 if j < 0 else sign > 0)]
        # Bellman-Ford in the orderings' topological order: one sweep settles it unless an edge moved a
        # timepoint whose outgoing edges that sweep had already visited (a "back" edge)
        for _sweep in range(n + 1):
            again = False
            for u, v, length, back in edges:
                w = t[u] + length
                if w > t[v]:
                    if ex[v] is not None or v == z:
                        return None  # a pinned timepoint would have to move: no schedule
                    t[v] = w
                    again = again or back
            if not again:
                return t
        return None

    def idle(self, times: list[int]) -> int:
        """Ticks the agents stand still between the start and their last end, summed over agents."""
        total = 0
        for legs in self.legs.values():
            if not legs:
                continue
            busy = 0
            for dep, arr, park, unpark, start, end in legs:
                busy += times[arr] - times[dep] + times[end] - times[start]
                if park >= 0:
                    busy -= times[unpark] - times[park]
            total += max(0, times[legs[-1][5]] - busy)
        return total
