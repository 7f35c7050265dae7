"""The plan sink: where compiled plans go, in any order, and how ``compiled.json`` is written from them.

`PlanSink` takes each plan as a worker sends it (`hrc.compile.stream.compact_records`): it spools the
plan's line and STNU (`hrc.compile.spool`), keeps its rank key as a compact record (eight numbers and
the id, about 100 bytes per plan, in typed arrays: 36 MB for 362,880 plans) and the full `CompiledPlan`
only for the `keep` best plans and the best plan of each class (what the report shows). At the end
(`finish`) it sorts the compact records by `rank_key` (the same total order as `compile_task`, so the
same ranks) and writes ``compiled.json`` in rank order, one line per plan, straight from the spools, and
``stnu.zip`` or the kept GraphML files; after an interrupt it writes a partial output with
``resume.npy`` (`hrc.compile.resume`).
"""

from __future__ import annotations

import bisect
import contextlib
import functools
import json
import math
import os
import zipfile
import zlib
from array import array
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import BinaryIO

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
)
from hrc.compile.defaults import REPORT_TOP  # here too, as before
from hrc.compile.dispatch_form import FormWriter, plan_record, read_form
from hrc.compile.executors import run_apart
from hrc.compile.output import (
    FORM_PLACEHOLDER,
    INLINE_MAX_BYTES,
    JSON_TAIL,
    PLAN_LINES,
    ROWS_MAX,
    STNU_ARCHIVE,
    STNU_MODES,
    header_dict,
    json_head,
    line_head,
    line_places,
    lines_path,
    plan_row,
    ranking_summary,
    read_header,
    split_lines,
)
from hrc.compile.resume import KEY_COLUMNS, RESUME_FILE, line_tails, resume_dtype
from hrc.compile.spool import (
    ARCHIVE_LEVEL,
    DEFLATED_HEAD,
    SPOOLED,
    Spooled,
    Written,
    deflated,
    kernel_copy,
    link_or_copy,
    needs_zip64,
    open_folder,
    write_deflated_zip,
    write_stnu_file,
)
from hrc.errors import HrcError, InputError
from hrc.io.task_file import task_digest
from hrc.model import Plan, Task
from hrc.motion import PathLibrary
from hrc.plans import allocation_key, code_sequences, family_of, plan_code, plan_from_code
from hrc.temporal.graphml import read_graphml

__all__ = ["HISTOGRAM_BINS", "REPORT_TOP", "Bar", "PlanSink", "Record"]

_CLASS_NAMES = {c.order: c.value for c in PlanClass}
_FORM_BLOCK = 1024  # plans per block of the dispatch form written at the end (`PlanSink._write_form`)


HISTOGRAM_BINS = 24
"""Bins of the worst-case makespan histogram over all plans."""


Bar = tuple[tuple | None, dict[str, tuple], dict[tuple, tuple]]
"""The keep-th best rank key so far, the best key per class, and with `PlanSink.best` the key a plan of an
allocation (of the work's plans) must beat to be kept at all (`PlanSink.bar`)."""
Record = tuple[tuple, str, str, "str | Written | None", "str | Written", CompiledPlan | None, bytes, bytes]
"""A plan as `compact_records` sends it: rank key, id, class, its STNU (GraphML text; where the worker
wrote it itself, None for a file of ``stnu/`` or `Written` for a spool), its line tail (text or
`Written`), its full record when it beat the bar, and the plan itself in a few bytes (`plan_code`)."""



class PlanSink:
    """Where compiled plans go, in any order: spooled to `out_dir`, a compact rank record each, the full
    record only for the `keep` best and the best of each class. A mutable builder (see the module
    docstring); `finish` writes ``compiled.json`` (and ``plans.jsonl`` when the lines total more than
    `inline_max` bytes: `hrc.compile.output`'s schema version 3) and returns what the report needs."""

    inline_max: int = INLINE_MAX_BYTES

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
        # (for the archive, deflated where the plan was compiled: `hrc.compile.spool.deflated`)
        self.stnu_to = ("none" if stnu == "none" else "deflate" if stnu == "archive" else "spool" if best
                        else "files")
        self._lines = Spooled(self.out_dir, ".plans.spool", b"\n")
        self._graphml: Spooled | None = None
        self._stnu_dir: int | None = None
        if stnu == "graphml":
            (self.out_dir / "stnu").mkdir(exist_ok=True)
            self._stnu_dir = open_folder(str(self.out_dir / "stnu"))
        if self.stnu_to in SPOOLED:
            self._graphml = Spooled(self.out_dir, ".stnu.spool", b"")
        # each plan's dispatch form record (`hrc.compile.dispatch_form`), written in rank order at the end;
        # none with --stnu none (such an output cannot be dispatched)
        self._form = None if stnu == "none" else Spooled(self.out_dir, ".form.spool", b"")
        self._codes = bytearray()  # each plan's `plan_code`: to group (`best`), recover and resume them
        self._width = 0  # bytes per plan code
        self._restored = 0  # the first this many plans came from an interrupted run's output (`restore`)
        self._among: dict[tuple, list[tuple]] = {}  # with `best`: the best keys of each allocation so far
        self._cols = {name: array("d") for name in KEY_COLUMNS}
        self._ids = bytearray()  # 16 bytes per plan: its id, padded with spaces
        self._held: list[tuple[tuple, int, CompiledPlan]] = []
        self._best: dict[str, tuple[tuple, int, CompiledPlan]] = {}
        self.extra: dict = {}  # more header entries (the search compile's ``"search"``, `hrc.compile.search`)

    def __len__(self) -> int:
        return len(self._ids) // 16  # the last of a plan's columns `add_record` appends to

    def _settle(self) -> None:
        """Forget what `add_record` appended for a plan it did not finish taking (an interrupt between
        two of its appends): every column as long as the plans taken."""
        n = len(self)
        for spool in (self._lines, self._graphml, self._form):
            if spool is not None:
                for column in (spool.file, spool.at, spool.size):
                    del column[n:]
        for values in self._cols.values():
            del values[n:]
        del self._codes[n * self._width:]

    def add(self, cp: CompiledPlan, tail: str) -> None:
        """Take one compiled plan and its line tail (`compile_records`)."""
        self.add_record((rank_key(cp, self.rank_by), cp.plan.id, cp.plan_class.value, cp.graphml, tail,
                         replace(cp, graphml="", form=b""), plan_code(self.task, cp.plan), cp.form))

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
                keys = self._among.get(allocation_key(self.task, plan))
                if keys is not None and len(keys) >= self.best:
                    among[allocation_key(self.task, plan)] = keys[-1]
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
                allocation = allocation_key(self.task, h[2].plan)
                if taken.get(allocation, 0) < self.best:
                    taken[allocation] = taken.get(allocation, 0) + 1
                    held.append(h)
            self._held = held
        del self._held[self.keep:]

    def add_record(self, record: Record) -> None:
        """Take one plan as `compact_records` sends it (its full record only if it beat the bar; its texts
        or, from a worker on this machine, where the worker wrote them)."""
        key, pid, cls, graphml, tail, light, code, form = record
        i = len(self)
        if isinstance(tail, str):
            self._lines.add_text(tail.encode("utf-8"))
        else:
            self._lines.add_written(tail)
        if isinstance(graphml, str):
            if self._graphml is not None:
                raw = graphml.encode("utf-8")
                self._graphml.add_text(deflated(raw) if self.stnu_to == "deflate" else raw)
            elif self.stnu_to == "files":
                write_stnu_file(self._stnu_dir, str(self.out_dir / "stnu"), pid, graphml)
        elif graphml is not None and self._graphml is not None:
            self._graphml.add_written(graphml)
        if self._form is not None:
            self._form.add_text(form)
        self._width = len(code)
        self._codes += code
        if self.best is not None:
            keys = self._among.setdefault(allocation_key(self.task, plan_from_code(self.task, code)), [])
            if len(keys) < self.best or key < keys[-1]:
                bisect.insort(keys, key)
                del keys[self.best:]
        for name, value in zip(KEY_COLUMNS, key[:-1], strict=True):
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
        cols = [np.frombuffer(self._cols[name], dtype=np.float64) for name in KEY_COLUMNS]
        return np.lexsort([ids, *reversed(cols)])

    def _head_of(self, i: int, rank: int) -> bytes:
        """Plan `i`'s ``compiled.json`` line up to its rank (the rest is its tail in the spool; not read
        through a memory map, whose pages would count as the process's memory)."""
        return line_head(self._id(i), rank).encode("utf-8")

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
        ranked = order.tolist()
        lines = self._lines
        sizes = [len(self._head_of(i, k + 1)) + lines.size[i] for k, i in enumerate(ranked)]
        split = split_lines(sizes, self.inline_max)  # large: the lines to plans.jsonl, rows in compiled.json
        rows = None if split is None else self._rows(ranked[:ROWS_MAX])
        summary = None
        if split is not None:  # the ranking at a glance, once for both headers
            early, worst = (np.frombuffer(self._cols[name], dtype=np.float64)[order] for name in ("early", "worst"))
            summary = ranking_summary(cls_col, early, worst)

        def header_of(form: str | None) -> dict:
            return header_dict(self.task, seed, digest, options, counts, self.stnu,
                               None if partial is None else (n, partial), self.symmetric,
                               None if self.best is None else (self.best, compiled), form, self.extra,
                               None if split is None else (split[0], len(rows or ())), summary)

        # the archive (copied in the kernel: it frees the GIL) or the kept files in a thread, and the lines
        # of a split layout in a second process, while the dispatch form and compiled.json are written here:
        # files from other spools, so the second core shortens the end of a large compile
        # the lines in a forked process (before any thread starts): a thread copying them, 40,000 system
        # calls, waits for the GIL after each while this one writes the form (3.7 s where it takes 0.7 alone)
        plan_lines = None if rows is None else run_apart(functools.partial(self._write_plan_lines, ranked))
        with ThreadPoolExecutor(max_workers=1) as pool:
            writer = self._write_archive if self.stnu == "archive" else self._write_files
            archive = pool.submit(writer, order) if self._graphml is not None else None
            form = None
            if self._form is not None:  # before compiled.json: its header names the form, and the form the lines
                places = line_places(header_of(FORM_PLACEHOLDER), sizes) if split is None else split[1]
                form = self._write_form(order, places, options.rank_by)
            header = header_of(form)
            with open(self.out_dir / "compiled.json", "wb") as out:
                out.write(json_head(header).encode("utf-8"))
                if rows is None:
                    self._copy_lines(out, ranked, b",\n", b"")
                else:
                    out.write(",\n".join(rows).encode("utf-8"))
                out.write(JSON_TAIL.encode("utf-8"))
            if plan_lines is not None and not plan_lines():  # it failed: written here (or the error said)
                self._write_plan_lines(ranked)
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

    def _copy_lines(self, out: BinaryIO, ranked: list[int], between: bytes, after: bytes) -> None:
        """Write the lines of the plans `ranked` (indices, rank order) to `out`, `between` before each but
        the first and `after` after each: each line's head, then its tail copied from its spool (in the
        kernel where the file system can)."""
        lines = self._lines
        fds = lines.fds()
        copy = kernel_copy if hasattr(os, "copy_file_range") else None
        for k, i in enumerate(ranked):
            head = (between if k else b"") + self._head_of(i, k + 1)
            fd, start, size = fds[lines.file[i]], lines.at[i], lines.size[i]
            if copy is not None:  # the line's tail copied from spool to file in the kernel
                out.write(head)
                out.flush()
                if copy(fd, out.fileno(), size, start):
                    if after:
                        out.write(after)
                    continue
                copy = None  # not on this file system: read and write from here on
                out.seek(0, os.SEEK_END)
            else:
                out.write(head)
            out.write(os.pread(fd, size, start) + after)

    def _write_plan_lines(self, ranked: list[int]) -> bool:
        """`PLAN_LINES`: every plan's line, rank order, one a line (True: written)."""
        with open(self.out_dir / PLAN_LINES, "wb") as out:
            self._copy_lines(out, ranked, b"", b"\n")
        return True

    def _rows(self, ranked: list[int]) -> list[str]:
        """The rows of a split ``compiled.json`` for the plans `ranked` (indices, rank order), from the
        compact records: class, makespans and preference from the rank key's columns (makespans are whole
        ticks, so the columns' six decimals round to the line's three alike), sequences from the codes read
        as arrays (`code_sequences`: what `plan_from_code` gives, without a `Plan` per row)."""
        if not ranked:
            return []
        agents, actions = self.task.agent_ids, self.task.action_ids
        codes = np.frombuffer(bytes(self._codes), dtype=np.uint16).reshape(len(self), self._width // 2)
        sequences = code_sequences(self.task, codes[ranked]).tolist()
        cls, early, worst, pref = (np.frombuffer(self._cols[name], dtype=np.float64)[ranked].tolist()
                                   for name in ("cls", "early", "worst", "pref"))
        return [plan_row(self._id(i), k + 1, _CLASS_NAMES[int(cls[k])],
                         [(agent, [actions[x] for x in seq if x >= 0])
                          for agent, seq in zip(agents, sequences[k], strict=True)],
                         (early[k], worst[k]) if math.isfinite(worst[k]) else None,
                         None if math.isinf(pref[k]) else -pref[k])
                for k, i in enumerate(ranked)]

    def _resume_rows(self) -> np.ndarray:
        """Every plan taken so far as one row of `resume_dtype`, in the order taken."""
        n, width = len(self), self._width // 2
        rows = np.zeros(n, dtype=resume_dtype(width))
        for name in KEY_COLUMNS:
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
        source = lines_path(old)  # compiled.json, or plans.jsonl beside a split one
        tails = line_tails(source)
        # the old lines are copied from the old file as from a worker's spool (linked here)
        spool = ".plans.resumed.spool"
        link_or_copy(source, self.out_dir / spool)
        classes = {c.order: c.value for c in PlanClass}
        archive = zipfile.ZipFile(old / STNU_ARCHIVE) if (old / STNU_ARCHIVE).is_file() else None
        old_form = self._old_form(old)
        try:
            for row in rows:
                pid = row["id"].decode("ascii").rstrip(" ")
                place = tails.get(pid)
                if place is None and self.best is None:
                    raise InputError(str(old / RESUME_FILE), "", f"--resume: plan {pid} is not in compiled.json")
                key = (*(float(row[name]) for name in KEY_COLUMNS), pid)
                graphml: str | None = ""  # "": none; None: its file is in place
                if self.stnu_to == "files":
                    graphml = None
                    if place is not None:
                        link_or_copy(old / "stnu" / f"{pid}.graphml", self.out_dir / "stnu" / f"{pid}.graphml")
                elif place is not None and self.stnu_to in SPOOLED:
                    graphml = (archive.read(f"stnu/{pid}.graphml").decode("utf-8") if archive is not None
                               else (old / "stnu" / f"{pid}.graphml").read_text(encoding="utf-8"))
                tail: str | Written = "" if place is None else (spool, *place)
                form = b"" if place is None or self._form is None else old_form(pid, row["code"].tobytes(), place)
                self.add_record((key, pid, classes[int(row["cls"])], graphml, tail, None, row["code"].tobytes(), form))
        finally:
            if archive is not None:
                archive.close()
        self._restored = len(self)
        return frozenset(self._id(i) for i in range(self._restored))

    def _old_form(self, old: Path) -> Callable[[str, bytes, tuple[int, int]], bytes]:
        """How to get an interrupted run's plan's dispatch form record, from its id, `plan_code` and line's
        place: from that run's form, or where it has none (written before there was one), from its GraphML
        and its line (whether it was blocked)."""
        header = read_header(old)
        meta = header.get("dispatch_form")
        if isinstance(meta, dict):
            form = read_form(old, self.task, self.rank_by, expected=meta.get("sha256"))
            index = {form.plan_id(p): p for p in range(len(form))}
            return lambda pid, code, place: form.record(index[pid])
        archive = zipfile.ZipFile(old / STNU_ARCHIVE) if (old / STNU_ARCHIVE).is_file() else None

        def from_graphml(pid: str, code: bytes, place: tuple[int, int]) -> bytes:
            where = f"{old}/stnu/{pid}.graphml"
            text = archive.read(f"stnu/{pid}.graphml") if archive is not None else Path(where).read_bytes()
            with open(lines_path(old, header), "rb") as f:
                f.seek(place[0])
                line = json.loads(b'{"id":"","rank":0,' + f.read(place[1]).rstrip(b",\n"))
            blocked = line.get("pattern", {}).get("candidates") == 0
            return plan_record(self.task, plan_from_code(self.task, code), read_graphml(text, where), blocked,
                               graphml_names=True, where=where)

        return from_graphml

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
        if self.task.has_crew_choice:  # a joint action's crew: the agents holding it (`allocation_key`)
            np.bitwise_or.at(allocation, (rows, codes[rows, cols]), (1 << agent[rows, cols]).astype(np.uint16))
        else:
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

        Deflate level 1 (`ARCHIVE_LEVEL`): level 1 deflates kitting_7picks' GraphML (40,320 files, 1.25
        GB) in about 6 s where the default level took 17 s, for an archive about a quarter larger (135 MB).
        The spool holds each file deflated already (`hrc.compile.spool.deflated`: by the workers, as the
        plans were compiled), so the archive is laid out around those bytes (`write_deflated_zip`); one
        too large for that layout is written by `zipfile` from the same files inflated again."""
        spool = self._graphml
        assert spool is not None
        ranked = order.tolist()
        names = [f"stnu/{self._id(i)}.graphml" for i in ranked]
        if not needs_zip64(names, [spool.size[i] for i in ranked]):
            fds = spool.fds()
            with open(self.out_dir / STNU_ARCHIVE, "wb") as out:
                write_deflated_zip(out, names, [(fds[spool.file[i]], spool.at[i], spool.size[i]) for i in ranked])
            return
        with zipfile.ZipFile(self.out_dir / STNU_ARCHIVE, "w", zipfile.ZIP_DEFLATED) as zf:
            for name, i in zip(names, ranked, strict=True):
                info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = 0o644 << 16
                zf.writestr(info, zlib.decompress(spool.read(i)[DEFLATED_HEAD.size:], -15), compresslevel=ARCHIVE_LEVEL)

    def _write_files(self, order: np.ndarray) -> None:
        """The GraphML files of the plans in `order` (the kept ones, with `best`) from the spool."""
        spool = self._graphml
        assert spool is not None
        for i in order.tolist():
            write_stnu_file(self._stnu_dir, str(self.out_dir / "stnu"), self._id(i), spool.read(i))

    def _write_form(self, order: np.ndarray, places: Sequence[tuple[int, int]], rank_by: str) -> str:
        """The dispatch form of the plans in `order` (rank order), from the spooled records; the SHA-256
        of its ``form.json``. `places`: where each plan's line lies in ``compiled.json``. In blocks of
        `_FORM_BLOCK` plans, each read as arrays (`FormWriter.add_many`, `code_sequences`)."""
        spool = self._form
        assert spool is not None
        codes = np.frombuffer(bytes(self._codes), dtype=np.uint16).reshape(len(self), self._width // 2)
        cls_col = np.frombuffer(self._cols["cls"], dtype=np.float64)
        pref_col = np.frombuffer(self._cols["pref"], dtype=np.float64)
        ranked = order.tolist()
        for wide in (False, True):
            writer = FormWriter(self.out_dir, self.task, rank_by, wide)
            try:
                for start in range(0, len(ranked), _FORM_BLOCK):
                    block = ranked[start:start + _FORM_BLOCK]
                    at = places[start:start + _FORM_BLOCK]
                    writer.add_many([self._id(i) for i in block], [_CLASS_NAMES[int(cls_col[i])] for i in block],
                                    [None if math.isinf(p := float(pref_col[i])) else -p for i in block],
                                    code_sequences(self.task, codes[block]), [spool.read(i) for i in block],
                                    [a for a, _ in at], [n for _, n in at])
            except OverflowError:
                writer.abandon()
                if wide:  # pragma: no cover - every bound of the temporal core fits 64 bits
                    raise
                continue
            except BaseException:
                writer.abandon()
                raise
            return writer.close()
        raise AssertionError("unreachable")  # pragma: no cover

    def _close(self) -> None:
        if self._stnu_dir is not None:
            os.close(self._stnu_dir)
            self._stnu_dir = None
        for spool in (self._lines, self._graphml, self._form):
            if spool is not None:
                spool.close()
        # this process's spools and every worker's, also those whose plans never arrived (interrupted)
        for path in [*self.out_dir.glob(".plans*.spool"), *self.out_dir.glob(".stnu*.spool"),
                     *self.out_dir.glob(".form*.spool")]:
            with contextlib.suppress(FileNotFoundError):
                path.unlink()

    def _drop_unlisted(self) -> None:
        """Remove the GraphML files of plans the sink never took: after an interrupt, workers writing
        into ``stnu/`` themselves (`WorkerFiles`) may have written plans whose records never came."""
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
