"""Close the loop in simulation: a person whose true durations differ from the task's bounds, `hrc learn`
on N of their runs, a recompile, and the same person again (docs/learn.md).

    PYTHONPATH=. nice .venv/bin/python scripts/bench_learn.py [--scale 0.75] [--sizes 50 200]
        [--learn-from 200] [--check-runs 200] [--timing-logs 1000] [--jobs 1]

1. The hidden truth: the workshop person's manipulation times triangular on the task's bounds times
   `--scale` (`hrc.sim.human.scaled_truth`; 0.75: faster than typed, so that a fair share of them fall
   below the typed lower bounds and break the contingent links the promise rests on); they choose freely.
2. ``max(--sizes)`` runs of the ``hrc`` policy are simulated once with their logs kept; the first N of
   them (the runs are independent, seeded per index) are N runs. For each N, `hrc learn`'s bounds: how
   many were learned, and of those, the share whose true content ``F(ub) - F(lb)`` reaches the stated
   coverage (the tolerance interval's promise: expected at least the stated confidence) and the share
   that holds the true central quantiles ``[q((1-p)/2), q((1+p)/2)]``.
3. The task learned from ``--learn-from`` runs is compiled, and ``--check-runs`` new runs (other seeds)
   of the same person are simulated on the old and on the new compile, the person now following the
   robot's plan (so that the first plan is the one carried out and its promise is what is tested): the
   DC first plans that kept every constraint, the makespan median, the deadline met.
4. `hrc learn` (the command, in process, ``--no-compile``: reading, learning, the task, the diff, the
   report and its figures) on ``--timing-logs`` logs: the simulated logs, repeated as needed to make up
   the number when fewer were simulated (the work per log is the same; the table says so).
"""

from __future__ import annotations

import argparse
import io
import os
import platform
import shutil
import sys
import tempfile
import time
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def share(xs: list[bool]) -> str:
    return f"{sum(xs)}/{len(xs)} ({100 * sum(xs) / len(xs):.0f} %)" if xs else "-"


def timed(task: object, task_path: Path, logs: Path, work: Path, simulated: int, p: float, gamma: float) -> None:
    """`hrc learn` on the logs in `logs`, in process (its imports already paid): wall and CPU seconds for
    reading and learning, and for the whole command (the task, the diff, the report and its figures)."""
    from hrc.cli import main as hrc_main
    from hrc.learn.estimate import learn
    from hrc.learn.runs import read_runs

    n = sum(1 for _ in logs.iterdir())
    w, c = time.perf_counter(), time.process_time()
    runs, _ = read_runs(task, [logs])  # type: ignore[arg-type]
    learn(task, runs, p, gamma)  # type: ignore[arg-type]
    core = (time.perf_counter() - w, time.process_time() - c)
    w, c = time.perf_counter(), time.process_time()
    with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
        assert hrc_main(["learn", str(task_path), str(logs), "--out", str(work / "timed.yaml"), "--no-compile",
                         "-q"]) == 0
    whole = (time.perf_counter() - w, time.process_time() - c)
    print(f"hrc learn on {n} logs ({simulated} simulated, repeated): read and learn {core[0]:.1f} s wall / "
          f"{core[1]:.1f} s CPU; the whole command (task, diff, report, figures) {whole[0]:.1f} s wall / "
          f"{whole[1]:.1f} s CPU (load {os.getloadavg()[0]:.1f})")


def main() -> int:
    from scipy.stats import triang

    from hrc.cli import main as hrc_main
    from hrc.compile.compiler import compile_task
    from hrc.io.task_file import load_task
    from hrc.learn.estimate import learn
    from hrc.learn.runs import read_runs
    from hrc.sim.human import HumanModel, scaled_truth
    from hrc.sim.metrics import aggregate
    from hrc.sim.montecarlo import simulate
    from hrc.sim.run import SimSettings
    from hrc.sim.runlog import log_name

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--task", default="tasks/cube_stacking.yaml")
    ap.add_argument("--scale", type=float, default=0.75)
    ap.add_argument("--sizes", nargs="+", type=int, default=[50, 200])  # 1000: not run at full size (load)
    ap.add_argument("--learn-from", type=int, default=200)
    ap.add_argument("--check-runs", type=int, default=200)
    ap.add_argument("--timing-logs", type=int, default=1000)
    ap.add_argument("--coverage", type=float, default=0.90)
    ap.add_argument("--confidence", type=float, default=0.95)
    ap.add_argument("--jobs", type=int, default=1)
    args = ap.parse_args()
    task_path = ROOT / args.task
    task = load_task(task_path)
    truth = scaled_truth(task, args.scale)
    human = next(a.id for a in task.agents if a.is_human)
    settings = SimSettings(human=HumanModel(choice="free", truth=truth))
    follow = SimSettings(human=HumanModel(choice="follow", truth=truth))  # keeps to the plan: its promise is tested
    p, gamma = args.coverage, args.confidence
    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}; "
          f"{task.name}, true durations = bounds x {args.scale:g} (triangular), person chooses freely, "
          f"coverage {p:g}, confidence {gamma:g}")
    work = Path(tempfile.mkdtemp(prefix="hrc-bench-learn-"))
    try:
        t0 = time.perf_counter()
        old_compile = compile_task(task, seed=0, jobs=args.jobs)
        n_max = max([*args.sizes, args.learn_from])
        sim = simulate(task, n_max, 1, ["hrc"], settings, jobs=args.jobs, compiles={"motion": old_compile},
                       keep_logs=True)
        assert sim.logs is not None
        logs = work / "logs"
        logs.mkdir()
        files = []
        for i, data in sorted(sim.logs["hrc"].items()):
            files.append(logs / log_name("hrc", i))
            files[-1].write_bytes(data)
        print(f"# simulated {n_max} runs in {time.perf_counter() - t0:.0f} s (compile included)")
        true = {(a, ph): triang(0.5, loc=lb, scale=ub - lb) for a, ph, lb, ub in truth}
        print()
        print("| runs N | disjoint samples | bounds learned | true content >= coverage | holds the true central "
              "quantiles |")
        print("|---:|---:|---:|---:|---:|")
        for n in sorted(args.sizes):
            blocks = n_max // n  # disjoint samples of n runs each: more bounds to count coverage over
            new, content, holds = [], [], []
            for k in range(blocks):
                runs, _ = read_runs(task, files[k * n:(k + 1) * n])
                got = learn(task, runs, p, gamma)
                mine = [b for b in got.bounds if b.agent == human and not b.kept]
                new += mine
                for b in mine:
                    dist = true[(b.action, b.phase)]
                    content.append(dist.cdf(b.new.ub) - dist.cdf(b.new.lb) >= p)
                    holds.append(b.new.lb <= dist.ppf((1 - p) / 2) and b.new.ub >= dist.ppf((1 + p) / 2))
            phases = sum(1 for a in task.actions for ph in a.phases if human in a.agents) * blocks
            print(f"| {n} | {blocks} | {len(new)} of {phases} | {share(content)} | {share(holds)} |")
        learned_from = args.learn_from
        new_task_path = work / "learned.yaml"
        with redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
            assert hrc_main(["learn", str(task_path), *map(str, files[:learned_from]), "--out", str(new_task_path),
                             "--no-compile", "-q", "--coverage", str(p), "--confidence", str(gamma)]) == 0
        new_task = load_task(new_task_path)
        new_compile = compile_task(new_task, seed=0, jobs=args.jobs)
        print()
        print(f"Old task: {old_compile.counts()}; learned from {learned_from} runs: {new_compile.counts()}.")
        print()
        print(f"| {args.check_runs} new runs on | DC first plan | ... kept every constraint | ... every duration "
              "of the person inside its bound | makespan median | deadline met |")
        print("|---|---:|---:|---:|---:|---:|")
        for label, tk, cps in (("the typed bounds", task, old_compile), ("the learned bounds", new_task, new_compile)):
            check = simulate(tk, args.check_runs, 2, ["hrc"], follow, jobs=args.jobs, compiles={"motion": cps})
            a = aggregate(check.results["hrc"])
            dc, kept = a["first_plan_dc_kept"], a["first_plan_dc_kept_all_constraints"]
            inside = sum(1 for r in check.results["hrc"] if r.first_class == "DC" and r.first_kept
                         and not any(b.startswith(f"{human}'s") and "travel" not in b for b in r.first_broken))
            print(f"| {label} | {a['first_plan_dc']} | {kept}/{dc} ({100 * kept / max(1, dc):.0f} %) | "
                  f"{inside}/{dc} ({100 * inside / max(1, dc):.0f} %) | "
                  f"{a['makespan']['median']} s | {100 * (a['deadline_met_rate'] or 0):.1f} % |")
        timing = work / "timing"
        timing.mkdir()
        for i in range(args.timing_logs):
            shutil.copyfile(files[i % len(files)], timing / f"run-{i:05d}.jsonl")
        print()
        timed(task, task_path, timing, work, len(files), p, gamma)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
