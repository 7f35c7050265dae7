"""APA's printed DO form dispatched on its own, and the dispatcher's answer to an event out of order or a
deadline passed (Wilcox, Nikolaidis & Shah 2012, Figs. 5 and 8; Muscettola, Morris & Tsamardinos 1998).

The dispatcher here is written from MMT 1998, section 3, over the constraints `do_form` returns (what
``hrc apa`` prints), with nothing of hrc's APSP: an event is *enabled* once every event a negative edge
of it points to has happened, *live* once the current time is inside its window; each execution tightens
only its direct neighbours' windows (one step). It picks a random enabled live event at a random time
that passes no enabled event's deadline. A run is *stuck* when an event's window empties or passes, or
no event can go; a dispatchable form never gets stuck, and every schedule it gives keeps the optimum.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hrc.apa.compile import compile_stpp, do_form
from hrc.apa.dispatch import STPPDispatcher
from hrc.apa.generator import random_stpp
from hrc.apa.model import STPP, Constraint

TPS = 1_000_000  # the printed seconds are whole microseconds (APA's default ticks)


def one_step_dispatch(events: tuple[str, ...], form: tuple[Constraint, ...], rng: np.random.Generator
                      ) -> dict[str, float] | None:
    """A schedule (s) dispatched over `form` alone, or None when the dispatch gets stuck."""
    idx = {e: i for i, e in enumerate(events)}
    n = len(events)
    out: list[list[tuple[int, int]]] = [[] for _ in range(n)]  # u -> (v, w): T(v) - T(u) <= w
    into: list[list[tuple[int, int]]] = [[] for _ in range(n)]
    for c in form:
        a, b = idx[c.source], idx[c.target]
        if math.isfinite(c.ub):
            w = round(c.ub * TPS)
            out[a].append((b, w))
            into[b].append((a, w))
        if math.isfinite(c.lb):
            w = -round(c.lb * TPS)
            out[b].append((a, w))
            into[a].append((b, w))
    before = [{v for v, w in out[u] if w < 0} for u in range(n)]  # T(v) <= T(u) + w < T(u): v first
    lo, hi = [-math.inf] * n, [math.inf] * n
    t: list[int | None] = [None] * n
    now = 0
    while any(x is None for x in t):
        waiting = [e for e in range(n) if t[e] is None]
        if any(lo[e] > hi[e] or hi[e] < now for e in waiting):
            return None
        enabled = [e for e in waiting if all(t[p] is not None for p in before[e])]
        if not enabled:
            return None
        deadline = min(hi[e] for e in enabled)
        ready = [e for e in enabled if max(lo[e], now) <= min(hi[e], deadline)]
        if not ready:
            return None
        e = ready[int(rng.integers(len(ready)))]
        a = max(lo[e], now)
        b = min(hi[e], deadline, a + 5 * TPS)
        at = int(rng.integers(int(a), int(b) + 1))
        now = t[e] = at
        for v, w in out[e]:
            hi[v] = min(hi[v], at + w)
        for u, w in into[e]:
            lo[u] = max(lo[u], at - w)
    start = t[0]
    return {ev: (t[i] - start) / TPS for i, ev in enumerate(events)}  # type: ignore[operator]


def test_a_member_at_offset_zero_of_a_rigid_pair_waits_for_its_leaders_predecessors():
    """e1 and e2 at the same time, e1 at least 1 s after e0: e2 must wait for e0 too (the printed form
    used to give e2 only [0, 0] to e1, and a dispatcher over it ran e2 first and got stuck)."""
    stpp = STPP(("e0", "e1", "e2", "e3"), (Constraint("e0", "e1", 1.0, 5.0), Constraint("e1", "e2", 0.0, 0.0),
                                           Constraint("e2", "e3", 1.0, 3.0)))
    form = do_form(compile_stpp(stpp))
    assert Constraint("e0", "e2", 1.0, 5.0) in form and Constraint("e1", "e2", 0.0, 0.0) in form
    rng = np.random.default_rng(0)
    for _ in range(50):
        s = one_step_dispatch(stpp.events, form, rng)
        assert s is not None and stpp.violation(s) <= 1e-9


@pytest.mark.parametrize("density", [1.0, 1.5, 3.0])
def test_the_printed_do_form_dispatches_on_its_own(density):
    """100 random problems in all (the paper's generator, three densities c/n, preferences on 20-100 % of
    n, some pinned to make rigid runs of offset 0), 10 runs each: no run gets stuck, and every schedule
    meets the STPP and reaches the optimum within the compile's tolerance."""
    stuck, runs = 0, 0
    for seed in range(34 if density != 3.0 else 32):
        rng = np.random.default_rng(seed)
        n = int(rng.integers(5, 45))
        stpp = random_stpp(n, rng, constraints=round(density * n), preference_share=(0.2, 0.5, 1.0)[seed % 3])
        if seed % 4 == 0:  # rigid links of offset 0 between neighbours: rigid components with zero offsets
            zeros = tuple(Constraint(f"e{i}", f"e{i + 1}", 0.0, 0.0) for i in range(1, n - 1, 5))
            stpp = STPP(stpp.events, stpp.constraints + zeros, stpp.name)
        result = compile_stpp(stpp)
        if not result.consistent:
            continue
        form = do_form(result)
        for _ in range(10):
            runs += 1
            s = one_step_dispatch(stpp.events, form, rng)
            if s is None:
                stuck += 1
                continue
            assert stpp.violation(s) <= 1e-6
            assert stpp.value(s) >= result.value - result.value_tolerance - 1e-6 * max(1.0, abs(result.value))
    assert runs >= 200 and stuck == 0, f"{stuck} of {runs} runs stuck"


# ------------------------------------------------------------------ deviations reported at once
def _chain() -> STPP:
    """e0 -> e1 in [1, 4] s, e1 -> e2 in [1, 4] s, a preference that e1 come 2 s after e0 (DO: rigid)."""
    from hrc.apa.model import PreferenceFunction

    peak = PreferenceFunction.quadratic(-4.0, 4.0, -1.0)  # -(x - 2)^2: best at 2 s
    return STPP(("e0", "e1", "e2"), (Constraint("e0", "e1", 1.0, 4.0, peak), Constraint("e1", "e2", 1.0, 4.0)))


def test_an_event_before_its_predecessor_is_a_violation_at_once():
    d = STPPDispatcher(_chain())
    assert d.observe("e0", 0.0).status == "on_policy"
    step = d.observe("e2", 3.0)  # e2 before e1, which must come at least 1 s before it: e1 is already late
    assert step.status == "violation"


def test_an_event_that_leaves_a_partner_no_do_window_is_a_deviation_at_once():
    """e3 (any time after e1) observed at 2.5 s inside its own DO window, while e1, due at 2 s by the DO
    form, has not come: e1 can still keep the hard constraints (up to 2.5 s), not the policy. The
    deviation is this observation's answer (a recompile), not the next event's."""
    base = _chain()
    stpp = STPP((*base.events, "e3"), (*base.constraints, Constraint("e1", "e3", 0.0, 10.0)))
    d = STPPDispatcher(stpp)
    d.observe("e0", 0.0)
    assert "e3" in d.enabled() and d.window("e3")[0] <= 2.5
    step = d.observe("e3", 2.5)
    assert step.status == "recompiled"
    assert d.window("e1") == (2.5, 2.5)  # the best left: as close to 2 s as it can be


def test_a_do_deadline_passed_by_advance_is_a_deviation_at_once():
    """e1 not yet observed at 2.5 s, past its DO time (2 s) though inside its hard window: the policy is
    broken now, not at the next event."""
    d = STPPDispatcher(_chain())
    d.observe("e0", 0.0)
    assert d.window("e1") == (2.0, 2.0)
    step = d.advance(2.5)  # e1's DO deadline passed without it
    assert step.status == "recompiled"
    assert d.window("e1")[0] >= 2.5


def test_a_hard_deadline_passed_by_advance_is_a_violation():
    d = STPPDispatcher(_chain())
    d.observe("e0", 0.0)
    assert d.advance(4.5).status == "violation"  # e1 had to come by 4 s
    assert d.result is None


def test_on_time_is_on_policy():
    d = STPPDispatcher(_chain())
    d.observe("e0", 0.0)
    assert d.advance(1.5).status == "on_policy"
    assert d.observe("e1", 2.0).status == "on_policy"
    assert d.observe("e2", 4.0).status == "on_policy"
