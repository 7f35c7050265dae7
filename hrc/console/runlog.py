"""The run's log file: every line the console gave the dispatcher, and its answer, on disk before
anyone is told the answer (so a crash loses nothing already acknowledged).

Format: JSON lines as ``hrc dispatch`` reads and writes them: each message in, then its answer.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import IO

__all__ = ["RunLog", "next_log_path"]


def next_log_path(out_dir: str | os.PathLike[str]) -> Path:
    """``OUT_DIR/runs/console-N.jsonl`` for the first N not yet taken (runs never overwrite each other)."""
    folder = Path(out_dir) / "runs"
    n = 1
    while (folder / f"console-{n}.jsonl").exists():
        n += 1
    return folder / f"console-{n}.jsonl"


class RunLog:
    """Append-only; each `write` is flushed and synced. `path=None` keeps nothing (tests of the page)."""

    def __init__(self, path: str | os.PathLike[str] | None) -> None:
        self.path = None if path is None else Path(path)
        self._file: IO[str] | None = None
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._file = open(self.path, "x", encoding="utf-8")  # noqa: SIM115 - lives as long as the run

    def write(self, line_in: str, line_out: str) -> None:
        if self._file is None:
            return
        self._file.write(line_in + "\n" + line_out + "\n")
        self._file.flush()
        os.fsync(self._file.fileno())

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None
