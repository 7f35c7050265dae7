"""A team's simulated runs kept as dispatcher logs and MCAP recordings (issue 37: ``hrc simulate --keep-logs``,
``--record``), and a person's absence in a team's run (``--absence-rate``).

The truth each test holds to is the real dispatcher's, not the simulator's: each run's log, fed to a fresh
dispatcher over the same compile by ``hrc dispatch --replay``'s own loop (`hrc.dispatch.protocol.replay`,
header check included), gives every logged answer again, byte for byte; the recording, read back with MCAP's
own reader (tests/mcap_check.py), holds those same answers on ``/hrc/out`` and a pose channel per agent, a
goal channel per robot (``hrc dispatch --record``'s team form). Under late buttons the log carries each
message's ``delay`` and the stated maximum, so that its replay reads the sensing as the run did.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import pytest
from conftest import ROOT
from mcap_check import read_mcap

from hrc.compile.compiler import compile_task
from hrc.dispatch import Dispatcher
from hrc.dispatch.logfile import read_log
from hrc.dispatch.protocol import replay
from hrc.io.task_file import load_task
from hrc.model import SENSING_PATHS, Sensing
from hrc.sim.montecarlo import simulate, simulation_json
from hrc.sim.run import SimContext, SimSettings
from hrc.sim.runlog import log_name

POSE = ("foxglove.PoseInFrame", "protobuf", "protobuf")


@pytest.fixture(scope="module")
def workers() -> SimContext:
    task = load_task(ROOT / "tasks" / "two_workers.yaml")
    return SimContext(task, {"motion": compile_task(task, seed=0, jobs=1)}, SimSettings(), 0)


@pytest.fixture(scope="module")
def workers_late() -> SimContext:
    full = load_task(ROOT / "tasks" / "two_workers.yaml")
    delay, dated = SENSING_PATHS["buttons"]
    task = replace(full, sensing=Sensing("buttons", delay, dated))
    return SimContext(task, {"motion": compile_task(task, seed=0, jobs=1)}, SimSettings(detection_delay=0.5), 0)


def _replays(ctx: SimContext, sim, runs: int, tmp_path: Path) -> None:
    """Every dispatched run's log replays answer for answer on a fresh dispatcher over the same compile."""
    pristine = Dispatcher.from_compiled(ctx.compiles["motion"])
    for i in range(runs):
        path = tmp_path / log_name("hrc", i)
        path.write_bytes(sim.logs["hrc"][i])
        contents = read_log(path)
        assert contents.torn is None and len(contents.messages) > 10
        assert contents.header["team"] == {a.id: a.kind.value for a in ctx.task.agents}
        pairs = list(replay(pristine.fork(), contents, str(path)))
        assert pairs and all(a == b for a, b in pairs)
        # every robot and person named in the answers, and every person's events in the log
        outs = [json.loads(b) for _, b in pairs]
        assert all(set(o["robots"]) == {"robot"} and set(o["people"]) == {"alice", "bob"} for o in outs if o["ok"])
        sent = [json.loads(m.data) for m in contents.messages]
        assert {m.get("agent") for m in sent} >= {"alice", "bob", "robot"}


def test_a_teams_runs_logs_replay_answer_for_answer(workers: SimContext, tmp_path: Path) -> None:
    plain = simulate(workers.task, 3, 1, ["hrc", "fixed"], jobs=1, compiles=workers.compiles)
    kept = simulate(workers.task, 3, 1, ["hrc", "fixed"], jobs=1, compiles=workers.compiles, keep_logs=True)
    assert plain.logs is None and sorted(kept.logs) == ["fixed", "hrc"]
    assert simulation_json(plain) == simulation_json(kept)  # keeping the logs changes no run
    _replays(workers, kept, 3, tmp_path)
    fixed = read_log_bytes(kept.logs["fixed"][0], tmp_path / "fixed.jsonl")
    assert all(set(json.loads(m.answer)["robots"]) == {"robot"} for m in fixed.messages)
    assert "max_observation_delay" not in fixed.header


def test_a_teams_logs_under_late_buttons_replay_with_their_delays(workers_late: SimContext, tmp_path: Path) -> None:
    kept = simulate(workers_late.task, 2, 0, ["hrc"], workers_late.settings, jobs=1, compiles=workers_late.compiles,
                    keep_logs=True)
    contents = read_log_bytes(kept.logs["hrc"][0], tmp_path / "x.jsonl")
    assert contents.header["max_observation_delay"] == 0.5
    people = [json.loads(m.data) for m in contents.messages]
    people = [m for m in people if m.get("agent") in ("alice", "bob")]
    assert people and all(m["delay"] == 0.5 for m in people)
    _replays(workers_late, kept, 2, tmp_path)


def read_log_bytes(data: bytes, path: Path):
    path.write_bytes(data)
    return read_log(path)


def test_a_teams_run_is_recorded_as_hrc_dispatch_records_a_team(workers: SimContext) -> None:
    from hrc.record.sim import record_run

    kept = simulate(workers.task, 1, 1, ["hrc"], jobs=1, compiles=workers.compiles, keep_logs=True)
    data, result = record_run(replace(workers, seed=1), "hrc", 0)
    ids = [a.id for a in workers.task.agents]
    expected = {f"/hrc/{i}/pose": POSE for i in ids} | {"/hrc/robot/goal": POSE}
    rec = read_mcap(data, expected)
    assert set(expected) <= set(rec.channels)
    assert all(rec.counts[f"/hrc/{i}/pose"] > 10 for i in ids) and rec.counts["/hrc/robot/goal"] >= 1
    # the recording holds the run's exchanges: the same answers as its log
    log = [json.loads(line) for line in kept.logs["hrc"][0].decode().splitlines()[1:]]
    answers = [json.loads(r["out"]) for r in log if "out" in r]
    assert rec.of("/hrc/out") == answers
    assert all(set(d["robots"]) == {"robot"} for d in rec.of("/hrc/decision"))
    assert result.finished and result.makespan == kept.results["hrc"][0].makespan
