"""Benchmark the human action detector's own cost per position message.

    PYTHONPATH=. .venv/bin/python scripts/bench_detect.py [--runs 5] [--tasks tasks/cube_stacking.yaml
        tasks/kitting.yaml] [--clock cpu|wall]

Per task, the task is compiled once (not timed), then ``--runs`` simulated runs are recorded as a tracker
and the robot's controller would send them (scripts/make_trace.py's streams: the person's noisy
positions and the robot's acknowledgements, policy hrc, the motion detector in front of the dispatcher),
for both sensors of issue 28: sigma 0.05 m at 10 Hz, and sigma 0.15 m at 5 Hz with 5 % dropouts. Each
stream is then replayed through a fresh `hrc.detect.DetectingDispatcher` and every position message is
timed with ``--clock`` (``cpu``: this process's CPU time, which a loaded machine disturbs less than wall
time). The table gives, per task and sensor, the positions timed and the median, p99 and max in
milliseconds of:

- ``detector``: the detector's own work (what the dispatcher knows of the person, read once per
  decision; the filter; the change-point fits), that is the whole `DetectingDispatcher.position` less
  the time inside `Dispatcher.observe` for the events it gives;
- ``with dispatcher``: the whole of it, the dispatcher's re-ranking after each event given included
  (what `hrc dispatch --detect motion` spends on a position message, less parsing and the log).

Medians and ratios of one run on a shared machine; the absolute numbers move with the load.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

from make_trace import record  # noqa: E402

from hrc.compile.compiler import compile_task  # noqa: E402
from hrc.detect import DetectingDispatcher, DetectParams  # noqa: E402
from hrc.detect.sensor import SensorModel  # noqa: E402
from hrc.dispatch import Observation  # noqa: E402
from hrc.io.task_file import load_task  # noqa: E402

SENSORS = {"0.05 m, 10 Hz": SensorModel(0.05, 10.0, 0.0), "0.15 m, 5 Hz, 5 % drop": SensorModel(0.15, 5.0, 0.05)}


class _Timed(DetectingDispatcher):
    """Counts the time spent in the dispatcher's own `observe` (events given, the robot's messages)."""

    clock = staticmethod(time.process_time)
    inside = 0.0

    def observe(self, obs: Observation):  # type: ignore[override]
        t0 = self.clock()
        try:
            return super().observe(obs)
        finally:
            self.inside += self.clock() - t0


def _replay(pristine: _Timed, stream: list[dict]) -> tuple[list[float], list[float]]:
    d = pristine.fork()
    assert isinstance(d, _Timed)
    own: list[float] = []
    total: list[float] = []
    clock = d.clock
    for msg in stream:
        if "x" in msg:
            d.inside = 0.0
            t0 = clock()
            d.position(msg["t"], msg["x"], msg["y"])
            spent = clock() - t0
            total.append(spent)
            own.append(spent - d.inside)
        else:
            d.observe(Observation(max(msg["t"], d.now), msg["event"], msg.get("agent"), msg.get("action"),
                                  msg.get("phase")))
    return own, total


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--runs", type=int, default=5)
    p.add_argument("--tasks", nargs="+", default=["tasks/cube_stacking.yaml", "tasks/kitting.yaml"])
    p.add_argument("--clock", choices=("cpu", "wall"), default="cpu")
    a = p.parse_args()
    _Timed.clock = staticmethod(time.process_time if a.clock == "cpu" else time.perf_counter)
    print(f"# bench_detect: {platform.python_version()}, {a.runs} runs per task and sensor, clock {a.clock}")
    head = "| task | sensor | positions | detector median / p99 / max (ms) | with dispatcher median / p99 / max (ms) |"
    rows = [head, "|---|---|---:|---:|---:|"]
    for task in a.tasks:
        cps = compile_task(load_task(task), seed=0, jobs=1)
        for name, sensor in SENSORS.items():
            streams = [record(cps, i, 1, sensor)[0] for i in range(a.runs)]
            pristine = _Timed.from_compiled(cps, threads=1, params=DetectParams(sigma=sensor.sigma))
            assert isinstance(pristine, _Timed)
            own: list[float] = []
            total: list[float] = []
            for stream in streams:
                o, t = _replay(pristine, stream)
                own += o
                total += t

            def ms(xs: list[float]) -> str:
                return (f"{1000 * statistics.median(xs):.3f} / {1000 * float(np.percentile(xs, 99)):.3f} / "
                        f"{1000 * max(xs):.2f}")

            rows.append(f"| {Path(task).stem} | {name} | {len(own):,} | {ms(own)} | {ms(total)} |")
            print(rows[-1], file=sys.stderr, flush=True)
    print("\n".join(rows))


if __name__ == "__main__":
    main()
