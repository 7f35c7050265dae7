"""Hand-worked cases for the temporal core: validation, STN algorithms, DC verdicts and explanations."""

from __future__ import annotations

import math

import pytest

import hrc.temporal as T
from hrc.temporal import (
    STNU,
    ContingentLink,
    EdgeKind,
    NetworkError,
    RequirementLink,
    Verdict,
    Window,
    all_pairs_shortest_paths,
    check_consistency,
    check_dc,
    minimal_dispatchable_network,
    propagate_execution,
    time_windows,
)
from hrc.temporal.dc import ALGORITHMS
from hrc.temporal.graph import labelled_edges
from hrc.temporal.oracle import oracle_is_dc
from hrc.temporal.ticks import scale_to_integers, to_ticks

R, C = RequirementLink, ContingentLink

# name -> (network, expected verdict); each worked by hand, comments give the reason
CASES: dict[str, tuple[STNU, Verdict]] = {
    # X must come 1..2 before C, but C is only seen when it happens
    "wait-before-contingent": (STNU(("A", "C", "X"), (R("X", "C", 1, 2),), (C("A", "C", 1, 10),)), Verdict.NOT_DC),
    # X within 0..2 after C: wait for C, then act
    "react-after-contingent": (STNU(("A", "C", "X"), (R("C", "X", 0, 2),), (C("A", "C", 1, 10),)), Verdict.DC),
    # the requirement C - A >= 5 fails when nature picks 1..4
    "squeezed-duration": (STNU(("A", "C"), (R("A", "C", 5, None),), (C("A", "C", 1, 10),)), Verdict.NOT_DC),
    # X - A in [0, 3] and X <= C: X can go at A + 0..1 (C >= A + 1): DC
    "early-enough": (STNU(("A", "C", "X"), (R("A", "X", 0, 3), R("X", "C", 0, None)), (C("A", "C", 1, 10),)),
                     Verdict.DC),
    # A + 5 <= X <= C: C may come at A + 1
    "too-late": (STNU(("A", "C", "X"), (R("A", "X", 5, None), R("X", "C", 0, None)), (C("A", "C", 1, 10),)),
                 Verdict.NOT_DC),
    # the STN itself is infeasible: C - A <= 0 against a duration >= 1
    "inconsistent": (STNU(("A", "C"), (R("A", "C", None, 0),), (C("A", "C", 1, 10),)), Verdict.INCONSISTENT),
    # two contingent links in a chain, with a deadline only on the total: DC iff 3 + 4 <= deadline
    "chain-ok": (STNU(("A", "B", "C"), (R("A", "C", 0, 7),), (C("A", "B", 1, 3), C("B", "C", 2, 4))), Verdict.DC),
    "chain-tight": (STNU(("A", "B", "C"), (R("A", "C", 0, 6),), (C("A", "B", 1, 3), C("B", "C", 2, 4))),
                    Verdict.NOT_DC),
    # the robot (X) must finish within 2 after the human's action (A->C), and may not start before A
    "sync-end": (STNU(("A", "C", "X", "Y"), (R("A", "X", 0, None), R("X", "Y", 3, 3), R("C", "Y", 0, 2)),
                      (C("A", "C", 4, 5),)), Verdict.DC),
    "sync-end-wide": (STNU(("A", "C", "X", "Y"), (R("A", "X", 0, None), R("X", "Y", 3, 3), R("C", "Y", 0, 2)),
                           (C("A", "C", 2, 8),)), Verdict.NOT_DC),
    # Y must come exactly 3 before C, which nature places: the forward check for C's own lower-case edge
    # (A --c:1--> C --(-3)--> Y bypasses it, and Y --3--> C --C:-10--> A closes a negative cycle)
    "pinned-before-contingent": (STNU(("A", "C", "Y"), (R("Y", "C", 3, 3),), (C("A", "C", 1, 10),)),
                                 Verdict.NOT_DC),
    # the requirement C - A <= 5 caps a duration nature may stretch to 10 (consistent, not DC)
    "duration-capped": (STNU(("A", "C"), (R("A", "C", None, 5),), (C("A", "C", 1, 10),)), Verdict.NOT_DC),
    # two links from one activation; X within 4 after both ends: wait for both (they differ by <= 4)
    "shared-activation": (STNU(("A", "B", "C", "X"), (R("B", "X", 0, 4), R("C", "X", 0, 4)),
                               (C("A", "B", 1, 3), C("A", "C", 2, 5))), Verdict.DC),
    # an STN (no contingent link) is DC iff consistent
    "stn": (STNU(("A", "B"), (R("A", "B", 1, 2),)), Verdict.DC),
}


@pytest.mark.parametrize("algorithm", sorted(ALGORITHMS))
@pytest.mark.parametrize("name", sorted(CASES))
def test_named_cases(name: str, algorithm: str) -> None:
    stnu, expected = CASES[name]
    result = check_dc(stnu, algorithm)
    assert result.verdict is expected
    assert result.consistent is (expected is not Verdict.INCONSISTENT)
    assert (result.cycle == ()) is (expected is Verdict.DC)
    assert oracle_is_dc(stnu) is (expected is Verdict.DC)


@pytest.mark.parametrize("algorithm", sorted(ALGORITHMS))
@pytest.mark.parametrize("name", sorted(CASES))
def test_cycles_explain_the_verdict(name: str, algorithm: str) -> None:
    stnu, expected = CASES[name]
    result = check_dc(stnu, algorithm)
    if expected is Verdict.DC:
        return
    graph = set(labelled_edges(stnu))
    cycle = result.cycle
    assert sum(e.value for e in cycle) < 0
    for a, b in zip(cycle, cycle[1:] + cycle[:1], strict=True):
        assert a.target == b.source  # a closed walk
    for e in cycle:  # derived edges are expanded back to edges of the network
        assert e.kind is not EdgeKind.DERIVED and e in graph
        assert e.source in str(e) and e.target in str(e) and str(e.value) in str(e)
    if expected is Verdict.INCONSISTENT:
        assert all(e.kind is EdgeKind.ORDINARY for e in cycle)


def test_cycle_str_names_the_contingent_label() -> None:
    stnu, _ = CASES["wait-before-contingent"]
    text = [str(e) for e in check_dc(stnu).cycle]
    assert "A --[lc(C):1]--> C" in text and "C --[UC(C):-10]--> A" in text


def test_public_names_match_all() -> None:
    for name in T.__all__:
        assert hasattr(T, name)
    assert {"STNU", "RequirementLink", "ContingentLink", "Verdict", "DCResult", "check_dc",
            "check_consistency"} <= set(T.__all__)


@pytest.mark.parametrize(
    "build, message",
    [
        (lambda: STNU(("A",), (R("A", "B", 0, 1),)), "unknown timepoint"),
        (lambda: STNU(("A", "A"),), "listed twice"),
        (lambda: R("A", "B", 3, 2), "lb 3 > ub 2"),
        (lambda: C("A", "B", 3, 2), "0 <= lb <= ub"),
        (lambda: C("A", "B", -1, 2), "0 <= lb <= ub"),
        (lambda: C("A", "A", 1, 2), "loop"),
        (lambda: R("A", "B", 1.5, 2), "integer"),
        (lambda: STNU(("A", "B", "C"), (), (C("A", "C", 1, 2), C("B", "C", 1, 2))), "target of two contingent"),
        (lambda: STNU(("A", "B"), (C("A", "B", 1, 2),)), "RequirementLink"),
        (lambda: STNU(("A", "B"), (), (R("A", "B", 1, 2),)), "ContingentLink"),
        (lambda: STNU(("A", "B"), ("A->B",)), "not a link"),  # type: ignore[arg-type]
        (lambda: STNU(("B",), (), (C("A", "B", 1, 2),)), "unknown timepoint 'A'"),
        (lambda: STNU(("A", "B"), (R("A", "B", 0, 1),), (C("A", "C", 1, 2),)), "unknown timepoint 'C'"),
    ],
)
def test_validation_rejects_bad_networks(build, message: str) -> None:
    with pytest.raises(NetworkError, match=message):
        build()


def test_network_is_immutable_and_hashable() -> None:
    stnu, _ = CASES["chain-ok"]
    with pytest.raises(AttributeError):
        stnu.name = "x"  # type: ignore[misc]
    assert hash(stnu) == hash(STNU(stnu.timepoints, stnu.requirements, stnu.contingents))
    assert STNU(["A", "B"], [R("A", "B", 0, 1)]).timepoints == ("A", "B")  # lists become tuples


def test_consistency_solution_and_cycle() -> None:
    ok = STNU(("A", "B", "C"), (R("A", "B", 2, 4), R("B", "C", 1, 1), R("A", "C", None, 4)))
    res = check_consistency(ok)
    assert res.consistent and res.solution is not None
    t = res.solution
    assert 2 <= t["B"] - t["A"] <= 4 and t["C"] - t["B"] == 1 and t["C"] - t["A"] <= 4
    bad = STNU(("A", "B", "C"), (R("A", "B", 2, 4), R("B", "C", 1, 1), R("A", "C", None, 2)))
    res = check_consistency(bad)
    assert not res.consistent and sum(e.value for e in res.cycle) == -1


def test_apsp_windows_and_propagation() -> None:
    stn = STNU(("O", "A", "B"), (R("O", "A", 1, 5), R("A", "B", 2, 3), R("O", "B", None, 6)))
    d = all_pairs_shortest_paths(stn)
    assert d[0, 2] == 6 and d[2, 0] == -3 and d[0, 1] == 4 and d[1, 0] == -1
    win = time_windows(stn, "O")
    assert win == {"O": Window(0, 0), "A": Window(1, 4), "B": Window(3, 6)}
    net = minimal_dispatchable_network(stn)
    after = propagate_execution(win, net.edges, "A", 2)
    assert after["A"] == Window(2, 2) and after["B"] == Window(4, 5)
    with pytest.raises(NetworkError):
        time_windows(stn, "nope")
    with pytest.raises(NetworkError):
        all_pairs_shortest_paths(CASES["inconsistent"][0])
    unbounded = time_windows(STNU(("O", "A"), (R("O", "A", 0, None),)), "O")
    assert unbounded["A"] == Window(0, None) and math.isinf(all_pairs_shortest_paths(
        STNU(("O", "A"), (R("O", "A", 0, None),)))[0, 1])


def test_minimal_dispatchable_network_drops_dominated_edges() -> None:
    # A->B->C chain with a redundant A->C bound: the A->C upper edge is dominated via B
    stn = STNU(("A", "B", "C"), (R("A", "B", 1, 2), R("B", "C", 1, 2), R("A", "C", 0, 10)))
    edges = {(e.source, e.target): e.value for e in minimal_dispatchable_network(stn).edges}
    assert edges == {("A", "B"): 2, ("B", "A"): -1, ("B", "C"): 2, ("C", "B"): -1}


def test_minimal_dispatchable_network_collapses_rigid_components() -> None:
    stn = STNU(("A", "B", "C"), (R("A", "B", 3, 3), R("A", "C", 1, 5), R("B", "C", None, 1)))
    net = minimal_dispatchable_network(stn)
    pairs = {(e.source, e.target): e.value for e in net.edges}
    assert pairs[("A", "B")] == 3 and pairs[("B", "A")] == -3


def test_dc_result_added_edges() -> None:
    stnu = STNU(("A", "C", "X", "Y"), (R("X", "Y", None, -1), R("C", "X", 0, 3)), (C("A", "C", 2, 6),))
    result = check_dc(stnu, "morris2014")
    assert result.verdict is Verdict.DC
    assert all(e.kind is EdgeKind.DERIVED and e.value >= 0 for e in result.added)  # Morris's waits
    # X must follow C by at most 3 and precede Y: the bypass of A --c:2--> C gives A --(2 - 3)--> ...
    assert check_dc(stnu, "bypass").verdict is Verdict.DC


def test_unknown_algorithm() -> None:
    with pytest.raises(KeyError):
        check_dc(CASES["stn"][0], "nope")


def test_ticks() -> None:
    assert to_ticks(1.2345, 1000) == 1234  # exact decimal value, ties to even
    assert to_ticks(0.1, 10) == 1 and to_ticks(2.5, 2) == 5
    with pytest.raises(ValueError):
        to_ticks(math.inf)
    assert scale_to_integers(["0.1", "0.25", "3"]) == ([2, 5, 60], 20)
    assert scale_to_integers([]) == ([], 1)


def test_derived_networks_are_the_networks_built_in_full():
    """`STNU.truncated` and `STNU.inserted` skip checking what was checked already; the network built
    from the same parts (and checked in full) is the truth, and a bad inserted link is still refused."""
    net = STNU(("Z", "A", "B"), (R("Z", "A", 0, 5), R("A", "B", 1, None)), (C("Z", "B", 1, 3),), "n")
    assert net.truncated(1) == STNU(("Z", "A", "B"), (R("Z", "A", 0, 5),), (C("Z", "B", 1, 3),), "n")
    added = (R("Z", "B", 2, None), R("B", "A", None, 4))
    built = STNU(("Z", "A", "B"), (R("Z", "A", 0, 5), *added, R("A", "B", 1, None)), (C("Z", "B", 1, 3),), "n")
    assert net.inserted(1, added) == built and hash(net.inserted(1, added)) == hash(built)
    with pytest.raises(NetworkError, match="unknown timepoint 'Q'"):
        net.inserted(0, (R("Z", "Q", 1, None),))
    with pytest.raises(NetworkError, match="must hold RequirementLink"):
        net.inserted(0, (C("A", "B", 1, 2),))  # type: ignore[arg-type]
