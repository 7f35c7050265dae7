"""The real-time execution strategy (`hrc.temporal.execution`) against brute force.

* hand-worked states: waits for a contingent timepoint, upper-case waits, deadlines that order two
  timepoints, overruns, the STN and EARLIEST readings, bad histories;
* windows are exact: on random small DC STNUs and random partial executions (contingent durations at
  their bounds, inside them, and overrunning them), a tick t is in X's window iff the brute-force rest of
  the game at t (the network with the history pinned, running contingent links ending at t or later, X
  pinned at t) is DC and so is the rest at every tick from now to t (waiting is safe); "must wait" only
  where no tick before the awaited contingent timepoints' upper bounds is safe;
* executing the strategy (random timepoints at random ticks of their windows, window ends included,
  nature's durations at and inside their bounds) never violates a constraint and never gets stuck;
* the strategy agrees with the brute-force dispatcher of test_temporal_properties (`_residual`): whatever
  it lets run now, that dispatcher's residual DC check accepts.

The brute force here rebuilds the rest of the game from the network's links on its own (`_rest`) and
asks `check_dc`, itself checked against the exhaustive game oracle in test_temporal_properties.
"""

from __future__ import annotations

import doctest
import random

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_temporal_properties import _residual, stnus

import hrc.temporal.execution as execution
from hrc.temporal import STNU, ContingentLink, NetworkError, RequirementLink, Verdict, check_consistency, check_dc
from hrc.temporal.execution import (
    ExecutionMode,
    ExecutionWindow,
    MustWait,
    real_time_state,
    residual_network,
    violated_links,
)
from hrc.temporal.graph import distance_edges

R, C = RequirementLink, ContingentLink

FAST = settings(max_examples=150, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
SLOW = settings(max_examples=3000, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
ORIGIN = "origin*"


def test_doctests() -> None:
    assert doctest.testmod(execution, raise_on_error=True).attempted > 0


# --- hand-worked states -------------------------------------------------------------------------------

REACT = STNU(("A", "C", "X"), (R("C", "X", 0, 2),), (C("A", "C", 1, 10),))  # X within 0..2 after C


def test_reacting_timepoint_waits_for_the_contingent_then_gets_its_window() -> None:
    assert real_time_state(REACT, {"A": 0}, 3).step("X") == MustWait("X", ("C",))
    assert real_time_state(REACT, {"A": 0, "C": 4}, 5).step("X") == ExecutionWindow("X", 5, 6)
    # a late message: the window may already be over; the verdict says so
    late = real_time_state(REACT, {"A": 0, "C": 4}, 7)
    assert late.verdict is Verdict.INCONSISTENT


def test_upper_case_wait_sets_the_earliest_tick() -> None:
    # C - X <= 3: X may not go more than 3 before C; C in A + [1, 10]: wait until A + 7 unless C comes
    net = STNU(("A", "C", "X"), (R("X", "C", None, 3),), (C("A", "C", 1, 10),))
    assert real_time_state(net, {"A": 0}, 0).step("X") == ExecutionWindow("X", 7, None, ("C",))
    assert real_time_state(net, {"A": 0, "C": 2}, 2).step("X") == ExecutionWindow("X", 2, None)


def test_a_deadline_orders_two_executables() -> None:
    # Y by 5, X from 8: X cannot go first
    net = STNU(("S", "X", "Y"), (R("S", "Y", 0, 5), R("S", "X", 8, None)))
    state = real_time_state(net, {"S": 0}, 0)
    assert state.step("X") == MustWait("X", ("Y",))
    assert state.step("Y") == ExecutionWindow("Y", 0, 5)
    assert real_time_state(net, {"S": 0, "Y": 4}, 4).step("X") == ExecutionWindow("X", 8, None)


def test_uncontrolled_timepoints_are_waited_for_even_at_distance_zero() -> None:
    # X no earlier than H (a co-worker's start): the agent could do both at once, the robot cannot
    net = STNU(("S", "H", "X"), (R("S", "H", 0, 10), R("H", "X", 0, 10)))
    state = real_time_state(net, {"S": 0}, 2)
    assert state.step("X") == ExecutionWindow("X", 2, 10)
    assert state.step("X", uncontrolled={"H"}) == MustWait("X", ("H",))


def test_an_overrun_occurs_any_moment_now() -> None:
    # C in A + [2, 4] overran (now 6): the link becomes [6, 6]; X after C still waits for it
    net = STNU(("A", "C", "X", "Y"), (R("C", "X", 0, 5), R("A", "Y", 0, 20)), (C("A", "C", 2, 4),))
    state = real_time_state(net, {"A": 0}, 6)
    assert state.residual.contingents == (C("A", "C", 6, 6),)
    assert state.verdict is Verdict.DC
    assert state.step("X") == MustWait("X", ("C",))
    assert state.step("Y") == ExecutionWindow("Y", 6, 20)


def test_stn_reading_of_a_network_that_is_not_dc() -> None:
    # X 1..2 before C: not DC, but a co-worker who keeps to the plan ends C after X; in-bounds C <= 10
    net = STNU(("A", "C", "X"), (R("X", "C", 1, 2),), (C("A", "C", 1, 10),))
    state = real_time_state(net, {"A": 0}, 0)
    assert state.verdict is Verdict.NOT_DC
    assert state.default_mode() is ExecutionMode.STN
    assert state.step("X") == ExecutionWindow("X", 0, 9)
    with pytest.raises(NetworkError, match="no DC strategy"):
        state.step("X", ExecutionMode.DC)


def test_earliest_reading_of_an_inconsistent_rest() -> None:
    # the deadline (S + 5) is gone, X still comes 3 after C, as early as possible
    net = STNU(("S", "A", "C", "X"), (R("S", "X", 0, 5), R("C", "X", 3, None), R("S", "A", 0, None)),
               (C("A", "C", 1, 4),))
    state = real_time_state(net, {"S": 0, "A": 1}, 4)
    assert state.verdict is Verdict.INCONSISTENT
    assert state.step("X") == MustWait("X", ("C",))
    after = real_time_state(net, {"S": 0, "A": 1, "C": 6}, 6)
    assert after.step("X") == ExecutionWindow("X", 9, 9)


def test_history_links_are_left_out_and_reported() -> None:
    net = STNU(("S", "X", "Y"), (R("S", "X", 0, 2), R("X", "Y", 1, 3)))
    executed = {"S": 0, "X": 5}
    assert violated_links(net, executed) == (R("S", "X", 0, 2),)
    state = real_time_state(net, executed, 5)
    assert state.verdict is Verdict.DC  # what is left (Y 1..3 after X) can still be done
    assert state.step("Y") == ExecutionWindow("Y", 6, 8)
    assert violated_links(net, {"S": 0, "X": 1}) == ()


def test_a_reading_ahead_of_the_clock_keeps_the_clock() -> None:
    """`ahead`: a sensed event read as happened after now (a detector's estimate plus its error). Its
    contingent link has lasted nothing yet (full range), what follows it is held back by it alone, and
    anything else may still go now (reading the clock at that time would push Y to 10 as well)."""
    net = STNU(("S", "A", "C", "X", "Y"), (R("A", "X", 1, None), R("S", "Y", 0, 20)), (C("A", "C", 2, 5),))
    state = real_time_state(net, {"S": 0, "A": 10}, 8, ahead=True)
    assert state.residual.contingents == (C("A", "C", 2, 5),)
    assert state.step("X") == ExecutionWindow("X", 11, 20)
    assert state.step("Y") == ExecutionWindow("Y", 8, 20)
    with pytest.raises(NetworkError, match="after now"):
        real_time_state(net, {"S": 0, "A": 10}, 8)


@pytest.mark.parametrize(("executed", "now", "message"), [
    ({"Q": 0}, 1, "not in the network"),
    ({"A": 4}, 3, "after now"),
    ({"C": 2}, 3, "before its activation"),
    ({"A": 3, "C": 2}, 3, "before its activation"),
    ({"A": 1.5}, 3, "integer"),
])
def test_bad_histories_are_refused(executed: dict, now: int, message: str) -> None:
    with pytest.raises(NetworkError, match=message):
        residual_network(REACT, executed, now)


@pytest.mark.parametrize(("x", "message"), [("C", "contingent"), ("A", "executed already"), ("Q", "unknown")])
def test_step_refuses_what_cannot_be_executed(x: str, message: str) -> None:
    with pytest.raises(NetworkError, match=message):
        real_time_state(REACT, {"A": 0}, 1).step(x)


def test_origin_name_never_clashes() -> None:
    net = STNU((execution.RESIDUAL_ORIGIN, "B"), (R(execution.RESIDUAL_ORIGIN, "B", 1, 2),))
    res = residual_network(net, {execution.RESIDUAL_ORIGIN: 0}, 0)
    assert res.timepoints[0] == execution.RESIDUAL_ORIGIN + "_"


# --- brute force ---------------------------------------------------------------------------------------

def _rest(stnu: STNU, times: dict[str, int], t: int, fix: tuple[str, int] | None = None,
          as_stn: bool = False) -> STNU:
    """The game from tick t on when nothing has happened since `times`: executed timepoints pinned,
    contingent links running since A end at t or later (an overdue one exactly at t), every other
    executable at t or later (or `fix`ed)."""
    reqs = [RequirementLink(ORIGIN, x, tx, tx) for x, tx in times.items()]
    reqs += [r for r in stnu.requirements if not (r.source in times and r.target in times)]
    conts = []
    for c in stnu.contingents:
        if c.target in times:
            continue
        if c.source in times:
            lb = max(c.lb, t - times[c.source])
            conts.append(ContingentLink(c.source, c.target, lb, max(lb, c.ub)))
        else:
            conts.append(c)
    for x in stnu.timepoints:
        if x not in times and x not in stnu.contingent_timepoints:
            lo, hi = (fix[1], fix[1]) if fix is not None and fix[0] == x else (t, None)
            reqs.append(RequirementLink(ORIGIN, x, lo, hi))
    if as_stn:
        reqs += [RequirementLink(c.source, c.target, c.lb, c.ub) for c in conts]
        conts = []
    return STNU((ORIGIN, *stnu.timepoints), tuple(reqs), tuple(conts))


def _ok(net: STNU) -> bool:
    return check_dc(net).verdict is Verdict.DC


def _horizon(stnu: STNU) -> int:
    return 2 + sum(abs(b) for r in stnu.requirements for b in (r.lb, r.ub) if b is not None) + sum(
        c.ub for c in stnu.contingents)


def _brute_window(stnu: STNU, times: dict[str, int], now: int, x: str, top: int, as_stn: bool = False) -> list[int]:
    out = []
    for t in range(now, top + 1):
        if not _ok(_rest(stnu, times, t, as_stn=as_stn)):
            break  # waiting until t is not safe: no later tick is reachable
        if _ok(_rest(stnu, times, t, (x, t), as_stn=as_stn)):
            out.append(t)
    return out


def _random_history(stnu: STNU, rng: random.Random, overrun: int) -> tuple[dict[str, int], int]:
    """Play up to a random tick: nature's durations at a bound, inside, or up to `overrun` past the upper
    bound; the agent executes now and then what brute force says is safe to execute now."""
    duration = {c.target: rng.choice([c.lb, c.ub, rng.randint(c.lb, c.ub + overrun)]) for c in stnu.contingents}
    activation = {c.target: c.source for c in stnu.contingents}
    stop = rng.randint(0, _horizon(stnu))
    times: dict[str, int] = {}
    for t in range(stop + 1):
        for c, a in activation.items():
            if a in times and c not in times and times[a] + duration[c] == t:
                times[c] = t
        if t == stop:
            break
        for x in stnu.timepoints:
            if x not in times and x not in activation and rng.random() < 0.3 and _ok(_rest(stnu, times, t, (x, t))):
                times[x] = t
    return times, stop


def _check_windows(stnu: STNU, rng: random.Random, overrun: int) -> None:
    if not _ok(stnu):
        return
    times, now = _random_history(stnu, rng, overrun)
    state = real_time_state(stnu, times, now)
    assert (state.verdict is Verdict.DC) is _ok(_rest(stnu, times, now))
    if state.verdict is not Verdict.DC:
        return
    top = now + _horizon(stnu) + 3
    running = [times[c.source] + c.ub for c in stnu.contingents if c.source in times and c.target not in times]
    overdue = any(t < now for t in running) or any(  # `_residual` knows no overruns, running or done
        c.source in times and c.target in times and not c.lb <= times[c.target] - times[c.source] <= c.ub
        for c in stnu.contingents)
    for x in state.pending:
        exact = _brute_window(stnu, times, now, x, top)
        step = state.step(x)
        if isinstance(step, ExecutionWindow):
            hi = top if step.latest is None else step.latest
            assert step.earliest <= hi, step
            assert exact == list(range(step.earliest, hi + 1)), (x, step, exact)
            if step.earliest == now and not overdue:  # the brute-force dispatcher of test_temporal_properties agrees
                assert _ok(_residual(stnu, now - 1, now, times, ORIGIN, (x, now)))
        else:
            cap = min(running, default=top + 1)
            assert not [t for t in exact if t < cap], (x, step, exact)
            assert step.until


@FAST
@given(stnus(max_nodes=5, max_contingent=2, max_requirements=6, min_contingent=1), st.randoms(use_true_random=False))
def test_dc_windows_are_exact(stnu: STNU, rng: random.Random) -> None:
    _check_windows(stnu, rng, overrun=0)


@FAST
@given(stnus(max_nodes=5, max_contingent=2, max_requirements=6, min_contingent=1), st.randoms(use_true_random=False))
def test_dc_windows_are_exact_after_overruns(stnu: STNU, rng: random.Random) -> None:
    _check_windows(stnu, rng, overrun=3)


@pytest.mark.slow
@SLOW
@given(stnus(max_nodes=6, max_contingent=3, max_requirements=8), st.randoms(use_true_random=False))
def test_dc_windows_are_exact_many(stnu: STNU, rng: random.Random) -> None:
    _check_windows(stnu, rng, overrun=rng.choice([0, 3]))


# --- the strategy, executed -------------------------------------------------------------------------------

def _execute(stnu: STNU, rng: random.Random) -> dict[str, int]:
    """Run the strategy against nature: at each state pick a timepoint with a window and a tick in it (an
    end or inside), unless a contingent timepoint comes first. Checks every step against the brute-force
    dispatcher of test_temporal_properties when a timepoint goes at once."""
    duration = {c.target: rng.choice([c.lb, c.ub, rng.randint(c.lb, c.ub)]) for c in stnu.contingents}
    activation = {c.target: c.source for c in stnu.contingents}
    times: dict[str, int] = {}
    now = 0
    while len(times) < len(stnu.timepoints):
        state = real_time_state(stnu, times, now)
        assert state.verdict is Verdict.DC, (times, now)
        windows = [s for s in (state.step(x) for x in state.pending) if isinstance(s, ExecutionWindow)]
        due = [(times[activation[c]] + duration[c], c) for c in activation if activation[c] in times and c not in times]
        plan = None
        if windows:
            w = rng.choice(windows)
            hi = w.latest if w.latest is not None else w.earliest + 6
            t = rng.choice([w.earliest, hi, rng.randint(w.earliest, hi)])
            plan = (t, w.timepoint)
            if t == now:  # the brute-force dispatcher agrees that it may go now
                assert _ok(_residual(stnu, now - 1, now, times, ORIGIN, (w.timepoint, now)))
        assert plan is not None or due, f"stuck at {now} with {times}"
        if due and (plan is None or min(due)[0] < plan[0] or (min(due)[0] == plan[0] and rng.random() < 0.5)):
            now, c = min(due)
            times[c] = now
        else:
            assert plan is not None
            now, x = plan
            times[x] = now
    return times


def _check_execution(stnu: STNU, rng: random.Random) -> None:
    if not _ok(stnu):
        return
    times = _execute(stnu, rng)
    for e in distance_edges(stnu):
        assert times[e.target] - times[e.source] <= e.value, (e, times)


@FAST
@given(stnus(max_nodes=5, max_contingent=2, max_requirements=6), st.randoms(use_true_random=False))
def test_executing_the_windows_never_violates_a_constraint(stnu: STNU, rng: random.Random) -> None:
    _check_execution(stnu, rng)


@pytest.mark.slow
@SLOW
@given(stnus(max_nodes=6, max_contingent=3, max_requirements=8), st.randoms(use_true_random=False))
def test_executing_the_windows_never_violates_a_constraint_many(stnu: STNU, rng: random.Random) -> None:
    _check_execution(stnu, rng)


# --- the STN reading --------------------------------------------------------------------------------------

@FAST
@given(stnus(max_nodes=5, max_contingent=2, max_requirements=6), st.randoms(use_true_random=False))
def test_stn_windows_are_safe_and_exact_while_the_co_worker_keeps_to_the_plan(
        stnu: STNU, rng: random.Random) -> None:
    if not check_consistency(stnu).consistent:
        return
    times, now = _random_history(stnu, rng, overrun=0)
    state = real_time_state(stnu, times, now)
    if state.verdict is Verdict.INCONSISTENT:
        return
    top = now + _horizon(stnu) + 3
    cap = min((times[c.source] + c.ub for c in stnu.contingents if c.source in times and c.target not in times),
              default=top)
    for x in state.pending:
        exact = set(_brute_window(stnu, times, now, x, top, as_stn=True))
        step = state.step(x, ExecutionMode.STN)
        if isinstance(step, ExecutionWindow):
            window = set(range(step.earliest, (top if step.latest is None else step.latest) + 1))
            assert window <= exact, (x, step, sorted(exact))
            assert {t for t in exact if t <= cap} <= window, (x, step, sorted(exact))
        elif any(v not in stnu.contingent_timepoints for v in step.until):
            assert not exact, (x, step, sorted(exact))  # an executable has to go first
