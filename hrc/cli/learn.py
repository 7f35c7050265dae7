"""`hrc learn TASK RUNS... --out NEW_TASK.yaml`: better bounds from recorded runs (docs/learn.md).

RUNS are dispatcher logs, ``hrc simulate --keep-logs`` output folders, or MCAP recordings, all of this
task (checked by the task's digest: a run of another task is refused, exit 2). Writes the task with the
new duration bounds (its comments and layout kept; the map path re-pointed if the new file lives
elsewhere) and prints the unified diff; writes a report (``report.md`` and figures) into ``--report``
(default: ``NEW_TASK-learn/`` beside it), with the plans whose class moves between the old and the new
task's compile (``--no-compile``: skip both compiles). ``--types`` clusters the runs into worker types
and adds their preference sets. Both outputs are written atomically, after every check has passed.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

from hrc.cli.argtypes import real, whole
from hrc.errors import InputError

__all__ = ["add_parser", "run"]


def add_parser(sub: Any) -> None:
    p = sub.add_parser("learn", help="learn duration bounds and worker types from recorded runs; write a new task")
    p.add_argument("task", help="the task YAML file the runs were made with")
    p.add_argument("runs", nargs="+", metavar="RUNS",
                   help="dispatcher logs (*.jsonl), hrc simulate --keep-logs output folders, or MCAP recordings")
    p.add_argument("--out", required=True, metavar="NEW_TASK.yaml", help="the task file to write (new bounds)")
    p.add_argument("--report", default=None, metavar="DIR",
                   help="report folder (report.md, figures/; default: NEW_TASK-learn beside --out)")
    p.add_argument("--coverage", type=real(0.0, 0.9999, low_open=True), default=0.90,
                   help="share of the durations a bound must cover (default 0.90)")
    p.add_argument("--confidence", type=real(0.0, 0.9999, low_open=True), default=0.95,
                   help="confidence that it does (default 0.95)")
    p.add_argument("--agents", default=None, metavar="A,B",
                   help="agents whose bounds are learned (default: the person; a robot's are controllable)")
    p.add_argument("--types", action="store_true",
                   help="cluster the runs into worker types; write their preference sets (APA) and bounds")
    p.add_argument("--no-compile", action="store_true", help="do not compile the old and new task for the report")
    p.add_argument("--seed", type=whole(0), default=0, help="compile seed for the report (default 0)")
    p.add_argument("--jobs", type=whole(1), default=None, help="compile worker processes")
    p.add_argument("--quiet", "-q", action="store_true", help="no diff, no summary")
    p.set_defaults(run=run)


def _classes(task: Any, seed: int, jobs: int | None) -> dict[str, str]:
    from hrc.compile.compiler import compile_task

    cps = compile_task(task, seed=seed, jobs=jobs)
    return {cp.plan.id: cp.plan_class.value for cp in cps.plans}


def _counts(classes: dict[str, str]) -> dict[str, int]:
    return {c: sum(1 for v in classes.values() if v == c) for c in ("DC", "consistent", "inconsistent")}


def run(args: argparse.Namespace) -> int:
    from hrc.io.atomic import atomic_dir
    from hrc.io.task_file import load_task
    from hrc.learn.estimate import learn
    from hrc.learn.runs import read_runs
    from hrc.learn.task_edit import replace_bounds, replace_top_scalar, unified_diff

    task = load_task(args.task)
    out = Path(args.out)
    if out.resolve() == Path(args.task).resolve():
        raise InputError(args.out, "--out", "is the task the runs were made with: write the learned task to a new "
                                            "file (the runs stay that task's)")
    if out.exists() and not out.is_file():
        raise InputError(args.out, "--out", "exists and is not a file")
    report = Path(args.report) if args.report else out.with_name(out.stem + "-learn")
    if report.exists() and (not report.is_dir() or any(p.name not in ("report.md", "figures")
                                                       for p in report.iterdir())):
        raise InputError(str(report), "--report", "refusing to replace something that is not an earlier hrc learn "
                                                  "report (report.md, figures/)")
    agents = None
    if args.agents:
        agents = [a for a in args.agents.split(",") if a]
        for a in agents:
            if a not in task.agent_ids:
                raise InputError(args.agents, "--agents", f"{a!r} is not an agent of {task.name} "
                                                          f"(expected some of: {', '.join(task.agent_ids)})")
    runs, skipped = read_runs(task, args.runs)
    for s in skipped:
        print(f"warning: {s}", file=sys.stderr)
    if not runs:
        raise InputError(args.runs[0], "", "no usable run in the records given")
    learned = learn(task, runs, args.coverage, args.confidence, agents)
    for w in learned.warnings:
        print(f"warning: {w}", file=sys.stderr)
    text = Path(args.task).read_text(encoding="utf-8")
    new_text = replace_bounds(text, {(b.agent, b.action, b.phase): b.new for b in learned.bounds if b.changed},
                              args.task)
    types_md = ""
    if args.types:
        from hrc.learn.worker_types import find_types, types_markdown, types_yaml

        found = find_types(task, runs, args.coverage, args.confidence)
        types_md = types_markdown(found)
        block = types_yaml(task, found)
        if block:
            new_text = new_text.rstrip("\n") + "\n" + block
        elif found.k > 1:
            why = ("the task has preference sets already (kept)" if task.preference_sets
                   else "a type has no learned bound to prefer (too few observations)")
            print(f"warning: {found.k} worker types found, no preference sets written: {why}; see the report",
                  file=sys.stderr)
    map_abs = (Path(args.task).parent / task.map_path).resolve()
    new_map = os.path.relpath(map_abs, out.resolve().parent)
    if Path(new_map) != Path(task.map_path):
        new_text = replace_top_scalar(new_text, "map", new_map)
    # the new task must load before anything is written (it is checked where it will live)
    out.resolve().parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", suffix=".tmp", dir=out.resolve().parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(new_text)
        new_task = load_task(tmp)
        moves = counts = None
        if not args.no_compile:
            old_c, new_c = _classes(task, args.seed, args.jobs), _classes(new_task, args.seed, args.jobs)
            moves = {p: (old_c.get(p), new_c.get(p)) for p in sorted(set(old_c) | set(new_c))
                     if old_c.get(p) != new_c.get(p)}
            counts = (_counts(old_c), _counts(new_c))
        from hrc.report.learn import write_learn_report

        with atomic_dir(report) as stage:
            write_learn_report(stage, task, learned, len(runs), [str(s) for s in skipped], moves, counts, types_md)
        os.replace(tmp, out)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    if not args.quiet:
        sys.stdout.write(unified_diff(text, new_text, args.task, str(out)))
        changed = sum(1 for b in learned.bounds if b.changed)
        print(f"learned from {len(runs)} runs: {changed} bounds changed, "
              f"{sum(1 for b in learned.bounds if b.kept and b.n)} kept (too few observations or controllable); "
              f"wrote {out} and {report}/report.md" + (f"; classes {counts[0]} -> {counts[1]}" if counts else ""))
    return 0
