"""What recording a simulated run as MCAP costs: file size and time per run (``hrc simulate --record``).

For runs 0..N-1 of a policy, times the run alone (`hrc.sim.run.simulate_run`) and the same run recorded
(`hrc.record.sim.record_run`: the run with the floor's positions kept, plus the MCAP written in memory),
interleaved in the same process, and prints medians: the run, the recorded run, their difference (the
recording's cost), the ratio, and the file's size. Run it alone on the machine where it matters; medians
and ratios of one run are what to compare.

    PYTHONPATH=. .venv/bin/python scripts/bench_record.py [tasks/kitting.yaml] [--runs 10] [--policy hrc]
"""

from __future__ import annotations

import argparse
import statistics
import time

from hrc.compile.compiler import compile_task
from hrc.io.task_file import load_task
from hrc.record.sim import record_run
from hrc.sim.run import SimContext, SimSettings, simulate_run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("task", nargs="?", default="tasks/kitting.yaml")
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--policy", default="hrc")
    ap.add_argument("--jobs", type=int, default=2, help="for the compile only")
    args = ap.parse_args()
    task = load_task(args.task)
    t0 = time.perf_counter()
    cps = compile_task(task, seed=0, jobs=args.jobs)
    print(f"{task.name}: {len(cps.plans)} plans compiled in {time.perf_counter() - t0:.1f} s")
    ctx = SimContext(task, {"motion": cps}, SimSettings(), seed=1)
    simulate_run(ctx, args.policy, 0)  # warm: the pristine dispatcher, the imports
    record_run(ctx, args.policy, 0)
    plain, recorded, sizes, makespans = [], [], [], []
    for i in range(args.runs):
        t0 = time.perf_counter()
        r = simulate_run(ctx, args.policy, i)
        plain.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        data, r2 = record_run(ctx, args.policy, i)
        recorded.append(time.perf_counter() - t0)
        assert r == r2
        sizes.append(len(data))
        makespans.append(r.makespan or 0.0)
    cost = [b - a for a, b in zip(plain, recorded, strict=True)]
    print(f"{args.runs} runs of {args.policy} (makespan median {statistics.median(makespans):.1f} s):")
    print(f"  run alone     median {1000 * statistics.median(plain):7.1f} ms")
    print(f"  run recorded  median {1000 * statistics.median(recorded):7.1f} ms")
    print(f"  recording     median {1000 * statistics.median(cost):7.1f} ms per run "
          f"(ratio {statistics.median(b / a for a, b in zip(plain, recorded, strict=True)):.2f})")
    print(f"  MCAP size     median {statistics.median(sizes) / 1000:7.1f} kB (min {min(sizes) / 1000:.1f}, "
          f"max {max(sizes) / 1000:.1f})")


if __name__ == "__main__":
    main()
