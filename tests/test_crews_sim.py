"""`hrc simulate` for a task whose joint-action crew is a choice of the plan (issue 37, crews):
`tasks/two_workers_joint.yaml` (either worker lifts the kit at the dock O with the robot) and the hand-worked
case of tests/test_crews.py.

What the runs must show is checked against independent truth, not the simulator's own counts:

- **the crew** is who left for the joint action (the happenings): one of the action's crews; the plan the
  dispatcher ended on has that crew (`Task.crew`) and every agent's sequence is what the run did;
- **every constraint of the executed DC plan**: the times the dispatcher accepted (its history) against
  every link of that plan's STNU as the compile wrote it (GraphML read back, `dispatch_client.broken_links`);
- **no robot told to start a joint phase before its crew is there**: each order to start one, logged beside
  what the dispatcher had seen when it gave it, names a phase whose every other crew member's arrival is in
  that history; on the floor, the lead starts it after every crew member arrived, nobody else starts or ends it;
- **a person outside the crew keeps off the joint spot**: no event of theirs for the action, never co-working
  at it, and their disc never within a robot's disc and the margin of the spot while the crew goes there and
  does it (the recorded positions: from the crew's first arrival to the end), even when they stand on it to
  begin with (they walk off);
- **the floor**: as for every team (`test_sim_team._check_floor`);
- **the logs** (`--keep-logs`) replay answer for answer on a fresh dispatcher (`hrc dispatch --replay`'s loop).

Default runs: 15 of the whole task with people who follow, 10 with people who choose freely, 8 with the plans
whose crew is Alice's (the best plans are Bob's: Bob, not in the crew, keeps off the dock, his start), 3 of
the hand case with Bob standing idle on the joint spot. The issue's 200 runs are `slow`.
"""

from __future__ import annotations

import copy
import json
import math
import re
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from conftest import ROOT
from dispatch_client import broken_links
from test_crews import HAND, _write
from test_sim_team import _check_floor

from hrc.cli import main
from hrc.compile.compiler import CompiledPlanSet, compile_task
from hrc.dispatch import Dispatcher
from hrc.dispatch.logfile import read_log
from hrc.dispatch.protocol import replay
from hrc.io.task_file import load_task
from hrc.model import Task
from hrc.sim.human import HumanModel
from hrc.sim.metrics import aggregate
from hrc.sim.montecarlo import simulate, simulation_json
from hrc.sim.run import RunResult, SimContext, SimSettings
from hrc.sim.runlog import log_name
from hrc.sim.team_policies import TeamDispatched, make_team_controller
from hrc.sim.team_run import simulate_team_run
from hrc.temporal.graphml import read_graphml

ERROR_LINE = re.compile(r"^error: [^\n]+: [^\n]+\n$")
TASK = ROOT / "tasks" / "two_workers_joint.yaml"
IDLE_NEARER = 0.5  # m: how much nearer the joint spot an idle person outside the crew may end (`_idle_towards`)


@pytest.fixture(scope="module")
def joint() -> tuple[Task, CompiledPlanSet]:
    task = load_task(TASK)
    return task, compile_task(task, seed=0, jobs=1)


def _ctx(task: Task, cps: CompiledPlanSet, choice: str = "follow") -> SimContext:
    return SimContext(task, {"motion": cps}, SimSettings(human=HumanModel(choice=choice)), 0)


def _only(task: Task, cps: CompiledPlanSet, keep: Any) -> CompiledPlanSet:
    """The compile with only the plans `keep` takes (what a plan choosing that crew gives the dispatcher)."""
    return replace(cps, plans=tuple(cp for cp in cps.plans if keep(cp.plan)))


def _watched(ctx: SimContext, policy: str, index: int) -> tuple[RunResult, TeamDispatched | None, list]:
    """Run `index` recorded, with every order to start a joint phase logged beside the dispatcher's history
    when it gave it (its own, not the simulator's)."""
    held: list[TeamDispatched] = []
    starts: list[tuple[str, Any, frozenset]] = []

    def make(c: SimContext, p: Any) -> Any:
        ctl = make_team_controller(c, p)
        if isinstance(ctl, TeamDispatched):
            held.append(ctl)
            inner = ctl.order

            def order(robot: str) -> Any:
                o = inner(robot)
                if o is not None and o.event == "start" and c.task.action(o.action).joint:
                    starts.append((robot, o, frozenset(ctl.d.seen.times)))
                return o

            ctl.order = order  # type: ignore[method-assign]
        return ctl

    result = simulate_team_run(ctx, policy, index, record=True, controller=make)
    return result, held[0] if held else None, starts


def _came(result: RunResult, action: str) -> tuple[str, ...]:
    return tuple(sorted({h.agent for h in result.happenings if (h.action, h.event) == (action, "depart")}))


def _check_crews(task: Task, result: RunResult, starts: list) -> dict[str, tuple[str, ...]]:
    """Each joint action: its crew (who left for it) is one of its crews; its lead (the crew's first robot)
    starts and ends each phase, after every crew member arrived there, and nobody outside the crew has an event
    of it; every order to start it came once the crew's arrivals were in the dispatcher's history."""
    crews = {}
    for action in (a for a in task.actions if a.joint):
        came = _came(result, action.id)
        assert tuple(sorted(came)) in {tuple(sorted(c)) for c in action.crews}, (action.id, came)
        lead = next(a.id for a in task.agents if a.id in came and not a.is_human)
        for phase in action.phases:
            on = [h for h in result.happenings if (h.action, h.phase) == (action.id, phase.id)]
            assert {h.agent for h in on} == set(came)
            (start,) = [h for h in on if h.event == "start"]
            (end,) = [h for h in on if h.event == "end"]
            assert start.agent == end.agent == lead
            for ag in came:
                (arrive,) = [h.t for h in on if (h.agent, h.event) == (ag, "arrive")]
                assert arrive <= start.t + 1e-9, (ag, action.id)
            for robot, o, seen in starts:
                if (o.action, o.phase) == (action.id, phase.id):
                    assert robot == lead
                    assert all((ag, action.id, phase.id, "arrive") in seen for ag in came if ag != robot)
        crews[action.id] = came
    return crews


def _check_run(task: Task, cps: CompiledPlanSet, result: RunResult, ctl: TeamDispatched | None,
               starts: list) -> tuple[str, ...]:
    """A dispatched run of people who follow: finished on a DC plan whose crew is the one that came and whose
    sequences the run did, every link of its STNU kept; the crews' rules; the floor's. The load's crew."""
    assert result.finished and result.reason == "", result.reason
    assert ctl is not None and result.refused == () and result.late == 0
    crews = _check_crews(task, result, starts)
    cp = next(c for c in cps.plans if c.plan.id == result.final_plan)
    assert cp.plan_class.value == "DC"
    for agent in task.agent_ids:
        did = tuple(dict.fromkeys(h.action for h in result.happenings
                                  if h.agent == agent and h.event == "depart" and h.action))
        assert did == cp.plan.sequence(agent), agent
    assert task.crew("load", cp.plan) == crews["load"]
    assert broken_links(read_graphml(cp.graphml.encode()), dict(ctl.d.seen.times)) == []
    assert result.joint is not None and result.joint["told_before_arrival"] == 0
    _check_floor(task, result)
    return crews["load"]


def _kept_off(task: Task, result: RunResult, action: str, person: str) -> float:
    """How close `person` came to the spot of `action` (its one phase) from the first arrival of its crew
    there to its end, in free metres beyond their disc, a robot's and the margin (must be >= 0); and they
    never co-worked with anyone there."""
    spot = task.workspace.location(task.action(action).phases[0].location)
    on = [h.t for h in result.happenings if h.action == action and h.event in ("arrive", "end")]
    k = task.agent_ids.index(person)
    reach = task.agent(person).radius + max(a.radius for a in task.agents if not a.is_human) + task.safety_margin
    closest = math.inf
    for t, where, cowork in result.agent_frames:
        assert all(person not in pair for pair in cowork), (t, cowork)
        x, y, present = where[k]
        if min(on) - 1e-9 <= t <= max(on) + 1e-9 and present:
            closest = min(closest, math.dist((x, y), (spot.x, spot.y)) - reach)
    return closest


def _idle_towards(task: Task, result: RunResult, action: str, person: str) -> float:
    """How much nearer its spot `person`, idle (from their last event before `action` ends), stands when it ends
    (m; <= 0 when they stayed or went away): a person outside the crew with nothing to do does not head for
    it (going home, when home is its spot). Home elsewhere may lie a little nearer it than where they were
    (Alice's start H is 2 cm nearer the dock than the inspection Q): `IDLE_NEARER` at most."""
    spot = task.workspace.location(task.action(action).phases[0].location)
    end = max(h.t for h in result.happenings if h.action == action)
    idle = max((h.t for h in result.happenings if h.agent == person and h.t < end), default=0.0)
    k = task.agent_ids.index(person)
    dist = [math.dist(where[k][:2], (spot.x, spot.y)) for t, where, _ in result.agent_frames
            if idle - 1e-9 <= t <= end + 1e-9]
    return dist[0] - dist[-1]


# ------------------------------------------------------------------------------------------- the whole task

def test_people_who_follow_keep_every_constraint_and_the_robot_waits_for_its_crew(joint) -> None:
    task, cps = joint
    ctx = _ctx(task, cps)
    for i in range(15):
        result, ctl, starts = _watched(ctx, "hrc", i)
        came = _check_run(task, cps, result, ctl, starts)
        other = next(p for p in ("alice", "bob") if p not in came)
        assert _kept_off(task, result, "load", other) >= 0, i
        assert _idle_towards(task, result, "load", other) < IDLE_NEARER, i


def test_people_who_choose_freely_choose_the_crew_and_the_dispatcher_follows_it(joint) -> None:
    """Free choice: whoever of the two joins the load first is its crew (the other does not join it); the
    dispatcher ends on a plan with that crew and never tells the robot to start before that crew is there."""
    task, cps = joint
    ctx = _ctx(task, cps, "free")
    seen = set()
    for i in range(10):
        result, ctl, starts = _watched(ctx, "hrc", i)
        assert result.finished, (i, result.reason)
        came = _check_crews(task, result, starts)["load"]
        seen.add(came)
        assert ctl is not None and task.crew("load", next(c.plan for c in cps.plans
                                                          if c.plan.id == result.final_plan)) == came
        other = next(p for p in ("alice", "bob") if p not in came)
        assert _kept_off(task, result, "load", other) >= 0, i
        assert result.joint is not None and result.joint["told_before_arrival"] == 0
    assert seen == {("alice", "robot"), ("bob", "robot")}  # both crews come up in these runs


@pytest.mark.parametrize("policy", ["hrc", "fixed"])
def test_alices_crew_bob_keeps_off_the_dock_his_start(joint, policy: str) -> None:
    """The plans whose crew is Alice's only: Bob does his part of them and, with nothing left to do, does not
    go home to the dock while the load is to be done there (he would stand in its spot); under both the
    dispatcher and the fixed plan."""
    task, cps = joint
    alices = _only(task, cps, lambda plan: task.crew("load", plan) == ("alice", "robot"))
    ctx = _ctx(task, alices)
    for i in range(8):
        result, ctl, starts = _watched(ctx, policy, i)
        if policy == "hrc":
            assert _check_run(task, alices, result, ctl, starts) == ("alice", "robot")
        else:
            assert result.finished, result.reason
            assert _check_crews(task, result, starts)["load"] == ("alice", "robot")
            assert result.overlaps == 0  # (a person may walk up to 2 cm of a robot the fixed plan sends: no margin)
        assert _kept_off(task, result, "load", "bob") >= 0, i
        assert _idle_towards(task, result, "load", "bob") < IDLE_NEARER, i


def test_a_person_standing_idle_on_the_joint_spot_walks_off_it(tmp_path: Path) -> None:
    """The hand case with Bob starting on the lift's spot J and the plan giving him nothing (Alice carries and
    lifts): he walks off J before the robot gets there, and the lift is done by its crew, every link kept."""
    doc = copy.deepcopy(HAND)
    doc["agents"][1]["start"] = "J"
    task = load_task(_write(tmp_path, doc))
    full = compile_task(task, seed=0, jobs=1)
    cps = _only(task, full, lambda plan: plan.sequence("bob") == ())
    assert len(cps.plans) == 1 and cps.plans[0].plan_class.value == "DC"
    ctx = _ctx(task, cps)
    for i in range(3):
        result, ctl, starts = _watched(ctx, "hrc", i)
        assert result.finished, result.reason
        crews = _check_crews(task, result, starts)
        assert crews["lift"] == ("alice", "robot")
        assert ctl is not None and broken_links(read_graphml(cps.plans[0].graphml.encode()),
                                                dict(ctl.d.seen.times)) == []
        assert _kept_off(task, result, "lift", "bob") >= 0, i
        assert [h.event for h in result.happenings if h.agent == "bob"] == []  # he only walked off
        _check_floor(task, result)


# ----------------------------------------------------------------------------------------------- the command

def test_hrc_simulate_runs_a_crew_choice_deterministically(tmp_path: Path, capsys) -> None:
    outs = []
    for k in range(2):
        out = tmp_path / f"sim{k}"
        assert main(["simulate", str(TASK), "--runs", "3", "--policy", "hrc,fixed", "--absence-rate", "0.5",
                     "--jobs", "1", "--no-figures", "--quiet", "--out", str(out)]) == 0
        outs.append((out / "simulation.json").read_bytes())
    assert outs[0] == outs[1]
    runs = json.loads(outs[0])["policies"]["hrc"]["runs"]
    assert all(r["finished"] and r["joint"]["told_before_arrival"] == 0 for r in runs)
    rec = tmp_path / "rec"
    assert main(["simulate", str(TASK), "--runs", "1", "--policy", "hrc", "--jobs", "1", "--no-figures",
                 "--quiet", "--out", str(tmp_path / "sim2"), "--record", str(rec)]) == 0
    assert [p.name for p in rec.iterdir()] == ["hrc-0000.mcap"]
    capsys.readouterr()


def test_the_logs_of_runs_with_a_crew_choice_replay_answer_for_answer(joint, tmp_path: Path) -> None:
    """`--keep-logs`: each run's dispatcher log (free people: both crews come up) replays answer for answer on
    a fresh dispatcher over the same compile (`hrc dispatch --replay`'s loop), and keeping them changes no run."""
    task, cps = joint
    ctx = _ctx(task, cps, "free")
    plain = simulate(task, 4, 0, ["hrc"], ctx.settings, jobs=1, compiles={"motion": cps})
    kept = simulate(task, 4, 0, ["hrc"], ctx.settings, jobs=1, compiles={"motion": cps}, keep_logs=True)
    assert simulation_json(plain) == simulation_json(kept) and kept.logs is not None
    holders = {next(p for p in ("alice", "bob") if "load" in r.team["agents"][p]["sequence"])
               for r in kept.results["hrc"] if r.team is not None}
    assert holders == {"alice", "bob"}  # Alice's crew in some runs, Bob's in the others
    pristine = Dispatcher.from_compiled(cps)
    for i in range(4):
        path = tmp_path / log_name("hrc", i)
        path.write_bytes(kept.logs["hrc"][i])
        pairs = list(replay(pristine.fork(), read_log(path), str(path)))
        assert pairs and all(a == b for a, b in pairs), i


def test_a_searched_compile_follows_the_crew_too(joint) -> None:
    """Beyond ``--max-plans`` (`hrc.sim.montecarlo`: a searched compile in memory, compiling on demand when
    the run leaves its plans): 10 runs of people who follow finish, the robot never told to start before its
    crew is there, every run on a DC plan keeps every constraint of it."""
    task, _ = joint
    settings = SimSettings(human=HumanModel(choice="follow"))
    agg = aggregate(simulate(task, 10, 0, ["hrc"], settings, jobs=1, max_plans=10).results["hrc"])
    assert agg["unfinished"] == 0 and agg["joint"]["told_before_arrival"] == 0
    assert agg["first_plan_dc"] == agg["first_plan_dc_kept_all_constraints"] == 10


def test_the_motion_detector_follows_the_crew_too(joint) -> None:
    """`--detector motion`: each person's detector reads the remaining plans (`hrc.detect`), so a candidate
    seen walking to the dock joins the load. 12 runs of people who follow: every run finishes, the robot is
    never told to start before its crew is there, every run on a DC plan keeps it and every constraint."""
    task, cps = joint
    settings = SimSettings(human=HumanModel(choice="follow"), detector="motion")
    agg = aggregate(simulate(task, 12, 0, ["hrc"], settings, compiles={"motion": cps}, jobs=1).results["hrc"])
    assert agg["unfinished"] == 0 and agg["joint"]["told_before_arrival"] == 0
    assert agg["first_plan_dc"] == agg["first_plan_dc_kept"] == agg["first_plan_dc_kept_all_constraints"] == 12


@pytest.mark.slow
def test_200_runs_of_two_workers_joint_keep_every_constraint(joint) -> None:
    """The issue's target with a crew to choose: `hrc simulate tasks/two_workers_joint.yaml --policy hrc --runs
    200`: every run on a DC plan keeps every constraint of it, no robot told to start before its crew is there;
    checked run by run against the dispatcher's history, and on the command's own counts."""
    task, cps = joint
    ctx = _ctx(task, cps)
    for i in range(200):
        result, ctl, starts = _watched(ctx, "hrc", i)
        _check_run(task, cps, result, ctl, starts)
    agg = aggregate(simulate(task, 200, 0, ["hrc"], compiles={"motion": cps}, jobs=1).results["hrc"])
    assert agg["unfinished"] == 0 and agg["joint"]["told_before_arrival"] == 0
    assert agg["first_plan_dc"] == agg["first_plan_dc_kept"] == agg["first_plan_dc_kept_all_constraints"] == 200
