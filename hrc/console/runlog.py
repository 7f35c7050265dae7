"""Where a console run's log goes: a new file per run, never an old one overwritten; or the log of a run
to resume.

The log itself is the dispatcher's (`hrc.dispatch.logfile`, written ahead of every change by
`hrc.dispatch.durable.LoggedDispatcher`), so that ``hrc dispatch OUT_DIR --replay LOG`` replays a console
run like any other, and ``hrc console OUT_DIR --resume LOG`` (or ``hrc dispatch --resume``) continues it.
"""

from __future__ import annotations

import os
from pathlib import Path

from hrc.dispatch import Dispatcher
from hrc.dispatch.durable import LoggedDispatcher, Resumed

__all__ = ["next_log_path", "open_log", "resume_log"]


def next_log_path(out_dir: str | os.PathLike[str]) -> Path:
    """``OUT_DIR/runs/console-N.jsonl`` for the first N not yet taken (runs never overwrite each other)."""
    folder = Path(out_dir) / "runs"
    n = 1
    while (folder / f"console-{n}.jsonl").exists():
        n += 1
    return folder / f"console-{n}.jsonl"


def open_log(path: str | os.PathLike[str], dispatcher: Dispatcher) -> LoggedDispatcher:
    """`dispatcher` logged to `path`, a new file (its folder made if missing); `InputError` when the file
    holds a run already (resume it instead) or another process holds it."""
    return LoggedDispatcher.create(dispatcher, path)


def resume_log(path: str | os.PathLike[str], dispatcher: Dispatcher) -> tuple[LoggedDispatcher, Resumed]:
    """The run logged at `path` rebuilt in `dispatcher` (fresh), to go on appending to its log."""
    return LoggedDispatcher.resume(dispatcher, path)
