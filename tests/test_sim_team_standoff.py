"""The stand-off rules on a team's floor (issue 37, `hrc.sim.team_run` through `hrc.sim.standoff.Standoffs`).

By hand, on the kitting cell of `tasks/kitting_2robots.yaml` (its first three picks, 60 plans): two robots
sent head-on along the open aisle at y = 5.2 stop 2 cm apart (the floor's rule); after `ASIDE_AFTER` seconds
the rule decides who makes room, checked by positions at every step:

- the one whose next phase may not start makes room for the one whose may (here robot, though first in task
  order, for robot2, whose pick may start);
- neither may start: the later in task order (robot2) makes room;
- a person standing idle at the goal of a robot: the robot cannot go round; the person makes room and
  the robot arrives.

In each: the one that made room went to a spot and on, the other never left its way; both reached their
goals; the discs never came closer than the floor keeps them (2 cm between robots, the margin between a
robot and a person), no pymunk contact. Then a few runs of the `motion-blind` policy on `two_workers`
(every one of them ended in a deadlock before these rules): all finish, with stand-offs and no contact.
"""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
from conftest import ROOT

from hrc.compile.compiler import compile_task
from hrc.io.task_file import load_task
from hrc.sim.blind import blind_compile
from hrc.sim.floor import CONTACT
from hrc.sim.human import draw_people
from hrc.sim.policies import POLICIES
from hrc.sim.run import SimContext, SimSettings
from hrc.sim.standoff import yields
from hrc.sim.team_policies import make_team_controller
from hrc.sim.team_run import _TeamRun, simulate_team_run

Point = tuple[float, float]


@pytest.fixture(scope="module")
def kitting3() -> SimContext:
    full = load_task(ROOT / "tasks" / "kitting_2robots.yaml")
    task = replace(full, actions=full.actions[:3])  # 60 plans: 3! C(5, 2)
    return SimContext(task, {"motion": compile_task(task, seed=0, jobs=1)}, SimSettings(), 0)


def _loop(ctx: SimContext) -> _TeamRun:
    import numpy as np

    draws = draw_people(ctx.task, ctx.settings.human, np.random.default_rng([0, 0]))
    return _TeamRun(ctx, POLICIES["hrc"], draws, make_team_controller(ctx, POLICIES["hrc"]), False)


def _send(run: _TeamRun, agent: str, start: Point, goal: Point, action: str | None = None) -> None:
    """`agent` on its way from `start` to `goal` (`action`: the pick it is on the way to fetch)."""
    a = run.agents[agent]
    run.floor.place(a.mover, start)
    a.mover.set_route((start, goal), a.mover.agent.speed)
    a.mode, a.loc, a.action, a.pi = "travel", None, action, 0


def _drive(run: _TeamRun, goals: dict[str, Point], seconds: float = 90.0) -> tuple[set[str], float, float]:
    """The loop's stand-off steps and the floor, until every agent of `goals` stands at its goal and has
    nothing left of making room. Returns who made room, the closest robot-robot and robot-person free
    distances seen at any step."""
    floor, aside = run.floor, set()
    robots = [m for m in floor.movers.values() if not m.agent.is_human]
    people = [m for m in floor.movers.values() if m.agent.is_human]
    closest_rr = closest_rp = math.inf
    while run.t < seconds:
        for _ in range(10):
            if not any(run._home_or_aside(a) for a in run.agents.values()):
                break
        aside |= {a.id for a in run.agents.values() if a.mode.startswith("aside")}
        if all(math.dist(run.agents[g].mover.xy, xy) < 1e-6 and not run.agents[g].mover.moving
               and run.agents[g].aside is None and run.agents[g].mode not in ("aside", "aside_wait", "returning")
               for g, xy in goals.items()):
            break
        h = min(floor.safe_step(), 0.1)
        floor.advance(h)
        for a in run.agents.values():
            if a.mode == "aside_wait" and a.held_up:
                a.wait_for += h
        run.t += h
        closest_rr = min([closest_rr] + [floor.gap(m, n) for m in robots for n in robots if m is not n])
        closest_rp = min([closest_rp] + [floor.gap(m, p) for m in robots for p in people])
    else:
        pytest.fail(f"not resolved in {seconds} s: " + ", ".join(f"{a.id} {a.mode} {a.mover.xy}"
                                                                for a in run.agents.values()))
    assert floor.robot_contacts() == 0 and floor.overlaps() == 0
    return aside, closest_rr, closest_rp


def test_two_robots_head_on_the_one_whose_phase_may_start_goes_first(kitting3: SimContext) -> None:
    run = _loop(kitting3)
    run.floor.place(run.floor.movers["human"], (1.5, 1.0))
    _send(run, "robot", (3.0, 5.2), (9.0, 5.2))  # nothing under way: its next phase may not start
    _send(run, "robot2", (9.0, 5.2), (3.0, 5.2), "pick_a")  # on its way to fetch A: it may start
    assert run._startable(run.agents["robot2"]) and not run._startable(run.agents["robot"])
    aside, rr, _ = _drive(run, {"robot": (9.0, 5.2), "robot2": (3.0, 5.2)})
    assert aside == {"robot"}  # robot made room though it comes first in task order
    assert run.standoffs >= 1
    assert rr >= CONTACT - 1e-6


def test_two_robots_head_on_neither_may_start_the_later_in_task_order_makes_room(kitting3: SimContext) -> None:
    run = _loop(kitting3)
    run.floor.place(run.floor.movers["human"], (1.5, 1.0))
    _send(run, "robot", (3.0, 5.2), (9.0, 5.2))
    _send(run, "robot2", (9.0, 5.2), (3.0, 5.2))
    aside, rr, _ = _drive(run, {"robot": (9.0, 5.2), "robot2": (3.0, 5.2)})
    assert aside == {"robot2"}
    assert rr >= CONTACT - 1e-6


def test_a_person_standing_at_a_robots_goal_makes_room_and_the_robot_gets_there(kitting3: SimContext) -> None:
    """The person stands idle at (6, 5.2); robot drives along the aisle to exactly there. Held up at the
    margin for `ASIDE_AFTER` s, it cannot go round (the person stands on its goal): the person makes room, the
    robot arrives, and the person, who had nothing under way, stays at the spot (free, off the robot)."""
    run = _loop(kitting3)
    person, robot = run.agents["human"], run.agents["robot"]
    run.floor.place(person.mover, (6.0, 5.2))
    person.loc, person.mode = None, "free"
    run.floor.place(run.floor.movers["robot2"], (12.0, 1.0))
    _send(run, "robot", (3.0, 5.2), (6.0, 5.2))
    modes: dict[str, set[str]] = {"human": set(), "robot": set()}
    closest = math.inf
    while run.t < 60 and not (not robot.mover.moving and math.dist(robot.mover.xy, (6.0, 5.2)) < 1e-6):
        run._home_or_aside(person)
        run._home_or_aside(robot)
        modes["human"].add(person.mode)
        modes["robot"].add(robot.mode)
        h = min(run.floor.safe_step(), 0.1)
        run.floor.advance(h)
        run.t += h
        closest = min(closest, run.floor.gap(person.mover, robot.mover))
    assert math.dist(robot.mover.xy, (6.0, 5.2)) < 1e-6, (robot.mode, robot.mover.xy, person.mode, person.mover.xy)
    assert "aside" in modes["human"] and modes["robot"] == {"travel"}  # the person made room, the robot went on
    assert person.mode == "free" and person.aside is None
    assert run.floor.gap(person.mover, robot.mover) >= run.floor.margin + 0.3 - 1e-6  # the spot: reach + CLEAR
    assert run.floor.overlaps() == 0 and closest >= run.floor.margin - 1e-6
    assert run.standoffs == 1


def test_the_give_way_order_of_two_of_a_kind() -> None:
    """`yields(a may start, b may start, a first in task order)`: whether a makes room for b."""
    assert yields(False, True, True) and not yields(True, False, False)  # the one that may not start
    assert yields(True, True, False) and not yields(True, True, True)  # else the later in task order
    assert yields(False, False, False) and not yields(False, False, True)


def test_motion_blind_team_runs_finish_instead_of_deadlocking() -> None:
    """Every motion-blind run of `two_workers` ended in a deadlock without the rules (docs/simulate.md,
    "Teams"): its robot drives into the people's ways. Now they finish; the rules show as stand-offs and
    time aside; no robot-person contact, and the separation is the floor's (2 cm: a person stops short)."""
    task = load_task(ROOT / "tasks" / "two_workers.yaml")
    ctx = SimContext(task, {"motion": compile_task(task, seed=0, jobs=1), "blind": blind_compile(task, jobs=1)},
                     SimSettings(), 0)
    total = 0
    for i in range(3):
        r = simulate_team_run(ctx, "motion-blind", i)
        assert r.finished and r.reason == "", r.reason
        assert r.overlaps == 0 and r.team is not None and r.team["robot_contacts"] == 0
        assert r.min_distance is not None and r.min_distance >= CONTACT - 1e-6
        total += r.standoffs
        assert r.standoffs == 0 or r.robot_aside + r.human_aside > 0
    assert total >= 1


@pytest.mark.slow
def test_motion_blind_runs_under_ssm_finish_without_coming_closer_than_the_standard() -> None:
    """`kitting_2robots_iso` (speed and separation monitoring): runs 0 and 6 of seed 0 ran to the time cap with
    the first rules (a robot in a protective stop facing the person, both held up, robot2 waiting aside: the
    stall rule did not see it, and the person's only spot lay within robot2's separation at full speed). Now
    they finish: stand-offs resolved, no contact, never closer than `S_p` (no breach)."""
    task = load_task(ROOT / "tasks" / "kitting_2robots_iso.yaml")
    ctx = SimContext(task, {"motion": compile_task(task, seed=0, jobs=1), "blind": blind_compile(task, jobs=1)},
                     SimSettings(), 0)
    for i in (0, 6):
        r = simulate_team_run(ctx, "motion-blind", i)
        assert r.finished and r.reason == "", r.reason
        assert r.standoffs >= 1 and r.overlaps == 0 and r.team is not None and r.team["robot_contacts"] == 0
        assert r.ssm is not None and r.ssm.breaches == 0
