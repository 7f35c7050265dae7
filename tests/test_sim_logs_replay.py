"""A simulated run's dispatcher log (``hrc simulate --keep-logs``) replayed by ``hrc dispatch OUT --replay LOG``
over a compile folder of the same task, seed and options, as a user replays it.

The simulator names its compile (in memory) by the digest of the dispatch form's arrays; a folder names
its own by ``form.json``'s, at no cost. The truth held to is the real dispatcher's: each log replays answer
for answer through the command (exit 0), for one pair and for a team; a log the folder's dispatcher did not
write is refused in one line saying why (exit 2): the fixed policy's (no dispatcher), the motion-blind
policy's (another compile), a feasible-only log without ``--feasible-only``.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import ROOT, WORKSHOP_TASK, compiled_folder

from hrc.cli import main


def _simulate(task: Path, out: Path, *policies: str) -> Path:
    args = ["simulate", str(task), "--runs", "2", "--out", str(out), "--keep-logs", "--no-figures", "-q"]
    for policy in policies:
        args += ["--policy", policy]
    assert main(args) == 0
    return out / "runs"


def _replay(folder: Path, log: Path, *extra: str) -> int:
    return main(["dispatch", str(folder), "--replay", str(log), *extra])


@pytest.fixture(scope="module")
def workshop(tmp_path_factory) -> tuple[Path, Path]:
    base = tmp_path_factory.mktemp("workshop")
    return compiled_folder(base / "compiled"), _simulate(WORKSHOP_TASK, base / "sim")


def test_a_simulated_runs_log_replays_over_the_compile_folder(workshop, capsys) -> None:
    folder, runs = workshop
    for i in range(2):
        capsys.readouterr()
        assert _replay(folder, runs / f"hrc-{i:04d}.jsonl") == 0, capsys.readouterr().err
        answers = capsys.readouterr().out.splitlines()
        logged = (runs / f"hrc-{i:04d}.jsonl").read_text().count('{"out": ')
        assert len(answers) == logged > 10
        assert _replay(folder, runs / f"feasible-only-{i:04d}.jsonl", "--feasible-only") == 0


@pytest.mark.parametrize(("policy", "extra", "why"), [
    ("fixed", (), "fixed policy: no dispatcher gave its answers"),
    ("motion-blind", (), "another compiled plan set"),
    ("feasible-only", (), "give --feasible-only"),
    ("hrc", ("--feasible-only",), "leave out --feasible-only"),
])
def test_a_log_another_dispatcher_wrote_is_refused_in_one_line(workshop, capsys, policy, extra, why) -> None:
    folder, runs = workshop
    capsys.readouterr()
    assert _replay(folder, runs / f"{policy}-0000.jsonl", *extra) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and why in err and "Traceback" not in err


def test_a_teams_simulated_log_replays_over_the_compile_folder(tmp_path, capsys) -> None:
    task = ROOT / "tasks" / "two_workers.yaml"
    folder = compiled_folder(tmp_path / "compiled", task)
    runs = _simulate(task, tmp_path / "sim", "hrc")
    for i in range(2):
        assert _replay(folder, runs / f"hrc-{i:04d}.jsonl") == 0, capsys.readouterr().err


def test_a_folder_of_another_seed_refuses_the_log(workshop, tmp_path, capsys) -> None:
    _, runs = workshop
    other = compiled_folder(tmp_path / "other", WORKSHOP_TASK, "--seed", "1")
    capsys.readouterr()
    assert _replay(other, runs / "hrc-0000.jsonl") == 2
    assert "another compiled plan set" in capsys.readouterr().err
