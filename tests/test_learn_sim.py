"""The simulator's logs (``hrc simulate --keep-logs``) and recordings as `hrc learn` reads them: the same
runs, a log the dispatcher itself replays answer for answer, and simulation.json unchanged."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import WORKSHOP_TASK

from hrc.dispatch import Dispatcher
from hrc.dispatch.logfile import read_log
from hrc.dispatch.protocol import replay
from hrc.io.task_file import load_task
from hrc.learn.estimate import durations_of
from hrc.learn.runs import read_run, read_runs
from hrc.sim.human import HumanModel, scaled_truth
from hrc.sim.montecarlo import simulate, simulation_json
from hrc.sim.run import SimSettings
from hrc.sim.runlog import log_name

TASK = load_task(WORKSHOP_TASK)


@pytest.fixture(scope="module")
def sims() -> tuple:
    settings = SimSettings(human=HumanModel(choice="free"))
    plain = simulate(TASK, 4, 3, ["hrc", "fixed"], settings, jobs=1)
    kept = simulate(TASK, 4, 3, ["hrc", "fixed"], settings, jobs=1, compiles=plain.context.compiles, keep_logs=True)
    return plain, kept


def _write(kept, folder: Path) -> Path:
    folder.mkdir()
    for policy, logs in kept.logs.items():
        for i, data in logs.items():
            (folder / log_name(policy, i)).write_bytes(data)
    return folder


def test_keeping_logs_changes_no_run(sims: tuple) -> None:
    plain, kept = sims
    assert plain.logs is None and sorted(kept.logs) == ["fixed", "hrc"]
    assert simulation_json(plain) == simulation_json(kept)


def test_a_simulated_runs_log_replays_answer_for_answer(sims: tuple, tmp_path: Path) -> None:
    _, kept = sims
    folder = _write(kept, tmp_path / "runs")
    pristine = Dispatcher.from_compiled(kept.context.compiles["motion"])
    for i in range(4):
        contents = read_log(folder / log_name("hrc", i))
        assert contents.torn is None and len(contents.messages) > 10
        pairs = list(replay(pristine.fork(), contents))
        assert all(a == b for a, b in pairs)


def test_learn_reads_each_run_as_it_happened(sims: tuple, tmp_path: Path) -> None:
    _, kept = sims
    folder = _write(kept, tmp_path / "runs")
    runs, skipped = read_runs(TASK, [folder])
    assert not skipped and len(runs) == 8
    results = {(r.policy, r.run): r for p in kept.results.values() for r in p}
    for run in runs:
        policy, index = Path(run.source).stem.rsplit("-", 1)
        result = results[(policy, int(index))]
        assert run.sequence("human") == result.human_sequence
        assert run.sequence("robot") == result.robot_sequence


def test_a_recording_holds_the_same_events_as_the_log(sims: tuple, tmp_path: Path) -> None:
    from hrc.io.task_file import task_digest
    from hrc.record.sim import record_run

    _, kept = sims
    data, _ = record_run(kept.context, "hrc", 1)
    (tmp_path / "run.mcap").write_bytes(data)
    (tmp_path / "run.jsonl").write_bytes(kept.logs["hrc"][1])
    from_mcap, skip_a = read_run(tmp_path / "run.mcap", task_digest(TASK))
    from_log, skip_b = read_run(tmp_path / "run.jsonl", task_digest(TASK))
    assert not skip_a and not skip_b and from_mcap is not None and from_log is not None
    assert from_mcap.events == from_log.events and len(from_log.events) > 20


@pytest.mark.slow
def test_two_simulated_worker_types_are_recovered(sims: tuple, tmp_path: Path) -> None:
    """A fast worker who takes the actions in a preferred order and a slow one who chooses freely (the
    hidden true durations 0.6 and 1.3 times the task's bounds), 25 runs each: the types found match."""
    from hrc.io.task_file import task_digest
    from hrc.learn.worker_types import adjusted_rand_index, find_types

    compiles = sims[0].context.compiles
    fast = HumanModel(choice="preferred", preferred=("cube2", "cube4", "cube1", "cube3", "triangle"),
                      truth=scaled_truth(TASK, 0.6))
    slow = HumanModel(choice="free", truth=scaled_truth(TASK, 1.3))
    runs, truth = [], []
    for label, (model, seed) in enumerate(((fast, 11), (slow, 12))):
        sim = simulate(TASK, 25, seed, ["hrc"], SimSettings(human=model), jobs=1, compiles=compiles, keep_logs=True)
        for i, data in sorted(sim.logs["hrc"].items()):
            path = tmp_path / f"{label}-{i:04d}.jsonl"
            path.write_bytes(data)
            run, _ = read_run(path, task_digest(TASK))
            assert run is not None
            runs.append(run)
            truth.append(label)
    types = find_types(TASK, runs, 0.80, 0.80)
    ari = adjusted_rand_index(truth, types.labels)
    print(f"worker types: k={types.k}, silhouettes {types.scores}, adjusted Rand index {ari:.3f}")
    assert types.k == 2 and ari >= 0.8


def test_simulate_keeps_logs_learn_reads_them(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import json

    from hrc.cli import main

    out = tmp_path / "sim"
    assert main(["simulate", str(WORKSHOP_TASK), "--runs", "2", "--policy", "hrc", "--keep-logs", "--no-figures",
                 "--true-scale", "0.8", "--jobs", "1", "-q", "--out", str(out)]) == 0
    assert sorted(p.name for p in (out / "runs").iterdir()) == ["hrc-0000.jsonl", "hrc-0001.jsonl"]
    human = json.loads((out / "simulation.json").read_text())["settings"]["human"]
    assert human["truth"][0] == ["cube1", "fetch", pytest.approx(1.6), pytest.approx(3.2)]
    runs, skipped = read_runs(TASK, [out])
    assert len(runs) == 2 and not skipped
    truth = {(a, p): (lb, ub) for a, p, lb, ub in human["truth"]}
    seen = durations_of(runs)
    assert any(agent == "human" for agent, _, _ in seen)
    for (agent, action, phase), ds in seen.items():  # the person's times on the hidden truth (times: to the ms)
        lb, ub = truth[(action, phase)] if agent == "human" else TASK.action(action).phase(phase).duration(agent)
        assert all(lb - 0.002 <= d <= ub + 0.002 for d in ds)
    assert main(["simulate", str(WORKSHOP_TASK), "--runs", "1", "--true-scale", "0", "-q",
                 "--out", str(tmp_path / "bad")]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_a_motion_detectors_run_keeps_its_positions_and_gives_the_sensing_delays(sims: tuple, tmp_path: Path) -> None:
    from hrc.detect import DetectingDispatcher, DetectParams
    from hrc.learn.estimate import learn

    compiles = sims[0].context.compiles
    settings = SimSettings(human=HumanModel(choice="follow"), detector="motion")
    sim = simulate(TASK, 1, 5, ["hrc"], settings, jobs=1, compiles=compiles, keep_logs=True, baseline=0.0)
    path = tmp_path / "motion.jsonl"
    path.write_bytes(sim.logs["hrc"][0])
    contents = read_log(path)
    assert contents.header["detect"]["detector"] == "motion"
    fresh = DetectingDispatcher.from_compiled(compiles["motion"], threads=1,
                                              params=DetectParams(sigma=max(settings.sensor.sigma, 0.01)))
    assert all(a == b for a, b in replay(fresh, contents, str(path)))  # the dispatcher's own answers
    (run,), skipped = read_runs(TASK, [path])
    assert not skipped
    human = [e for e in run.events if e.agent == "human"]
    assert {e.event for e in human} >= {"depart", "arrive", "start", "end"} and all(e.at is not None for e in human)
    delays = dict(learn(TASK, [run]).delays.by_event)
    assert sorted(delays) == ["arrive", "depart", "end", "start"]
    assert all(0.0 <= x < 5.0 for xs in delays.values() for x in xs)


def test_a_hidden_truth_is_checked() -> None:
    from hrc.errors import SimulationError

    with pytest.raises(SimulationError, match=r"true duration of cube1.fetch must be 0 <= LB <= UB, found 3 2"):
        HumanModel(truth=(("cube1", "fetch", 3.0, 2.0),))
    with pytest.raises(SimulationError, match=r"name cube9.fetch, not a phase of cube_stacking"):
        HumanModel(truth=(("cube9", "fetch", 1.0, 2.0),)).check(TASK)
    with pytest.raises(SimulationError, match="--true-scale must be a finite number > 0, found -1"):
        scaled_truth(TASK, -1.0)
    truth = dict(((a, p), (lb, ub)) for a, p, lb, ub in scaled_truth(TASK, 0.5))
    assert truth[("triangle", "put")] == (1.5, 3.0) and len(truth) == 10
