"""The CLI's rough edges of issue 12: each one `error:` line, exit 2, before any work, nothing left behind.

Cases: `--out` a read-only place, under /proc, the current folder, below a file; SIGTERM during a compile
and a failed rename (no staging folder left); `--jobs` beyond the cores; malformed executor URLs and an
executor URL that points at a web server (no hang); absurd numbers in a task (a human duration of 1e300 s,
a speed of 1e-9 m/s), `1e300` that YAML 1.1 reads as a string; an action one of its agents cannot reach;
`hrc paths --out p.jpg`; `hrc check TASK.yaml`; more plans than `--max-plans`.
"""

from __future__ import annotations

import http.server
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from conftest import ROOT, WORKSHOP_TASK

from hrc.cli import main
from hrc.io.atomic import atomic_dir

KITTING_8 = ROOT / "tasks" / "kitting_8picks.yaml"


def _one_error_line(capsys: pytest.CaptureFixture[str], *words: str) -> str:
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1, err
    assert "Traceback" not in err
    for w in words:
        assert w in err, err
    return err


def _compile(*args: str) -> int:
    return main(["compile", *args, "-q"])


# --- --out --------------------------------------------------------------------------------------------

def test_out_is_the_current_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "compiled.json").write_text("{}")  # even an earlier output: . would be replaced whole
    assert _compile(str(WORKSHOP_TASK), "--out", ".") == 2
    _one_error_line(capsys, "--out", "current folder")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["compiled.json"]


def test_out_below_a_file(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("keep")
    assert _compile(str(WORKSHOP_TASK), "--out", str(tmp_path / "notes.txt" / "out")) == 2
    _one_error_line(capsys, "notes.txt")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_out_under_proc(capsys):
    t0 = time.monotonic()
    assert _compile(str(WORKSHOP_TASK), "--out", "/proc/hrc-no-such-place/out") == 2
    _one_error_line(capsys, "/proc")
    assert time.monotonic() - t0 < 10  # before path planning and any plan


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_out_in_a_read_only_folder(tmp_path, capsys):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        assert _compile(str(WORKSHOP_TASK), "--out", str(ro / "out")) == 2
        _one_error_line(capsys)
        assert list(ro.iterdir()) == []
    finally:
        ro.chmod(0o755)


def test_out_where_the_machine_refuses_a_folder(tmp_path, monkeypatch, capsys):
    """As a read-only place does for a user who is not root: nothing can be made beside the output (its
    claim file, first: `hrc.io.claim`)."""
    real = os.open

    def refuse(path, *args, **kwargs):
        if str(path).startswith(str(tmp_path)):
            raise PermissionError(13, "Permission denied", str(path))
        return real(path, *args, **kwargs)

    monkeypatch.setattr(os, "open", refuse)
    assert _compile(str(WORKSHOP_TASK), "--out", str(tmp_path / "new" / "out")) == 2
    _one_error_line(capsys, "Permission denied")
    assert list(tmp_path.iterdir()) == []  # the folder made for it is gone again


def test_a_full_disk_names_the_output_and_leaves_nothing(tmp_path, monkeypatch, capsys):
    """A full disk fails a write, which names no file: the error names the output folder instead."""
    import errno

    import hrc.compile.spool as spool

    def full(fd: int, data: bytes) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(spool, "write_all", full)
    out = tmp_path / "out"
    assert _compile(str(WORKSHOP_TASK), "--out", str(out), "--jobs", "1") == 2
    _one_error_line(capsys, str(out), "No space left on device")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("earlier", [False, True])
def test_sigterm_leaves_a_partial_output_and_no_staging_folder(tmp_path, earlier):
    """SIGTERM mid-compile: the plans so far as a partial output in a new folder; an earlier output in
    --out is kept instead. Either way no staging folder is left."""
    out = tmp_path / "out"
    if earlier:
        out.mkdir()
        (out / "compiled.json").write_text('{"earlier": true}')
    # no disk cache: a compile taken whole from it (issue 38) would end before it could be interrupted
    env = dict(os.environ, PYTHONPATH=str(ROOT), HRC_CACHE_DIR="")
    proc = subprocess.Popen([sys.executable, "-m", "hrc", "compile", str(WORKSHOP_TASK), "--out", str(out),
                             "--jobs", "1", "--no-report"], cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:  # wait until some plans are compiled (their lines spooled)
        spools = list(tmp_path.glob(".out.*/.plans.spool"))
        if spools and spools[0].stat().st_size > 0:
            break
        if proc.poll() is not None:
            pytest.fail(f"compile ended before it could be interrupted: {proc.communicate()}")
        time.sleep(0.05)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert err.strip().splitlines()[-1].startswith("error: interrupted after ") and "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no staging folder
    if earlier:
        assert "earlier output" in err and sorted(p.name for p in out.iterdir()) == ["compiled.json"]
        assert "interrupted: writing" not in err  # it would be thrown away: not written at all
        assert json.loads((out / "compiled.json").read_text()) == {"earlier": True}
        return
    data = json.loads((out / "compiled.json").read_text())
    assert data["partial"] is True and data["plans_expected"] == 32
    # said before the writing, which takes a while for a large run
    said = f"interrupted: writing the {len(data['plans'])} of 32 plans compiled so far as a partial output"
    assert err.strip().splitlines()[-2] == said
    assert [p["rank"] for p in data["plans"]] == list(range(1, len(data["plans"]) + 1))
    assert sum(data["counts"].values()) == len(data["plans"]) >= 1
    assert sorted(p.name for p in (out / "stnu").iterdir()) == sorted(f"{p['id']}.graphml" for p in data["plans"])


@pytest.mark.parametrize("exchange", [True, False])
def test_a_failed_swap_leaves_no_staging_folder_and_the_old_output(tmp_path, monkeypatch, exchange):
    """The swap fails: the exchange of the two folders (`exchange`), or, on a file system without it, the
    rename of the staging folder into place (putting the old one back works)."""
    import hrc.io.claim as claim

    target = tmp_path / "out"
    target.mkdir()
    (target / "compiled.json").write_text("old")

    def full(*args):
        raise OSError(28, "No space left on device", str(target))

    if exchange:
        monkeypatch.setattr(claim, "exchange", full)
    else:
        real = os.rename
        monkeypatch.setattr(claim, "exchange", lambda a, b: False)  # a file system that cannot exchange

        def failing(src, dst):
            return full() if Path(dst) == target and ".aside-" not in str(src) else real(src, dst)

        monkeypatch.setattr(os, "rename", failing)
    with pytest.raises(OSError, match="No space"), atomic_dir(target) as stage:
        (stage / "compiled.json").write_text("new")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert (target / "compiled.json").read_text() == "old"


def test_a_failure_removes_the_folders_made_for_the_output(tmp_path):
    with pytest.raises(KeyboardInterrupt), atomic_dir(tmp_path / "a" / "b" / "out"):
        raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []


# --- --jobs and --executor --------------------------------------------------------------------------

@pytest.mark.parametrize("jobs", ["99999999999999999999", "300"])
def test_jobs_beyond_the_cores(tmp_path, capsys, jobs):
    assert _compile(str(WORKSHOP_TASK), "--out", str(tmp_path / "out"), "--jobs", jobs) == 2
    _one_error_line(capsys, "--jobs", "cores")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("jobs", ["0", "-3", "two"])
def test_jobs_not_a_positive_number(tmp_path, capsys, jobs):
    with pytest.raises(SystemExit) as exc:
        _compile(str(WORKSHOP_TASK), "--out", str(tmp_path / "out"), "--jobs", jobs)
    assert exc.value.code == 2
    _one_error_line(capsys, "--jobs")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("url", ["dask://127.0.0.1", "dask://:8786", "dask://127.0.0.1:port", "ftp://127.0.0.1:8786",
                                 "dask://127.0.0.1:8786/x", "dask://127.0.0.1:99999", "127.0.0.1:8786", "dask://"])
def test_malformed_executor_urls(tmp_path, capsys, url):
    t0 = time.monotonic()
    assert _compile(str(WORKSHOP_TASK), "--out", str(tmp_path / "out"), "--executor", url) == 2
    _one_error_line(capsys, "executor")
    assert time.monotonic() - t0 < 5
    assert list(tmp_path.iterdir()) == []


def test_executor_url_of_a_closed_port(tmp_path, capsys):
    import socket

    with socket.socket() as s:  # a port nobody listens on (bound, then released)
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    assert _compile(str(WORKSHOP_TASK), "--out", str(tmp_path / "out"), "--executor", f"dask://127.0.0.1:{port}") == 2
    _one_error_line(capsys, "cannot reach")
    assert list(tmp_path.iterdir()) == []


def test_executor_url_of_a_web_server_does_not_hang(tmp_path, capsys):
    server = http.server.HTTPServer(("127.0.0.1", 0), http.server.SimpleHTTPRequestHandler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        t0 = time.monotonic()
        url = f"dask://127.0.0.1:{server.server_address[1]}"
        assert _compile(str(WORKSHOP_TASK), "--out", str(tmp_path / "out"), "--executor", url) == 2
        _one_error_line(capsys, "not a Dask scheduler")
        assert time.monotonic() - t0 < 15
    finally:
        server.shutdown()
        server.server_close()
    assert list(tmp_path.iterdir()) == []


# --- task files --------------------------------------------------------------------------------------

def _mini_cases():
    def human_duration(task, map_):
        task["actions"][0]["phases"][0]["duration"]["human"] = [2, 1.0e300]

    def robot_speed(task, map_):
        task["agents"][1]["speed"] = 1.0e-9

    def constraint(task, map_):
        task["constraints"][0]["bounds"] = [0, 1.0e300]

    return {"human-duration-1e300": (human_duration, "duration.human[1]", "at most"),
            "speed-1e-9": (robot_speed, "agents[1].speed", ">= 0.01"),
            "constraint-1e300": (constraint, "constraints[0].bounds[1]", "at most")}


@pytest.mark.parametrize("command", ["show", "compile"])
@pytest.mark.parametrize("case", sorted(_mini_cases()))
def test_absurd_numbers_in_a_task(mini, write_mini, tmp_path, capsys, command, case):
    mutate, key, words = _mini_cases()[case]
    task, map_ = mini
    mutate(task, map_)
    path = write_mini(task, map_)
    args = [command, str(path)] + (["--out", str(tmp_path / "out"), "-q"] if command == "compile" else [])
    assert main(args) == 2
    _one_error_line(capsys, key, words)
    assert not (tmp_path / "out").exists()


def test_yaml11_number_written_as_a_string_says_how_to_write_it(mini, write_mini, capsys):
    task, map_ = mini
    path = write_mini(task, map_)
    path.write_text(path.read_text().replace("deadline: 100", "deadline: 1e300"))
    assert main(["show", str(path)]) == 2
    _one_error_line(capsys, "deadline", "'1e300'", "YAML 1.1", "1.0e+300")


def test_an_action_one_of_its_agents_cannot_reach(mini, write_mini, tmp_path, capsys):
    """A wall with a gap the human fits through (0.85 m > 2 x 0.4 m) but the robot does not (2 x 0.45 m):
    the robot may fetch at A (beyond the wall from its start), so show would count plans compile refuses."""
    task, map_ = mini
    map_["obstacles"] = [{"id": "wall_south", "rect": [4.9, 0, 5.1, 3.0]},
                         {"id": "wall_north", "rect": [4.9, 3.85, 5.1, 8]}]
    path = write_mini(task, map_)
    for args in (["show", str(path)], ["compile", str(path), "--out", str(tmp_path / "out"), "-q"]):
        assert main(args) == 2
        _one_error_line(capsys, "actions[0].phases[0].location", "robot cannot reach location 'A'")
    assert not (tmp_path / "out").exists()


# --- other commands -----------------------------------------------------------------------------------

def test_paths_out_must_be_a_png(tmp_path, capsys):
    assert main(["paths", str(WORKSHOP_TASK), "--out", str(tmp_path / "p.jpg")]) == 2
    _one_error_line(capsys, "--out", ".png")
    assert list(tmp_path.iterdir()) == []


def test_check_a_task_file(capsys):
    assert main(["check", str(WORKSHOP_TASK)]) == 2
    _one_error_line(capsys, "not an STNU file")


# --- told up front -------------------------------------------------------------------------------------

def test_more_plans_than_max_plans_is_refused_up_front(tmp_path, capsys):
    t0 = time.monotonic()
    assert _compile(str(KITTING_8), "--out", str(tmp_path / "out"), "--plans", "all") == 2
    _one_error_line(capsys, "362,880 plans", "--max-plans 50,000", "raise --max-plans", "--executor", "--pin",
                    "--symmetry")
    assert time.monotonic() - t0 < 10
    assert list(tmp_path.iterdir()) == []


def test_max_plans_applies_to_any_task(tmp_path, capsys):
    assert _compile(str(WORKSHOP_TASK), "--out", str(tmp_path / "out"), "--max-plans", "31", "--plans", "all") == 2
    _one_error_line(capsys, "32 plans, more than --max-plans 31")
    assert list(tmp_path.iterdir()) == []


def test_show_bounds_a_count_that_would_be_slow(tmp_path, capsys):
    """16 independent picks and one precedence: the exact count would take minutes and gigabytes."""
    lines = ["name: big", f"map: {ROOT / 'maps' / 'kitting_cell.yaml'}", "agents:",
             "  - {id: human, kind: human, radius: 0.30, speed: 1.2, start: H}",
             "  - {id: robot, kind: robot, radius: 0.35, speed: 0.6, start: R}", "actions:"]
    for i in range(16):
        lines += [f"  - id: p{i}", "    agents: [human, robot]", "    phases:",
                  f"      - {{id: fetch, location: {'ABCDE'[i % 5]}, duration: {{human: [2, 4], robot: [4, 5]}}}}",
                  "      - {id: place, location: K, duration: {human: [1, 3], robot: [3, 4]}}"]
    lines += ["precedence:", "  - [p0, p1]"]
    path = tmp_path / "big.yaml"
    path.write_text("\n".join(lines) + "\n")
    t0 = time.monotonic()
    assert main(["show", str(path), "--json"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert time.monotonic() - t0 < 20
    assert data["plan_count"] == 355687428096000 and data["plan_count_exact"] is False
    assert main(["show", str(path)]) == 0
    out = capsys.readouterr().out
    assert "plans: at most 355687428096000" in out and "searches for the best plans instead" in out


def test_best_per_allocation_says_what_it_kept(mini, write_mini, tmp_path, capsys):
    """Without its precedence (and the constraint and preference on it), the mini task has six plans in
    four allocations (two actions, two agents): the best of each is four plans."""
    task, map_ = mini
    task["precedence"], task["constraints"], task["preferences"] = [], [], []
    path = write_mini(task, map_)
    out = tmp_path / "out"
    assert main(["compile", str(path), "--out", str(out), "--best-per-allocation", "1", "--jobs", "1"]) == 0
    captured = capsys.readouterr()
    assert "keeping the best 1 of each of 4 allocations" in captured.err
    assert "compiled 6 plans of" in captured.out and "kept the best 1 of each allocation, 4 plans" in captured.out
    data = json.loads((out / "compiled.json").read_text())
    assert len(data["plans"]) == 4 and data["plans_compiled"] == 6 and data["best_per_allocation"] == 1
    assert len({json.dumps(p["allocation"], sort_keys=True) for p in data["plans"]}) == 4
    assert "**Plans kept:** the best 1 of each allocation: 4 of the 6 plans compiled" in (out / "report.md").read_text()
    with pytest.raises(SystemExit) as exc:
        main(["compile", str(path), "--out", str(tmp_path / "o2"), "--best-per-allocation", "0"])
    assert exc.value.code == 2
    _one_error_line(capsys, "--best-per-allocation", "at least 1")
    assert not (tmp_path / "o2").exists()


def test_progress_lines_off_a_terminal_cover_every_long_stage(capsys):
    """Off a terminal the progress is a line now and then, for the plans of a compile and the runs of a
    simulation alike (the simulator used to print nothing for minutes)."""
    from hrc.cli.compile import _Progress

    progress = _Progress(tty=False, quiet=False, every=0.0)
    for stage in ("plans", "runs", "blind"):
        progress(stage, 5, 10)
        progress(stage, 7, 10)
    err = capsys.readouterr().err
    assert "plans: 7/10" in err and "runs: 7/10" in err and "motion-blind plans: 7/10" in err
    quiet = _Progress(tty=False, quiet=True, every=0.0)
    quiet("runs", 7, 10)
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("argv, message", [
    (["compile", str(WORKSHOP_TASK), "--jobs", "0"], "argument --jobs: must be at least 1, found 0"),
    (["compile", str(WORKSHOP_TASK), "--jobs", "two"], "argument --jobs: expected a whole number, found 'two'"),
    (["apa", "x.json", "--ticks-per-second", "-5"], "argument --ticks-per-second: must be at least 1, found -5"),
    (["console", "OUT", "--speed", "0"], "argument --speed: must lie in (0, 1000], got 0"),
    (["console", "OUT", "--port", "65536"], "argument --port: must lie in 0..65535, found 65536"),
    (["console", "OUT", "--tick", "nan"], "argument --tick: not a finite number: 'nan'"),
    (["detect", "OUT", "--sensor-sigma", "fine"], "argument --sensor-sigma: not a number: 'fine'"),
    (["ros2", "OUT", "--map-origin", "0", "inf", "0"], "argument --map-origin: not a finite number: 'inf'"),
])
def test_a_number_out_of_its_bounds_is_one_line(argv, message, capsys):
    """Every numeric option goes through hrc.cli.argtypes: one line naming the option and what it wants."""
    with pytest.raises(SystemExit) as done:
        main(argv)
    err = capsys.readouterr().err
    assert done.value.code == 2 and err.count("\n") == 1 and err.startswith("error: ") and message in err, err
