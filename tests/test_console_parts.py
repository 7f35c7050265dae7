"""The console's parts that need neither a browser nor a server: the run's clock, the log's name, the
Gantt bars, the phases under way, the command line's refusals and the access secrets."""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from hrc.console.access import TOKEN_PATTERN, Credentials, allowed_hosts, is_loopback, load_or_create_token
from hrc.console.clock import RunClock
from hrc.console.runlog import next_log_path
from hrc.console.views import gantt_bars, under_way
from hrc.errors import InputError

ROOT = Path(__file__).resolve().parents[1]


@dataclass(frozen=True)
class Obs:
    t: float
    event: str
    agent: str | None = None
    action: str | None = None
    phase: str | None = None


def test_run_clock_counts_run_seconds_at_its_speed() -> None:
    ticks = iter([100.0, 100.25, 101.0, 101.0])
    clock = RunClock(speed=4.0, monotonic=lambda: next(ticks))
    assert clock.now() == 0.0 and clock.real_delay(1.0) == float("inf")  # not started
    clock.start()
    assert clock.now() == 1.0
    assert clock.real_delay(6.0) == pytest.approx(0.5)   # at run time 4.0, 2 run s = 0.5 real s
    assert clock.real_delay(1.0) == 0.0                   # already past


def test_run_clock_refuses_a_speed_that_is_not_positive() -> None:
    with pytest.raises(ValueError, match="positive"):
        RunClock(speed=0)


def test_a_new_run_never_takes_an_old_log(tmp_path: Path) -> None:
    first = next_log_path(tmp_path)
    assert first == tmp_path / "runs" / "console-1.jsonl"
    first.parent.mkdir()
    first.write_text("")
    assert next_log_path(tmp_path).name == "console-2.jsonl"


def test_gantt_bars_join_planned_and_observed_events() -> None:
    planned = {("human", "cube1", "fetch", "depart"): 0.0, ("human", "cube1", "fetch", "arrive"): 5.0,
               ("human", "cube1", "fetch", "start"): 5.0, ("human", "cube1", "fetch", "end"): 8.0,
               ("robot", "cube2", "fetch", "depart"): 1.0}
    history = [Obs(0.5, "depart", "human", "cube1", "fetch"), Obs(6.0, "arrive", "human", "cube1", "fetch"),
               Obs(6.5, "start", "human", "cube1", "fetch"), Obs(7.0, "tick")]
    bars = gantt_bars(planned, history, now=9.0)
    assert [(b["kind"], b["from"], b["to"]) for b in bars["planned"]] == [("travel", 0.0, 5.0), ("work", 5.0, 8.0)]
    assert [(b["kind"], b["from"], b["to"], b["open"]) for b in bars["actual"]] == [
        ("travel", 0.5, 6.0, False), ("work", 6.5, 9.0, True)]
    assert under_way(history, "human") == [("cube1", "fetch")]
    assert under_way([*history, Obs(9.0, "end", "human", "cube1", "fetch")], "human") == []


# -- access: the CLI's refusals, the token files -------------------------------------------------------
def _hrc(*argv: str) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "hrc", *argv], capture_output=True, text=True, timeout=60, env=env,
                          cwd=ROOT)


@pytest.mark.parametrize("argv, message", [
    (["--port", "99999"], "must lie in 0..65535"),
    (["--port", "-1"], "must lie in 0..65535"),
    (["--port", "http"], "expected a port number"),
    (["--host", "0.0.0.0"], "add --allow-remote"),
    (["--host", "192.0.2.7"], "add --allow-remote"),
    (["--tick", "-1"], "must lie in [0, 3600]"),
])
def test_console_cli_refuses_bad_options_in_one_line(tmp_path: Path, argv: list[str], message: str) -> None:
    done = _hrc("console", str(tmp_path), *argv)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.startswith("error: ") and done.stderr.count("\n") == 1 and message in done.stderr, done.stderr


def test_a_token_file_is_written_once_private_and_read_back(tmp_path: Path) -> None:
    path = tmp_path / "robot.token"
    token = load_or_create_token(path)
    assert TOKEN_PATTERN.fullmatch(token) and len(token) >= 43
    assert path.stat().st_mode & 0o777 == 0o600
    assert load_or_create_token(path) == token  # read, never replaced
    assert load_or_create_token(tmp_path / "other.token") != token


@pytest.mark.parametrize("content, mode, message", [
    ("short\n", 0o600, "not a token"),
    ("a" * 40 + " " + "b" * 40 + "\n", 0o600, "not a token"),
    ("a" * 43 + "\n", 0o644, "chmod 600"),
])
def test_a_bad_token_file_is_refused(tmp_path: Path, content: str, mode: int, message: str) -> None:
    path = tmp_path / "t.token"
    path.write_text(content)
    path.chmod(mode)
    with pytest.raises(InputError, match=message):
        load_or_create_token(path)


def test_only_loopback_names_are_loopback_and_hosts_carry_the_port() -> None:
    assert all(is_loopback(h) for h in ("127.0.0.1", "localhost", "::1", "[::1]", "127.1.2.3"))
    assert not any(is_loopback(h) for h in ("0.0.0.0", "192.0.2.7", "example.org", "::", "localhost.example.org"))
    assert allowed_hosts("127.0.0.1", 8765) == {"127.0.0.1:8765", "localhost:8765", "[::1]:8765"}
    assert allowed_hosts("192.0.2.7", 9000) == {"192.0.2.7:9000"}
    assert "127.0.0.1" in allowed_hosts("127.0.0.1", 80)  # a browser omits the default port


def test_credentials_must_be_two_different_tokens() -> None:
    token = "a" * 43
    with pytest.raises(ValueError, match="differ"):
        Credentials(token, token)
    with pytest.raises(ValueError, match="not a token"):
        Credentials("short", token)
    pair = Credentials.generate()
    assert pair.page != pair.robot
