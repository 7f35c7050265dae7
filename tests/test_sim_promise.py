"""Issue 32 in simulation: the dispatcher follows the delay-robust strategy, and `hrc simulate` measures it.

The truth each test holds runs to is the plan's own STNU, replayed against what happened on the floor
(`hrc.sim.replay.broken_constraints`: every link, to the tick), and for the late-observation counts the
run's own record of the person's events (each one late by construction).
"""

from __future__ import annotations

import json
from dataclasses import replace

import pytest
from conftest import ROOT, WORKSHOP_TASK

from hrc.compile.compiler import compile_task
from hrc.detect.sensor import SensorModel
from hrc.io.task_file import load_task
from hrc.model import SENSING_PATHS, Sensing
from hrc.sim.human import HumanModel
from hrc.sim.montecarlo import simulate, simulation_json
from hrc.sim.run import SimContext, SimSettings, simulate_run

FOLLOW = HumanModel(choice="follow")


@pytest.fixture(scope="module")
def workshop():
    task = load_task(WORKSHOP_TASK)
    return task, compile_task(task, seed=0, jobs=1)


def _motion(task, cps, sigma: float = 0.05) -> SimContext:
    settings = SimSettings(human=FOLLOW, detector="motion", sensor=SensorModel(sigma=sigma))
    return SimContext(task, {"motion": cps}, settings, 0)


# Runs of the workshop (seed 0, the motion detector at 0.05 m / 10 Hz) in which the dispatcher of main broke
# a passing order of its DC first plan: the person left S3 when told, the detector dated it 20-60 ms late,
# and the robot, its window pinned to that estimate with no slack, passed T that much too late.
BROKEN_BEFORE = (0, 1, 3, 4)


@pytest.mark.parametrize("index", BROKEN_BEFORE)
def test_the_delay_robust_dispatcher_keeps_the_passing_orders_the_estimate_broke(workshop, index):
    task, cps = workshop
    r = simulate_run(_motion(task, cps), "hrc", index)
    assert r.first_class == "DC" and r.first_kept and r.finished
    assert r.first_broken == ()


def test_a_late_observation_is_counted_once_per_event_and_voids_nothing_else(workshop):
    """Buttons 0.7 s late against a stated maximum of 0.5 s: every one of the person's events comes late,
    so a run counts exactly as many late observations as the person had events told (the run's record);
    0.3 s late: none. simulation.json carries the counts per run and the aggregate."""
    task, _ = workshop
    delay, dated = SENSING_PATHS["buttons"]
    stated = replace(task, sensing=Sensing("buttons", delay, dated))
    cps = compile_task(stated, seed=0, jobs=1)
    for lateness, every in ((0.7, True), (0.3, False)):
        settings = SimSettings(human=FOLLOW, detection_delay=lateness)
        sim = simulate(stated, 2, 0, ("hrc",), settings, jobs=1, compiles={"motion": cps})
        out = json.loads(simulation_json(sim))["policies"]["hrc"]
        ctx = SimContext(stated, {"motion": cps}, settings, 0)
        for run in out["runs"]:
            record = simulate_run(ctx, "hrc", run["run"], record=True)
            # the person's events passed on before the run ended (at its last phase's end: one due later
            # is never told)
            end = max(h.t for h in record.happenings)
            events = sum(1 for h in record.happenings if h.agent == "human" and h.t + lateness <= end + 1e-9)
            assert events >= 20
            assert run["late_observations"] == (events if every else 0)
            assert run["first_sensing_class"] == "DC"
        promise = out["aggregate"]["promise"]
        assert promise["runs_with_late_observations"] == (2 if every else 0)
        assert promise["late_observations"] == sum(r["late_observations"] for r in out["runs"])
        assert promise["dc_at_sensing"] == 2
        assert promise["dc_at_sensing_within_delay"] == (0 if every else 2)
        if not every:
            assert promise["kept_every_constraint"] == 2


def test_without_a_stated_delay_simulation_json_has_no_promise_counts(workshop):
    task, cps = workshop
    sim = simulate(task, 1, 0, ("hrc",), SimSettings(human=FOLLOW, detection_delay=0.7), jobs=1,
                   compiles={"motion": cps})
    out = json.loads(simulation_json(sim))["policies"]["hrc"]
    assert "promise" not in out["aggregate"] and "late_observations" not in out["runs"][0]


# Runs of the workshop that broke a passing order before the detector stated a change point's span: the
# person left S5 at the hinted earliest, the hinge dated it 127-154 ms early (0.05 m) or 376-508 ms (0.15 m /
# 5 Hz / 5 % dropouts), beyond 3 sigma: read as leaving early, the plan turned inconsistent and the robot,
# told no latest, ended its put of cube 4 up to 1 s too late (issue 32's 1.5-2.5 % of runs).
SPAN_BROKE = ((50, 0.05, 10.0, 0.0), (98, 0.05, 10.0, 0.0), (110, 0.05, 10.0, 0.0), (40, 0.15, 5.0, 0.05),
              (126, 0.15, 5.0, 0.05))


@pytest.mark.parametrize("index, sigma, rate, dropout", SPAN_BROKE)
def test_an_estimate_beyond_three_sigma_but_within_its_span_keeps_the_promise(workshop, index, sigma, rate,
                                                                               dropout):
    task, cps = workshop
    task = replace(task, sensing=Sensing("motion", *SENSING_PATHS["motion"]))
    settings = SimSettings(human=FOLLOW, detector="motion", sensor=SensorModel(sigma=sigma, rate=rate,
                                                                               dropout=dropout))
    r = simulate_run(SimContext(task, {"motion": cps}, settings, 0), "hrc", index)
    assert r.first_class == "DC" and r.first_kept and not r.late_observations
    assert r.first_broken == ()


@pytest.mark.slow
def test_kitting_under_the_motion_detector_costs_little_makespan():
    """Kitting's stay at Q (inspect, label, deliver's take: no step between them for a tracker to see):
    the person goes through it as the instruction ahead says for its first step, instead of waiting for
    the chart's planned times (issue 32: +8-9 % median makespan against buttons on time before). Runs
    0-7: median within 3 % of buttons on time, every DC run keeping every constraint."""
    import statistics

    task = load_task(ROOT / "tasks" / "kitting.yaml")
    cps = compile_task(task, seed=0, jobs=1)
    on = SimContext(task, {"motion": cps}, SimSettings(human=FOLLOW), 0)
    motion = _motion(replace(task, sensing=Sensing("motion", *SENSING_PATHS["motion"])), cps)
    base = [simulate_run(on, "hrc", i).makespan for i in range(8)]
    runs = [simulate_run(motion, "hrc", i) for i in range(8)]
    assert all(r.first_broken == () for r in runs if r.first_class == "DC" and r.first_kept)
    assert statistics.median(r.makespan for r in runs) <= 1.03 * statistics.median(base)


@pytest.mark.slow
def test_kitting_under_the_motion_detector_keeps_the_promise_the_old_dispatcher_broke():
    """Kitting, fine sensor: on main every run on the DC first plan broke a passing order (the instruction
    ahead forgot "leave 5 s after the robot" once the robot had left, and estimates pinned the robot's
    windows); runs 0-5 now keep every constraint."""
    task = load_task(ROOT / "tasks" / "kitting.yaml")
    cps = compile_task(task, seed=0, jobs=1)
    ctx = _motion(task, cps)
    kept = 0
    for index in range(1, 6):
        r = simulate_run(ctx, "hrc", index)
        if r.first_class == "DC" and r.first_kept:
            assert r.first_broken == ()
            kept += 1
    assert kept >= 4


def test_hrc_simulate_compiles_under_the_stated_sensing_and_reports_the_promise(tmp_path, capsys):
    from hrc.cli import main

    out = tmp_path / "sim"
    assert main(["simulate", str(WORKSHOP_TASK), "--policy", "hrc", "--human", "follow", "--runs", "1", "--jobs",
                 "1", "--no-figures", "--detection-delay", "0.7", "--sensing", "buttons", "--observation-delay",
                 "0:0.6", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "the promise under buttons (observation delay [0, 0.6] s)" in printed
    assert "1/1 runs with an observation later than stated" in printed
    data = json.loads((out / "simulation.json").read_text())
    assert data["policies"]["hrc"]["aggregate"]["promise"]["runs_with_late_observations"] == 1


@pytest.mark.slow
def test_without_the_c_core_the_windows_under_the_detector_are_the_same(workshop):
    """The Python reading of the windows (no C core) takes an estimate's latest possible time after the
    last message as the core does: the same run, field for field (it used to refuse it and stick)."""
    import copy

    from hrc.sim.run import make_controller

    task, cps = workshop
    ctx = _motion(task, cps)

    def python_only(c, policy):
        ctl = make_controller(c, policy)
        ranker = copy.copy(ctl.d.ranker)
        ranker.native = None
        ctl.d.ranker = ranker
        return ctl

    native = simulate_run(ctx, "hrc", 1).to_json()
    plain = simulate_run(_motion(task, cps), "hrc", 1, controller=python_only).to_json()
    assert plain == native and native["finished"]
