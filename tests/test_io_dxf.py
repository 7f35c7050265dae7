"""DXF floor plans: closed polylines become obstacles with the polylines' coordinates; bad plans fail cleanly."""

from __future__ import annotations

import importlib.util
import io
import subprocess
import sys

import ezdxf
import pytest
from conftest import ROOT
from shapely.geometry import Polygon

from hrc.errors import MapFileError
from hrc.io.map_file import load_workspace
from hrc.io.task_file import load_task
from hrc.plans import count_plans

DEMO_MAP = ROOT / "maps" / "floorplan_demo.yaml"
DXF = ROOT / "maps" / "floorplan.dxf"
SCRIPT = ROOT / "scripts" / "make_floorplan_dxf.py"


def _generator():
    spec = importlib.util.spec_from_file_location("make_floorplan_dxf", SCRIPT)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _ring(points) -> set[tuple[float, float]]:
    return {(round(x, 9), round(y, 9)) for x, y in points}


def test_floorplan_obstacles_match_the_polylines():
    racks = _generator().RACKS
    ws = load_workspace(DEMO_MAP)
    assert ws.floorplan == "floorplan.dxf"
    from_dxf = [o for o in ws.obstacles if o.id.startswith("dxf")]
    assert [o.id for o in ws.obstacles] == ["table", "dxf1", "dxf2"]
    assert len(from_dxf) == len(racks)
    # same vertices, same shape, whatever the order or orientation trimesh gives them
    for outline in racks.values():
        matches = [o for o in from_dxf if _ring(o.polygon) == _ring(outline)]
        assert len(matches) == 1, outline
        assert Polygon(matches[0].polygon).equals(Polygon(outline))
        assert len(matches[0].polygon) == len(outline)


def test_open_polyline_is_not_an_obstacle():
    wall = _generator().WALL
    ws = load_workspace(DEMO_MAP)
    assert all(not (_ring(wall) <= _ring(o.polygon)) for o in ws.obstacles)


def test_floorplan_task_loads_with_four_plans():
    task = load_task(ROOT / "tasks" / "floorplan_demo.yaml")
    assert task.workspace.floorplan == "floorplan.dxf"
    assert count_plans(task) == 4


def test_generator_reproduces_the_shipped_dxf(tmp_path):
    out = tmp_path / "plan.dxf"
    subprocess.run([sys.executable, str(SCRIPT), str(out)], check=True, capture_output=True, timeout=60)
    assert out.read_bytes() == DXF.read_bytes()


def _map_with_plan(tmp_path, dxf_text: str | None):
    if dxf_text is not None:
        (tmp_path / "plan.dxf").write_text(dxf_text, encoding="utf-8")
    path = tmp_path / "map.yaml"
    path.write_text("bounds: [0, 0, 8, 5]\nfloorplan: plan.dxf\nlocations:\n  A: [0.5, 0.5]\n", encoding="utf-8")
    return path


def _dxf_text(closed: bool) -> str:
    doc = ezdxf.new("R2010")
    doc.modelspace().add_lwpolyline([(1, 1), (2, 1), (2, 2), (1, 2)], close=closed)
    doc.modelspace().add_line((3, 3), (4, 4))
    buf = io.StringIO()
    doc.write(buf)
    return buf.getvalue()


@pytest.mark.parametrize(("dxf_text", "message"), [
    pytest.param(None, "does not exist", id="missing"),
    pytest.param(_dxf_text(closed=False), "has no closed polylines", id="no-closed-polyline"),
    pytest.param("0\nSECTION\n2\nENTITIES\n0\nENDSEC\n0\nEOF\n", "has no closed polylines", id="empty-dxf"),
    pytest.param("not a dxf\n", "cannot read DXF floor plan", id="garbage"),
])
def test_bad_floorplan_is_a_map_error(tmp_path, dxf_text, message):
    path = _map_with_plan(tmp_path, dxf_text)
    with pytest.raises(MapFileError) as exc:
        load_workspace(path)
    err = exc.value
    assert (err.file, err.key, err.line) == (str(path), "floorplan", 2)
    assert message in err.message
    assert "\n" not in str(err)


def test_closed_polyline_in_a_generated_dxf(tmp_path):
    ws = load_workspace(_map_with_plan(tmp_path, _dxf_text(closed=True)))
    assert [o.id for o in ws.obstacles] == ["dxf1"]
    assert _ring(ws.obstacles[0].polygon) == {(1, 1), (2, 1), (2, 2), (1, 2)}


def test_lines_that_close_a_loop_are_an_obstacle(tmp_path):
    """trimesh joins curves whose ends meet: three lines forming a triangle are one closed outline."""
    doc = ezdxf.new("R2010")
    for a, b in [((1, 1), (2, 1)), ((2, 1), (2, 2)), ((2, 2), (1, 1))]:
        doc.modelspace().add_line(a, b)
    buf = io.StringIO()
    doc.write(buf)
    ws = load_workspace(_map_with_plan(tmp_path, buf.getvalue()))
    assert [_ring(o.polygon) for o in ws.obstacles] == [{(1, 1), (2, 1), (2, 2)}]
