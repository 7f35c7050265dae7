"""The class and the ranking read the person's told-but-not-yet-learnt event as the windows do (issue 32).

Under a stated delay (buttons up to 0.5 s late, a compile with ``--observation-delay 0:0.5``), once the
latest the person was told for their next event has passed, less than the delay ago, and the button has
not come yet, the event may have happened anywhere in the window they were told, unobserved: the robot's
windows hold for both readings (`Dispatcher._unlearnt`). The class must read it so too (Bhargava, Muise &
Williams 2018, delay controllability): before, the plan read the unseen departure as "not yet", at now or
later, past its told latest, and turned "consistent" in the answers until the button came, which could
move the best plan.

Reproduced with the outside driver of tests/detect_client.py (`PressingRun`, the person pressing each
event's button 0.5 s after it, the robot anywhere in its windows, seed 0): on the workshop's first plan,
the person is told to leave for the triangle's put in [70.221, 70.24] and leaves at 70.221; the press
comes at 70.721. Ticks between 70.24 and 70.721 answered "consistent" (the robot's step unchanged:
`robot.cube4.put.end` at 71.338, hand-checked against the dispatcher before this change).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from conftest import ROOT, compiled_folder

from hrc.dispatch import Dispatcher
from hrc.dispatch.plan_set import load_plan_set
from hrc.dispatch.protocol import handle_line

sys.path.insert(0, str(ROOT / "scripts"))


@pytest.fixture(scope="module")
def late_buttons(tmp_path_factory) -> Path:
    return compiled_folder(tmp_path_factory.mktemp("unlearnt") / "ws", ROOT / "tasks" / "cube_stacking.yaml",
                           "--observation-delay", "0:0.5")


def _log(folder: Path, seed: int) -> list[tuple[str, dict]]:
    from detect_client import PressingRun
    from measure_promise import routes_of

    plan_set = load_plan_set(folder)
    d = Dispatcher(plan_set, threads=1)
    log: list[tuple[str, dict]] = []

    def send(line: str) -> str:
        answer = handle_line(d, line)
        log.append((line, json.loads(answer)))
        return answer

    routes, paths = routes_of(str(folder), plan_set)
    PressingRun(plan_set, send, seed, routes=routes, paths=paths, late=0.5).play()
    return log


def test_an_unseen_departure_past_its_told_latest_keeps_the_class_and_the_best_plan(late_buttons):
    log = _log(late_buttons, 0)
    press = next(k for k, (line, _) in enumerate(log)
                 if json.loads(line).get("action") == "triangle" and json.loads(line)["phase"] == "put"
                 and json.loads(line)["event"] == "depart")
    pressed_at = json.loads(log[press][0])["t"]
    # the last answer that told the person when to leave, before the clock passed its latest
    told = next(a for _, a in reversed(log[:press]) if isinstance(a.get("human"), dict)
                and a["human"].get("event") == "depart" and a["human"]["latest"] is not None
                and a["human"]["latest"] < pressed_at)
    latest = told["human"]["latest"]
    assert (told["human"]["action"], told["human"]["phase"]) == ("triangle", "put")
    assert pressed_at - 0.5 <= latest < pressed_at  # the press came within the delay after the latest
    before = [line for line, a in log[:press] if json.loads(line)["t"] <= latest]
    d = Dispatcher(load_plan_set(late_buttons), threads=1)
    for line in before:
        answer = json.loads(handle_line(d, line))
    assert answer["class"] == "DC"
    plan = answer["plan"]
    ticks = [round(latest + f * (pressed_at - latest), 3) for f in (0.1, 0.5, 0.9)]
    for t in ticks:
        got = json.loads(handle_line(d, json.dumps({"t": t, "event": "tick"})))
        assert got["ok"], got
        assert got["class"] == "DC", (t, got["class"])  # was "consistent" before the change
        assert got["plan"] == plan
        # the robot's windows are as before the change (the windows already read the event so)
        assert got["robot"] == {"action": "cube4", "phase": "put", "event": "end", "earliest": 71.338,
                                "latest": 71.338}
    got = json.loads(handle_line(d, log[press][0]))
    assert got["ok"] and got["plan"] == plan


def test_a_start_pressed_later_than_its_window_by_less_than_the_delay_keeps_the_followed_plan(late_buttons):
    """Buttons late by a delay drawn in [0, 0.5] s (seed 10): the arrival at S1 pressed 0.28 s late, the
    start (at the same instant) 0.39 s late, 14 ms past the start's window [10.641, 10.735] told after the
    arrival's press. Read at the press, the followed plan was inconsistent and the dispatcher moved to one
    giving the person cube 4, which they never took: the run stalled with the first plan's constraints
    broken. Read on the window's latest (`Dispatcher._on_bound`), the run keeps every link of its plan."""
    from detect_client import PressingRun
    from dispatch_client import broken_links
    from measure_promise import routes_of

    plan_set = load_plan_set(late_buttons)
    d = Dispatcher(plan_set, threads=1)
    routes, paths = routes_of(str(late_buttons), plan_set)
    out = PressingRun(plan_set, lambda line: handle_line(d, line), 10, routes=routes, paths=paths, late=0.5,
                      uniform=True).play()
    first = plan_set.entry(plan_set.index(out.first["plan"]))
    final = plan_set.entry(plan_set.index(out.answers[-1]["plan"]))
    assert out.first["class"] == "DC" and not out.refused
    assert dict(final.plan.sequences)["human"] == dict(first.plan.sequences)["human"]
    assert broken_links(final.stnu, out.times) == []
    assert not any("late" in (a.get("deviation") or {}) for a in out.answers)
