"""Outside instances (shared/benchmarks/stnu): every recorded verdict is reproduced, via `hrc check`.

Verdicts come from their sources (see INDEX.md there); none is special-cased. Mapping of expected values:
``DC`` -> DC; ``consistent-not-DC`` -> not DC; ``inconsistent`` -> inconsistent; ``not-DC`` -> not DC or
inconsistent (the source only says "not DC"); ``unknown`` (format fixtures) -> any verdict, but the file
must read.
"""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import pytest

from hrc.cli import main
from hrc.temporal import Verdict, check_dc
from hrc.temporal.dc import ALGORITHMS
from hrc.temporal.graphml import read_graphml, read_network, write_graphml
from hrc.temporal.rul import rul2021_check

ROOT = Path(__file__).resolve().parents[1]


def _find_bench() -> Path:
    """The outside instances: $HRC_SHARED/benchmarks/stnu, else the nearest `shared/benchmarks/stnu` in a
    folder above the checkout (beside it for /work/main, two levels up for a worktree under /work/wt)."""
    import os

    if os.environ.get("HRC_SHARED"):
        return Path(os.environ["HRC_SHARED"]) / "benchmarks" / "stnu"
    for parent in ROOT.parents:
        if (parent / "shared" / "benchmarks" / "stnu" / "verdicts.csv").is_file():
            return parent / "shared" / "benchmarks" / "stnu"
    return ROOT.parent / "shared" / "benchmarks" / "stnu"


BENCH = _find_bench()
needs_shared = pytest.mark.skipif(
    not (BENCH / "verdicts.csv").is_file(),
    reason=f"outside instances not found at {BENCH} (set HRC_SHARED to the shared folder)",
)

ACCEPT = {
    "DC": {"DC"},
    "consistent-not-DC": {"not DC"},
    "inconsistent": {"inconsistent"},
    "not-DC": {"not DC", "inconsistent"},
    "unknown": {"DC", "not DC", "inconsistent"},
}


def _rows() -> list[dict[str, str]]:
    if not (BENCH / "verdicts.csv").is_file():
        return []
    with open(BENCH / "verdicts.csv", newline="") as fh:
        return list(csv.DictReader(fh))


@needs_shared
@pytest.mark.parametrize("algorithm", sorted(ALGORITHMS))
def test_every_instance_gets_its_recorded_verdict(algorithm: str) -> None:
    rows = _rows()
    assert len(rows) >= 500
    wrong = []
    for row in rows:
        result = check_dc(read_network(BENCH / row["file"]), algorithm)
        if result.verdict.value not in ACCEPT[row["expected"]]:
            wrong.append((row["file"], row["expected"], result.verdict.value))
    assert wrong == []


@needs_shared
def test_rul2021_python_gets_every_recorded_verdict_too() -> None:
    """check_dc's rul2021 verdict comes from the C core when it is built; the Python one must match."""
    wrong = []
    for row in _rows():
        verdict = rul2021_check(read_network(BENCH / row["file"]), accelerated=False)[0]
        if verdict not in ACCEPT[row["expected"]]:
            wrong.append((row["file"], row["expected"], verdict))
    assert wrong == []


@needs_shared
@pytest.mark.parametrize("row", [r for r in _rows() if r["file"].startswith("cstnu_tool/")], ids=lambda r: r["file"])
def test_hrc_check_json_on_cstnu_tool_instances(row: dict[str, str], capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["check", "--json", str(BENCH / row["file"])]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) == {"file", "algorithm", "verdict", "consistent", "nodes", "edges", "contingent", "seconds",
                        "cycle"}
    assert out["verdict"] in ACCEPT[row["expected"]]
    assert out["consistent"] is (out["verdict"] != "inconsistent")
    assert (out["cycle"] == []) is (out["verdict"] == "DC")
    if out["cycle"]:
        assert sum(e["value"] for e in out["cycle"]) < 0


@needs_shared
def test_graphml_round_trip_keeps_verdicts() -> None:
    for row in _rows():
        if row["file"].startswith("cstnu_tool/") or row["file"].endswith(("1.json", "uncontrollable7.json")):
            net = read_network(BENCH / row["file"])
            again = check_dc(read_graphml(write_graphml(net).encode()))
            assert again.verdict is check_dc(net).verdict, row["file"]


def test_hrc_check_text_output_and_exit_codes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    good = tmp_path / "n.stnu"
    good.write_text("# KIND OF NETWORK\nSTNU\n# Num Time-Points\n3\n# Num Ordinary Edges\n2\n"
                    "# Num Contingent Links\n1\n# Time-Point Names\nA C X\n# Ordinary Edges\nX 2 C\nC -1 X\n"
                    "# Contingent Links\nA 1 10 C\n")
    assert main(["check", str(good)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "not DC"
    assert "3 nodes, 2 edges, 1 contingent links" in out[1] and " ms" in out[1]
    assert "semi-reducible negative cycle" in out[2] and any("lc(C):1" in line for line in out[3:])
    bad = tmp_path / "bad.stnu"
    bad.write_text("# KIND OF NETWORK\nSTNU\n# Num Time-Points\nx\n")
    assert main(["check", str(bad)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"error: {bad}:4:") and "\n" not in err


def test_hrc_check_as_a_process(tmp_path: Path) -> None:
    bad = tmp_path / "bad.graphml"
    bad.write_text("<graphml><graph>")
    proc = subprocess.run([sys.executable, "-m", "hrc", "check", str(bad)], capture_output=True, text=True,
                          cwd=ROOT, check=False)
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr.count("\n") == 1 and proc.stderr.startswith(f"error: {bad}:1:")


@pytest.mark.slow
@needs_shared
def test_501_node_instances_check_in_under_a_second() -> None:
    import time

    for path in sorted((BENCH / "cstnu_tool").iterdir()):
        if path.suffix not in {".stnu", ".stn"}:
            continue
        net = read_network(path)
        if len(net.timepoints) < 500:
            continue
        start = time.perf_counter()
        result = check_dc(net)
        assert time.perf_counter() - start < 1.0, path.name
        assert result.verdict in (Verdict.DC, Verdict.NOT_DC, Verdict.INCONSISTENT)
