"""An independent DC check for tests: solve the execution game exhaustively (tiny networks only).

This shares no theory with `hrc.temporal.dc`: it does not use distance graphs or reductions, it plays
the game that defines dynamic controllability (Morris, Muscettola & Vidal 2001; Hunsberger 2009) in
integer time. At each tick ``t`` nature first ends any subset of the running contingent links that may
end now (it must end those at their upper bound); the agent, who sees this, then executes timepoints at
``t`` one at a time, and then time advances. The agent wins if every timepoint gets a time and every
link holds. The agent may react at the tick of an observation (instantaneous reaction), the semantics
the reduction-based algorithms decide. Integer play suffices for integer networks.

WLOG the first execution is at tick 0 (no origin), and play stops at a horizon ``H`` = 1 + the sum of the
absolute values of all finite bounds: a DC network has a strategy in which every timepoint waits for at
most a chain of distinct bounds, so nothing needs to happen later.

Contingent links must have ``lb >= 1`` (then nothing a contingent link starts can end in the tick
it starts, and nature moving first in each tick is exact).

Cost: exponential (memoised AND-OR search). Keep networks to ~6 timepoints and small bounds.
"""

from __future__ import annotations

from functools import cache

from hrc.temporal.network import STNU

__all__ = ["oracle_is_dc", "oracle_is_delay_controllable"]


def _requirements(stnu: STNU) -> tuple[dict[str, int], list[tuple[int, int, int]]]:
    """Each timepoint's index and the requirement links as ``(i, j, w)``: ``T(j) - T(i) <= w`` (the games'
    common start; contingent lower bounds must be >= 1: nature moves before the agent each tick)."""
    if any(c.lb == 0 for c in stnu.contingents):
        raise ValueError("oracle: contingent links need lb >= 1 (nature moves before the agent each tick)")
    idx = {v: i for i, v in enumerate(stnu.timepoints)}
    cons: list[tuple[int, int, int]] = []
    for r in stnu.requirements:
        if r.ub is not None:
            cons.append((idx[r.source], idx[r.target], r.ub))
        if r.lb is not None:
            cons.append((idx[r.target], idx[r.source], -r.lb))
    return idx, cons


def _by_timepoint(n: int, cons: list[tuple[int, int, int]]) -> list[list[tuple[int, int, int]]]:
    """The constraints touching each timepoint."""
    out: list[list[tuple[int, int, int]]] = [[] for _ in range(n)]
    for con in cons:
        out[con[0]].append(con)
        out[con[1]].append(con)
    return out


def _nature_may_must(activation: dict[int, tuple[int, int, int]], times: tuple[int | None, ...],
                     t: int) -> tuple[list[int], list[int]]:
    """The contingent timepoints nature may end at tick `t` (activated, within bounds) and those it must
    (at their upper bound), given the `times` so far."""
    may, must = [], []
    for c, (a, lb, ub) in activation.items():
        ta = times[a]
        if ta is not None and times[c] is None:
            if ta + ub == t:
                must.append(c)
            elif ta + lb <= t < ta + ub:
                may.append(c)
    return may, must


def oracle_is_dc(stnu: STNU, *, max_states: int = 2_000_000) -> bool:
    """True iff the agent has a winning dynamic strategy (see the module docstring).

    Raises `RuntimeError` if the search visits more than ``max_states`` states (network too big).
    """
    n = len(stnu.timepoints)
    if n == 0:
        return True
    idx, cons = _requirements(stnu)
    activation: dict[int, tuple[int, int, int]] = {}  # contingent tp -> (activation tp, lb, ub)
    for c in stnu.contingents:
        activation[idx[c.target]] = (idx[c.source], c.lb, c.ub)
    horizon = 1 + sum(abs(w) for _, _, w in cons) + sum(c.ub for c in stnu.contingents)
    executables = [i for i in range(n) if i not in activation]
    cons_of = _by_timepoint(n, cons)
    visited = 0

    def ok_with(times: tuple[int | None, ...], v: int) -> bool:
        for i, j, w in cons_of[v]:
            ti, tj = times[i], times[j]
            if ti is not None and tj is not None and tj - ti > w:
                return False
        return True

    def can_wait(times: tuple[int | None, ...], t: int) -> bool:
        """Moving to tick t+1 leaves no unassigned timepoint past a deadline set by an assigned one."""
        for i, j, w in cons:
            ti = times[i]
            if ti is not None and times[j] is None and ti + w < t + 1:
                return False
        return True

    @cache
    def nature(t: int, times: tuple[int | None, ...]) -> bool:
        nonlocal visited
        visited += 1
        if visited > max_states:
            raise RuntimeError("oracle: state space too large")
        if t > horizon:
            return False
        may, must = _nature_may_must(activation, times, t)
        # every subset of `may`, plus all of `must`
        for mask in range(1 << len(may)):
            new = list(times)
            for c in must:
                new[c] = t
            for k, c in enumerate(may):
                if mask >> k & 1:
                    new[c] = t
            tup = tuple(new)
            if any(not ok_with(tup, c) for c in must) or any(
                mask >> k & 1 and not ok_with(tup, c) for k, c in enumerate(may)
            ):
                return False
            if not agent(t, tup, 0):
                return False
        return True

    @cache
    def agent(t: int, times: tuple[int | None, ...], first: int) -> bool:
        # executions at tick t form a set: try them in increasing index order (`first`)
        if all(x is not None for x in times):
            return True
        for v in executables:
            if v < first or times[v] is not None:
                continue
            new = times[:v] + (t,) + times[v + 1 :]
            if ok_with(new, v) and agent(t, new, v + 1):
                return True
        if all(x is None for x in times):
            return False  # the first execution is at tick 0 WLOG
        return can_wait(times, t) and nature(t + 1, times)

    return agent(0, (None,) * n, 0)


def oracle_is_delay_controllable(stnu: STNU, delays: dict[str, tuple[int, int | None]], *,
                                 max_states: int = 2_000_000) -> bool:
    """True iff the agent wins the execution game in which each contingent timepoint ``C`` is learnt
    late: nature ends ``C`` at ``c`` and delivers its observation at a tick ``o`` in ``c + [lo, hi]`` of
    its choice (``delays[C] = (lo, hi)``; missing: ``(0, 0)``; ``hi`` None: never); the observation says
    that ``C`` happened, not when. Each tick nature moves first (ends, delivers), then the agent executes a
    set of timepoints, knowing only its own executions, the clock and the observations delivered so far.

    An imperfect-information game, solved over *belief states* (the set of nature's histories the agent
    cannot tell apart; its strategy is a function of its information, so one action applies to every
    history in the set, and the agent must win from each set of histories nature's next observations
    leave). It shares nothing with `hrc.temporal.delay`'s reduction. Integer ticks, contingent lower bounds
    >= 1, as `oracle_is_dc`; exponential: a handful of timepoints with small bounds only. At delay 0 it is
    `oracle_is_dc`'s game.
    """
    n = len(stnu.timepoints)
    if n == 0:
        return True
    idx, cons = _requirements(stnu)
    activation: dict[int, tuple[int, int, int]] = {}
    delay: dict[int, tuple[int, int | None]] = {}
    for c in stnu.contingents:
        activation[idx[c.target]] = (idx[c.source], c.lb, c.ub)
        delay[idx[c.target]] = delays.get(c.target, (0, 0))
        cons.append((idx[c.source], idx[c.target], c.ub))
        cons.append((idx[c.target], idx[c.source], -c.lb))
    horizon = (1 + sum(abs(w) for _, _, w in cons)
               + sum(hi for _, hi in delay.values() if hi is not None))
    executables = [i for i in range(n) if i not in activation]
    cons_of = _by_timepoint(n, cons)
    visited = 0
    State = tuple[tuple[int | None, ...], tuple[bool, ...]]  # times, observed

    def ok_with(times: tuple[int | None, ...], v: int) -> bool:
        for i, j, w in cons_of[v]:
            ti, tj = times[i], times[j]
            if ti is not None and tj is not None and tj - ti > w:
                return False
        return True

    def successors(t: int, state: State) -> list[State] | None:
        """Nature's moves at tick t from one history; None if one of them breaks a link (nature wins)."""
        times, seen = state
        may, must = _nature_may_must(activation, times, t)
        out: list[State] = []
        for mask in range(1 << len(may)):
            new = list(times)
            ended = list(must) + [c for k, c in enumerate(may) if mask >> k & 1]
            for c in ended:
                new[c] = t
            tup = tuple(new)
            if any(not ok_with(tup, c) for c in ended):
                return None
            # deliveries: each happened, unobserved C may (must, at its hi) be observed now
            may_o, must_o = [], []
            for c in activation:
                tc = tup[c]
                if tc is None or seen[c]:
                    continue
                lo, hi = delay[c]
                if hi is not None and t - tc == hi:
                    must_o.append(c)
                elif t - tc >= lo and (hi is None or t - tc < hi) and hi is not None:
                    may_o.append(c)
            for omask in range(1 << len(may_o)):
                s = list(seen)
                for c in must_o:
                    s[c] = True
                for k, c in enumerate(may_o):
                    if omask >> k & 1:
                        s[c] = True
                out.append((tup, tuple(s)))
        return out

    @cache
    def nature(t: int, belief: frozenset[State]) -> bool:
        nonlocal visited
        visited += 1
        if visited > max_states:
            raise RuntimeError("oracle: state space too large")
        if t > horizon:
            return False
        groups: dict[tuple[bool, ...], set[State]] = {}
        for state in belief:
            nxt = successors(t, state)
            if nxt is None:
                return False
            for s in nxt:
                groups.setdefault(s[1], set()).add(s)
        return all(agent(t, frozenset(g)) for g in groups.values())

    @cache
    def agent(t: int, belief: frozenset[State]) -> bool:
        some = next(iter(belief))[0]
        pending = [v for v in executables if some[v] is None]
        started = any(x is not None for x in some)
        for mask in range(1 << len(pending)):
            if mask == 0 and not started:
                continue  # the first execution is at tick 0 WLOG
            chosen = [v for k, v in enumerate(pending) if mask >> k & 1]
            new: set[State] = set()
            good = True
            for times, seen in belief:
                lst = list(times)
                for v in chosen:
                    lst[v] = t
                tup = tuple(lst)
                if any(not ok_with(tup, v) for v in chosen):
                    good = False
                    break
                new.add((tup, seen))
            if not good:
                continue
            if all(all(x is not None for x in times) for times, _ in new):
                return True
            # waiting to t+1 must not pass a deadline of an unexecuted timepoint
            if any(times[i] is not None and times[j] is None and times[i] + w < t + 1  # type: ignore[operator]
                   for times, _ in new for i, j, w in cons):
                continue
            if nature(t + 1, frozenset(new)):
                return True
        return False

    return agent(0, frozenset({((None,) * n, (False,) * n)}))
