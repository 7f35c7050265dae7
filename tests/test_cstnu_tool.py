"""The CSTNU Tool itself on the GraphML hrc writes: the other side of our GraphML.

`cstnu-check` (``../shared/oracles/cstnu-tool``, beside the repository: its README) runs the tool's own
reader and DC check (RUL2021) on each file and prints ``DC``, ``NOT_DC`` or ``ERROR`` with the tool's
exception. Every file hrc writes must read (DC or NOT_DC: never ERROR) and the tool's verdict must be
hrc's class (DC for DC; NOT_DC for consistent and inconsistent): on the workshop's compile, on kitting's
(a pinned part by default, all 2,880 plans in a slow test), on random networks, and on blocked plans.

Skipped, saying why, where the oracle is absent (no ``cstnu-check`` beside the repository). Where it is
there but cannot run (no Java / libraries: ``cstnu-check --install`` as root, which `make test` runs),
skipped too, or failed under ``HRC_REQUIRE_CSTNU_TOOL=1``, as CI sets it. Set ``HRC_CSTNU_CHECK`` to use
another copy.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

from hrc.cli import main
from hrc.compile.compiler import CompileOptions, compile_family, compile_plan
from hrc.compile.motion_pattern import pattern_network
from hrc.compile.output import iter_plans
from hrc.io.task_file import load_task
from hrc.motion import plan_paths
from hrc.plans import generate_plans, plan_families
from hrc.temporal import STNU, ContingentLink, RequirementLink, check_dc
from hrc.temporal.graphml import read_network, write_graphml

TOOL = Path(os.environ.get("HRC_CSTNU_CHECK", ROOT.parent / "shared" / "oracles" / "cstnu-tool" / "cstnu-check"))
TOOL_VERDICT = {"DC": "DC", "consistent": "NOT_DC", "inconsistent": "NOT_DC"}
"""The tool's verdict for each of hrc's classes (the tool says only whether a network is DC)."""


def _absent(why: str) -> None:
    if os.environ.get("HRC_REQUIRE_CSTNU_TOOL") == "1":
        pytest.fail(f"the CSTNU Tool tests are required (HRC_REQUIRE_CSTNU_TOOL=1) but {why}")
    pytest.skip(f"CSTNU Tool tests skipped: {why}")


@pytest.fixture(scope="session")
def tool() -> Path:
    """The oracle's path, once it has shown it runs: skipped, saying why, where there is no oracle (a clone
    without shared/ beside it); where there is one that cannot run, failed under HRC_REQUIRE_CSTNU_TOOL=1
    (CI, whose `make test` installs its Java) and skipped otherwise."""
    if not TOOL.is_file():
        pytest.skip(f"CSTNU Tool tests skipped: no {TOOL} (the oracle lies in shared/oracles/cstnu-tool beside "
                    "the repository)")
    probe = subprocess.run([str(TOOL)], capture_output=True, text=True, timeout=120)
    if probe.returncode == 3:  # its documented "Java or a library is missing"
        _absent(f"{probe.stderr.strip()} (as root: {TOOL} --install; `make test` does it)")
    return TOOL


def tool_verdicts(tool: Path, files: list[Path]) -> dict[str, str]:
    """File name -> the tool's DC / NOT_DC / ``ERROR: why``, from one call (one JVM) for all `files`."""
    done = subprocess.run([str(tool), *map(str, files)], capture_output=True, text=True, timeout=1800)
    assert done.returncode == 0, done.stderr
    out = {}
    for line in done.stdout.splitlines():
        path, verdict, *why = line.split("\t")
        out[Path(path).name] = verdict if verdict in ("DC", "NOT_DC") else f"{verdict}: {' '.join(why)}"
    assert len(out) == len(files), done.stdout[-2000:]
    return out


def _agree(tool: Path, classes: dict[Path, str]) -> dict[str, int]:
    """Run the tool on every file of `classes` (file -> hrc's class) at once; require that it reads each
    and that its verdict is the class's; return the tool's verdict counts."""
    verdicts = tool_verdicts(tool, sorted(classes))
    refused = {name: v for name, v in verdicts.items() if v not in ("DC", "NOT_DC")}
    assert not refused, f"{len(refused)} of {len(verdicts)} files refused, e.g. {next(iter(refused.items()))}"
    wrong = {p.name: (cls, verdicts[p.name]) for p, cls in classes.items() if TOOL_VERDICT[cls] != verdicts[p.name]}
    assert not wrong, f"{len(wrong)} of {len(verdicts)} verdicts differ (hrc's class, the tool's), e.g. {wrong}"
    return {v: list(verdicts.values()).count(v) for v in ("DC", "NOT_DC")}


def _compiled_classes(out: Path) -> dict[Path, str]:
    return {out / p["stnu"]: p["class"] for p in iter_plans(out)}  # kitting's lines are in plans.jsonl


def _compile(task: str, out: Path) -> dict[Path, str]:
    assert main(["compile", str(ROOT / "tasks" / task), "--out", str(out), "--no-report", "-q"]) == 0
    return _compiled_classes(out)


def test_the_tool_reads_every_workshop_stnu_and_agrees(tool: Path, tmp_path: Path) -> None:
    classes = _compile("cube_stacking.yaml", tmp_path / "ws")
    assert len(classes) == 32
    counts = _agree(tool, classes)
    assert counts == {"DC": 11, "NOT_DC": 21}  # 11 DC, 13 consistent, 8 inconsistent (the compile's counts)
    for path, cls in classes.items():  # and hrc on the file alone, as the tool reads it
        assert TOOL_VERDICT[cls] == ("DC" if check_dc(read_network(path)).is_dc else "NOT_DC")


def _write(folder: Path, cps: list) -> dict[Path, str]:
    folder.mkdir(parents=True, exist_ok=True)
    out = {}
    for cp in cps:
        path = folder / f"{cp.plan.id}.graphml"
        path.write_text(cp.graphml, "utf-8")
        out[path] = cp.plan_class.value
    return out


def test_the_tool_reads_a_pinned_part_of_kitting_and_agrees(tool: Path, tmp_path: Path) -> None:
    """Kitting's plan families (2,880 plans in 360-odd families), every 12th family compiled as the compile
    does (`compile_family`: the first in full, the others renamed): a part of every kind of file."""
    task = load_task(ROOT / "tasks" / "kitting.yaml")
    paths = plan_paths(task, seed=0)
    cps = [cp for family in list(plan_families(task))[::12] for cp in compile_family(task, family, paths)]
    assert len(cps) >= 200
    counts = _agree(tool, _write(tmp_path / "kit", cps))
    assert counts["DC"] and counts["NOT_DC"]


@pytest.mark.slow
def test_the_tool_reads_every_kitting_stnu_and_agrees(tool: Path, tmp_path: Path) -> None:
    """All 2,880 files of `hrc compile tasks/kitting.yaml` in one call of the tool (about 10 s of it)."""
    classes = _compile("kitting.yaml", tmp_path / "kit")
    assert len(classes) == 2880
    assert _agree(tool, classes) == {"DC": 1833, "NOT_DC": 1047}


def test_the_tool_agrees_on_the_hand_worked_joint_start(tool: Path, tmp_path: Path) -> None:
    """Issue 37: the hand-worked joint lift of tests/test_joint.py, as the paper's reading compiles it (DC:
    the robot waits for the person's arrival, then starts) and as the strict one does (the person would
    be at the spot before the robot: not DC), each file as its compile wrote it."""
    from test_joint import LIFT, _write

    task = load_task(_write(tmp_path, LIFT))
    (plan,) = list(generate_plans(task))
    paths = plan_paths(task, seed=0)
    cps = [compile_plan(task, plan, paths), compile_plan(task, plan, paths, CompileOptions(human_waits=False))]
    classes = {}
    for name, cp in zip(("waits", "strict"), cps, strict=True):
        path = tmp_path / f"{name}.graphml"
        path.write_text(cp.graphml, "utf-8")
        classes[path] = cp.plan_class.value
    assert sorted(classes.values()) == ["DC", "inconsistent"]
    assert _agree(tool, classes) == {"DC": 1, "NOT_DC": 1}


@pytest.mark.slow
def test_the_tool_reads_every_joint_workshop_stnu_and_agrees(tool: Path, tmp_path: Path) -> None:
    """Issue 37: the workshop with "support the pile" (a joint action: one start the robot executes once the
    person is there, one contingent end for both): all 32 files, each read and judged as hrc classed it."""
    classes = _compile("cube_stacking_joint.yaml", tmp_path / "joint")
    assert len(classes) == 32
    counts = _agree(tool, classes)
    assert counts["DC"] and counts["NOT_DC"]


def test_the_tool_agrees_on_the_hand_worked_robot_robot_crossing(tool: Path, tmp_path: Path) -> None:
    """Issue 37: the two robots crossing of tests/test_team.py, the passing order the plan chose between
    them a requirement link: DC with room for it (deadline 10.5 s), not DC without (10 s: inconsistent)."""
    from test_team import CROSS, CROSS_MAP, write_task

    classes = {}
    for deadline in (10.5, 10):
        folder = tmp_path / str(deadline)
        folder.mkdir()
        task = load_task(write_task(folder, CROSS | {"deadline": deadline}, CROSS_MAP))
        (plan,) = list(generate_plans(task))
        cp = compile_plan(task, plan, plan_paths(task, seed=0))
        path = tmp_path / f"deadline{deadline:g}-{plan.id}.graphml"  # the tool's verdicts are by file name
        path.write_text(cp.graphml, "utf-8")
        classes[path] = cp.plan_class.value
    assert sorted(classes.values()) == ["DC", "inconsistent"]
    assert _agree(tool, classes) == {"DC": 1, "NOT_DC": 1}


@pytest.mark.slow
@pytest.mark.parametrize(("task", "plans"), [("two_workers.yaml", 120), ("kitting_2robots.yaml", 2520)])
def test_the_tool_reads_every_team_stnu_and_agrees(tool: Path, tmp_path: Path, task: str, plans: int) -> None:
    """Issue 37: tasks of more than one person or robot (two people and a robot, with a joint action of one
    person and the robot; two robots and a person): every person's durations contingent, the passing
    orders between every robot and every other agent requirement links; every file read and judged as
    hrc classed it."""
    classes = _compile(task, tmp_path / "team")
    assert len(classes) == plans
    counts = _agree(tool, classes)
    assert counts["DC"] and counts["NOT_DC"]


@pytest.fixture(scope="module")
def blocked_plans() -> list:
    """Kitting with the person never waiting for the robot's sake (``human_waits=False``): most plans'
    co-workers would block each other (`tests/test_dispatch.py`, the plan the compile found blocked)."""
    task = load_task(ROOT / "tasks" / "kitting.yaml")
    paths = plan_paths(task, seed=0)
    options = CompileOptions(human_waits=False)
    return [compile_plan(task, p, paths, options) for p in list(generate_plans(task))[::90]]


def test_a_blocked_plans_file_carries_the_block(tool: Path, blocked_plans: list, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    """The file of a plan for which motion acquisition found no order of passing says, alone, that it is
    not DC (the tool) and inconsistent (`hrc check`), while the same plan's network without the block
    (what it held before) checks DC for some of them: the file, not compiled.json only, knows."""
    blocked = [cp for cp in blocked_plans if cp.pattern.candidates == 0]
    assert blocked
    classes = _write(tmp_path / "blocked", blocked_plans)
    _agree(tool, classes)
    for cp in blocked:
        path = tmp_path / "blocked" / f"{cp.plan.id}.graphml"
        assert main(["check", str(path)]) == 0
        out = capsys.readouterr().out
        assert out.startswith("inconsistent\n") and "Z" in out, out
    task = load_task(ROOT / "tasks" / "kitting.yaml")
    before = [check_dc(pattern_network(task, cp.plan, cp.pattern, human_waits=False).stnu).is_dc for cp in blocked]
    assert any(before)  # what such a file said before it carried the block


def _random_stnu(rng: np.random.Generator, n: int) -> STNU:
    """A random STNU on `n` timepoints and the origin Z (every timepoint at or after it, as the tool reads
    Z): contingent links ``0 < lb < ub`` chained from Z, requirement links between random pairs (never
    on a contingent link's pair, which the tool's format cannot hold twice), a horizon."""
    tps = ["Z", *(f"t{i}" for i in range(n))]
    conts, used = [], set()
    for c in rng.choice(np.arange(1, n + 1), size=int(rng.integers(0, n // 3 + 1)), replace=False):
        a = int(rng.integers(0, c))
        lb = int(rng.integers(1, 20))
        conts.append(ContingentLink(tps[a], tps[c], lb, lb + int(rng.integers(1, 30))))
        used |= {(a, int(c)), (int(c), a)}
    reqs = [RequirementLink("Z", t, 0, 40 * n) for t in tps[1:]]
    for _ in range(int(rng.integers(n, 3 * n + 1))):
        a, b = (int(x) for x in rng.choice(n + 1, size=2, replace=False))
        if (a, b) in used or a == 0 or b == 0:
            continue
        lb = int(rng.integers(-30, 20))
        reqs.append(RequirementLink(tps[a], tps[b], lb, lb + int(rng.integers(0, 40))))
    return STNU(tuple(tps), tuple(reqs), tuple(conts), f"random {n}")


def test_the_tool_agrees_with_hrc_on_random_networks(tool: Path, tmp_path: Path) -> None:
    rng = np.random.default_rng(27)
    classes = {}
    for i in range(160):
        stnu = _random_stnu(rng, int(rng.integers(2, 30)))
        path = tmp_path / f"r{i:03d}.graphml"
        path.write_text(write_graphml(stnu), "utf-8")
        result = check_dc(stnu)
        assert check_dc(read_network(path)).verdict is result.verdict  # the file says what the network says
        classes[path] = "DC" if result.is_dc else ("consistent" if result.consistent else "inconsistent")
    kinds = set(classes.values())
    assert kinds == {"DC", "consistent", "inconsistent"}, kinds  # the sample holds every class
    _agree(tool, classes)


def test_the_block_is_the_dispatch_forms_too(blocked_plans: list) -> None:
    """A blocked plan's dispatch form record is its GraphML file read back (the block included), so the
    form keeps equal to the files."""
    from hrc.compile.dispatch_form import plan_record
    from hrc.temporal.graphml import read_graphml

    task = load_task(ROOT / "tasks" / "kitting.yaml")
    for cp in blocked_plans:
        back = read_graphml(cp.graphml.encode())
        assert plan_record(task, cp.plan, back, cp.pattern.candidates == 0, graphml_names=True) == cp.form
