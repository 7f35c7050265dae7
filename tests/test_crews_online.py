"""Crews (issue 37) online: the console, hrc ros2 and the motion detector follow a joint action whose crew
is a choice of the plan (`hrc.model.Action.crew_choice`).

The hand-worked case of tests/test_crews.py (alice and bob, one robot; carry by either person, the lift at
J by the robot with alice or bob holding; 4 plans, worked out there by hand). What each person may do is
worked out by hand from those 4 plans: a joint action is offered to every candidate who is in its crew in
some remaining plan; a candidate's press keeps only the plans whose crew has them, and the other candidate
is not offered it afterwards; the robot waits for the crew that came.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from test_crews import HAND, hand_out  # noqa: F401 - the fixture: the hand-worked case, compiled

from hrc.compile.output import read_header
from hrc.console.clock import RunClock
from hrc.console.session import ConsoleSession
from hrc.dispatch import Dispatcher, RobotStep
from hrc.dispatch.durable import LoggedDispatcher
from hrc.dispatch.messages import WaitFor
from hrc.dispatch.plan_set import load_plan_set
from hrc.dispatch.routes import PlanRoutes, plan_motions
from hrc.motion import plan_paths

assert HAND["actions"][1]["id"] == "lift"


def _session(out: Path) -> ConsoleSession:
    plan_set = load_plan_set(out)
    header = read_header(out)
    routes = PlanRoutes(plan_motions(out, plan_set), plan_paths(plan_set.task, seed=int(header.get("seed", 0))))
    session = ConsoleSession(LoggedDispatcher(Dispatcher(plan_set)), header, routes, RunClock(1.0))
    session.clock.now = lambda: session.dispatcher.now + 0.5  # type: ignore[method-assign]  # run time moves
    return session


def _offered(state: dict[str, Any], person: str) -> set[tuple[str, str, str]]:
    return {(o["action"], o["phase"], o["event"]) for o in state["persons"][person]["options"]}


def _press(s: ConsoleSession, person: str, action: str, phase: str, event: str) -> dict[str, Any]:
    reply = s.page_message({"type": "press", "hseq": s.hseqs[person], "action": action, "phase": phase,
                            "event": event}, person)
    assert reply["ok"], reply
    return s.state()


def _ack(s: ConsoleSession, action: str, phase: str, event: str) -> dict[str, Any]:
    reply = s.robot_message({"type": "ack", "action": action, "phase": phase, "event": event}, robot="robot")
    assert reply["ok"], reply
    return s.state()


LIFT = ("lift", "hold", "depart")
CARRY = ("carry", "put", "depart")


@pytest.mark.parametrize("holder", ["alice", "bob"])
def test_the_console_offers_a_joint_action_to_every_candidate_until_one_joins(hand_out: Path,  # noqa: F811
                                                                              holder: str) -> None:
    """alice carries; then the lift is offered to both (a plan with either holding remains); the one who
    departs for it holds it: the other is not offered it again, the robot waits for the holder's arrival,
    and the shared view draws the lift under the holder and the robot only."""
    other = "bob" if holder == "alice" else "alice"
    s = _session(hand_out)
    state = s.state()
    # by hand: either may carry (4 plans); either may go straight to the lift (a plan where the other carries)
    assert {CARRY, LIFT} <= _offered(state, "alice") and {CARRY, LIFT} <= _offered(state, "bob")
    state = _press(s, "alice", *CARRY)  # carry: alice's (2 plans left: the lift's crew alice's or bob's)
    assert LIFT in _offered(state, "bob") and LIFT not in _offered(state, "alice")  # alice carries first
    for event in ("arrive", "start", "end"):
        state = _press(s, "alice", "carry", "put", event)
    assert LIFT in _offered(state, "alice") and LIFT in _offered(state, "bob")  # either may still hold it
    assert sum(state["decision"]["candidates"].values()) == 2
    state = _press(s, holder, *LIFT)
    assert sum(state["decision"]["candidates"].values()) == 1  # the plan whose crew has the holder
    assert not any(o["action"] == "lift" for o in state["persons"][other]["options"])
    assert s.crews()["lift"] == tuple(a for a in ("alice", "bob", "robot") if a in (holder, "robot"))
    step = s.robot_step("robot")
    assert isinstance(step, RobotStep) and step.action == "lift"
    state = _ack(s, "lift", "hold", "depart")
    state = _ack(s, "lift", "hold", "arrive")
    wait = s.dispatcher.decision.robots["robot"]  # type: ignore[index]
    assert isinstance(wait, WaitFor) and (wait.agent, wait.event) == (holder, "arrive")  # the crew that came
    state = _press(s, holder, "lift", "hold", "arrive")
    assert not any(o["action"] == "lift" for o in state["persons"][other]["options"])
    state = _ack(s, "lift", "hold", "start")
    assert state["persons"][holder]["under_way"] == [["lift", "hold"]]
    assert state["persons"][other]["under_way"] == []
    work = {b["agent"] for b in state["gantt"]["actual"] if b["action"] == "lift" and b["kind"] == "work"}
    assert work == {holder, "robot"}
    assert s.lead("lift") == "robot"
    state = _ack(s, "lift", "hold", "end")
    assert state["finished"] and state["persons"][other]["options"] == []


def test_a_candidate_who_goes_straight_to_the_joint_action_takes_it_from_the_other(hand_out: Path) -> None:  # noqa: F811
    """bob departs for the lift first thing: the plans left are those where alice carries and bob holds
    (the one DC plan of the four, by hand); alice is offered the carry, never the lift."""
    s = _session(hand_out)
    state = _press(s, "bob", *LIFT)
    assert state["decision"]["candidates"] == {"DC": 1, "consistent": 0, "inconsistent": 0}
    assert _offered(state, "alice") == {CARRY, ("carry", "put", "start")}
    assert _offered(state, "bob") == {("lift", "hold", "arrive")}  # the robot starts the joint action
    for event in ("depart", "arrive", "start", "end"):
        state = _press(s, "alice", "carry", "put", event)
        assert not any(o["action"] == "lift" for o in state["persons"]["alice"]["options"])
    assert json.loads(json.dumps(s.crews())) == {"lift": ["bob", "robot"]}


# --------------------------------------------------------------------------- the console in a browser

@pytest.fixture(scope="module")
def joint_workers(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """tasks/two_workers_joint.yaml compiled (240 plans: the load's holder is alice or bob)."""
    from console_harness import browser_or_skip
    from conftest import ROOT, compiled_folder

    browser_or_skip()
    return compiled_folder(tmp_path_factory.mktemp("twj") / "out", ROOT / "tasks" / "two_workers_joint.yaml",
                           "--jobs", "1")


@pytest.mark.parametrize("seed", [3, 8])
def test_two_candidates_press_on_their_own_pages_and_one_holds(joint_workers: Path, tmp_path: Path,
                                                               seed: int) -> None:
    """two_workers_joint in a real headless Chromium, the robot simulated: alice and bob each press their
    own offered buttons (seeded) to the end of the run. Each page's buttons were the dispatcher's options
    for that person at that point (the log replayed into a fresh dispatcher); the load was offered to both
    at some point; once one departed for it the other's page never offered it again; the crew that did it
    (the holder who pressed, the robot) is the crew of the one plan left (`Task.crew`), and the log replays
    byte for byte."""
    from console_harness import ConsoleProcess, chromium
    from test_console_team import SPEED, _options_after_each, _play, _replays, person_urls

    from hrc.compile.output import iter_plans
    from hrc.io.task_file import load_task
    from hrc.plans import generate_plans

    console = ConsoleProcess(joint_workers, tmp_path / "run.jsonl", "--speed", str(SPEED), "--simulate-robot")
    try:
        with chromium() as ctx:
            pages = {}
            for person, url in person_urls(console, ("alice", "bob")).items():
                page = pages[person] = ctx.browser.new_context().new_page()
                page.goto(url)
            for page in pages.values():
                page.wait_for_function("() => window.hrcConsole && window.hrcConsole.state !== null "
                                       "&& window.hrcConsole.connected", timeout=15_000)
            seen, pressed = _play(pages, joint_workers, seed=seed)
        state = console.state()
    finally:
        console.stop()
    assert state["finished"] and state["decision"]["robots"] == {"robot": None}
    lines = console.log_lines()
    ins, outs = lines[0::2], lines[1::2]
    assert all(o["ok"] for o in outs), [o for o in outs if not o["ok"]]
    holders = {p for p, (action, _, _) in pressed if action == "load"}
    assert len(holders) == 1, pressed
    holder = holders.pop()
    other = "bob" if holder == "alice" else "alice"
    # pressed by the holder: the load was offered to both at some point before, and never to the other after
    loads = [(p, snap["seq"]) for p, snap in seen if any(b[0] == "load" and not b[3] for b in snap["buttons"])]
    assert {p for p, _ in loads} == {"alice", "bob"}, loads
    first_in = next(k for k, m in enumerate(ins) if m.get("agent") == holder and m.get("action") == "load")
    seq_joined = sum(1 for o in outs[:first_in + 1] if o["ok"] and not o.get("unchanged"))
    assert all(s < seq_joined for p, s in loads if p == other), (loads, seq_joined)
    # each page's buttons were that person's options in a fresh dispatcher at that point
    options = _options_after_each(joint_workers, console.log, ("alice", "bob"))
    checked = 0
    for person, snap in seen:
        if not snap["finished"] and snap["connected"]:
            assert sorted(b[:3] for b in snap["buttons"]) == options[snap["seq"]][person], (person, snap)
            checked += 1
    assert checked > 20
    # the one plan left does the load with the holder and the robot
    task = load_task(joint_workers / "input" / "task.yaml")
    plan = next(p for p in generate_plans(task) if p.id == outs[-1]["plan"])
    assert task.crew("load", plan) == tuple(a for a in ("alice", "bob", "robot") if a in (holder, "robot"))
    assert {m["agent"] for m in ins if m.get("action") == "load"} == {holder, "robot"}
    assert outs[-1]["plan"] in {p["id"] for p in iter_plans(joint_workers)}
    _replays(joint_workers, console.log, outs)
