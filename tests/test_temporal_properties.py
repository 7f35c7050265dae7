"""Property tests of the temporal core on random small STNUs (hypothesis).

* the Morris 2014 DC check agrees with the exhaustive game oracle;
* consistency agrees with LP feasibility (scipy.optimize.linprog);
* explanations are negative closed walks of the labelled graph;
* the minimal dispatchable network keeps the shortest paths and dispatches without dead ends;
* a DC network dispatched online under random contingent durations never violates a constraint.

Default runs use a few hundred examples per property; ``pytest -m slow`` runs thousands.
"""

from __future__ import annotations

import random

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from oracles import lp_consistent

from hrc.temporal import (
    STNU,
    ContingentLink,
    EdgeKind,
    RequirementLink,
    Verdict,
    Window,
    all_pairs_shortest_paths,
    check_consistency,
    check_dc,
    earliest_times,
    minimal_dispatchable_network,
    propagate_execution,
    rul,
    time_windows,
)
from hrc.temporal.dc import ALGORITHMS
from hrc.temporal.graph import distance_edges, labelled_edges
from hrc.temporal.oracle import oracle_is_dc
from hrc.temporal.rul import rul2021_check

FAST = settings(max_examples=300, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
SLOW = settings(max_examples=5000, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@st.composite
def stnus(draw, max_nodes: int = 5, max_contingent: int = 2, max_requirements: int = 6,
          min_contingent: int = 0) -> STNU:
    n = draw(st.integers(2, max_nodes))
    names = tuple(f"T{i}" for i in range(n))
    order = draw(st.permutations(names))
    k = draw(st.integers(min(min_contingent, n // 2), min(max_contingent, n // 2)))
    conts = []
    for i in range(k):
        lb = draw(st.integers(1, 4))
        conts.append(ContingentLink(order[2 * i], order[2 * i + 1], lb, lb + draw(st.integers(0, 4))))
    reqs = []
    for _ in range(draw(st.integers(0, max_requirements))):
        a, b = draw(st.sampled_from(names)), draw(st.sampled_from(names))
        if a == b:
            continue
        lb = draw(st.one_of(st.none(), st.integers(-5, 6)))
        ub = draw(st.one_of(st.none(), st.integers(-5, 8)))
        if lb is not None and ub is not None and lb > ub:
            lb, ub = ub, lb
        reqs.append(RequirementLink(a, b, lb, ub))
    return STNU(names, tuple(reqs), tuple(conts))


def _dc_agrees_with_oracle(stnu: STNU) -> None:
    expected = oracle_is_dc(stnu)
    for name in ALGORITHMS:  # every registered DC algorithm
        assert (check_dc(stnu, name).verdict is Verdict.DC) is expected, (name, stnu)
    # rul2021 has two implementations of its verdict: C (when built, used by check_dc) and Python
    assert (rul2021_check(stnu, accelerated=False)[0] == "DC") is expected, stnu


@FAST
@given(stnus(min_contingent=1))
def test_dc_agrees_with_game_oracle(stnu: STNU) -> None:
    _dc_agrees_with_oracle(stnu)


@pytest.mark.slow
@SLOW
@given(stnus(max_nodes=6, max_contingent=3, max_requirements=8, min_contingent=1))
def test_dc_agrees_with_game_oracle_many(stnu: STNU) -> None:
    try:
        _dc_agrees_with_oracle(stnu)
    except RuntimeError:  # the oracle's state space is too large for this one
        pass


@FAST
@given(stnus(max_nodes=7, max_requirements=10))
def test_consistency_agrees_with_lp(stnu: STNU) -> None:
    res = check_consistency(stnu)
    assert res.consistent is lp_consistent(stnu)
    if res.consistent:
        assert res.solution is not None
        for e in distance_edges(stnu):
            assert res.solution[e.target] - res.solution[e.source] <= e.value
        assert check_dc(stnu).verdict is not Verdict.INCONSISTENT
    else:
        assert sum(e.value for e in res.cycle) < 0
        assert check_dc(stnu).verdict is Verdict.INCONSISTENT


@FAST
@given(stnus(max_nodes=6, max_contingent=3, max_requirements=8))
def test_explanations_are_negative_cycles_of_the_network(stnu: STNU) -> None:
    for name in ALGORITHMS:
        result = check_dc(stnu, name)
        if result.verdict is Verdict.DC:
            assert result.cycle == ()
            assert all(e.kind in (EdgeKind.DERIVED, EdgeKind.UPPER) for e in result.added)
            continue
        cycle, graph = result.cycle, set(labelled_edges(stnu))
        assert cycle and sum(e.value for e in cycle) < 0
        for a, b in zip(cycle, cycle[1:] + cycle[:1], strict=True):
            assert a.target == b.source
        assert all(e in graph and e.kind is not EdgeKind.DERIVED for e in cycle)


@FAST
@given(stnus(max_nodes=6, max_contingent=0, max_requirements=10), st.randoms(use_true_random=False))
@example(  # a rigid pair at offset 0 whose follower must not run before the leader's predecessor
    STNU(("T0", "T1", "T2", "T3"), (RequirementLink("T0", "T1", 0, 0), RequirementLink("T3", "T0", None, 0),
                                    RequirementLink("T2", "T0", 1, None))),
    random.Random(0),
)
def test_minimal_dispatchable_network_keeps_paths_and_dispatches(stnu: STNU, rng: random.Random) -> None:
    if not check_consistency(stnu).consistent:
        return
    net = minimal_dispatchable_network(stnu)
    rebuilt = STNU(stnu.timepoints, tuple(RequirementLink(e.source, e.target, None, e.value) for e in net.edges))
    assert np.array_equal(all_pairs_shortest_paths(rebuilt), all_pairs_shortest_paths(stnu))
    # MMT 1998 dispatching: local propagation only, random choices, time never goes back
    windows = {v: Window(None, None) for v in stnu.timepoints}
    pending, now, times = set(stnu.timepoints), 0, {}
    while pending:
        enabled = [x for x in sorted(pending) if not net.must_follow(x) & pending]
        deadline = min((windows[y].hi for y in pending if windows[y].hi is not None), default=None)
        options = []
        for x in enabled:
            lo = max(now, windows[x].lo if windows[x].lo is not None else now)
            hi = min(h for h in (windows[x].hi, deadline, lo + 5) if h is not None)
            if lo <= hi:
                options.append((x, lo, hi))
        assert options, f"dispatch dead end at {now} with {sorted(pending)} left"
        x, lo, hi = rng.choice(options)
        now = rng.randint(lo, hi)
        times[x] = now
        pending.discard(x)
        windows = propagate_execution(windows, net.edges, x, now)
    for e in distance_edges(stnu):
        assert times[e.target] - times[e.source] <= e.value


def _residual(
    stnu: STNU, seen: int, earliest: int, times: dict[str, int], origin: str, fix: tuple[str, int] | None
) -> STNU:
    """The rest of the game as an STNU: what happened is fixed, running contingent links that have not
    ended by tick ``seen`` end after it, unexecuted executables come at ``earliest`` or later."""
    reqs = list(stnu.requirements)
    conts = []
    for x, tx in times.items():
        reqs.append(RequirementLink(origin, x, tx, tx))
    for c in stnu.contingents:
        if c.target in times:
            continue
        if c.source in times:
            conts.append(ContingentLink(c.source, c.target, max(c.lb, seen - times[c.source] + 1), c.ub))
        else:
            conts.append(c)
    contingent = stnu.contingent_timepoints
    for x in stnu.timepoints:
        if x not in times and x not in contingent:
            if fix is not None and fix[0] == x:
                reqs.append(RequirementLink(origin, x, fix[1], fix[1]))
            else:
                reqs.append(RequirementLink(origin, x, earliest, None))
    return STNU((origin, *stnu.timepoints), tuple(reqs), tuple(conts))


def _dispatch(stnu: STNU, rng: random.Random) -> dict[str, int]:
    """Execute a DC network online: nature draws integer durations; the agent executes a timepoint
    at tick t as soon as the rest of the game stays DC (checked with `check_dc` on the residual game)."""
    origin = "__origin__"
    horizon = 2 + sum(abs(b) for r in stnu.requirements for b in (r.lb, r.ub) if b is not None) + sum(
        c.ub for c in stnu.contingents)
    duration = {c.target: rng.randint(c.lb, c.ub) for c in stnu.contingents}
    activation = {c.target: c.source for c in stnu.contingents}
    times: dict[str, int] = {}
    for t in range(horizon + 1):
        for c, a in activation.items():  # nature first
            if a in times and c not in times and times[a] + duration[c] == t:
                times[c] = t
        progress = True
        while progress:
            progress = False
            for x in stnu.timepoints:
                if x in times or x in activation:
                    continue
                if check_dc(_residual(stnu, t, t, times, origin, (x, t))).verdict is Verdict.DC:
                    times[x] = t
                    progress = True
        if len(times) == len(stnu.timepoints):
            return times
        assert check_dc(_residual(stnu, t, t + 1, times, origin, None)).verdict is Verdict.DC
    raise AssertionError("dispatch did not finish before the horizon")


@FAST
@given(stnus(max_nodes=5, max_contingent=2, max_requirements=6), st.randoms(use_true_random=False))
def test_dc_networks_dispatch_without_violations(stnu: STNU, rng: random.Random) -> None:
    if check_dc(stnu).verdict is not Verdict.DC:
        return
    times = _dispatch(stnu, rng)
    for e in distance_edges(stnu):
        assert times[e.target] - times[e.source] <= e.value, (e, times)


@st.composite
def medium_stnus(draw) -> STNU:
    """10-40 timepoints, up to a third of them contingent: too big for the oracle."""
    n = draw(st.integers(10, 40))
    names = tuple(f"T{i}" for i in range(n))
    order = draw(st.permutations(names))
    conts = []
    for i in range(draw(st.integers(1, n // 3))):
        lb = draw(st.integers(0, 10))
        conts.append(ContingentLink(order[2 * i], order[2 * i + 1], lb, lb + draw(st.integers(0, 15))))
    reqs = []
    for _ in range(draw(st.integers(n // 2, 2 * n))):
        a, b = draw(st.sampled_from(names)), draw(st.sampled_from(names))
        lb = draw(st.one_of(st.none(), st.integers(-5, 10)))
        ub = draw(st.one_of(st.none(), st.integers(5, 80)))
        if a != b:
            reqs.append(RequirementLink(a, b, None if lb is not None and ub is not None and lb > ub else lb, ub))
    return STNU(names, tuple(reqs), tuple(conts))


@settings(max_examples=200, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(medium_stnus())
def test_dc_algorithms_agree_on_medium_networks(stnu: STNU) -> None:
    verdicts = {name: check_dc(stnu, name).verdict.value for name in ALGORITHMS}
    verdicts["rul2021 in Python"] = rul2021_check(stnu, accelerated=False)[0]
    assert len(set(verdicts.values())) == 1, verdicts


@pytest.mark.skipif(rul._CORE is None, reason="rul2021's C core is not built (no C compiler at install time)")
@settings(max_examples=1000, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(st.one_of(stnus(max_nodes=7, max_contingent=3, max_requirements=10), medium_stnus()))
def test_rul2021_c_core_agrees_with_python(stnu: STNU) -> None:
    """The C core decides check_dc's verdict; the Python implementation explains it: they must agree."""
    python = rul2021_check(stnu, accelerated=False)[0]
    assert rul._core_verdict(stnu) == python
    result = check_dc(stnu)
    assert result.verdict.value == python and (result.cycle == ()) is (python == "DC")
    # numbers past 64 bits (HEATlab's exact decimals scale to such) take the core's 128-bit path
    f = 2**70 + 1
    big = STNU(stnu.timepoints, tuple(RequirementLink(r.source, r.target, None if r.lb is None else r.lb * f,
                                                      None if r.ub is None else r.ub * f) for r in stnu.requirements),
               tuple(ContingentLink(c.source, c.target, c.lb * f, c.ub * f) for c in stnu.contingents))
    assert rul._core_verdict(big) == python


@FAST
@given(stnus(max_nodes=6, max_contingent=0, max_requirements=10))
def test_earliest_times_agree_with_all_pairs_windows(stnu: STNU) -> None:
    """The single-target earliest times equal -D[x, origin] of APSP, with every x after the origin."""
    origin = stnu.timepoints[0]
    anchored = STNU(stnu.timepoints, stnu.requirements + tuple(
        RequirementLink(origin, t, 0, None) for t in stnu.timepoints[1:]))
    got = earliest_times(stnu, origin)
    if not check_consistency(anchored).consistent:
        assert got is None
        return
    windows = time_windows(anchored, origin)
    assert got == {t: windows[t].lo for t in stnu.timepoints}


@pytest.mark.skipif(rul.native_library() is None, reason="the native core is not built (no C compiler at install time)")
@FAST
@given(stnus(max_nodes=7, max_contingent=3, max_requirements=10), st.sampled_from(["", "ub", "mid"]))
def test_native_earliest_times_are_the_python_ones(stnu: STNU, fix: str) -> None:
    """`hrc.compile.classify._earliest` reads the compiler's schedules off the native core
    (``_stncore.c``); its Python reference must give the same times, or None on the same networks. The
    first timepoint plays the origin; networks where some timepoint must come before it included."""
    from hrc.compile import classify
    from hrc.compile.temporal_net_creator import ORIGIN

    named = STNU(tuple(ORIGIN if t == stnu.timepoints[0] else t for t in stnu.timepoints),
                 tuple(RequirementLink(ORIGIN if r.source == "T0" else r.source, ORIGIN if r.target == "T0"
                                       else r.target, r.lb, r.ub) for r in stnu.requirements),
                 tuple(ContingentLink(ORIGIN if c.source == "T0" else c.source, ORIGIN if c.target == "T0"
                                      else c.target, c.lb, c.ub) for c in stnu.contingents))
    assert classify._earliest(named, fix) == classify._earliest_python(named, fix)  # type: ignore[arg-type]


@pytest.mark.skipif(rul.native_library() is None, reason="the native core is not built (no C compiler at install time)")
@FAST
@given(stnus(max_nodes=7, max_contingent=3, max_requirements=10), st.sampled_from(["", "ub"]))
def test_native_shortest_distances_are_scipy_and_the_lp(stnu: STNU, fix: str) -> None:
    """The native Floyd-Warshall (`motion_pattern._apsp`) against scipy's on the same edges, and the
    native consistency check (`motion_pattern._consistent`) against the LP oracle."""
    from hrc.compile import motion_pattern as mp

    src, dst, wt = mp._distance_graph(stnu, fix, False)
    native, reference = mp._apsp(stnu, fix), mp._apsp_scipy(len(stnu.timepoints), src, dst, wt)
    assert (native is None) == (reference is None)
    if native is not None and reference is not None:
        assert np.array_equal(native, reference)
    assert mp._consistent(stnu) == lp_consistent(stnu)


@pytest.mark.skipif(rul.native_library() is None, reason="the native core is not built (no C compiler at install time)")
@FAST
@given(stnus(max_nodes=7, max_contingent=3, max_requirements=10))
def test_lower_bound_reading_is_the_network_with_lower_bounds_as_links(stnu: STNU) -> None:
    """`classify.packed_lower_bounds` (the search's "robust" reading, `motion_pattern._Routing.robust`)
    against scipy on the network its docstring describes, built as links: every contingent duration as a
    requirement link with its lower bound and no upper bound."""
    from hrc.compile import classify
    from hrc.compile import motion_pattern as mp
    from hrc.temporal.native_stn import native_apsp

    packed = classify.packed_lower_bounds(stnu)
    lows = tuple(RequirementLink(c.source, c.target, c.lb, None) for c in stnu.contingents)
    built = STNU(stnu.timepoints, stnu.requirements + lows, (), stnu.name)
    reference = mp._apsp_scipy(len(built.timepoints), *mp._distance_graph(built, "", False))
    if packed is None:  # a link from a timepoint to itself: the caller takes the lists
        assert any(r.source == r.target for r in stnu.requirements)
        return
    found = native_apsp(len(stnu.timepoints), *packed)
    assert found is not None
    assert found[0] == (reference is not None)
    if reference is not None:
        assert np.array_equal(found[1], reference)


@FAST
@given(stnus(max_nodes=6, max_contingent=2, max_requirements=8), st.data())
def test_derived_networks_arrays_are_those_read_in_full(stnu: STNU, data) -> None:
    """A network derived by `STNU.truncated` / `STNU.inserted` from one whose arrays are kept gets its
    index arrays and its packing by cutting and splicing the parent's (`rul.edge_arrays`,
    `classify._packed`): the same as reading the network, built in full from the same links, from
    scratch; also along a chain of derivations, with loops and weights the native core refuses."""
    from hrc.compile import classify
    from hrc.temporal.native_stn import MAX_WEIGHT

    names = stnu.timepoints
    net = stnu
    if data.draw(st.booleans()):  # the parent read first (otherwise nothing to derive from)
        rul.edge_arrays(net)
        classify.packed_graph(net)
    for _ in range(data.draw(st.integers(1, 3))):
        if data.draw(st.booleans()):
            n = data.draw(st.integers(0, len(net.requirements)))
            child = net.truncated(n)
            reqs = net.requirements[:n]
        else:
            at = data.draw(st.integers(0, len(net.requirements)))
            weights = st.one_of(st.none(), st.integers(0, 8), st.just(MAX_WEIGHT))  # upper bounds, >= 0
            added = tuple(RequirementLink(data.draw(st.sampled_from(names)), data.draw(st.sampled_from(names)),
                                          data.draw(st.one_of(st.none(), st.integers(-5, 0))), data.draw(weights))
                          for _ in range(data.draw(st.integers(0, 3))))
            child = net.inserted(at, added)
            reqs = net.requirements[:at] + added + net.requirements[at:]
        built = STNU(names, reqs, stnu.contingents, stnu.name)
        assert rul.edge_arrays(child) == rul._edge_arrays(built)
        assert classify._packed(child) == classify._pack(built)
        net = child


@pytest.mark.skipif(rul.native_library() is None, reason="the native core is not built (no C compiler at install time)")
@FAST
@given(st.integers(1, 6), st.integers(-3, 9), st.booleans(), st.booleans())
def test_native_cores_refuse_an_index_outside_the_network(n: int, bad: int, at_source: bool, as_z: bool) -> None:
    """An edge end (or the target z) outside 0..n-1 would make the C core read and write outside its
    arrays: it refuses before touching them, and the wrappers raise; every index inside is answered."""
    from hrc.temporal.native_stn import native_apsp, native_distances

    inside = 0 <= bad < n
    if as_z:
        calls = [lambda: native_distances(n, [0], [n - 1], [1], bad)]
    else:
        src, dst = ([bad], [0]) if at_source else ([0], [bad])
        calls = [lambda: native_distances(n, src, dst, [1], None), lambda: native_apsp(n, src, dst, [1])]
    for call in calls:
        if inside:
            assert call() is not None
        else:
            with pytest.raises(ValueError, match="outside"):
                call()
