"""The console's parts that need neither a browser nor a server: the run's clock, the log's name, the
Gantt bars, the phases under way."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pytest

from hrc.console.clock import RunClock
from hrc.console.runlog import next_log_path
from hrc.console.views import gantt_bars, under_way


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
