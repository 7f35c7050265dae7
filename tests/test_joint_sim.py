"""Joint actions on the simulated floor (issue 37): `hrc simulate` on a task with "support the pile".

A small task on a bare floor (two fetches, then a joint lift at J, then a place) is simulated under every
policy and person; what the runs must show is checked against independent truth, not the simulator's own
counts: the dispatcher's history (the robot is never told to start the lift before the person's arrival is
in what the dispatcher has seen), the plan's STNU (`dispatch_client.broken_links` on the observed times:
every link kept on a DC plan), the recorded positions (the two stay apart wherever the robot is not
standing at the joint spot), and the happenings (one start and one end, the robot's, inside the joint
phase's contingent bounds). The joint workshop's 200 runs are `slow`.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import pytest
from conftest import ROOT
from dispatch_client import broken_links
from joint_tasks import J, lift_task, write_lift

from hrc.cli import main
from hrc.compile.compiler import compile_task
from hrc.errors import SimulationError
from hrc.io.task_file import load_task
from hrc.report.simulation import actual_spans
from hrc.sim.blind import blind_compile
from hrc.sim.floor import CONTACT, Floor
from hrc.sim.human import HumanModel
from hrc.sim.metrics import aggregate
from hrc.sim.montecarlo import simulate, simulation_json
from hrc.sim.policies import DispatchedController
from hrc.sim.run import SimContext, SimSettings, make_controller, simulate_run

LIFT = lift_task()
"""Fetches at A and B (either agent), the joint lift at J between the two starts (the person holds 3-5 s, the
robot lifts 2-4 s: the step lasts 3-5 s, contingent), then a place at B: after the lift one of them walks or
drives away from the joint spot while the other may still stand there."""

ERROR_LINE = re.compile(r"^error: [^\n]+: [^\n]+\n$")


@pytest.fixture(scope="module")
def lift(tmp_path_factory):
    path = write_lift(tmp_path_factory.mktemp("lift"), LIFT)
    task = load_task(path)
    return path, task, {"motion": compile_task(task, seed=0, jobs=1), "blind": blind_compile(task, jobs=1)}


def _watched(ctx: SimContext, policy: str, index: int) -> tuple[Any, list, DispatchedController | None]:
    """Run `index` recorded, with every order to start a joint phase logged beside what the dispatcher had
    seen when it gave it (its own history, not the simulator's)."""
    starts: list[tuple[Any, frozenset]] = []
    held: list[DispatchedController] = []

    def make(c: SimContext, p: Any):
        ctl = make_controller(c, p)
        if isinstance(ctl, DispatchedController):
            held.append(ctl)
            inner = ctl.order

            def order():
                o = inner()
                if o is not None and o.event == "start" and c.task.action(o.action).joint:
                    starts.append((o, frozenset(ctl.d.seen.times)))
                return o

            ctl.order = order  # type: ignore[method-assign]
        return ctl

    result = simulate_run(ctx, policy, index, record=True, controller=make)
    return result, starts, held[0] if held else None


def _at(happenings, agent: str, action: str, event: str) -> list[float]:
    return [h.t for h in happenings if (h.agent, h.action, h.event) == (agent, action, event)]


def test_a_person_following_a_dc_plan_shares_the_lift_and_every_link_is_kept(lift) -> None:
    _, task, compiles = lift
    ctx = SimContext(task, compiles, SimSettings(), 0)
    margin = task.safety_margin
    for i in range(12):
        r, starts, ctl = _watched(ctx, "hrc", i)
        assert r.finished and r.first_class == "DC" and r.first_kept, (i, r.reason)
        # told to start the lift only once the person's arrival there was in the dispatcher's history
        assert starts and all(("human", "lift", "hold", "arrive") in seen for _, seen in starts), i
        # one start and one end, the robot's, after both arrived, inside the step's contingent bounds
        (start,), (end,) = _at(r.happenings, "robot", "lift", "start"), _at(r.happenings, "robot", "lift", "end")
        assert _at(r.happenings, "human", "lift", "start") == _at(r.happenings, "human", "lift", "end") == []
        (h_arrive,) = _at(r.happenings, "human", "lift", "arrive")
        (r_arrive,) = _at(r.happenings, "robot", "lift", "arrive")
        assert start >= max(h_arrive, r_arrive) - 1e-9
        assert 3 - 1e-6 <= end - start <= 5 + 1e-6
        # every link of the plan's STNU on the times the dispatcher was told
        assert ctl is not None
        stnu = ctl.d.plan_set.entry(ctl.d.plan_set.index(r.final_plan)).stnu
        assert broken_links(stnu, dict(ctl.d.seen.times)) == [], i
        # the separation wherever the robot does not stand at the joint spot (co-work: only there)
        assert r.overlaps == 0 and r.min_distance is not None and r.min_distance >= margin - 1e-6
        # co-work only from the person's departure for the lift to their next arrival elsewhere (or home)
        (h_depart,) = _at(r.happenings, "human", "lift", "depart")
        after = [h.t for h in r.happenings if h.agent == "human" and h.event == "arrive" and h.t > end]
        until = after[0] if after else math.inf
        for f, shared in zip(r.frames, r.cowork_frames, strict=True):
            robot_at_j = math.dist((f[3], f[4]), J) < 1e-6
            assert robot_at_j or not shared
            assert not shared or h_depart <= f[0] <= until + 1e-9, (i, f[0], h_depart, until)
            if not robot_at_j:
                assert math.dist((f[1], f[2]), (f[3], f[4])) - 0.65 >= margin - 1e-6, (i, f)
        assert any(r.cowork_frames) and r.joint is not None and r.joint["cowork_seconds"] > 0
        # the Gantt draws the lift on both rows, over the same span
        joint = frozenset({"lift"})
        lifts = {agent: [(s, e) for k, s, e, label in actual_spans(r, agent, joint) if label == "lift hold"]
                 for agent in ("human", "robot")}
        assert lifts["human"] == lifts["robot"] == [(start, end)]


@pytest.mark.parametrize("choice", ["follow", "preferred", "free"])
def test_every_policy_and_person_shares_the_lift(lift, choice) -> None:
    """Every policy with every simulated person: the lift is done together (the robot's start after the
    person's arrival on the floor), no disc contact outside the co-work, and a dispatched robot is never told
    to start it before the person's arrival is in the dispatcher's history. Runs end finished, or (the
    feasible-only policy with a person who leaves the plans) with the robot stopped."""
    _, task, compiles = lift
    ctx = SimContext(task, compiles, SimSettings(human=HumanModel(choice=choice)), 0)
    for policy in ("hrc", "motion-blind", "feasible-only", "fixed"):
        for i in range(4):
            r, starts, _ = _watched(ctx, policy, i)
            assert r.finished or (policy == "feasible-only" and r.reason.startswith("stuck: the robot stopped")), \
                (policy, i, r.reason)
            assert all(("human", "lift", "hold", "arrive") in seen for _, seen in starts), (policy, i)
            if r.finished:
                (start,), (h_arrive,) = _at(r.happenings, "robot", "lift", "start"), _at(r.happenings, "human", "lift",
                                                                                         "arrive")
                assert start >= h_arrive - 1e-9
            assert r.overlaps == 0 and (r.min_distance is None or r.min_distance > 0), (policy, i)


def test_cowork_lets_the_person_walk_up_to_the_standing_robot(lift) -> None:
    """The floor's rule by hand: the robot stands at J; the person walking H -> J stops 2 cm short of its
    disc, unless the two co-work, when they walk on to J and nothing is measured but the time."""
    _, task, _ = lift
    for cowork in (False, True):
        floor = Floor(task)
        floor.place(floor.robot, J)
        floor.human.set_route(((1.0, 2.0), J), 1.0)
        floor.cowork = cowork
        for _ in range(20):
            floor.advance(0.5)
        x = floor.human.xy[0]
        if cowork:
            assert floor.human.xy == J and not floor.human.moving
            assert floor.cowork_time == pytest.approx(10.0) and floor.overlaps == 0 and math.isinf(floor.min_free)
        else:
            assert x == pytest.approx(5.0 - 0.65 - CONTACT) and floor.cowork_time == 0
            assert floor.min_free == pytest.approx(CONTACT)


def test_the_joint_simulation_is_deterministic_and_says_what_it_measured(lift, tmp_path: Path, capsys) -> None:
    path, task, compiles = lift
    first = simulation_json(simulate(task, 3, 5, ["hrc", "fixed"], compiles=compiles, jobs=1))
    again = simulation_json(simulate(task, 3, 5, ["hrc", "fixed"], compiles=compiles, jobs=1))
    assert first == again
    agg = aggregate(simulate(task, 3, 5, ["hrc"], compiles=compiles, jobs=1).results["hrc"])
    assert agg["joint"]["told_to_start"] == 3 and agg["joint"]["told_before_arrival"] == 0
    out = tmp_path / "sim"
    assert main(["simulate", str(path), "--runs", "2", "--policy", "hrc", "--no-figures", "--jobs", "1",
                 "--out", str(out), "--quiet"]) == 0
    runs = json.loads((out / "simulation.json").read_text("utf-8"))["policies"]["hrc"]["runs"]
    assert all(r["finished"] and r["joint"]["told_before_arrival"] == 0 for r in runs)
    capsys.readouterr()


def test_the_motion_detector_refuses_a_joint_task_in_one_line(lift, tmp_path: Path, capsys) -> None:
    path, task, compiles = lift
    with pytest.raises(SimulationError, match=r"actions\[2\]\.roles: 'lift' is a joint action: --detector motion"):
        simulate(task, 1, 0, ["hrc"], SimSettings(detector="motion"), compiles=compiles)
    out = tmp_path / "sim"
    assert main(["simulate", str(path), "--runs", "1", "--detector", "motion", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert ERROR_LINE.match(err) and str(path) in err, err
    assert not out.exists()


@pytest.mark.slow
def test_the_joint_workshop_200_runs(tmp_path: Path) -> None:
    """The issue's target on `tasks/cube_stacking_joint.yaml`: a person who follows, the dispatcher on the
    motion-aware compile, 200 runs: never told to start "support the pile" before the person was there,
    every run on a DC plan keeping every constraint of its STNU, the separation kept outside the co-work."""
    task = load_task(ROOT / "tasks" / "cube_stacking_joint.yaml")
    sim = simulate(task, 200, 0, ["hrc"], jobs=1)
    agg = aggregate(sim.results["hrc"])
    assert agg["unfinished"] == 0 and agg["joint"]["told_before_arrival"] == 0
    assert agg["joint"]["told_to_start"] == 200
    assert agg["first_plan_dc"] == agg["first_plan_dc_kept"] == agg["first_plan_dc_kept_all_constraints"] == 200
    assert agg["overlaps"] == 0 and agg["min_distance"] >= task.safety_margin
