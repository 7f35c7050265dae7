"""Every bad task or map ends with one ``error: FILE[:LINE]: KEY.PATH: message`` line and exit status 2.

Each case starts from the minimal valid task and map of conftest.py, breaks one thing, runs
``hrc show`` in-process (and a sample of cases in a subprocess) and checks: exit 2, nothing on stdout,
exactly one line on stderr naming the file, the key path and (where YAML gives one) the line, which
must be the line of the offending key; never a traceback.
"""

from __future__ import annotations

import copy
import io
import re
import subprocess
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import ezdxf
import pytest
from conftest import MIN_MAP, MIN_TASK, ROOT, dump
from hypothesis import given, settings
from hypothesis import strategies as st

from hrc.cli import main

ERROR_LINE = re.compile(r"^error: (?P<file>[^:\n]+?)(?::(?P<line>\d+))?: (?P<rest>[^\n]*)\n$")


def put(obj: Any, path: str, value: Any) -> None:
    """Set ``obj[a][b]...`` for a dotted `path` (integers index lists)."""
    *parents, last = [int(p) if p.isdigit() else p for p in path.split(".")]
    for p in parents:
        obj = obj[p]
    obj[last] = value


def drop(obj: Any, path: str) -> None:
    *parents, last = [int(p) if p.isdigit() else p for p in path.split(".")]
    for p in parents:
        obj = obj[p]
    del obj[last]


def _dxf(polylines: list[tuple[list[tuple[float, float]], bool]]) -> str:
    doc = ezdxf.new("R2010")
    for points, closed in polylines:
        doc.modelspace().add_lwpolyline(points, close=closed)
    buf = io.StringIO()
    doc.write(buf)
    return buf.getvalue()


Edit = Callable[[dict[str, Any], dict[str, Any]], None]


@dataclass(frozen=True)
class Case:
    id: str
    file: str  # "task" or "map": the file the error must name
    key: str  # the key path the error must name ("" when the whole file is at fault)
    fragment: str  # part of the message
    line_has: str | None  # text on the reported line; None: no line is expected
    edit: Edit | None = None  # mutates the task and map dicts
    text: Callable[[str, str], tuple[str, str]] | None = None  # or rewrites their text
    files: tuple[tuple[str, str], ...] = ()  # extra files to write beside them


def _floorplan(name: str) -> Edit:
    return lambda t, m: put(m, "floorplan", name)


OPEN_ONLY_DXF = _dxf([([(1, 1), (2, 1), (2, 2)], False)])

CASES = [
    # --- the task file as a whole ----------------------------------------------------------------
    Case("yaml-syntax", "task", "", "YAML syntax: mapping values are not allowed here", "deadline: 1: 2",
         text=lambda t, m: (t.replace("deadline: 100", "deadline: 1: 2"), m)),
    Case("yaml-unclosed", "task", "", "YAML syntax", None,
         text=lambda t, m: (t.replace("agents:\n", "agents: [unclosed\n", 1), m)),
    Case("yaml-tab-indent", "task", "", "YAML syntax", None,
         text=lambda t, m: (t.replace("name: mini", "name: mini\n\tdeadline: 3"), m)),
    Case("empty-file", "task", "", "expected a mapping, found nothing", None, text=lambda t, m: ("", m)),
    Case("top-level-list", "task", "", "expected a mapping, found a list", "- 1",
         text=lambda t, m: ("- 1\n- 2\n", m)),
    Case("top-level-scalar", "task", "", "expected a mapping, found a string", "just text",
         text=lambda t, m: ("just text\n", m)),
    Case("duplicate-yaml-key", "task", "deadline", "duplicate key", "deadline: 5",
         text=lambda t, m: (t.replace("deadline: 100\n", "deadline: 100\ndeadline: 5\n"), m)),
    Case("python-tag", "task", "deadline", "bad value", "deadline",
         text=lambda t, m: (t.replace("deadline: 100", "deadline: !!python/name:os.system ''"), m)),
    Case("recursive-alias", "task", "deadline[0]", "recursive structure", "deadline: &x [*x]",
         text=lambda t, m: (t.replace("deadline: 100", "deadline: &x [*x]"), m)),
    Case("alias-bomb", "task", "", "too many values", None,
         text=lambda t, m: (t + "x0: &x0 [1, 1]\n" + "".join(f"x{k}: &x{k} [*x{k - 1}, *x{k - 1}]\n"
                                                             for k in range(1, 24)), m)),
    Case("nesting-too-deep", "task", "", "YAML nesting too deep", None,
         text=lambda t, m: (t.replace("deadline: 100", "deadline: " + "[" * 1000 + "]" * 1000), m)),
    Case("missing-top-key", "task", "agents", "missing", None, edit=lambda t, m: drop(t, "agents")),
    Case("unknown-top-key", "task", "colour", "unknown key", "colour: red",
         edit=lambda t, m: put(t, "colour", "red")),
    Case("name-with-space", "task", "name", "must not contain spaces", "name: my task",
         edit=lambda t, m: put(t, "name", "my task")),
    Case("map-missing", "task", "map", "does not exist", "map: nowhere.yaml",
         edit=lambda t, m: put(t, "map", "nowhere.yaml")),
    Case("map-not-string", "task", "map", "expected a string", "map: 5", edit=lambda t, m: put(t, "map", 5)),
    Case("safety-margin-negative", "task", "safety_margin", ">= 0", "safety_margin: -0.1",
         edit=lambda t, m: put(t, "safety_margin", -0.1)),
    Case("safety-margin-nan", "task", "safety_margin", "finite", "safety_margin: .nan",
         edit=lambda t, m: put(t, "safety_margin", float("nan"))),
    Case("deadline-zero", "task", "deadline", "positive", "deadline: 0", edit=lambda t, m: put(t, "deadline", 0)),
    Case("deadline-negative", "task", "deadline", "positive", "deadline: -5",
         edit=lambda t, m: put(t, "deadline", -5)),
    Case("deadline-inf", "task", "deadline", "finite", "deadline: .inf",
         edit=lambda t, m: put(t, "deadline", float("inf"))),
    Case("deadline-string", "task", "deadline", "expected a number, found a string", "deadline: soon",
         edit=lambda t, m: put(t, "deadline", "soon")),
    # --- agents ----------------------------------------------------------------------------------
    Case("agents-not-list", "task", "agents", "expected a list", "agents:",
         edit=lambda t, m: put(t, "agents", {"human": 1})),
    Case("agent-unknown-key", "task", "agents[0].height", "unknown key", "height: 1.8",
         edit=lambda t, m: put(t, "agents.0.height", 1.8)),
    Case("agent-missing-key", "task", "agents[1].speed", "missing", "id: robot",
         edit=lambda t, m: drop(t, "agents.1.speed")),
    Case("agent-radius-string", "task", "agents[0].radius", "expected a number, found a string", "radius: big",
         edit=lambda t, m: put(t, "agents.0.radius", "big")),
    Case("agent-radius-bool", "task", "agents[0].radius", "found a boolean", "radius: true",
         edit=lambda t, m: put(t, "agents.0.radius", True)),
    Case("agent-radius-negative", "task", "agents[0].radius", "positive", "radius: -0.3",
         edit=lambda t, m: put(t, "agents.0.radius", -0.3)),
    Case("agent-speed-zero", "task", "agents[1].speed", "positive", "speed: 0",
         edit=lambda t, m: put(t, "agents.1.speed", 0)),
    Case("agent-speed-nan", "task", "agents[1].speed", "finite", "speed: .nan",
         edit=lambda t, m: put(t, "agents.1.speed", float("nan"))),
    Case("agent-radius-inf", "task", "agents[0].radius", "finite", "radius: .inf",
         edit=lambda t, m: put(t, "agents.0.radius", float("inf"))),
    Case("agent-speed-huge-int", "task", "agents[0].speed", "finite", "speed: 1000",
         edit=lambda t, m: put(t, "agents.0.speed", 10**400)),
    Case("agent-unknown-kind", "task", "agents[1].kind", "expected one of human, robot", "kind: drone",
         edit=lambda t, m: put(t, "agents.1.kind", "drone")),
    Case("no-agent", "task", "agents", "expected at least 1 item(s), found 0", "agents:",
         edit=lambda t, m: put(t, "agents", [])),
    Case("safety-without-robot", "task", "safety", "the task has no robot", "safety:",
         edit=lambda t, m: (put(t, "agents.1.kind", "human"),
                            put(t, "safety", {"reaction_time": "0.1 s", "stopping": {"deceleration": "1 m/s^2"}}))),
    Case("duplicate-agent-id", "task", "agents[1].id", "duplicate agent id 'human'", "id: human",
         edit=lambda t, m: put(t, "agents.1.id", "human")),
    Case("agent-id-with-dot", "task", "agents[0].id", "must not contain spaces or dots", "id: hu.man",
         edit=lambda t, m: put(t, "agents.0.id", "hu.man")),
    Case("unknown-start", "task", "agents[0].start", "unknown location 'Z'", "start: Z",
         edit=lambda t, m: put(t, "agents.0.start", "Z")),
    Case("start-overlaps-obstacle", "task", "agents[0].start", "overlaps obstacle 'box'", "start: H",
         edit=lambda t, m: put(m, "locations.H", [3.8, 4])),
    Case("start-overlaps-bound", "task", "agents[1].start", "overlaps the east bound", "start: R",
         edit=lambda t, m: put(m, "locations.R", [9.7, 1])),
    Case("start-overlaps-at-margin", "task", "agents[1].start", "safety margin 0.5", "start: R",
         edit=lambda t, m: (put(m, "locations.R", [9.5, 1]), put(t, "safety_margin", 0.5))),
    # --- actions and phases ----------------------------------------------------------------------
    Case("actions-empty", "task", "actions", "at least 1", "actions:", edit=lambda t, m: put(t, "actions", [])),
    Case("action-not-mapping", "task", "actions[1]", "expected a mapping, found a string", "- a2",
         edit=lambda t, m: put(t, "actions.1", "a2")),
    Case("action-unknown-key", "task", "actions[0].colour", "unknown key", "colour: red",
         edit=lambda t, m: put(t, "actions.0.colour", "red")),
    Case("duplicate-action-id", "task", "actions[1].id", "duplicate action id 'a1'", "id: a1",
         edit=lambda t, m: put(t, "actions.1.id", "a1")),
    Case("action-unknown-agent", "task", "actions[0].agents[1]", "unknown agent 'ghost'", "- ghost",
         edit=lambda t, m: put(t, "actions.0.agents.1", "ghost")),
    Case("action-agent-not-string", "task", "actions[0].agents[1]", "expected a non-empty string id", "- - robot",
         edit=lambda t, m: put(t, "actions.0.agents.1", ["robot"])),
    Case("action-duplicate-agent", "task", "actions[0].agents[1]", "duplicate agent id 'human'", "- human",
         edit=lambda t, m: put(t, "actions.0.agents.1", "human")),
    Case("action-no-agent", "task", "actions[1].agents", "no agent can do action 'a2'", "agents: []",
         edit=lambda t, m: put(t, "actions.1.agents", [])),
    Case("action-no-phases", "task", "actions[1].phases", "at least 1", "phases: []",
         edit=lambda t, m: put(t, "actions.1.phases", [])),
    Case("phase-missing-location", "task", "actions[0].phases[1].location", "missing", "id: put",
         edit=lambda t, m: drop(t, "actions.0.phases.1.location")),
    Case("duplicate-phase-id", "task", "actions[0].phases[1].id", "duplicate phase id 'fetch'", "id: fetch",
         edit=lambda t, m: put(t, "actions.0.phases.1.id", "fetch")),
    Case("phase-unknown-location", "task", "actions[0].phases[0].location", "unknown location 'Q'",
         "location: Q", edit=lambda t, m: put(t, "actions.0.phases.0.location", "Q")),
    Case("phase-location-overlaps", "task", "actions[1].phases[0].location", "robot at location 'C' overlaps",
         "location: C",
         edit=lambda t, m: (put(m, "locations.C", [6.45, 4]), put(t, "actions.1.phases.0.location", "C"))),
    Case("duration-lb-gt-ub", "task", "actions[0].phases[0].duration.human", "lb 5 > ub 3", "human:",
         edit=lambda t, m: put(t, "actions.0.phases.0.duration.human", [5, 3])),
    Case("duration-negative", "task", "actions[0].phases[1].duration.robot[0]", ">= 0", "- -1",
         edit=lambda t, m: put(t, "actions.0.phases.1.duration.robot", [-1, 3])),
    Case("travel-slack-below-one", "task", "agents[0].travel_slack", ">= 1", "travel_slack",
         edit=lambda t, m: put(t, "agents.0.travel_slack", 0.5)),
    Case("duration-inf", "task", "actions[1].phases[0].duration.robot[1]", "finite", "- .inf",
         edit=lambda t, m: put(t, "actions.1.phases.0.duration.robot", [1, float("inf")])),
    Case("duration-three-items", "task", "actions[0].phases[0].duration.human", "expected [lb, ub]", "human:",
         edit=lambda t, m: put(t, "actions.0.phases.0.duration.human", [1, 2, 3])),
    Case("duration-scalar", "task", "actions[0].phases[0].duration.human", "expected a list", "human: 3",
         edit=lambda t, m: put(t, "actions.0.phases.0.duration.human", 3)),
    Case("duration-missing-agent", "task", "actions[0].phases[0].duration.robot", "missing", "duration:",
         edit=lambda t, m: drop(t, "actions.0.phases.0.duration.robot")),
    Case("duration-agent-not-allowed", "task", "actions[1].phases[0].duration.robot",
         "agent 'robot' may not do action 'a2'", "robot:", edit=lambda t, m: put(t, "actions.1.agents", ["human"])),
    # --- the task graph --------------------------------------------------------------------------
    Case("precedence-unknown-action", "task", "precedence[0][1]", "unknown action 'a9'", "- a9.go",
         edit=lambda t, m: put(t, "precedence.0.1", "a9.go")),
    Case("precedence-unknown-phase", "task", "precedence[0][0]", "action 'a1' has no phase 'wash'", "- a1.wash",
         edit=lambda t, m: put(t, "precedence.0.0", "a1.wash")),
    Case("precedence-too-many-dots", "task", "precedence[0][0]", "expected ACTION or ACTION.PHASE", "- a1.put.end",
         edit=lambda t, m: put(t, "precedence.0.0", "a1.put.end")),
    Case("precedence-three-items", "task", "precedence[0]", "expected [before, after]", "- - a1.put",
         edit=lambda t, m: put(t, "precedence.0", ["a1.put", "a2.go", "a1.fetch"])),
    Case("precedence-not-string", "task", "precedence[0][1]", "expected a string", "- 7",
         edit=lambda t, m: put(t, "precedence.0.1", 7)),
    Case("precedence-mapping-missing", "task", "precedence[0].after", "missing", "before: a1.put",
         edit=lambda t, m: put(t, "precedence.0", {"before": "a1.put"})),
    Case("precedence-within-action", "task", "precedence[0]", "precedence within one action", "- - a1.fetch",
         edit=lambda t, m: put(t, "precedence.0", ["a1.fetch", "a1.put"])),
    Case("precedence-cycle", "task", "precedence", "cycle: a1.fetch -> a1.put -> a2.go -> a1.fetch",
         "precedence:", edit=lambda t, m: t["precedence"].append(["a2.go", "a1.fetch"])),
    # --- temporal constraints and preferences ----------------------------------------------------
    Case("constraint-bad-event", "task", "constraints[0].from", "expected ACTION.PHASE.start or ACTION.PHASE.end",
         "from: a1.put.middle", edit=lambda t, m: put(t, "constraints.0.from", "a1.put.middle")),
    Case("constraint-event-no-boundary", "task", "constraints[0].to", "found 'a2.go'", "to: a2.go",
         edit=lambda t, m: put(t, "constraints.0.to", "a2.go")),
    Case("constraint-unknown-action", "task", "constraints[0].to", "unknown action 'zz'", "to: zz.go.end",
         edit=lambda t, m: put(t, "constraints.0.to", "zz.go.end")),
    Case("constraint-lb-gt-ub", "task", "constraints[0].bounds", "lb 30 > ub 0", "bounds:",
         edit=lambda t, m: put(t, "constraints.0.bounds", [30, 0])),
    Case("constraint-nan", "task", "constraints[0].bounds[0]", "finite", "- .nan",
         edit=lambda t, m: put(t, "constraints.0.bounds", [float("nan"), 3])),
    Case("constraint-lb-minus-inf", "task", "constraints[0].bounds[0]", "finite", "- -.inf",
         edit=lambda t, m: put(t, "constraints.0.bounds", [float("-inf"), 3])),
    Case("constraint-missing-to", "task", "constraints[0].to", "missing", "from: a1.put.end",
         edit=lambda t, m: drop(t, "constraints.0.to")),
    Case("preference-bad-kind", "task", "preferences[0].kind", "expected one of constant, linear, quadratic",
         "kind: cubic", edit=lambda t, m: put(t, "preferences.0.kind", "cubic")),
    Case("preference-coefficient-count", "task", "preferences[0].coefficients", "takes 2 coefficient(s)",
         "coefficients:", edit=lambda t, m: put(t, "preferences.0.coefficients", [1, 2, 3])),
    Case("preference-convex", "task", "preferences[0].coefficients[2]", "concave", "- 0.5",
         edit=lambda t, m: (put(t, "preferences.0.kind", "quadratic"),
                            put(t, "preferences.0.coefficients", [0, 1, 0.5]))),
    Case("preference-infinite-domain", "task", "preferences[0].domain", "finite domain", "domain:",
         edit=lambda t, m: put(t, "preferences.0.domain", [0, float("inf")])),
    Case("preference-coefficient-inf", "task", "preferences[0].coefficients[0]", "finite", "- .inf",
         edit=lambda t, m: put(t, "preferences.0.coefficients", [float("inf"), 1])),
    Case("preference-bad-event", "task", "preferences[0].to", "has no phase 'stop'", "to: a2.stop.start",
         edit=lambda t, m: put(t, "preferences.0.to", "a2.stop.start")),
    # --- the map ---------------------------------------------------------------------------------
    Case("map-yaml-syntax", "map", "", "YAML syntax", "name: a: b",
         text=lambda t, m: (t, m.replace("name: mini", "name: a: b", 1))),
    Case("map-empty", "map", "", "expected a mapping, found nothing", None, text=lambda t, m: (t, "")),
    Case("map-duplicate-yaml-key", "map", "locations.A", "duplicate key", "A:",
         text=lambda t, m: (t, m.replace("locations:\n", "locations:\n  A:\n  - 1\n  - 1\n"))),
    Case("map-unknown-key", "map", "walls", "unknown key", "walls: []", edit=lambda t, m: put(m, "walls", [])),
    Case("map-missing-bounds", "map", "bounds", "missing", None, edit=lambda t, m: drop(m, "bounds")),
    Case("bounds-inverted", "map", "bounds", "empty area", "bounds:",
         edit=lambda t, m: put(m, "bounds", [10, 0, 0, 8])),
    Case("bounds-three", "map", "bounds", "expected [xmin, ymin, xmax, ymax]", "bounds:",
         edit=lambda t, m: put(m, "bounds", [0, 0, 10])),
    Case("bounds-nan", "map", "bounds[3]", "finite", "- .nan", edit=lambda t, m: put(m, "bounds.3", float("nan"))),
    Case("obstacle-bowtie", "map", "obstacles[0]", "not a simple polygon", "id: box",
         edit=lambda t, m: put(m, "obstacles.0", {"id": "box", "polygon": [[4, 3], [6, 5], [6, 3], [4, 5]]})),
    Case("obstacle-collinear", "map", "obstacles[0]", "not a simple polygon", "id: box",
         edit=lambda t, m: put(m, "obstacles.0", {"id": "box", "polygon": [[4, 3], [5, 3], [6, 3]]})),
    Case("obstacle-two-points", "map", "obstacles[0].polygon", "at least 3", "polygon:",
         edit=lambda t, m: put(m, "obstacles.0", {"id": "box", "polygon": [[4, 3], [5, 3]]})),
    Case("obstacle-closed-two-corners", "map", "obstacles[0].polygon", "at least 3 corners", "polygon:",
         edit=lambda t, m: put(m, "obstacles.0", {"id": "box", "polygon": [[4, 3], [5, 3], [4, 3]]})),
    Case("obstacle-point-shape", "map", "obstacles[0].polygon[1]", "expected [x, y]", "- - 5",
         edit=lambda t, m: put(m, "obstacles.0", {"id": "box", "polygon": [[4, 3], [5, 3, 1], [5, 4]]})),
    Case("obstacle-rect-and-polygon", "map", "obstacles[0]", "exactly one of 'polygon' or 'rect'", "id: box",
         edit=lambda t, m: put(m, "obstacles.0.polygon", [[4, 3], [5, 3], [5, 4]])),
    Case("obstacle-empty-rect", "map", "obstacles[0].rect", "empty rectangle", "rect:",
         edit=lambda t, m: put(m, "obstacles.0.rect", [4, 3, 4, 5])),
    Case("duplicate-obstacle-id", "map", "obstacles[1].id", "duplicate obstacle id 'box'", "id: box",
         edit=lambda t, m: m["obstacles"].append({"id": "box", "rect": [7, 3, 8, 4]})),
    Case("location-inside-obstacle", "map", "locations.A", "inside obstacle 'box'", "A:",
         edit=lambda t, m: put(m, "locations.A", [5, 4])),
    Case("location-outside-bounds", "map", "locations.B", "outside the bounds", "B:",
         edit=lambda t, m: put(m, "locations.B", [11, 7])),
    Case("location-bad-shape", "map", "locations.B", "expected [x, y]", "B:",
         edit=lambda t, m: put(m, "locations.B", [8])),
    Case("location-id-with-dot", "map", "locations.B.1", "must not contain spaces or dots", "B.1:",
         edit=lambda t, m: m["locations"].update({"B.1": [8, 6]})),
    Case("locations-empty", "map", "locations", "at least one location", "locations: {}",
         edit=lambda t, m: put(m, "locations", {})),
    Case("locations-list", "map", "locations", "expected a mapping, found a list", "locations:",
         edit=lambda t, m: put(m, "locations", [[1, 1]])),
    Case("locations-number", "map", "locations", "expected a mapping, found int", "locations: 5",
         edit=lambda t, m: put(m, "locations", 5)),
    # --- the DXF floor plan ----------------------------------------------------------------------
    Case("dxf-missing", "map", "floorplan", "does not exist", "floorplan: nowhere.dxf",
         edit=_floorplan("nowhere.dxf")),
    Case("dxf-no-closed-polyline", "map", "floorplan", "no closed polylines", "floorplan: open.dxf",
         edit=_floorplan("open.dxf"), files=(("open.dxf", OPEN_ONLY_DXF),)),
    Case("dxf-garbage", "map", "floorplan", "cannot read DXF floor plan", "floorplan: bad.dxf",
         edit=_floorplan("bad.dxf"), files=(("bad.dxf", "this is\nnot a DXF\n"),)),
    Case("dxf-reserved-id", "map", "obstacles[0].id", "reserved", "id: dxf1",
         edit=lambda t, m: (_floorplan("plan.dxf")(t, m), put(m, "obstacles.0.id", "dxf1")),
         files=(("plan.dxf", (ROOT / "maps" / "floorplan.dxf").read_text()),)),
    Case("dxf-location-inside-rack", "map", "locations.A", "inside obstacle 'dxf1'", "A:",
         edit=lambda t, m: (_floorplan("plan.dxf")(t, m), put(m, "locations.A", [2, 4.3])),
         files=(("plan.dxf", (ROOT / "maps" / "floorplan.dxf").read_text()),)),
]

# run these in a real `python -m hrc` subprocess too
SUBPROCESS = {"yaml-syntax", "start-overlaps-obstacle", "precedence-cycle", "location-inside-obstacle",
              "dxf-garbage"}


def _write(case: Case, tmp_path: Path) -> tuple[Path, Path]:
    task, map_ = copy.deepcopy(MIN_TASK), copy.deepcopy(MIN_MAP)
    if case.edit is not None:
        case.edit(task, map_)
    task_text, map_text = dump(task), dump(map_)
    if case.text is not None:
        new_task, new_map = case.text(task_text, map_text)
        assert (new_task, new_map) != (task_text, map_text) or task_text == "", "the text edit changed nothing"
        task_text, map_text = new_task, new_map
    for name, content in case.files:
        (tmp_path / name).write_text(content, encoding="utf-8")
    task_path, map_path = tmp_path / "task.yaml", tmp_path / "map.yaml"
    task_path.write_text(task_text, encoding="utf-8")
    map_path.write_text(map_text, encoding="utf-8")
    return task_path, map_path


def _check(case: Case, task_path: Path, map_path: Path, code: int, out: str, err: str) -> None:
    assert code == 2, err
    assert out == ""
    assert "Traceback" not in err
    m = ERROR_LINE.match(err)
    assert m, f"not one 'error: FILE[:LINE]: ...' line: {err!r}"
    target = task_path if case.file == "task" else map_path
    assert m["file"] == str(target)
    rest = m["rest"]
    if case.key:
        assert rest.startswith(f"{case.key}: "), rest
    assert case.fragment in rest
    if case.line_has is not None:
        assert m["line"] is not None, err
        line = target.read_text(encoding="utf-8").splitlines()[int(m["line"]) - 1]
        assert case.line_has in line, f"line {m['line']} is {line!r}; {err}"


def test_valid_minimal_task_loads(tmp_path, capsys):
    task_path, _ = _write(Case("valid", "task", "", "", None), tmp_path)
    assert main(["show", str(task_path)]) == 0
    assert "plans: " in capsys.readouterr().out


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input_in_process(case, tmp_path, capsys):
    task_path, map_path = _write(case, tmp_path)
    code = main(["show", str(task_path)])
    captured = capsys.readouterr()
    _check(case, task_path, map_path, code, captured.out, captured.err)


@pytest.mark.parametrize("case", [c for c in CASES if c.id in SUBPROCESS], ids=sorted(SUBPROCESS, key=[
    c.id for c in CASES].index))
def test_bad_input_subprocess(case, tmp_path):
    task_path, map_path = _write(case, tmp_path)
    proc = subprocess.run([sys.executable, "-m", "hrc", "show", str(task_path)], capture_output=True,
                          text=True, timeout=60, cwd=tmp_path)
    _check(case, task_path, map_path, proc.returncode, proc.stdout, proc.stderr)


ALIAS_TASK = """\
name: aliases
map: map.yaml
agents:
  - {id: human, kind: human, radius: 0.3, speed: 1.2, start: H}
  - {id: robot, kind: robot, radius: 0.35, speed: 0.6, start: R}
actions:
  - id: a1
    agents: &both [human, robot]
    phases:
      - {id: fetch, location: A, duration: &d {human: [2, 4], robot: [5, 6]}}
      - {id: put, location: B, duration: *d}
  - {id: a2, agents: *both, phases: [{id: go, location: B, duration: *d}]}
"""


def test_aliases_are_allowed(tmp_path, capsys):
    """Anchors and aliases are ordinary YAML: reusing one duration mapping is fine."""
    (tmp_path / "map.yaml").write_text(dump(MIN_MAP), encoding="utf-8")
    (tmp_path / "task.yaml").write_text(ALIAS_TASK, encoding="utf-8")
    assert main(["show", str(tmp_path / "task.yaml")]) == 0
    assert "put      at B    human [2, 4] s, robot [5, 6] s" in capsys.readouterr().out


def test_case_ids_are_unique():
    assert len({c.id for c in CASES}) == len(CASES)
    assert SUBPROCESS <= {c.id for c in CASES}


@pytest.mark.parametrize("make", [
    pytest.param(lambda p: p / "absent.yaml", id="task-file-missing"),
    pytest.param(lambda p: p, id="task-path-is-a-folder"),
    pytest.param(lambda p: (p / "latin1.yaml").write_bytes(b"name: caf\xe9\n") and p / "latin1.yaml", id="not-utf8"),
])
def test_unreadable_task_file(make, tmp_path, capsys):
    path = make(tmp_path)
    assert main(["show", str(path)]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert re.fullmatch(rf"error: {re.escape(str(path))}: (file not found|cannot read: [^\n]+)\n", captured.err)


def test_usage_error_is_one_line(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["show"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1


# --- fuzz: any one value replaced by anything is either valid or one clean error ----------------------

def _paths(value: Any, prefix: tuple = ()) -> list[tuple]:
    out = [prefix] if prefix else []
    if isinstance(value, dict):
        for k, v in value.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            out += _paths(v, (*prefix, i))
    return out


_scalars = (st.none() | st.booleans() | st.integers(-10**30, 10**30) | st.floats()
            | st.text(max_size=8) | st.sampled_from(["human", "robot", "A", "B", "H", "a1", "a1.put", "a2.go.end"]))
_values = st.recursive(_scalars, lambda inner: st.lists(inner, max_size=4) | st.dictionaries(
    st.text(max_size=6) | st.sampled_from(["id", "human", "robot", "rect"]), inner, max_size=3), max_leaves=8)


@settings(max_examples=80, deadline=None)
@given(data=st.data(), which=st.sampled_from(["task", "map"]))
def test_fuzz_one_value_gives_success_or_one_clean_error(data, which):
    from hypothesis import note

    from hrc.errors import HrcError
    from hrc.io.task_file import load_task

    task, map_ = copy.deepcopy(MIN_TASK), copy.deepcopy(MIN_MAP)
    target = task if which == "task" else map_
    path = data.draw(st.sampled_from(_paths(target)))
    parent = target
    for p in path[:-1]:
        parent = parent[p]
    if data.draw(st.booleans()):
        parent[path[-1]] = data.draw(_values)
    else:
        del parent[path[-1]]
    note(f"{which} {path}")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "map.yaml").write_text(dump(map_), encoding="utf-8")
        (folder / "task.yaml").write_text(dump(task), encoding="utf-8")
        try:
            load_task(folder / "task.yaml")
        except HrcError as err:
            text = str(err)
            assert "\n" not in text and text.startswith(str(folder)), text
