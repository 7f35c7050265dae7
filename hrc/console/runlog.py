"""Where a console run's log goes: a new file per run, never an old one overwritten.

The log itself is the dispatcher's (`hrc.dispatch.protocol.Log`: a header, then every line in and every
answer, flushed and synced before the answer is given), so that ``hrc dispatch OUT_DIR --replay LOG``
replays a console run like any other.
"""

from __future__ import annotations

import os
from pathlib import Path

from hrc.dispatch import Dispatcher
from hrc.dispatch.protocol import Log

__all__ = ["next_log_path", "open_log"]


def next_log_path(out_dir: str | os.PathLike[str]) -> Path:
    """``OUT_DIR/runs/console-N.jsonl`` for the first N not yet taken (runs never overwrite each other)."""
    folder = Path(out_dir) / "runs"
    n = 1
    while (folder / f"console-{n}.jsonl").exists():
        n += 1
    return folder / f"console-{n}.jsonl"


def open_log(path: str | os.PathLike[str], dispatcher: Dispatcher) -> Log:
    """The dispatcher's log at `path`, a new file (its folder made if missing); `FileExistsError` if it exists.

    A console run has a file of its own: the dispatcher's `Log` appends, and a replay takes the last
    session of a file, so an old file would work, but one file per run is easier to find and to keep.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "x", encoding="utf-8"):
        pass
    return Log(path, dispatcher)
