"""Every answer of the dispatcher equals its definition's, on every message of many random runs.

The dispatcher (`hrc.dispatch.Dispatcher`: the compile's dispatch form, set validation by index, set
ranking in the C core over arrays, shared between twin plans, windows in the C core, APA's DO form on
arrays) is driven side by side with `reference_dispatch.ReferenceDispatcher` (the same cycle on the GraphML
files, plan by plan, from the residual networks' definitions) through the JSON-lines protocol. A random
driver plays the person and the robot from the dispatcher's own options, with unreported departures and
arrivals, overruns, robot acknowledgements early, late and on time, ticks, announced next actions,
away/back, undo and messages no plan allows; after every message the two answers must be the same
bytes, and so must the person's options, and now and then the whole ranking and the best plan's
planned times. Run with the Python evaluator as well as the C core (`native=False`).
"""

from __future__ import annotations

import json
import random
from pathlib import Path

import pytest
from conftest import ROOT
from reference_dispatch import ReferenceDispatcher, read_entries

from hrc.cli import main
from hrc.dispatch import Dispatcher
from hrc.dispatch.protocol import handle_line


def _compile(out: Path, task: str, *args: str) -> Path:
    assert main(["compile", str(ROOT / "tasks" / task), "--out", str(out), "--no-report", "-q", *args]) == 0
    return out


@pytest.fixture(scope="module")
def workshop(tmp_path_factory) -> Path:
    return _compile(tmp_path_factory.mktemp("oracle") / "ws", "cube_stacking.yaml")


@pytest.fixture(scope="module")
def kitting_part(tmp_path_factory) -> Path:
    """Kitting with three actions pinned (360 of its 2,880 plans), its STNUs in an archive."""
    return _compile(tmp_path_factory.mktemp("oracle") / "kit", "kitting.yaml", "--pin", "pick_a=human",
                    "--pin", "pick_c=robot", "--pin", "inspect=human", "--stnu", "archive")


class Driver:
    """Random messages for both dispatchers, from the fast one's options (see the module docstring)."""

    def __init__(self, fast: Dispatcher, ref: ReferenceDispatcher, seed: int) -> None:
        self.fast, self.ref, self.rng = fast, ref, random.Random(seed)
        self.task = fast.task
        self.human = next(a.id for a in self.task.agents if a.is_human)
        self.robot = next(a.id for a in self.task.agents if not a.is_human)
        self.sent = 0

    def send(self, msg: dict) -> dict:
        line = json.dumps(msg)
        got, want = handle_line(self.fast, line), handle_line(self.ref, line)
        assert got == want, f"message {self.sent}: {line}\n fast: {got}\n  ref: {want}"
        self.sent += 1
        options = self.fast.human_options()
        assert options == self.ref.human_options(), f"options after {line}"
        if self.rng.random() < 0.1:
            assert self.fast.candidates == self.ref.candidates, f"candidates after {line}"
            if self.fast.decision.plan is not None:
                assert self.fast.planned_times() == self.ref.planned_times(), f"planned times after {line}"
        return json.loads(got)

    def _later(self, now: float) -> float:
        r = self.rng.random()
        if r < 0.25:
            return now
        if r < 0.9:
            return round(now + self.rng.uniform(0, 6), 3)
        return round(now + self.rng.uniform(10, 60), 3)  # an overrun, a long pause

    def play(self, messages: int) -> None:
        rng = self.rng
        answer = self.send({"t": 0, "event": "tick"})
        for _ in range(messages):
            now = self.fast.now
            decision = answer if answer.get("ok") else self.fast.decision.to_json()
            robot = decision.get("robot")
            options = self.fast.human_options()
            if robot is None and not options and not decision.get("human_away"):
                break
            r = rng.random()
            if r < 0.35 and robot and "wait_for" not in robot:
                lo, hi = robot["earliest"], robot["latest"]
                pick = rng.random()
                if pick < 0.7:
                    t = rng.uniform(lo, lo + 2 if hi is None else min(hi, lo + 2))
                elif pick < 0.85:
                    t = lo - rng.uniform(0, 3)  # early
                else:
                    t = (lo if hi is None else hi) + rng.uniform(0, 5)  # late
                msg = {"t": round(max(now, t), 3), "agent": self.robot, "action": robot["action"],
                       "phase": robot["phase"], "event": robot["event"]}
            elif r < 0.75 and options:
                o = rng.choice(options)
                msg = {"t": self._later(now), "agent": self.human, "action": o.action, "phase": o.phase,
                       "event": o.event}
                if o.event in ("depart", "start") and rng.random() < 0.15:
                    msg["next"] = rng.choice(self.task.action_ids)
            elif r < 0.82:
                msg = {"t": self._later(now), "event": "tick"}
            elif r < 0.86:
                msg = {"t": self._later(now), "agent": self.human, "event": "back" if decision.get("human_away")
                       else "away"}
            elif r < 0.92:
                msg = {"t": round(now + rng.uniform(0, 4), 3), "event": "undo"}
            else:  # anything: most of it no plan allows
                action = rng.choice(self.task.actions)
                msg = {"t": self._later(now), "agent": rng.choice([self.human, self.robot]), "action": action.id,
                       "phase": rng.choice(action.phases).id, "event": rng.choice(["depart", "arrive", "start", "end"])}
            answer = self.send(msg)


def _run(folder: Path, seeds: range, messages: int, native: bool = True, forked: bool = False) -> int:
    """`messages` random messages per seed to the dispatcher and the reference, every answer the same;
    `forked`: each run's dispatcher a fork of one per options, as the simulator's are (the caches of what
    is a function of the plan set, filled by the runs before, shared)."""
    task, entries, rank_by = read_entries(folder)
    shared: dict[tuple, Dispatcher] = {}
    base = Dispatcher.from_folder(folder, threads=2)
    if not native:
        base.ranker.native = None
    sent = 0
    memo: dict = {}
    for seed in seeds:
        options = {"feasible_only": seed % 7 == 3, "use_preferences": seed % 5 != 4}
        if forked:
            key = tuple(options.values())
            fast = shared.setdefault(key, Dispatcher(base.plan_set, ranker=base.ranker, **options)).fork()
        else:
            fast = Dispatcher(base.plan_set, ranker=base.ranker, **options)
        ref = ReferenceDispatcher(task, entries, rank_by, memo=memo, apa_entry=base.plan_set.entry, **options)
        assert fast.decision == ref.decision
        driver = Driver(fast, ref, seed)
        driver.play(messages)
        sent += driver.sent
    return sent


def test_the_workshop_answers_as_defined(workshop):
    """The workshop, with its APA preference: 120 random runs (the next 140 with ``-m slow``)."""
    assert _run(workshop, range(120), 30) > 2300


def test_forks_sharing_their_caches_answer_as_defined(workshop):
    """Each run on a fork of one dispatcher (issue 38: the instruction ahead's distances and the DO forms
    kept across forks): the answers of a fresh one, 15 random runs."""
    assert _run(workshop, range(3000, 3015), 30, forked=True) > 200


def test_kitting_answers_as_defined(kitting_part):
    """Kitting (parks at waiting places, detours, blocked plans), three actions pinned: 10 random runs
    (the next 10 with ``-m slow``)."""
    assert _run(kitting_part, range(1000, 1010), 60) > 350


@pytest.mark.slow
def test_more_workshop_and_kitting_runs_answer_as_defined(workshop, kitting_part):
    """The runs the default test run leaves out, for the full 260 + 20 of before."""
    assert _run(workshop, range(120, 260), 30) > 2700
    assert _run(kitting_part, range(1010, 1020), 60) > 350


def test_the_python_evaluator_answers_as_defined(workshop):
    """Without the C core: the same answers from the Python twin (`hrc.dispatch.fastnet`): 20 runs."""
    assert _run(workshop, range(2000, 2020), 40, native=False) > 400


@pytest.mark.slow
@pytest.mark.parametrize("task", ["kitting.yaml", "kitting_6picks.yaml"])
def test_large_sets_answer_as_defined(tmp_path, task):
    """The whole of kitting (2,880 plans) and kitting_6picks (5,040 plans, twins by identical actions):
    60 random runs each."""
    folder = _compile(tmp_path / "out", task, "--stnu", "archive")
    assert _run(folder, range(3000, 3060), 80) > 2500
