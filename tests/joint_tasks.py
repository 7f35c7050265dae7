"""The small joint-action task the joint tests share (issue 37): fetches at A and B (either agent), the joint
lift at J between the two starts (the person holds 3-5 s, the robot lifts 2-4 s: the step lasts 3-5 s,
contingent), then, unless left out, a place at B; on a bare 10 m x 4 m floor."""

from __future__ import annotations

import copy
from pathlib import Path
from typing import Any

import yaml

BARE: dict[str, Any] = {"name": "bare", "bounds": [0, 0, 10, 4], "obstacles": [],
                        "locations": {"H": [1, 2], "R": [9, 2], "J": [5, 2], "A": [1, 3.5], "B": [9, 3.5]}}
J = (5.0, 2.0)


def _either(action: str, phase: str, at: str) -> dict[str, Any]:
    return {"id": action, "agents": ["human", "robot"], "phases": [
        {"id": phase, "location": at, "duration": {"human": [1, 2], "robot": [2, 3]}}]}


def lift_task(*, place: bool = True, set_down: bool = False, deadline: float | None = None) -> dict[str, Any]:
    """The task as a document: `place` adds the place at B after the lift; `set_down` gives the lift a
    second phase (set down at A: both agents go on together); `deadline` one."""
    phases = [{"id": "hold", "location": "J", "duration": {"holder": [3, 5], "lifter": [2, 4]}}]
    if set_down:
        phases.append({"id": "set", "location": "A", "duration": {"holder": [1, 2], "lifter": [1, 3]}})
    task: dict[str, Any] = {"name": "lift_then_place", "map": "map.yaml", "safety_margin": 0.1}
    if deadline is not None:
        task["deadline"] = deadline
    task["agents"] = [{"id": "human", "kind": "human", "radius": 0.3, "speed": 1.0, "start": "H"},
                      {"id": "robot", "kind": "robot", "radius": 0.35, "speed": 0.5, "start": "R"}]
    task["actions"] = [_either("a", "fetch", "A"), _either("b", "fetch", "B"),
                       {"id": "lift", "roles": {"holder": "human", "lifter": "robot"}, "phases": phases}]
    task["precedence"] = [["a", "lift"], ["b", "lift"]]
    if place:
        task["actions"].append(_either("c", "place", "B"))
        task["precedence"].append(["lift", "c"])
    return task


def write_lift(folder: Path, task: dict[str, Any]) -> Path:
    """`task` and the bare map written into `folder`; the task file's path."""
    (folder / "map.yaml").write_text(yaml.safe_dump(BARE, sort_keys=False), "utf-8")
    path = folder / "task.yaml"
    path.write_text(yaml.safe_dump(copy.deepcopy(task), sort_keys=False), "utf-8")
    return path
