"""Benchmark the compiler: wall time, plans/s per core, peak memory, speed-up on more workers.

    .venv/bin/python scripts/bench_compile.py [--repeat 3] [--tasks tasks/cube_stacking.yaml tasks/kitting.yaml]
        [--jobs 1 2] [--dask 2] [--stnu archive] [--max-plans N] [--time-limit S]

Each configuration runs as a fresh `hrc compile TASK --no-report -q --stnu MODE --jobs N` process (so
start-up, OMPL planning and process-pool start are counted, as a user sees them); the table shows the
median wall time, plans/s per core (plans / wall / workers), the peak memory of the whole process tree
(the compile and its workers: the largest sum of their resident sets, sampled every 0.1 s from /proc)
and the speed-up over the first configuration of the task. ``--dask N`` adds a run on a local Dask
cluster of N single-threaded worker processes (`distributed.LocalCluster`, started once, not timed).
``--time-limit S`` stops a run after S seconds with SIGTERM (the compile then writes its partial
output) and reports the plans it wrote: for tasks too large to finish, the rate and the memory still
show. Task names ``pile:N`` (the workshop map, a pile of N cubes built in order: 2**N plans) and
``picks:N`` (the kitting cell, N independent picks: (N+1)! plans) are generated into a temporary folder.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def pile_task(n: int, folder: Path) -> Path:
    """The workshop map, n cubes from the five storages (cycled) onto the pile at T, in order."""
    lines = [f"name: pile_{n}", f"map: {ROOT / 'maps' / 'workshop.yaml'}", "safety_margin: 0.1",
             f"deadline: {16 * n}", "agents:",
             "  - {id: human, kind: human, radius: 0.30, speed: 1.2, start: H}",
             "  - {id: robot, kind: robot, radius: 0.35, speed: 0.6, start: R}", "actions:"]
    for i in range(1, n + 1):
        lines += [f"  - id: cube{i}", "    agents: [human, robot]", "    phases:",
                  f"      - {{id: fetch, location: S{(i - 1) % 5 + 1}, duration: {{human: [2, 4], robot: [5, 6]}}}}",
                  "      - {id: put, location: T, duration: {human: [2, 4], robot: [4, 5]}}"]
    lines += ["precedence:"] + [f"  - [cube{i}.put, cube{i + 1}.put]" for i in range(1, n)]
    path = folder / f"pile_{n}.yaml"
    path.write_text("\n".join(lines) + "\n")
    return path


def picks_task(n: int, folder: Path) -> Path:
    """The kitting cell, n independent picks (racks A-E, cycled) into the tray at K."""
    lines = [f"name: picks_{n}", f"map: {ROOT / 'maps' / 'kitting_cell.yaml'}", "safety_margin: 0.1",
             f"deadline: {20 * n}", "agents:",
             "  - {id: human, kind: human, radius: 0.30, speed: 1.2, start: H}",
             "  - {id: robot, kind: robot, radius: 0.35, speed: 0.6, start: R}", "actions:"]
    for i in range(n):
        lines += [f"  - id: pick_{i}", "    agents: [human, robot]", "    phases:",
                  f"      - {{id: fetch, location: {'ABCDE'[i % 5]}, duration: {{human: [2, 4], robot: [4, 5]}}}}",
                  "      - {id: place, location: K, duration: {human: [1, 3], robot: [3, 4]}}"]
    path = folder / f"picks_{n}.yaml"
    path.write_text("\n".join(lines) + "\n")
    return path


def _tree_rss(pid: int) -> int:
    """Resident bytes of `pid` and its descendants (from /proc; 0 when it is gone)."""
    total, todo = 0, [pid]
    while todo:
        p = todo.pop()
        try:
            with open(f"/proc/{p}/status") as fh:
                total += next((int(line.split()[1]) * 1024 for line in fh if line.startswith("VmRSS:")), 0)
            with open(f"/proc/{p}/task/{p}/children") as fh:
                todo += [int(c) for c in fh.read().split()]
        except (OSError, ValueError):
            continue
    return total


def _children_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def run_once(task: str, args: list[str], out: Path,
             time_limit: float | None) -> tuple[float, int, int, bool, float]:
    """(wall s, peak tree RSS bytes, plans written, partial, CPU s of the compile and its workers)."""
    cpu0 = _children_cpu()
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "hrc", "compile", task, "--out", str(out), "--no-report", "-q",
                             *args], cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    peak = 0
    stopped = False
    while proc.poll() is None:
        peak = max(peak, _tree_rss(proc.pid))
        if time_limit is not None and not stopped and time.perf_counter() - t0 > time_limit:
            proc.send_signal(signal.SIGTERM)
            stopped = True
        time.sleep(0.1)
    wall = time.perf_counter() - t0
    if proc.returncode not in (0, 130):
        raise SystemExit(f"hrc compile {task} {' '.join(args)} failed with exit status {proc.returncode}")
    data = json.loads((out / "compiled.json").read_text())
    return wall, peak, len(data["plans"]), bool(data.get("partial")), _children_cpu() - cpu0


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--tasks", nargs="+", default=["tasks/cube_stacking.yaml", "tasks/kitting.yaml"])
    ap.add_argument("--jobs", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--dask", type=int, default=0, metavar="N", help="also run on a local Dask cluster of N workers")
    ap.add_argument("--stnu", default="archive", choices=("graphml", "archive", "none"))
    ap.add_argument("--max-plans", type=int, default=None)
    ap.add_argument("--time-limit", type=float, default=None, metavar="S")
    args = ap.parse_args()
    cluster = None
    if args.dask:
        from distributed import LocalCluster

        cluster = LocalCluster(n_workers=args.dask, threads_per_worker=1, processes=True, dashboard_address=None)
    load = os.getloadavg()
    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cores, Python "
          f"{platform.python_version()}, load average {load[0]:.1f} / {load[1]:.1f} / {load[2]:.1f} at start")
    print(f"| task | plans | workers | wall s (median of {args.repeat}) | plans/s | plans/s per core | "
          "plans per CPU s | peak memory MB | speed-up |")
    print("|---|---:|---|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for spec in args.tasks:
            kind, _, n = spec.partition(":")
            task = str(pile_task(int(n), Path(tmp)) if kind == "pile" else picks_task(int(n), Path(tmp))
                       if kind == "picks" else spec)
            base = None
            configs = [(f"{j} local", ["--jobs", str(j)], j) for j in args.jobs]
            if cluster is not None:
                configs.append((f"{args.dask} Dask", ["--executor", cluster.scheduler_address.replace("tcp", "dask")],
                                args.dask))
            for label, extra, workers in configs:
                extra = extra + ["--stnu", args.stnu] + (["--max-plans", str(args.max_plans)] if args.max_plans
                                                         else [])
                runs = [run_once(task, extra, Path(tmp) / "o", args.time_limit) for _ in range(args.repeat)]
                wall = statistics.median(r[0] for r in runs)
                peak = max(r[1] for r in runs)
                plans, partial = runs[0][2], runs[0][3]
                rate = plans / wall
                base = base or rate
                name = Path(task).stem + (" (stopped: partial)" if partial else "")
                cpu = statistics.median(r[4] for r in runs)
                per_cpu = f"{plans / cpu:.1f}" if "Dask" not in label else "n/a"  # Dask workers are not ours
                print(f"| {name} | {plans:,} | {label} | {wall:.1f} | {rate:.1f} | {rate / workers:.1f} | "
                      f"{per_cpu} | {peak / 2**20:.0f} | {rate / base:.2f} |", flush=True)
    if cluster is not None:
        cluster.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
