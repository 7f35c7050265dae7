"""Streaming compile (issue 12): plans flow from generation through motion, STNU and classification to
disk, and the memory held does not grow with the plans' full records.

`compile_task` keeps every `CompiledPlan` (about 50 KB each) until it ranks them; this module is how
``hrc compile`` runs instead. Each plan is compiled in an executor (`compile_records`, which also
encodes its ``compiled.json`` line there, in parallel); the parent process hands it to a `PlanSink`,
which

- appends the plan's line to a spool file and its STNU to ``stnu/`` (or to a spool for ``stnu.zip``);
  or, from a worker process on this machine, which wrote them itself (`_WorkerFiles`), notes where,
- keeps its rank key as a compact record (eight numbers and the id, about 100 bytes per plan, in
  typed arrays: 36 MB for 362,880 plans),
- keeps the full `CompiledPlan` only for the `keep` best plans and the best plan of each class (what
  the report shows); workers send it only for a plan that beats the bar of the moment
  (`compact_records`, `PlanSink.bar`), the rest as a few strings,

and at the end sorts the compact records by `rank_key` (the same total order as `compile_task`, so the
same ranks) and writes ``compiled.json`` in rank order, one line per plan, straight from the spools. The
bytes are those `write_compiled` writes for the same set (tested on the workshop).

An interrupted run (SIGINT, or SIGTERM which the CLI turns into the same) still leaves a valid output:
the plans compiled so far, ranked among themselves, with ``"partial": true`` in ``compiled.json``, and
only their STNU files.
"""

from __future__ import annotations

import bisect
import contextlib
import functools
import itertools
import json
import os
import shutil
import time
import zipfile
import zlib
from array import array
from collections.abc import Callable, Sequence
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
from hrc.errors import HrcError, InputError
from hrc.model import Plan, Task
from hrc.motion import PathLibrary, plan_paths
from hrc.plans import (
    family_of,
    generate_plans,
    identical_actions,
    plan_code,
    plan_families,
    plan_from_code,
    spread_families,
    symmetry_factor,
)

__all__ = ["HISTOGRAM_BINS", "REPORT_TOP", "RESUME_FILE", "Abandoned", "PlanSink", "Sample", "StreamResult",
           "chunk_size", "compact_records", "compile_records", "compile_stream", "read_resume", "resume_dtype"]

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
    return [(cp, _line_tail(task, cp, stnu)) for cp in _compiled(options, stnu, task, paths, families)]


def _compiled(options: CompileOptions, stnu: str, task: Task, paths: PathLibrary,
              families: list[tuple[Plan, ...]]) -> list[CompiledPlan]:
    return [cp for family in families for cp in compile_family(task, family, paths, options, stnu != "none")]


def _line_tail(task: Task, cp: CompiledPlan, stnu: str) -> str:
    """`cp`'s ``compiled.json`` line after ``"rank":`` (`plan_line`)."""
    text = plan_line(task, cp, stnu)
    head = _line_head(cp.plan.id, 0)
    if not text.startswith(head):  # pragma: no cover - plan_dict puts id and rank first
        raise HrcError(f"internal: plan {cp.plan.id}'s line does not start with its id and rank")
    return text[len(head):]


Bar = tuple[tuple | None, dict[str, tuple], dict[tuple, tuple]]
"""The keep-th best rank key so far, the best key per class, and with `PlanSink.best` the key a plan of an
allocation (of the work's plans) must beat to be kept at all (`PlanSink.bar`)."""
Written = tuple[str, int, int]  # what a worker wrote itself: a spool file's name, the offset and the length
Record = tuple[tuple, str, str, "str | Written | None", "str | Written", CompiledPlan | None, bytes]
"""A plan as `compact_records` sends it: rank key, id, class, its STNU (GraphML text; where the worker
wrote it itself, None for a file of ``stnu/`` or `Written` for a spool), its line tail (text or
`Written`), its full record when it beat the bar, and the plan itself in a few bytes (`plan_code`)."""


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

    With `folder` (the output folder, for a worker on the parent's machine: `_WorkerFiles`), the worker
    writes the texts there itself and sends where they are: 56 kB per kitting_7picks plan no longer cross
    a pipe twice and pass through the parent, whose CPU the workers share. `stnu_to` (`PlanSink.stnu_to`)
    says where a GraphML goes then: its file in ``stnu/``, a spool, or nowhere.

    A plan that cannot be kept at all gets neither line nor GraphML (empty texts: never written out)."""
    (top, best, among), families = work
    out: list[Record] = []
    compiled = _compiled(options, stnu, task, paths, families)
    keys = [rank_key(cp, options.rank_by) for cp in compiled]
    kept = [not among or (beat := among.get(cp.plan.allocation)) is None or key < beat
            for cp, key in zip(compiled, keys, strict=True)]
    texts = [(_line_tail(task, cp, stnu), cp.graphml) if k else ("", "") for cp, k in zip(compiled, kept, strict=True)]
    tails: Sequence[str | Written] = [tail for tail, _ in texts]
    graphml: Sequence[str | Written | None] = [text for _, text in texts]
    if folder is not None:
        files = _WorkerFiles.of(folder, stnu_to)
        tails, graphml = files.lines([tail for tail, _ in texts]), files.stnus(compiled, [t for _, t in texts])
    for cp, key, k, text, tail in zip(compiled, keys, kept, graphml, tails, strict=True):
        cls = cp.plan_class.value
        full = k and ((top is None or key < top) or cls not in best or key < best[cls])
        out.append((key, cp.plan.id, cls, text, tail, replace(cp, graphml="") if full else None,
                    plan_code(task, cp.plan)))
    return out


class _WorkerFiles:
    """A worker's own files in the output folder (`compact_records` with a folder): its spool of line
    tails ``.plans.PID.spool`` and, by `PlanSink.stnu_to`, the GraphML files in ``stnu/`` or its spool
    ``.stnu.PID.spool`` (for the archive, or for the files of the plans kept in the end); opened at the
    worker's first unit of work, appended to with one write per unit. The parent reads the spools when
    it writes ``compiled.json`` and ``stnu.zip`` and removes them (`PlanSink`); after an interrupt, it
    removes the GraphML files of plans it never heard of."""

    _open: dict[str, _WorkerFiles] = {}  # per process (a forked child opens its own): folder -> files

    def __init__(self, folder: str, stnu_to: str) -> None:
        self.pid, self.stnu_to = os.getpid(), stnu_to
        self.names = (f".plans.{self.pid}.spool", f".stnu.{self.pid}.spool")
        flags = os.O_WRONLY | os.O_CREAT | os.O_APPEND
        self.fds = [os.open(os.path.join(folder, self.names[0]), flags, 0o666),
                    os.open(os.path.join(folder, self.names[1]), flags, 0o666) if stnu_to == "spool" else -1]
        self.at = [os.fstat(fd).st_size if fd >= 0 else 0 for fd in self.fds]
        self.stnu_path = os.path.join(folder, "stnu")
        self.stnu_dir = _open_folder(self.stnu_path) if stnu_to == "files" else None

    @classmethod
    def of(cls, folder: str, stnu_to: str) -> _WorkerFiles:
        files = cls._open.get(folder)
        if files is None or files.pid != os.getpid() or files.stnu_to != stnu_to:
            for old in cls._open.values():  # another run's, in a process that lives on (a test's)
                old.close()
            cls._open = {folder: cls(folder, stnu_to)}
            files = cls._open[folder]
        return files

    def close(self) -> None:
        if self.pid == os.getpid():
            for fd in (*self.fds, self.stnu_dir):
                if fd is not None and fd >= 0:
                    os.close(fd)

    def _append(self, which: int, texts: list[str], newline: bool) -> list[Written]:
        """Append `texts` to spool `which` in one write; where each went."""
        out: list[Written] = []
        data = bytearray()
        at = self.at[which]
        for text in texts:
            raw = text.encode("utf-8")
            out.append((self.names[which], at + len(data), len(raw)))
            data += raw
            if newline:
                data += b"\n"
        _write_all(self.fds[which], data)
        self.at[which] = at + len(data)
        return out

    def lines(self, tails: list[str]) -> list[Written]:
        return self._append(0, tails, newline=True)

    def stnus(self, compiled: list[CompiledPlan], texts: list[str]) -> list[str | Written | None]:
        """Write each plan's GraphML `texts` where `stnu_to` says; where each went."""
        if self.stnu_to == "files":
            for cp, text in zip(compiled, texts, strict=True):
                _write_stnu_file(self.stnu_dir, self.stnu_path, cp.plan.id, text)
            return [None] * len(compiled)
        if self.stnu_to == "spool":
            return list(self._append(1, texts, newline=False))
        return [None] * len(compiled)


def _line_head(plan_id: str, rank: int) -> str:
    return f'{{"id":{json.dumps(plan_id)},"rank":{rank},'


def chunk_size(total: int, jobs: int) -> int:
    """Plans per unit of work: at least 8 units per worker, at most 16 plans (a plan takes 10-300 ms, so
    a unit stays under a few seconds: progress stays live and an interrupt loses little)."""
    return max(1, min(16, total // (8 * max(1, jobs))))


class _Spooled:
    """Where a text of each plan went, in the order the plans came: a spool (by number; 0 is this
    process's own, written through `add_text`; the others are workers', `_WorkerFiles`), an offset and a
    length. Each text is followed by `sep` in its spool."""

    def __init__(self, folder: Path, own: str, sep: bytes) -> None:
        self.folder, self.sep = folder, sep
        self.names = [own]
        self._numbers = {own: 0}
        self.own: IO[bytes] = open(folder / own, "w+b")  # noqa: SIM115 - closed in close
        self.file, self.at, self.size = array("H"), array("q"), array("q")
        self._fds: list[int] = []

    def __len__(self) -> int:
        return len(self.at)

    def add_text(self, data: bytes) -> None:
        self.file.append(0)
        self.at.append(self.own.tell())
        self.size.append(len(data))
        self.own.write(data + self.sep)

    def add_written(self, written: Written) -> None:
        name, at, size = written
        number = self._numbers.get(name)
        if number is None:
            if os.path.basename(name) != name or not name.startswith("."):  # pragma: no cover - ours alone
                raise HrcError(f"internal: a worker wrote to {name!r}, not a spool of the output folder")
            number = self._numbers[name] = len(self.names)
            self.names.append(name)
        self.file.append(number)
        self.at.append(at)
        self.size.append(size)

    def fds(self) -> list[int]:
        """A readable descriptor per spool (the own one flushed), opened once."""
        self.own.flush()
        if not self._fds:
            self._fds = [self.own.fileno()] + [os.open(self.folder / n, os.O_RDONLY) for n in self.names[1:]]
        return self._fds

    def read(self, i: int) -> bytes:
        return os.pread(self.fds()[self.file[i]], self.size[i], self.at[i])

    def close(self) -> None:
        for fd in self._fds[1:]:
            os.close(fd)
        self._fds = []
        self.own.close()


class PlanSink:
    """Where compiled plans go, in any order: spooled to `out_dir`, a compact rank record each, the full
    record only for the `keep` best and the best of each class. A mutable builder (see the module
    docstring); `finish` writes ``compiled.json`` and returns what the report needs."""

    def __init__(self, task: Task, out_dir: Path, stnu: str = "graphml", keep: int = REPORT_TOP,
                 rank_by: str = "worst", symmetric: tuple[tuple[str, ...], ...] = (),
                 best: int | None = None) -> None:
        if stnu not in STNU_MODES:
            raise ValueError(f"stnu must be one of {STNU_MODES}, got {stnu!r}")
        if best is not None and best < 1:
            raise ValueError(f"best must be at least 1, got {best}")
        self.task, self.out_dir, self.stnu, self.keep, self.rank_by = task, Path(out_dir), stnu, keep, rank_by
        self.symmetric, self.best = symmetric, best
        # where a plan's GraphML goes: its file at once; a spool, for the archive or, when only the best
        # of each allocation are kept, for the files of those alone, written at the end; or nowhere
        self.stnu_to = "none" if stnu == "none" else "spool" if stnu == "archive" or best else "files"
        self._lines = _Spooled(self.out_dir, ".plans.spool", b"\n")
        self._graphml: _Spooled | None = None
        self._stnu_dir: int | None = None
        if stnu == "graphml":
            (self.out_dir / "stnu").mkdir(exist_ok=True)
            self._stnu_dir = _open_folder(str(self.out_dir / "stnu"))
        if self.stnu_to == "spool":
            self._graphml = _Spooled(self.out_dir, ".stnu.spool", b"")
        self._codes = bytearray()  # each plan's `plan_code`: to group (`best`), recover and resume them
        self._width = 0  # bytes per plan code
        self._restored = 0  # the first this many plans came from an interrupted run's output (`restore`)
        self._among: dict[tuple, list[tuple]] = {}  # with `best`: the best keys of each allocation so far
        self._cols = {name: array("d") for name in _KEY_COLUMNS}
        self._ids = bytearray()  # 16 bytes per plan: its id, padded with spaces
        self._held: list[tuple[tuple, int, CompiledPlan]] = []
        self._best: dict[str, tuple[tuple, int, CompiledPlan]] = {}

    def __len__(self) -> int:
        return len(self._ids) // 16  # the last of a plan's columns `add_record` appends to

    def _settle(self) -> None:
        """Forget what `add_record` appended for a plan it did not finish taking (an interrupt between
        two of its appends): every column as long as the plans taken."""
        n = len(self)
        for spool in (self._lines, self._graphml):
            if spool is not None:
                for column in (spool.file, spool.at, spool.size):
                    del column[n:]
        for values in self._cols.values():
            del values[n:]
        del self._codes[n * self._width:]

    def add(self, cp: CompiledPlan, tail: str) -> None:
        """Take one compiled plan and its line tail (`compile_records`)."""
        self.add_record((rank_key(cp, self.rank_by), cp.plan.id, cp.plan_class.value, cp.graphml, tail,
                         replace(cp, graphml=""), plan_code(self.task, cp.plan)))

    def bar(self, families: Sequence[tuple[Plan, ...]] = ()) -> Bar:
        """What a plan must beat to be kept in full (`compact_records`): the keep-th best key so far (None
        while fewer are held), the best key of each class so far, and with `best`, for the allocations
        of `families`' plans that have had `best` plans, the worst of their `best` best keys (a plan of
        such an allocation that does not beat it is never kept: without this, the first bar stays None
        until `keep` allocations have been seen, and every plan would be sent in full until then)."""
        top = None
        if len(self._held) >= self.keep:
            self._trim()
            top = self._held[-1][0] if len(self._held) >= self.keep else None
        among: dict[tuple, tuple] = {}
        if self.best is not None:
            for plan in (plan for family in families for plan in family):
                keys = self._among.get(plan.allocation)
                if keys is not None and len(keys) >= self.best:
                    among[plan.allocation] = keys[-1]
        return top, {cls: b[0] for cls, b in self._best.items()}, among

    def _trim(self) -> None:
        """Keep only the `keep` best held plans, best first; with `best`, at most that many of each
        allocation among them.

        Why the keep-th best of these is a sound bar with `best`: if `keep` of them beat a plan, then in
        the end at least as many plans that are kept beat it, because an allocation's final `best` best
        include, rank by rank, plans at least as good as those of its plans held now."""
        self._held.sort(key=lambda h: h[0])
        if self.best is not None:
            taken: dict[tuple, int] = {}
            held = []
            for h in self._held:
                allocation = h[2].plan.allocation
                if taken.get(allocation, 0) < self.best:
                    taken[allocation] = taken.get(allocation, 0) + 1
                    held.append(h)
            self._held = held
        del self._held[self.keep:]

    def add_record(self, record: Record) -> None:
        """Take one plan as `compact_records` sends it (its full record only if it beat the bar; its texts
        or, from a worker on this machine, where the worker wrote them)."""
        key, pid, cls, graphml, tail, light, code = record
        i = len(self)
        if isinstance(tail, str):
            self._lines.add_text(tail.encode("utf-8"))
        else:
            self._lines.add_written(tail)
        if isinstance(graphml, str):
            if self._graphml is not None:
                self._graphml.add_text(graphml.encode("utf-8"))
            elif self.stnu_to == "files":
                _write_stnu_file(self._stnu_dir, str(self.out_dir / "stnu"), pid, graphml)
        elif graphml is not None and self._graphml is not None:
            self._graphml.add_written(graphml)
        self._width = len(code)
        self._codes += code
        if self.best is not None:
            keys = self._among.setdefault(plan_from_code(self.task, code).allocation, [])
            if len(keys) < self.best or key < keys[-1]:
                bisect.insort(keys, key)
                del keys[self.best:]
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
        return _line_head(self._id(i), rank).encode("utf-8")

    def _id(self, i: int) -> str:
        """Plan `i`'s id."""
        return self._ids[16 * i:16 * i + 16].rstrip(b" ").decode("ascii")

    def finish(self, seed: int, paths: PathLibrary, options: CompileOptions,
               partial: int | None = None) -> CompiledPlanSet:
        """Write ``compiled.json`` (and ``stnu.zip``, or with `best` the kept plans' GraphML files) in rank
        order; remove the spools. `partial`: the number of plans expected when the run was interrupted.
        Returns the best plans with their ranks and a `PlanSetSummary` of all kept (for the report)."""
        self._settle()
        order = self._order()
        compiled = len(order)
        if self.best is not None:
            order = order[self._among_best(order)]
        n = len(order)
        rank = np.zeros(compiled, dtype=np.int64)  # 0: not kept (with `best`)
        rank[order] = np.arange(1, n + 1)
        cls_col = np.frombuffer(self._cols["cls"], dtype=np.float64)[order]
        counts = {c.value: int(np.count_nonzero(cls_col == c.order)) for c in PlanClass}
        digest = task_digest(self.task)
        header = header_dict(self.task, seed, digest, options, counts, self.stnu,
                             None if partial is None else (n, partial), self.symmetric,
                             None if self.best is None else (self.best, compiled))
        # the archive (deflating, which frees the GIL) or the kept files in a thread while compiled.json is
        # copied: two files from two spools, so a second core shortens the end of a large compile
        with ThreadPoolExecutor(max_workers=1) as pool:
            writer = self._write_archive if self.stnu == "archive" else self._write_files
            archive = pool.submit(writer, order) if self._graphml is not None else None
            lines = self._lines
            fds = lines.fds()
            with open(self.out_dir / "compiled.json", "wb") as out:
                out.write(json_head(header).encode("utf-8"))
                copy = _kernel_copy if hasattr(os, "copy_file_range") else None
                for k, i in enumerate(order.tolist()):
                    head = (b",\n" if k else b"") + self._head_of(i, k + 1)
                    fd, start, size = fds[lines.file[i]], lines.at[i], lines.size[i]
                    if copy is not None:  # the line's tail copied from spool to file in the kernel
                        out.write(head)
                        out.flush()
                        if copy(fd, out.fileno(), size, start):
                            continue
                        copy = None  # not on this file system: read and write from here on
                        out.seek(0, os.SEEK_END)
                    else:
                        out.write(head)
                    out.write(os.pread(fd, size, start))
                out.write(JSON_TAIL.encode("utf-8"))
            if archive is not None:
                archive.result()
        self._close()
        if partial is not None:
            self._write_resume()
            if self.stnu_to == "files":
                self._drop_unlisted()
        held = {i: cp for _, i, cp in self._held}
        held.update({i: cp for _, i, cp in self._best.values()})
        # what the report shows: the keep best and the best of each class
        wanted = dict.fromkeys(order[:self.keep].tolist())
        for c in PlanClass:
            first = np.flatnonzero(cls_col == c.order)
            if first.size:
                wanted[int(order[first[0]])] = None
        plans = tuple(replace(held[i] if i in held else self._recover(i, rank[i] <= self.keep, paths, options),
                              rank=int(rank[i])) for i in sorted(wanted, key=lambda i: rank[i]))
        return CompiledPlanSet(task=self.task, seed=seed, digest=digest, paths=paths, plans=plans, options=options,
                               summary=self._summary(counts, np.sort(order)), stnu_files=self.stnu)

    def _resume_rows(self) -> np.ndarray:
        """Every plan taken so far as one row of `resume_dtype`, in the order taken."""
        n, width = len(self), self._width // 2
        rows = np.zeros(n, dtype=resume_dtype(width))
        for name in _KEY_COLUMNS:
            rows[name] = np.frombuffer(self._cols[name], dtype=np.float64)
        rows["id"] = np.frombuffer(bytes(self._ids), dtype="S16")
        if width:
            rows["code"] = np.frombuffer(bytes(self._codes), dtype=np.uint16).reshape(n, width)
        return rows

    def _write_resume(self) -> None:
        """``resume.npy`` beside a partial ``compiled.json``: each plan compiled (also those `best` did
        not list) with its exact rank key and its `plan_code`, for ``hrc compile --resume``."""
        np.save(self.out_dir / RESUME_FILE, self._resume_rows(), allow_pickle=False)

    def restore(self, old: Path, rows: np.ndarray) -> frozenset[str]:
        """Take the plans of an interrupted run's output `old` (its ``resume.npy`` rows, `read_resume`):
        their line tails from its ``compiled.json``, their GraphML from its ``stnu/`` (linked, not copied,
        when this sink writes files) or ``stnu.zip``. A plan compiled there but not listed (`best`) has
        neither and is never listed here either: the plans that beat it are restored too. Call before
        any other plan is added. Returns the ids taken (not to be compiled again)."""
        if len(self):
            raise ValueError("restore before any plan is added")
        tails = _line_tails(old / "compiled.json")
        # the old lines are copied from the old compiled.json as from a worker's spool (linked here)
        spool = ".plans.resumed.spool"
        _link_or_copy(old / "compiled.json", self.out_dir / spool)
        classes = {c.order: c.value for c in PlanClass}
        archive = zipfile.ZipFile(old / STNU_ARCHIVE) if (old / STNU_ARCHIVE).is_file() else None
        try:
            for row in rows:
                pid = row["id"].decode("ascii").rstrip(" ")
                place = tails.get(pid)
                if place is None and self.best is None:
                    raise InputError(str(old / RESUME_FILE), "", f"--resume: plan {pid} is not in compiled.json")
                key = (*(float(row[name]) for name in _KEY_COLUMNS), pid)
                graphml: str | None = ""  # "": none; None: its file is in place
                if self.stnu_to == "files":
                    graphml = None
                    if place is not None:
                        _link_or_copy(old / "stnu" / f"{pid}.graphml", self.out_dir / "stnu" / f"{pid}.graphml")
                elif place is not None and self.stnu_to == "spool":
                    graphml = (archive.read(f"stnu/{pid}.graphml").decode("utf-8") if archive is not None
                               else (old / "stnu" / f"{pid}.graphml").read_text(encoding="utf-8"))
                tail: str | Written = "" if place is None else (spool, *place)
                self.add_record((key, pid, classes[int(row["cls"])], graphml, tail, None, row["code"].tobytes()))
        finally:
            if archive is not None:
                archive.close()
        self._restored = len(self)
        return frozenset(self._id(i) for i in range(self._restored))

    def _among_best(self, order: np.ndarray) -> np.ndarray:
        """Which plans of `order` (rank order) are among the `best` first of their allocation."""
        n, best = len(order), self.best
        assert best is not None
        if not n:
            return np.ones(0, dtype=bool)
        codes = np.frombuffer(bytes(self._codes), dtype=np.uint16).reshape(n, -1)
        parts = codes == 0xFFFF  # between two agents' sequences (`plan_code`)
        agent = np.cumsum(parts, axis=1, dtype=np.uint16)
        rows, cols = np.nonzero(~parts)
        allocation = np.zeros((n, len(self.task.actions)), dtype=np.uint16)
        allocation[rows, codes[rows, cols]] = agent[rows, cols]
        group = np.unique(allocation, axis=0, return_inverse=True)[1].ravel()[order]
        by_group = np.argsort(group, kind="stable")  # each allocation's plans together, in rank order
        sorted_group = group[by_group]
        at = np.arange(n)
        starts = np.maximum.accumulate(np.where(np.r_[True, sorted_group[1:] != sorted_group[:-1]], at, 0))
        place = np.empty(n, dtype=np.int64)
        place[by_group] = at - starts  # 0 for the best of its allocation, 1 for the next, ...
        return place < best

    def _recover(self, i: int, top: bool, paths: PathLibrary, options: CompileOptions) -> CompiledPlan:
        """Plan `i`'s full record, compiled again here (in its family, as the workers did: the same
        record): with `best`, the best kept plan of a class may have been sent without it, since a plan
        of its class that beat it then was dropped later with its allocation's worse plans; and a plan
        restored from an interrupted run (`restore`) comes without one. Otherwise never one of the `keep`
        best (`top`): the bar keeps those (`_trim`)."""
        if i >= self._restored and (self.best is None or top):  # pragma: no cover - the bars keep them
            raise HrcError(f"internal: plan {i} is shown but its record was not kept")
        width = self._width
        plan = plan_from_code(self.task, bytes(self._codes[width * i:width * (i + 1)]))
        family = family_of(self.task, plan, symmetry=bool(self.symmetric))
        cp = next(cp for cp in compile_family(self.task, family, paths, options, graphml=False) if cp.plan == plan)
        return replace(cp, graphml="")

    def _write_archive(self, order: np.ndarray) -> None:
        """``stnu.zip``: the GraphML files in rank order, deflated, with fixed dates (deterministic bytes).

        Deflate level 1: this runs after the last plan (beside the copy of ``compiled.json``), and level 1
        deflates kitting_7picks' GraphML (40,320 files, 1.25 GB) in about 6 s where the default level
        took 17 s, for an archive about a quarter larger (135 MB)."""
        spool = self._graphml
        assert spool is not None
        with zipfile.ZipFile(self.out_dir / STNU_ARCHIVE, "w", zipfile.ZIP_DEFLATED) as zf:
            for i in order.tolist():
                pid = self._id(i)
                info = zipfile.ZipInfo(f"stnu/{pid}.graphml", date_time=(1980, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = 0o644 << 16
                zf.writestr(info, spool.read(i), compresslevel=1)

    def _write_files(self, order: np.ndarray) -> None:
        """The GraphML files of the plans in `order` (the kept ones, with `best`) from the spool."""
        spool = self._graphml
        assert spool is not None
        for i in order.tolist():
            _write_stnu_file(self._stnu_dir, str(self.out_dir / "stnu"), self._id(i), spool.read(i))

    def _close(self) -> None:
        if self._stnu_dir is not None:
            os.close(self._stnu_dir)
            self._stnu_dir = None
        for spool in (self._lines, self._graphml):
            if spool is not None:
                spool.close()
        # this process's spools and every worker's, also those whose plans never arrived (interrupted)
        for path in [*self.out_dir.glob(".plans*.spool"), *self.out_dir.glob(".stnu*.spool")]:
            with contextlib.suppress(FileNotFoundError):
                path.unlink()

    def _drop_unlisted(self) -> None:
        """Remove the GraphML files of plans the sink never took: after an interrupt, workers writing
        into ``stnu/`` themselves (`_WorkerFiles`) may have written plans whose records never came."""
        listed = {f"{self._id(i)}.graphml" for i in range(len(self))}
        folder = self.out_dir / "stnu"
        for name in os.listdir(folder):
            if name not in listed:
                (folder / name).unlink()

    def abandon(self) -> None:
        """Close and remove the spools (the caller removes the folder)."""
        self._close()

    def _summary(self, counts: dict[str, int], kept: np.ndarray) -> PlanSetSummary:
        """Statistics over the plans `kept` (indices)."""
        n = len(kept)
        cls = np.frombuffer(self._cols["cls"], dtype=np.float64)[kept]
        worst = np.frombuffer(self._cols["worst"], dtype=np.float64)[kept]
        early = np.frombuffer(self._cols["early"], dtype=np.float64)[kept]
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
            # ties go to the smallest id: the plans' arrival order depends on the workers' timing
            top = early.max(where=np.isfinite(early), initial=-np.inf)
            slowest = (float(top), min(self._id(int(kept[j])) for j in np.flatnonzero(early == top)))
        return PlanSetSummary(total=n, counts=tuple(counts.items()), stats=tuple(stats),
                              bins=tuple(round(float(x), 3) for x in edges), slowest=slowest,
                              best=None if self.best is None else (self.best, len(self)))


RESUME_FILE = "resume.npy"
"""Beside a partial ``compiled.json``: what ``hrc compile --resume`` needs of every plan compiled."""


def resume_dtype(width: int) -> np.dtype:
    """A ``resume.npy`` row: the rank key's columns (exact), the id, the `plan_code` (`width` numbers)."""
    return np.dtype([*((name, "<f8") for name in _KEY_COLUMNS), ("id", "S16"), ("code", "<u2", (width,))])


_RESUMED_KEYS = ("schema_version", "generator", "seed", "options", "task", "stnu_files", "stnu_archive",
                 "identical_actions", "best_per_allocation")
"""What an interrupted run's ``compiled.json`` must say as the resumed run would (`read_resume`)."""


def read_resume(folder: Path, task: Task, seed: int, options: CompileOptions, stnu: str, symmetry: bool,
                best: int | None) -> np.ndarray:
    """The ``resume.npy`` rows of the partial output in `folder`, after checking that it is one, of the
    same task and options as the run that resumes it. Raises `InputError` (one line: which file, what
    differs, what to do) before any work."""
    header = header_dict(task, seed, task_digest(task), options, {}, stnu, None,
                         identical_actions(task) if symmetry else (), None if best is None else (best, 0))
    header = json.loads(json.dumps(header))  # as read back: lists, not tuples
    compiled = Path(folder) / "compiled.json"
    try:
        with open(compiled, encoding="utf-8") as f:
            head = f.read(1 << 16).split(',\n "plans": [', 1)[0] + "\n}"
        old = json.loads(head)
        if not isinstance(old, dict):
            raise ValueError("not an object")
    except (OSError, ValueError) as err:
        raise InputError(str(compiled), "", f"--resume: not an hrc compile output ({err})") from err
    if not old.get("partial"):
        raise InputError(str(compiled), "partial", "--resume: this output is complete, nothing to resume")
    for key in _RESUMED_KEYS:
        was, now = old.get(key), header.get(key)
        where = key
        while isinstance(was, dict) and isinstance(now, dict) and was != now:  # the first key that differs
            sub = next(k for k in (*was, *now) if was.get(k) != now.get(k))
            where, was, now = f"{where}.{sub}", was.get(sub), now.get(sub)
        if was != now:
            why = " (the task, its map or --pin differ)" if where == "task.digest" else ""
            raise InputError(str(compiled), where, f"--resume: compiled with {json.dumps(was)}, this run with "
                                                   f"{json.dumps(now)}{why}; resume with the same task and "
                                                   "options, or compile into a new --out")
    path = Path(folder) / RESUME_FILE
    try:
        rows = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as err:
        raise InputError(str(path), "", f"--resume: cannot read it ({err})") from err
    names = rows.dtype.names or ()
    if rows.ndim != 1 or names[:len(_KEY_COLUMNS) + 1] != (*_KEY_COLUMNS, "id") or "code" not in names:
        raise InputError(str(path), "", "--resume: not the rows hrc compile writes")
    return rows


def _line_tails(path: Path) -> dict[str, tuple[int, int]]:
    """Where each plan line of ``compiled.json`` has its tail (after its id and rank, `_line_head`): offset
    and length, by plan id. Read line by line: a partial output's lines can be gigabytes in all."""
    out: dict[str, tuple[int, int]] = {}
    at = 0
    with open(path, "rb") as f:
        for line in f:
            if line.startswith(b'{"id":'):
                head, sep, rest = line.partition(b',"rank":')
                skip = len(head) + len(sep) + rest.index(b",") + 1
                end = len(line.rstrip(b"\n"))
                end -= line[end - 1:end] == b","
                out[json.loads(head[len(b'{"id":'):])] = (at + skip, end - skip)
            at += len(line)
    return out


def _link_or_copy(source: Path, target: Path) -> None:
    """`target` as a hard link to `source` (the same bytes, no copy), or a copy where links fail."""
    try:
        os.link(source, target)
    except OSError:
        shutil.copyfile(source, target)


def _open_folder(path: str) -> int | None:
    """`path` opened as a folder, for files opened relative to it (no path to build and resolve per
    plan: 40,320 of them); None where the system has no ``dir_fd``."""
    if os.open not in os.supports_dir_fd:
        return None
    return os.open(path, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))


def _write_stnu_file(folder: int | None, path: str, plan_id: str, text: str | bytes) -> None:
    """A plan's GraphML file ``PLAN.graphml`` in ``stnu/`` (open as `folder`, or at `path`)."""
    name = f"{plan_id}.graphml"
    _write_at(folder, name if folder is not None else os.path.join(path, name),
              text.encode("utf-8") if isinstance(text, str) else text)


def _write_at(folder: int | None, name: str, data: bytes) -> None:
    """Write file `name` (new or emptied, as ``open(name, "wb")`` does) in the open folder `folder` (a file
    descriptor; None: `name` is a path)."""
    fd = os.open(name, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o666, dir_fd=folder)
    try:
        _write_all(fd, data)
    finally:
        os.close(fd)


def _write_all(fd: int, data: bytes | bytearray) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


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
            stnu: str, sink: PlanSink, budget: float, taken: frozenset[str] = frozenset()) -> Sample:
    """Compile sample families here until `budget` seconds pass (at least one family, at most 16 plans),
    then the same again (`Sample`): the time and disk per plan for the up-front estimate; the first
    time's plans are kept, not wasted (but for those the sink has `taken` already)."""
    t0 = time.perf_counter()
    n = done = 0
    size = 0.0
    for family in families:
        for cp, tail in compile_records(options, stnu, task, paths, [family]):
            if cp.plan.id not in taken:
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
                   symmetry: bool = False, best: int | None = None,
                   resume: tuple[Path, np.ndarray] | None = None, keep_partial: bool = True) -> StreamResult:
    """Compile every plan of `task` into `out_dir` (a staging folder: ``input/``, ``compiled.json``,
    the STNUs). `total`: the plan count (or its bound) for progress. `estimate` is called once with the
    seconds per plan measured on the first plans (compiled here for `sample_seconds`), before the rest
    goes to the executor. Interrupted (KeyboardInterrupt) after some plans: a partial output; before
    any: re-raised. `symmetry`: one plan per class of plans that differ only by swapping identical actions
    (`hrc.plans.identical_actions`; ``compiled.json`` names the groups). `best`: keep only the best this
    many plans of each allocation (all are compiled; the others are not written, ranked or reported).
    `resume`: an interrupted run's output folder and its `read_resume` rows: its plans are taken as they
    are and not compiled again (the output is the same as a run never interrupted). `keep_partial`:
    whether an interrupted run writes what it compiled (else it raises `Abandoned` at once: the caller
    keeps an earlier output instead, and writing a large partial one would take a while for nothing).
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
            sample = _sample(task, paths, spread, options, stnu, sink, sample_seconds, taken)
            per_plan = sample.seconds_per_plan
            done = {f[0] for f in spread[:sample.families]}
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
            # workers on this machine write their plans' texts into the folder themselves
            folder = str(out_dir) if getattr(ex, "local_processes", False) else None
            work = functools.partial(_records_with, options, stnu, folder, sink.stnu_to)
            chunks = iter(lambda: list(itertools.islice(stream, size)), [])
            for batch in ex.map_chunks(work, task, paths, ((sink.bar(chunk), chunk) for chunk in chunks)):
                for record in batch:
                    if record[1] not in taken:
                        sink.add_record(record)
                if progress:
                    progress("plans", len(sink), total)
    except KeyboardInterrupt:
        if paths is None or not len(sink):
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
    plan_set = sink.finish(seed, paths, options, partial=total if partial else None)
    return StreamResult(plan_set=plan_set, compiled=compiled, partial=partial, seconds_per_plan=per_plan)


def _records_with(options: CompileOptions, stnu: str, folder: str | None, stnu_to: str, task: Task,
                  paths: PathLibrary, work: tuple[Bar, list[tuple[Plan, ...]]]) -> list[Record]:
    return compact_records(options, stnu, task, paths, work, folder, stnu_to)
