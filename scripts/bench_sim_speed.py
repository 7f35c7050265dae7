"""Benchmark `hrc simulate` before and after a change, alternately, with the outputs compared (issue 38).

    .venv/bin/python scripts/bench_sim_speed.py --before DIR [--runs 1000] [--jobs 2] [--repeat 3]
        [--task tasks/cube_stacking.yaml] [--no-figures]

Each run is a fresh ``python -m hrc simulate TASK --runs N --jobs J --out OUT -q`` process (start-up, the
up-front compile, the worker pool, ``simulation.json`` and the figures counted, as a user sees them), from
`DIR` (another checkout of the code, e.g. ``git archive main | tar -x -C DIR`` with its C core built in
place, or a worktree) and from this checkout, in turns: before, after, before, after, ... so that both
see the same load. Each side first runs once with ``--runs 1`` untimed (its compile and path caches warm,
as on a user's second run). After each pair the two ``simulation.json`` are compared byte for byte (the
same seed must give the same file): a difference stops the benchmark.

The table gives each run's wall time and CPU time (user + sys of the process tree, from
``getrusage(RUSAGE_CHILDREN)``: less sensitive to a shared machine's load than the wall time) with the
load average (1 min) at its start and end, then the medians and the ratio after / before.
"""

from __future__ import annotations

import argparse
import filecmp
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run_once(root: Path, args: list[str], out: Path) -> tuple[float, float]:
    """Wall and CPU seconds (user + sys of the process tree) of ``hrc simulate ARGS --out OUT -q`` from `root`."""
    shutil.rmtree(out, ignore_errors=True)
    env = {**os.environ, "PYTHONPATH": str(root)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "hrc", "simulate", *args, "--out", str(out), "-q"], cwd=root, env=env,
                   check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--before", type=Path, required=True, metavar="DIR", help="the checkout to compare with")
    ap.add_argument("--task", default="tasks/cube_stacking.yaml")
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-figures", action="store_true")
    a = ap.parse_args()
    roots = {"before": a.before.resolve(), "after": ROOT}
    task = str((ROOT / a.task).resolve())
    extra = ["--no-figures"] if a.no_figures else []
    print(f"`hrc simulate {a.task} --runs {a.runs} --jobs {a.jobs}{' --no-figures' if a.no_figures else ''}`, "
          f"{a.repeat} runs each, alternately; {os.cpu_count()} cores\n")
    print("| pair | code | wall, s | CPU, s | load (1 min) | simulation.json |")
    print("|---:|---|---:|---:|---|---|")
    walls: dict[str, list[float]] = {"before": [], "after": []}
    cpus: dict[str, list[float]] = {"before": [], "after": []}
    with tempfile.TemporaryDirectory(prefix="hrc-bench-sim-") as tmp:
        for root in roots.values():  # caches warm, untimed
            run_once(root, [task, "--runs", "1", "--jobs", str(a.jobs), "--no-figures"], Path(tmp) / "warm")
        for k in range(a.repeat):
            outs = {}
            for label, root in roots.items():
                outs[label] = Path(tmp) / label
                load0 = os.getloadavg()[0]
                wall, cpu = run_once(root, [task, "--runs", str(a.runs), "--jobs", str(a.jobs), *extra], outs[label])
                walls[label].append(wall)
                cpus[label].append(cpu)
                same = ""
                if label == "after":
                    same = "identical" if filecmp.cmp(outs["before"] / "simulation.json",
                                                      outs["after"] / "simulation.json", shallow=False) else "DIFFERS"
                print(f"| {k + 1} | {label} | {wall:.1f} | {cpu:.1f} | {load0:.1f}-{os.getloadavg()[0]:.1f} | {same} |",
                      flush=True)
                if same == "DIFFERS":
                    print("simulation.json differs: stopped", file=sys.stderr)
                    return 1
    wb, wa = statistics.median(walls["before"]), statistics.median(walls["after"])
    cb, ca = statistics.median(cpus["before"]), statistics.median(cpus["after"])
    print(f"\n| median | wall, s | CPU, s |\n|---|---:|---:|\n| before | {wb:.1f} | {cb:.1f} |\n"
          f"| after | {wa:.1f} | {ca:.1f} |\n| after / before | **{wa / wb:.2f}** | **{ca / cb:.2f}** |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
