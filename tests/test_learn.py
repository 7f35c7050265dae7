"""`hrc learn`: order-statistic bounds on hand-made logs of known durations, the guard rails, the task
edit that keeps comments, and the records the simulator and the recorder write read back."""

from __future__ import annotations

import json
import os
import statistics
from pathlib import Path

import pytest
import yaml
from conftest import WORKSHOP_TASK
from scipy.stats import beta

from hrc.cli import main
from hrc.dispatch.logfile import encode_answer, encode_header, encode_input
from hrc.io.task_file import load_task, task_digest
from hrc.learn.estimate import learn
from hrc.learn.runs import read_runs
from hrc.learn.task_edit import replace_bounds
from hrc.learn.tolerance import min_observations, tolerance_interval
from hrc.model import Interval

TASK = load_task(WORKSHOP_TASK)
OK = json.dumps({"ok": True})


def _log(path: Path, events: list[dict], digest: str | None = None, answers: list[str] | None = None,
         raw: list[bytes] | None = None) -> Path:
    """A dispatcher log in the project's format (its own encoders) holding `events` as accepted messages."""
    header = {"hrc_dispatch_log": 2, "compiled": "0123456789abcdef", "plans": 32}
    if digest != "":
        header["task"] = digest or task_digest(TASK)
    parts = [encode_header(header)]
    for i, ev in enumerate(events):
        parts += [encode_input(json.dumps(ev).encode()), encode_answer(answers[i] if answers else OK)]
    parts += raw or []
    path.write_bytes(b"".join(parts))
    return path


def _phase(t0: float, d: float, action: str = "cube1", phase: str = "fetch") -> list[dict]:
    return [{"t": t0, "agent": "human", "action": action, "phase": phase, "event": "start"},
            {"t": round(t0 + d, 3), "agent": "human", "action": action, "phase": phase, "event": "end"}]


def _logs(folder: Path, durations: list[float]) -> Path:
    folder.mkdir()
    for i, d in enumerate(durations):
        _log(folder / f"run-{i:04d}.jsonl", _phase(10.0, d))
    return folder


# -- the order statistics --------------------------------------------------------------------------
def test_fewest_observations_are_the_classic_table_values() -> None:
    # two-sided distribution-free tolerance limits [min, max] (Wilks): the NIST/SEMATECH table values
    assert min_observations(0.90, 0.95) == 46
    assert min_observations(0.95, 0.95) == 93
    assert min_observations(0.99, 0.95) == 473
    assert min_observations(0.90, 0.90) == 38


@pytest.mark.parametrize("n", [46, 60, 100, 250, 1000])
@pytest.mark.parametrize("p,gamma", [(0.90, 0.95), (0.95, 0.90), (0.80, 0.99)])
def test_the_interval_is_the_widest_order_that_keeps_the_promise(n: int, p: float, gamma: float) -> None:
    xs = [float(k) for k in range(n, 0, -1)]  # x(k) = k: the order statistic is its own index
    got = tolerance_interval(xs, p, gamma)
    if beta.sf(p, n - 1, 2) < gamma:  # coverage of [x(1), x(n)] is Beta(n-1, 2)
        assert got is None
        return
    assert got is not None
    lo, hi, r, conf = got
    assert (lo, hi) == (r, n + 1 - r)
    # the coverage of [x(r), x(n+1-r)] is Beta(n+1-2r, 2r): r keeps the promise, r+1 does not
    assert beta.sf(p, n + 1 - 2 * r, 2 * r) >= gamma > beta.sf(p, n - 1 - 2 * r, 2 * r + 2)
    assert conf == pytest.approx(beta.sf(p, n + 1 - 2 * r, 2 * r))


# -- hand-made logs of known durations ---------------------------------------------------------------
def test_bounds_from_known_durations_are_the_exact_order_statistics(tmp_path: Path) -> None:
    durations = [2.0 + 0.01 * k for k in range(100)]  # 2.00 .. 2.99, one run each, shuffled
    order = sorted(range(100), key=lambda k: (k * 37) % 100)
    runs, skipped = read_runs(TASK, [_logs(tmp_path / "runs", [durations[k] for k in order])])
    assert len(runs) == 100 and not skipped
    b = learn(TASK, runs, 0.90, 0.95).bound("human", "cube1", "fetch")
    # n = 100, p = 0.90, gamma = 0.95: r = 2 (P(Binomial(100, 0.9) <= 96) = 0.976, <= 94: 0.942)
    assert b.n == 100 and b.order == 2 and not b.kept
    assert (b.new.lb, b.new.ub) == (2.01, 2.98)  # x(2) and x(99)
    assert b.overruns == 0
    # nothing else was observed: every other bound of the person is kept, with a warning each
    other = learn(TASK, runs, 0.90, 0.95)
    assert sum(1 for x in other.bounds if x.changed) == 1
    assert len(other.warnings) == 9


def test_too_few_observations_keep_the_old_bound_with_a_warning(tmp_path: Path) -> None:
    wide = [1.0 + 0.1 * k for k in range(45)]  # 1.0 .. 5.4: overruns of [2, 4] below and above
    runs, _ = read_runs(TASK, [_logs(tmp_path / "a", wide)])
    got = learn(TASK, runs, 0.90, 0.95)
    b = got.bound("human", "cube1", "fetch")
    assert b.kept and b.new == Interval(2, 4) and b.n == 45
    assert any("cube1.fetch: 45 observations, fewer than the 46" in w for w in got.warnings)
    assert (b.below, b.above) == (10, 14)  # 1.0..1.9 below 2; 4.1..5.4 above 4
    runs, _ = read_runs(TASK, [_logs(tmp_path / "b", [*wide, 5.5])])  # the 46th: [min, max]
    b = learn(TASK, runs, 0.90, 0.95).bound("human", "cube1", "fetch")
    assert not b.kept and (b.new.lb, b.new.ub) == (1.0, 5.5)


def test_the_robots_durations_are_reported_not_learned(tmp_path: Path) -> None:
    folder = tmp_path / "r"
    folder.mkdir()
    for i in range(50):
        ev = _phase(10.0, 5.5)
        for e in ev:
            e["agent"] = "robot"
        _log(folder / f"{i}.jsonl", ev)
    runs, _ = read_runs(TASK, [folder])
    b = learn(TASK, runs).bound("robot", "cube1", "fetch")
    assert b.n == 50 and b.kept and "controllable" in b.why
    b = learn(TASK, runs, agents=("robot",)).bound("robot", "cube1", "fetch")
    assert not b.kept and (b.new.lb, b.new.ub) == (5.5, 5.5)


# -- guard rails: bad lines, refused messages, other tasks ---------------------------------------------
def test_a_bad_line_is_reported_with_its_place_and_skipped(tmp_path: Path) -> None:
    events = [*_phase(1.0, 3.0), *_phase(20.0, 2.5, "cube3", "put")]
    answers = [OK, OK, OK, "not json"]  # the last answer cannot be read: its message is not used
    raw = [encode_input(b"{broken"), encode_answer(OK),                       # accepted, yet not JSON
           encode_input(json.dumps({"t": 30, "event": "end"}).encode()), encode_answer(OK)]  # no agent
    log = _log(tmp_path / "bad.jsonl", events, answers=answers, raw=raw)
    runs, skipped = read_runs(TASK, [log])
    assert [str(s) for s in skipped] == [
        f"{log}:8: its answer is not JSON: skipped",
        f"{log}:10: a message that is not JSON, yet accepted: skipped",
        f"{log}:12: an event without a time, agent, action, phase or event: skipped"]
    (run,) = runs
    assert [(e.action, e.phase, e.event) for e in run.events] == [
        ("cube1", "fetch", "start"), ("cube1", "fetch", "end"), ("cube3", "put", "start")]


def test_refused_messages_tell_nothing(tmp_path: Path) -> None:
    refused = json.dumps({"t": 5, "ok": False, "error": "the human has not started cube1.fetch"})
    log = _log(tmp_path / "r.jsonl", [*_phase(1.0, 3.0), _phase(1.0, 9.0)[1]], answers=[OK, OK, refused])
    (run,), skipped = read_runs(TASK, [log])
    assert not skipped and len(run.events) == 2


def test_a_damaged_log_is_skipped_whole_and_said_where(tmp_path: Path) -> None:
    good = _log(tmp_path / "good.jsonl", _phase(1.0, 3.0))
    bad = _log(tmp_path / "bad.jsonl", _phase(1.0, 3.0),
               raw=[b"{not a record\n", encode_input(b'{"t": 9, "event": "tick"}'), encode_answer(OK)])
    runs, skipped = read_runs(TASK, [good, bad])
    assert [r.source for r in runs] == [str(good)]
    assert len(skipped) == 1 and str(skipped[0]).startswith(f"{bad}:6: damaged record")


def _learn(tmp_path: Path, *runs: Path, extra: tuple[str, ...] = ()) -> int:
    return main(["learn", str(WORKSHOP_TASK), *map(str, runs), "--out", str(tmp_path / "new.yaml"),
                 "--no-compile", "-q", *extra])


def test_a_log_of_another_task_is_refused_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    good = _logs(tmp_path / "runs", [3.0] * 3)
    other = _log(tmp_path / "other.jsonl", _phase(1.0, 3.0), digest="f" * 64)
    assert _learn(tmp_path, good, other) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"error: {other}: header.task: a run of another task")
    assert not (tmp_path / "new.yaml").exists() and not (tmp_path / "new-learn").exists()
    old = _log(tmp_path / "old.jsonl", _phase(1.0, 3.0), digest="")  # written before logs named their task
    assert _learn(tmp_path, old) == 2
    assert "names no task digest" in capsys.readouterr().err


def test_no_usable_run_is_an_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "empty").mkdir()
    assert _learn(tmp_path, tmp_path / "empty") == 2
    assert "holds no run records" in capsys.readouterr().err


# -- the task written back -----------------------------------------------------------------------------
def test_new_bounds_change_only_their_numbers(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    runs = _logs(tmp_path / "runs", [2.0 + 0.01 * k for k in range(100)])
    out = tmp_path / "sub" / "new.yaml"
    assert main(["learn", str(WORKSHOP_TASK), str(runs), "--out", str(out), "--no-compile"]) == 0
    diff = capsys.readouterr().out
    changed = [ln for ln in diff.splitlines() if ln.startswith(("-", "+")) and not ln.startswith(("---", "+++"))]
    assert changed == [
        "-map: ../maps/workshop.yaml",
        f"+map: {os.path.relpath(WORKSHOP_TASK.parent.parent / 'maps' / 'workshop.yaml', out.parent)}",
        "-      - {id: fetch, location: S1, duration: {human: [2, 4], robot: [5, 6]}}",
        "+      - {id: fetch, location: S1, duration: {human: [2.01, 2.98], robot: [5, 6]}}"]
    old_text, new_text = WORKSHOP_TASK.read_text(), out.read_text()
    old_lines, new_lines = old_text.splitlines(), new_text.splitlines()
    assert len(old_lines) == len(new_lines)
    assert [a for a in old_lines if a.lstrip().startswith("#")] == [b for b in new_lines if b.lstrip().startswith("#")]
    new = load_task(out)  # loads where it lives: the map path re-pointed
    assert new.action("cube1").phase("fetch").duration("human") == Interval(2.01, 2.98)
    assert new.workspace == TASK.workspace
    assert (tmp_path / "sub" / "new-learn" / "report.md").is_file()
    assert (tmp_path / "sub" / "new-learn" / "figures" / "durations-human.png").is_file()


def test_replace_bounds_keeps_block_style_and_comments() -> None:
    text = ("actions:\n  - id: a   # the first\n    phases:\n      - id: p\n        duration:\n"
            "          human:   # typed by hand\n            - 2     # lb\n            - 4.0   # ub\n")
    out = replace_bounds(text, {("human", "a", "p"): Interval(1.5, 3.25)})
    assert out == text.replace("- 2     #", "- 1.5     #").replace("- 4.0   #", "- 3.25   #")
    assert yaml.safe_load(out)["actions"][0]["phases"][0]["duration"]["human"] == [1.5, 3.25]


# -- worker types -----------------------------------------------------------------------------------
def test_adjusted_rand_index_on_hand_worked_cases() -> None:
    from hrc.learn.worker_types import adjusted_rand_index as ari

    assert ari([0, 0, 1, 1, 2], [5, 5, 3, 3, 4]) == 1.0  # the same partition, other names
    assert ari([0, 0, 0, 0], [1, 1, 1, 1]) == 1.0
    # contingency [[2, 1], [0, 2]] (rows: a, cols: b): sum C(n_ij, 2) = 2, rows 3 + 1 = 4, cols 1 + 3 = 4,
    # C(5, 2) = 10: expected 4 * 4 / 10 = 1.6, max 4: (2 - 1.6) / (4 - 1.6) = 1/6
    assert ari([0, 0, 0, 1, 1], [0, 0, 1, 1, 1]) == pytest.approx(1 / 6)


def _typed_run(path: Path, fast: bool, i: int) -> Path:
    """A run of a fast worker who takes cube1 then cube3, or a slow one who takes cube1 then cube2."""
    second = "cube3" if fast else "cube2"
    d = (2.1 if fast else 3.7) + 0.01 * (i % 17)
    events = []
    for k, action in enumerate(("cube1", second)):
        t0 = 30.0 * k
        events.append({"t": t0, "agent": "human", "action": action, "phase": "fetch", "event": "depart"})
        events += _phase(t0 + 5, d, action, "fetch") + _phase(t0 + 15, d + 0.05, action, "put")
    return _log(path, events)


def test_two_kinds_of_worker_are_told_apart_and_written_as_preference_sets(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from hrc.learn.worker_types import adjusted_rand_index, find_types

    folder = tmp_path / "runs"
    folder.mkdir()
    truth = [int(i % 3 == 0) for i in range(48)]  # 16 fast, 32 slow, interleaved
    files = [_typed_run(folder / f"{i:03d}.jsonl", bool(f), i) for i, f in enumerate(truth)]
    runs, _ = read_runs(TASK, files)
    types = find_types(TASK, runs, 0.80, 0.80)
    assert types.k == 2 and adjusted_rand_index(truth, types.labels) == 1.0
    # at (0.90, 0.95) the 16 runs of the fast worker are too few for any bound: no sets, and a warning
    assert _learn(tmp_path, folder, extra=("--types",)) == 0
    assert "2 worker types found, no preference sets written: a type has no learned bound" in capsys.readouterr().err
    assert not load_task(tmp_path / "new.yaml").preference_sets
    assert _learn(tmp_path, folder, extra=("--types", "--coverage", "0.8", "--confidence", "0.8")) == 0
    new = load_task(tmp_path / "new.yaml")
    sets = dict(new.preference_sets)
    assert sorted(sets) == ["type_1", "type_2"]
    fast = sets["type_1"]  # run 0 is a fast one, so type_1: the fast worker
    fetch = next(p for p in fast if str(p.source) == "cube1.fetch.start")
    assert fetch.domain.lb == 2.1 and fetch.domain.ub <= 2.27
    m = statistics.median(2.1 + 0.01 * (i % 17) for i, f in enumerate(truth) if f)  # it peaks at the median
    assert max((fetch.value(2.1 + 0.001 * j), 2.1 + 0.001 * j) for j in range(200))[1] == pytest.approx(m, abs=1e-3)
    assert "worker types" in (tmp_path / "new-learn" / "report.md").read_text().lower()
    # APA's worker-type switch, fed the learned sets, names the type a person's timing belongs to
    from hrc.apa.model import STPP, Constraint
    from hrc.apa.plan import ORIGIN, preference_constraint
    from hrc.apa.workers import best_worker_type

    sets = {name: tuple(preference_constraint(str(p.source), str(p.target), p) for p in prefs)
            for name, prefs in new.preference_sets}
    events = sorted({e for cons in sets.values() for c in cons for e in (c.source, c.target)})
    hard = STPP((ORIGIN, *events), tuple(
        [Constraint(ORIGIN, e, 0.0, 200.0) for e in events]
        + [Constraint(f"{a}.{p}.start", f"{a}.{p}.end", *TASK.action(a).phase(p).duration("human"))
           for a, p, _ in (e.split(".") for e in events if e.endswith(".start"))]), "typed")
    for d, want in ((2.16, "type_1"), (3.81, "type_2")):
        seen = {ORIGIN: 0.0, "cube1.fetch.start": 5.0, "cube1.fetch.end": 5.0 + d}
        assert best_worker_type(hard, sets, seen, 5.0 + d, ticks_per_second=1000) == want


def test_a_motion_detectors_events_give_their_delays_and_an_undo_takes_one_back(tmp_path: Path) -> None:
    def position(t: float, *given: dict) -> tuple[dict, str]:
        return {"t": t, "event": "position", "x": 1.0, "y": 1.0}, json.dumps(
            {"t": t, "ok": True, "detect": {"events": list(given), "belief": {}}})

    def ev(t: float, at: float, action: str, phase: str, event: str) -> dict:
        # "at": the time the dispatcher stamped it (not the position's): the delay is the position's t - t
        return {"t": t, "agent": "human", "action": action, "phase": phase, "event": event, "at": t}

    exchanges = [position(1.0), position(2.4, ev(2.0, 2.4, "cube2", "fetch", "depart")),
                 position(3.0, {"t": 3.0, "event": "undo", "at": 3.0}),  # that departure was for cube1
                 position(3.5, ev(2.0, 3.5, "cube1", "fetch", "depart")),
                 position(9.9, ev(9.0, 9.9, "cube1", "fetch", "arrive")),
                 position(10.6, ev(10.0, 10.6, "cube1", "fetch", "start")),
                 position(13.7, ev(13.0, 13.7, "cube1", "fetch", "end"))]
    log = _log(tmp_path / "motion.jsonl", [m for m, _ in exchanges], answers=[a for _, a in exchanges])
    (run,), skipped = read_runs(TASK, [log])
    assert not skipped
    assert [(e.action, e.event) for e in run.events] == [("cube1", "depart"), ("cube1", "arrive"),
                                                         ("cube1", "start"), ("cube1", "end")]
    got = learn(TASK, [run])
    assert dict(got.delays.by_event) == {"arrive": (pytest.approx(0.9),), "depart": (pytest.approx(1.5),),
                                         "end": (pytest.approx(0.7),), "start": (pytest.approx(0.6),)}
    assert got.bound("human", "cube1", "fetch").samples == (3.0,)
    assert got.travels[0].samples == (7.0,)


def test_recordings_another_tasks_is_refused_and_a_broken_one_skipped(tmp_path: Path) -> None:
    import io

    from hrc.errors import RunFileError
    from hrc.record.recorder import RunRecorder

    def recording(path: Path, digest: str) -> Path:
        sink = io.BytesIO()
        rec = RunRecorder(sink, TASK, metadata={"task_digest": digest})
        for ev in _phase(1.0, 3.0):
            rec.exchange(json.dumps(ev).encode(), OK)
        rec.finish()
        path.write_bytes(sink.getvalue())
        return path

    good = recording(tmp_path / "good.mcap", task_digest(TASK))
    (tmp_path / "broken.mcap").write_bytes(good.read_bytes()[:200])
    runs, skipped = read_runs(TASK, [good, tmp_path / "broken.mcap"])
    assert [r.source for r in runs] == [str(good)] and len(runs[0].events) == 2
    assert len(skipped) == 1 and str(skipped[0]).startswith(f"{tmp_path / 'broken.mcap'}: not a readable MCAP")
    with pytest.raises(RunFileError, match="metadata.hrc.task_digest: a run of another task"):
        read_runs(TASK, [recording(tmp_path / "other.mcap", "0" * 64)])
