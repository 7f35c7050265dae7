"""Draw the motion detector at work on a recorded trace: docs/detect.png.

    PYTHONPATH=. .venv/bin/python scripts/plot_detect.py [--trace tests/data/detect/workshop_015_5hz_drop5]
        [--sigma 0.15] [--out docs/detect.png]

Replays TRACE.trace.jsonl (the person's positions and the robot's acknowledgements) through the detector
in front of a dispatcher of the workshop (compiled here, seed 0), keeping its belief after every position,
and draws it against TRACE.truth.jsonl (`hrc.report.detect.detection_figure`).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from hrc.compile.compiler import compile_task
from hrc.detect import DetectingDispatcher, DetectParams
from hrc.dispatch import Observation
from hrc.io.task_file import load_task
from hrc.report.detect import detection_figure

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--trace", default=str(ROOT / "tests" / "data" / "detect" / "workshop_015_5hz_drop5"))
    p.add_argument("--sigma", type=float, default=0.15)
    p.add_argument("--task", default=str(ROOT / "tasks" / "cube_stacking.yaml"))
    p.add_argument("--out", default=str(ROOT / "docs" / "detect.png"))
    a = p.parse_args()
    task = load_task(a.task)
    d = DetectingDispatcher.from_compiled(compile_task(task, seed=0, jobs=1), params=DetectParams(sigma=a.sigma))
    assert isinstance(d, DetectingDispatcher)
    lines = [json.loads(x) for x in Path(a.trace + ".trace.jsonl").read_text().splitlines() if x.strip()]
    truth = [(h["t"], h["event"], h["action"], h["phase"])
             for h in (json.loads(x) for x in Path(a.trace + ".truth.jsonl").read_text().splitlines() if x.strip())
             if h["event"] in ("depart", "arrive", "start", "end")]
    samples, beliefs, given = [], [], []
    for m in lines:
        if "x" not in m:
            d.observe(Observation(max(m["t"], d.now), m["event"], m.get("agent"), m.get("action"), m.get("phase")))
            continue
        events, _ = d.position(m["t"], m["x"], m["y"])
        samples.append((m["t"], m["x"], m["y"]))
        b = d.track.belief
        beliefs.append((m["t"], b.doing, b.action, b.phase, b.p))
        given += [(m["t"], ev.t, ev.event, ev.action, ev.phase) for ev, _ in events if ev.event != "undo"]
    name = Path(a.trace).name
    detection_figure(task, samples, beliefs, truth, given,
                     f"hrc detect on a recorded workshop trace ({name}: sigma {a.sigma:g} m)", Path(a.out))
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
