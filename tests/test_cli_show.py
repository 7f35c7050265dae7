"""`hrc show`: the workshop summary with its 32 plans, as text and as strict JSON."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

from conftest import ROOT, WORKSHOP_TASK

from hrc.cli import main


def _strict_json(text: str):
    def no_constant(name: str):
        raise AssertionError(f"not JSON: {name}")

    return json.loads(text, parse_constant=no_constant)


def test_show_text(capsys):
    assert main(["show", str(WORKSHOP_TASK), "--no-calibrate"]) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    out = captured.out
    assert out.startswith("task cube_stacking")
    assert out.rstrip().splitlines()[-1].startswith("plans: 32 ")
    for word in ("human", "robot", "cube1", "triangle", "cube4.put -> triangle.put", "map workshop", "9 obstacles"):
        assert word in out
    # 32 plans: a second of plans, and the start-up, path planning and report around them (measured 2.4-22 s)
    line = next(x for x in out.splitlines() if x.startswith("compile estimate: "))
    assert line.startswith("compile estimate: about 2 s - 2") and " s on " in line and "report included" in line, line


def test_time_spans_read_as_a_person_would_say_them():
    from hrc.compile.estimate import fmt_span

    assert [fmt_span(0.1, 0.2), fmt_span(0.1, 2.2), fmt_span(12.2, 12.4), fmt_span(21, 180),
            fmt_span(50, 3000, " - ")] == ["under 1 s", "up to 2 s", "12 s", "21 s-3 min", "50 s - 50 min"]
    assert [fmt_span(0.1, 0.2, about=True), fmt_span(0.1, 2.2, about=True), fmt_span(21, 180, about=True)] == [
        "under 1 s", "up to 2 s", "about 21 s-3 min"]


def test_show_json(capsys):
    assert main(["show", str(WORKSHOP_TASK), "--json"]) == 0
    data = _strict_json(capsys.readouterr().out)
    assert data["plan_count"] == 32 and data["allocations"] == 32  # cube_stacking: one order per allocation
    assert [a["id"] for a in data["agents"]] == ["human", "robot"]
    assert [a["id"] for a in data["actions"]] == ["cube1", "cube2", "cube3", "cube4", "triangle"]
    assert data["actions"][0]["phases"][0] == {"id": "fetch", "location": "S1",
                                               "duration": {"human": [2, 4], "robot": [5, 6]}}
    assert data["map"]["name"] == "workshop" and data["map"]["obstacles"] == 9
    assert data["deadline"] == 80


def test_show_json_with_an_unbounded_constraint_is_strict_json(mini, write_mini, capsys):
    task, map_ = mini
    task["constraints"][0]["bounds"] = [0, float("inf")]
    assert main(["show", str(write_mini(task, map_)), "--json"]) == 0
    data = _strict_json(capsys.readouterr().out)
    assert data["constraints"][0]["bounds"] == [0, "inf"]


def test_readme_demo_command():
    """What `make demo` runs: the console script on the bundled task, from the repository root."""
    script = shutil.which("hrc", path=str(Path(sys.executable).parent))
    command = [script] if script else [sys.executable, "-m", "hrc"]
    proc = subprocess.run([*command, "show", "tasks/cube_stacking.yaml"], cwd=ROOT,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    assert "plans: 32" in proc.stdout
    proc = subprocess.run([sys.executable, "-m", "hrc", "show", "tasks/cube_stacking.yaml", "--json"], cwd=ROOT,
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and _strict_json(proc.stdout)["plan_count"] == 32


def test_show_floorplan_demo(capsys):
    assert main(["show", str(ROOT / "tasks" / "floorplan_demo.yaml")]) == 0
    out = capsys.readouterr().out
    assert "3 obstacles (floor plan floorplan.dxf)" in out
    assert "plans: 4 " in out


def test_the_calibrated_estimate_is_said_and_kept(capsys):
    """`hrc show` compiles a sample of the workshop's plans here and says the wall time it implies (the
    model's constants: tests/test_estimate_model.py); asked again, the kept calibration answers alike."""
    assert main(["show", str(WORKSHOP_TASK), "--json"]) == 0
    first = _strict_json(capsys.readouterr().out)["estimate"]
    c = first["calibration"]
    assert 0 < c["seconds_per_plan"] <= c["first_seconds_per_plan"] * 1.5 and 8 <= c["plans"] <= 32
    assert 3000 < c["line_bytes"] < 30000  # the workshop's lines are about 9 kB
    assert 1 < first["wall_seconds"] < 30 and first["wall_seconds_now"] >= first["wall_seconds"]
    assert first["wall_seconds"] >= first["wall_seconds_archive"] >= first["wall_seconds_archive_no_report"]
    assert main(["show", str(WORKSHOP_TASK), "--json"]) == 0
    assert _strict_json(capsys.readouterr().out)["estimate"] == first  # from the cache folder
    assert main(["show", str(WORKSHOP_TASK)]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("compile estimate: "))
    assert line.startswith(f"compile estimate: about {round(first['wall_seconds'])} s on ")
    assert " sample plans compiled here at " in line


def test_compile_says_the_estimate_of_hrc_shows_sample(capsys, tmp_path):
    """Once ``hrc show TASK`` has sampled the task here, ``hrc compile TASK`` says that estimate up front
    (one figure, the same as show's for its options) instead of the rough range."""
    assert main(["show", str(WORKSHOP_TASK), "--json"]) == 0
    shown = _strict_json(capsys.readouterr().out)["estimate"]
    assert main(["compile", str(WORKSHOP_TASK), "--out", str(tmp_path / "out"), "--stnu", "archive"]) == 0
    captured = capsys.readouterr()
    first = next(x for x in (captured.out + captured.err).splitlines() if x.startswith("cube_stacking: 32 plans"))
    said = re.search(r"; (\d+) s on \d+ workers? \(hrc show's sample\)$", first)
    assert said is not None, first
    assert abs(int(said.group(1)) - shown["wall_seconds_archive"]) <= 0.6, (first, shown)
