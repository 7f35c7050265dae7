"""The resume format: what a partial output keeps so that ``hrc compile --resume`` goes on from it.

Beside a partial ``compiled.json`` (an interrupted compile, ``"partial": true``) the sink writes
``resume.npy`` (`RESUME_FILE`): one row per plan compiled, with its exact rank key (`KEY_COLUMNS`), its
id and its `hrc.plans.plan_code`, in a structured numpy array (no pickle, deterministic bytes).
`read_resume` checks that a folder is a partial output of the same task and options before any work;
`line_tails` finds where each plan's line sits in the old ``compiled.json`` (or ``plans.jsonl`` beside a
large one, `hrc.compile.output.lines_path`), so that the resumed run
copies the old lines instead of compiling their plans again (`hrc.compile.sink.PlanSink.restore`).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from hrc.compile.compiler import CompileOptions
from hrc.compile.output import SCHEMA_VERSION, SPLIT_SCHEMA_VERSION, header_dict
from hrc.errors import InputError
from hrc.io.task_file import task_digest
from hrc.model import Task
from hrc.plans import identical_actions

__all__ = ["KEY_COLUMNS", "RESUME_FILE", "line_tails", "read_resume", "resume_dtype"]

KEY_COLUMNS = ("cls", "second", "pref", "first", "worst", "early", "idle")  # rank_key without the id
"""The rank key's columns as the sink keeps them (`hrc.compile.compiler.rank_key` without the id)."""

RESUME_FILE = "resume.npy"
"""Beside a partial ``compiled.json``: what ``hrc compile --resume`` needs of every plan compiled."""


def resume_dtype(width: int) -> np.dtype:
    """A ``resume.npy`` row: the rank key's columns (exact), the id, the `plan_code` (`width` numbers)."""
    return np.dtype([*((name, "<f8") for name in KEY_COLUMNS), ("id", "S16"), ("code", "<u2", (width,))])


_RESUMED_KEYS = ("generator", "seed", "options", "task", "stnu_files", "stnu_archive", "identical_actions",
                 "best_per_allocation")
"""What an interrupted run's ``compiled.json`` must say as the resumed run would (`read_resume`); its
``schema_version`` may be either layout's (its lines are the same wherever they are: `line_tails`)."""


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
    if old.get("schema_version") not in (SCHEMA_VERSION, SPLIT_SCHEMA_VERSION):
        raise InputError(str(compiled), "schema_version", f"--resume: {json.dumps(old.get('schema_version'))} is no "
                                                          "schema this hrc writes; compile into a new --out")
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
    if rows.ndim != 1 or names[:len(KEY_COLUMNS) + 1] != (*KEY_COLUMNS, "id") or "code" not in names:
        raise InputError(str(path), "", "--resume: not the rows hrc compile writes")
    return rows


def line_tails(path: Path) -> dict[str, tuple[int, int]]:
    """Where each plan line of ``compiled.json`` or ``plans.jsonl`` (`path`) has its tail (after its id and
    rank, `line_head`): offset and length, by plan id. Read line by line: a partial output's lines can be
    gigabytes in all."""
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

