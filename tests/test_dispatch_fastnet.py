"""The dispatcher's fast re-check (`hrc.dispatch.fastnet`) against its definition on the residual
network (`reference_evaluate`: `residual_network`, `check_dc`, `earliest_times`), on random histories
of the workshop: every state a random run passes through, every remaining plan."""

from __future__ import annotations

import random

import pytest
from conftest import ROOT
from dispatch_client import Run

from hrc.cli import main
from hrc.dispatch import Dispatcher
from hrc.dispatch.plan_set import load_plan_set
from hrc.dispatch.protocol import handle_line
from hrc.dispatch.ranking import evaluate, reference_evaluate
from hrc.dispatch.validation import executed, ticks


@pytest.fixture(scope="module")
def workshop(tmp_path_factory):
    out = tmp_path_factory.mktemp("fastnet") / "ws"
    assert main(["compile", str(ROOT / "tasks" / "cube_stacking.yaml"), "--out", str(out), "--no-report",
                 "-q"]) == 0
    return load_plan_set(out)


def _states(plan_set, seed: int, timing: str):
    d = Dispatcher(plan_set)
    states = []

    def send(line: str) -> str:
        answer = handle_line(d, line)
        states.append((d.seen, tuple(d.plan_set.plans[i] for i in d._state.ranked)))
        return answer

    Run(plan_set, send, seed, human_choice="random", timing=timing).play()
    return states


@pytest.mark.parametrize("seed", range(4))
def test_fast_recheck_is_the_residual_networks(workshop, seed):
    rng = random.Random(seed)
    checked = 0
    for history, plans in _states(workshop, seed, "eager" if seed % 2 else "hinted"):
        for entry in plans:
            done = executed(entry, history)
            for now in {ticks(history.now), ticks(history.now) + rng.randint(0, 40000)}:
                for rank_by in ("worst", "earliest", "nominal"):
                    assert evaluate(entry, done, now, rank_by) == reference_evaluate(entry, done, now, rank_by), \
                        (entry.id, now, rank_by, sorted(done.items()))
                    checked += 1
    assert checked > 100

