"""APA on the paper's random structured STPPs (section V), checked against independent truth.

* the optimum of ``hrc apa --json`` matches a QP written here from the STPP directly (clarabel on a
  formulation of our own: all event times free but the first, every bound a separate row), to 1e-6
  relative; its schedule meets every hard constraint;
* the DO form keeps that optimum: schedules drawn at random by dispatching the DO form (any event,
  any time inside its current window, one-step propagation through the DO form's APSP) meet every
  constraint and reach the optimum within the stated `value_tolerance` (and 1e-6 relative);
* the flexibility ratio is what its definition says, recomputed here from an independent APSP.
"""

from __future__ import annotations

import io
import json
import math
from contextlib import redirect_stdout

import clarabel
import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse.csgraph import csgraph_from_dense, floyd_warshall

from hrc.apa.compile import compile_stpp, do_apsp, interval_flexibility, stpp_network
from hrc.apa.generator import random_stpp
from hrc.apa.io import dump_stpp, load_stpp
from hrc.apa.model import STPP
from hrc.cli import main
from hrc.temporal.stn import all_pairs_shortest_paths


def independent_optimum(stpp: STPP) -> float:
    """max F by clarabel on a dense formulation written here (not `hrc.apa.qp`)."""
    n = len(stpp.events)
    idx = {e: i for i, e in enumerate(stpp.events)}
    pmat = np.zeros((n, n))
    q = np.zeros(n)
    const = 0.0
    for c in stpp.preferred:
        assert c.preference is not None
        c0, c1, c2 = (*c.preference.coefficients, 0.0, 0.0)[:3]
        a = np.zeros(n)
        a[idx[c.target]] += 1
        a[idx[c.source]] -= 1
        pmat += -2 * c2 * np.outer(a, a)
        q += -c1 * a
        const += c0
    rows, rhs = [], []
    eq = np.zeros(n)
    eq[0] = 1.0
    rows.append(eq)
    rhs.append(0.0)
    for c in stpp.constraints:
        a = np.zeros(n)
        a[idx[c.target]] += 1
        a[idx[c.source]] -= 1
        if math.isfinite(c.ub):
            rows.append(a)
            rhs.append(c.ub)
        if math.isfinite(c.lb):
            rows.append(-a)
            rhs.append(-c.lb)
    settings_ = clarabel.DefaultSettings()
    settings_.verbose = False
    settings_.tol_gap_abs = settings_.tol_gap_rel = settings_.tol_feas = 1e-10
    solver = clarabel.DefaultSolver(sp.csc_matrix(np.triu(pmat)), q, sp.csc_matrix(np.array(rows)),
                                    np.array(rhs), [clarabel.ZeroConeT(1), clarabel.NonnegativeConeT(len(rows) - 1)],
                                    settings_)
    sol = solver.solve()
    assert str(sol.status) == "Solved"
    return const - sol.obj_val


def sample_do_schedule(result, rng: np.random.Generator) -> dict[str, float]:
    """Dispatch the DO form with random choices: events in random order, each at a uniform time of its
    current window (the first event at 0), propagated one step through the APSP."""
    d = np.asarray(do_apsp(result), dtype=float)
    n = d.shape[0]
    lo, hi = np.full(n, -np.inf), np.full(n, np.inf)
    t = np.zeros(n)
    order = [0, *rng.permutation(np.arange(1, n)).tolist()]
    for k in order:
        a, b = (0.0, 0.0) if k == 0 else (lo[k], hi[k])
        if math.isinf(a) and math.isinf(b):  # nothing dispatched so far bounds it (another part)
            a = b = 0.0
        elif math.isinf(a):
            a = b - 1e6
        elif math.isinf(b):
            b = a + 1e6
        assert a <= b
        t[k] = int(round(rng.uniform(a, b)))
        lo = np.maximum(lo, t[k] - d[:, k])
        hi = np.minimum(hi, t[k] + d[k, :])
    return {e: t[i] / result.ticks_per_second for i, e in enumerate(result.stpp.events)}


def dispatch_matrix(d: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A schedule dispatched through the distance matrix `d` (seconds): events in random order, each at a
    uniform time of its current window (the first at 0), one-step propagation."""
    n = d.shape[0]
    lo, hi = np.full(n, -np.inf), np.full(n, np.inf)
    t = np.zeros(n)
    for k in [0, *rng.permutation(np.arange(1, n)).tolist()]:
        a, b = (0.0, 0.0) if k == 0 else (lo[k], hi[k])
        a, b = (a if math.isfinite(a) else (b - 100 if math.isfinite(b) else 0.0)), b
        b = b if math.isfinite(b) else a + 100
        assert a <= b + 1e-9
        t[k] = rng.uniform(a, max(a, b))
        lo = np.maximum(lo, t[k] - d[:, k])
        hi = np.minimum(hi, t[k] + d[k, :])
    return t


def run_cli(path) -> dict:
    out = io.StringIO()
    with redirect_stdout(out):
        assert main(["apa", str(path), "--json"]) == 0
    return json.loads(out.getvalue())


@pytest.mark.parametrize("n", [10, 25, 50])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_cli_optimum_matches_an_independent_qp(tmp_path, n, seed):
    stpp = random_stpp(n, np.random.default_rng(seed))
    path = tmp_path / "s.json"
    dump_stpp(stpp, path)
    assert load_stpp(path) == stpp
    out = run_cli(path)
    truth = independent_optimum(stpp)
    assert out["value"] == pytest.approx(truth, rel=1e-6)
    times = out["times"]
    assert stpp.violation(times) <= 1e-9
    assert stpp.value(times) == pytest.approx(truth, rel=1e-6)
    assert 0 <= out["flexibility"] <= 1
    # the printed DO form, read back on its own (scipy's Floyd-Warshall on whole microseconds, exact in
    # float64, as the printed seconds are): its windows from the reference are the printed windows, and
    # schedules dispatched inside it keep the optimum
    cons = out["do_form"]
    assert all(set(c) == {"from", "to", "lb", "ub"} for c in cons)
    idx = {e: i for i, e in enumerate(stpp.events)}
    dense = np.full((n, n), np.inf)
    np.fill_diagonal(dense, 0.0)
    for c in cons:
        i, j = idx[c["from"]], idx[c["to"]]
        if c["ub"] is not None:
            dense[i, j] = min(dense[i, j], round(c["ub"] * 1e6))
        if c["lb"] is not None:
            dense[j, i] = min(dense[j, i], -round(c["lb"] * 1e6))
    d = floyd_warshall(csgraph_from_dense(dense, null_value=np.inf)) / 1e6  # a 0 weight is an edge
    for e, (lo, hi) in out["windows"].items():
        k = idx[e]
        assert (lo is None) == math.isinf(d[k, 0]) and (hi is None) == math.isinf(d[0, k])
        assert lo is None or lo == pytest.approx(-d[k, 0], abs=1e-9)
        assert hi is None or hi == pytest.approx(d[0, k], abs=1e-9)
    rng = np.random.default_rng(seed)
    for _ in range(5):
        sample = dispatch_matrix(d, rng)
        times = {e: sample[i] for i, e in enumerate(stpp.events)}
        assert stpp.violation(times) <= 1e-6
        assert stpp.value(times) == pytest.approx(truth, rel=1e-6, abs=1e-6)


@settings(max_examples=15, deadline=None)
@given(n=st.integers(2, 30), seed=st.integers(0, 10**6), share=st.sampled_from([0.2, 0.5, 1.0]))
def test_do_form_keeps_the_optimum(n, seed, share):
    rng = np.random.default_rng(seed)
    stpp = random_stpp(n, rng, preference_share=share)
    result = compile_stpp(stpp)
    truth = independent_optimum(stpp)
    assert result.value == pytest.approx(truth, rel=1e-6, abs=1e-6)
    for _ in range(5):
        s = sample_do_schedule(result, rng)
        assert stpp.violation(s) <= 1e-9
        assert abs(stpp.value(s) - truth) <= result.value_tolerance + 1e-6 * max(1.0, abs(truth))
        assert stpp.value(s) == pytest.approx(truth, rel=1e-6, abs=1e-6)


def test_flexibility_is_its_definition():
    stpp = random_stpp(40, np.random.default_rng(7))
    r = compile_stpp(stpp)
    d0 = all_pairs_shortest_paths(stpp_network(stpp))
    d1 = do_apsp(r)
    widths0 = [d0[0, j] + d0[j, 0] for j in range(1, 40) if np.isfinite(d0[0, j] + d0[j, 0])]
    widths1 = [d1[0, j] + d1[j, 0] for j in range(1, 40) if np.isfinite(d0[0, j] + d0[j, 0])]
    assert r.flexibility == pytest.approx(sum(widths1) / sum(widths0))
    for j, e in enumerate(stpp.events):   # the DO windows are the DO form's APSP row and column
        lo, hi = r.window(e)
        assert (lo is None) == (not np.isfinite(d1[j, 0])) and (hi is None) == (not np.isfinite(d1[0, j]))
        if lo is not None and hi is not None:
            assert (lo, hi) == (-d1[j, 0] / 1e6, d1[0, j] / 1e6)


def test_interval_flexibility_is_the_papers_definition():
    """Per original constraint of finite width, DO width (scipy's Floyd-Warshall on the tightened network,
    not hrc's APSP) over original width, averaged; constant preferences keep their interval whole."""
    stpp = random_stpp(40, np.random.default_rng(8), constraints=40, preference_share=0.5)
    r = compile_stpp(stpp)
    idx = {e: i for i, e in enumerate(stpp.events)}
    dense = np.full((40, 40), np.inf)
    np.fill_diagonal(dense, 0.0)
    for link in r.do_network.requirements:
        i, j = idx[link.source], idx[link.target]
        if link.ub is not None:
            dense[i, j] = min(dense[i, j], link.ub)
        if link.lb is not None:
            dense[j, i] = min(dense[j, i], -link.lb)
    d = floyd_warshall(csgraph_from_dense(dense, null_value=np.inf)) / 1e6
    ratios = [min(1.0, (d[idx[c.source], idx[c.target]] + d[idx[c.target], idx[c.source]]) / (c.ub - c.lb))
              for c in stpp.constraints if math.isfinite(c.ub - c.lb) and c.ub > c.lb]
    assert interval_flexibility(r) == pytest.approx(sum(ratios) / len(ratios))
    constant = [k for k, c in enumerate(stpp.constraints) if c.preference is not None
                and c.preference.kind.value == "constant"]
    assert constant  # and each keeps its original bounds in the tightened network
    for k in constant:
        c, link = stpp.constraints[k], r.do_network.requirements[k]
        assert (link.lb, link.ub) == (round(c.lb * 1e6), round(c.ub * 1e6))


def test_solvers_agree_and_output_is_deterministic(tmp_path):
    stpp = random_stpp(60, np.random.default_rng(11))
    a, b = compile_stpp(stpp, solver="piqp"), compile_stpp(stpp, solver="clarabel")
    assert a.value == pytest.approx(b.value, rel=1e-8)
    path = tmp_path / "s.json"
    dump_stpp(stpp, path)
    outs = []
    for _ in range(2):
        buf = io.StringIO()
        with redirect_stdout(buf):
            main(["apa", str(path), "--json"])
        outs.append(buf.getvalue())
    assert outs[0] == outs[1]


def test_inconsistent_stpp_is_an_answer(tmp_path):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"events": ["a", "b", "c"], "constraints": [
        {"from": "a", "to": "b", "lb": 5, "ub": 6}, {"from": "b", "to": "c", "lb": 0, "ub": 1},
        {"from": "a", "to": "c", "lb": 0, "ub": 2}]}))
    out = run_cli(path)
    assert out["consistent"] is False and set(out["cycle"]) == {"a", "b", "c"}


@pytest.mark.parametrize("solver", ["piqp", "clarabel"])
def test_rigid_links_are_contracted(solver):
    """Rigid links (the past, once the dispatcher commits it) have no interior; the QP gives the events
    they tie one variable. Here c - b would like 3 but a -> c caps it at 2; then a rigid cycle (a -> b
    -> c -> a, consistent, so its rows are dependent) and a contradictory one."""
    from hrc.apa.model import Constraint, PreferenceFunction
    stpp = STPP(("a", "b", "c"), (Constraint("a", "b", 2, 2),
                                  Constraint("b", "c", 0, 5, PreferenceFunction.quadratic(0, 6, -1)),
                                  Constraint("a", "c", 1, 4)))
    r = compile_stpp(stpp, solver=solver)
    assert r.value == pytest.approx(8.0, abs=1e-7) and r.schedule() == {"a": 0.0, "b": 2.0, "c": 4.0}
    f = PreferenceFunction.quadratic(0, 8, -1)
    cycle = STPP(("a", "b", "c", "d"), (Constraint("a", "b", 2, 2), Constraint("b", "c", 1, 1),
                                        Constraint("c", "a", -3, -3), Constraint("a", "d", 0, 10, f),
                                        Constraint("c", "d", 0, 3)))
    r = compile_stpp(cycle, solver=solver)
    assert r.value == pytest.approx(16.0, abs=1e-7) and r.schedule() == {"a": 0.0, "b": 2.0, "c": 3.0, "d": 4.0}
    bad = STPP(("a", "b", "c"), (Constraint("a", "b", 2, 2), Constraint("b", "c", 1, 1), Constraint("c", "a", -4, -4)))
    r = compile_stpp(bad, solver=solver)
    assert not r.consistent and set(r.cycle) == {"a", "b", "c"}


def test_recompile_with_rigid_past_that_piqp_once_refused():
    """The STPP a 50-event dispatch recompiled after a late event (past rigid, the rest after now;
    data/apa_rigid_past.json): piqp called it infeasible while its rigid rows were inequalities."""
    from pathlib import Path
    stpp = load_stpp(Path(__file__).parent / "data" / "apa_rigid_past.json")
    a, b = compile_stpp(stpp, solver="piqp"), compile_stpp(stpp, solver="clarabel")
    assert a.consistent and a.value == pytest.approx(b.value, rel=1e-8)
    assert a.value == pytest.approx(independent_optimum(stpp), rel=1e-6)
