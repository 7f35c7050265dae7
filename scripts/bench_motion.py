"""Benchmark motion acquisition: planning throughput, cache hit rate, length vs exact, plan_motions speed.

    .venv/bin/python scripts/bench_motion.py [TASK.yaml] [--seeds N]

For each seed: `plan_paths` wall and CPU time (CPU time is the steadier figure on a shared machine),
planned queries per second, the path library's cache hit rate
(``1 - planned / lookups``, lookups = the ordered (agent, from, to) pairs asked for while building plus
every `PathLibrary.get` made by `plan_motions` over all plans), the length ratio against the exact
visibility-graph shortest path (`hrc.motion.exact`, the oracle), and `plan_motions` time per plan.
Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

from hrc.io.task_file import load_task
from hrc.motion import plan_motions, plan_paths
from hrc.motion.exact import ExactPlanner
from hrc.plans import generate_plans

ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("task", nargs="?", default=str(ROOT / "tasks" / "cube_stacking.yaml"))
    ap.add_argument("--seeds", type=int, default=5, help="seeds 0..N-1 (default 5)")
    args = ap.parse_args(argv)
    task = load_task(args.task)
    ws = task.workspace
    exact = {a.id: ExactPlanner(ws, a.radius + task.safety_margin) for a in task.agents}
    plans = list(generate_plans(task))
    optimum: dict[tuple[str, str, str], float] = {}
    rows = []
    for seed in range(args.seeds):
        t0, c0 = time.perf_counter(), time.process_time()
        lib = plan_paths(task, seed=seed)
        planning, cpu = time.perf_counter() - t0, time.process_time() - c0
        ratios = []
        for p in lib:
            key = (p.agent, p.origin, p.target)
            if key not in optimum:
                optimum[key] = exact[p.agent].shortest(ws.location(p.origin).xy, ws.location(p.target).xy)[0]
            ratios.append(p.length / optimum[key])
        lib.gets = 0
        t1 = time.perf_counter()
        interfered = sum(any(m.interference for m in plan_motions(task, plan, lib)) for plan in plans)
        per_plan = (time.perf_counter() - t1) / max(1, len(plans))
        lookups = lib.stats["requested"] + lib.gets
        rows.append({
            "seed": seed, "planning_s": planning, "cpu_s": cpu, "qps": lib.stats["planned"] / planning,
            "planned": int(lib.stats["planned"]), "lookups": int(lookups),
            "hit": 1 - lib.stats["planned"] / lookups, "fallbacks": int(lib.stats["fallbacks"]),
            "min": min(ratios), "median": statistics.median(ratios), "max": max(ratios),
            "motions_ms": per_plan * 1000, "interfered": interfered,
        })
    print(f"task {task.name}: {len(plans)} plans, {len(ws.locations)} locations, "
          f"{len(ws.obstacles)} obstacles; python {sys.version.split()[0]}\n")
    print("| seed | plan_paths wall s | cpu s | queries/s (wall) | planned / lookups | cache hit | fallbacks | "
          "length/exact min | median | max | plan_motions ms/plan | plans with interference |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['seed']} | {r['planning_s']:.3f} | {r['cpu_s']:.3f} | {r['qps']:.0f} | "
              f"{r['planned']} / {r['lookups']} | "
              f"{r['hit']:.1%} | {r['fallbacks']} | {r['min']:.4f} | {r['median']:.4f} | {r['max']:.4f} | "
              f"{r['motions_ms']:.2f} | {r['interfered']} / {len(plans)} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
