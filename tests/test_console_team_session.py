"""The console's session for a team (issue 37), in process: whatever a page or a robot controller sends,
in the name of whichever id, a refused message changes nothing, and no client speaks for another agent.

two_workers (two people, one robot). hypothesis draws sequences of messages, each from a person's page
(alice, bob, the shared view, or an id not of the team) or a robot controller (robot, or an unknown id):
a valid press of that person's offered buttons, a press of another person's button, away/back/undo, an ack
of the robot's step (its own id, or naming another agent), or garbage. Checked after each one, against the
session's own state before it: a refusal leaves the decision, the history, every counter and the log as
they were; an accepted message is logged under the agent whose page or controller sent it, and only a
person's page moves that person's counter.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from conftest import ROOT, compiled_folder
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from hrc.compile.output import read_header
from hrc.console.clock import RunClock
from hrc.console.session import ConsoleSession
from hrc.dispatch import Dispatcher, RobotStep
from hrc.dispatch.durable import LoggedDispatcher
from hrc.dispatch.plan_set import load_plan_set
from hrc.dispatch.routes import PlanRoutes, plan_motions
from hrc.motion import plan_paths

PAGES = ("alice", "bob", None, "zed")   # None: the shared view; zed: not of the team
ROBOTS = ("robot", "r9")


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return compiled_folder(tmp_path_factory.mktemp("tw") / "out", ROOT / "tasks" / "two_workers.yaml", "--jobs", "1")


@pytest.fixture(scope="module")
def parts(folder: Path) -> tuple[Any, Any, PlanRoutes]:
    plan_set = load_plan_set(folder)
    header = read_header(folder)
    return plan_set, header, PlanRoutes(plan_motions(folder, plan_set),
                                        plan_paths(plan_set.task, seed=int(header.get("seed", 0))))


def _session(parts: tuple[Any, Any, PlanRoutes]) -> ConsoleSession:
    plan_set, header, routes = parts
    session = ConsoleSession(LoggedDispatcher(Dispatcher(plan_set)), header, routes, RunClock(1.0))
    session.clock.now = lambda: session.dispatcher.now + 0.5  # type: ignore[method-assign]  # run time moves
    return session


def _view(s: ConsoleSession) -> Any:
    return (json.dumps(s.dispatcher.decision.to_json(), sort_keys=True), s.dispatcher.history, s.seq, s.hseq,
            dict(s.hseqs), s.total)


# what to send: (from a page or a robot, which id, what kind of message, a choice among the options)
_MESSAGE = st.tuples(st.sampled_from(["page", "robot"]), st.integers(0, 3),
                     st.sampled_from(["own", "other", "away", "back", "undo", "ack", "ack_other", "garbage"]),
                     st.integers(0, 5))


def _build(s: ConsoleSession, kind: str, who: Any, what: str, pick: int) -> tuple[Any, str | None]:
    """The message as its client sends it, and the agent it names (None: none)."""
    if what == "garbage":
        return ["not json", '{"type": "press"}', '{"type": "ack", "action": 1}', "[]"][pick % 4], None
    if kind == "page":
        person = who if who in s.hseqs else "alice"
        other = "bob" if person == "alice" else "alice"
        if what in ("own", "other"):  # "other": the other person's button, naming them
            target = person if what == "own" else other
            options = s.dispatcher.human_options(target)
            if not options:
                return json.dumps({"type": "away", "hseq": s.hseqs[person]}), person
            o = options[pick % len(options)]
            named = {} if what == "own" else {"agent": other}
            return json.dumps({"type": "press", "hseq": s.hseqs[person], "action": o.action, "phase": o.phase,
                               "event": o.event, **named}), target
        return json.dumps({"type": what if what in ("away", "back", "undo") else "away",
                           "hseq": s.hseqs[person]}), person
    step = s.robot_step("robot")
    event = {"action": "pick_a", "phase": "fetch", "event": "depart"} if step is None else \
        {"action": step.action, "phase": step.phase, "event": step.event}
    if isinstance(step, RobotStep) and what == "ack":
        return json.dumps({"type": "ack", **event}), "robot"
    return json.dumps({"type": "ack", "agent": ["alice", "bob"][pick % 2], **event}), "other"


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(_MESSAGE, min_size=1, max_size=14))
def test_a_refused_message_changes_nothing_and_no_client_speaks_for_another(parts: Any, messages: list) -> None:
    s = _session(parts)
    for kind, k, what, pick in messages:
        who = PAGES[k] if kind == "page" else ROBOTS[k % 2]
        text, named = _build(s, kind, who, what, pick)
        before = _view(s)
        reply = s.page_message(text, person=who) if kind == "page" else s.robot_message(text, robot=who)
        after = _view(s)
        if not reply["ok"]:
            decision, history, seq, hseq, hseqs, total = before
            assert after[:5] == before[:5], (kind, who, text, reply)
            assert after[5] in (total, total + 1)  # refused here (not logged), or by the dispatcher (logged)
            continue
        assert after[2] == before[2] + 1
        event(f"accepted from a {kind}")  # both kinds are drawn and accepted (--hypothesis-show-statistics)
        logged = s.entries[-1]["in"]
        if kind == "robot":  # a controller acknowledges its own robot only
            assert who == "robot" and named == "robot" and logged["agent"] == "robot"
            assert after[4] == before[4]
        else:  # a person's page: that person's observation (an undo withdraws their own), their counter only
            assert who in ("alice", "bob")
            assert logged.get("agent", who) == who
            assert after[4] == {**before[4], who: before[4][who] + 1}
        assert named in (who, None)
