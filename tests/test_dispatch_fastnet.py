"""Set ranking's two evaluators of a plan under a state — the C core over the dispatch form's arrays
(`hrc.dispatch.native`) and its Python twin (`hrc.dispatch.fastnet`) — against the definition on the
residual network of the plan's GraphML file (`reference_evaluate`: `residual_network`, `check_dc`,
`earliest_times`), on every remaining plan of every state random workshop runs pass through, for every
``rank_by`` and at later times too (time passing with nothing seen). Also: the form's arrays are the
GraphML files' networks (the same distance graph, timepoint by timepoint)."""

from __future__ import annotations

import random

import numpy as np
import pytest
from conftest import ROOT
from dispatch_client import Run
from reference_dispatch import read_entries

from hrc.cli import main
from hrc.dispatch import Dispatcher, Observation
from hrc.dispatch import native as native_core
from hrc.dispatch.fastnet import PlanNet
from hrc.dispatch.protocol import handle_line
from hrc.dispatch.ranking import CLASS_ORDER, NO_FINISH, reference_evaluate
from hrc.dispatch.validation import executed, seen_arrays, ticks
from hrc.temporal.graph import distance_edges


@pytest.fixture(scope="module")
def workshop(tmp_path_factory):
    out = tmp_path_factory.mktemp("fastnet") / "ws"
    assert main(["compile", str(ROOT / "tasks" / "cube_stacking.yaml"), "--out", str(out), "--no-report",
                 "-q"]) == 0
    return out


def _states(d: Dispatcher, seed: int, timing: str):
    states = []

    def send(line: str) -> str:
        answer = handle_line(d, line)
        states.append((d.seen, d._state.plans.tolist()))
        return answer

    Run(d.plan_set, send, seed, human_choice="random", timing=timing).play()
    return states


def test_the_forms_networks_are_the_graphml_files(workshop):
    d = Dispatcher.from_folder(workshop)
    _task, entries, _rank_by = read_entries(workshop)
    for p, entry in enumerate(entries):
        assert d.plan_set.id(p) == entry.id and d.plan_set.form.plan(p) == entry.plan

        def graph(stnu):
            best: dict = {}
            for e in distance_edges(stnu):
                if e.source != e.target or e.value < 0:
                    best[(e.source, e.target)] = min(best.get((e.source, e.target), e.value), e.value)
            return best, {(c.source, c.target, c.lb, c.ub) for c in stnu.contingents}

        assert graph(d.plan_set.form.stnu(p)) == graph(entry.stnu)


@pytest.mark.parametrize("seed", range(4))
def test_fast_recheck_is_the_residual_networks(workshop, seed):
    rng = random.Random(seed)
    d = Dispatcher.from_folder(workshop)
    _task, entries, _rank_by = read_entries(workshop)
    form = d.plan_set.form
    core = native_core.NativeForm(form) if native_core.available() else None
    checked = 0
    for history, plans in _states(d, seed, "eager" if seed % 2 else "hinted"):
        seen, legs_seen = seen_arrays(history, form.nodes.shape[2])
        for now in {ticks(history.now), ticks(history.now) + rng.randint(0, 40000)}:
            later = history if now == ticks(history.now) else history.add(Observation(now / 1000, "tick"))
            for rank_by in ("worst", "earliest", "nominal"):
                got = core.evaluate(np.array(plans), seen, legs_seen, now, rank_by) if core else None
                for k, p in enumerate(plans):
                    want = reference_evaluate(entries[p], executed(entries[p], later), now, rank_by)
                    want_t = (want.plan_class, NO_FINISH if want.finish is None else want.finish, want.idle)
                    net = PlanNet(form.arrays(p))
                    ex = net.executed(seen, legs_seen)
                    times = net.schedule(ex, now, rank_by)
                    cls = "inconsistent" if entries[p].blocked else net.verdict(ex, now, lambda: "?")
                    twin = (cls, NO_FINISH if times is None else max(times), 0 if times is None else net.idle(times))
                    assert twin == want_t, (entries[p].id, now, rank_by)
                    if got is not None:
                        assert (CLASS_ORDER[int(got[0][k])], int(got[1][k]), int(got[2][k])) == want_t
                    checked += 1
    assert checked > 150


@pytest.fixture(scope="module")
def team_kitting():
    from dataclasses import replace

    from hrc.compile.compiler import compile_task
    from hrc.io.task_file import load_task

    full = load_task(ROOT / "tasks" / "kitting_2robots.yaml")
    return Dispatcher.from_compiled(compile_task(replace(full, actions=full.actions[:3]), seed=0, jobs=1))


def _team_states(d: Dispatcher, seed: int) -> list:
    from team_client import TeamRun

    states = []
    stnus = {}

    class Recorded(TeamRun):
        def send(self, message):  # noqa: ANN001, ANN202
            out = super().send(message)
            states.append((d.seen, d._state.plans.tolist()))
            return out

    class STNUs(dict):
        def __missing__(self, plan):  # noqa: ANN001, ANN204
            self[plan] = d.plan_set.entry(d.plan_set.index(plan)).stnu
            return self[plan]

    agents = d.task.agents
    Recorded(d, STNUs(stnus), tuple(a.id for a in agents if not a.is_human),
             tuple(a.id for a in agents if a.is_human), random.Random(seed)).play()
    return states


def test_the_cores_shortcuts_are_the_residual_networks(team_kitting, workshop):
    """The C core decides most plans without the RUL check (`hrc/dispatch/_dispatchcore.c`: a residual
    that is strongly controllable is DC; one whose STN is inconsistent is inconsistent, its schedules
    skipped): on a team (two robots, one person, three picks), every remaining plan of every state of random
    runs, at the state's time and later (links past their bounds), every ``rank_by``, equal to the definition
    on the residual network; and the workshop's (one of each, plans often not DC). Each way the core can
    decide a class is taken: by Vidal & Fargier's strong
    controllability (`hrc.temporal.delay.strong_network`, an independent reduction) checked here on each
    residual: strongly controllable plans (all DC), consistent ones and inconsistent ones."""
    from hrc.temporal import STNU, RequirementLink, check_dc, earliest_times, residual_network
    from hrc.temporal.delay import strong_network

    if not native_core.available():
        pytest.skip("the C core is not built")
    rng = random.Random(7)
    kinds: dict[str, int] = {}
    ws = Dispatcher.from_folder(workshop)
    runs = [(team_kitting, _team_states(team_kitting.fork(), seed)[::3]) for seed in range(2)]
    runs += [(ws, _states(ws.fork(), 1, "eager")[::2])]
    for d, states in runs:
        form = d.plan_set.form
        core = native_core.NativeForm(form)
        for history, plans in states:
            seen, legs_seen = seen_arrays(history, form.nodes.shape[2])
            for now in (ticks(history.now), ticks(history.now) + rng.randint(0, 120000)):
                later = history if now == ticks(history.now) else history.add(Observation(now / 1000, "tick"))
                for rank_by in ("worst", "earliest", "nominal"):
                    got = core.evaluate(np.array(plans), seen, legs_seen, now, rank_by)
                    for k, p in enumerate(plans):
                        entry = d.plan_set.entry(p)
                        done = executed(entry, later)
                        want = reference_evaluate(entry, done, now, rank_by)
                        want_t = (want.plan_class, NO_FINISH if want.finish is None else want.finish, want.idle)
                        assert (CLASS_ORDER[int(got[0][k])], int(got[1][k]), int(got[2][k])) == want_t
                        if rank_by == "worst" and not entry.blocked:
                            residual = residual_network(entry.stnu, done, now)
                            strong = strong_network(residual)
                            sc = not strong.broken and check_dc(strong.network).consistent
                            assert not sc or want.plan_class == "DC"
                            at_lb = STNU(residual.timepoints, residual.requirements + tuple(
                                RequirementLink(c.source, c.target, c.lb, c.lb) for c in residual.contingents), ())
                            lb = earliest_times(at_lb, residual.timepoints[0]) is not None
                            kind = f"{want.plan_class}{' SC' if sc else ''}{' lb' if lb else ''}"
                            kinds[kind] = kinds.get(kind, 0) + 1
    # strongly controllable (DC without the RUL check); consistent with a schedule at the lower bounds (the
    # STN check passed, then the RUL check); inconsistent (the STN check fails: no RUL check, no strict
    # schedule). No residual here is DC without being strongly controllable (nor in kitting's runs): those
    # take the RUL check, as every plan did before.
    assert {"DC SC lb", "consistent lb", "inconsistent"} <= set(kinds), kinds
