"""Benchmark the compiler: wall time and plans/s for the bundled tasks at 1 and 2 jobs.

    .venv/bin/python scripts/bench_compile.py [--repeat 3] [--tasks tasks/cube_stacking.yaml tasks/kitting.yaml]

Each configuration runs as a fresh `hrc compile ... --no-report -q` process (so start-up, OMPL
planning and process-pool start are counted, as a user sees them); the table shows the median.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_once(task: str, jobs: int, out: Path) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "hrc", "compile", task, "--out", str(out), "--jobs", str(jobs),
                    "--no-report", "-q"], check=True, cwd=ROOT)
    return time.perf_counter() - t0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--tasks", nargs="+", default=["tasks/cube_stacking.yaml", "tasks/kitting.yaml"])
    ap.add_argument("--jobs", nargs="+", type=int, default=[1, 2])
    args = ap.parse_args()
    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    print(f"| task | plans | jobs | wall s (median of {args.repeat}) | plans/s | speed-up |")
    print("|---|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for task in args.tasks:
            base = None
            for jobs in args.jobs:
                times = [run_once(task, jobs, Path(tmp) / "o") for _ in range(args.repeat)]
                plans = len(json.loads((Path(tmp) / "o" / "compiled.json").read_text())["plans"])
                wall = statistics.median(times)
                base = base or wall
                print(f"| {Path(task).stem} | {plans} | {jobs} | {wall:.2f} | {plans / wall:.0f} | {base / wall:.2f} |",
                      flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
