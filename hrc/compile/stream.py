"""Streaming compile (issue 12): plans flow from generation through motion, STNU and classification to
disk, and the memory held does not grow with the plans' full records.

`compile_task` keeps every `CompiledPlan` (about 50 KB each) until it ranks them; this module is how
``hrc compile`` runs instead. Each plan is compiled in an executor (`compile_records`, which also
encodes its ``compiled.json`` line there, in parallel); the parent process hands it to a `PlanSink`,
which

- appends the plan's line to a spool file and its STNU to ``stnu/`` (or to a spool for ``stnu.zip``);
  or, from a worker process on this machine, which wrote them itself (`hrc.compile.spool`), notes where,
- keeps its rank key as a compact record, and the full `CompiledPlan` only for the plans the report
  shows; workers send it only for a plan that beats the bar of the moment (`compact_records`,
  `PlanSink.bar`), the rest as a few strings,

and at the end writes ``compiled.json`` in rank order (`hrc.compile.sink`). The bytes are those
`write_compiled` writes for the same set (tested on the workshop). Where things live: this module is the
orchestration; `hrc.compile.sink` the ranking records and the final files; `hrc.compile.spool` the
low-level file writing; `hrc.compile.resume` the partial output's resume format.

An interrupted run still leaves a valid output: the plans compiled so far, ranked among themselves,
with ``"partial": true`` in ``compiled.json``, and only their STNU files. The interrupt is a
KeyboardInterrupt raised by the caller's `stop` callback, which `compile_stream` calls only where
stopping is safe (between units of work, at least twice a second while it waits for a local pool's
workers, between path plans; `hrc.cli.interrupt` says why); from then on, writing the partial output is
not interrupted again.
"""

from __future__ import annotations

import functools
import itertools
import math
import time
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from hrc.compile.compiler import CompiledPlan, CompiledPlanSet, CompileOptions, compile_family, rank_key
from hrc.compile.defaults import SAMPLE_MIN_PLANS
from hrc.compile.dispatch_form import FORM_FOLDER
from hrc.compile.executors import make_executor, run_apart
from hrc.compile.lean_import import import_lean
from hrc.compile.output import STNU_ARCHIVE, line_head, plan_line, write_input
from hrc.compile.resume import RESUME_FILE
from hrc.compile.sink import REPORT_TOP, Bar, PlanSink, Record
from hrc.compile.spool import WorkerFiles, Written
from hrc.errors import HrcError
from hrc.model import Plan, Task
from hrc.motion import PathLibrary, plan_paths
from hrc.plans import (
    allocation_key,
    generate_plans,
    identical_actions,
    plan_code,
    plan_families,
    spread_families,
    symmetry_factor,
)

__all__ = ["FORKED_IMPORTS", "OUTPUT_FILES", "RESULTS_MAX_PLANS", "SAMPLE_MIN_PLANS", "Abandoned", "Sample",
           "StreamResult", "chunk_size", "compact_records", "compile_records", "compile_stream", "sample_twice"]

OUTPUT_FILES = ("compiled.json", "input", "stnu", STNU_ARCHIVE, RESUME_FILE, FORM_FOLDER)
"""Every name `compile_stream` may write into an output folder (``hrc compile`` adds the report's,
`hrc.report.REPORT_FILES`). ``hrc compile`` replaces an output folder whole, so it refuses one that holds
anything else (files it did not write would be lost): a file the compile comes to write must be named
here, or the next compile into the same folder refuses it (tests/test_compile_faults.py checks each mode's
files against this list)."""

Progress = Callable[[str, int, int], None]  # (stage, done, total)

RESULTS_MAX_PLANS = 512
"""A compile of at most this many plans keeps all its plans (their records and lines) in the disk cache
(`hrc.caches.cache_folder` ``results``; about 50 kB a plan), keyed by everything they are computed from
(`_results_key`): compiling the same task again (the report's figures and text changed, the output
folder lost, a colleague's checkout of the same code) takes the plans from there and writes the same
bytes, without planning a motion or starting a worker (issue 38: the workshop in about a second).
Larger compiles are not kept: a file per compile of hundreds of MB would cost more to write than a
repeated compile saves."""

FORKED_IMPORTS = ("scipy.sparse.csgraph", "scipy.ndimage", "scipy.spatial", "ompl.geometric", "hrc.apa.plan")
"""What planning the paths and compiling a plan import on first use (a roadmap's Dijkstra, the conflicts'
labelling and k-d tree, the roadmap planner, the preferences' QP: kept out of the start-up, so that a
compile taken from the cache never pays them; about 0.5 s of CPU in all). A compile on a local pool
imports them once before it forks (`_compile_into`): the second roadmap's process and every worker
inherit them, where each imported them again before (issue 38: 0.25-0.3 s of CPU per process)."""


def compile_records(options: CompileOptions, stnu: str, task: Task, paths: PathLibrary,
                    families: list[tuple[Plan, ...]]) -> list[tuple[CompiledPlan, str]]:
    """The executor's unit of work: whole families of plans (`hrc.plans.plan_families`, one motion
    search each, `compile_family`), each plan with its ``compiled.json`` line after ``"rank":``
    (`plan_line`, encoded where the plan was compiled, so that the parent only copies bytes)."""
    return [(cp, _line_tail(task, cp, stnu)) for cp in _compiled(options, stnu, task, paths, families)]


def _compiled(options: CompileOptions, stnu: str, task: Task, paths: PathLibrary,
              families: list[tuple[Plan, ...]]) -> list[CompiledPlan]:
    return [cp for family in families for cp in compile_family(task, family, paths, options, stnu != "none")]


def _line_tail(task: Task, cp: CompiledPlan, stnu: str) -> str:
    """`cp`'s ``compiled.json`` line after ``"rank":`` (`plan_line`)."""
    text = plan_line(task, cp, stnu)
    head = line_head(cp.plan.id, 0)
    if not text.startswith(head):  # pragma: no cover - plan_dict puts id and rank first
        raise HrcError(f"internal: plan {cp.plan.id}'s line does not start with its id and rank")
    return text[len(head):]


def compact_records(options: CompileOptions, stnu: str, task: Task, paths: PathLibrary,
                    work: tuple[Bar, list[tuple[Plan, ...]]], folder: str | None = None,
                    stnu_to: str = "files") -> list[Record]:
    """`compile_records` as the parent needs it (`PlanSink.add_record`): each plan's rank key, id, class,
    GraphML and line tail, and the full record (without its GraphML) only when the plan beats `bar`,
    the parent's `PlanSink.bar` when it sent the work: the keep-th best key so far, or the best of the
    plan's class, unless it cannot be kept at all (with `PlanSink.best`: `best` plans of its allocation
    beat it). Bars only ever fall, so every plan that ends among the kept ones is sent in full; the
    rest (most of a large task) cross the process boundary as a few strings instead of thousands of
    small objects (pickling full records was a quarter of kitting_7picks' CPU time).

    With `folder` (the output folder, for a worker on the parent's machine: `WorkerFiles`), the worker
    writes the texts there itself and sends where they are: 56 kB per kitting_7picks plan no longer cross
    a pipe twice and pass through the parent, whose CPU the workers share. `stnu_to` (`PlanSink.stnu_to`)
    says where a GraphML goes then: its file in ``stnu/``, a spool, or nowhere.

    A plan that cannot be kept at all gets neither line nor GraphML nor dispatch form record (empty texts:
    never written out)."""
    (top, best, among), families = work
    out: list[Record] = []
    compiled = _compiled(options, stnu, task, paths, families)
    keys = [rank_key(cp, options.rank_by) for cp in compiled]
    kept = [not among or (beat := among.get(allocation_key(task, cp.plan))) is None or key < beat
            for cp, key in zip(compiled, keys, strict=True)]
    texts = [(_line_tail(task, cp, stnu), cp.graphml) if k else ("", "") for cp, k in zip(compiled, kept, strict=True)]
    tails: Sequence[str | Written] = [tail for tail, _ in texts]
    graphml: Sequence[str | Written | None] = [text for _, text in texts]
    if folder is not None:
        files = WorkerFiles.of(folder, stnu_to)
        tails, graphml = files.lines([tail for tail, _ in texts]), files.stnus(compiled, [t for _, t in texts])
    for cp, key, k, text, tail in zip(compiled, keys, kept, graphml, tails, strict=True):
        cls = cp.plan_class.value
        full = k and ((top is None or key < top) or cls not in best or key < best[cls])
        out.append((key, cp.plan.id, cls, text, tail, replace(cp, graphml="", form=b"") if full else None,
                    plan_code(task, cp.plan), cp.form if k else b""))
    return out


def chunk_size(total: int, jobs: int) -> int:
    """Plans per unit of work: at least 8 units per worker, at most 16 plans (a plan takes 10-300 ms, so
    a unit stays under a few seconds: progress stays live and an interrupt loses little)."""
    return max(1, min(16, total // (8 * max(1, jobs))))


class Abandoned(Exception):
    """An interrupted `compile_stream` that was not to keep a partial output: nothing was written;
    `compiled` plans had been compiled."""

    def __init__(self, compiled: int) -> None:
        super().__init__(compiled)
        self.compiled = compiled


@dataclass(frozen=True, slots=True)
class StreamResult:
    """What `compile_stream` did: the report's view of the set (the plans kept: with `best`, fewer than
    compiled), the plans compiled, and whether the run was interrupted (``compiled.json`` then says
    ``"partial": true``)."""

    plan_set: CompiledPlanSet
    compiled: int
    partial: bool
    seconds_per_plan: float | None  # the estimate's sample plans, the second time (`Sample`), in this process
    cached: bool = False  # every plan came from the disk cache of whole compiles (`RESULTS_MAX_PLANS`)
    finish_seconds: tuple[float, float] = (0.0, 0.0)
    """Wall and CPU seconds (this process's) of writing the outputs in rank order once every plan was in
    (`PlanSink.finish`): ``hrc compile -v`` tells them apart from the plans'."""


@dataclass(frozen=True, slots=True)
class Sample:
    """What the plans compiled for the up-front estimate cost: wall seconds per plan in this process,
    compiled a second time (`seconds_per_plan`) and the first time (`first_seconds_per_plan`), and bytes
    per plan on disk for the run's ``--stnu`` mode (its ``compiled.json`` line and its STNU).

    The first time pays for what a process computes once and keeps (detour routes, the geometry of
    conflicts, text layouts): 3 to 6 times the second on the bundled tasks. A large compile pays that
    once per worker, so the second time is the pace of a long run (kitting_7picks: 3.9 ms per plan the
    second time, 17.5 ms the first, about 4 ms of CPU per plan over the whole run)."""

    families: int  # the first this many of the sample's families were compiled
    plans: int
    seconds_per_plan: float
    first_seconds_per_plan: float
    bytes_per_plan: float


def sample_twice(options: CompileOptions, stnu: str, task: Task, paths: PathLibrary,
                 families: Sequence[tuple[Plan, ...]], budget: float, most: float,
                 each: Callable[[CompiledPlan, str], None], clock: Callable[[], float] = time.perf_counter,
                 again: int = 1) -> tuple[int, int, float, float]:
    """Compile `families` here in order, each plan and its line tail to `each`, until `budget` seconds of
    `clock` pass or `most` plans are compiled (at least one family); then the same families again, with
    this process's caches filled (`again` times: the least of those times, the one the least disturbed by
    other work on the machine). Returns the families and plans compiled, and the seconds the first time
    and the second (the up-front estimate's `_sample`; ``hrc show``'s `hrc.compile.estimate.calibrate`)."""
    t0 = clock()
    n = done = 0
    for family in families:
        for cp, tail in compile_records(options, stnu, task, paths, [family]):
            each(cp, tail)
        n += len(family)
        done += 1
        if clock() - t0 >= budget or n >= most:
            break
    first = clock() - t0
    second = math.inf
    for _ in range(max(1, again)):
        t1 = clock()
        compile_records(options, stnu, task, paths, list(families[:done]))  # again, with the caches filled
        second = min(second, clock() - t1)
    return done, n, first, second


def _sample(task: Task, paths: PathLibrary, families: list[tuple[Plan, ...]], options: CompileOptions,
            stnu: str, sink: PlanSink, budget: float, taken: frozenset[str] = frozenset(), most: int = 16,
            kept: list[tuple[CompiledPlan, str]] | None = None) -> Sample:
    """Compile sample families here until `budget` seconds pass (at least one family, at most `most` plans),
    then the same again (`Sample`): the time and disk per plan for the up-front estimate; the first
    time's plans are kept, not wasted (but for those the sink has `taken` already), and appended to `kept`."""
    size = 0.0

    def each(cp: CompiledPlan, tail: str) -> None:
        nonlocal size
        if cp.plan.id not in taken:
            sink.add(cp, tail)
        if kept is not None:
            kept.append((cp, tail))
        size += len(tail.encode()) + 32
        if stnu == "graphml":
            size += -(-len(cp.graphml.encode()) // 4096) * 4096
        elif stnu == "archive":
            size += len(zlib.compress(cp.graphml.encode(), 1))

    done, n, first, second = sample_twice(options, stnu, task, paths, families, budget, most, each)
    return Sample(done, n, second / max(n, 1), first / max(n, 1), size / max(n, 1))


def _results_key(task: Task, seed: int, options: CompileOptions, stnu: str, symmetry: bool) -> str:
    """The disk cache key of a whole compile's plans: the task and its map as loaded (`task_digest`), the
    motion planner's seed, the options, the STNU mode (the lines name the files), the families compiled
    (`symmetry`) and all of the code (`code_digest`: any change of hrc or a library is a miss)."""
    from hrc.caches import code_digest
    from hrc.io.task_file import task_digest

    return repr(("results-1", code_digest(), task_digest(task), seed, options.human_waits, options.rank_by, stnu,
                 symmetry))


def compile_stream(task: Task, out_dir: Path, total: int, *, seed: int = 0, jobs: int | None = None,
                   executor: str | None = None, options: CompileOptions | None = None,
                   stnu: str = "graphml", keep: int = REPORT_TOP, progress: Progress | None = None,
                   estimate: Callable[[Sample], None] | None = None, sample_seconds: float = 1.0,
                   symmetry: bool = False, best: int | None = None,
                   resume: tuple[Path, np.ndarray] | None = None, keep_partial: bool = True,
                   stop: Callable[[], None] | None = None, reuse: bool = False,
                   sample_min: int = SAMPLE_MIN_PLANS) -> StreamResult:
    """Compile every plan of `task` into `out_dir` (a staging folder: ``input/``, ``compiled.json``,
    the STNUs). `total`: the plan count (or its bound) for progress. `estimate` is called once with the
    seconds per plan measured on the first plans (compiled here for `sample_seconds`), before the rest
    goes to the executor; never for a `total` under `sample_min` (`SAMPLE_MIN_PLANS`: no sample is
    taken). Interrupted (KeyboardInterrupt) after some plans: a partial output; before
    any: re-raised. `symmetry`: one plan per class of plans that differ only by swapping identical actions
    (`hrc.plans.identical_actions`; ``compiled.json`` names the groups). `best`: keep only the best this
    many plans of each allocation (all are compiled; the others are not written, ranked or reported).
    `resume`: an interrupted run's output folder and its `read_resume` rows: its plans are taken as they
    are and not compiled again (the output is the same as a run never interrupted). `keep_partial`:
    whether an interrupted run writes what it compiled (else it raises `Abandoned` at once: the caller
    keeps an earlier output instead, and writing a large partial one would take a while for nothing).
    `stop`: called where the compile may stop (module docstring); it raises KeyboardInterrupt to stop it.
    `reuse` (``hrc compile``): a small compile on this machine is taken whole from the disk cache when
    the same was compiled before, and kept there otherwise (`RESULTS_MAX_PLANS`).
    Raises `hrc.errors.HrcError`."""
    options = options or CompileOptions()
    out_dir = Path(out_dir)
    write_input(task, out_dir)
    sink = PlanSink(task, out_dir, stnu, keep, options.rank_by,
                    identical_actions(task) if symmetry else (), best)
    taken: frozenset[str] = frozenset()
    if resume is not None:
        try:
            taken = sink.restore(*resume)
        except BaseException:
            sink.abandon()
            raise
    per_plan: float | None = None
    partial = False
    check = stop or (lambda: None)
    # a small compile on this machine is kept whole on disk (`RESULTS_MAX_PLANS`): taken from there when
    # the same task is compiled again with the same code, else its plans are kept as they come
    from hrc.caches import cache_folder, disk_load, disk_store

    results = cache_folder("results") if (reuse and executor is None and resume is None
                                          and total <= RESULTS_MAX_PLANS) else None
    rkey = _results_key(task, seed, options, stnu, symmetry) if results is not None else ""
    found = disk_load(results, rkey)
    kept: list[tuple[CompiledPlan, str]] | None = None if results is None else []
    planned: list[PathLibrary] = []  # the paths, once planned (an interrupt may come after them)
    try:
        if isinstance(found, list):
            planned.append(plan_paths(task, seed=seed))
            check()
            for cp, tail in found:
                sink.add(cp, tail)
                check()  # as between the units of work of a compile (an interrupt: a partial output)
            if progress:
                progress("plans", len(sink), total)
        else:
            per_plan = _compile_into(task, sink, total, seed, jobs, executor, options, stnu, progress, estimate,
                                     sample_seconds if total >= sample_min else None, symmetry, taken, check,
                                     kept, planned)
    except KeyboardInterrupt:
        if not planned or not len(sink):
            sink.abandon()
            raise
        if not keep_partial:
            sink.abandon()
            raise Abandoned(len(sink)) from None
        partial = True
        if progress:  # writing them takes a while for a large run (a 1.5 GB compiled.json, an archive): say so
            progress("stopping", len(sink), total)
    except BaseException:
        sink.abandon()
        raise
    compiled = len(sink)
    paths = planned[0]
    w0, c0 = time.perf_counter(), time.process_time()
    plan_set = sink.finish(seed, paths, options, partial=total if partial else None)
    finish = (time.perf_counter() - w0, time.process_time() - c0)
    if kept is not None and not partial and not isinstance(found, list):
        disk_store(results, rkey, kept)
    return StreamResult(plan_set=plan_set, compiled=compiled, partial=partial, seconds_per_plan=per_plan,
                        cached=isinstance(found, list), finish_seconds=finish)


def _compile_into(task: Task, sink: PlanSink, total: int, seed: int, jobs: int | None, executor: str | None,
                  options: CompileOptions, stnu: str, progress: Progress | None,
                  estimate: Callable[[Sample], None] | None, sample_seconds: float | None, symmetry: bool,
                  taken: frozenset[str], check: Callable[[], None],
                  kept: list[tuple[CompiledPlan, str]] | None, planned: list[PathLibrary]) -> float | None:
    """`compile_stream`'s compile: the paths (appended to `planned` at once), the estimate's sample (none
    if `sample_seconds` is None), then the rest over the executor, every plan into `sink`; returns the
    sample's seconds per plan (None without one). With
    `kept` (a compile to keep whole on disk), each plan's full record and line tail is also appended to
    it (the workers then send them whole: a small compile's few MB)."""
    with make_executor(executor, jobs) as ex:  # first, so a bad executor fails before any planning
        def motion(done: int, total: int) -> None:
            check()
            if progress:
                progress("motion", done, total)

        # a local pool's second core plans every other roadmap meanwhile (no threads here yet: a fork is safe)
        apart = run_apart if getattr(ex, "local_processes", False) else None
        if apart is not None:  # imported once here, before the forks, rather than in each forked process
            import_lean(FORKED_IMPORTS)  # without scipy's docstring notes: 0.2-0.3 s of CPU less
        paths = plan_paths(task, seed=seed, progress=motion, apart=apart)
        planned.append(paths)
        check()
        sample: Sample | None = None
        done: set[Plan] = set()
        if sample_seconds is not None:
            # the estimate's sample comes from allocations spread over the whole space (the stream's first
            # plans are all of one corner: the human doing everything), and is left out of the stream
            spread = spread_families(task, 16, symmetry)
            # at most a quarter of a small compile: this process compiles the sample alone (twice), while
            # the workers wait
            sample = _sample(task, paths, spread, options, stnu, sink, sample_seconds, taken,
                             most=max(1, min(16, total // 4)), kept=kept)
            done = {f[0] for f in spread[:sample.families]}
            check()
            if estimate is not None:
                estimate(sample)
        stream = (((plan,) for plan in generate_plans(task, symmetry=True)) if symmetry
                  else plan_families(task))
        # a family the interrupted run took in part (interrupted between its plans) is compiled
        # again, and only its missing plans are taken
        stream = (f for f in stream if f[0] not in done and not (taken and all(p.id in taken for p in f)))
        if progress:
            progress("plans", len(sink), total)
        family = 1 if symmetry else symmetry_factor(task)
        size = max(1, chunk_size(max(total - len(sink), 1), getattr(ex, "jobs", 2)) // family)
        chunks = iter(lambda: list(itertools.islice(stream, size)), [])
        if kept is not None:  # whole records, to keep (`RESULTS_MAX_PLANS`)
            whole = functools.partial(_whole_records, options, stnu)
            for batch in ex.map_chunks(whole, task, paths, ((None, chunk) for chunk in chunks), poll=check):
                for cp, tail in batch:
                    if cp.plan.id not in taken:
                        sink.add(cp, tail)
                    kept.append((cp, tail))
                if progress:
                    progress("plans", len(sink), total)
                check()
            return None if sample is None else sample.seconds_per_plan
        # workers on this machine write their plans' texts into the folder themselves
        folder = str(sink.out_dir) if getattr(ex, "local_processes", False) else None
        work = functools.partial(_records_with, options, stnu, folder, sink.stnu_to)
        bars = ((sink.bar(chunk), chunk) for chunk in chunks)
        for batch in ex.map_chunks(work, task, paths, bars, poll=check):
            for record in batch:
                if record[1] not in taken:
                    sink.add_record(record)
            if progress:
                progress("plans", len(sink), total)
            check()
    return None if sample is None else sample.seconds_per_plan


def _whole_records(options: CompileOptions, stnu: str, task: Task, paths: PathLibrary,
                   work: tuple[None, list[tuple[Plan, ...]]]) -> list[tuple[CompiledPlan, str]]:
    return compile_records(options, stnu, task, paths, work[1])


def _records_with(options: CompileOptions, stnu: str, folder: str | None, stnu_to: str, task: Task,
                  paths: PathLibrary, work: tuple[Bar, list[tuple[Plan, ...]]]) -> list[Record]:
    return compact_records(options, stnu, task, paths, work, folder, stnu_to)
