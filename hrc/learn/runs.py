"""Recorded runs read back: what the person and the robot were seen doing, and when, run by run.

Three kinds of record hold the same events (docs/learn.md):

- a **dispatcher log** (`hrc.dispatch.logfile`, read with its own reader `read_log`): every message a
  dispatcher was given and its answer, from ``hrc dispatch --log``, the console, ``hrc ros2``, or
  ``hrc simulate --keep-logs`` (one per run, ``runs/POLICY-NNNN.jsonl`` in the output folder);
- an ``hrc simulate`` **output folder** (its ``runs/*.jsonl``), or a folder of logs or recordings;
- an **MCAP recording** (`hrc.record`, read with the ``mcap`` package): its ``/hrc/in`` and ``/hrc/out``
  channels are the same messages and answers.

Only what the dispatcher *accepted* is used: a message it refused changed nothing on the floor either
(a refused observation is one the dispatcher did not believe). With a motion detector in front
(``--detect motion``), the events are the ones it gave, each at the time it *estimated* the event
happened, and given when a later position came (the position's time: the sensing path's delay is the
difference); a withdrawn departure (``undo``) takes back the one it withdrew.

**Guard rails.** A record from another task is refused whole (`RunFileError`, one line: its header's
task digest is not this task's, `hrc.compile.compiler.task_digest`): bounds learned from another task's
runs would be wrong without anyone noticing. A bad message (not JSON, not an observation, an answer that
is not JSON) is reported with its place (``FILE:LINE``) and skipped, never used; a log damaged before its
end (the log reader refuses it) is reported and skipped whole; a torn end is dropped and reported.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hrc.errors import InputError, RunFileError
from hrc.model import Task

__all__ = ["LEG_EVENTS", "Run", "Seen", "Skipped", "expand_runs", "read_run", "read_runs"]

LEG_EVENTS = ("depart", "park", "unpark", "arrive", "start", "end")
_TOLD = 5  # bad messages reported one by one per file; the rest counted


@dataclass(frozen=True, slots=True)
class Seen:
    """One event of a run: `agent` did `event` of `action`.`phase` at `t` (s from the task's start);
    `at`: when a motion detector gave it to the dispatcher (None: as it happened, e.g. a button)."""

    t: float
    agent: str
    action: str
    phase: str
    event: str
    at: float | None = None


@dataclass(frozen=True, slots=True)
class Run:
    """One recorded run: where it came from and the events seen, in the order they were accepted."""

    source: str
    events: tuple[Seen, ...]

    def sequence(self, agent: str) -> tuple[str, ...]:
        """The actions `agent` set off for, in order (its choices)."""
        return tuple(dict.fromkeys(e.action for e in self.events if e.agent == agent and e.event == "depart"))


@dataclass(frozen=True, slots=True)
class Skipped:
    """Something in a record that was not used: where (``FILE`` or ``FILE:LINE``) and why."""

    place: str
    why: str

    def __str__(self) -> str:
        return f"{self.place}: {self.why}"


def expand_runs(paths: Sequence[str | os.PathLike[str]]) -> list[Path]:
    """The record files the RUNS arguments name, in a fixed order: a file as it is; a folder's ``*.jsonl``
    and ``*.mcap`` (an ``hrc simulate`` output folder: its ``runs/``). Raises `InputError` for a path that
    does not exist or a folder that holds no records."""
    out: list[Path] = []
    for raw in paths:
        path = Path(raw)
        if path.is_file():
            out.append(path)
            continue
        if not path.is_dir():
            raise InputError(str(path), "", "no such run file or folder")
        folder = path / "runs" if (path / "runs").is_dir() else path
        found = sorted(p for p in folder.iterdir() if p.suffix in (".jsonl", ".mcap", ".log") and p.is_file())
        if not found:
            hint = (" (an hrc simulate output without --keep-logs: simulate again with it)"
                    if (path / "simulation.json").is_file() else "")
            raise InputError(str(path), "", f"holds no run records (*.jsonl logs or *.mcap recordings){hint}")
        out += found
    return out


def _check_task(file: str, key: str, digest: Any, want: str) -> None:
    if digest is None:
        raise RunFileError(file, key, "names no task digest (recorded before hrc learn could check it): "
                                      "cannot tell it is a run of this task")
    if digest != want:
        raise RunFileError(file, key, f"a run of another task (task digest {str(digest)[:12]}..., this task "
                                      f"{want[:12]}...): learn from this task's runs only")


class _Events:
    """Builds a run's events from exchanges (message, answer), reporting the bad ones."""

    def __init__(self, file: str) -> None:
        self.file = file
        self.events: list[Seen] = []
        self.skipped: list[Skipped] = []
        self.bad = 0

    def _skip(self, line: int | None, why: str) -> None:
        self.bad += 1
        if self.bad <= _TOLD:
            self.skipped.append(Skipped(self.file if line is None else f"{self.file}:{line}", why))

    def take(self, data: bytes, answer_text: str, line: int | None) -> None:
        try:
            answer = json.loads(answer_text)
        except ValueError:
            self._skip(line, "its answer is not JSON: skipped")
            return
        if not isinstance(answer, dict) or answer.get("ok") is not True:
            return  # refused by the dispatcher: it changed nothing, so it tells nothing
        try:
            msg = json.loads(data.decode("utf-8"))
        except (UnicodeDecodeError, ValueError, RecursionError):
            self._skip(line, "a message that is not JSON, yet accepted: skipped")
            return
        if not isinstance(msg, dict):
            self._skip(line, "a message that is not a JSON object: skipped")
            return
        if msg.get("event") == "position":
            detect = answer.get("detect")
            for ev in (detect.get("events", ()) if isinstance(detect, dict) else ()):
                if isinstance(ev, dict) and ev.get("event") == "undo":
                    human = [i for i, e in enumerate(self.events) if e.at is not None]
                    if human:
                        del self.events[human[-1]]
                    continue
                self._event(ev, line, msg.get("t"))  # given when this position came
            return
        if msg.get("event") in LEG_EVENTS:
            self._event(msg, line, None)

    def _event(self, obj: Any, line: int | None, at: Any) -> None:
        try:
            t = obj["t"]
            parts = [obj["agent"], obj["action"], obj["phase"], obj["event"]]
            if isinstance(t, bool) or not isinstance(t, int | float) or not all(isinstance(p, str) for p in parts):
                raise TypeError
            if at is not None and (isinstance(at, bool) or not isinstance(at, int | float)):
                raise TypeError
        except (KeyError, TypeError):
            self._skip(line, "an event without a time, agent, action, phase or event: skipped")
            return
        agent, action, phase, event = parts
        self.events.append(Seen(float(t), agent, action, phase, event, None if at is None else float(at)))

    def finish(self) -> None:
        if self.bad > _TOLD:
            self.skipped.append(Skipped(self.file, f"{self.bad - _TOLD} more bad messages skipped"))


def _read_log(file: Path, want: str) -> tuple[Run | None, list[Skipped]]:
    from hrc.dispatch.logfile import read_log

    try:
        contents = read_log(file)
    except InputError as err:  # damaged before its end, or not a log at all: nothing of it is used
        place = err.file + (f":{err.line}" if err.line else "")
        return None, [Skipped(place, f"{err.message}: the whole file skipped")]
    _check_task(str(file), "header.task", contents.header.get("task"), want)
    events = _Events(str(file))
    skipped: list[Skipped] = []
    if contents.torn is not None:
        skipped.append(Skipped(str(file), str(contents.torn)))
    for m in contents.messages:
        events.take(m.data, m.answer, m.message_line or None)
    events.finish()
    return Run(str(file), tuple(events.events)), skipped + events.skipped


def _read_mcap(file: Path, want: str) -> tuple[Run | None, list[Skipped]]:
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    events = _Events(str(file))
    try:
        with open(file, "rb") as fh:
            reader = make_reader(fh)
            meta = {m.name: dict(m.metadata) for m in reader.iter_metadata()}.get("hrc", {})
            _check_task(str(file), "metadata.hrc.task_digest", meta.get("task_digest"), want)
            pending: bytes | None = None
            n = 0
            for _, channel, message in reader.iter_messages(topics=["/hrc/in", "/hrc/out"], log_time_order=False):
                n += 1
                if channel.topic == "/hrc/in":
                    pending = message.data
                elif pending is not None:
                    events.take(pending, message.data.decode("utf-8", "replace"), None)
                    pending = None
                else:
                    events._skip(None, f"an answer without its message (message {n}): skipped")
    except (McapError, OSError, ValueError, KeyError, EOFError) as err:  # (a RunFileError goes through)
        return None, [Skipped(str(file), f"not a readable MCAP recording ({type(err).__name__}: {err}): "
                                         "the whole file skipped")]
    events.finish()
    return Run(str(file), tuple(events.events)), events.skipped


def read_run(file: str | os.PathLike[str], task_digest: str) -> tuple[Run | None, list[Skipped]]:
    """One record file: its run (None if nothing of it is usable) and what was skipped in it. Raises
    `RunFileError` when it is a run of another task (`task_digest` is the task's)."""
    path = Path(file)
    return (_read_mcap if path.suffix == ".mcap" else _read_log)(path, task_digest)


def read_runs(task: Task, paths: Sequence[str | os.PathLike[str]]) -> tuple[tuple[Run, ...], tuple[Skipped, ...]]:
    """Every run the RUNS arguments name (`expand_runs`), read and checked against `task`."""
    from hrc.io.task_file import task_digest

    want = task_digest(task)
    runs: list[Run] = []
    skipped: list[Skipped] = []
    for file in expand_runs(paths):
        run, skip = read_run(file, want)
        skipped += skip
        if run is not None:
            runs.append(run)
    return tuple(runs), tuple(skipped)
