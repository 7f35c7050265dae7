"""Fault injection for the online half (issue 26, items 3, 4 and 6): the dispatcher and the console
killed, starved of disk, fed torn logs, bad lines and floods, and what must hold each time.

Independent truth: a recorded session (the test client of tests/dispatch_client.py playing a valid
workshop run, with the issue's bad lines slipped in) answered in-process, message by message, by a
dispatcher that never saw a log. Every run here, however it is interrupted, must end with exactly those
answers, in its output and in its log, and the log must replay to them byte for byte.

- ``kill -9`` of ``hrc dispatch --log`` at 20 random points (5 in the default run, the other 15 with
  ``-m slow``), each followed by ``--resume``: nothing answered is missing from the log, the resumed run
  answers the rest as the uninterrupted one did;
- a log on a full file system (a small tmpfs, as root where ``mount`` works; always also a writer that
  fails on demand, in-process): the message is refused in one line, nothing changes, and the same
  message is accepted once there is room; in the console, the page says so;
- torn logs cut at every record boundary and inside records; a damaged middle is refused;
- bad lines (20,000 nested ``[``, over-long, not UTF-8, U+2028 / U+0085, a lone surrogate, a 5,000-digit
  number) get one-line refusals, are logged losslessly and replay;
- floods: 10,000 ticks a second and 10,000 impossible presses to ``hrc dispatch``; 10,000 impossible
  presses to the console while the robot acknowledges (answered within 100 ms) and memory stays flat.
"""

from __future__ import annotations

import base64
import contextlib
import json
import os
import queue
import random
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from conftest import ROOT, compiled_folder
from dispatch_client import Run

from hrc.dispatch import Dispatcher
from hrc.dispatch.durable import LoggedDispatcher
from hrc.dispatch.limits import MAX_LINE
from hrc.dispatch.logfile import LogWriter, read_log
from hrc.dispatch.plan_set import load_plan_set
from hrc.dispatch.protocol import answer, replay
from hrc.errors import InputError

TIMEOUT = 60.0  # s: any one wait for a process

# The bad lines, and a few more; none of them may change the state.
BAD_LINES = [
    b"[" * 20_000,
    b'{"a":' * 20_000,
    b"\xff\xfe not UTF-8 \x80",
    '{"t": 0, "agent": "human", "action": "cube\u20281", "phase": "fetch", "event": "start"}'.encode(),
    '{"t": 0, "agent": "human", "action": "cube\u00851", "phase": "fetch", "event": "start"}'.encode(),
    '{"t": 0,\u2028"event": "tick"}'.encode(),
    b'{"t": 0, "event": "undo"}\r',
    b'{"t": 0, "agent": "human", "action": "\\ud800", "phase": "fetch", "event": "start"}',
    b"x" * 200_000,
    b"",
    b"\x00\x00",
    b'{"t": 1e999, "event": "tick"}',
    b'{"t": ' + b"9" * 5000 + b', "event": "tick"}',
    '{"t": 0, "event": "tick", "next": "\u000c\u001c\u001d\u001e\u0085\u2029"}'.encode(),
]


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return compiled_folder(tmp_path_factory.mktemp("faults") / "ws")


@pytest.fixture(scope="module")
def fresh(folder: Path) -> Dispatcher:
    """A dispatcher that is never given a message: `.fork()` it for a fresh one (no reload)."""
    return Dispatcher.from_folder(folder)


@pytest.fixture(scope="module")
def session(folder: Path, fresh: Dispatcher) -> tuple[list[bytes], list[str]]:
    """A recorded workshop run, bad lines included: its lines and their uninterrupted answers."""
    d = fresh.fork()
    lines: list[bytes] = []
    answers: list[str] = []
    rng = random.Random(11)
    bad = iter(BAD_LINES)

    def say(data: bytes) -> str:
        lines.append(data)
        answers.append(answer(d, data))
        return answers[-1]

    def send(line: str) -> str:
        if rng.random() < 0.3:
            extra = next(bad, None)
            if extra is not None:
                say(extra)
        return say(line.encode())

    Run(load_plan_set(folder), send, 11, human_choice="random", timing="eager").play()
    for extra in bad:
        say(extra)
    assert sum(json.loads(a)["ok"] for a in answers) >= 30  # a real run, not just refusals
    assert all(not json.loads(answers[lines.index(b)])["ok"] for b in BAD_LINES)
    return lines, answers


# -- a process and its pipes, every wait bounded ---------------------------------------------------
class Dispatch:
    """``hrc dispatch FOLDER ARGS`` with its stdin written by a thread and its output read by others;
    a context manager that kills it (if still running) and closes its pipes."""

    def __init__(self, folder: Path, *args: str) -> None:
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        self.proc = subprocess.Popen([sys.executable, "-m", "hrc", "dispatch", str(folder), *args], cwd=ROOT, env=env,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        self.lines: queue.Queue[bytes] = queue.Queue()
        self._err: list[bytes] = []
        self._writes: queue.Queue[bytes | None] = queue.Queue()
        self._threads = [threading.Thread(target=self._read, daemon=True),
                         threading.Thread(target=self._read_err, daemon=True),
                         threading.Thread(target=self._write, daemon=True)]
        for thread in self._threads:
            thread.start()

    def __enter__(self) -> Dispatch:
        return self

    def __exit__(self, *exc: object) -> None:
        self.kill()
        self._writes.put(None)
        for thread in self._threads:
            thread.join(timeout=TIMEOUT)
        for stream in (self.proc.stdin, self.proc.stdout, self.proc.stderr):
            if stream is not None:
                with contextlib.suppress(OSError):
                    stream.close()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.put(line)

    def _read_err(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            self._err.append(line)

    def _write(self) -> None:
        assert self.proc.stdin is not None
        with contextlib.suppress(BrokenPipeError, ValueError, OSError):
            while (data := self._writes.get()) is not None:
                self.proc.stdin.write(data)
                self.proc.stdin.flush()
            self.proc.stdin.close()

    def send(self, lines: list[bytes]) -> None:
        if lines:
            self._writes.put(b"".join(line + b"\n" for line in lines))

    def close_input(self) -> None:
        self._writes.put(None)

    def answers(self, n: int, timeout: float = TIMEOUT) -> list[str]:
        deadline = time.monotonic() + timeout
        out: list[str] = []
        while len(out) < n:
            try:
                out.append(self.lines.get(timeout=0.1).decode().rstrip("\n"))
            except queue.Empty:
                ended = self.proc.poll() is not None and not self._threads[0].is_alive() and self.lines.empty()
                if ended or time.monotonic() > deadline:
                    if ended:
                        self.wait()
                    why = "it ended" if ended else f"not within {timeout} s"
                    raise AssertionError(f"only {len(out)} of {n} answers ({why}): {self.stderr()}") from None
        return out

    def wait(self, timeout: float = TIMEOUT) -> int:
        code = self.proc.wait(timeout=timeout)
        self._threads[1].join(timeout=TIMEOUT)
        return code

    def stderr(self) -> str:
        return b"".join(self._err).decode(errors="replace")

    def kill(self) -> None:
        if self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGKILL)
        self.proc.wait(timeout=TIMEOUT)


Spawn = Callable[..., Dispatch]


@pytest.fixture
def spawn() -> Iterator[Spawn]:
    """Start ``hrc dispatch`` processes; each is killed (if still running) and closed after the test."""
    made: list[Dispatch] = []

    def start(folder: Path, *args: str) -> Dispatch:
        made.append(Dispatch(folder, *args))
        return made[-1]

    yield start
    for process in made:
        process.__exit__(None, None, None)


def _hrc_dispatch(folder: Path, *args: str) -> subprocess.CompletedProcess[bytes]:
    """``hrc dispatch FOLDER ARGS`` on an empty input, run to its end."""
    return subprocess.run([sys.executable, "-m", "hrc", "dispatch", str(folder), *args], input=b"",
                          capture_output=True, timeout=TIMEOUT, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)))


def _replays(fresh: Dispatcher, log: Path, expected: list[str]) -> None:
    """The log holds every line's answer as expected, and replays to them byte for byte."""
    contents = read_log(log)
    assert contents.torn is None
    assert [m.answer for m in contents.messages] == expected
    assert [a for a, _ in replay(fresh.fork(), contents)] == expected


# -- kill -9 and resume ------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", [pytest.param(s, marks=pytest.mark.slow) if s >= 3 else s for s in range(20)])
def test_kill_9_then_resume_answers_as_the_uninterrupted_run(spawn: Spawn, folder: Path, fresh: Dispatcher,
                                                              session: Any, tmp_path: Path, seed: int) -> None:
    lines, expected = session
    rng = random.Random(seed)
    answered = rng.randrange(1, len(lines))         # answers read before the kill
    in_flight = rng.randrange(0, 30)                # lines sent after them, not waited for
    log = tmp_path / "run.log"
    first = spawn(folder, "--log", str(log))
    first.send(lines[:answered])
    got = first.answers(answered)
    first.send(lines[answered:answered + in_flight])
    time.sleep(rng.uniform(0.0, 0.03))
    first.kill()
    assert got == expected[:answered]

    kept = read_log(log)
    n = len(kept.messages)
    print(f"\nkill -9 after {answered} answers and {in_flight} lines in flight: the log kept {n} messages"
          f"{'' if kept.torn is None else f', and a torn end ({kept.torn.why}, {kept.torn.nbytes} bytes)'}")
    assert n >= answered, "an answered message is missing from the log"
    assert [m.answer for m in kept.messages] == expected[:n]
    assert [(m.data, m.size) for m in kept.messages] == [(x[:MAX_LINE + 1], len(x)) for x in lines[:n]]

    second = spawn(folder, "--resume", str(log))
    second.send(lines[n:])
    second.close_input()
    rest = second.answers(len(lines) - n)
    assert second.wait() == 0
    err = second.stderr()
    assert f"resumed {log} after {n} messages" in err and "Traceback" not in err, err
    assert rest == expected[n:]
    _replays(fresh, log, expected)
    assert read_log(log).resumed == 1
    if seed == 0:  # once through the command line too
        done = _hrc_dispatch(folder, "--replay", str(log))
        assert done.returncode == 0 and done.stdout.decode().splitlines() == expected, done.stderr


def test_a_log_held_by_a_running_dispatcher_is_refused(spawn: Spawn, folder: Path, tmp_path: Path) -> None:
    log = tmp_path / "run.log"
    running = spawn(folder, "--log", str(log))
    try:
        running.send([b'{"t": 0, "event": "tick"}'])
        running.answers(1)
        for args in (["--resume", str(log)], ["--log", str(log)]):
            done = _hrc_dispatch(folder, *args)
            err = done.stderr.decode()
            assert done.returncode == 2 and err.startswith("error: ") and err.count("\n") == 1, err
            assert "in use" in err, err
    finally:
        running.close_input()
        assert running.wait() == 0
    # once it has ended, the log resumes; a new run needs a new file
    with pytest.raises(InputError, match="holds a run already"):
        LogWriter.create(log, {"hrc_dispatch_log": 2})


# -- torn and damaged logs ---------------------------------------------------------------------------
def _whole_log(spawn: Spawn, folder: Path, tmp_path: Path, lines: list[bytes]) -> Path:
    log = tmp_path / "whole.log"
    run = spawn(folder, "--log", str(log))
    run.send(lines)
    run.close_input()
    run.answers(len(lines))
    assert run.wait() == 0
    return log


def test_a_torn_log_is_read_to_its_last_whole_message_wherever_it_was_cut(spawn: Spawn, folder: Path,
                                                                           fresh: Dispatcher, session: Any,
                                                                           tmp_path: Path) -> None:
    lines, expected = session
    whole = _whole_log(spawn, folder, tmp_path, lines).read_bytes()
    ends = [i + 1 for i, b in enumerate(whole) if b == ord("\n")]
    rng = random.Random(3)
    cuts = sorted({*ends, *(e - 1 for e in ends), *(e - 7 for e in ends[1:]), *rng.sample(range(len(whole)), 200)})
    cut_log = tmp_path / "cut.log"
    for cut in cuts:
        if cut <= ends[0]:
            continue  # not even its header
        cut_log.write_bytes(whole[:cut])
        contents = read_log(cut_log)
        n = len(contents.messages)
        assert [m.answer for m in contents.messages] == expected[:n], cut
        whole_message = contents.size == cut
        assert (contents.torn is None) == whole_message, (cut, contents.torn)
        if not whole_message:
            assert contents.torn is not None and contents.torn.offset + contents.torn.nbytes == cut
    # one cut mid-record through the command line: one line on stderr, the rest replays, then resumes
    cut = ends[len(ends) // 2] - 5
    cut_log.write_bytes(whole[:cut] + b"\x00" * 3000)  # a power cut may leave zeros, too
    n = len(read_log(cut_log).messages)
    done = _hrc_dispatch(folder, "--replay", str(cut_log))
    err = done.stderr.decode()
    assert done.returncode == 0 and err.count("\n") == 1 and "torn" in err and "dropped" in err, err
    assert done.stdout.decode().splitlines() == expected[:n]
    resumed = spawn(folder, "--resume", str(cut_log))
    resumed.send(lines[n:])
    resumed.close_input()
    assert resumed.answers(len(lines) - n) == expected[n:]
    assert resumed.wait() == 0
    _replays(fresh, cut_log, expected)


def test_a_log_damaged_before_its_end_is_refused_not_dropped(spawn: Spawn, folder: Path, session: Any,
                                                              tmp_path: Path) -> None:
    lines, _ = session
    whole = _whole_log(spawn, folder, tmp_path, lines[:20]).read_bytes()
    middle = whole.index(b"\n", len(whole) // 2)
    damaged = tmp_path / "damaged.log"
    damaged.write_bytes(whole[:middle - 3] + b"#" + whole[middle - 2:])
    with pytest.raises(InputError, match="damaged record"):
        read_log(damaged)
    for args in (["--replay", str(damaged)], ["--resume", str(damaged)]):
        done = _hrc_dispatch(folder, *args)
        err = done.stderr.decode()
        assert done.returncode == 2 and err.startswith("error: ") and err.count("\n") == 1, err
    assert damaged.read_bytes() == whole[:middle - 3] + b"#" + whole[middle - 2:]  # left as it was


# -- bad lines ---------------------------------------------------------------------------------------
def test_bad_lines_are_refused_in_one_line_and_logged_losslessly(spawn: Spawn, folder: Path, fresh: Dispatcher,
                                                                 tmp_path: Path) -> None:
    lines = [b'{"t": 0, "event": "tick"}', *BAD_LINES, b'{"t": 1, "event": "tick"}']
    log = tmp_path / "bad.log"
    run = spawn(folder, "--log", str(log))
    for line in lines:  # one at a time: each answer before the next line
        run.send([line])
        (got,) = run.answers(1)
        out = json.loads(got)
        assert set(out) >= {"t", "ok"} and "\n" not in got
        if line in BAD_LINES:
            assert out["ok"] is False and 0 < len(out["error"]) <= 500, (line[:60], got)
    run.close_input()
    assert run.wait() == 0
    assert run.stderr() == ""
    # every line's bytes are in the log, the over-long one in parts, whole
    records = [json.loads(r) for r in log.read_bytes().split(b"\n") if r]
    assert log.read_bytes().isascii()
    stored: list[bytes] = []
    part = b""
    for rec in records:
        if "in" in rec:
            stored.append(rec["in"].encode("utf-8", "surrogatepass"))
        elif "in_more" in rec:
            part += base64.b64decode(rec["in_more"])
        elif "in_b64" in rec:
            stored.append(part + base64.b64decode(rec["in_b64"]))
            part = b""
    assert stored == lines
    _replays(fresh, log, _answers(fresh, lines))


def _answers(fresh: Dispatcher, lines: list[bytes]) -> list[str]:
    d = fresh.fork()
    return [answer(d, x) for x in lines]


def test_the_reader_splits_on_newlines_only_and_reads_version_1(folder: Path, fresh: Dispatcher,
                                                                tmp_path: Path) -> None:
    d = fresh.fork()
    tick = '{"t": 0, "event": "tick"}'
    odd = '{"t": 0, "agent": "human", "action": "c\u2028u\u0085b\u000ce\u001c", "phase": "fetch", "event": "start"}'
    header = {**read_header(fresh), "hrc_dispatch_log": 1}
    text = "".join(json.dumps(r, ensure_ascii=False) + "\n" for r in (
        header, {"in": tick}, {"out": answer(d, tick.encode())}, {"in": odd}, {"out": answer(d, odd.encode())}))
    old = tmp_path / "v1.log"
    old.write_text(text, encoding="utf-8")
    assert len(text.splitlines()) > 5  # what the old reader split it into
    contents = read_log(old)
    assert contents.version == 1 and [m.data.decode() for m in contents.messages] == [tick, odd]
    assert all(a == b for a, b in replay(fresh.fork(), contents))


# -- a full disk -------------------------------------------------------------------------------------
class FailingWriter(LogWriter):
    """A real log writer whose next write (half of it written first) or sync fails on demand."""

    fail_write = False
    fail_sync = False

    def _write(self, data: bytes) -> None:
        if self.fail_write:
            super()._write(data[:len(data) // 2])
            raise OSError(28, "No space left on device")
        super()._write(data)

    def _sync(self) -> None:
        if self.fail_sync:
            raise OSError(5, "Input/output error")
        super()._sync()


def test_a_log_that_cannot_be_written_refuses_the_message_and_changes_nothing(fresh: Dispatcher, session: Any,
                                                                             tmp_path: Path) -> None:
    lines, expected = session
    log = tmp_path / "run.log"
    writer = FailingWriter.create(log, read_header(fresh))
    logged = LoggedDispatcher(fresh.fork(), writer)
    for i, line in enumerate(lines[:10]):
        assert logged.submit(line) == expected[i]
    size, state = log.stat().st_size, logged.dispatcher.decision
    writer.fail_write = True
    refused = json.loads(logged.submit(lines[10]))
    assert refused["ok"] is False and "No space left on device" in refused["error"], refused
    assert logged.dispatcher.decision is state and log.stat().st_size == size  # the half record was cut back
    writer.fail_write = False
    assert logged.submit(lines[10]) == expected[10]  # the same message, now that there is room
    # a failed sync: refused, taken back out of the file, and nothing more until a resume
    size, state = log.stat().st_size, logged.dispatcher.decision
    writer.fail_sync = True
    accepted_next = next(i for i in range(11, len(lines)) if json.loads(expected[i])["ok"])
    for i in range(11, accepted_next):
        assert logged.submit(lines[i]) == expected[i]  # refusals are not synced: not affected
    refused = json.loads(logged.submit(lines[accepted_next]))
    assert refused["ok"] is False and "could not be synced" in refused["error"], refused
    assert logged.dispatcher.decision is state
    writer.fail_sync = False
    assert "resume" in json.loads(logged.submit(lines[accepted_next]))["error"]  # broken for good
    logged.close()
    resumed, report = LoggedDispatcher.resume(fresh.fork(), log)
    assert report.messages == accepted_next
    for i in range(accepted_next, len(lines)):
        assert resumed.submit(lines[i]) == expected[i]
    resumed.close()
    _replays(fresh, log, expected)


def read_header(dispatcher: Dispatcher) -> dict[str, Any]:
    from hrc.dispatch.protocol import log_header

    return log_header(dispatcher, 2)


@contextlib.contextmanager
def small_file_system(tmp_path: Path, size: str = "4m") -> Iterator[Path]:
    """A tmpfs of `size` mounted for the test (root and a working ``mount`` needed, else skip)."""
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root (the in-process failing writer test covers the logic)")
    mnt = tmp_path / "small"
    mnt.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mnt)], capture_output=True,
                          text=True, timeout=30)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({done.stderr.strip()})")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], capture_output=True, timeout=30)


def _fill(folder: Path) -> Path:
    """Fill the file system of `folder` to its last byte; the filler's path."""
    filler = folder / "filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT | os.O_EXCL)
    try:
        for size in (1 << 16, 1 << 10, 1):
            with contextlib.suppress(OSError):
                while os.write(fd, b"\0" * size):
                    pass
    finally:
        os.close(fd)
    return filler


def test_a_full_file_system_refuses_messages_until_there_is_room(spawn: Spawn, folder: Path, fresh: Dispatcher,
                                                                 session: Any, tmp_path: Path) -> None:
    lines, expected = session
    with small_file_system(tmp_path) as mnt:
        log = mnt / "run.log"
        run = spawn(folder, "--log", str(log))
        for i in range(5):
            run.send([lines[i]])
            assert run.answers(1) == [expected[i]]
        filler = _fill(mnt)
        i, refused = 5, None
        while refused is None and i < len(lines):  # the log's last page may still hold a few records
            run.send([lines[i]])
            (got,) = run.answers(1)
            if "cannot be written" in got:
                refused = got
            else:
                assert got == expected[i]
                i += 1
        assert refused is not None, "the full file system never refused a message"
        out = json.loads(refused)
        assert out["ok"] is False and "No space left on device" in out["error"] and "nothing changed" in out["error"]
        filler.unlink()
        run.send(lines[i:])  # the refused one again, and the rest
        run.close_input()
        assert run.answers(len(lines) - i) == expected[i:]
        assert run.wait() == 0 and run.stderr() == ""
        _replays(fresh, log, expected)


# -- floods ------------------------------------------------------------------------------------------
def test_a_flood_of_ticks_and_impossible_presses_is_answered_promptly(spawn: Spawn, folder: Path,
                                                                     tmp_path: Path) -> None:
    ticks = [json.dumps({"t": round(1 + i * 1e-4, 4), "event": "tick"}).encode() for i in range(10_000)]  # 10 kHz
    presses = [json.dumps({"t": 2.0, "agent": "human", "action": "cube9", "phase": "fetch", "event": "start"}).encode()
               for _ in range(10_000)]
    run = spawn(folder, "--log", str(tmp_path / "flood.log"))
    run.send([b'{"t": 0, "event": "tick"}'])
    run.answers(1)
    timings = {}
    for name, flood in (("ticks", ticks), ("presses", presses)):
        start = time.monotonic()
        run.send(flood)
        got = run.answers(len(flood), timeout=30)
        timings[name] = time.monotonic() - start
        outs = [json.loads(a) for a in got]
        accepted = sum(out["ok"] and not out.get("unchanged") for out in outs)
        timings[name + " accepted"] = accepted
        assert accepted <= (1 + 1 / 0.05 if name == "ticks" else 0), (name, accepted)
        if name == "ticks":  # the rest: valid, answered with the last decision, not refused
            assert all(out["ok"] for out in outs) and sum(bool(out.get("unchanged")) for out in outs) >= 9_970
    run.close_input()
    assert run.wait() == 0
    print(f"\n10,000 ticks at 10 kHz answered in {timings['ticks']:.2f} s ({timings['ticks accepted']} accepted), "
          f"10,000 impossible presses in {timings['presses']:.2f} s")
    assert timings["ticks"] < 10 and timings["presses"] < 10, timings
