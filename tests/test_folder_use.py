"""A compile and a live run on the same output folder (issue 34, item 4): the run holds the folder
(`hrc.io.folder_use`), a compile into it is refused in one line (exit 2) and the run answers on as
before; a run that starts while a compile runs makes its swap refuse; a run reads later only what it
opened at the start, whatever is put at the folder's path; and a log is named by the set's content, so
that a log of another compile (another seed: the same plan ids) is refused as such.

Real compiles of the small task (`conftest.MIN_TASK`), a real ``hrc console`` process
(`console_harness.ConsoleProcess`, no browser: its HTTP API and the page's websocket) and real
``hrc dispatch`` processes.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from conftest import ROOT, compiled_folder, tree_bytes
from console_harness import ConsoleProcess

from hrc.cli import main
from hrc.dispatch import Dispatcher
from hrc.dispatch.logfile import read_log
from hrc.dispatch.plan_set import load_plan_set
from hrc.dispatch.protocol import replay
from hrc.dispatch.routes import plan_motions

ENV = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))


@pytest.fixture(scope="module")
def compiles(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The small task compiled with seed 0 and with seed 1 (kept as the pristine copies to start from)."""
    import yaml
    from conftest import MIN_MAP, MIN_TASK

    base = tmp_path_factory.mktemp("compiles")
    (base / "map.yaml").write_text(yaml.safe_dump(MIN_MAP), encoding="utf-8")
    task = base / "task.yaml"
    task.write_text(yaml.safe_dump(MIN_TASK), encoding="utf-8")
    return {"task": task, "seed0": compiled_folder(base / "seed0", task, "--jobs", "1"),
            "seed1": compiled_folder(base / "seed1", task, "--jobs", "1", "--seed", "1")}


def _copy(compiles: dict[str, Path], which: str, to: Path) -> Path:
    shutil.copytree(compiles[which], to)
    return to


def _compile(task: Path, out: Path, *extra: str) -> subprocess.CompletedProcess[str]:
    """``hrc compile`` into `out` in its own process (as a user in another terminal)."""
    return subprocess.run([sys.executable, "-m", "hrc", "compile", str(task), "--out", str(out), "-q", "--jobs", "1",
                           "--no-report", *extra], cwd=out.parent, env=ENV, text=True, capture_output=True,
                          timeout=300)


def _refused(done: subprocess.CompletedProcess[str], out: Path) -> None:
    assert done.returncode == 2, done.stderr
    assert done.stderr.count("\n") == 1 and done.stderr.startswith(f"error: {out}: --out: a live run"), done.stderr
    assert "Traceback" not in done.stderr


class DispatchProcess:
    """``hrc dispatch OUT --log LOG``: one JSON line in, its answer out."""

    def __init__(self, out: Path, log: Path) -> None:
        self.proc = subprocess.Popen([sys.executable, "-m", "hrc", "dispatch", str(out), "--log", str(log)],
                                     cwd=ROOT, env=ENV, text=True, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                     stderr=subprocess.PIPE)

    def ask(self, message: dict[str, Any]) -> dict[str, Any]:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(json.dumps(message) + "\n")
        self.proc.stdin.flush()
        return json.loads(self.proc.stdout.readline())

    def end(self) -> tuple[int, str]:
        _, err = self.proc.communicate(timeout=30)
        return self.proc.returncode, err


def _human_first(answer: dict[str, Any]) -> dict[str, Any]:
    """A human observation that the answer's plans allow: the departure the robot waits for, or the first
    action's fetch."""
    wait = (answer.get("robot") or {}).get("wait_for", "human.a1.fetch.depart")
    agent, action, phase, event = wait.split(".")
    return {"agent": agent, "action": action, "phase": phase, "event": event}


def test_a_compile_into_the_folder_a_console_serves_is_refused_and_the_console_answers_on(compiles, tmp_path):
    """The issue's attack: ``hrc compile --out DIR`` (another seed) while ``hrc console DIR`` runs with its
    log elsewhere. Was: the new compiled.json read at the old offsets, ``/state`` 500, presses unanswered."""
    from websockets.sync.client import connect

    out = _copy(compiles, "seed0", tmp_path / "out")
    before = tree_bytes(out)
    (tmp_path / "logs").mkdir()
    console = ConsoleProcess(out, tmp_path / "logs" / "run.jsonl", "--tick", "0")
    try:
        state = console.state()
        assert state["routes"], "the plan's routes (read from compiled.json at its offsets)"
        _refused(_compile(compiles["task"], out, "--seed", "1"), out)
        assert tree_bytes(out) == before
        again = console.state()
        assert again["routes"] == state["routes"] and again["decision"] == state["decision"]
        with connect(console.ws + "ws", open_timeout=10, close_timeout=5,
                     additional_headers=console.page_headers()) as page:
            option = again["options"][0]
            page.send(json.dumps({"type": "press", "hseq": again["hseq"], "id": 1, **option}))
            while (reply := json.loads(page.recv(timeout=10)))["type"] != "reply":
                pass
        assert reply["ok"], reply
        after = console.state()
        assert after["routes"], after  # the next plan's motions, read from the file the console opened
    finally:
        console.stop()
    # the run's log replays against the folder, answer for answer (the independent truth: a fresh dispatcher)
    pairs = list(replay(Dispatcher.from_folder(out), read_log(console.log), str(console.log)))
    assert pairs and all(got == logged for got, logged in pairs)
    assert _compile(compiles["task"], out, "--seed", "1").returncode == 0  # the console gone: the folder is free


def test_a_compile_into_the_folder_hrc_dispatch_serves_is_refused_and_it_answers_on(compiles, tmp_path):
    out = _copy(compiles, "seed0", tmp_path / "out")
    log = tmp_path / "run.jsonl"
    run = DispatchProcess(out, log)
    first = run.ask({"t": 0, "event": "tick"})
    assert first["ok"], first
    _refused(_compile(compiles["task"], out, "--seed", "1"), out)
    second = run.ask({"t": 0.5, **_human_first(first)})
    assert second["ok"], second
    code, err = run.end()
    assert code == 0, err
    pairs = list(replay(Dispatcher.from_folder(out), read_log(log), str(log)))
    assert [json.loads(got) for got, _ in pairs] == [first, second]
    assert _compile(compiles["task"], out, "--seed", "1").returncode == 0  # ended: the lock went with it
    assert json.loads((out / "compiled.json").read_text())["seed"] == 1


def test_a_run_that_starts_during_a_compile_stops_its_swap(compiles, tmp_path, monkeypatch, capsys):
    """A compile claims the folder (no run uses it), and while it compiles ``hrc dispatch`` starts on the
    earlier output: the swap refuses, the earlier output stays, the run answers on."""
    import hrc.compile.stream as stream

    out = _copy(compiles, "seed0", tmp_path / "out")
    before = tree_bytes(out)
    real = stream.compile_stream
    runs: list[DispatchProcess] = []

    def meanwhile(*args: Any, **kwargs: Any) -> Any:
        result = real(*args, **kwargs)
        runs.append(DispatchProcess(out, tmp_path / "run.jsonl"))
        assert runs[0].ask({"t": 0, "event": "tick"})["ok"]  # it has loaded the folder, and holds it
        return result

    monkeypatch.setattr(stream, "compile_stream", meanwhile)
    assert main(["compile", str(compiles["task"]), "--out", str(out), "-q", "--jobs", "1", "--no-report",
                 "--seed", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a run started during the compile" in err, err
    assert tree_bytes(out) == before and sorted(p.name for p in tmp_path.iterdir()) == ["out", "run.jsonl"]
    assert runs[0].ask({"t": 1, "event": "tick"})["ok"]
    assert runs[0].end()[0] == 0


def test_a_run_reads_the_motions_it_opened_whatever_is_put_at_the_path(compiles, tmp_path):
    """What a run reads later (a plan's motions, at offsets into compiled.json) comes from the file it
    opened at the start: a folder moved away and another compile put in its place (by hand, say: no lock
    stops ``mv``) changes nothing of what it reads."""
    out = _copy(compiles, "seed0", tmp_path / "out")
    plan_set = load_plan_set(out)
    motions = plan_motions(out, plan_set)
    truth = {p["id"]: p["motions"] for p in json.loads((out / "compiled.json").read_text())["plans"]}
    other = {p["id"]: p["motions"] for p in json.loads((compiles["seed1"] / "compiled.json").read_text())["plans"]}
    assert truth.keys() == other.keys() and truth != other  # another seed: the same plans, other motions
    os.rename(out, tmp_path / "gone")
    shutil.copytree(compiles["seed1"], out)
    shutil.rmtree(tmp_path / "gone")
    assert {plan_id: motions(plan_id) for plan_id in truth} == truth
    plan_set.close()


def test_a_log_of_another_seeds_compile_is_refused_for_that_reason(compiles, tmp_path):
    """Two compiles of one task with two seeds: the same plan ids in the same order (the old digest, of
    the task and the ids, was the same), other STNUs and motions. The log of a run on one is refused by
    the other when it is opened, in one line saying so (was: caught at its first answer that differed)."""
    seed0, seed1 = load_plan_set(compiles["seed0"]), load_plan_set(compiles["seed1"])
    assert [seed0.id(p) for p in range(len(seed0))] == [seed1.id(p) for p in range(len(seed1))]
    assert seed0.digest != seed1.digest
    again = load_plan_set(_copy(compiles, "seed0", tmp_path / "copy"))
    assert again.digest == seed0.digest  # the content, not where it lies
    for s in (seed0, seed1, again):
        s.close()
    log = tmp_path / "run.jsonl"
    run = DispatchProcess(compiles["seed0"], log)
    assert run.ask({"t": 0, "event": "tick"})["ok"]
    assert run.end()[0] == 0
    for option in ("--replay", "--resume"):
        done = subprocess.run([sys.executable, "-m", "hrc", "dispatch", str(compiles["seed1"]), option, str(log)],
                              cwd=ROOT, env=ENV, text=True, capture_output=True, timeout=60, stdin=subprocess.DEVNULL)
        assert done.returncode == 2, done.stderr
        assert done.stderr.count("\n") == 1, done.stderr
        assert "the log was written for another compiled plan set" in done.stderr, done.stderr


@pytest.mark.slow
def test_a_folder_held_by_a_killed_run_is_free_again(compiles, tmp_path):
    """The kernel drops a run's hold when it dies, however: kill -9 of ``hrc dispatch`` and the compile
    goes ahead."""
    out = _copy(compiles, "seed0", tmp_path / "out")
    run = DispatchProcess(out, tmp_path / "run.jsonl")
    assert run.ask({"t": 0, "event": "tick"})["ok"]
    _refused(_compile(compiles["task"], out, "--seed", "1"), out)
    run.proc.kill()
    run.end()
    t0 = time.monotonic()
    assert _compile(compiles["task"], out, "--seed", "1").returncode == 0
    assert time.monotonic() - t0 < 120
