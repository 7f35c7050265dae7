"""Route signatures (`hrc.compile.route_signatures`): made by the compile once per network shape and stored
with the dispatch form, they are each leg's route as the plan's STNU gives it (the definition,
`route_signature`), and set validation reads them instead of making them at a first departure (issue 37).
"""

from __future__ import annotations

import json
import random
from dataclasses import replace

import numpy as np
import pytest
from conftest import ROOT
from team_client import TeamRun

from hrc.compile.compiler import compile_task
from hrc.compile.route_signatures import route_signature, route_signatures
from hrc.dispatch import Dispatcher
from hrc.dispatch.plan_set import PlanSet, plan_set_from_compiled
from hrc.dispatch.protocol import handle_line
from hrc.dispatch.validation import RouteIndex
from hrc.dispatch.validation import route_signature as entry_route
from hrc.io.task_file import load_task
from hrc.temporal.network import STNU, ContingentLink, RequirementLink


def test_a_hand_worked_plan():
    """One agent, two legs. Leg 0 stops at a waiting place: depart (1) -> park (2) bounded by a
    requirement link [3, 9] and a contingent link [3, 12] (the tightest, 9, wins), unpark (3) -> arrive
    (4) by a contingent link [2, 7] alone (its upper bound, 7). Leg 1 drives straight: depart (7) ->
    arrive (8) by a contingent link of one fixed duration [5, 5] (a requirement link in the form). No
    third leg: (0, -1, -1). The definition on the STNU and the form's arrays agree."""
    names = ["Z", "d0", "p0", "u0", "a0", "s0", "e0", "d1", "a1", "s1", "e1"]
    stnu = STNU(tuple(names), (RequirementLink("d0", "p0", 3, 9),),
                (ContingentLink("d0", "p0", 3, 12), ContingentLink("u0", "a0", 2, 7), ContingentLink("d1", "a1", 5, 5)))
    assert route_signature(stnu, {"depart": "d0", "park": "p0", "unpark": "u0", "arrive": "a0"}) == (1, 9, 7)
    assert route_signature(stnu, {"depart": "d1", "arrive": "a1"}) == (0, 5, -1)
    nodes = np.full((1, 1, 3, 6), -1, dtype=np.int16)
    nodes[0, 0, 0] = [1, 2, 3, 4, 5, 6]
    nodes[0, 0, 1] = [7, -1, -1, 8, 9, 10]
    # the form's edges: T(v) - T(u) <= w, the fixed link as two edges; its contingent links
    edges = np.array([(1, 2, 9), (2, 1, -3), (7, 8, 5), (8, 7, -5)], dtype=np.int64)
    conts = np.array([(1, 2, 3, 12), (3, 4, 2, 7)], dtype=np.int64)
    got = route_signatures(nodes, (np.array([0, 4]), edges[:, 0], edges[:, 1], edges[:, 2]),
                           (np.array([0, 2]), conts[:, 0], conts[:, 1], conts[:, 3]), np.array([0]))
    assert got[0, 0].tolist() == [[1, 9, 7], [0, 5, -1], [0, -1, -1]]


@pytest.fixture(scope="module")
def kitting3() -> PlanSet:
    """kitting_2robots cut to three picks: 60 plans, three agents, stops at waiting places and detours."""
    full = load_task(ROOT / "tasks" / "kitting_2robots.yaml")
    return plan_set_from_compiled(compile_task(replace(full, actions=full.actions[:3]), seed=0, jobs=1))


def test_the_forms_routes_are_each_plans_stnus(kitting3):
    """Every leg of every plan: the form's stored signature (by shape) is the definition on the plan's STNU;
    the positions after an agent's last leg are (0, -1, -1); plans of one shape have one set of routes.
    Not vacuous: some leg stops at a waiting place, and the bounds differ between routes."""
    form = kitting3.form
    assert form.routes is not None
    shape = np.asarray(form.plans["shape"])
    agents = kitting3.task.agent_ids
    stops, bounds = 0, set()
    for p in range(len(kitting3)):
        entry = kitting3.entry(p)
        for g, agent in enumerate(agents):
            legs = entry.legs[agent]
            for k in range(form.routes.shape[2]):
                got = tuple(int(x) for x in form.routes[shape[p], g, k])
                if k < len(legs):
                    assert got == entry_route(entry, agent, *legs[k]), (entry.id, agent, legs[k])
                    stops += got[0]
                    bounds.add(got[1])
                else:
                    assert got == (0, -1, -1)
    assert stops and len(bounds) > 3


def test_a_form_without_routes_makes_the_same(kitting3):
    """A form written before routes.npy (`DispatchForm.routes` None): `RouteIndex` makes them from the
    form's arrays as asked, the same; and a dispatcher on it gives the same answers, byte for byte, on
    random runs of every robot and person (tests/team_client.py)."""
    form = kitting3.form
    old = PlanSet(replace(form, routes=None), kitting3.source)
    stored, made = RouteIndex(form), RouteIndex(old.form)
    plans = np.arange(len(form))
    for g in range(form.nodes.shape[1]):
        for k in range(form.nodes.shape[2]):
            assert np.array_equal(stored.routes(plans, g, k), made.routes(plans[::-1], g, k)[::-1])
    robots = tuple(a.id for a in kitting3.task.agents if not a.is_human)
    people = tuple(a.id for a in kitting3.task.agents if a.is_human)
    stnus = {kitting3.id(p): kitting3.entry(p).stnu for p in range(len(kitting3))}
    new_d, old_d = Dispatcher(kitting3), Dispatcher(old)
    for seed in range(6):
        run = TeamRun(new_d.fork(), stnus, robots, people, random.Random(seed))
        run.play()
        replay = old_d.fork()
        assert [json.loads(handle_line(replay, line)) for line in run.sent] == run.answers
