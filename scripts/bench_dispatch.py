"""Benchmark the dispatcher: latency of one message (median, p99, max) over random valid histories.

    .venv/bin/python scripts/bench_dispatch.py [--runs 20] [--tasks tasks/cube_stacking.yaml tasks/kitting.yaml]

Each task is compiled once (`hrc compile --no-report`, into a temporary folder) and loaded with
`Dispatcher.from_folder`. Then `--runs` histories are played by the test client (tests/dispatch_client.py:
a human who picks a random valid order and goes at once, a robot that acts inside every window it is
given), each message through `hrc.dispatch.protocol.handle_line` as `hrc dispatch` answers it; the time of
each answer is measured in this process (no pipes). The table prints the latency over all messages, and
separately over the first message of each run (the whole compiled set still in play). ``--cpu`` times
with the thread's CPU time, which a loaded machine disturbs far less than wall time.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from dispatch_client import Run  # noqa: E402

from hrc.dispatch import Dispatcher  # noqa: E402
from hrc.dispatch.protocol import handle_line  # noqa: E402


def _pct(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def bench(task: str, runs: int, clock=time.perf_counter, preferences: bool = True) -> dict:  # noqa: ANN001
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out"
        subprocess.run([sys.executable, "-m", "hrc", "compile", task, "--out", str(out), "--no-report", "-q"],
                       check=True, cwd=ROOT)
        t0 = time.perf_counter()
        base = Dispatcher.from_folder(out)
        load = time.perf_counter() - t0
    all_ms: list[float] = []
    first_ms: list[float] = []
    for seed in range(runs):
        d = Dispatcher(base.plan_set, use_preferences=preferences)
        times: list[float] = []

        def send(line: str, d: Dispatcher = d, times: list[float] = times) -> str:
            t = clock()
            answer = handle_line(d, line)
            times.append((clock() - t) * 1000)
            return answer

        Run(base.plan_set, send, seed, human_choice="random", timing="eager").play()
        first_ms.append(times[1])  # times[0] is the opening tick (nothing seen: nothing to re-check)
        all_ms.extend(times)
    return {"task": Path(task).name, "plans": len(base.plan_set.plans), "load": load, "messages": len(all_ms),
            "median": statistics.median(all_ms), "p99": _pct(all_ms, 0.99), "max": max(all_ms),
            "first_median": statistics.median(first_ms), "first_max": max(first_ms)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20)
    parser.add_argument("--tasks", nargs="+", default=["tasks/cube_stacking.yaml", "tasks/kitting.yaml"])
    parser.add_argument("--cpu", action="store_true",
                        help="time with this process's CPU time (time.thread_time) instead of wall time: "
                             "steadier on a shared, loaded machine")
    parser.add_argument("--no-preferences", dest="preferences", action="store_false",
                        help="dispatch without APA's DO windows (hrc dispatch --no-preferences)")
    args = parser.parse_args()
    clock = time.thread_time if args.cpu else time.perf_counter
    print(f"# {platform.processor() or platform.machine()}, Python {platform.python_version()}, "
          f"{args.runs} random histories per task, {'CPU' if args.cpu else 'wall'} time, "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores, "
          f"APA windows {'on' if args.preferences else 'off'}")
    print("| task | plans | load (s) | messages | median (ms) | p99 (ms) | max (ms) | "
          "first message median / max (ms) |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for task in args.tasks:
        r = bench(task, args.runs, clock, args.preferences)
        print(f"| {r['task']} | {r['plans']} | {r['load']:.2f} | {r['messages']} | {r['median']:.2f} | "
              f"{r['p99']:.2f} | {r['max']:.2f} | {r['first_median']:.1f} / {r['first_max']:.1f} |", flush=True)


if __name__ == "__main__":
    main()
