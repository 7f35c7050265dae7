"""Write maps/floorplan.dxf: a tiny shop floor plan whose closed polylines are the obstacles.

    .venv/bin/python scripts/make_floorplan_dxf.py [OUT.dxf]

Two racks (closed LWPOLYLINEs on layer RACKS, one rectangular, one L-shaped) and an open wall line
on layer WALLS, which `hrc.io.map_file` must ignore (only closed polylines become obstacles).
`RACKS` is the single source of the coordinates: the tests import it and compare the loaded obstacles
with it. Units are metres. The output is byte-for-byte reproducible (ezdxf's fixed metadata, and a
fixed PYTHONHASHSEED because ezdxf writes its CLASS records in set order) and written atomically.
"""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

import ezdxf

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from hrc.io.atomic import write_text_atomic  # noqa: E402

OUT = Path(__file__).resolve().parents[1] / "maps" / "floorplan.dxf"

# id -> closed outline (m), counter-clockwise
RACKS: dict[str, tuple[tuple[float, float], ...]] = {
    "rack_north": ((1.0, 4.0), (5.0, 4.0), (5.0, 4.6), (1.0, 4.6)),
    "rack_east": ((6.5, 0.5), (7.1, 0.5), (7.1, 2.5), (6.0, 2.5), (6.0, 1.9), (6.5, 1.9)),
}
# an open polyline: a wall stub, not an obstacle
WALL: tuple[tuple[float, float], ...] = ((0.0, 3.0), (0.5, 3.0), (0.5, 2.5))


def floorplan_text() -> str:
    ezdxf.options.write_fixed_meta_data_for_testing = True  # fixed dates and GUIDs
    doc = ezdxf.new("R2010")
    doc.units = ezdxf.units.M
    doc.layers.add("RACKS")
    doc.layers.add("WALLS")
    msp = doc.modelspace()
    for outline in RACKS.values():
        msp.add_lwpolyline(outline, close=True, dxfattribs={"layer": "RACKS"})
    msp.add_lwpolyline(WALL, close=False, dxfattribs={"layer": "WALLS"})
    buf = io.StringIO()
    doc.write(buf)
    return buf.getvalue()


def main(argv: list[str]) -> int:
    if os.environ.get("PYTHONHASHSEED") != "0":  # see the module docstring
        return subprocess.call([sys.executable, __file__, *argv[1:]], env={**os.environ, "PYTHONHASHSEED": "0"})
    out = Path(argv[1]) if len(argv) > 1 else OUT
    write_text_atomic(out, floorplan_text())
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
