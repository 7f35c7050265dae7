"""Time to the first usable output of the search compile (issue 35, docs/search.md, docs/benchmarks.md).

For each task: ``hrc compile TASK --plans best:K --cover D --no-report -q`` in a fresh process (path
planning, search, coverage, writing the output), wall seconds; then one ``hrc dispatch`` answer from the
output (it is usable only if it dispatches). Prints one JSON line per run with the search's own counts
and the compile's CPU seconds (it runs in one process: on a free core, its wall time).

    PYTHONPATH=. .venv/bin/python scripts/bench_search.py [--k 50] [--cover 2] [--repeat 1] TASK.yaml ...
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("tasks", nargs="+")
    p.add_argument("--k", type=int, default=50)
    p.add_argument("--cover", type=int, default=2)
    p.add_argument("--budget", type=int, default=None, help="--search-budget (default: the compile's)")
    p.add_argument("--repeat", type=int, default=1)
    args = p.parse_args()
    for task in args.tasks:
        for _ in range(args.repeat):
            out = Path(tempfile.mkdtemp(prefix="hrc-bench-search-")) / "out"
            cmd = [sys.executable, "-m", "hrc", "compile", task, "--out", str(out), "--plans", f"best:{args.k}",
                   "--cover", str(args.cover), "--no-report", "-q"]
            if args.budget is not None:
                cmd += ["--search-budget", str(args.budget)]
            load = os.getloadavg()[0]
            before = resource.getrusage(resource.RUSAGE_CHILDREN)
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True)
            wall = time.perf_counter() - t0
            after = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
            tick = '{"t": 0, "event": "tick"}\n'
            run = subprocess.run([sys.executable, "-m", "hrc", "dispatch", str(out)], input=tick, capture_output=True,
                                 text=True, check=True)
            answer = json.loads(run.stdout.splitlines()[0])
            head = json.loads((out / "compiled.json").read_text())
            search = head["search"]
            print(json.dumps({"task": task, "wall_s": round(wall, 1), "cpu_s": round(cpu, 1),
                              "load_at_start": round(load, 1),
                              "plans": sum(head["counts"].values()), "closed": search["closed"],
                              "best_gap_s": search["best_gap_s"], "kth_gap_s": search["kth_gap_s"],
                              "coverage": search["coverage"], "dispatch_ok": answer["ok"],
                              "best": head["plans"][0]["id"]}), flush=True)
            shutil.rmtree(out.parent)
    return 0


if __name__ == "__main__":
    sys.exit(main())
