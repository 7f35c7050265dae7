"""`hrc compile TASK.yaml --out DIR [--seed N] [--jobs N] [--executor URL]`: the compiler's main job.

Before any work (issue 12) it checks every argument and the output folder: it claims the folder
(`hrc.io.claim`: a lock file beside it, so that a read-only place, ``/proc/...`` or a parent that is a
file fail now, not after the compile, and a second compile into the same folder is refused), removes
what a killed run left beside it, and refuses a folder holding anything a compile does not write
(`_check_entries`). It counts the plans in bounded time (or bounds them) and refuses more than
``--max-plans`` with one line that says how to go on; it then says what the compile will cost, plans
the paths, measures its first plans and says how long the rest will take. Plans are compiled streaming
(`hrc.compile.stream`) into a staging folder beside ``--out``, swapped into place at the end; progress
is a bar with ETA on a terminal, a line every `PROGRESS_EVERY` seconds otherwise.

Signals and kills (issue 26; the README says the same):

- SIGINT (Ctrl-C) or SIGTERM is acted on only where it is safe (`hrc.cli.interrupt`), and the process
  always ends with status 130. Before the first plan: nothing is written, ``--out`` is as it was. While
  plans are compiled: the workers end their unit of work, and the plans so far are written as a partial
  output (``"partial": true`` in compiled.json, and ``resume.npy``) into a new or empty ``--out``, or the
  one being resumed; an earlier complete output there is kept instead, and nothing is written. Once every
  plan is compiled (compiled.json being written, the report, the swap): that is finished first, and
  ``--out`` holds the complete output.
- SIGKILL (or a power cut): ``--out`` holds the earlier output, or none, never a part; the workers die
  with the parent (`hrc.compile.executors`); the next compile into the same ``--out`` removes the staging
  folder left beside it.

``--resume`` goes on with a partial output (its plans are taken as they are) and ends with the output an
uninterrupted run writes, byte for byte.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import sys
import time
from collections.abc import Callable
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hrc.cli.argtypes import delay_range, real, whole
from hrc.errors import InputError
from hrc.io.claim import FolderClaim

if TYPE_CHECKING:
    from hrc.cli.interrupt import DeferredInterrupt
    from hrc.model import Task
    from hrc.report.drawer import FigureDrawer

__all__ = ["PROGRESS_EVERY", "add_parser", "run"]

PROGRESS_EVERY = 30.0
"""Seconds between progress lines when stderr is not a terminal."""


def _pin(text: str) -> tuple[str, str]:
    action, sep, agent = text.partition("=")
    if not sep or not action or not agent:
        raise argparse.ArgumentTypeError(f"expected ACTION=AGENT, found {text!r}")
    return action, agent


def _plans(text: str) -> str | int:
    """``all``, ``auto`` or ``best:K`` (K at least 1): "all", "auto" or K."""
    if text in ("all", "auto"):
        return text
    head, sep, k = text.partition(":")
    if head != "best" or not sep or not k.isdigit() or int(k) < 1:
        raise argparse.ArgumentTypeError(f"expected all, auto or best:K with K a whole number >= 1, found {text!r}")
    return int(k)


def add_parser(sub: Any) -> None:
    from hrc.compile.defaults import COVER_DEPTH, DEFAULT_K, REPORT_TOP, SEARCH_FAMILIES, STNU_MODES
    from hrc.compile.estimate import DEFAULT_MAX_PLANS

    p = sub.add_parser("compile", help="compile a task into its ranked set of HRC schedules (STNUs)")
    p.add_argument("task", help="task YAML file")
    p.add_argument("--out", default=None, help="output folder (default: out/TASK_NAME)")
    p.add_argument("--seed", type=int, default=0, help="seed for motion planning (default 0)")
    p.add_argument("--jobs", type=whole(1), default=None,
                   help="worker processes, at most the cores (default: one per core; 1 = serial)")
    p.add_argument("--executor", default=None, metavar="URL",
                   help="run plans on a Dask scheduler instead, e.g. dask://127.0.0.1:8786")
    p.add_argument("--human-waits", choices=("yes", "no"), default="yes",
                   help="yes (default, the paper's model): the robot's strategy decides when the human leaves "
                        "for and starts each step; no: the human never waits for the robot's sake")
    p.add_argument("--observation-delay", metavar="LO:HI", type=delay_range, default=None,
                   help="class every plan for a robot that learns each human event LO to HI seconds after it "
                        "happens (D: exactly D; inf: never); overrides the task's sensing: (its path kept)")
    p.add_argument("--rank-by", choices=("worst", "earliest", "nominal"), default="worst",
                   help="makespan that ranks plans within a class (default: worst case)")
    p.add_argument("--stnu", choices=STNU_MODES, default="graphml",
                   help="STNUs as one GraphML file per plan in stnu/ (default), packed into stnu.zip "
                        "(archive), or not written (none)")
    p.add_argument("--max-plans", type=whole(1), default=DEFAULT_MAX_PLANS,
                   help=f"refuse a task with more plans than this (default {DEFAULT_MAX_PLANS:,})")
    p.add_argument("--pin", type=_pin, action="append", default=[], metavar="ACTION=AGENT",
                   help="give ACTION to AGENT only (fewer plans: the others are not compiled); repeatable")
    p.add_argument("--symmetry", action="store_true",
                   help="compile one plan per relabelling of identical actions (same agents, phases, "
                        "locations, durations; in no precedence, constraint or preference)")
    p.add_argument("--best-per-allocation", type=whole(1), default=None, metavar="K",
                   help="keep only the K best plans of each allocation (all are compiled; the others are not "
                        "written, ranked or offered to the dispatcher)")
    p.add_argument("--plans", type=_plans, default="auto", metavar="all|best:K|auto",
                   help="all: every plan (refused above --max-plans); best:K: search for the K best by the ranking's "
                        "order, with a plan for each of the person's first choices (docs/search.md); auto "
                        f"(default): all up to --max-plans, else best:{DEFAULT_K}")
    p.add_argument("--search-budget", type=whole(1), default=None, metavar="N",
                   help=f"the search compiles at most N families for the best K (default {SEARCH_FAMILIES} K): a "
                        "budget in work, so the output is the same on any machine")
    p.add_argument("--search-seconds", type=real(0.1), default=None, metavar="S",
                   help="also stop the search after S seconds, and the coverage after as much again (the output "
                        "then depends on the machine's pace)")
    p.add_argument("--search-batch", type=whole(1, 4096), default=1, metavar="B",
                   help="the search compiles up to B leaves at a time over --jobs workers or --executor (default "
                        "1: one at a time, in this process); the output depends on B, never on the workers")
    p.add_argument("--cover", type=whole(0), default=COVER_DEPTH, metavar="D",
                   help=f"with the search: a plan for each action the person could start next, at the start and "
                        f"after each of their first D-1 choices (default {COVER_DEPTH}; 0: none)")
    p.add_argument("--resume", action="store_true",
                   help="go on with the interrupted compile in --out (same task and options): its plans are "
                        "kept, the rest compiled; the output is the same as an uninterrupted run's")
    p.add_argument("--report-top", type=whole(1), default=REPORT_TOP, metavar="N",
                   help=f"the report's ranked table shows the N best plans and the best of each class "
                        f"(default {REPORT_TOP}), with statistics over all plans")
    p.add_argument("--no-report", action="store_true", help="write compiled.json and STNUs only")
    p.add_argument("--quiet", "-q", action="store_true", help="no estimate, no progress, no summary")
    p.add_argument("--verbose", "-v", action="store_true",
                   help="say where the time went: start-up, paths (planned or from the cache), plans, report")
    p.set_defaults(run=run)


class _Progress:
    """A tqdm bar per stage (with ETA) on a terminal; otherwise one line every `every` seconds."""

    def __init__(self, tty: bool, quiet: bool, every: float = PROGRESS_EVERY) -> None:
        self.tty, self.quiet, self.every = tty, quiet, every
        self.bars: dict[str, Any] = {}
        self.t0 = time.monotonic()
        self.last = self.t0
        self.start_done: dict[str, tuple[float, int]] = {}

    def __call__(self, stage: str, done: int, total: int) -> None:
        if self.quiet:
            return
        if stage == "stopping":  # interrupted: the plans so far are being written as a partial output
            self.close()
            print(f"interrupted: writing the {done:,} of {total:,} plans compiled so far as a partial output",
                  file=sys.stderr, flush=True)
            return
        label = {"motion": "motion planning", "plans": "plans", "blind": "motion-blind plans"}.get(stage, stage)
        if self.tty:
            from tqdm import tqdm

            bar = self.bars.get(stage)
            if bar is None:
                bar = self.bars[stage] = tqdm(total=total, desc=label, unit="", file=sys.stderr, leave=False,
                                              dynamic_ncols=True)
            bar.update(done - bar.n)
            return
        now = time.monotonic()
        t_start, d_start = self.start_done.setdefault(stage, (now, done))
        if now - self.last < self.every or stage == "motion":
            return
        self.last = now
        rate = (done - d_start) / max(now - t_start, 1e-9)
        from hrc.compile.estimate import fmt_seconds

        eta = fmt_seconds((total - done) / rate) if rate > 0 and total >= done else "?"
        print(f"{label}: {done:,}/{total:,} ({100 * done / max(total, 1):.0f} %), {rate:.1f}/s, "
              f"{fmt_seconds(now - self.t0)} so far, about {eta} left", file=sys.stderr, flush=True)

    def close(self) -> None:
        for bar in self.bars.values():
            bar.close()
        self.bars.clear()


def _check_out(out: str) -> None:
    """The output folder is replaced whole: it must not be a file, nor hold the current folder
    (``--out .``). What it holds is checked once it is claimed (`_check_entries`)."""
    path = Path(out)
    if path.exists() and not path.is_dir():
        raise InputError(out, "--out", "exists and is not a folder")
    resolved = path.resolve()
    here = Path.cwd().resolve()
    if resolved == here or resolved in here.parents:
        raise InputError(out, "--out", "is the current folder or holds it; the output folder is replaced "
                                       "whole: name a new folder, e.g. --out out/NAME")


def _foreign(folder: Path, also: tuple[str, ...] = ()) -> list[str]:
    """What `folder` holds that a compile does not write (`OUTPUT_FILES`, `REPORT_FILES`) nor `also` names,
    sorted, folders with a ``/``."""
    from hrc.compile.stream import OUTPUT_FILES
    from hrc.report import REPORT_FILES

    ours = {*OUTPUT_FILES, *REPORT_FILES, *also}
    return sorted(f"{e.name}/" if e.is_dir() and not e.is_symlink() else e.name
                  for e in os.scandir(folder) if e.name not in ours)


def _named(names: list[str]) -> str:
    shown = ", ".join(names[:4])
    return shown + (f" and {len(names) - 4} more" if len(names) > 4 else "")


def _check_entries(out: str) -> None:
    """Refuse, before any work, an ``--out`` that holds anything an ``hrc compile`` does not write: it
    would be lost when the folder is replaced (console run logs in ``runs/``, notes, another program's
    output). Why refuse rather than carry them into the new output: a run log records runs of the plans
    it was dispatched from, and beside a new plan set ``--replay`` would replay it against plans it was
    not recorded with; where such files belong is the user's call."""
    path = Path(out)
    if not path.is_dir():
        return
    if any(path.iterdir()) and not (path / "compiled.json").is_file():
        raise InputError(out, "--out", "refusing to replace a folder that is not empty and holds no "
                                       "compiled.json (not an earlier hrc compile output)")
    foreign = _foreign(path)
    if foreign:
        raise InputError(out, "--out", f"holds {_named(foreign)}, which hrc compile did not write; the output "
                                       "folder is replaced whole, so they would be lost: move them out of it, "
                                       "or compile into another --out")


def _check_earlier(out: str) -> Callable[[Path, Path], None]:
    """`FolderClaim.staging`'s last look at the earlier output, once it is out of the way: anything that
    appeared in it during the compile and that no compile writes (the new output's names count as
    ours) stops the swap."""

    def check(earlier: Path, new: Path) -> None:
        foreign = _foreign(earlier, also=tuple(os.listdir(new)))
        if foreign:
            raise InputError(out, "--out", f"{_named(foreign)} appeared in it during the compile, and hrc "
                                           "compile did not write them; the output folder is replaced whole, "
                                           "so the new output was not put in place: move them out of it and "
                                           "compile again")

    return check


def _search(args: argparse.Namespace, interrupt: DeferredInterrupt, task: Any, out: str, k: int,
            claim: FolderClaim, say: Callable[[str], None], options: Any) -> int:
    """``--plans best:K`` (or ``auto`` above ``--max-plans``): the search compile (`hrc.compile.search`),
    in this process. Options that only the exhaustive compile has are refused, not ignored."""
    for flag, used in (("--resume", args.resume), ("--symmetry", args.symmetry),
                       ("--best-per-allocation", args.best_per_allocation is not None),
                       ("--executor without --search-batch", args.executor is not None and args.search_batch == 1)):
        if used:
            raise InputError(args.task, flag, f"not with the search compile (--plans best:{k}); it compiles "
                                              "only the plans it needs")
    from hrc.compile.search import SEARCH_FAMILIES, compile_search
    budget = args.search_budget or SEARCH_FAMILIES * k
    limit = "" if args.search_seconds is None else f", {args.search_seconds:g} s"
    say(f"{task.name}: searching for the best {k} plans (at most {budget} families compiled{limit}), then a plan "
        f"for each of the person's first {args.cover} choice{'s' * (args.cover != 1)}")
    progress = _Progress(tty=sys.stderr.isatty(), quiet=args.quiet)
    t0 = time.perf_counter()
    with claim.staging(check_earlier=_check_earlier(out)) as stage:
        try:
            result = compile_search(task, stage, k, seed=args.seed, options=options, stnu=args.stnu,
                                    keep=args.report_top, families=budget, seconds=args.search_seconds,
                                    cover=args.cover, batch=args.search_batch, jobs=args.jobs,
                                    executor=args.executor, progress=progress, stop=interrupt.check)
        finally:
            progress.close()
        if not args.no_report:
            from hrc.report import write_report

            write_report(result.plan_set, stage)
    o = result.outcome
    if not args.quiet:
        counts = result.plan_set.counts()
        print(f"searched {task.name} in {time.perf_counter() - t0:.2f} s: compiled {o.found} plans ("
              + ", ".join(f"{n} {c}" for c, n in counts.items()) + f"); {o.guarantee()}")
        if o.cover_depth:
            print(f"the person's choices (first {o.cover_depth}): {o.covered} of {o.choices} have a plan, "
                  f"{o.impossible} no valid plan allows, {o.given_up} given up (time or the dive's limit)")
        stnu = {"graphml": f"{out}/stnu/", "archive": f"{out}/stnu.zip", "none": "no STNU files"}[args.stnu]
        report = "" if args.no_report else f", {out}/report.md, {out}/report.html"
        print(f"wrote {out}/compiled.json, {stnu}{report}")
    return 0


def _refusal(task_file: str, est: Any, limit: int, workers: int) -> InputError:
    from hrc.compile.estimate import fmt_bytes, fmt_span

    lo, hi = est.wall(workers)
    return InputError(task_file, "", f"{est.plans} plans, more than --max-plans {limit:,} ("
                      f"{fmt_span(lo, hi, about=True)} on {workers} core{'s' * (workers > 1)}, "
                      f"{fmt_bytes(est.disk('archive'))} with --stnu archive): raise --max-plans to compile "
                      "them all, spread them over a Dask cluster (--executor dask://HOST:PORT), or compile "
                      "fewer (--pin ACTION=AGENT, --symmetry)")


def run(args: argparse.Namespace) -> int:
    """The command (module docstring). SIGINT and SIGTERM are deferred to safe points for its whole run
    (`DeferredInterrupt`), and looked at once more at the end."""
    from hrc.cli.interrupt import DeferredInterrupt

    with DeferredInterrupt() as interrupt:
        try:
            code = _run(args, interrupt)
        except KeyboardInterrupt:  # `interrupt.check` before the first plan: nothing was written
            print(f"error: interrupted ({interrupt.name}) before any plan was compiled; the output folder is as "
                  "it was", file=sys.stderr)
            return 130
        if code == 0 and interrupt.requested:  # after the output was complete: in its last lines, the release
            print(f"error: interrupted ({interrupt.name}) once the output was written; it is complete",
                  file=sys.stderr)
            return 130
        return code


def _stated_sensing(task: Task, delay: tuple[Fraction, Fraction | None]) -> Task:
    """`task` with the observation delay of ``--observation-delay`` (its sensing's path and dating kept,
    else the path "stated", undated)."""
    from dataclasses import replace

    from hrc.io.task_file import MAX_SECONDS
    from hrc.model import Sensing

    lo, hi = float(delay[0]), None if delay[1] is None else float(delay[1])
    if lo > MAX_SECONDS or (hi is not None and hi > MAX_SECONDS):
        raise InputError("--observation-delay", "", f"at most {MAX_SECONDS:g} s")
    old = task.sensing
    sensing = Sensing("stated", (lo, hi), False) if old is None else Sensing(old.path, (lo, hi), old.dated)
    return replace(task, sensing=sensing)


def _run(args: argparse.Namespace, interrupt: DeferredInterrupt) -> int:
    # the figures' process, forked first: while this one reads the task and imports the compiler, it
    # imports matplotlib, then draws the figures' bases on the other core (none for a search compile)
    drawer = None
    if not args.no_report and not isinstance(args.plans, int):
        from hrc.report.drawer import FigureDrawer

        drawer = FigureDrawer()
    with drawer or contextlib.nullcontext():
        return _run_with(args, interrupt, drawer)


def _run_with(args: argparse.Namespace, interrupt: DeferredInterrupt, drawer: FigureDrawer | None) -> int:
    from hrc.compile.executors import check_jobs, default_jobs, parse_executor_url, probe_scheduler
    from hrc.io.task_file import load_task  # here: the figure process is forked before numpy and shapely
    from hrc.plans import pin_actions

    task = load_task(args.task)
    if args.pin:
        task = pin_actions(task, dict(args.pin))
    if args.observation_delay is not None:
        task = _stated_sensing(task, args.observation_delay)
    out = args.out or f"out/{task.name}"
    _check_out(out)
    if args.executor is not None:
        _, host, port = parse_executor_url(args.executor)
        probe_scheduler(f"tcp://[{host}]:{port}" if ":" in host else f"tcp://{host}:{port}")
        workers = default_jobs()
    else:
        workers = check_jobs(args.jobs) if args.jobs is not None else default_jobs()
    interrupt.check()
    quiet = args.quiet
    say = (lambda text: None) if quiet else (lambda text: print(text, file=sys.stderr, flush=True))
    try:
        with FolderClaim(out) as claim:
            for line in claim.recovered:  # a killed run's leftovers, cleaned up: said even with --quiet
                print(f"{out}: {line}", file=sys.stderr, flush=True)
            _check_entries(out)
            if drawer is not None:
                drawer.task(task)
            return _compile(args, interrupt, task, out, workers, claim, say, drawer)
    except OSError as err:  # writing the output (a full disk: a write names no file); said by `hrc.cli.main`
        if not err.filename:
            err.filename = str(out)
        raise


def _times(start_cpu: float, stages: list[tuple[str, float, float]]) -> str:
    """``-v``: where the time went, as lines: each stage's wall and CPU time (this process's; worker
    processes' apart), after the start-up's CPU (imports, reading the task: before any clock was read)."""
    import resource

    lines = ["where the time went (wall / CPU of this process):",
             f"  start-up (imports, reading the task): {start_cpu:.2f} s CPU"]
    lines += [f"  {name}: {wall:.2f} s / {cpu:.2f} s" for name, wall, cpu in stages]
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    workers = children.ru_utime + children.ru_stime
    total = start_cpu + sum(cpu for _, _, cpu in stages)
    lines.append(f"  total: {sum(w for _, w, _ in stages):.2f} s after start-up / {total:.2f} s"
                 + (f", and {workers:.2f} s CPU in worker processes (the pool, a second roadmap; not the figures')"
                    if workers else ""))
    return "\n".join(lines)


def _compile(args: argparse.Namespace, interrupt: DeferredInterrupt, task: Any, out: str, workers: int,
             claim: FolderClaim, say: Callable[[str], None], drawer: FigureDrawer | None = None) -> int:
    start_cpu = time.process_time()  # CPU since the process began: the imports, reading the task
    start = time.perf_counter()
    from hrc.compile.compiler import CompileOptions
    from hrc.compile.defaults import SAMPLE_MIN_PLANS
    from hrc.compile.estimate import estimate, fmt_bytes, fmt_span, kept_calibration
    from hrc.compile.stream import Sample
    from hrc.plans import allocation_count

    options = CompileOptions(human_waits=args.human_waits == "yes", rank_by=args.rank_by)
    resume = None
    if args.resume:
        from hrc.compile.resume import read_resume

        if not Path(out).is_dir():
            raise InputError(out, "--out", "--resume: no such output folder (nothing to resume)")
        resume = (Path(out), read_resume(Path(out), task, args.seed, options, args.stnu, args.symmetry,
                                         args.best_per_allocation))
    est = estimate(task, symmetry=args.symmetry)
    k = args.plans
    if k == "auto" and est.plans.value > args.max_plans:
        from hrc.compile.search import DEFAULT_K

        k = DEFAULT_K
        say(f"{task.name}: {est.plans} plans, more than --max-plans {args.max_plans:,}: searching for the best "
            f"{k} instead (--plans best:K; --plans all to refuse; docs/search.md)")
    if isinstance(k, int):
        if drawer is not None:  # the search compile writes its report without it
            drawer.close(at_once=True)
        return _search(args, interrupt, task, out, k, claim, say, options)
    if est.plans.value > args.max_plans:
        raise _refusal(args.task, est, args.max_plans, workers)
    interrupt.check()
    total = est.plans.value
    jobs = None if args.executor is not None else max(1, min(workers, total))  # no idle worker processes
    quiet = args.quiet
    lo, hi = est.wall(jobs or workers)
    kept = kept_calibration(task, args.seed) if args.executor is None else None
    if kept is not None:  # `hrc show TASK` sampled it on this machine: its estimate, not the rough range
        lo = hi = kept.wall(total, jobs or workers, args.stnu, report=not args.no_report)
    best = args.best_per_allocation
    keeping = "" if best is None else (f", keeping the best {best} of each of {allocation_count(task):,} allocations "
                                    "(all are compiled)")
    say(f"{task.name}: {est.plans} plans{keeping}; about {fmt_bytes(est.disk(args.stnu))} on disk (--stnu "
        f"{args.stnu}{', less what is not kept' * bool(keeping)}); {fmt_span(lo, hi)} on "
        f"{jobs or workers} worker{'s' * ((jobs or workers) > 1)}"
        + (" (hrc show's sample)" if kept is not None else " until measured" if total >= SAMPLE_MIN_PLANS else "")
        + ("" if resume is None else f"; resuming: {len(resume[1]):,} compiled already"))

    def on_estimate(sample: Sample) -> None:
        # between the pace with this process's caches filled (the same plans again: a long run's pace, or
        # faster) and the first time's (which pays for filling them: a short run's, or slower)
        first, again = sample.first_seconds_per_plan, sample.seconds_per_plan
        lo, hi = est.wall(jobs or workers, again)[0], est.wall(jobs or workers, first)[0]
        disk = fmt_bytes(sample.bytes_per_plan * total)
        say(f"{sample.plans} sample plans (from allocations across the task) took {first:.3f} s "
            f"each, {again:.3f} s the second time: {fmt_span(lo, hi, about=True)} for "
            f"all {total:,} at those paces, and {disk} on disk (plans differ a lot: the progress line's estimate "
            "follows the real pace)")

    progress = _Progress(tty=sys.stderr.isatty(), quiet=quiet)
    stages: list[tuple[str, float, float]] = [("the compiler's imports, the plan count", time.perf_counter() - start,
                                               time.process_time() - start_cpu)]
    t0 = time.perf_counter()
    c0 = time.process_time()
    from hrc.compile.stream import Abandoned, compile_stream

    # an earlier output is not replaced by a partial one (but the one resumed is: it holds fewer plans)
    earlier = Path(out).is_dir() and any(Path(out).iterdir()) and resume is None
    try:
        with claim.staging(check_earlier=_check_earlier(out)) as stage:
            try:
                result = compile_stream(task, stage, total, seed=args.seed, jobs=jobs, executor=args.executor,
                                        options=options, stnu=args.stnu, keep=args.report_top, progress=progress,
                                        estimate=on_estimate, symmetry=args.symmetry, best=best,
                                        resume=resume, keep_partial=not earlier, stop=interrupt.check,
                                        reuse=True)
            finally:
                progress.close()
            path_stats = result.plan_set.paths.stats
            path_wall = float(path_stats.get("seconds", 0.0))
            path_cpu = float(path_stats.get("cpu_seconds", 0.0))
            roadmaps, cached = int(path_stats.get("roadmaps", 0)), int(path_stats.get("cached", 0))
            apart = int(path_stats.get("apart", 0))
            beside = f", {apart} planned in a second process (its CPU with the workers')" if apart else ""
            stages += [(f"paths ({roadmaps} roadmap{'s' * (roadmaps != 1)}, {cached} from the cache{beside})",
                        path_wall, path_cpu),  # planned in this process
                       (f"plans ({result.compiled:,}, "
                        + ("from the cache of whole compiles" if result.cached else
                           f"{jobs or workers} worker{'s' * ((jobs or workers) > 1)}")
                        + ")", time.perf_counter() - t0 - path_wall - result.finish_seconds[0],
                        time.process_time() - c0 - path_cpu - result.finish_seconds[1]),
                       ("compiled.json, STNUs, the dispatch form in rank order", *result.finish_seconds)]
            # from here on a signal only is noted: the report and the swap are finished first (the output
            # is complete; throwing it away would lose every plan)
            if not args.no_report and not result.partial:
                from hrc.report import write_report

                t1, c1 = time.perf_counter(), time.process_time()
                write_report(result.plan_set, stage, _margin_compile(task, args.seed, jobs, args.executor, options),
                             drawer=drawer)
                stages.append(("report (figures, tables)", time.perf_counter() - t1, time.process_time() - c1))
    except Abandoned as kept:  # the staging folder is gone with nothing written into it
        print(f"error: interrupted after {kept.compiled:,} of {total:,} plans; the earlier output in {out} is kept "
              "(a partial output replaces only a new or empty folder)", file=sys.stderr)
        return 130
    cps = result.plan_set
    kept_text = None if best is None else f"the best {best} of each allocation, {cps.total:,} plans"
    if result.partial:
        wrote = "them" if kept_text is None else f"{kept_text},"
        print(f"error: interrupted after {result.compiled:,} of {total:,} plans: wrote {wrote} as a partial output "
              f"to {out} (\"partial\": true in compiled.json, no report); --resume goes on", file=sys.stderr)
        return 130
    if interrupt.requested:  # came after the last plan: the output was finished, and is complete
        print(f"error: interrupted ({interrupt.name}) once all {result.compiled:,} plans were compiled: finished "
              f"writing them; the output in {out} is complete", file=sys.stderr)
        return 130
    if not quiet:
        counts = cps.counts()
        print(f"compiled {result.compiled} plans of {task.name} in {time.perf_counter() - t0:.2f} s"
              + ("" if kept_text is None else f"; kept {kept_text}") + ": "
              + ", ".join(f"{n} {c}" for c, n in counts.items()))
        if cps.plans:
            best = cps.plans[0]
            ms = best.classification.makespan
            span = "" if ms is None else f", makespan {ms[0]:.1f}-{ms[1]:.1f} s"
            print(f"best plan {best.plan.id} ({best.plan_class.value}{span}): "
                  + "; ".join(f"{agent}: {' -> '.join(seq) or '-'}" for agent, seq in best.plan.sequences))
        stnu = {"graphml": f"{out}/stnu/ ({cps.total} GraphML)", "archive": f"{out}/stnu.zip",
                "none": "no STNU files"}[args.stnu]
        lines = f" (a row per plan), {out}/plans.jsonl" if (Path(out) / "plans.jsonl").is_file() else ""
        print(f"wrote {out}/compiled.json{lines}, {stnu}"
              + ("" if args.no_report else f", {out}/report.md, {out}/report.html"))
    if args.verbose:
        print(_times(start_cpu, stages), file=sys.stderr, flush=True)
    return 0



def _margin_compile(task: Any, seed: int, jobs: int | None, executor: str | None, options: Any) -> Any:
    """`task` compiled again with its fixed safety margin in place of its protective separation, for the
    report's cost of the separation per plan (None for a task without `safety:`: nothing to compare)."""
    if task.safety is None:
        return None
    from dataclasses import replace

    from hrc.compile.compiler import compile_task

    return compile_task(replace(task, safety=None), seed=seed, jobs=jobs, executor=executor, options=options)
