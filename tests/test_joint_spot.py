"""An agent who starts at a joint action's spot (issue 37; reported with the crews of tests/test_crews.py).

The co-work rule at a joint spot (docs/motion.md, "Joint actions"; `hrc.motion.conflicts._coworking`)
drops the separation between the robot *standing* at the spot and the person coming, working and going,
and keeps it for the robot's *drives* to and from it: the robot arrives first and never drives within
reach of someone standing there. A person who stands at the spot from the start (their start is the
spot, and they do nothing elsewhere before the joint phase) therefore blocks the robot's drive in: "robot
first" would need the robot there before the start, "person first" would need the person gone before the
joint phase ends, which waits for the robot. The plan has no schedule whatever the order, and its
explanation says why (`hrc.motion.conflicts.joint_spot_starts`, `hrc.compile.motion_pattern._blocked`);
the other plans of the task, the robot starting at the spot, and a person who leaves the spot first and
comes back are schedulable, with the classes and makespans worked out by hand below.
"""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import pytest
import yaml
from oracles import orders_schedulable
from test_crews import BARE_MAP, HAND, cstnu_tool  # noqa: F401 (a fixture)
from test_cstnu_tool import _agree, _compiled_classes

from hrc.cli import main
from hrc.compile.output import iter_plans
from hrc.io.task_file import load_task
from hrc.model import Task
from hrc.motion import plan_paths
from hrc.motion.conflicts import JointSpotStart, joint_spot_starts
from hrc.plans import generate_plans

BLOCK = ("the co-workers would block each other: {who} stands at {spot} from the start until {phase} ends, and "
         "{robot} must drive to {spot} for that joint action; at a joint spot the robot arrives first and never "
         "drives within reach of someone standing there")


def _starts(task: dict[str, Any], **starts: str) -> dict[str, Any]:
    out = copy.deepcopy(task)
    for agent in out["agents"]:
        agent["start"] = starts.get(agent["id"], agent["start"])
    return out


def _compile(tmp: Path, task: dict[str, Any]) -> tuple[Task, Path, dict[tuple, dict]]:
    """Compile `task` on the bare map: the task, the output folder, and each plan's record by (who does
    `carry` or `fetch`, the lift's person)."""
    (tmp / "map.yaml").write_text(yaml.safe_dump(BARE_MAP, sort_keys=False), "utf-8")
    path = tmp / "task.yaml"
    path.write_text(yaml.safe_dump(task, sort_keys=False), "utf-8")
    out = tmp / "out"
    assert main(["compile", str(path), "--out", str(out), "--no-report", "-q"]) == 0
    loaded = load_task(out / "input" / "task.yaml")
    plans = {p.id: p for p in generate_plans(loaded)}
    first = loaded.actions[0].id
    records = {}
    for rec in iter_plans(out):
        plan = plans[rec["id"]]
        person = next(a for a in loaded.crew("lift", plan) if loaded.agent(a).is_human)
        records[(plan.agent_of(first), person)] = rec
    return loaded, out, records


def _check(records: dict[tuple, dict], expected: dict[tuple, tuple[str, tuple[float, float] | None]]) -> None:
    got = {key: (rec["class"], rec["makespan"]) for key, rec in records.items()}
    assert got.keys() == expected.keys()
    for key, (cls, span) in expected.items():
        assert got[key][0] == cls, (key, got[key])
        if span is None:
            assert got[key][1] is None, (key, got[key])
        else:
            assert got[key][1] == pytest.approx(span, abs=0.002), (key, got[key])


# --------------------------------------------------------------------------- the crews' task, bob at J

BOB_AT_J = _starts(HAND, bob="J")
"""tests/test_crews.py's HAND with bob starting at J, the lift's spot (instead of B). By hand (routes
straight, people 1 m/s with travel up to x1.25, the robot 0.5 m/s; J->A 4.272 m; reach 0.3 + 0.35 + 0.1 =
0.75 m; S->J 1.5 m, 3 s):
- carry alice, alice holds: bob does nothing (no legs, out of the way, as every idle agent): as in HAND,
  alice at J after 1.5-1.875 + 1-2 + 4.272-5.340 s, the lift 3-5 s: 9.772-14.215 s: DC;
- carry alice, bob holds: bob stands at J from the start until the lift ends; the robot must drive in
  to him: blocked (inconsistent, no schedule), the explanation naming bob, J, lift.hold and robot;
- carry bob, alice holds: bob walks J->A (4.272-5.340 s, leaving J at once, before the robot comes),
  carries 1-2 s: carry done 5.272-7.340 s; alice at J by 4-5 s, the robot by 3 s: the lift ends
  8.272-12.340 s: DC;
- carry bob, bob holds: bob J->A, carry, A->J: at J after 9.544-12.680 s, the lift ends 12.544-17.680 s:
  the worst case misses the 15 s deadline, the best meets it: consistent.
"""


def test_a_person_at_the_joint_spot_blocks_the_robots_drive_in(tmp_path: Path) -> None:
    task, out, records = _compile(tmp_path, BOB_AT_J)
    _check(records, {("alice", "alice"): ("DC", (9.772, 14.215)), ("alice", "bob"): ("inconsistent", None),
                     ("bob", "alice"): ("DC", (8.272, 12.340)), ("bob", "bob"): ("consistent", (12.544, 17.680))})
    why = records[("alice", "bob")]["explanation"]
    assert why.startswith(BLOCK.format(who="bob", spot="J", phase="lift.hold", robot="robot")), why
    assert all("stands at" not in (rec["explanation"] or "") for key, rec in records.items() if key != ("alice", "bob"))
    # the detector names exactly that plan, and that pair
    plans = {p.id: p for p in generate_plans(task)}
    named = {rec["id"]: joint_spot_starts(task, plans[rec["id"]]) for rec in records.values()}
    assert named == {rec["id"]: (JointSpotStart("bob", "robot", "lift", "hold", "J"),) if key == ("alice", "bob")
                     else () for key, rec in records.items()}
    # `hrc show --plan` gives the why
    assert main(["show", str(out), "--plan", records[("alice", "bob")]["id"]]) == 0


def test_no_order_at_all_by_the_milp(tmp_path: Path) -> None:
    """Independent of the compiler's order search: a MILP over every passing order of the conflicts finds
    no schedule for the blocked plan and one for each other plan (without the deadline's say: the
    consistent plan meets it at best)."""
    task, _, records = _compile(tmp_path, BOB_AT_J)
    paths = plan_paths(task, seed=0)
    plans = {p.id: p for p in generate_plans(task)}
    got = {key: orders_schedulable(task, plans[rec["id"]], paths) for key, rec in records.items()}
    assert got == {("alice", "alice"): True, ("alice", "bob"): False, ("bob", "alice"): True, ("bob", "bob"): True}


def test_the_tool_agrees_that_the_blocked_file_alone_is_not_dc(cstnu_tool: Path, tmp_path: Path) -> None:  # noqa: F811
    _, out, _ = _compile(tmp_path, BOB_AT_J)
    assert _agree(cstnu_tool, _compiled_classes(out)) == {"DC": 2, "NOT_DC": 2}


# ------------------------------------------------------------------------------- the robot at the spot

ROBOT_AT_J = _starts(HAND, robot="J")
"""HAND with the robot starting at J (bob at B): the robot never drives; it stands at J from the start,
and the co-work rule drops its stay against the holder's walk up and stay (docs/motion.md). By hand:
- carry alice, alice holds: 9.772-14.215 s, DC (as in HAND);
- carry alice, bob holds: bob B->J 4.272-5.340 s, carry done by 3.875 s: the lift ends 7.272-10.340 s, DC
  (HAND's 10.34 s worst case, the lift's start no longer waiting for the robot's 3 s);
- carry bob, alice holds: carry done 9-12 s (B->A 8-10 s, then 1-2 s): 12-17 s, consistent;
- carry bob, bob holds: bob at J after 13.272 s at the earliest: 16.272 s at best > 15 s: inconsistent,
  the deadline's doing (a makespan, not a block)."""


def test_the_robot_at_the_joint_spot_is_no_block(tmp_path: Path) -> None:
    task, _, records = _compile(tmp_path, ROBOT_AT_J)
    _check(records, {("alice", "alice"): ("DC", (9.772, 14.215)), ("alice", "bob"): ("DC", (7.272, 10.340)),
                     ("bob", "alice"): ("consistent", (12.0, 17.0)),
                     ("bob", "bob"): ("inconsistent", (16.272, 22.340))})
    assert all(joint_spot_starts(task, p) == () for p in generate_plans(task))


def test_bob_at_his_bench_with_the_robot_docked_there(tmp_path: Path) -> None:
    """bob and the robot both start at J (a worker at a bench the robot is docked at): the lift with bob
    needs no drive at all; carry alice 2.5-3.875 s, then the lift 3-5 s: 5.5-8.875 s, DC. (The plans in
    which bob walks away from the standing robot, not its co-worker there, start with the two discs on
    one spot: no schedule keeps them apart, which is the task's start, not the joint action.)"""
    task, _, records = _compile(tmp_path, _starts(HAND, robot="J", bob="J"))
    rec = records[("alice", "bob")]
    assert (rec["class"], rec["makespan"]) == ("DC", pytest.approx((5.5, 8.875), abs=0.002))
    assert all(joint_spot_starts(task, p) == () for p in generate_plans(task))


# ------------------------------------------------------------------------- one crew: a person and a robot

ONE_CREW: dict[str, Any] = {
    "name": "bench", "map": "map.yaml", "safety_margin": 0.1, "deadline": 30,
    "agents": [{"id": "worker", "kind": "human", "radius": 0.3, "speed": 1.0, "start": "J"},
               {"id": "robot", "kind": "robot", "radius": 0.35, "speed": 0.5, "start": "S"}],
    "actions": [
        {"id": "fetch", "name": "fetch the frame from A", "agents": ["worker", "robot"],
         "phases": [{"id": "get", "location": "A", "duration": {"worker": [1, 2], "robot": [2, 3]}}]},
        {"id": "lift", "name": "lift the frame at J", "roles": {"holder": "worker", "lifter": "robot"},
         "phases": [{"id": "hold", "location": "J", "duration": {"holder": [3, 5], "lifter": [2, 4]}}]}],
    "precedence": [["fetch", "lift"]],
}
"""One crew (cube_stacking_joint's kind): the worker starts at their bench J, where the joint lift is; a
fetch at A by either agent comes first. By hand (S->A 5 m, 10 s; A->J 4.272 m: the robot 8.544 s, the
worker 4.272-5.340 s; S->J 3 s):
- the worker fetches: they leave J at once (before the robot drives in), J->A, 1-2 s, A->J: back at J
  after 9.544-12.680 s (the robot there by 3 s); the lift ends 12.544-17.680 s: DC (deadline 30 s);
- the robot fetches: the worker stands at J from the start until the lift ends, the robot must drive to
  J after its fetch: blocked (inconsistent), the explanation naming worker, J, lift.hold and robot.
With the worker starting at H instead (4 m left of J, out of reach of the robot's routes) the robot's
fetch is schedulable: the robot leaves A at 12 s (10 s there, its own 2 s of fetch), at J 8.544 s later.
Both come to J from the left, so the worker may set off only when the robot will be through before they
come within reach (robot first, on the routes sampled every 2 cm with reach + 2 cm: the worker's first
sample within 0.77 m of J at u = 3.24 m, the robot at J at 8.544 s: 8.544 - 3.24 s, plus the sampling's
0.01 / 0.5 + 0.01 / 1 = 0.03 s): they leave at 12 + 5.334 s, at J 4-5 s later, the lift 3-5 s:
24.334-27.334 s: DC (the robot tells them when to go)."""


def test_one_crew_person_at_the_bench(tmp_path: Path) -> None:
    _, _, records = _compile(tmp_path, ONE_CREW)
    _check(records, {("worker", "worker"): ("DC", (12.544, 17.680)), ("robot", "worker"): ("inconsistent", None)})
    why = records[("robot", "worker")]["explanation"]
    assert why.startswith(BLOCK.format(who="worker", spot="J", phase="lift.hold", robot="robot")), why


def test_one_crew_person_out_of_reach_walks_up_after_the_robot(tmp_path: Path) -> None:
    task, _, records = _compile(tmp_path, _starts(ONE_CREW, worker="H"))
    assert (records[("robot", "worker")]["class"], records[("robot", "worker")]["makespan"]) == (
        "DC", pytest.approx((24.334, 27.334), abs=0.002))
    assert all(joint_spot_starts(task, p) == () for p in generate_plans(task))
