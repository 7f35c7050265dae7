"""The fuzz corpus replayed through the fuzz targets (`fuzz/targets.py`, docs/fuzzing.md), without
libFuzzer: every seed, and every input a fuzz run found that once crashed (kept in the corpus as
``crash-*``), must keep the targets' contract (only hrc's own errors escape; answers well formed; the
C cores agree with the Python definitions). The file parsers run by default; the targets that dispatch
on a compiled workshop, and the native ones (their inputs are read by atheris' FuzzedDataProvider),
under ``-m slow``.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest
from conftest import ROOT

sys.path.insert(0, str(ROOT / "fuzz"))
import targets  # noqa: E402

CORPUS = ROOT / "fuzz" / "corpus"
NEEDS_MORE = set(targets.COMPILED) | set(targets.NATIVE) | set(targets.TEAM) | set(targets.CREW)


def _inputs(name: str) -> list[Path]:
    return sorted((CORPUS / name).iterdir())


def test_every_target_has_a_seed_corpus() -> None:
    assert set(targets.TARGETS) == {p.name for p in CORPUS.iterdir() if p.is_dir()}
    for name in targets.TARGETS:
        assert _inputs(name), name


@pytest.mark.parametrize("name", sorted(set(targets.TARGETS) - NEEDS_MORE))
def test_the_parsers_keep_their_contract_on_the_corpus(name: str) -> None:
    for path in _inputs(name):
        targets.TARGETS[name](path.read_bytes())


@pytest.fixture(scope="module")
def workshop(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from conftest import compiled_folder

    return compiled_folder(tmp_path_factory.mktemp("fuzz") / "ws", ROOT / "tasks" / "cube_stacking.yaml", "--jobs", "1")


@pytest.fixture(scope="module")
def team(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from conftest import compiled_folder

    return compiled_folder(tmp_path_factory.mktemp("fuzz") / "team", ROOT / "tasks" / "two_workers.yaml", "--jobs", "1")


@pytest.fixture(scope="module")
def crew(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from conftest import compiled_folder

    return compiled_folder(tmp_path_factory.mktemp("fuzz") / "crew", ROOT / "tasks" / "two_workers_joint.yaml",
                           "--jobs", "1")


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(NEEDS_MORE))
def test_the_protocols_and_cores_keep_their_contract_on_the_corpus(name: str, workshop: Path, team: Path, crew: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip("atheris")
    monkeypatch.setitem(os.environ, targets.COMPILED_VARIABLE, str(workshop))
    monkeypatch.setitem(os.environ, targets.TEAM_VARIABLE, str(team))
    monkeypatch.setitem(os.environ, targets.CREW_VARIABLE, str(crew))
    for path in _inputs(name):
        targets.TARGETS[name](path.read_bytes())


def test_no_comparison_atheris_miscompiles() -> None:
    """atheris 2.3.0's instrumentation (what the fuzz targets run) miscompiles a comparison whose operand
    is a conditional expression with a list display of constants in a branch (Python 3.11: ``x != (a if
    c else [1, 2, 3])`` returns ``a`` when ``c`` holds). Fuzzing code of that shape fuzzes other code
    than ships: once it made every team dispatcher refuse its own compile (`hrc.dispatch.plan_set`)."""
    import ast

    def lists(node: ast.AST) -> bool:
        return any(isinstance(n, ast.List | ast.Set) and len(n.elts) >= 3 for n in ast.walk(node))

    found = []
    for path in sorted((ROOT / "hrc").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Compare):
                found += [f"{path.relative_to(ROOT)}:{node.lineno}" for opnd in (node.left, *node.comparators)
                          if isinstance(opnd, ast.IfExp) and (lists(opnd.body) or lists(opnd.orelse))]
    assert not found, found
