"""A team under speed and separation monitoring (ISO/TS 15066, issue 37 with issue 33): every robot against
every person on the team floor (`hrc.sim.team_floor.TeamFloor`), and simulated runs of
tasks/kitting_2robots_iso.yaml.

The truth the floor is held to is computed here from the standard's equation (ISO/TS 15066:2016, 5.5.4.2.3,
eq. 1, constant speeds: ``S_p(v) = v_h (T_r + T_s) + v T_r + S_s + C + Z_d + Z_r``, ``T_s = v / a``,
``S_s = v^2 / 2a``), never from `hrc.motion.separation`:

- **by hand** on the corridor of tests/data/separation (T_r 0.1 s, a = 1 m/s^2, v_h 1.6 m/s, C = Z = 0,
  reduced speed 0.3 m/s): two robots of different speeds crossing towards a standing person each slow and
  stop where the standard says *at its own speed*; a robot passing one person on its way to another slows
  for the first (the most demanding) and stops at the second;
- **the runs**, from the recorded positions of every step: no robot ends a step in which it drove towards a
  person closer than S_p of the speed it drove, no robot-person pair closer than S_p(0) at any step, and
  every link of the executed DC plan's STNU kept (GraphML read back, `dispatch_client.broken_links`);
- **the compile** (motion acquisition keeps S_p between every robot and every person, at that robot's speed):
  an independent referee (tests/referee.py) moving every agent along its routes in dispatched DC plans;
- **what each robot is told**: its own limits, S_p at its own speed.

Default: 10 runs of kitting_2robots_iso cut to three picks (60 plans, as tests/test_sim_team.py); the whole
task's 200 runs are `slow`. 1+1 tasks are untouched by the team floor (their simulation.json bytes are
compared against main's in the branch's report, not here).
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from conftest import ROOT, dispatched_team_run
from dispatch_client import broken_links

from hrc.cli import main
from hrc.compile.compiler import compile_task
from hrc.io.task_file import load_task
from hrc.model import Agent, AgentKind, Task
from hrc.sim.run import RunResult, SimContext, SimSettings
from hrc.sim.team_policies import TeamDispatched
from hrc.temporal.graphml import read_graphml

CORRIDOR = ROOT / "tests" / "data" / "separation" / "crossing_iso.yaml"


def s_p(v: float, t_r: float = 0.1, a: float = 1.0, v_h: float = 1.6, c: float = 0.0, z: float = 0.0) -> float:
    """ISO/TS 15066 eq. 1 with constant speeds, by hand (see the module docstring)."""
    t_s = v / a
    return v_h * (t_r + t_s) + v * t_r + v * v / (2 * a) + c + z


# ------------------------------------------------------------------------------------------ by hand
def _team(people: int, speeds: tuple[float, ...]) -> Task:
    """The corridor task with `people` people (radius 0.3) and a robot (radius 0.35) per speed, under its
    safety: section (T_r 0.1 s, 1 m/s^2) with a reduced speed of 0.3 m/s."""
    task = load_task(CORRIDOR)
    assert task.safety is not None
    agents = [Agent(f"p{i}", AgentKind.HUMAN, 0.3, 1.2, "H") for i in range(people)]
    agents += [Agent(f"r{i}", AgentKind.ROBOT, 0.35, v, "R") for i, v in enumerate(speeds)]
    return replace(task, agents=tuple(agents), safety=replace(task.safety, reduced_speed=0.3))


def _drive(floor: Any, until: float) -> list[tuple[float, dict[str, tuple[float, float]]]]:
    """Advance `floor` by its own steps to `until` s: every disc's centre before the first step (at 0) and
    after each step, with the time."""
    t, out = 0.0, [(0.0, {k: m.xy for k, m in floor.movers.items()})]
    while t < until - 1e-9:
        h = min(floor.safe_step(), until - t)
        floor.advance(h)
        t += h
        out.append((t, {k: m.xy for k, m in floor.movers.items()}))
    return out


def _no_step_closer_than_the_standard(trace: list, floor: Any, radii: float = 0.65) -> None:
    """At the end of every step in which a robot drove towards a person, their free distance is at least
    S_p (by hand) of the robot's mean speed over the step (its speed, or less in a step it stopped in)."""
    t0, prev = trace[0]
    for t, where in trace[1:]:
        for r in (m for m in floor.robots):
            rid = r.agent.id
            moved = math.dist(prev[rid], where[rid])
            if moved <= 1e-12:
                continue
            for p in floor.people:
                pid = p.agent.id
                if math.dist(where[rid], where[pid]) < math.dist(prev[rid], where[pid]):  # towards them
                    free = math.dist(where[rid], where[pid]) - radii
                    assert free >= s_p(moved / (t - t0)) - 1e-9, (rid, pid, t, free)
        prev, t0 = where, t


def test_two_robots_crossing_by_a_person_each_stop_where_the_standard_says_at_its_own_speed() -> None:
    """The person stands at (5, 0.9) in the corridor. r0 (0.6 m/s) drives west along y = 0.5 from x = 9.5, r1
    (0.4 m/s) east along y = 1.3 from x = 0.5: their lanes are 0.8 m apart (free 0.1 m), so they cross.

    By hand, a robot at (x, y) is (x - 5)^2 + (y - 0.9)^2 from the person; radii 0.65 m. S_p(0.6) = 1.6 x 0.7 +
    0.06 + 0.18 = 1.36 m, S_p(0.4) = 1.6 x 0.5 + 0.04 + 0.08 = 0.92 m, S_p(0.3) = 1.6 x 0.4 + 0.03 + 0.045 =
    0.715 m. r0 drives at 0.6 until its free distance is 1.36 m (x = 5 + sqrt(2.01^2 - 0.4^2)), then at 0.3 until
    0.715 m (x = 5 + sqrt(1.365^2 - 0.4^2)), and stops; r1 at 0.4 until 0.92 m (x = 5 - sqrt(1.57^2 - 0.4^2)),
    then 0.3 until 0.715 m, and stops: one protective stop each, no breach. The person then walks up the side
    passage (north, to (5, 5)) and both resume, cross each other and reach their ends, never closer than
    the standard allows."""
    from hrc.sim.team_floor import TeamFloor

    floor = TeamFloor(_team(1, (0.6, 0.4)))
    person, r0, r1 = floor.movers["p0"], floor.movers["r0"], floor.movers["r1"]
    floor.place(person, (5.0, 0.9))
    floor.place(r0, (9.5, 0.5))
    floor.place(r1, (0.5, 1.3))
    r0.set_route(((9.5, 0.5), (1.0, 0.5)), 0.6)
    r1.set_route(((0.5, 1.3), (9.0, 1.3)), 0.4)
    slow0 = 5 + math.sqrt((0.65 + s_p(0.6)) ** 2 - 0.4 ** 2)
    stop0 = 5 + math.sqrt((0.65 + s_p(0.3)) ** 2 - 0.4 ** 2)
    slow1 = 5 - math.sqrt((0.65 + s_p(0.4)) ** 2 - 0.4 ** 2)
    stop1 = 5 - math.sqrt((0.65 + s_p(0.3)) ** 2 - 0.4 ** 2)
    trace = _drive(floor, 25.0)
    assert r0.xy[0] == pytest.approx(stop0, abs=1e-9) and r1.xy[0] == pytest.approx(stop1, abs=1e-9)
    assert floor.gap(r0, person) == pytest.approx(s_p(0.3), abs=1e-9)
    # each slowed exactly where S_p at its top speed was reached (a step ends there), and not before
    xs0 = [w["r0"][0] for _, w in trace]
    xs1 = [w["r1"][0] for _, w in trace]
    assert any(abs(x - slow0) < 1e-9 for x in xs0) and any(abs(x - slow1) < 1e-9 for x in xs1)
    # reached at full speed all the way, then 0.3 m/s (by the end of the step that got there: <= MIN_STEP later)
    t_slow0 = next(t for t, w in trace if abs(w["r0"][0] - slow0) < 1e-9)
    assert 0 <= t_slow0 - (9.5 - slow0) / 0.6 <= 0.02 + 1e-9
    t_stop0 = next(t for t, w in trace if abs(w["r0"][0] - stop0) < 1e-9)
    assert 0 <= t_stop0 - ((9.5 - slow0) / 0.6 + (slow0 - stop0) / 0.3) <= 0.04 + 1e-9
    t_slow1 = next(t for t, w in trace if abs(w["r1"][0] - slow1) < 1e-9)
    assert 0 <= t_slow1 - (slow1 - 0.5) / 0.4 <= 0.02 + 1e-9
    t_stop1 = next(t for t, w in trace if abs(w["r1"][0] - stop1) < 1e-9)
    assert 0 <= t_stop1 - ((slow1 - 0.5) / 0.4 + (stop1 - slow1) / 0.3) <= 0.04 + 1e-9
    _no_step_closer_than_the_standard(trace, floor)
    for rid in ("r0", "r1"):
        m = floor.ssm[rid].measures()
        assert (m.protective_stops, m.breaches) == (1, 0), rid
        assert m.min_free_robot_approaching == pytest.approx(s_p(0.3), abs=1e-9)
    # slowing: r0 lost half its time over (slow0 - stop0) / 0.3 s, r1 a quarter over (stop1 - slow1) / 0.3 s
    assert floor.ssm["r0"].measures().slow_time == pytest.approx((slow0 - stop0) / 0.3 / 2, abs=0.02)
    assert floor.ssm["r1"].measures().slow_time == pytest.approx((stop1 - slow1) / 0.3 / 4, abs=0.02)
    # the person leaves up the side passage: both resume, cross each other and reach their ends
    person.set_route(((5.0, 0.9), (5.0, 5.0)), 1.2)
    trace = _drive(floor, 40.0)
    assert not r0.moving and not r1.moving and r0.xy == (1.0, 0.5) and r1.xy == (9.0, 1.3)
    _no_step_closer_than_the_standard(trace, floor)
    assert all(floor.ssm[r].measures().breaches == 0 for r in ("r0", "r1"))
    assert floor.robot_contacts() == 0 and floor.min_free[("r0", "r1")] >= 0.1 - 1e-9
    assert floor.overlaps() == 0


def test_the_most_demanding_person_decides_the_speed() -> None:
    """One robot (0.6 m/s) drives west along y = 0.9 from x = 9.5 to x = 1; person A stands on its way at
    (2, 0.9), person B in the side passage at (5, 2.6), 1.7 m off its lane. By hand: B's free distance is
    sqrt((x - 5)^2 + 1.7^2) - 0.65, which reaches S_p(0.6) = 1.36 m at x = 5 + sqrt(2.01^2 - 1.7^2) (A is 4 m
    away: not it): B makes it slow to 0.3 m/s; B's closest, 1.05 m at x = 5, is above S_p(0.3) = 0.715 m, so
    no stop there; past x = 5 it drives away from B and A allows full speed again until 1.36 m from A (x = 2 +
    0.65 + 1.36), then 0.3 m/s until 0.715 m (x = 2 + 0.65 + 0.715), where it stops: one protective stop."""
    from hrc.sim.team_floor import TeamFloor

    floor = TeamFloor(_team(2, (0.6,)))
    a, b, r = floor.movers["p0"], floor.movers["p1"], floor.movers["r0"]
    floor.place(a, (2.0, 0.9))
    floor.place(b, (5.0, 2.6))
    floor.place(r, (9.5, 0.9))
    r.set_route(((9.5, 0.9), (1.0, 0.9)), 0.6)
    trace = _drive(floor, 30.0)
    slow_b = 5 + math.sqrt((0.65 + s_p(0.6)) ** 2 - 1.7 ** 2)
    fast_again, slow_a, stop_a = 5.0, 2 + 0.65 + s_p(0.6), 2 + 0.65 + s_p(0.3)
    assert r.xy[0] == pytest.approx(stop_a, abs=1e-9)
    speeds = []  # (x at the step's start, x at its end, speed)
    for (t0, w0), (t1, w1) in zip(trace, trace[1:], strict=False):
        if w0["r0"] != w1["r0"]:
            speeds.append((w0["r0"][0], w1["r0"][0], (w0["r0"][0] - w1["r0"][0]) / (t1 - t0)))
    for x0, x1, v in speeds:  # the speed each step was driven at, by where it began
        if x0 > slow_b + 1e-9:
            want = 0.6  # before B's S_p(0.6): full speed
        elif x0 > fast_again + 1e-9:
            want = 0.3  # towards B, within S_p(0.6) of B (the step that passes x = 5 too: decided at its start)
        elif x0 > slow_a + 1e-9:
            want = 0.6  # away from B, A still farther than S_p(0.6)
        else:
            want = 0.3  # towards A, within S_p(0.6) of A
        if any(abs(x1 - x) < 1e-9 for x in (slow_b, slow_a, stop_a)):
            assert v <= want + 1e-9, (x0, x1, v)  # a step cut short exactly where the standard says
        else:
            assert v == pytest.approx(want, abs=1e-9), (x0, x1, v)
    for x in (slow_b, slow_a, stop_a):  # a step ended exactly at B's S_p(0.6), A's S_p(0.6) and S_p(0.3)
        assert any(abs(x1 - x) < 1e-9 for _, x1, _ in speeds), x
    m = floor.ssm["r0"].measures()
    assert (m.protective_stops, m.breaches) == (1, 0)
    assert m.min_free_robot_approaching == pytest.approx(s_p(0.3), abs=1e-9)
    _no_step_closer_than_the_standard(trace, floor)


# ------------------------------------------------------------------------------------------ the runs
def _ctx(cut: int | None) -> SimContext:
    full = load_task(ROOT / "tasks" / "kitting_2robots_iso.yaml")
    task = replace(full, actions=full.actions[:cut]) if cut else full
    return SimContext(task, {"motion": compile_task(task, seed=0, jobs=1)}, SimSettings(), 0)


@pytest.fixture(scope="module")
def kitting3() -> SimContext:
    return _ctx(3)  # 60 plans: 3! C(5, 2)


def _run(ctx: SimContext, index: int) -> tuple[RunResult, TeamDispatched]:
    return dispatched_team_run(ctx, index)


def _check(ctx: SimContext, result: RunResult, ctl: TeamDispatched) -> None:
    """The run finished on its DC first plan, kept every link of that plan's STNU, and from its recorded
    positions: no robot-person pair ever closer than S_p(0), no robot ending a step in which it drove towards
    a person closer than S_p of its mean speed in it (by hand), no robot-robot contact."""
    task = ctx.task
    assert result.finished and result.reason == "", result.reason
    assert result.first_class == "DC" and result.first_kept
    cp = next(c for c in ctx.compiles["motion"].plans if c.plan.id == result.first_plan)
    assert broken_links(read_graphml(cp.graphml.encode()), dict(ctl.d.seen.times)) == []
    standing = s_p(0.0, c=0.2, z=0.1)  # kitting_iso's safety: C 0.2 m, Z_d + Z_r 0.1 m: 0.46 m
    agents = task.agents
    frames = result.agent_frames
    assert frames
    for (t0, before, _), (t1, after, _) in zip(frames, frames[1:], strict=False):
        for i, r in enumerate(agents):
            if r.is_human:
                continue
            moved = math.dist(before[i][:2], after[i][:2])
            for j, p in enumerate(agents):
                if not p.is_human or not (after[i][2] and after[j][2]):
                    continue
                d1 = math.dist(after[i][:2], after[j][:2])
                free = d1 - r.radius - p.radius
                assert free >= standing - 1e-6, (result.run, r.id, p.id, t1, free)
                if moved > 1e-12 and d1 < math.dist(before[i][:2], after[j][:2]):
                    assert free >= s_p(moved / (t1 - t0), c=0.2, z=0.1) - 1e-6, (result.run, r.id, p.id, t1)
    assert result.ssm is not None and result.ssm.breaches == 0
    assert result.team is not None and result.team["robot_contacts"] == 0
    assert set(result.team["ssm"]) == {a.id for a in agents if not a.is_human}


@pytest.mark.parametrize("index", range(10))
def test_runs_of_two_robots_and_a_person_under_ssm_keep_the_separation_and_every_constraint(
        kitting3: SimContext, index: int) -> None:
    result, ctl = _run(kitting3, index)
    _check(kitting3, result, ctl)


def test_simulate_reports_ssm_per_robot_and_as_one(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`hrc simulate` of a team with safety: runs (no refusal), reports speed and separation monitoring per
    robot in the team part and over all robots as the one pair does, and prints its line."""
    import yaml

    doc = yaml.safe_load((ROOT / "tasks" / "kitting_2robots_iso.yaml").read_text(encoding="utf-8"))
    doc["actions"] = doc["actions"][:3]  # 60 plans
    doc["map"] = str(ROOT / "maps" / "kitting_cell.yaml")
    task_file = tmp_path / "k3.yaml"
    task_file.write_text(yaml.safe_dump(doc), encoding="utf-8")
    out = tmp_path / "sim"
    assert main(["simulate", str(task_file), "--runs", "3", "--policy", "hrc", "--jobs", "1", "--no-figures",
                 "--out", str(out)]) == 0
    printed, _ = capsys.readouterr()
    assert "speed and separation monitoring (ISO/TS 15066)" in printed
    assert "team (hrc) under SSM, per robot: robot stops " in printed and ", robot2 stops " in printed
    doc = json.loads((out / "simulation.json").read_text("utf-8"))
    agg = doc["policies"]["hrc"]["aggregate"]
    assert agg["ssm"]["runs_closer_than_separation"] == 0
    assert set(agg["team"]["ssm"]) == {"robot", "robot2"}
    for run in doc["policies"]["hrc"]["runs"]:
        assert set(run["team"]["ssm"]) == {"robot", "robot2"} and run["ssm"]["breaches"] == 0
        assert run["ssm"]["protective_stops"] == sum(m["protective_stops"] for m in run["team"]["ssm"].values())
    assert doc["separation"]["policies"]["hrc"]["over_compiled_worst_case"] == 0


@pytest.mark.slow
def test_200_runs_of_kitting_2robots_iso_keep_the_separation_and_every_constraint() -> None:
    """The whole task (2,520 plans: a minute or more to compile), 200 runs."""
    ctx = _ctx(None)
    for i in range(200):
        result, ctl = _run(ctx, i)
        _check(ctx, result, ctl)


def test_each_robot_is_told_the_separation_at_its_own_speed() -> None:
    """A team whose second robot drives at 0.4 m/s: each robot step of `hrc dispatch`'s answers carries the
    limits of *that* robot (before, every robot was told the first robot's): S_p by hand with kitting_iso's
    safety: (C 0.2 m, Z_d + Z_r 0.1 m), 1.66 m at 0.6 m/s and 1.22 m at 0.4 m/s, 0.46 m standing, the reduced
    speed 0.3 m/s's 1.015 m for both."""
    from hrc.dispatch import Dispatcher
    from hrc.dispatch.messages import Observation, RobotStep

    full = load_task(ROOT / "tasks" / "kitting_2robots_iso.yaml")
    agents = tuple(replace(a, speed=0.4) if a.id == "robot2" else a for a in full.agents)
    a, b, c = full.actions[:3]  # one pick for each robot alone (both have a step from the start), one for all
    task = replace(full, agents=agents, actions=(replace(a, agents=("robot",)), replace(b, agents=("robot2",)), c))
    d = Dispatcher.from_compiled(compile_task(task, seed=0, jobs=1))
    told: dict[str, dict] = {}
    decision = d.decision
    for _ in range(3):  # (a robot may first be told to wait for the other's departure)
        for rid, step in (decision.robots or {}).items():
            if isinstance(step, RobotStep):
                told.setdefault(rid, step.to_json()["separation"])
                if step.event == "depart" and len(told) < 2:
                    decision = d.observe(Observation(0.0, "depart", rid, step.action, step.phase))
    assert set(told) == {"robot", "robot2"}, d.decision.to_json()
    for rid, v in (("robot", 0.6), ("robot2", 0.4)):
        assert told[rid]["speed"] == v
        assert told[rid]["separation"] == pytest.approx(s_p(v, c=0.2, z=0.1), abs=1e-6)
        assert told[rid]["standing"] == pytest.approx(s_p(0.0, c=0.2, z=0.1), abs=1e-6)
        assert told[rid]["reduced_separation"] == pytest.approx(s_p(0.3, c=0.2, z=0.1), abs=1e-6)
    from hrc.motion.separation import describe  # the reports and `hrc show` name the second robot's S_p too

    assert describe(task).endswith(f"; robot2 at its 0.4 m/s: S_p {s_p(0.4, c=0.2, z=0.1):.3f} m")


def test_the_compile_keeps_s_p_between_every_robot_and_the_person_in_dispatched_plans(kitting3: SimContext) -> None:
    """Motion acquisition of a team under `safety:` (issue 37's step 1, checked by an independent referee,
    tests/referee.py, which reads no passing order): DC plans of kitting_2robots_iso cut to three picks in
    which both robots work, each dispatched by its STNU's real-time strategy (nature's durations at the bounds
    or random), every agent moved along its routes: at every instant (every 20 ms) each robot's free distance
    to the person, at an even pace, rushing or dawdling, is at least S_p (by hand) of the robot's speed then
    (its speed over the next 20 ms: 0 standing, the reduced speed on a slowed leg), and the two robots keep
    the plain margin (``r_a + r_b + safety_margin``) from each other; no task constraint broken."""
    import random

    from referee import broken_constraints, sampled_run, trajectory

    from hrc.compile.classify import PlanClass

    task, cps = kitting3.task, kitting3.compiles["motion"]
    both = [cp for cp in cps.plans if cp.plan_class is PlanClass.DC and cp.plan.sequence("robot")
            and cp.plan.sequence("robot2")]
    assert len(both) >= 3
    rng = random.Random(0)
    picks = [lambda e, hi: e, lambda e, hi: e if hi is None else hi]
    dt = 0.02
    person = task.agent("human")
    for cp in both[:3]:
        stnu = read_graphml(cp.graphml.encode())
        for run in range(2):
            times = sampled_run(stnu, rng, picks[run])
            assert broken_constraints(task, cp.plan, times) == [], cp.plan.id
            steps = int(max(times.values()) / dt) + 2
            robots = {r: trajectory(task, cp.plan, cp.motions, times, r) for r in ("robot", "robot2")}
            for pace in ("even", "rush", "dawdle"):
                walk = trajectory(task, cp.plan, cp.motions, times, "human", pace)
                for k in range(steps):
                    h = walk(k * dt)
                    for rid, at in robots.items():
                        x, nxt = at(k * dt), at((k + 1) * dt)
                        if x is None or h is None:
                            continue
                        v = 0.0 if nxt is None else min(math.dist(x, nxt) / dt, task.agent(rid).speed)
                        free = math.dist(x, h) - person.radius - task.agent(rid).radius
                        assert free >= s_p(v, c=0.2, z=0.1) - 1e-6, (cp.plan.id, rid, pace, k * dt, v, free)
            for k in range(steps):
                a, b = robots["robot"](k * dt), robots["robot2"](k * dt)
                if a is not None and b is not None:
                    assert math.dist(a, b) >= 0.7 + task.safety_margin - 1e-3, (cp.plan.id, k * dt)
