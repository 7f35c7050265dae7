"""Benchmark the simulator: simulated runs per second, per policy, on one core and with --jobs 2.

    PYTHONPATH=. .venv/bin/python scripts/bench_sim.py [--task tasks/cube_stacking.yaml] [--runs 40]
                                                      [--policies hrc fixed] [--human follow]

The task is compiled once (not timed: `scripts/bench_compile.py` times compiles); then, per policy and
per jobs setting, `hrc.sim.montecarlo.simulate` runs `--runs` runs with those compiles, and the table
shows wall time and runs/s (process-pool start included, as `hrc simulate --jobs 2` pays it). The
dispatcher's share is the sum of its measured latencies over the runs, on one core.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def main() -> int:
    from hrc.compile.compiler import compile_task
    from hrc.io.task_file import load_task
    from hrc.sim.blind import blind_compile
    from hrc.sim.human import HumanModel
    from hrc.sim.montecarlo import simulate
    from hrc.sim.policies import POLICIES
    from hrc.sim.run import SimSettings

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--task", default="tasks/cube_stacking.yaml")
    ap.add_argument("--runs", type=int, default=40)
    ap.add_argument("--policies", nargs="+", default=list(POLICIES))
    ap.add_argument("--human", default="follow", choices=("follow", "preferred", "free"))
    ap.add_argument("--jobs", nargs="+", type=int, default=[1, 2])
    args = ap.parse_args()
    task = load_task(str(ROOT / args.task))
    compiles = {"motion": compile_task(task, seed=0, jobs=2)}
    if "motion-blind" in args.policies:
        compiles["blind"] = blind_compile(task, jobs=2)
    settings = SimSettings(human=HumanModel(choice=args.human))
    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}; {task.name}, {args.runs} runs per policy, person: {args.human}")
    print("| policy | jobs | wall s | runs/s | dispatcher share (1 job) |")
    print("|---|---:|---:|---:|---:|")
    for policy in args.policies:
        for jobs in args.jobs:
            t0 = time.perf_counter()
            sim = simulate(task, args.runs, 1, [policy], settings, jobs=jobs, compiles=compiles)
            wall = time.perf_counter() - t0
            share = ""
            if jobs == 1:
                spent = sum(sum(r.latencies) for r in sim.results[policy])
                share = f"{100 * spent / wall:.0f} %"
            print(f"| {policy} | {jobs} | {wall:.1f} | {args.runs / wall:.2f} | {share} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
