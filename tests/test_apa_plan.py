"""APA on `hrc` plans: a workshop plan's STNU read as an STP, valued under the task's preference, with
an independent optimum (the preference is one concave quadratic of one difference, so its optimum is
its peak clipped to that difference's feasible range, read off the plan's APSP)."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import WORKSHOP_TASK

from hrc.apa.compile import do_apsp
from hrc.apa.plan import plan_preference_value, task_stpp
from hrc.compile.temporal_net_creator import create_stnu, event_timepoint
from hrc.errors import ApaError
from hrc.io.task_file import load_task
from hrc.motion import plan_motions, plan_paths
from hrc.plans import generate_plans
from hrc.temporal.stn import all_pairs_shortest_paths


@pytest.fixture(scope="module")
def workshop():
    task = load_task(WORKSHOP_TASK)
    paths = plan_paths(task, seed=0)
    plans = list(generate_plans(task))[:6]
    return task, [(p, create_stnu(task, p, plan_motions(task, p, paths)).stnu) for p in plans]


def test_workshop_plans_valued_like_the_peak_clipped(workshop):
    task, plans = workshop
    (pref,) = task.preferences
    valued = 0
    for plan, stnu in plans:
        a, b = event_timepoint(plan, pref.source), event_timepoint(plan, pref.target)
        result = plan_preference_value(stnu, [(a, b, pref)])
        d = all_pairs_shortest_paths(stnu.as_stn())
        i, j = stnu.timepoints.index(a), stnu.timepoints.index(b)
        lo, hi = max(-d[j, i] / 1000, pref.domain.lb), min(d[i, j] / 1000, pref.domain.ub)
        if lo > hi:
            assert not result.consistent
            continue
        c0, c1, c2 = pref.coefficients
        best = float(np.clip(-c1 / (2 * c2), lo, hi))
        assert result.consistent
        assert result.value == pytest.approx(pref.value(best), abs=1e-6)
        times = result.schedule()
        assert pref.value(times[b] - times[a]) == pytest.approx(pref.value(best), abs=1e-6)
        # the DO form pins the preferred difference and keeps the origin first
        dd = do_apsp(result)
        assert dd[i, j] == -dd[j, i] == round(best * 1000)
        assert result.window(stnu.timepoints[0]) == (0.0, 0.0)
        valued += 1
    assert valued >= 3


def test_unknown_timepoint_and_many_agent_tasks_are_refused(workshop):
    task, plans = workshop
    plan, stnu = plans[0]
    with pytest.raises(ApaError, match="unknown event 'nowhere'"):
        plan_preference_value(stnu, [("nowhere", stnu.timepoints[1], task.preferences[0])])
    with pytest.raises(ApaError, match="one agent per action"):
        task_stpp(task)
