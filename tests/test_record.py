"""MCAP recordings (``--record``, hrc.record): what Foxglove gets, read back with MCAP's own reader.

- ``hrc dispatch --log --record``: a whole workshop run (the test client playing the person and the robot,
  bad lines slipped in); the file's channels, schemas and counts, the floor as scene entities, the
  robot's goals at the locations it drove to, the decisions' classes, times never going back; the same
  bytes from the run's log (``--replay LOG --record``);
- a run stopped by SIGINT or SIGTERM leaves a whole file (summary written) of what was answered;
- a simulated kitting run (`hrc.record.sim`): the floor's positions, every observation and answer, the
  same bytes twice, and ``hrc simulate --record DIR --record-runs N``;
- the console's ``--record``, stopped by SIGTERM, equal to the recording made from its log;
- a taken name is refused before anything is written; a recording that cannot be written stops
  without ending the run; `AtomicFile`.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from conftest import ROOT, compiled_folder
from dispatch_client import Run
from mcap_check import EXPECTED, read_mcap, read_ros2_mcap

from hrc.cli import main
from hrc.dispatch import Dispatcher
from hrc.dispatch.plan_set import load_plan_set
from hrc.dispatch.protocol import answer
from hrc.io.atomic import AtomicFile

WORKSHOP = ROOT / "tasks" / "cube_stacking.yaml"
BAD = ["not json", '{"t": 1, "agent": "human", "action": "cube9", "phase": "fetch", "event": "start"}',
       '{"t": 0, "event": "tick", "extra": 1}']


def _hrc(*args: str, stdin: bytes = b"", timeout: float = 120) -> subprocess.CompletedProcess[bytes]:
    return subprocess.run([sys.executable, "-m", "hrc", *args], input=stdin, capture_output=True, timeout=timeout,
                          cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)))


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return compiled_folder(tmp_path_factory.mktemp("record") / "ws")


@pytest.fixture(scope="module")
def session(folder: Path) -> list[str]:
    """A whole workshop run's lines (the person follows the hints, the robot its windows), bad ones among."""
    d = Dispatcher.from_folder(folder)
    lines: list[str] = []
    bad = iter(BAD)

    def send(line: str) -> str:
        if len(lines) % 9 == 4:
            extra = next(bad, None)
            if extra is not None:
                lines.append(extra)
                answer(d, extra.encode())
        lines.append(line)
        return answer(d, line.encode())

    Run(load_plan_set(folder), send, 5, human_choice="plan", timing="hinted").play()
    return lines


def test_a_dispatched_run_is_recorded_whole_and_the_same_from_its_log(folder: Path, session: list[str],
                                                                       tmp_path: Path) -> None:
    stdin = "".join(line + "\n" for line in session).encode()
    done = _hrc("dispatch", str(folder), "--log", str(tmp_path / "run.log"), "--record", str(tmp_path / "a.mcap"),
                stdin=stdin)
    assert done.returncode == 0, done.stderr
    answers = done.stdout.decode().splitlines()
    assert len(answers) == len(session)
    rec = read_mcap(tmp_path / "a.mcap")
    assert set(rec.channels) == set(EXPECTED)
    accepted = [json.loads(a) for a in answers if json.loads(a)["ok"]]
    assert rec.counts["/hrc/in"] == rec.counts["/hrc/out"] == len(session)
    assert rec.counts["/hrc/decision"] == len(accepted) and rec.counts["/hrc/log"] == 2 * len(session)
    assert rec.counts["/hrc/map"] == 1 and rec.counts["/hrc/routes"] >= 1
    assert [json.dumps(o) for o in rec.of("/hrc/out")] == [json.dumps(json.loads(a)) for a in answers]
    assert rec.of("/hrc/in")[0] == json.loads(session[0]) and {"text": "not json"} in rec.of("/hrc/in")
    assert rec.metadata["hrc"]["task"] == "cube_stacking" and rec.metadata["hrc"]["plans"] == "32"
    # the floor: every obstacle an entity, every location named
    ws = load_plan_set(folder).task.workspace
    entities = {e.id: e for e in rec.of("/hrc/map")[0].entities}
    assert {f"map/{o.id}" for o in ws.obstacles} <= set(entities)
    assert sorted(t.text for t in entities["map/locations"].texts) == sorted(ws.location_ids)
    # the class over time is the answers'; the last time is the last answer's
    assert [d["class"] for d in rec.of("/hrc/decision")] == [a["class"] for a in accepted]
    assert math.isclose(rec.times("/hrc/out")[-1], json.loads(answers[-1])["t"])
    # each goal is where the robot's next drive went: the location of the phase it departed for next
    task = load_plan_set(folder).task
    drives = [json.loads(x) for x in session if '"robot"' in x and '"depart"' in x]
    goals = [(round(g.pose.position.x, 3), round(g.pose.position.y, 3)) for g in rec.of("/hrc/robot/goal")]
    assert goals and len(goals) == len(drives) + 1  # then its way home after its last phase, as hrc ros2 sends
    home = task.workspace.location(task.agent("robot").start).xy
    assert goals == [task.workspace.location(task.action(d["action"]).phase(d["phase"]).location).xy
                     for d in drives] + [home]
    # the robot's last known place is where its last phase was done
    last = rec.of("/hrc/robot/pose")[-1].pose.position
    end = [json.loads(x) for x in session if '"robot"' in x and '"end"' in x][-1]
    assert (last.x, last.y) == task.workspace.location(task.action(end["action"]).phase(end["phase"]).location).xy
    # the same bytes from the log
    again = _hrc("dispatch", str(folder), "--replay", str(tmp_path / "run.log"), "--record", str(tmp_path / "b.mcap"))
    assert again.returncode == 0 and again.stdout == done.stdout
    assert (tmp_path / "a.mcap").read_bytes() == (tmp_path / "b.mcap").read_bytes()


def test_a_taken_name_is_refused_before_anything_is_written(folder: Path, tmp_path: Path) -> None:
    taken = tmp_path / "taken.mcap"
    taken.write_bytes(b"old")
    done = _hrc("dispatch", str(folder), "--log", str(tmp_path / "run.log"), "--record", str(taken))
    assert done.returncode == 2 and done.stderr.decode().count("\n") == 1, done.stderr
    assert "exists already" in done.stderr.decode()
    assert taken.read_bytes() == b"old" and not (tmp_path / "run.log").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["taken.mcap"]  # no hidden file either
    # a log in use: the recording is not left behind
    held = _hrc("dispatch", str(folder), "--record", str(tmp_path / "x.mcap"), "--replay", str(tmp_path / "none.log"))
    assert held.returncode == 2 and not (tmp_path / "x.mcap").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["taken.mcap"]


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_run_stopped_by_a_signal_leaves_a_whole_recording(folder: Path, session: list[str], tmp_path: Path,
                                                            sig: int) -> None:
    """The stdin stays open (a live run): half the messages, their answers read, then the signal."""
    log, path = tmp_path / "run.log", tmp_path / "run.mcap"
    # SIGINT as a terminal gives it: a test run started in the background of a shell inherits SIGINT
    # ignored, and Python (as any Unix program) leaves an inherited ignore in place
    proc = subprocess.Popen([sys.executable, "-m", "hrc", "dispatch", str(folder), "--log", str(log), "--record",
                             str(path)], cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)),
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    assert proc.stdin is not None and proc.stdout is not None
    half = session[:len(session) // 2]
    for line in half:
        proc.stdin.write(line.encode() + b"\n")
        proc.stdin.flush()
        assert proc.stdout.readline()
    proc.send_signal(sig)
    # both pipes drained while it ends (a full stderr pipe must not look like a hang); 60 s: a loaded CI box
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err.decode()
    assert b"recorded" in err
    rec = read_mcap(path)
    assert rec.counts["/hrc/in"] == len(half)
    again = _hrc("dispatch", str(folder), "--replay", str(log), "--record", str(tmp_path / "again.mcap"))
    assert again.returncode == 0
    assert path.read_bytes() == (tmp_path / "again.mcap").read_bytes()
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_a_killed_recordings_hidden_file_is_removed_by_the_next_one(folder: Path, session: list[str],
                                                                   tmp_path: Path) -> None:
    """SIGKILL mid-run leaves ``.run.mcap.hrc-*.tmp``; the next recording into the folder removes it (and
    says so), while a recording still being written there (locked) and other hidden files stay."""
    from hrc.io.atomic import AtomicFile

    log, path = tmp_path / "run.log", tmp_path / "run.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "hrc", "dispatch", str(folder), "--log", str(log), "--record",
                             str(path)], cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)),
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL)
    assert proc.stdin is not None and proc.stdout is not None
    for line in session[:5]:
        proc.stdin.write(line.encode() + b"\n")
        proc.stdin.flush()
        assert proc.stdout.readline()
    proc.kill()
    proc.wait(timeout=30)
    proc.stdin.close()
    proc.stdout.close()
    (left,) = [p for p in tmp_path.iterdir() if p.name.startswith(".run.mcap.")]
    assert left.name.endswith(".tmp") and not path.exists()
    (tmp_path / ".notes.tmp").write_text("not ours")
    live = AtomicFile(tmp_path / "live.mcap")  # a recording of another run, going on
    assert live.cleaned == [left] and not left.exists()  # it is the next one here: it cleans
    again = _hrc("dispatch", str(folder), "--replay", str(log), "--record", str(tmp_path / "again.mcap"))
    assert again.returncode == 0, again.stderr
    assert b"removed" not in again.stderr  # nothing stale left; the live one's file is locked, so kept
    assert live.tmp.exists() and (tmp_path / ".notes.tmp").exists()
    assert read_mcap(tmp_path / "again.mcap").counts["/hrc/in"] == 5
    live.discard()
    assert sorted(p.name for p in tmp_path.iterdir()) == [".notes.tmp", "again.mcap", "run.log"]


def test_the_next_recording_says_what_it_removed(folder: Path, tmp_path: Path) -> None:
    """The hidden file of a writer that is gone (its lock went with it), as the next recording reports it."""
    import fcntl

    from hrc.io.atomic import clean_stale

    dead = tmp_path / ".old.mcap.hrc-abcd1234.tmp"
    dead.write_bytes(b"half a recording")
    held = tmp_path / ".held.mcap.hrc-efgh5678.tmp"
    held.write_bytes(b"being written")
    with open(held, "rb") as f:
        fcntl.flock(f.fileno(), fcntl.LOCK_EX)
        run = _hrc("dispatch", str(folder), "--record", str(tmp_path / "new.mcap"),
                   stdin=b'{"t": 0, "event": "tick"}\n')
        assert run.returncode == 0, run.stderr
        assert b"removed .old.mcap.hrc-abcd1234.tmp: the unfinished recording of a run that was killed" in run.stderr
        assert not dead.exists() and held.exists()
        assert clean_stale(tmp_path) == []  # still held
    assert clean_stale(tmp_path) == [held]


def _xy(p: Any) -> tuple[float, float]:
    return (round(p.x, 6), round(p.y, 6))


def test_a_ros_typed_recording_decodes_back_to_the_same_run(folder: Path, session: list[str],
                                                           tmp_path: Path) -> None:
    """``--record-format ros2`` of a whole workshop run, read back by mcap-ros2-support's decoder from the
    definitions in the file: the protocol lines are the messages given and the answers printed, and the
    poses, goal, decisions, agents and routes are the ones the Foxglove recording of the same run holds
    (read by MCAP's protobuf decoder); the map has every obstacle and place; the same log gives the same
    bytes again."""
    log, ros, fox = tmp_path / "run.log", tmp_path / "ros.mcap", tmp_path / "fox.mcap"
    run = _hrc("dispatch", str(folder), "--log", str(log), "--record", str(ros), "--record-format", "ros2",
               stdin="".join(line + "\n" for line in session).encode())
    assert run.returncode == 0, run.stderr
    answers = run.stdout.decode().splitlines()
    assert _hrc("dispatch", str(folder), "--replay", str(log), "--record", str(fox)).returncode == 0
    r, f = read_ros2_mcap(ros), read_mcap(fox)
    assert r.metadata["hrc"] == f.metadata["hrc"] and "mcap-ros2-support" in r.library
    assert [m.data for m, _ in r.of("/hrc/in")] == [json.dumps(v, ensure_ascii=False, separators=(",", ":"))
                                                    if "text" in v else line
                                                    for v, line in zip(f.of("/hrc/in"), session, strict=True)]
    assert [m.data for m, _ in r.of("/hrc/out")] == answers and len(answers) == len(session)
    assert [json.loads(m.data) for m, _ in r.of("/hrc/decision")] == f.of("/hrc/decision")
    for topic in ("/hrc/human/pose", "/hrc/robot/pose", "/hrc/robot/goal"):
        got = [((m.header.stamp.sec, m.header.stamp.nanosec), m.header.frame_id, _xy(m.pose.position),
                round(m.pose.orientation.z, 6), round(m.pose.orientation.w, 6)) for m, _ in r.of(topic)]
        want = [((p.timestamp.seconds, p.timestamp.nanos), p.frame_id, _xy(p.pose.position),
                 round(p.pose.orientation.z, 6), round(p.pose.orientation.w, 6)) for p in f.of(topic)]
        assert got == want and got, topic
        assert r.times(topic) == f.times(topic)
    task = Dispatcher.from_folder(folder).task
    (floor,) = r.of("/hrc/map")
    by_ns: dict[str, int] = {}
    for marker in floor[0].markers:
        by_ns[marker.ns] = by_ns.get(marker.ns, 0) + 1
    assert by_ns == {"map": 2 + len(task.workspace.obstacles), "places": 2 * len(task.workspace.locations)}
    assert [m.text for m in floor[0].markers if m.type == 9] == [loc.id for loc in task.workspace.locations]
    for (agents, _), entities in zip(r.of("/hrc/agents"), f.of("/hrc/agents"), strict=True):
        assert [_xy(m.pose.position) for m in agents.markers if m.type == 3] == \
            [_xy(e.cylinders[0].pose.position) for e in entities.entities]
        assert [m.text for m in agents.markers if m.type == 9] == [e.texts[0].text for e in entities.entities]
    for (routes, _), entities in zip(r.of("/hrc/routes"), f.of("/hrc/routes"), strict=True):
        assert routes.markers[0].action == 3  # DELETEALL: the last plan's routes go
        assert [[_xy(p) for p in m.points] for m in routes.markers[1:]] == \
            [[_xy(p) for p in line.points] for e in entities.entities for line in e.lines]
    again = tmp_path / "again.mcap"
    assert _hrc("dispatch", str(folder), "--replay", str(log), "--record", str(again), "--record-format",
                "ros2").returncode == 0
    assert again.read_bytes() == ros.read_bytes()


def test_rclpy_reads_a_ros_typed_recording(folder: Path, session: list[str], tmp_path: Path) -> None:
    """ROS 2's own deserializer (rclpy, the ``ros2`` extra) reads every message as its installed type: the
    file's definitions are ROS 2's, field for field."""
    pytest.importorskip("rclpy")
    from geometry_msgs.msg import PoseStamped
    from rclpy.serialization import deserialize_message
    from std_msgs.msg import String

    types: dict[str, Any] = {"std_msgs/msg/String": String, "geometry_msgs/msg/PoseStamped": PoseStamped}
    try:
        from visualization_msgs.msg import MarkerArray

        types["visualization_msgs/msg/MarkerArray"] = MarkerArray
    except ImportError:  # not in the ros2 extra: mcap-ros2-support's decoder alone reads the scene
        pass
    ros = tmp_path / "ros.mcap"
    run = _hrc("dispatch", str(folder), "--record", str(ros), "--record-format", "ros2",
               stdin="".join(line + "\n" for line in session[:12]).encode())
    assert run.returncode == 0, run.stderr
    rec = read_ros2_mcap(ros)
    read = 0
    for topic, _, _, (decoded, data) in rec.messages:
        kind = types.get(rec.channels[topic][0])
        if kind is None:
            continue
        msg = deserialize_message(data, kind)
        read += 1
        if kind is String:
            assert msg.data == decoded.data
        elif kind is PoseStamped:
            assert msg.header.frame_id == "map" and _xy(msg.pose.position) == _xy(decoded.pose.position)
            assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (decoded.header.stamp.sec,
                                                                        decoded.header.stamp.nanosec)
        else:
            assert [(m.ns, m.id, m.type, m.action, _xy(m.pose.position), m.text, len(m.points)) for m in msg.markers] \
                == [(m.ns, m.id, m.type, m.action, _xy(m.pose.position), m.text, len(m.points))
                    for m in decoded.markers]
    assert read >= 12 * 2


def test_the_cli_offers_the_recorders_formats() -> None:
    from hrc.cli.record import RECORD_FORMATS
    from hrc.record import FORMATS

    assert RECORD_FORMATS == FORMATS


@pytest.fixture(scope="module")
def kitting():
    """Kitting pinned to 12 plans (as tests/test_sim.py does) so that it compiles in seconds."""
    from hrc.compile.compiler import compile_task
    from hrc.io.task_file import load_task
    from hrc.plans import pin_actions

    pins = {"pick_a": "robot", "pick_b": "human", "pick_c": "human", "pick_d": "human", "pick_e": "robot",
            "label": "robot", "deliver": "human"}
    task = pin_actions(load_task(ROOT / "tasks" / "kitting.yaml"), pins)
    return task, compile_task(task, seed=0, jobs=1)


def test_a_simulated_kitting_run_is_recorded_with_the_floors_positions(kitting) -> None:
    from hrc.record import FRAME_PERIOD
    from hrc.record.sim import record_run
    from hrc.sim.run import SimContext, SimSettings, simulate_run

    task, cps = kitting
    ctx = SimContext(task, {"motion": cps}, SimSettings(), seed=2)
    start = time.perf_counter()
    data, result = record_run(ctx, "hrc", 0)
    took = time.perf_counter() - start
    assert result == simulate_run(ctx, "hrc", 0)  # the run of simulation.json, not another
    assert result.finished and result.makespan is not None
    rec = read_mcap(data)
    assert set(rec.channels) == set(EXPECTED)
    assert rec.metadata["hrc"]["policy"] == "hrc" and rec.metadata["hrc"]["finished"] == "true"
    ins, outs = rec.of("/hrc/in"), rec.of("/hrc/out")
    assert len(ins) == len(outs) == len(result.latencies) > 20  # one per observation the dispatcher was given
    assert all(o["ok"] for o in outs) == (not result.refused)
    ends = [m for m in ins if m.get("event") == "end"]
    assert len(ends) == sum(len(a.phases) for a in task.actions)
    assert math.isclose(max(m["t"] for m in ends), result.makespan, abs_tol=1e-3)
    # measured positions: inside the floor, at most FRAME_PERIOD apart in time but for the floor's own steps
    x0, y0, x1, y1 = task.workspace.bounds
    for topic in ("/hrc/human/pose", "/hrc/robot/pose"):
        poses = rec.of(topic)
        assert len(poses) > 50
        assert all(x0 <= p.pose.position.x <= x1 and y0 <= p.pose.position.y <= y1 for p in poses)
        times = rec.times(topic)
        assert all(b - a >= FRAME_PERIOD - 1e-6 for a, b in zip(times[1:], times[2:], strict=False))
    last = rec.of("/hrc/robot/pose")[-1].pose.position
    assert math.dist((last.x, last.y), (result.frames[-1][3], result.frames[-1][4])) < 1e-6
    assert record_run(ctx, "hrc", 0)[0] == data  # the same bytes again
    print(f"kitting (12 plans) run 0: {len(data)} bytes, recorded in {took:.3f} s")


def test_simulate_record_writes_one_file_per_run(tmp_path: Path) -> None:
    from hrc.io.task_file import load_task
    from hrc.record.sim import record_run
    from hrc.sim.run import SimContext, SimSettings

    out, rec_dir = tmp_path / "sim", tmp_path / "rec"
    assert main(["simulate", str(WORKSHOP), "--runs", "3", "--policy", "hrc,fixed", "--out", str(out), "--record",
                 str(rec_dir), "--record-runs", "2", "--jobs", "1", "--no-figures", "-q", "--seed", "4"]) == 0
    assert sorted(p.name for p in rec_dir.iterdir()) == ["fixed-0000.mcap", "fixed-0001.mcap", "hrc-0000.mcap",
                                                         "hrc-0001.mcap"]
    runs = json.loads((out / "simulation.json").read_text())["policies"]["fixed"]["runs"]
    fixed = read_mcap(rec_dir / "fixed-0001.mcap")
    assert fixed.metadata["hrc"]["makespan"] == f"{runs[1]['makespan']:.3f}"
    assert all(o["policy"] == "fixed" for o in fixed.of("/hrc/out"))
    from hrc.compile.compiler import compile_task

    task = load_task(WORKSHOP)
    ctx = SimContext(task, {"motion": compile_task(task, seed=0, jobs=1)}, SimSettings(), seed=4)
    assert (rec_dir / "hrc-0001.mcap").read_bytes() == record_run(ctx, "hrc", 1)[0]
    # --record inside --out, or a folder of other files: one line, exit 2, nothing written
    assert main(["simulate", str(WORKSHOP), "--runs", "1", "--out", str(out), "--record", str(out / "r")]) == 2
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "notes.txt").write_text("mine")
    assert main(["simulate", str(WORKSHOP), "--runs", "1", "--out", str(out), "--record",
                 str(tmp_path / "other")]) == 2
    assert main(["simulate", str(WORKSHOP), "--runs", "1", "--out", str(out), "--record-runs", "1"]) == 2


def test_the_console_records_its_run(folder: Path, tmp_path: Path) -> None:
    from console_harness import ConsoleProcess
    from websockets.sync.client import connect

    log, path = tmp_path / "console.jsonl", tmp_path / "console.mcap"
    console = ConsoleProcess(folder, log, "--tick", "0", "--speed", "20", "--record", str(path))
    try:
        with connect(console.ws + "ws", open_timeout=10, close_timeout=5,
                     additional_headers=console.page_headers()) as page:
            for k in range(3):
                state = console.state()
                page.send(json.dumps({"type": "press", "hseq": state["hseq"], "id": k, **state["options"][0]}))
                while (msg := json.loads(page.recv(timeout=10)))["type"] != "reply":
                    pass
                assert msg["ok"], msg
    finally:
        console.stop()  # SIGTERM
    assert console.proc.returncode == 0 and "recorded 3 messages" in console.stderr(), console.stderr()
    assert f"stopped by SIGTERM after 3 messages; the log {log} is complete" in console.stderr()
    rec = read_mcap(path)
    assert rec.counts["/hrc/in"] == 3 and all(o["ok"] for o in rec.of("/hrc/out"))
    again = _hrc("dispatch", str(folder), "--replay", str(log), "--record", str(tmp_path / "again.mcap"))
    assert again.returncode == 0, again.stderr
    assert path.read_bytes() == (tmp_path / "again.mcap").read_bytes()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_the_console_stops_on_a_signal_as_hrc_ros2_does(folder: Path, tmp_path: Path, sig: int) -> None:
    """SIGINT or SIGTERM: the console shuts down, says so in one line and exits 0 with its log whole, the
    way ``hrc ros2`` ends (tests/test_ros2.py); it used to end as an error (130, "error: interrupted")."""
    from console_harness import ConsoleProcess
    from websockets.sync.client import connect

    log = tmp_path / "console.jsonl"
    console = ConsoleProcess(folder, log, "--tick", "0")
    try:
        with connect(console.ws + "ws", open_timeout=10, close_timeout=5,
                     additional_headers=console.page_headers()) as page:
            state = console.state()
            page.send(json.dumps({"type": "press", "hseq": state["hseq"], "id": 1, **state["options"][0]}))
            while (msg := json.loads(page.recv(timeout=10)))["type"] != "reply":
                pass
            assert msg["ok"], msg
        console.proc.send_signal(sig)
        assert console.proc.wait(timeout=30) == 0, console.stderr()
    finally:
        console.stop()
    err = console.stderr()
    name = signal.Signals(sig).name
    assert f"hrc console: stopped by {name} after 1 messages; the log {log} is complete" in err, err
    assert "Traceback" not in err and "error" not in err, err
    assert len(console.log_lines()) == 2


def test_a_recording_on_a_full_disk_stops_and_the_run_goes_on(folder: Path, session: list[str],
                                                               tmp_path: Path) -> None:
    """A 16 KiB file system for the recording (the log elsewhere): every message is answered as without a
    recording, the recording is given up in one line, and nothing of it is left on that disk."""
    from test_online_faults import small_file_system

    stdin = "".join(line + "\n" for line in session).encode()
    plain = _hrc("dispatch", str(folder), stdin=stdin)
    with small_file_system(tmp_path, "16k") as mnt:
        done = _hrc("dispatch", str(folder), "--log", str(tmp_path / "run.log"), "--record", str(mnt / "run.mcap"),
                    stdin=stdin)
        left = sorted(p.name for p in mnt.iterdir())
    assert done.returncode == 0 and done.stdout == plain.stdout
    errors = done.stderr.decode().splitlines()
    assert len(errors) == 1 and "cannot record" in errors[0] and "recording stopped" in errors[0], errors
    assert left == []


def test_atomic_file_is_whole_or_absent(tmp_path: Path) -> None:
    target = tmp_path / "sub" / "f.bin"
    f = AtomicFile(target)
    f.file.write(b"abc")
    assert not target.exists() and f.tmp.name.startswith(".f.bin.")
    assert f.commit() == target and target.read_bytes() == b"abc" and not f.tmp.exists()
    with pytest.raises(FileExistsError):
        AtomicFile(target)
    g = AtomicFile(tmp_path / "g.bin")
    g.file.write(b"x")
    (tmp_path / "g.bin").write_bytes(b"someone else's")  # appeared meanwhile: never overwritten
    with pytest.raises(FileExistsError):
        g.commit()
    assert (tmp_path / "g.bin").read_bytes() == b"someone else's" and not g.tmp.exists()
    h = AtomicFile(tmp_path / "h.bin")
    h.discard()
    h.discard()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.bin", "sub"]
    with pytest.raises(IsADirectoryError):
        AtomicFile(tmp_path)


def test_the_scene_colours_are_the_reports(folder: Path) -> None:
    from hrc.record import scene
    from hrc.report import figures

    task = load_plan_set(folder).task
    assert scene.AGENT_COLORS == figures.AGENT_COLORS
    assert all(scene.agent_color(task, a.id) == figures.agent_color(task, a.id) for a in task.agents)
