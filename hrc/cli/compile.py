"""`hrc compile TASK.yaml --out DIR [--seed N] [--jobs N] [--executor URL]`: the compiler's main job."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

from hrc.errors import InputError
from hrc.io.atomic import atomic_dir
from hrc.io.task_file import load_task

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    p = sub.add_parser("compile", help="compile a task into its ranked set of HRC schedules (STNUs)")
    p.add_argument("task", help="task YAML file")
    p.add_argument("--out", default=None, help="output folder (default: out/TASK_NAME)")
    p.add_argument("--seed", type=int, default=0, help="seed for motion planning (default 0)")
    p.add_argument("--jobs", type=int, default=None, help="worker processes (default: one per core; 1 = serial)")
    p.add_argument("--executor", default=None, metavar="URL",
                   help="run plans on a Dask scheduler instead, e.g. dask://127.0.0.1:8786")
    p.add_argument("--human-waits", choices=("yes", "no"), default="yes",
                   help="yes (default, the paper's model): the robot's strategy decides when the human leaves "
                        "for and starts each step; no: the human never waits for the robot's sake")
    p.add_argument("--rank-by", choices=("worst", "earliest", "nominal"), default="worst",
                   help="makespan that ranks plans within a class (default: worst case)")
    p.add_argument("--no-report", action="store_true", help="write compiled.json and STNUs only")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar, no summary")
    p.set_defaults(run=run)


class _Bar:
    """A tqdm progress bar per stage on a terminal; nothing when stderr is piped."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self.bars: dict[str, Any] = {}

    def __call__(self, stage: str, done: int, total: int) -> None:
        if not self.enabled:
            return
        from tqdm import tqdm

        bar = self.bars.get(stage)
        if bar is None:
            label = {"motion": "motion planning", "plans": "plans"}.get(stage, stage)
            bar = self.bars[stage] = tqdm(total=total, desc=label, unit="", file=sys.stderr, leave=False)
        bar.update(done - bar.n)

    def close(self) -> None:
        for bar in self.bars.values():
            bar.close()


def _check_out(out: str) -> None:
    """The output folder is replaced whole, so it must be new, empty, or an earlier compile's output."""
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise InputError(out, "--out", "exists and is not a folder")
    if path.is_dir() and any(path.iterdir()) and not (path / "compiled.json").is_file():
        raise InputError(out, "--out", "refusing to replace a folder that is not empty and holds no "
                                       "compiled.json (not an earlier hrc compile output)")


def run(args: argparse.Namespace) -> int:
    from hrc.compile.compiler import CompileOptions, compile_task
    from hrc.compile.output import write_compiled

    task = load_task(args.task)
    out = args.out or f"out/{task.name}"
    _check_out(out)
    bar = _Bar(enabled=sys.stderr.isatty() and not args.quiet)
    t0 = time.perf_counter()
    try:
        options = CompileOptions(human_waits=args.human_waits == "yes", rank_by=args.rank_by)
        cps = compile_task(task, seed=args.seed, jobs=args.jobs, executor=args.executor, progress=bar,
                           options=options)
    finally:
        bar.close()
    with atomic_dir(out) as stage:
        write_compiled(cps, stage)
        if not args.no_report:
            from hrc.report import write_report

            write_report(cps, stage)
    if not args.quiet:
        counts = cps.counts()
        print(f"compiled {len(cps.plans)} plans of {task.name} in {time.perf_counter() - t0:.2f} s: "
              + ", ".join(f"{n} {c}" for c, n in counts.items()))
        if cps.plans:
            best = cps.plans[0]
            ms = best.classification.makespan
            span = "" if ms is None else f", makespan {ms[0]:.1f}-{ms[1]:.1f} s"
            print(f"best plan {best.plan.id} ({best.plan_class.value}{span}): "
                  + "; ".join(f"{agent}: {' -> '.join(seq) or '-'}" for agent, seq in best.plan.sequences))
        print(f"wrote {out}/compiled.json, {out}/stnu/ ({len(cps.plans)} GraphML)"
              + ("" if args.no_report else f", {out}/report.md, {out}/report.html"))
    return 0
