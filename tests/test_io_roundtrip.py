"""One loader, one writer: ``load(dump(x)) == x`` for the bundled files and random valid tasks; frozen model."""

from __future__ import annotations

import dataclasses
import enum
import math
import shutil
import tempfile
from pathlib import Path
from typing import Any

import pytest
import yaml
from conftest import MIN_MAP, ROOT, WORKSHOP_MAP, WORKSHOP_TASK, dump
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hrc.io.map_file import dump_workspace, load_workspace, workspace_to_dict
from hrc.io.task_file import dump_task, load_task, task_to_dict
from hrc.model import Task, Workspace
from hrc.plans import generate_plans


def _copy_layout(tmp_path: Path, task: Path, map_: Path, *extra: Path) -> Path:
    """Copy a task and its map (and extra map-side files) keeping the tasks/ + maps/ layout."""
    (tmp_path / "tasks").mkdir()
    (tmp_path / "maps").mkdir()
    for f in (map_, *extra):
        shutil.copy(f, tmp_path / "maps" / f.name)
    shutil.copy(task, tmp_path / "tasks" / task.name)
    return tmp_path / "tasks" / task.name


@pytest.mark.parametrize(("task_name", "map_name", "extra"), [
    ("cube_stacking.yaml", "workshop.yaml", ()),
    ("floorplan_demo.yaml", "floorplan_demo.yaml", ("floorplan.dxf",)),
])
def test_bundled_task_round_trip(tmp_path, task_name, map_name, extra):
    path = _copy_layout(tmp_path, ROOT / "tasks" / task_name, ROOT / "maps" / map_name,
                        *(ROOT / "maps" / e for e in extra))
    task = load_task(path)
    again = path.with_name("again.yaml")
    dump_task(task, again)
    reloaded = load_task(again)
    assert reloaded == task
    assert reloaded.workspace == task.workspace
    # writing is deterministic and a fixed point
    dump_task(reloaded, path.with_name("again2.yaml"))
    assert path.with_name("again2.yaml").read_text() == again.read_text()


def test_task_dumped_elsewhere_points_at_the_same_map(tmp_path):
    task = load_task(WORKSHOP_TASK)
    out = tmp_path / "deep" / "er" / "task.yaml"
    dump_task(task, out)
    reloaded = load_task(out)
    assert (out.parent / reloaded.map_path).resolve() == WORKSHOP_MAP.resolve()
    assert reloaded == dataclasses.replace(task, map_path=reloaded.map_path)


@pytest.mark.parametrize("map_name", ["workshop.yaml", "floorplan_demo.yaml"])
def test_bundled_map_round_trip(tmp_path, map_name):
    same_folder = tmp_path / "maps"
    shutil.copytree(ROOT / "maps", same_folder)
    ws = load_workspace(same_folder / map_name)
    dump_workspace(ws, same_folder / "again.yaml")
    assert load_workspace(same_folder / "again.yaml") == ws
    # elsewhere: the floor plan reference is rewritten to reach the same DXF
    elsewhere = tmp_path / "other" / "map.yaml"
    dump_workspace(ws, elsewhere)
    reloaded = load_workspace(elsewhere)
    assert reloaded == dataclasses.replace(ws, floorplan=reloaded.floorplan)
    if ws.floorplan is not None:
        assert (elsewhere.parent / reloaded.floorplan).resolve() == (same_folder / ws.floorplan).resolve()


def test_workspace_dict_keeps_floorplan_obstacles_out():
    d = workspace_to_dict(load_workspace(ROOT / "maps" / "floorplan_demo.yaml"))
    assert d["floorplan"] == "floorplan.dxf"
    assert [o["id"] for o in d["obstacles"]] == ["table"]


# --- the model is frozen, all the way down ---------------------------------------------------------

def _walk(value: Any, path: str = "task"):
    """Yield (path, value) for every value reachable through dataclass fields and tuples."""
    yield path, value
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        for f in dataclasses.fields(value):
            yield from _walk(getattr(value, f.name), f"{path}.{f.name}")
    elif isinstance(value, tuple):
        for i, item in enumerate(value):
            yield from _walk(item, f"{path}[{i}]")


def test_model_is_immutable_all_the_way_down():
    task = load_task(WORKSHOP_TASK)
    plan = next(generate_plans(task))
    seen_dataclasses = 0
    for path, value in [*_walk(task), *_walk(plan, "plan")]:
        assert isinstance(value, (str, int, float, type(None), tuple, enum.Enum)) or dataclasses.is_dataclass(value), (
            f"{path} is a mutable {type(value).__name__}")
        if dataclasses.is_dataclass(value):
            seen_dataclasses += 1
            assert type(value).__dataclass_params__.frozen, path
            first = dataclasses.fields(value)[0].name
            with pytest.raises(dataclasses.FrozenInstanceError):
                setattr(value, first, getattr(value, first))
            with pytest.raises((AttributeError, TypeError)):  # slots: no new attributes either
                value.extra = 1
    assert seen_dataclasses > 50
    assert hash(task.agents) == hash(load_task(WORKSHOP_TASK).agents)


# --- random small valid tasks -----------------------------------------------------------------------

LOCS = list(MIN_MAP["locations"])  # H, R, A, B: all clear for both agents
AGENTS = ["human", "robot"]
small = st.integers(0, 40).map(float) | st.floats(0, 40, allow_nan=False, allow_infinity=False)


@st.composite
def interval(draw, lo=0.0):
    a, b = sorted((draw(small) + lo, draw(small) + lo))
    return [a, b]


@st.composite
def task_dicts(draw) -> dict[str, Any]:
    n = draw(st.integers(1, 4))
    actions = []
    for i in range(n):
        who = draw(st.sampled_from([["human"], ["robot"], ["human", "robot"], ["robot", "human"]]))
        phases = [{"id": f"p{j}", "location": draw(st.sampled_from(LOCS)),
                   "duration": {ag: draw(interval()) for ag in who}} for j in range(draw(st.integers(1, 3)))]
        action = {"id": f"act{i}", "agents": who, "phases": phases}
        if draw(st.booleans()):
            action["name"] = draw(st.text(max_size=12))
        actions.append(action)
    phase_refs = [(i, p["id"]) for i, a in enumerate(actions) for p in a["phases"]]
    # phase-level precedence only from a lower action index to a higher one: acyclic by construction
    precedence = []
    for (i, p), (j, q) in draw(st.lists(st.tuples(st.sampled_from(phase_refs), st.sampled_from(phase_refs)),
                                        max_size=4)):
        if i < j and [f"act{i}.{p}", f"act{j}.{q}"] not in precedence:
            precedence.append([f"act{i}.{p}", f"act{j}.{q}"])
    events = st.builds(lambda ref, b: f"act{ref[0]}.{ref[1]}.{b}", st.sampled_from(phase_refs),
                       st.sampled_from(["start", "end"]))
    constraints = []
    for _ in range(draw(st.integers(0, 2))):
        lb, ub = draw(interval(lo=-20.0))
        if draw(st.booleans()):
            ub = math.inf
        constraints.append({"from": draw(events), "to": draw(events), "bounds": [lb, ub]})
    preferences = []
    for _ in range(draw(st.integers(0, 2))):
        kind = draw(st.sampled_from(["constant", "linear", "quadratic"]))
        coeffs = [draw(small) - 20 for _ in range({"constant": 1, "linear": 2, "quadratic": 3}[kind])]
        if kind == "quadratic":
            coeffs[2] = -abs(coeffs[2])
        preferences.append({"from": draw(events), "to": draw(events), "domain": draw(interval(lo=-10.0)),
                            "kind": kind, "coefficients": coeffs})
    out: dict[str, Any] = {"name": "random", "map": "map.yaml",
                           "agents": [{"id": "human", "kind": "human", "radius": 0.3, "speed": 1.2, "start": "H"},
                                      {"id": "robot", "kind": "robot", "radius": 0.35, "speed": 0.6, "start": "R"}],
                           "actions": actions, "precedence": precedence, "constraints": constraints,
                           "preferences": preferences}
    if draw(st.booleans()):
        out["deadline"] = draw(small) + 1
    if draw(st.booleans()):
        out["safety_margin"] = draw(st.floats(0, 0.2))
    draw(st.randoms()).shuffle(out["agents"])
    return out


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(task_dicts())
def test_random_task_round_trip(raw):
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "map.yaml").write_text(dump(MIN_MAP), encoding="utf-8")
        (folder / "task.yaml").write_text(dump(raw), encoding="utf-8")
        task = load_task(folder / "task.yaml")
        # what was read is what was written
        written = task_to_dict(task)
        assert written["agents"] == raw["agents"]
        assert [a["id"] for a in written["actions"]] == [a["id"] for a in raw["actions"]]
        for got, want in zip(written["actions"], raw["actions"], strict=True):
            assert got["phases"] == want["phases"]
            assert got["agents"] == want["agents"]
            assert got["name"] == want.get("name", want["id"])
        assert written["precedence"] == raw["precedence"]
        assert written["constraints"] == raw["constraints"]
        assert written["preferences"] == raw["preferences"]
        assert written.get("deadline") == raw.get("deadline")
        # and the round trip is the identity
        dump_task(task, folder / "again.yaml")
        again = load_task(folder / "again.yaml")
        assert again == task
        assert isinstance(again, Task) and isinstance(again.workspace, Workspace)
        assert yaml.safe_load((folder / "again.yaml").read_text()) == written


def test_polygon_closing_point_is_optional(mini, write_mini):
    task, map_ = mini
    open_ring = load_task(write_mini(task, map_)).workspace
    map_["obstacles"][0] = {"id": "box", "polygon": [[4, 3], [6, 3], [6, 5], [4, 5], [4, 3]]}
    closed_ring = load_task(write_mini(task, map_)).workspace
    assert closed_ring == open_ring
    assert closed_ring.obstacles[0].polygon == ((4, 3), (6, 3), (6, 5), (4, 5))
