"""The dispatcher's two readings, side by side: the C core (``_dispatchcore.c``) and the Python one
(`hrc.dispatch.fastnet`, `hrc.temporal.execution`, what runs where the core is not built) give the same
answer to every message, under every sensing path, on a team whose joint action's crew is a choice of the
plan (issue 37, ``tasks/two_workers_joint.yaml``).

The cases were found by the ``crew_history`` fuzz target (fuzz/targets.py); both answers were wrong in
one of two ways there, and the tests pin the readings both sides now share:

- a start pressed with its walk unreported, the button up to 0.5 s late: the start is read as early as
  0.5 s before the press; its departure and arrival, which `hrc.dispatch.validation.executed` puts at the
  start's time, must be read with it (the Python reading left them at the press, after the start);
- a first press 0.4 s into the run, up to 0.5 s late: not read before the run's start (it was, at -0.1 s).
"""

from __future__ import annotations

import copy
import json
import sys
from typing import Any

import pytest
from conftest import ROOT, compiled_folder
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

sys.path.insert(0, str(ROOT / "fuzz"))
import targets  # noqa: E402  (the fuzz targets' team_messages: one way to draw a team's next message)

from hrc.dispatch import Dispatcher
from hrc.dispatch.plan_set import load_plan_set
from hrc.dispatch.protocol import answer

SENSING: list[dict[str, Any]] = [{}, {"bound_tolerance": 0.15}, {"bound_tolerance": 0.4},
                                 {"max_observation_delay": 0.5}]


@pytest.fixture(scope="module")
def plan_set(tmp_path_factory: pytest.TempPathFactory) -> Any:
    out = compiled_folder(tmp_path_factory.mktemp("crews") / "out", ROOT / "tasks" / "two_workers_joint.yaml")
    return load_plan_set(out)


def pair(plan_set: Any, **options: Any) -> tuple[Dispatcher, Dispatcher]:
    native = Dispatcher(plan_set, **options)
    if native.ranker.native is None:
        pytest.skip("the C core is not built (python setup.py build_ext --inplace)")
    ranker = copy.copy(native.ranker)
    ranker.native = None
    return native, Dispatcher(plan_set, ranker=ranker, **options)


def both(d: tuple[Dispatcher, Dispatcher], msg: dict[str, Any]) -> dict[str, Any]:
    line = json.dumps(msg).encode()
    a, b = answer(d[0], line), answer(d[1], line)
    assert a == b, msg
    return json.loads(a)


def test_a_late_start_with_its_walk_unreported_reads_the_walk_with_it(plan_set: Any) -> None:
    d = pair(plan_set, max_observation_delay=0.5)
    both(d, {"t": 8.3, "agent": "bob", "action": "pick_a", "phase": "fetch", "event": "start"})
    both(d, {"t": 19.52, "agent": "bob", "action": "pick_a", "phase": "fetch", "event": "end"})
    got = both(d, {"t": 27.21, "agent": "alice", "action": "pick_e", "phase": "fetch", "event": "start"})
    assert got["ok"] and got["class"] == "DC"
    # read as early as 26.71 s, alice's walk to E cannot have ended after it: the arrival she did not
    # press is read at the start's time in both readings (the early one is the Python side's `_estimates`)
    early, _ = d[1]._estimates(plan_set.entry(d[1]._state.best), _done(d[1]), d[1]._state.history,
                                (d[1]._state.seen, d[1]._state.legs_seen), d[1]._state.hinted)
    times = early[0]
    assert times["alice_fetch_pick_e_arrive"] <= times["alice_fetch_pick_e_start"] == 26710


def test_a_press_just_after_the_start_is_not_read_before_it(plan_set: Any) -> None:
    d = pair(plan_set, max_observation_delay=0.5)
    got = both(d, {"t": 0.4, "agent": "alice", "action": "pick_d", "phase": "fetch", "event": "start"})
    assert got["ok"]
    assert d[0]._state.hinted[("alice", "pick_d", "fetch", "start")] == (0, 400)


def _done(d: Dispatcher) -> dict[str, int]:
    from hrc.dispatch.validation import executed

    return executed(d.plan_set.entry(d._state.best), d._state.history)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_random_histories_get_the_same_answers(plan_set: Any, data: st.DataObject) -> None:
    """Random histories, drawn as the fuzz target draws them (`targets.team_messages`): each step an event
    some person may report now, a robot's step, a tick, an away or a back, at a time that never goes back."""
    d = pair(plan_set, **data.draw(st.sampled_from(SENSING), label="sensing"))
    people = [a.id for a in plan_set.task.agents if a.is_human]
    t = 0.0
    for _ in range(data.draw(st.integers(1, 24), label="messages")):
        t = round(t + data.draw(st.integers(0, 4000), label="dt") / 100, 2)
        person = data.draw(st.sampled_from(people), label="person")
        both(d, data.draw(st.sampled_from(targets.team_messages(d[0], person, t)), label="message"))


def test_idle_counts_a_joint_phase_another_agent_leads_from_the_arrival(plan_set: Any) -> None:
    """A crew member who does not lead the joint load has no start or end of their own for it (the lead's:
    -1 in the form's nodes). Their idle ends with their arrival there, in the C core, the Python ranking
    and the definition (`reference_evaluate`) alike, and by hand from the definition's schedule. The core
    read the word before its schedule for that end (ASan: heap-buffer-overflow, found by ``crew_history``)
    and Python the plan's last timepoint."""
    import numpy as np

    from hrc.compile.temporal_net_creator import ORIGIN
    from hrc.dispatch.ranking import Ranker, reference_evaluate, schedule
    from hrc.dispatch.validation import History, seen_arrays
    from hrc.temporal.execution import residual_network

    ranker = Ranker(plan_set, 1)
    if ranker.native is None:
        pytest.skip("the C core is not built (python setup.py build_ext --inplace)")
    python = copy.copy(ranker)
    python.native = None
    seen, legs_seen = seen_arrays(History.start(plan_set.task), plan_set.form.nodes.shape[2])
    plans = np.arange(len(plan_set))
    native_idle = ranker.evaluate(plans, seen, legs_seen, 0)[2]
    python_idle = python.evaluate(plans, seen, legs_seen, 0)[2]
    assert native_idle.tolist() == python_idle.tolist()
    for p in range(0, len(plan_set), 17):
        entry = plan_set.entry(p)
        ev = reference_evaluate(entry, {ORIGIN: 0}, 0, plan_set.rank_by)
        residual = residual_network(entry.stnu, {ORIGIN: 0}, 0)
        found = schedule(residual, plan_set.rank_by)
        assert found is not None
        times = {v: t - found[residual.timepoints[0]] for v, t in found.items()}
        by_hand = 0
        for agent, legs in entry.legs.items():
            busy, last = 0, 0
            for action, phase in legs:
                points = dict(entry.leg_points[(agent, action, phase)])
                busy += times[points["arrive"]] - times[points["depart"]]
                if "park" in points:
                    busy -= times[points["unpark"]] - times[points["park"]]
                if "end" in points:
                    busy += times[points["end"]] - times[points["start"]]
                last = times[points["end"] if "end" in points else points["arrive"]]
            by_hand += max(0, last - busy) if legs else 0
        assert ev.idle == by_hand == native_idle[p], p
