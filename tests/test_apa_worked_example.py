"""APA's worked example (Wilcox, Nikolaidis & Shah 2012, Figs. 6-9), number for number.

Fig. 6 itself is missing from the text. What the text gives: four events A, B, C, D; six intervals,
an APSP network with no redundant constraint; ``AC [1, 5]``, ``AD [5, 10]``, ``BC [0, 2]``; the
objective (1) ``-(D-A)^2 + 15(D-A) - 50 - (B-C)^2 + 2(B-C)``; the tightened ``AD [7.5, 7.5]`` and
``BC [1, 1]``; after A at 0 the windows ``B [3.5, 4.5]``, ``C [2.5, 3.5]``, ``D [7.5, 7.5]``; C executed at
2.5 then B at 3.5 and D at 7.5; C delayed to 3.0 gives ``B [4.0, 4.0]``, ``D [7.5, 7.5]``.

What we assumed (the smallest network consistent with all of that):
* ``BC`` is the interval of ``d = T(B) - T(C)`` (the printed optimum ``B = 3, C = 4`` has ``B - C = -1``,
  outside ``[0, 2]``, and contradicts both equation (1), maximised at ``B - C = 1``, and the walk-through);
* the two preferences are ``f_AD(d) = -d^2 + 15 d - 50`` on ``AD`` and ``f_BC(d) = -d^2 + 2 d`` on ``BC``,
  both 0 at the ends of their intervals (so "positive-valued" means non-negative);
* the unprinted intervals are ``CD [4, 5]``, ``BD [3, 4]`` and ``AB [1, 7]`` (the latter implied by the
  others): with ``D = 7.5`` and ``B - C = 1`` they give exactly the printed windows.
"""

from __future__ import annotations

import numpy as np
import pytest

from hrc.apa.compile import compile_stpp, do_apsp, stpp_network
from hrc.apa.dispatch import STPPDispatcher
from hrc.apa.model import STPP, Constraint, PreferenceFunction
from hrc.apa.qp import SOLVERS
from hrc.temporal.stn import all_pairs_shortest_paths

F_AD = PreferenceFunction.quadratic(-50, 15, -1)
F_BC = PreferenceFunction.quadratic(0, 2, -1)
FIG6 = STPP(("A", "B", "C", "D"), (
    Constraint("A", "B", 1, 7),
    Constraint("A", "C", 1, 5),
    Constraint("A", "D", 5, 10, F_AD),
    Constraint("C", "B", 0, 2, F_BC),
    Constraint("C", "D", 4, 5),
    Constraint("B", "D", 3, 4),
), "fig6")
TPS = 1000


def test_fig6_is_its_own_apsp_form():
    """'This network is an all-pairs-shortest path graph [...] and does not contain any redundant
    constraint': every printed interval is already minimal."""
    d = all_pairs_shortest_paths(stpp_network(FIG6, TPS))
    idx = {e: i for i, e in enumerate(FIG6.events)}
    for c in FIG6.constraints:
        i, j = idx[c.source], idx[c.target]
        assert (-d[j, i] / TPS, d[i, j] / TPS) == (c.lb, c.ub)


@pytest.mark.parametrize("solver", sorted(SOLVERS))
def test_fig7_do_form(solver):
    r = compile_stpp(FIG6, solver=solver, ticks_per_second=TPS)
    # equation (1) at D - A = 7.5 and B - C = 1: 6.25 + 1
    assert r.value == pytest.approx(7.25, abs=1e-9)
    tightened = {(lk.source, lk.target): (lk.lb, lk.ub) for lk in r.do_network.requirements}
    assert tightened[("A", "D")] == (7500, 7500)   # AD[5, 10] -> AD[7.5, 7.5]
    assert tightened[("C", "B")] == (1000, 1000)   # BC[0, 2] -> BC[1, 1]
    assert [r.window(e) for e in "ABCD"] == [(0.0, 0.0), (3.5, 4.5), (2.5, 3.5), (7.5, 7.5)]
    assert r.value_tolerance <= 1e-12  # both intervals snapped to exact ticks: only the solver error is left
    d = do_apsp(r)
    assert d[0, 3] == d[3, 0] * -1 == 7500
    s = r.schedule()
    assert FIG6.violation(s) <= 0 and FIG6.value(s) == pytest.approx(7.25, abs=1e-12)


def test_fig8_fig9_dispatch_walkthrough():
    disp = STPPDispatcher(FIG6, ticks_per_second=TPS)
    assert [w[0] for w in disp.next_events().windows] == ["A"]            # Line 1: Enabled = {A}
    step = disp.observe("A", 0.0)
    assert step.status == "on_policy"
    assert [disp.window(e) for e in "BCD"] == [(3.5, 4.5), (2.5, 3.5), (7.5, 7.5)]
    assert step.windows == (("C", 2.5, 3.5),)                             # only C is enabled
    step = disp.observe("C", 2.5)                                          # Fig. 9
    assert step.status == "on_policy"
    assert step.windows == (("B", 3.5, 3.5),)
    assert disp.observe("B", 3.5).windows == (("D", 7.5, 7.5),)
    assert disp.observe("D", 7.5).status == "on_policy" and disp.done
    times = {e: t / TPS for e, t in disp.executed.items()}
    assert FIG6.value(times) == pytest.approx(7.25)


def test_c_delayed_to_3():
    disp = STPPDispatcher(FIG6, ticks_per_second=TPS)
    disp.observe("A", 0.0)
    step = disp.observe("C", 3.0)     # still inside C's DO window [2.5, 3.5]: no recompile
    assert step.status == "on_policy"
    assert disp.window("B") == (4.0, 4.0) and disp.window("D") == (7.5, 7.5)


def test_deviation_recompiles_with_the_past_rigid():
    """C at 4.0 is outside its DO window [2.5, 3.5] but inside the hard window [1, 5]: the optimum
    D - A = 7.5 cannot be kept with B - C = 1 (B - D would be 2.5 <= 3 fails), so APA recompiles."""
    disp = STPPDispatcher(FIG6, ticks_per_second=TPS)
    disp.observe("A", 0.0)
    step = disp.observe("C", 4.0)
    assert step.status == "recompiled"
    # the new optimum given A = 0, C = 4: D in [8, 9], B in [C, C + 2] and [D - 4, D - 3]
    grid = [(b, dd) for b in np.arange(4, 6.001, 0.01) for dd in np.arange(8, 9.001, 0.01)
            if 3 - 1e-9 <= dd - b <= 4 + 1e-9]
    best = max(FIG6.value({"A": 0, "B": b, "C": 4, "D": dd}) for b, dd in grid)
    assert step.value == pytest.approx(best, abs=1e-3)
    lo, hi = disp.window("B")
    assert lo is not None and hi is not None and 4 <= lo <= hi <= 6


def test_violation_and_bad_messages():
    from hrc.errors import DispatchError
    disp = STPPDispatcher(FIG6, ticks_per_second=TPS)
    disp.observe("A", 0.0)
    with pytest.raises(DispatchError, match="unknown event"):
        disp.observe("Z", 1.0)
    with pytest.raises(DispatchError, match="already executed"):
        disp.observe("A", 1.0)
    before = dict(disp.executed)
    assert disp.observe("C", 6.0).status == "violation"   # AC [1, 5] broken
    with pytest.raises(DispatchError, match="before the last"):
        disp.observe("B", 5.0)
    assert set(disp.executed) == set(before) | {"C"}


def test_slow_recompile_dispatches_on_the_shadow_stp():
    """A recompile taking 2 s: the deviation at 4.0 leaves the shadow STP in charge until 6.0."""
    disp = STPPDispatcher(FIG6, ticks_per_second=TPS, recompile_latency=2.0)
    disp.observe("A", 0.0)
    step = disp.observe("C", 4.0)
    assert step.status == "shadow"
    assert disp.window("B") == (4.0, 6.0)           # hard constraints only: B - C in [0, 2]
    step = disp.observe("B", 4.5)                     # before the recompile is done
    assert step.status == "shadow"
    step = disp.advance(6.0)                          # the DO form compiled at 4.0 put B at 5: recompile
    assert step.status in ("recompiled", "shadow")
    disp.advance(8.0)
    assert disp.result is not None
    # B = 4.5: D - B in [3, 4] and D - C in [4, 5] leave D in [8, 8.5]; f_AD peaks at 7.5, so D = 8
    assert disp.window("D") == (8.0, 8.0)


def test_shipped_example_file_and_cli(capsys):
    from conftest import ROOT

    from hrc.apa.io import load_stpp
    from hrc.cli import main

    path = ROOT / "tasks" / "apa_fig6.stpp.json"
    assert load_stpp(path) == FIG6
    assert main(["apa", str(path), "--prune"]) == 0
    out = capsys.readouterr().out
    assert "optimal global preference value: 7.25 " in out
    for line in ("B               4  [3.5, 4.5]", "C               3  [2.5, 3.5]", "D             7.5  [7.5, 7.5]"):
        assert line in out
