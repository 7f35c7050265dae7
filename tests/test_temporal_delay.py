"""Controllability under observation delay (hrc.temporal.delay) against independent truths.

* a brute-force imperfect-information game over belief states (`oracle_is_delay_controllable`), on tiny
  integer networks with fixed, variable and infinite delays;
* delay 0 is today's DC check: the reduction is the identity and the verdicts match, on every shared
  benchmark instance and every compiled workshop STNU;
* unbounded delay, and a delay beyond the horizon of a network with an origin, is strong controllability
  decided by an LP over the vertices of the durations' box (scipy), not by the reduction;
* the verdict is monotone in the delay;
* a network declared controllable, executed through `delay_window` against random and extreme durations and
  delays, with observations arriving late, never breaks a link.
"""

from __future__ import annotations

import itertools
import random
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog

from hrc.temporal.dc import Verdict, check_dc
from hrc.temporal.delay import (
    NEVER,
    ZERO,
    DelayError,
    ObservationDelay,
    _fast_verdict,
    check_delay,
    delay_window,
    delayed_network,
)
from hrc.temporal.execution import ExecutionWindow
from hrc.temporal.graph import Edge
from hrc.temporal.graphml import read_network
from hrc.temporal.network import STNU, ContingentLink, RequirementLink
from hrc.temporal.oracle import oracle_is_dc, oracle_is_delay_controllable
from tests.test_temporal_benchmarks import BENCH, _rows, needs_shared

FAST = settings(max_examples=120, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
R, C = RequirementLink, ContingentLink


@st.composite
def tiny(draw, max_nodes: int = 5, max_requirements: int = 5) -> STNU:
    """2-5 timepoints, 1-2 contingent links (lower bound >= 1, the oracles' condition), small bounds."""
    n = draw(st.integers(2, max_nodes))
    names = tuple(f"T{i}" for i in range(n))
    order = draw(st.permutations(names))
    conts = []
    for i in range(draw(st.integers(1, min(2, n // 2)))):
        lb = draw(st.integers(1, 3))
        conts.append(C(order[2 * i], order[2 * i + 1], lb, lb + draw(st.integers(0, 3))))
    reqs = []
    executable = [v for v in names if v not in {c.target for c in conts}]
    for c in conts:  # a reaction to the contingent timepoint: where an observation delay bites
        if draw(st.booleans()):
            lb = draw(st.integers(-1, 1))
            reqs.append(R(c.target, draw(st.sampled_from(executable)), lb, lb + draw(st.integers(0, 3))))
    for _ in range(draw(st.integers(0, max_requirements))):
        a, b = draw(st.sampled_from(names)), draw(st.sampled_from(names))
        lb = draw(st.one_of(st.none(), st.integers(-4, 5)))
        ub = draw(st.one_of(st.none(), st.integers(-4, 7)))
        if lb is not None and ub is not None and lb > ub:
            lb, ub = ub, lb
        if a != b:
            reqs.append(R(a, b, lb, ub))
    return STNU(names, tuple(reqs), tuple(conts))


delay_values = st.one_of(
    st.integers(0, 3).map(lambda g: ObservationDelay(g, g)),
    st.tuples(st.integers(0, 2), st.integers(0, 3)).map(lambda p: ObservationDelay(p[0], p[0] + p[1])),
    st.just(NEVER),
)


def _pairs(delays: dict[str, ObservationDelay]) -> dict[str, tuple[int, int | None]]:
    return {c: (d.lo, d.hi) for c, d in delays.items()}


# ------------------------------------------------------------------------------------ the worked example
def worked_example() -> STNU:
    """docs/temporal.md: the person walks to S (1-3 s, contingent), the robot must start its pass within
    0.2 s after they arrive (ticks: milliseconds)."""
    return STNU(("go", "arrive", "robot"), (R("arrive", "robot", 0, 200),), (C("go", "arrive", 1000, 3000),))


def test_worked_example_is_dc_at_0_and_not_at_half_a_second() -> None:
    net = worked_example()
    assert check_dc(net).verdict is Verdict.DC
    assert check_delay(net, ObservationDelay(0, 0)).verdict is Verdict.DC
    assert check_delay(net, ObservationDelay(200, 200)).verdict is Verdict.DC  # learnt just in time
    late = check_delay(net, ObservationDelay(500, 500))
    assert late.verdict is Verdict.NOT_DC and late.consistent
    # the explanation: the robot's pass must come at most 200 - 500 ms after the arrival is learnt
    assert any(e.source == "arrive@seen" and e.target == "robot" and e.value == -300 for e in late.cycle)
    assert sum(e.value for e in late.cycle) < 0
    assert check_delay(net, NEVER).verdict is Verdict.NOT_DC  # strong controllability: never


def test_hand_worked_reductions() -> None:
    net = worked_example()
    fixed = delayed_network(net, ObservationDelay(500, 500)).network
    assert fixed.contingents == (C("go", "arrive@seen", 1500, 3500),)
    assert fixed.requirements == (R("arrive@seen", "robot", -500, -300),)
    # variable [0.1, 0.4] s: learnt 1.4 s to 3.1 s after "go"; the arrival lies in [seen - 0.4, seen - 0.1],
    # so "robot - arrive in [0, 0.2]" asks robot - seen in [-0.1, -0.2]: nature breaks it
    var = delayed_network(net, ObservationDelay(100, 400))
    assert var.network.contingents == (C("go", "arrive@seen", 1400, 3100),)
    assert var.network.requirements == () and len(var.broken) == 1
    # a delay spread at least as wide as the duration's tells nothing: substituted (Vidal & Fargier); then
    # robot - go must be >= 3 s (latest arrival) and <= 1.2 s (earliest arrival + 0.2): broken
    wide = delayed_network(net, ObservationDelay(0, 2000))
    assert wide.substituted == {"arrive"} and wide.network.timepoints == ("go", "robot")
    assert wide.broken == ((Edge("go", "robot", 1200), Edge("robot", "go", -3000)),)


def test_variable_reduction_bounds() -> None:
    """T(robot) - T(arrive) in [0, 200] for every arrival in [seen - hi, seen - lo]: [hi, 200 + lo]."""
    net = STNU(("go", "arrive", "robot"), (R("arrive", "robot", 0, 900),), (C("go", "arrive", 1000, 3000),))
    var = delayed_network(net, ObservationDelay(100, 400))
    assert var.network.requirements == (R("arrive@seen", "robot", -100, 500),)
    assert var.network.contingents == (C("go", "arrive@seen", 1400, 3100),)
    narrow = delayed_network(worked_example(), ObservationDelay(100, 400))
    assert narrow.broken and narrow.network.requirements == ()
    assert check_delay(worked_example(), ObservationDelay(100, 400)).verdict is Verdict.NOT_DC


def test_bad_delays_are_refused() -> None:
    for lo, hi in ((-1, 2), (3, 2), (1.5, 2)):
        with pytest.raises(DelayError):
            ObservationDelay(lo, hi)  # type: ignore[arg-type]
    with pytest.raises(DelayError, match="not a contingent"):
        check_delay(worked_example(), {"robot": ZERO})


def test_chains() -> None:
    """A contingent link activated by a contingent timepoint: fixed delays are exact renaming."""
    net = STNU(("A", "B", "C", "X"), (R("C", "X", 0, 1),), (C("A", "B", 1, 2), C("B", "C", 1, 2)))
    d = {"B": (1, 1), "C": (1, 1)}
    got = check_delay(net, {k: ObservationDelay(*v) for k, v in d.items()}).verdict is Verdict.DC
    assert got is oracle_is_delay_controllable(net, d)
    with pytest.raises(DelayError):
        delayed_network(net, {"B": ObservationDelay(0, 1), "C": ObservationDelay(1, 1)})
    never = check_delay(net, NEVER).verdict is Verdict.DC
    assert never is oracle_is_delay_controllable(net, {"B": (0, None), "C": (0, None)})


# ------------------------------------------------------------------------------------ the game oracle
@FAST
@given(tiny(), st.data())
def test_agrees_with_the_brute_force_game(stnu: STNU, data: st.DataObject) -> None:
    delays = {c.target: data.draw(delay_values) for c in stnu.contingents}
    try:
        expected = oracle_is_delay_controllable(stnu, _pairs(delays), max_states=200_000)
    except RuntimeError:
        return
    assert (check_delay(stnu, delays).verdict is Verdict.DC) is expected, (stnu, delays)


@settings(max_examples=100, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(tiny(max_nodes=4))
def test_the_game_at_delay_0_is_the_dc_game(stnu: STNU) -> None:
    assert oracle_is_delay_controllable(stnu, {}) is oracle_is_dc(stnu)


def test_delay_matters_in_such_networks() -> None:
    """The agreement above is not vacuous: on networks drawn as `tiny` draws them, delays often cost the DC
    verdict, and the game agrees each time."""
    rng = random.Random(7)
    lost = 0
    for _ in range(150):
        stnu = _random_tiny(rng)
        if check_dc(stnu).verdict is Verdict.DC and check_delay(stnu, ObservationDelay(2, 2)).verdict is not Verdict.DC:
            lost += 1
            assert not oracle_is_delay_controllable(stnu, {c.target: (2, 2) for c in stnu.contingents})
    assert lost >= 15


def _random_tiny(rng: random.Random) -> STNU:
    n = rng.randint(3, 5)
    names = tuple(f"T{i}" for i in range(n))
    order = list(names)
    rng.shuffle(order)
    lb = rng.randint(1, 3)
    conts = (C(order[0], order[1], lb, lb + rng.randint(0, 3)),)
    low = rng.randint(-1, 1)
    reqs = [R(order[1], rng.choice(order[2:]), low, low + rng.randint(0, 3))]
    for _ in range(rng.randint(0, 3)):
        a, b = rng.sample(names, 2)
        reqs.append(R(a, b, rng.choice([None, rng.randint(-3, 3)]), rng.choice([None, rng.randint(3, 6)])))
    return STNU(names, tuple(reqs), conts)


# ------------------------------------------------------------------------------------ delay 0 is DC
def _assert_zero_is_dc(stnu: STNU) -> None:
    reduced = delayed_network(stnu, ZERO)
    assert reduced.network == stnu and not reduced.substituted and not reduced.broken
    expected = check_dc(stnu).verdict
    assert check_delay(stnu, ZERO).verdict is expected
    fast = _fast_verdict(stnu, {c.target: ZERO for c in stnu.contingents})
    assert fast in (None, expected.value)


@needs_shared
def test_delay_0_is_dc_on_every_benchmark_instance() -> None:
    rows = _rows()
    assert len(rows) >= 500
    for row in rows:
        _assert_zero_is_dc(read_network(BENCH / row["file"]))


@needs_shared
def test_small_delays_on_benchmark_instances_never_gain_controllability() -> None:
    """Monotone on outside instances: DC at 1 tick only if DC at 0; the fast verdict equals the reduction's."""
    for row in _rows()[::7]:
        stnu = read_network(BENCH / row["file"])
        if len(stnu.timepoints) > 300:
            continue
        zero = check_dc(stnu).verdict
        one = check_delay(stnu, ObservationDelay(1, 1))
        if one.verdict is Verdict.DC:
            assert zero is Verdict.DC, row["file"]
        assert (one.verdict is Verdict.INCONSISTENT) is (zero is Verdict.INCONSISTENT)
        reduced = check_dc(delayed_network(stnu, ObservationDelay(1, 1)).network).verdict
        assert (reduced is Verdict.DC) is (one.verdict is Verdict.DC), row["file"]


@pytest.mark.slow
def test_delay_0_is_dc_on_the_workshops_stnus(workshop_stnus: list[STNU]) -> None:
    assert len(workshop_stnus) == 32
    for stnu in workshop_stnus:
        _assert_zero_is_dc(stnu)


@pytest.fixture(scope="module")
def workshop_stnus(tmp_path_factory: pytest.TempPathFactory) -> list[STNU]:
    from tests.conftest import compiled_folder

    out = compiled_folder(tmp_path_factory.mktemp("ws") / "out")
    return [read_network(p) for p in sorted((out / "stnu").glob("*.graphml"))]


# ------------------------------------------------------------------------------------ strong controllability
def lp_strongly_controllable(stnu: STNU) -> bool:
    """One schedule of the executable timepoints meeting every link for every vertex of the durations' box
    (links are linear in the durations, so every point of the box then too): an LP, no reduction."""
    conts = {c.target: c for c in stnu.contingents}
    execs = [v for v in stnu.timepoints if v not in conts]
    col = {v: i for i, v in enumerate(execs)}
    rows: list[list[float]] = []
    rhs: list[float] = []

    def expr(v: str, omega: dict[str, int]) -> tuple[dict[int, float], int]:
        const = 0
        while v in conts:
            const += omega[v]
            v = conts[v].source
        return {col[v]: 1.0}, const

    for vertex in itertools.product(*[(c.lb, c.ub) for c in stnu.contingents]):
        omega = dict(zip(conts, vertex, strict=True))
        for r in stnu.requirements:
            (s, cs), (t, ct) = expr(r.source, omega), expr(r.target, omega)
            for sign, bound in ((1, r.ub), (-1, None if r.lb is None else -r.lb)):
                if bound is None:
                    continue
                row = [0.0] * len(execs)
                for i, a in t.items():
                    row[i] += sign * a
                for i, a in s.items():
                    row[i] -= sign * a
                rows.append(row)
                rhs.append(bound - sign * (ct - cs))
    if not execs:
        return all(b >= 0 for b in rhs)
    res = linprog([0.0] * len(execs), A_ub=rows or None, b_ub=rhs or None, bounds=[(None, None)] * len(execs),
                  method="highs")
    assert res.status in (0, 2)
    return bool(res.status == 0)


@FAST
@given(tiny(max_nodes=6, max_requirements=7))
def test_never_observed_is_strong_controllability(stnu: STNU) -> None:
    assert (check_delay(stnu, NEVER).verdict is Verdict.DC) is lp_strongly_controllable(stnu)


@FAST
@given(tiny(max_nodes=5, max_requirements=6), st.integers(0, 2))
def test_delay_beyond_the_horizon_is_strong_controllability(stnu: STNU, extra: int) -> None:
    """With an origin Z and every timepoint within [0, H] of it, a fixed delay past H is never in time."""
    horizon = 12
    net = STNU(("Z", *stnu.timepoints), stnu.requirements + tuple(R("Z", v, 0, horizon) for v in stnu.timepoints),
               stnu.contingents)
    beyond = check_delay(net, ObservationDelay(horizon + 1 + extra, horizon + 1 + extra)).verdict is Verdict.DC
    assert beyond is lp_strongly_controllable(net)


# ------------------------------------------------------------------------------------ monotone
@st.composite
def medium(draw) -> STNU:
    n = draw(st.integers(8, 25))
    names = tuple(f"T{i}" for i in range(n))
    order = draw(st.permutations(names))
    conts = []
    for i in range(draw(st.integers(1, n // 3))):
        lb = draw(st.integers(1, 10))
        conts.append(C(order[2 * i], order[2 * i + 1], lb, lb + draw(st.integers(0, 15))))
    reqs = []
    for _ in range(draw(st.integers(n // 2, 2 * n))):
        a, b = draw(st.sampled_from(names)), draw(st.sampled_from(names))
        lb = draw(st.one_of(st.none(), st.integers(-5, 10)))
        ub = draw(st.one_of(st.none(), st.integers(5, 80)))
        if a != b:
            reqs.append(R(a, b, None if lb is not None and ub is not None and lb > ub else lb, ub))
    return STNU(names, tuple(reqs), tuple(conts))


@settings(max_examples=60, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(tiny(), medium()), st.integers(0, 8), st.integers(0, 8), st.integers(0, 8))
def test_verdict_is_monotone_in_the_delay(stnu: STNU, a: int, b: int, c: int) -> None:
    """More delay never makes a network controllable: a later fixed delay, a fixed delay made variable (the
    agent no longer learns when the event happened), a wider range of delays, never learnt."""
    lo, mid, hi = sorted((a, b, c))
    order = [ZERO, ObservationDelay(mid, mid), ObservationDelay(hi, hi), ObservationDelay(mid, hi),
             ObservationDelay(lo, hi), ObservationDelay(0, hi + 1), NEVER]
    dc = [check_delay(stnu, d).verdict is Verdict.DC for d in order]
    for x, y in itertools.pairwise(dc):
        assert x or not y, (stnu, order, dc)
    assert {check_delay(stnu, d).verdict is Verdict.INCONSISTENT for d in order} == {not check_dc(stnu).consistent}


# ------------------------------------------------------------------------------------ the strategy
def run_strategy(stnu: STNU, delays: dict[str, ObservationDelay], rng: random.Random, extreme: bool) -> dict[str, int]:
    """Execute `stnu` tick by tick: nature draws each duration and each observation's delay (at random, or
    at the ends of their ranges); the agent executes an executable timepoint only inside `delay_window`'s
    window (at a random tick of it, at its end at the latest), knowing only what has arrived."""
    conts = {c.target: c for c in stnu.contingents}
    pick = (lambda lo, hi: rng.choice((lo, hi))) if extreme else rng.randint
    duration = {c: pick(link.lb, link.ub) for c, link in conts.items()}
    lag = {c: pick(d.lo, d.hi) for c, d in delays.items() if d.hi is not None}
    times: dict[str, int] = {}
    arrived: dict[str, int] = {}
    horizon = 1 + sum(abs(b) for r in stnu.requirements for b in (r.lb, r.ub) if b is not None) + \
        sum(link.ub for link in conts.values()) + sum(lag.values())
    for now in range(horizon + 8):
        for c, link in conts.items():
            if c not in times and link.source in times and times[link.source] + duration[c] == now:
                times[c] = now
        for c, t in times.items():
            if c in lag and c not in arrived and t + lag[c] == now:
                arrived[c] = now
        progress = True
        while progress:
            progress = False
            for x in stnu.timepoints:
                if x in conts or x in times:
                    continue
                learnt = {**{v: t for v, t in times.items() if v not in conts}, **arrived}
                w = delay_window(stnu, delays, learnt, now, x)
                if isinstance(w, ExecutionWindow):
                    assert w.latest is None or w.latest >= now, (x, w, times)
                    due = now == w.latest or now >= w.earliest + 4 or not times
                    if w.earliest <= now and (due or rng.random() < 0.4):
                        times[x] = now
                        progress = True
        if len(times) == len(stnu.timepoints):
            break
    return times


def _broken(stnu: STNU, times: dict[str, int]) -> list[str]:
    out = []
    for r in stnu.requirements:
        d = times[r.target] - times[r.source]
        if (r.lb is not None and d < r.lb) or (r.ub is not None and d > r.ub):
            out.append(str(r))
    return out


@settings(max_examples=80, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(tiny(max_nodes=5, max_requirements=5), st.data(), st.integers(0, 2**32 - 1), st.booleans())
def test_the_strategy_never_breaks_a_link(stnu: STNU, data: st.DataObject, seed: int, extreme: bool) -> None:
    delays = {c.target: data.draw(delay_values) for c in stnu.contingents}
    if check_delay(stnu, delays).verdict is not Verdict.DC:
        return
    # a bounded network: every timepoint within 40 ticks of the first (else the run could wait forever)
    times = run_strategy(stnu, delays, random.Random(seed), extreme)
    assert len(times) == len(stnu.timepoints), (stnu, delays, times)
    assert _broken(stnu, times) == [], (stnu, delays, times)


def test_the_strategy_on_the_worked_example_waits_for_what_it_learns() -> None:
    net = STNU(("go", "arrive", "robot"), (R("arrive", "robot", 0, 900),), (C("go", "arrive", 1000, 3000),))
    delays = {"arrive": ObservationDelay(500, 500)}
    w = delay_window(net, delays, {"go": 0}, 1200, "robot")  # arrival not learnt: not before 3 s
    assert not isinstance(w, ExecutionWindow) or (w.earliest >= 3000 and w.waits_on == ("arrive",)), w
    w = delay_window(net, delays, {"go": 0, "arrive": 2100}, 2100, "robot")  # arrived at 1.6 s, learnt at 2.1
    assert isinstance(w, ExecutionWindow) and (w.earliest, w.latest) == (2100, 2500)


@pytest.mark.slow
@settings(max_examples=3000, deadline=None, database=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(tiny(max_nodes=6, max_requirements=7), st.data())
def test_agrees_with_the_brute_force_game_at_length(stnu: STNU, data: st.DataObject) -> None:
    test_agrees_with_the_brute_force_game.hypothesis.inner_test(stnu, data)  # type: ignore[attr-defined]


def test_the_strategy_on_networks_where_the_delay_bites() -> None:
    """Networks that need their reaction to a contingent timepoint, controllable at a delay (fixed or
    variable), run by the strategy against extreme and random durations and delays."""
    rng = random.Random(11)
    ran = 0
    for _ in range(120):
        stnu = _random_tiny(rng)
        for d in (ObservationDelay(2, 2), ObservationDelay(1, 3)):
            delays = {c.target: d for c in stnu.contingents}
            if check_delay(stnu, delays).verdict is not Verdict.DC or check_delay(
                    stnu, ObservationDelay(d.hi + 2, d.hi + 2)).verdict is Verdict.DC:  # type: ignore[operator]
                continue  # only networks a longer delay would break
            ran += 1
            for extreme in (True, False):
                times = run_strategy(stnu, delays, random.Random(ran), extreme)
                assert len(times) == len(stnu.timepoints) and _broken(stnu, times) == [], (stnu, d, times)
    assert ran >= 10


def _slow_verdict(stnu: STNU, delays: dict[str, ObservationDelay]) -> Verdict:
    reduced = delayed_network(stnu, delays)
    if not reduced.broken:
        verdict = check_dc(reduced.network, "bypass").verdict
        if verdict is not Verdict.INCONSISTENT:
            return verdict
    return Verdict.NOT_DC if check_dc(stnu.as_stn(), "bypass").consistent else Verdict.INCONSISTENT


@FAST
@given(st.one_of(tiny(), medium()), st.data())
def test_the_fast_verdict_is_the_reductions(stnu: STNU, data: st.DataObject) -> None:
    """`check_delay` decides on index arrays in C; the reduction as an STNU, checked by another DC algorithm
    (bypass), says the same."""
    wide = st.one_of(delay_values, st.tuples(st.integers(0, 20), st.integers(0, 20)).map(
        lambda p: ObservationDelay(min(p), max(p))))
    delays = {c.target: data.draw(wide) for c in stnu.contingents}
    assert check_delay(stnu, delays).verdict is _slow_verdict(stnu, delays)
    if check_delay(stnu, delays).verdict is Verdict.NOT_DC:
        assert sum(e.value for e in check_delay(stnu, delays).cycle) < 0


# ------------------------------------------------------------------------------------ hrc check --observation-delay
def test_hrc_check_observation_delay(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import json

    from hrc.cli import main
    from hrc.temporal.graphml import write_graphml

    path = tmp_path / "react.graphml"  # arrival 10-30 after go, robot within 2 of the arrival (file's unit)
    path.write_text(write_graphml(STNU(("go", "arrive", "robot"), (R("arrive", "robot", 0, 2),),
                                       (C("go", "arrive", 10, 30),))))
    expected = {"0": "DC", "1.5": "DC", "2": "DC", "2.5": "not DC", "inf": "not DC", "0:1.5": "DC",
                "0:2.5": "not DC", "0.5:1": "DC", "1:inf": "not DC"}
    for text, verdict in expected.items():
        assert main(["check", str(path), "--observation-delay", text, "--json"]) == 0
        out = json.loads(capsys.readouterr().out)
        assert out["verdict"] == verdict, text
    assert out["observation_delay"] == [1.0, None]
    assert main(["check", str(path), "--observation-delay", "2.5"]) == 0
    text = capsys.readouterr().out
    assert text.startswith("not DC at observation delay 2.5\n")
    assert "arrive@seen --[-1]--> robot" in text  # 2 - 2.5 units = -1 half-unit tick
    for bad in ("-1", "abc", "1:0.5", "inf:2", "1:2:3", "0.1234567", "nan", "1/2"):
        with pytest.raises(SystemExit) as stop:
            main(["check", str(path), "--observation-delay", bad])
        assert stop.value.code == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and err.startswith("error: hrc check: argument --observation-delay"), err


@needs_shared
def test_hrc_check_observation_delay_on_heatlab_decimals(capsys: pytest.CaptureFixture[str]) -> None:
    """HEATlab bounds are decimals scaled to integers: the delay is scaled alike (0 is the DC check)."""
    import json

    from hrc.cli import main

    row = next(r for r in _rows() if r["file"].endswith(".json") and r["expected"] == "DC")
    verdicts = []
    for text in ("0", "0.05", "inf"):
        assert main(["check", str(BENCH / row["file"]), "--observation-delay", text, "--json"]) == 0
        verdicts.append(json.loads(capsys.readouterr().out)["verdict"])
    assert verdicts[0] == "DC"
    assert verdicts[2] in ("DC", "not DC") and (verdicts[1] == "DC" or verdicts[2] == "not DC")


def test_a_link_squeezed_onto_its_root_is_explained_by_its_negative_loop() -> None:
    """Found by hypothesis: [1, 2] contingent, the robot within [0, 1] of its activation, the delay [0, 1]
    telling nothing: the substitution leaves a link of T0 to itself; the explanation is its negative loop
    alone (the loop of weight >= 0 beside it made a 'cycle' summing to 0)."""
    stnu = STNU(("T0", "T1"), (R("T1", "T0", -1, 0),), (C("T0", "T1", 1, 2),))
    result = check_delay(stnu, {"T1": ObservationDelay(0, 1)})
    assert result.verdict is Verdict.NOT_DC
    assert result.cycle and sum(e.value for e in result.cycle) < 0
