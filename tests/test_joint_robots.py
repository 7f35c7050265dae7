"""`hrc simulate` of a joint action of two robots (issue 37, a crew of two robots): `tasks/kitting_2robots_joint.yaml`
(three picks, then both robots load the kit at the dock O together) and a hand-worked bare-map case.

What the runs must show is checked against independent truth, not the simulator's own counts:

- **every constraint of the executed DC plan**: the times the dispatcher accepted (its history) against every
  link of that plan's STNU as the compile wrote it (GraphML read back, `dispatch_client.broken_links`);
- **the joint phase**: from the happenings, its lead (the robot, `Task.lead`) starts and ends it once, after
  both robots arrived there; robot2 never starts or ends it;
- **the floor**, from the recorded positions: two robots' discs overlap only at the joint spot (one of them
  standing on it), only while the floor names them co-working, and only from the lead's arrival there;
  anywhere else they keep contact (less a rounding hair); every robot and the person keep the margin;
  pymunk's robot-robot contacts outside co-work: 0;
- **the command**: ``hrc simulate tasks/kitting_2robots_joint.yaml --policy hrc`` finishes every run, each on a
  DC first plan kept with every constraint of its STNU, with no robot-robot contact (simulation.json);
- **the CSTNU Tool** reads every STNU of the task with hrc's verdicts.

The hand-worked case (a bare 14 m x 10 m floor, two robots at 0.5 m/s, the joint spot J 3 m from the robot and
7 m from robot2, 3 s for each role): both leave at 0, the robot arrives at 3 / 0.5 = 6 s, robot2 at
7 / 0.5 = 14 s, so the joint phase starts at 14 s (the later arrival) and ends at 17 s. Swapped (the robot,
which leads, 7 m away): the compile has the lead arrive first (`hrc.motion.conflicts._coworking`: robot2
drives up to the robot standing there), so robot2 waits and arrives the reach the compile keeps after it,
``(0.35 + 0.35 + 0.1 + STEP) / 0.5`` = 1.64 s, and the phase starts then: 15.64 s, ends 18.64 s.

The dispatch form names the lead as the joint action's agent, its leg with the start and end (robot2's: the drive).

The floor by hand (`TeamFloor`, no run loop): robot2 driving at the robot standing on the dock stops 2 cm
short of it, and, the two co-working, drives on to the spot.

Default: 20 runs of the task (and the command's 20); the issue's 200 runs are `slow`.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
import yaml
from conftest import ROOT, dispatched_team_run
from dispatch_client import broken_links
from test_cstnu_tool import _agree, _compiled_classes
from test_cstnu_tool import tool as cstnu_tool  # noqa: F401  (the fixture, as tests/test_cstnu_tool.py finds it)
from test_sim_team import floor_gaps

from hrc.cli import main
from hrc.compile.compiler import compile_task
from hrc.io.task_file import load_task
from hrc.model import Task
from hrc.sim.floor import CONTACT
from hrc.sim.run import RunResult, SimContext, SimSettings
from hrc.sim.team_policies import TeamDispatched
from hrc.temporal.graphml import read_graphml

TASK = ROOT / "tasks" / "kitting_2robots_joint.yaml"


@pytest.fixture(scope="module")
def shipping() -> SimContext:
    task = load_task(TASK)
    return SimContext(task, {"motion": compile_task(task, seed=0, jobs=1)}, SimSettings(), 0)


def _crew(task: Task, result: RunResult, action: str) -> tuple[tuple[str, ...], str]:
    """Who left for joint `action` (task order) and its lead, the first robot of them (`Task.lead`)."""
    came = tuple(a.id for a in task.agents if any((h.agent, h.action, h.event) == (a.id, action, "depart")
                                                  for h in result.happenings))
    return came, next(a for a in came if not task.agent(a).is_human)


def _check_joint(task: Task, result: RunResult) -> None:
    """Each joint phase: started and ended once, by its lead, after every agent of its crew arrived there."""
    for action in (a for a in task.actions if a.joint):
        crew, lead = _crew(task, result, action.id)
        assert tuple(sorted(crew)) in {tuple(sorted(c)) for c in action.crews}
        for phase in action.phases:
            on = [h for h in result.happenings if (h.action, h.phase) == (action.id, phase.id)]
            starts = [h for h in on if h.event == "start"]
            ends = [h for h in on if h.event == "end"]
            assert [h.agent for h in starts] == [lead] and [h.agent for h in ends] == [lead]
            for ag in crew:
                (arrive,) = [h.t for h in on if (h.agent, h.event) == (ag, "arrive")]
                assert arrive <= starts[0].t + 1e-9, (ag, action.id)


def _check_floor(task: Task, result: RunResult) -> None:
    """From the recorded positions: two robots overlap only at a joint spot of theirs, co-working, after the
    lead arrived there; else they keep contact; a robot and the person keep the margin (no co-work here)."""
    joint = {a.id: a for a in task.actions if a.joint}
    crews = {x: _crew(task, result, x) for x in joint}
    lead_there = {x: min(h.t for h in result.happenings if (h.agent, h.action, h.event) == (crews[x][1], x, "arrive"))
                  for x in joint}
    for t, a, b, free, shared, (p, q) in floor_gaps(task, result):
        if a.is_human or b.is_human:
            assert not shared and free >= task.safety_margin - 1e-6, (t, a.id, b.id, free)
            continue
        if free >= -1e-6:
            continue
        assert shared, (t, a.id, b.id, free)  # an overlap: at a joint spot of both, after the lead came
        spots = [(x_, task.workspace.location(ph.location)) for x_, act in joint.items()
                 if {a.id, b.id} <= set(crews[x_][0]) for ph in act.phases]
        assert any(t >= lead_there[x_] - 1e-9  # one of them stands on it
                   and min(math.dist(p, loc.xy), math.dist(q, loc.xy)) < 1e-6
                   for x_, loc in spots), (t, a.id, b.id)
    team = result.team
    assert team is not None and team["robot_contacts"] == 0 and result.overlaps == 0


def _check(ctx: SimContext, result: RunResult, ctl: TeamDispatched) -> None:
    task = ctx.task
    assert result.finished and result.reason == "", result.reason
    assert result.first_class == "DC" and result.first_kept and result.refused == () and result.late == 0
    cp = next(c for c in ctx.compiles["motion"].plans if c.plan.id == result.first_plan)
    assert broken_links(read_graphml(cp.graphml.encode()), dict(ctl.d.seen.times)) == []
    ends = [(h.action, h.phase) for h in result.happenings if h.event == "end"]
    assert sorted(ends) == sorted((a.id, p.id) for a in task.actions for p in a.phases)
    assert result.joint is not None and result.joint["told_before_arrival"] == 0
    _check_joint(task, result)
    _check_floor(task, result)


def test_two_robots_ship_the_kit_keeping_every_constraint(shipping: SimContext) -> None:
    for i in range(20):
        result, ctl = dispatched_team_run(shipping, i)
        _check(shipping, result, ctl)


@pytest.mark.slow
def test_two_robots_ship_the_kit_200_runs(shipping: SimContext) -> None:
    for i in range(200):
        result, ctl = dispatched_team_run(shipping, i)
        _check(shipping, result, ctl)


def test_the_dispatcher_has_the_lead_start_the_shipping(shipping: SimContext) -> None:
    """Every plan as the dispatcher reads it (the dispatch form): the shipping is the robot's (its lead,
    `Task.lead`), whose leg has its start and end; robot2's leg has its drive only."""
    from hrc.dispatch.plan_set import plan_set_from_compiled

    ps = plan_set_from_compiled(shipping.compiles["motion"])
    for p in range(len(ps)):
        entry = ps.entry(p)
        assert entry.plan.agent_of("ship_kit") == "robot"
        assert [e for e, _ in entry.leg_points[("robot", "ship_kit", "load")]] == ["depart", "arrive", "start", "end"]
        assert [e for e, _ in entry.leg_points[("robot2", "ship_kit", "load")]] == ["depart", "arrive"]


def test_hrc_simulate_finishes_every_run_of_the_task(tmp_path: Path) -> None:
    out = tmp_path / "sim"
    assert main(["simulate", str(TASK), "--policy", "hrc", "--runs", "20", "--jobs", "1", "--no-figures",
                 "--out", str(out), "--quiet"]) == 0
    runs = json.loads((out / "simulation.json").read_text("utf-8"))["policies"]["hrc"]["runs"]
    assert len(runs) == 20
    for r in runs:
        assert r["finished"] and r["first_class"] == "DC" and r["first_kept"] and r["first_broken"] == [], r
        assert r["team"]["robot_contacts"] == 0 and r["overlaps"] == 0
        assert r["joint"]["told_before_arrival"] == 0 and r["joint"]["cowork_seconds"] > 0


def test_the_tool_agrees_on_every_stnu_of_the_task(cstnu_tool: Path, tmp_path: Path) -> None:  # noqa: F811
    out = tmp_path / "kj"
    assert main(["compile", str(TASK), "--out", str(out), "--no-report", "-q"]) == 0
    classes = _compiled_classes(out)
    assert len(classes) == 60  # 3! C(5, 2): each robot's shipping last, by the precedence
    assert _agree(cstnu_tool, classes) == {"DC": 36, "NOT_DC": 24}


def test_a_crew_of_two_robots_chosen_by_the_plan(tmp_path: Path) -> None:
    """The shipping as a crew choice (`agents_needed: 2` over the person and the two robots; the person's role
    2-3 s), with only the plans whose crew is the two robots (the best plans have the person ship with robot2):
    the robots' crew ships the kit, every constraint kept, the floor as above; the person never joins it."""
    doc = yaml.safe_load(TASK.read_text("utf-8"))
    doc["map"] = str(ROOT / "maps" / "kitting_cell.yaml")
    ship = next(a for a in doc["actions"] if a["id"] == "ship_kit")
    del ship["roles"]
    ship["agents"], ship["agents_needed"] = ["human", "robot", "robot2"], 2
    ship["phases"][0]["duration"] = {"human": [2, 3], "robot": [3, 4], "robot2": [3, 4]}
    (tmp_path / "task.yaml").write_text(yaml.safe_dump(doc, sort_keys=False), "utf-8")
    task = load_task(tmp_path / "task.yaml")
    full = compile_task(task, seed=0, jobs=1)
    robots = ("robot", "robot2")
    cps = replace(full, plans=tuple(cp for cp in full.plans if task.crew("ship_kit", cp.plan) == robots))
    assert sum(cp.plan_class.value == "DC" for cp in cps.plans) == 36  # the plans of the task with roles
    ctx = SimContext(task, {"motion": cps}, SimSettings(), 0)
    for i in range(10):
        result, ctl = dispatched_team_run(ctx, i)
        _check(ctx, result, ctl)
        assert _crew(task, result, "ship_kit") == (robots, "robot")


# ------------------------------------------------------------------------------------- hand-worked

BARE = """name: bare
bounds: [0, 0, 14, 10]
obstacles: []
locations: {A: [2.0, 5.0], B: [12.0, 5.0], J: [5.0, 5.0]}
"""


def _hand(tmp_path: Path, robot: str, robot2: str) -> SimContext:
    (tmp_path / "bare.yaml").write_text(BARE, "utf-8")
    (tmp_path / "task.yaml").write_text(f"""name: two_robots_one_joint
map: bare.yaml
safety_margin: 0.1
deadline: 60
agents:
  - {{id: robot, kind: robot, radius: 0.35, speed: 0.5, start: {robot}}}
  - {{id: robot2, kind: robot, radius: 0.35, speed: 0.5, start: {robot2}}}
actions:
  - id: lift
    roles: {{front: robot, back: robot2}}
    phases:
      - {{id: hold, location: J, duration: {{front: [3, 3], back: [3, 3]}}}}
""", "utf-8")
    task = load_task(tmp_path / "task.yaml")
    cps = compile_task(task, seed=0, jobs=1)
    assert [cp.plan_class.value for cp in cps.plans] == ["DC"]
    return SimContext(task, {"motion": cps}, SimSettings(), 0)


def _times(result: RunResult) -> dict[tuple[str, str], float]:
    return {(h.agent, h.event): h.t for h in result.happenings}


def test_hand_worked_the_joint_phase_starts_at_the_later_arrival(tmp_path: Path) -> None:
    ctx = _hand(tmp_path, "A", "B")
    result, ctl = dispatched_team_run(ctx, 0)
    _check(ctx, result, ctl)
    t = _times(result)
    assert t[("robot", "depart")] == t[("robot2", "depart")] == 0.0
    assert t[("robot", "arrive")] == pytest.approx(6.0, abs=1e-6)
    assert t[("robot2", "arrive")] == pytest.approx(14.0, abs=1e-6)
    assert t[("robot", "start")] == pytest.approx(14.0, abs=1e-3)
    assert t[("robot", "end")] == pytest.approx(17.0, abs=1e-3) == result.makespan


def test_hand_worked_the_lead_far_away_robot2_comes_after_it(tmp_path: Path) -> None:
    ctx = _hand(tmp_path, "B", "A")
    result, ctl = dispatched_team_run(ctx, 0)
    _check(ctx, result, ctl)
    t = _times(result)
    assert t[("robot", "arrive")] == pytest.approx(14.0, abs=1e-6)
    assert t[("robot2", "arrive")] == pytest.approx(14.0 + (0.35 + 0.35 + 0.1 + 0.02) / 0.5, abs=1e-3)
    assert t[("robot", "start")] == pytest.approx(t[("robot2", "arrive")], abs=1e-3)
    assert t[("robot", "end")] == pytest.approx(t[("robot", "start")] + 3.0, abs=1e-3)


# ------------------------------------------------------------------------------------- the floor by hand

def _robots_at_the_dock(cowork: bool) -> tuple[Any, Any, Any]:
    """The kitting cell: the robot standing on the dock O (7.8, 0.8), robot2 driving at it from 3 m west along
    y = 0.8 (0.6 m/s, radii 0.35), the pair co-working or not."""
    from hrc.sim.team_floor import TeamFloor

    floor = TeamFloor(load_task(TASK))
    person, r1, r2 = floor.movers["human"], floor.movers["robot"], floor.movers["robot2"]
    floor.place(person, (1.5, 1.0))
    floor.place(r1, (7.8, 0.8))
    floor.place(r2, (4.8, 0.8))
    r2.set_route(((4.8, 0.8), (7.8, 0.8)), 0.6)
    floor.cowork = frozenset({("robot2", "robot")}) if cowork else frozenset()
    t = 0.0
    while t < 20.0 and r2.moving:
        h = floor.safe_step()
        floor.advance(h)
        t += h
    return floor, r1, r2


def test_co_working_robots_drive_onto_the_spot_others_stop_short() -> None:
    """Not co-working, robot2 stops 2 cm (CONTACT) short of the robot standing on the spot; co-working, it drives
    on to the spot (both on it, as a person and a robot co-work), no contact counted and their distance not
    measured; the robot never moved."""
    floor, r1, r2 = _robots_at_the_dock(False)
    assert CONTACT - 1e-6 <= math.dist(r1.xy, r2.xy) - 0.7 <= CONTACT + 0.05
    assert floor.robot_contacts() == 0 and r2.blocked_for > 0
    floor, r1, r2 = _robots_at_the_dock(True)
    assert r2.xy == pytest.approx((7.8, 0.8)) and r1.xy == pytest.approx((7.8, 0.8)) and not r2.moving
    assert floor.robot_contacts() == 0 and floor.min_free[("robot", "robot2")] > 2.0
    assert floor.cowork_time > 0
