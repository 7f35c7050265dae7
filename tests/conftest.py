"""Shared fixtures: the repository's paths and a minimal valid task + map that tests mutate."""

from __future__ import annotations

import copy
import os
import tempfile
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import settings

# CI replays the same examples every run (a red CI is then a reproducible bug, not a dice roll);
# a developer's run explores new ones. Both print the blob that reproduces a failure.
settings.register_profile("ci", derandomize=True, print_blob=True)
settings.register_profile("dev", print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else "dev")

# hrc's on-disk caches (`hrc.caches.cache_folder`: the roadmaps) go to a folder of this test session, never
# the user's ~/.cache/hrc; the hrc processes tests start inherit it.
os.environ["HRC_CACHE_DIR"] = tempfile.mkdtemp(prefix="hrc-test-cache-")

ROOT = Path(__file__).resolve().parents[1]
WORKSHOP_TASK = ROOT / "tasks" / "cube_stacking.yaml"
WORKSHOP_MAP = ROOT / "maps" / "workshop.yaml"



def compiled_folder(out: Path, task: Path = WORKSHOP_TASK, *args: str) -> Path:
    """`task` compiled into the new folder `out` as ``hrc compile --no-report`` writes it (more options in
    `args`); the folder."""
    from hrc.cli import main

    assert main(["compile", str(task), "--out", str(out), "--no-report", "-q", *args]) == 0
    return out


# A 10 m x 8 m floor with one box in the middle; every optional key present so that tests can break it.
MIN_MAP: dict[str, Any] = {
    "name": "mini",
    "bounds": [0, 0, 10, 8],
    "obstacles": [{"id": "box", "rect": [4, 3, 6, 5]}],
    "locations": {"H": [1, 1], "R": [9, 1], "A": [2, 7], "B": [8, 7]},
}
MIN_TASK: dict[str, Any] = {
    "name": "mini",
    "map": "map.yaml",
    "safety_margin": 0.1,
    "deadline": 100,
    "agents": [
        {"id": "human", "kind": "human", "radius": 0.3, "speed": 1.2, "start": "H"},
        {"id": "robot", "kind": "robot", "radius": 0.35, "speed": 0.6, "start": "R"},
    ],
    "actions": [
        {"id": "a1", "name": "fetch at A, put at B", "agents": ["human", "robot"], "phases": [
            {"id": "fetch", "location": "A", "duration": {"human": [2, 4], "robot": [5, 6]}},
            {"id": "put", "location": "B", "duration": {"human": [2, 4], "robot": [4, 5]}},
        ]},
        {"id": "a2", "agents": ["human", "robot"], "phases": [
            {"id": "go", "location": "B", "duration": {"human": [1, 2], "robot": [2, 3]}},
        ]},
    ],
    "precedence": [["a1.put", "a2.go"]],
    "constraints": [{"from": "a1.put.end", "to": "a2.go.end", "bounds": [0, 30]}],
    "preferences": [{"from": "a1.put.end", "to": "a2.go.start", "domain": [0, 10], "kind": "linear",
                     "coefficients": [1, -0.1]}],
}


def tree_bytes(folder: Path) -> dict[str, bytes]:
    """Every file under `folder`, by its relative path: its bytes (to compare two outputs whole)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def dump(value: Any) -> str:
    """Block-style YAML, one key per line (so that error lines point at distinct keys)."""
    return yaml.safe_dump(value, sort_keys=False, default_flow_style=False)


@pytest.fixture
def mini() -> tuple[dict[str, Any], dict[str, Any]]:
    """Fresh deep copies of the minimal valid task and map, to mutate."""
    return copy.deepcopy(MIN_TASK), copy.deepcopy(MIN_MAP)


@pytest.fixture
def write_mini(tmp_path: Path):
    """``write_mini(task, map) -> task path``: writes task.yaml and map.yaml into tmp_path."""

    def write(task: dict[str, Any], map_: dict[str, Any]) -> Path:
        (tmp_path / "map.yaml").write_text(dump(map_), encoding="utf-8")
        path = tmp_path / "task.yaml"
        path.write_text(dump(task), encoding="utf-8")
        return path

    return write


@pytest.fixture
def mini_task(mini, write_mini):
    """The minimal valid task, loaded (`hrc.task.load_task`)."""
    from hrc.io.task_file import load_task

    task, map_ = mini
    return load_task(write_mini(task, map_))


def dispatched_team_run(ctx: Any, index: int) -> tuple[Any, Any]:
    """Run `index` of policy ``hrc`` of a team (`hrc.sim.team_run.simulate_team_run`, recorded), with the
    dispatching controller it ran under (`TeamDispatched`: its dispatcher's history)."""
    from hrc.sim.team_policies import TeamDispatched, make_team_controller
    from hrc.sim.team_run import simulate_team_run

    kept: list[TeamDispatched] = []

    def make(c: Any, p: Any) -> Any:
        ctl = make_team_controller(c, p)
        assert isinstance(ctl, TeamDispatched)
        kept.append(ctl)
        return ctl

    return simulate_team_run(ctx, "hrc", index, record=True, controller=make), kept[0]
