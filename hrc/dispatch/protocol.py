"""The dispatcher's JSON-lines protocol, its log, and replay (docs/dispatch.md).

One JSON object per line in, exactly one JSON object per line out: the `Decision` (``"ok": true``) or a
refusal ``{"t": ..., "ok": false, "error": "one line"}`` that changed nothing. `handle_line` never raises.

The log (`Log`) is JSON lines too: a header ``{"hrc_dispatch_log": 1, "compiled": DIGEST, "plans": N}``,
then for every message ``{"in": LINE}`` and ``{"out": LINE}``, appended, flushed and fsync'd before the
answer is given, so a crash loses nothing already answered. `replay` feeds a log's inputs to a new
dispatcher over the same compiled folder and yields each answer with the logged one.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from hrc.errors import DispatchError, HrcError, InputError

from .dispatcher import Dispatcher
from .messages import observation_from_json

__all__ = ["LOG_VERSION", "MAX_LINE", "Log", "handle_line", "read_log", "replay", "serve"]

LOG_VERSION = 1
MAX_LINE = 65536
"""Longest message accepted, in bytes (a longer one is refused)."""


def _dumps(obj: Any) -> str:
    return json.dumps(obj, ensure_ascii=False, allow_nan=False)


def _refusal(t: Any, reason: str) -> str:
    if isinstance(t, bool) or not isinstance(t, int | float) or t != t or t in (float("inf"), float("-inf")):
        t = None
    return _dumps({"t": t, "ok": False, "error": " ".join(reason.split())[:500]})


def handle_line(dispatcher: Dispatcher, line: str) -> str:
    """Answer one message line (see the module docstring); never raises, refusals change nothing."""
    if len(line.encode("utf-8", "surrogatepass")) > MAX_LINE:
        return _refusal(None, f"message longer than {MAX_LINE} bytes")
    try:
        obj = json.loads(line)
    except ValueError as err:
        return _refusal(None, f"not JSON: {err}")
    t = obj.get("t") if isinstance(obj, dict) else None
    try:
        decision = dispatcher.observe(observation_from_json(obj))
    except DispatchError as err:
        return _refusal(t, str(err))
    except Exception as err:  # noqa: BLE001 - a bug must not end a run; the state was not changed
        return _refusal(t, f"internal error ({type(err).__name__}: {err}); nothing changed")
    return _dumps(decision.to_json())


def _digest(dispatcher: Dispatcher) -> str:
    return dispatcher.plan_set.digest


class Log:
    """An append-only, fsync'd log of a dispatch session (see the module docstring)."""

    def __init__(self, path: str | os.PathLike[str], dispatcher: Dispatcher) -> None:
        self.path = Path(path)
        if self.path.exists() and not self.path.is_file():
            raise InputError(str(self.path), "", "the log must be a regular file")
        header = {"hrc_dispatch_log": LOG_VERSION, "compiled": _digest(dispatcher),
                  "plans": len(dispatcher.plan_set)}
        self._file: IO[str] = open(self.path, "a", encoding="utf-8")  # noqa: SIM115 - closed by close()
        self._write(_dumps(header))

    def _write(self, *lines: str) -> None:
        self._file.write("".join(line + "\n" for line in lines))
        self._file.flush()
        os.fsync(self._file.fileno())

    def record(self, line_in: str, line_out: str) -> None:
        self._write(_dumps({"in": line_in}), _dumps({"out": line_out}))

    def close(self) -> None:
        self._file.close()


def read_log(path: str | os.PathLike[str]) -> tuple[dict[str, Any], list[tuple[str, str | None]]]:
    """The header of the log's last session and its ``(in, out)`` pairs (out None where the log ends
    after an input). Raises `InputError` naming the line at fault."""
    file = str(path)
    header: dict[str, Any] | None = None
    pairs: list[tuple[str, str | None]] = []
    try:
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(file, "", f"cannot read the log: {err}") from err
    for number, raw in enumerate(text.splitlines(), 1):
        if not raw.strip():
            continue
        try:
            rec = json.loads(raw)
        except ValueError as err:
            raise InputError(file, "", f"not a JSON line ({err})", number) from err
        if isinstance(rec, dict) and "hrc_dispatch_log" in rec:
            header, pairs = rec, []  # a new session appended to the same file: replay the last one
        elif isinstance(rec, dict) and isinstance(rec.get("in"), str) and header is not None:
            pairs.append((rec["in"], None))
        elif isinstance(rec, dict) and isinstance(rec.get("out"), str) and pairs and pairs[-1][1] is None:
            pairs[-1] = (pairs[-1][0], rec["out"])
        else:
            raise InputError(file, "", "expected a header, then {\"in\": ...} / {\"out\": ...} records", number)
    if header is None:
        raise InputError(file, "", "not an hrc dispatch log (no header line)")
    return header, pairs


def replay(dispatcher: Dispatcher, path: str | os.PathLike[str]) -> Iterator[tuple[str, str | None]]:
    """Feed the log's inputs to `dispatcher` (fresh, over the same compiled folder); yield each answer
    with the logged one. Raises `HrcError` when the log was written for another compiled folder."""
    header, pairs = read_log(path)
    if header.get("compiled") != _digest(dispatcher):
        raise HrcError(f"{path}: the log was written for another compiled plan set "
                       f"(compiled {header.get('compiled')!r}, this folder {_digest(dispatcher)!r})")
    for line_in, line_out in pairs:
        yield handle_line(dispatcher, line_in), line_out


def serve(dispatcher: Dispatcher, stream_in: IO[bytes], stream_out: IO[str], log: Log | None = None) -> int:
    """Answer every line of `stream_in` on `stream_out` (flushed at once) until end of input; 0."""
    while True:
        raw = stream_in.readline(MAX_LINE + 1)
        if not raw:
            return 0
        if len(raw) > MAX_LINE and not raw.endswith(b"\n"):
            while True:  # drop the rest of an over-long line
                more = stream_in.readline(MAX_LINE)
                if not more or more.endswith(b"\n"):
                    break
            line, out = "<over-long line>", _refusal(None, f"message longer than {MAX_LINE} bytes")
        else:
            try:
                line = raw.decode("utf-8").rstrip("\r\n")
                out = handle_line(dispatcher, line)
            except UnicodeDecodeError:
                line, out = raw.decode("utf-8", "replace").rstrip("\r\n"), _refusal(None, "message is not UTF-8")
        if log is not None:
            log.record(line, out)
        stream_out.write(out + "\n")
        stream_out.flush()
