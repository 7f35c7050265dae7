"""Faults injected into real workshop compiles (issue 26): SIGTERM, SIGINT and SIGKILL at random moments
and at named points, then ``--resume`` (after a partial output) or a new compile (after a kill), and the
output compared byte for byte with an uninterrupted run's.

Each run is ``hrc compile tasks/cube_stacking.yaml --jobs 2`` in its own process (the parent and its two
workers, marked by an environment variable so that the test finds every process of the run, orphans
included). What must hold after every fault:

- the process ends with 130 after SIGINT or SIGTERM (never 0 once the signal came: a signal is never
  swallowed), and no process of the run is left (bounded waits), SIGKILL of the parent included;
- ``--out`` is the earlier output (byte for byte), or the complete output, or (only where there was no
  earlier output) a valid partial output, or nothing: never a part, never missing while an earlier one
  existed;
- after SIGINT or SIGTERM nothing but ``--out`` is left beside it; after SIGKILL the next compile into
  the same folder removes what was left, and says so;
- a partial output resumed, and any other state compiled again, gives the uninterrupted run's bytes.

The default run tries a few points; ``-m slow`` tries many more random moments. The named points use
`tests/fault_driver.py`, which runs the real CLI and only picks the instant of the signal.
"""

from __future__ import annotations

import json
import os
import random
import shutil
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest
from conftest import ROOT, WORKSHOP_TASK, tree_bytes

from hrc.cli import main

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc to find the processes")

DRIVER = Path(__file__).with_name("fault_driver.py")
MARK = "HRC_FAULT_TEST_RUN"


def _marked(mark: str) -> list[int]:
    """Live processes (not zombies: an orphan's exit is only reaped by whoever adopts it) whose
    environment holds `mark`."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            if f"{MARK}={mark}".encode() not in (entry / "environ").read_bytes():
                continue
            state = (entry / "stat").read_text().rpartition(")")[2].split()[0]
        except OSError:  # gone meanwhile, or not ours to read
            continue
        if state not in ("Z", "X"):
            found.append(int(entry.name))
    return found


def _wait_gone(mark: str, timeout: float = 15.0) -> None:
    deadline = time.monotonic() + timeout
    while (left := _marked(mark)) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not left, f"processes of the run still alive {timeout} s after it ended: {left}"


def _command(out: Path, *extra: str, driver: tuple[str, ...] = ()) -> list[str]:
    head = [sys.executable, str(DRIVER), *driver, "--"] if driver else [sys.executable, "-m", "hrc"]
    return [*head, "compile", str(WORKSHOP_TASK), "--out", str(out), "--jobs", "2", "-q", *extra]


def _start(out: Path, *extra: str, driver: tuple[str, ...] = ()) -> tuple[subprocess.Popen[str], str]:
    mark = uuid.uuid4().hex
    env = dict(os.environ, PYTHONPATH=str(ROOT), **{MARK: mark})
    proc = subprocess.Popen(_command(out, *extra, driver=driver), env=env, cwd=out.parent, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    return proc, mark


def _finish(proc: subprocess.Popen[str], mark: str, timeout: float = 180) -> tuple[int, str]:
    """Wait for the run's end, then for every process of it to be gone (orphans would hold the pipes)."""
    try:
        proc.wait(timeout)
        _wait_gone(mark)
    finally:
        for pid in _marked(mark):  # (only when a check failed) none of the run's processes outlives the test
            os.kill(pid, signal.SIGKILL)
    _, err = proc.communicate(timeout=30)
    return proc.returncode, err


def _compile(out: Path, *extra: str) -> tuple[int, str]:
    return _finish(*_start(out, *extra))


@pytest.fixture(scope="module")
def truth(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    """The uninterrupted run's output (the independent truth), its wall time, and an earlier output of
    the same task (another seed: other bytes) to put in --out before a run."""
    base = tmp_path_factory.mktemp("truth")
    t0 = time.monotonic()
    code, err = _compile(base / "whole")
    seconds = time.monotonic() - t0
    assert code == 0, err
    code, err = _compile(base / "earlier", "--seed", "1")
    assert code == 0, err
    whole, earlier = tree_bytes(base / "whole"), tree_bytes(base / "earlier")
    assert whole != earlier and json.loads(whole["compiled.json"])["seed"] == 0
    return {"whole": whole, "earlier": earlier, "earlier_dir": base / "earlier", "seconds": seconds}


def _prepare(tmp_path: Path, truth: dict[str, object], earlier: bool) -> Path:
    case = tmp_path / "case"
    case.mkdir()
    out = case / "out"
    if earlier:
        shutil.copytree(truth["earlier_dir"], out)  # type: ignore[arg-type]
    return out


def _check_partial(out: Path) -> None:
    """A valid partial output: ranks 1..n, its counts, exactly its plans' STNU files, ``resume.npy``."""
    data = json.loads((out / "compiled.json").read_text())
    plans = data["plans"]
    assert data["partial"] is True and data["plans_expected"] == 32 and 1 <= len(plans) < 32
    assert [p["rank"] for p in plans] == list(range(1, len(plans) + 1))
    assert sum(data["counts"].values()) == len(plans)
    assert sorted(p.name for p in (out / "stnu").iterdir()) == sorted(f"{p['id']}.graphml" for p in plans)
    assert (out / "resume.npy").is_file() and not (out / "report.md").exists()


def _after_fault(out: Path, truth: dict[str, object], earlier: bool, sig: str, code: int, err: str) -> str:
    """Check what a run ended by the fault `sig` left, bring it to the end (resume or compile again), and
    check that the end is the uninterrupted run's bytes. Returns what the fault left."""
    whole, before = truth["whole"], truth["earlier"]
    case = out.parent
    # (a KeyboardInterrupt's traceback only from Python itself, when Ctrl-C came before hrc had started)
    assert "Traceback" not in err or code == -signal.SIGINT, err
    if sig in ("TERM", "INT"):
        # 130, or 0 when the run had ended before the signal came; -SIGTERM when it came before Python
        # had started the command (no handler yet: nothing was written)
        assert code in (130, 0, -signal.SIGTERM, -signal.SIGINT), (code, err)
        assert sorted(p.name for p in case.iterdir()) == (["out"] if out.exists() else []), err
    else:
        assert code in (-signal.SIGKILL, 0), (code, err)
    if not out.exists():
        assert not earlier
        left = "nothing"
    elif tree_bytes(out) == whole:
        left = "complete"
    elif earlier and tree_bytes(out) == before:
        left = "earlier"
    else:
        assert not earlier, "an earlier complete output was replaced by something else"
        _check_partial(out)
        left = "partial"
    if code == 130 and left in ("nothing", "earlier"):
        assert err.startswith("error: interrupted"), err
    if left == "partial":
        assert code == 130 and "as a partial output" in err, err
        code, err = _compile(out, "--resume")
        assert code == 0, err
    elif left != "complete" or sig == "KILL":
        leftovers = sorted(p.name for p in case.iterdir() if p.name != "out")
        code, err = _compile(out)
        assert code == 0, err
        for name in leftovers:  # what the killed run left beside --out, cleaned up and said so
            if name != ".out.lock":
                assert name in err, (name, err)
    assert tree_bytes(out) == whole
    assert sorted(p.name for p in case.iterdir()) == ["out"]
    return left


# --- named points -------------------------------------------------------------------------------------

NAMED = {  # point -> fault_driver arguments
    "in a pymunk callback": ("--in-pymunk-callback", "TERM"),
    "amid the plans": ("--at", "hrc.compile.sink:PlanSink.add_record@5"),
    "writing compiled.json": ("--at", "hrc.compile.sink:PlanSink.finish"),
    "writing the report": ("--at", "hrc.report:write_report"),
    "at the swap": ("--at", "hrc.io.claim:exchange"),
    "after the swap": ("--at", "hrc.io.claim:exchange", "--after"),
    "after the claim's release": ("--at", "hrc.io.claim:FolderClaim.__exit__", "--after"),
    "after main returned": ("--after-main",),
}


@pytest.mark.parametrize(("point", "sig", "earlier", "expected"), [
    ("in a pymunk callback", "TERM", False, "nothing"),  # was: swallowed in the callback, exit 0
    ("amid the plans", "TERM", False, "partial"),
    ("writing the report", "TERM", False, "complete"),  # was: every plan lost, "nothing to resume"
    ("after the swap", "KILL", True, "complete"),  # the earlier output, at the staging name, cleaned next time
    pytest.param("after the claim's release", "TERM", False, "complete", marks=pytest.mark.slow),  # was: exit 0
    ("after main returned", "TERM", False, "complete"),  # was: the default action in the shutdown, -15
    pytest.param("amid the plans", "INT", True, "earlier", marks=pytest.mark.slow),
    pytest.param("writing compiled.json", "TERM", True, "complete", marks=pytest.mark.slow),
    pytest.param("writing the report", "KILL", True, "earlier", marks=pytest.mark.slow),
    pytest.param("at the swap", "KILL", True, "earlier", marks=pytest.mark.slow),
])
def test_a_signal_at_a_named_point(tmp_path, truth, point, sig, earlier, expected):
    out = _prepare(tmp_path, truth, earlier)
    args = NAMED[point]
    driver = args if args[0] == "--in-pymunk-callback" else (*args, "--signal", sig)
    proc, mark = _start(out, driver=driver)
    code, err = _finish(proc, mark)
    if sig != "KILL":
        assert code == 130, (code, err)  # never 0: the signal came
    assert _after_fault(out, truth, earlier, sig, code, err) == expected


# --- random moments -----------------------------------------------------------------------------------

def _random_faults(truth: dict[str, object], tmp_path: Path, points: int, seed: int) -> dict[str, int]:
    rng = random.Random(seed)
    seen: dict[str, int] = {}
    for k in range(points):
        sig = rng.choice(["TERM", "INT", "KILL"])
        earlier = rng.random() < 0.4
        at = rng.uniform(0.2, 1.1) * float(truth["seconds"])  # type: ignore[arg-type]
        case = tmp_path / f"point{k}"
        case.mkdir()
        out = _prepare(case, truth, earlier)
        proc, mark = _start(out)
        time.sleep(at)
        if proc.poll() is None:
            if sig == "INT":  # as Ctrl-C at a terminal does: to the whole process group
                os.killpg(proc.pid, signal.SIGINT)
            else:
                proc.send_signal(getattr(signal, f"SIG{sig}"))
        code, err = _finish(proc, mark)
        left = _after_fault(out, truth, earlier, sig, code, err)
        key = f"{sig} {'over an earlier output' if earlier else 'into a new folder'}: {left}"
        seen[key] = seen.get(key, 0) + 1
    return seen


def test_signals_at_random_moments(tmp_path, truth):
    seen = _random_faults(truth, tmp_path, points=2, seed=26)
    assert sum(seen.values()) == 2


@pytest.mark.slow
def test_signals_at_many_random_moments(tmp_path, truth):
    seen = _random_faults(truth, tmp_path, points=40, seed=2026)
    print(seen)
    assert sum(seen.values()) == 40
    assert any(key.endswith("partial") for key in seen) and any(key.startswith("KILL") for key in seen)


# --- workers and the parent's death --------------------------------------------------------------------

def test_the_workers_die_with_their_parent_and_the_next_compile_cleans_up(tmp_path, truth, monkeypatch):
    """kill -9 of the compile while its two workers compile: they are gone within seconds (they were
    left blocked for ever, ~120 MB each), and so is the report's figure drawer (`hrc.report.drawer`, forked
    before the paths); the staging folder is left, and the next compile into the same folder removes it,
    says so, and writes the uninterrupted run's bytes."""
    # an empty cache: the compile is not taken whole from the cache of whole compiles (it has workers)
    monkeypatch.setenv("HRC_CACHE_DIR", str(tmp_path / "cache"))
    case = tmp_path / "case"
    case.mkdir()
    out = case / "out"
    proc, mark = _start(out)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:  # until the drawer and both workers are there, the workers with plans
        spools = list(case.glob(".out.staging-*/.plans*.spool"))  # the workers' (or, kept whole, the parent's)
        if len(_marked(mark)) >= 4 and spools and all(p.stat().st_size for p in spools):
            break
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.02)
    workers = [pid for pid in _marked(mark) if pid != proc.pid]
    assert len(workers) == 3
    t0 = time.monotonic()
    proc.kill()
    proc.wait(30)
    try:
        _wait_gone(mark, timeout=10)
        print(f"workers gone {time.monotonic() - t0:.3f} s after the parent's SIGKILL")
    finally:
        for pid in _marked(mark):  # (only when the check failed) the orphans do not outlive the test
            os.kill(pid, signal.SIGKILL)
    proc.communicate(timeout=30)
    left = sorted(p.name for p in case.iterdir())
    assert left[0] == ".out.lock" and left[1].startswith(".out.staging-") and len(left) == 2
    code, err = _compile(out)
    assert code == 0 and f"removed {left[1]}, left by a run (pid {proc.pid}) that was killed" in err, err
    assert tree_bytes(out) == truth["whole"] and sorted(p.name for p in case.iterdir()) == ["out"]


# --- files a compile did not write ----------------------------------------------------------------------

def test_console_logs_in_out_are_never_lost(tmp_path, capsys, truth):
    """``hrc console`` writes run logs into ``OUT/runs/``: a compile into OUT refuses, in one line naming
    them, before any work, and OUT is left as it was; so is one whose logs appear during the compile."""
    out = tmp_path / "out"
    shutil.copytree(truth["earlier_dir"], out)  # type: ignore[arg-type]
    (out / "runs").mkdir()
    (out / "runs" / "console-1.jsonl").write_text('{"t": 0}\n')
    (out / "notes.txt").write_text("mine")
    before = tree_bytes(out)
    assert main(["compile", str(WORKSHOP_TASK), "--out", str(out), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"error: {out}: --out: holds notes.txt, runs/, which hrc "
                                                   "compile did not write"), err
    assert "move them out of it" in err and tree_bytes(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_logs_that_appear_during_the_compile_stop_the_swap(tmp_path, capsys, monkeypatch, truth):
    import hrc.report

    out = tmp_path / "out"
    shutil.copytree(truth["earlier_dir"], out)  # type: ignore[arg-type]
    real = hrc.report.write_report

    def console_meanwhile(*args, **kwargs):  # a console started on OUT while it compiles
        (out / "runs").mkdir()
        (out / "runs" / "console-1.jsonl").write_text('{"t": 0}\n')
        return real(*args, **kwargs)

    monkeypatch.setattr(hrc.report, "write_report", console_meanwhile)
    assert main(["compile", str(WORKSHOP_TASK), "--out", str(out), "-q", "--jobs", "1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "runs/ appeared in it during the compile" in err, err
    assert tree_bytes(out) == {**truth["earlier"], "runs/console-1.jsonl": b'{"t": 0}\n'}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


@pytest.mark.parametrize("extra", [("--stnu", "archive"), ("--stnu", "none", "--no-report")])
def test_a_compile_writes_only_what_it_may_find_again(mini, write_mini, tmp_path, extra):
    """Every name a compile writes into its output (each --stnu mode, with and without the report, a
    partial output) is one `OUTPUT_FILES` or `REPORT_FILES` names: otherwise the next compile into the
    same folder would refuse it as holding files it did not write."""
    from hrc.compile.stream import OUTPUT_FILES
    from hrc.report import REPORT_FILES

    task = write_mini(*mini)
    out = tmp_path / "out"
    assert main(["compile", str(task), "--out", str(out), "-q", "--jobs", "1", *extra]) == 0
    assert {p.name for p in out.iterdir()} <= {*OUTPUT_FILES, *REPORT_FILES}
    assert main(["compile", str(task), "--out", str(out), "-q", "--jobs", "1", *extra]) == 0  # not refused
