"""Streaming compile (issue 12): plans flow from generation through motion, STNU and classification to
disk, and the memory held does not grow with the plans' full records.

`compile_task` keeps every `CompiledPlan` (about 50 KB each) until it ranks them; this module is how
``hrc compile`` runs instead. Each plan is compiled in an executor (`compile_records`, which also
encodes its ``compiled.json`` line there, in parallel); the parent process hands it to a `PlanSink`,
which

- appends the plan's line to a spool file and its STNU to ``stnu/`` (or to a spool for ``stnu.zip``),
- keeps its rank key as a compact record (eight numbers and the id, about 100 bytes per plan, in
  typed arrays: 36 MB for 362,880 plans),
- keeps the full `CompiledPlan` only for the `keep` best plans and the best plan of each class (what
  the report shows); workers send it only for a plan that beats the bar of the moment
  (`compact_records`, `PlanSink.bar`), the rest as a few strings,

and at the end sorts the compact records by `rank_key` (the same total order as `compile_task`, so the
same ranks) and writes ``compiled.json`` in rank order, one line per plan, straight from the spool. The
bytes are those `write_compiled` writes for the same set (tested on the workshop).

An interrupted run (SIGINT, or SIGTERM which the CLI turns into the same) still leaves a valid output:
the plans compiled so far, ranked among themselves, with ``"partial": true`` in ``compiled.json``.
"""

from __future__ import annotations

import contextlib
import functools
import itertools
import json
import os
import time
import zipfile
import zlib
from array import array
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import IO

import numpy as np

from hrc.compile.classify import PlanClass
from hrc.compile.compiler import (
    ClassStats,
    CompiledPlan,
    CompiledPlanSet,
    CompileOptions,
    PlanSetSummary,
    compile_family,
    rank_key,
    task_digest,
)
from hrc.compile.executors import make_executor
from hrc.compile.output import (
    JSON_TAIL,
    STNU_ARCHIVE,
    STNU_MODES,
    header_dict,
    json_head,
    plan_line,
    write_input,
)
from hrc.errors import HrcError
from hrc.model import Plan, Task
from hrc.motion import PathLibrary, plan_paths
from hrc.plans import generate_plans, identical_actions, plan_families, spread_families, symmetry_factor

__all__ = ["HISTOGRAM_BINS", "REPORT_TOP", "PlanSink", "Sample", "StreamResult", "chunk_size", "compact_records",
           "compile_records", "compile_stream"]

REPORT_TOP = 100
"""Plans the report's ranked table shows by default (plus the best of each class)."""

HISTOGRAM_BINS = 24
"""Bins of the worst-case makespan histogram over all plans."""

Progress = Callable[[str, int, int], None]  # (stage, done, total)
_KEY_COLUMNS = ("cls", "second", "pref", "first", "worst", "early", "idle")  # rank_key without the id


def compile_records(options: CompileOptions, stnu: str, task: Task, paths: PathLibrary,
                    families: list[tuple[Plan, ...]]) -> list[tuple[CompiledPlan, str]]:
    """The executor's unit of work: whole families of plans (`hrc.plans.plan_families`, one motion
    search each, `compile_family`), each plan with its ``compiled.json`` line after ``"rank":``
    (`plan_line`, encoded where the plan was compiled, so that the parent only copies bytes)."""
    out = []
    for cp in (cp for family in families for cp in compile_family(task, family, paths, options, stnu != "none")):
        text = plan_line(task, cp, stnu)
        head = _line_head(cp.plan.id, 0)
        if not text.startswith(head):  # pragma: no cover - plan_dict puts id and rank first
            raise HrcError(f"internal: plan {cp.plan.id}'s line does not start with its id and rank")
        out.append((cp, text[len(head):]))
    return out


Bar = tuple[tuple | None, dict[str, tuple]]  # the keep-th best rank key so far, the best key per class
Record = tuple[tuple, str, str, str, str, CompiledPlan | None]  # key, id, class, GraphML, line tail, full?


def compact_records(options: CompileOptions, stnu: str, task: Task, paths: PathLibrary,
                    work: tuple[Bar, list[tuple[Plan, ...]]]) -> list[Record]:
    """`compile_records` as the parent needs it (`PlanSink.add_record`): each plan's rank key, id, class,
    GraphML and line tail, and the full record (without its GraphML) only when the plan beats `bar`,
    the parent's `PlanSink.bar` when it sent the work: the keep-th best key so far, or the best of the
    plan's class. Bars only ever fall, so every plan that ends among the kept ones is sent in full; the
    rest (most of a large task) cross the process boundary as a few strings instead of thousands of
    small objects (pickling full records was a quarter of kitting_7picks' CPU time)."""
    (top, best), families = work
    out: list[Record] = []
    for cp, tail in compile_records(options, stnu, task, paths, families):
        key = rank_key(cp, options.rank_by)
        cls = cp.plan_class.value
        full = (top is None or key < top) or cls not in best or key < best[cls]
        out.append((key, cp.plan.id, cls, cp.graphml, tail, replace(cp, graphml="") if full else None))
    return out


def _line_head(plan_id: str, rank: int) -> str:
    return f'{{"id":{json.dumps(plan_id)},"rank":{rank},'


def chunk_size(total: int, jobs: int) -> int:
    """Plans per unit of work: at least 8 units per worker, at most 16 plans (a plan takes 10-300 ms, so
    a unit stays under a few seconds: progress stays live and an interrupt loses little)."""
    return max(1, min(16, total // (8 * max(1, jobs))))


class PlanSink:
    """Where compiled plans go, in any order: spooled to `out_dir`, a compact rank record each, the full
    record only for the `keep` best and the best of each class. A mutable builder (see the module
    docstring); `finish` writes ``compiled.json`` and returns what the report needs."""

    def __init__(self, task: Task, out_dir: Path, stnu: str = "graphml", keep: int = REPORT_TOP,
                 rank_by: str = "worst", symmetric: tuple[tuple[str, ...], ...] = ()) -> None:
        if stnu not in STNU_MODES:
            raise ValueError(f"stnu must be one of {STNU_MODES}, got {stnu!r}")
        self.task, self.out_dir, self.stnu, self.keep, self.rank_by = task, Path(out_dir), stnu, keep, rank_by
        self.symmetric = symmetric
        self._lines: IO[bytes] = open(self.out_dir / ".plans.spool", "w+b")  # noqa: SIM115 - closed in finish
        self._graphml: IO[bytes] | None = None
        self._stnu_dir: int | None = None
        if stnu == "graphml":
            (self.out_dir / "stnu").mkdir(exist_ok=True)
            # files opened relative to the folder: no path to build and resolve per plan (40,320 of them)
            if os.open in os.supports_dir_fd:
                self._stnu_dir = os.open(self.out_dir / "stnu", os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
        elif stnu == "archive":
            self._graphml = open(self.out_dir / ".stnu.spool", "w+b")  # noqa: SIM115
        self._cols = {name: array("d") for name in _KEY_COLUMNS}
        self._ids = bytearray()  # 16 bytes per plan: its id, padded with spaces
        self._line_at, self._graphml_at = array("q"), array("q")
        self._held: list[tuple[tuple, int, CompiledPlan]] = []
        self._best: dict[str, tuple[tuple, int, CompiledPlan]] = {}

    def __len__(self) -> int:
        return len(self._line_at)

    def add(self, cp: CompiledPlan, tail: str) -> None:
        """Take one compiled plan and its line tail (`compile_records`)."""
        self.add_record((rank_key(cp, self.rank_by), cp.plan.id, cp.plan_class.value, cp.graphml, tail,
                         replace(cp, graphml="")))

    def bar(self) -> Bar:
        """What a plan must beat to be kept in full (`compact_records`): the keep-th best key so far (None
        while fewer are held), and the best key of each class so far."""
        top = None
        if len(self._held) >= self.keep:
            self._trim()
            top = self._held[-1][0]
        return top, {cls: b[0] for cls, b in self._best.items()}

    def _trim(self) -> None:
        """Keep only the `keep` best held plans, best first."""
        self._held.sort(key=lambda h: h[0])
        del self._held[self.keep:]

    def add_record(self, record: Record) -> None:
        """Take one plan as `compact_records` sends it (its full record only if it beat the bar)."""
        key, pid, cls, graphml, tail, light = record
        i = len(self)
        self._line_at.append(self._lines.tell())
        self._lines.write(tail.encode("utf-8") + b"\n")
        data = graphml.encode("utf-8")
        if self.stnu == "graphml":
            name = f"{pid}.graphml"
            _write_at(self._stnu_dir, name if self._stnu_dir is not None else str(self.out_dir / "stnu" / name), data)
        elif self._graphml is not None:
            self._graphml_at.append(self._graphml.tell())
            self._graphml.write(data)
        for name, value in zip(_KEY_COLUMNS, key[:-1], strict=True):
            self._cols[name].append(float(value))
        self._ids += pid.encode("ascii").ljust(16, b" ")[:16]
        if light is None:  # below both bars when it was sent: it cannot be among the kept
            return
        self._held.append((key, i, light))
        if len(self._held) >= 2 * self.keep + 16:
            self._trim()
        if cls not in self._best or key < self._best[cls][0]:
            self._best[cls] = (key, i, light)

    def _order(self) -> np.ndarray:
        """Plan indices in rank order (`rank_key`'s total order: its columns, then the id)."""
        ids = np.frombuffer(bytes(self._ids), dtype="S16")
        cols = [np.frombuffer(self._cols[name], dtype=np.float64) for name in _KEY_COLUMNS]
        return np.lexsort([ids, *reversed(cols)])

    def _head_of(self, i: int, rank: int) -> bytes:
        """Plan `i`'s ``compiled.json`` line up to its rank (the rest is its tail in the spool; not read
        through a memory map, whose pages would count as the process's memory)."""
        pid = self._ids[16 * i:16 * i + 16].rstrip(b" ").decode("ascii")
        return _line_head(pid, rank).encode("utf-8")

    def finish(self, seed: int, paths: PathLibrary, options: CompileOptions,
               partial: int | None = None) -> CompiledPlanSet:
        """Write ``compiled.json`` (and ``stnu.zip``) in rank order; remove the spools. `partial`: the
        number of plans expected when the run was interrupted. Returns the best plans with their ranks
        and a `PlanSetSummary` of all (for the report)."""
        order = self._order()
        n = len(order)
        rank = np.empty(n, dtype=np.int64)
        rank[order] = np.arange(1, n + 1)
        cls_col = np.frombuffer(self._cols["cls"], dtype=np.float64)
        counts = {c.value: int(np.count_nonzero(cls_col == c.order)) for c in PlanClass}
        digest = task_digest(self.task)
        header = header_dict(self.task, seed, digest, options, counts, self.stnu,
                             None if partial is None else (n, partial), self.symmetric)
        # the archive (deflating, which frees the GIL) in a thread while compiled.json is copied: two
        # files from two spools, so a second core shortens the end of a large compile
        with ThreadPoolExecutor(max_workers=1) as pool:
            archive = pool.submit(self._write_archive, order) if self._graphml is not None else None
            self._lines.flush()
            size = self._lines.tell()
            ends = np.append(np.frombuffer(self._line_at, dtype=np.int64)[1:], size) - 1  # before each "\n"
            with open(self.out_dir / "compiled.json", "wb") as out:
                out.write(json_head(header).encode("utf-8"))
                copy = _kernel_copy if hasattr(os, "copy_file_range") else None
                for k, i in enumerate(order):
                    head = (b",\n" if k else b"") + self._head_of(int(i), k + 1)
                    start = self._line_at[int(i)]
                    size = int(ends[i]) - start
                    if copy is not None:  # the line's tail copied from spool to file in the kernel
                        out.write(head)
                        out.flush()
                        if copy(self._lines.fileno(), out.fileno(), size, start):
                            continue
                        copy = None  # not on this file system: read and write from here on
                        out.seek(0, os.SEEK_END)
                    else:
                        out.write(head)
                    out.write(os.pread(self._lines.fileno(), size, start))
                out.write(JSON_TAIL.encode("utf-8"))
            if archive is not None:
                archive.result()
        self._close()
        self._trim()
        chosen = {h[1]: h[2] for h in self._held}
        chosen.update({i: cp for _, i, cp in self._best.values()})
        plans = tuple(sorted((replace(cp, rank=int(rank[i])) for i, cp in chosen.items()), key=lambda cp: cp.rank))
        return CompiledPlanSet(task=self.task, seed=seed, digest=digest, paths=paths, plans=plans, options=options,
                               summary=self._summary(counts, n), stnu_files=self.stnu)

    def _write_archive(self, order: np.ndarray) -> None:
        """``stnu.zip``: the GraphML files in rank order, deflated, with fixed dates (deterministic bytes).

        Deflate level 1: this runs after the last plan (beside the copy of ``compiled.json``), and level 1
        deflates kitting_7picks' GraphML (40,320 files, 1.25 GB) in about 6 s where the default level
        took 17 s, for an archive about a quarter larger (135 MB)."""
        assert self._graphml is not None
        ends = np.append(np.frombuffer(self._graphml_at, dtype=np.int64), self._graphml.tell())
        with zipfile.ZipFile(self.out_dir / STNU_ARCHIVE, "w", zipfile.ZIP_DEFLATED) as zf:
            for i in order:
                pid = self._ids[16 * i:16 * i + 16].rstrip(b" ").decode("ascii")
                self._graphml.seek(int(ends[i]))
                data = self._graphml.read(int(ends[i + 1] - ends[i]))
                info = zipfile.ZipInfo(f"stnu/{pid}.graphml", date_time=(1980, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = 0o644 << 16
                zf.writestr(info, data, compresslevel=1)

    def _close(self) -> None:
        if self._stnu_dir is not None:
            os.close(self._stnu_dir)
            self._stnu_dir = None
        for fh, name in ((self._lines, ".plans.spool"), (self._graphml, ".stnu.spool")):
            if fh is not None:
                fh.close()
                with contextlib.suppress(FileNotFoundError):
                    (self.out_dir / name).unlink()

    def abandon(self) -> None:
        """Close and remove the spools (the caller removes the folder)."""
        self._close()

    def _summary(self, counts: dict[str, int], n: int) -> PlanSetSummary:
        cls = np.frombuffer(self._cols["cls"], dtype=np.float64)
        worst = np.frombuffer(self._cols["worst"], dtype=np.float64)
        early = np.frombuffer(self._cols["early"], dtype=np.float64)
        timed = np.isfinite(worst)
        edges = (np.histogram_bin_edges(worst[timed], bins=HISTOGRAM_BINS) if timed.any()
                 else np.array([0.0, 1.0]))
        stats = []
        for c in PlanClass:
            mine = cls == c.order
            ok = mine & timed
            q = (0, 25, 50, 75, 100)
            stats.append(ClassStats(
                plan_class=c.value, plans=int(mine.sum()), no_schedule=int((mine & ~timed).sum()),
                earliest=tuple(round(float(x), 3) for x in np.percentile(early[ok], q)) if ok.any() else None,
                worst=tuple(round(float(x), 3) for x in np.percentile(worst[ok], q)) if ok.any() else None,
                histogram=tuple(int(x) for x in np.histogram(worst[ok], bins=edges)[0])))
        slowest = None
        if np.isfinite(early).any():
            j = int(np.argmax(np.where(np.isfinite(early), early, -np.inf)))
            slowest = (float(early[j]), self._ids[16 * j:16 * j + 16].rstrip(b" ").decode("ascii"))
        return PlanSetSummary(total=n, counts=tuple(counts.items()), stats=tuple(stats),
                              bins=tuple(round(float(x), 3) for x in edges), slowest=slowest)


def _write_at(folder: int | None, name: str, data: bytes) -> None:
    """Write file `name` (new or emptied, as ``open(name, "wb")`` does) in the open folder `folder` (a file
    descriptor; None: `name` is a path)."""
    fd = os.open(name, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666, dir_fd=folder)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
    finally:
        os.close(fd)


def _kernel_copy(src: int, dst: int, size: int, offset: int) -> bool:
    """Append `size` bytes of file `src` from `offset` to file `dst` (at its end) without reading them
    into this process (``copy_file_range``: the end of a kitting_7picks run, 687 MB of lines, went from
    3.4 to 1.6 s); False, with nothing written, where the kernel cannot (another file system on an older
    kernel, or a file system without it)."""
    done = 0
    while done < size:
        try:
            n = os.copy_file_range(src, dst, size - done, offset + done)
        except OSError:
            if done:  # pragma: no cover - failing midway: no known case
                raise
            return False
        if n == 0:  # pragma: no cover - the spool ends early: cannot happen while we hold it
            raise HrcError("internal: the plans' spool ended before its last line")
        done += n
    return True


@dataclass(frozen=True, slots=True)
class StreamResult:
    """What `compile_stream` did: the report's view of the set, the plans compiled, and whether the run
    was interrupted (``compiled.json`` then says ``"partial": true``)."""

    plan_set: CompiledPlanSet
    compiled: int
    partial: bool
    seconds_per_plan: float | None  # the estimate's sample plans, the second time (`Sample`), in this process


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


def _sample(task: Task, paths: PathLibrary, families: list[tuple[Plan, ...]], options: CompileOptions,
            stnu: str, sink: PlanSink, budget: float) -> Sample:
    """Compile sample families here until `budget` seconds pass (at least one family, at most 16 plans),
    then the same again (`Sample`): the time and disk per plan for the up-front estimate; the first
    time's plans are kept, not wasted."""
    t0 = time.perf_counter()
    n = done = 0
    size = 0.0
    for family in families:
        for cp, tail in compile_records(options, stnu, task, paths, [family]):
            sink.add(cp, tail)
            size += len(tail.encode()) + 32
            if stnu == "graphml":
                size += -(-len(cp.graphml.encode()) // 4096) * 4096
            elif stnu == "archive":
                size += len(zlib.compress(cp.graphml.encode(), 1))
        n += len(family)
        done += 1
        if time.perf_counter() - t0 >= budget or n >= 16:
            break
    t1 = time.perf_counter()
    compile_records(options, stnu, task, paths, families[:done])  # again, with this process's caches filled
    t2 = time.perf_counter()
    return Sample(done, n, (t2 - t1) / max(n, 1), (t1 - t0) / max(n, 1), size / max(n, 1))


def compile_stream(task: Task, out_dir: Path, total: int, *, seed: int = 0, jobs: int | None = None,
                   executor: str | None = None, options: CompileOptions | None = None,
                   stnu: str = "graphml", keep: int = REPORT_TOP, progress: Progress | None = None,
                   estimate: Callable[[Sample], None] | None = None, sample_seconds: float = 1.0,
                   symmetry: bool = False) -> StreamResult:
    """Compile every plan of `task` into `out_dir` (a staging folder: ``input/``, ``compiled.json``,
    the STNUs). `total`: the plan count (or its bound) for progress. `estimate` is called once with the
    seconds per plan measured on the first plans (compiled here for `sample_seconds`), before the rest
    goes to the executor. Interrupted (KeyboardInterrupt) after some plans: a partial output; before
    any: re-raised. `symmetry`: one plan per class of plans that differ only by swapping identical actions
    (`hrc.plans.identical_actions`; ``compiled.json`` names the groups). Raises `hrc.errors.HrcError`."""
    options = options or CompileOptions()
    out_dir = Path(out_dir)
    write_input(task, out_dir)
    sink = PlanSink(task, out_dir, stnu, keep, options.rank_by,
                    identical_actions(task) if symmetry else ())
    paths: PathLibrary | None = None
    per_plan: float | None = None
    partial = False
    try:
        with make_executor(executor, jobs) as ex:  # first, so a bad executor fails before any planning
            paths = plan_paths(task, seed=seed,
                               progress=(lambda d, t: progress("motion", d, t)) if progress else None)
            # the estimate's sample comes from allocations spread over the whole space (the stream's first
            # plans are all of one corner: the human doing everything), and is left out of the stream
            spread = spread_families(task, 16, symmetry)
            sample = _sample(task, paths, spread, options, stnu, sink, sample_seconds)
            per_plan = sample.seconds_per_plan
            done = {f[0] for f in spread[:sample.families]}
            if estimate is not None:
                estimate(sample)
            stream = (((plan,) for plan in generate_plans(task, symmetry=True)) if symmetry
                      else plan_families(task))
            stream = (f for f in stream if f[0] not in done)
            if progress:
                progress("plans", len(sink), total)
            family = 1 if symmetry else symmetry_factor(task)
            size = max(1, chunk_size(max(total - len(sink), 1), getattr(ex, "jobs", 2)) // family)
            work = functools.partial(_records_with, options, stnu)
            chunks = iter(lambda: list(itertools.islice(stream, size)), [])
            for batch in ex.map_chunks(work, task, paths, ((sink.bar(), chunk) for chunk in chunks)):
                for record in batch:
                    sink.add_record(record)
                if progress:
                    progress("plans", len(sink), total)
    except KeyboardInterrupt:
        if paths is None or not len(sink):
            sink.abandon()
            raise
        partial = True
    except BaseException:
        sink.abandon()
        raise
    plan_set = sink.finish(seed, paths, options, partial=total if partial else None)
    return StreamResult(plan_set=plan_set, compiled=plan_set.total, partial=partial, seconds_per_plan=per_plan)


def _records_with(options: CompileOptions, stnu: str, task: Task, paths: PathLibrary,
                  work: tuple[Bar, list[tuple[Plan, ...]]]) -> list[Record]:
    return compact_records(options, stnu, task, paths, work)
