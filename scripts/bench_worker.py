"""Benchmark a compile worker's cost per plan, in this process: what one `hrc compile` worker spends on
each plan of a task (motion search, STNU, classification, `compiled.json` line, GraphML), without the
process pool, the parent's spooling or the report.

    PYTHONPATH=. .venv/bin/python scripts/bench_worker.py [--stride 10] [--repeat 3]
        [--tasks tasks/kitting_6picks.yaml tasks/kitting_7picks.yaml]

The sample: every `--stride`-th family of `hrc.plans.plan_families` (spread over the whole plan space,
whose corners differ a lot: the first allocations give the human everything), compiled in chunks of
four families by `hrc.compile.stream.compact_records` (the executor's unit of work) with ``--stnu
archive``. Each repeat is a fresh process (cold caches, as a worker starts); the table shows the median
CPU ms per plan and the plans per CPU second. ``--stride 1`` measures every plan (one worker's work
for the whole task, on one core). Numbers on a shared VM vary by 10-20 % from run to run: compare two
versions by alternating runs.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_CHILD = """
import itertools, json, sys, time
from hrc.compile.compiler import CompileOptions
from hrc.compile.stream import compact_records
from hrc.io.task_file import load_task
from hrc.motion import plan_paths
from hrc.plans import plan_families

task = load_task(sys.argv[1])
paths = plan_paths(task, seed=0)
families = list(itertools.islice(plan_families(task), 0, None, int(sys.argv[2])))
t = time.process_time()
for i in range(0, len(families), 4):
    compact_records(CompileOptions(), "archive", task, paths, ((None, {}), families[i:i + 4]))
print(json.dumps({"families": len(families), "plans": sum(map(len, families)), "cpu": time.process_time() - t}))
"""


def measure(task: Path, stride: int) -> dict:
    out = subprocess.run([sys.executable, "-c", _CHILD, str(task), str(stride)], cwd=ROOT, check=True,
                         capture_output=True, text=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tasks", nargs="+", type=Path,
                    default=[ROOT / "tasks" / "kitting_6picks.yaml", ROOT / "tasks" / "kitting_7picks.yaml"])
    ap.add_argument("--stride", type=int, default=10, help="every N-th family (default 10)")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    if args.stride < 1 or args.repeat < 1:
        ap.error("--stride and --repeat must be at least 1")
    print("| task | families | plans | CPU ms per plan (median) | runs (ms per plan) | plans per CPU s |")
    print("|---|---:|---:|---:|---|---:|")
    for task in args.tasks:
        runs = [measure(task, args.stride) for _ in range(args.repeat)]
        per_plan = [1000 * r["cpu"] / r["plans"] for r in runs]
        mid = statistics.median(per_plan)
        print(f"| {task.stem} | {runs[0]['families']:,} | {runs[0]['plans']:,} | {mid:.2f} | "
              f"{', '.join(f'{x:.2f}' for x in per_plan)} | {1000 / mid:.0f} |", flush=True)


if __name__ == "__main__":
    main()
