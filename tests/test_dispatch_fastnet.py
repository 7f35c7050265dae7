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
