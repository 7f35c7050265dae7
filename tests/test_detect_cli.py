"""The motion detector at the edges (issue 28): `hrc detect` on recorded noisy traces of the workshop
against their truth, its one-line refusals; `hrc dispatch --detect motion` driven by positions, its log
replayed byte for byte; the console's robot endpoint taking positions and showing the belief."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT, compiled_folder

from hrc.console.clock import RunClock
from hrc.console.run import open_console
from hrc.detect import DetectParams

DATA = ROOT / "tests" / "data" / "detect"
TRACES = {"workshop_005_10hz": 0.05, "workshop_015_5hz_drop5": 0.15}
HRC = [sys.executable, "-m", "hrc"]


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return compiled_folder(tmp_path_factory.mktemp("detect") / "ws")


def _lines(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]


def _matched(truth: list[dict], given: list[dict]) -> tuple[int, list[float]]:
    """Given events matched one to one with true ones of the same kind within 1 s; their time errors."""
    used: set[int] = set()
    errors = []
    for h in truth:
        for k, g in enumerate(given):
            if k not in used and (g["action"], g["phase"], g["event"]) == (h["action"], h["phase"], h["event"]) \
                    and abs(g["t"] - h["t"]) <= 1.0:
                used.add(k)
                errors.append(g["t"] - h["t"])
                break
    return len(used), errors


@pytest.mark.parametrize("name", sorted(TRACES))
def test_hrc_detect_reproduces_a_recorded_traces_events(folder, name, tmp_path):
    out = tmp_path / "observations.jsonl"
    got = subprocess.run([*HRC, "detect", str(folder), str(DATA / f"{name}.trace.jsonl"), "--out", str(out),
                          "--sensor-sigma", str(TRACES[name])], capture_output=True, text=True, timeout=120)
    assert got.returncode == 0, got.stderr
    assert got.stdout == "" and got.stderr == ""
    given = _lines(out)
    truth = [h for h in _lines(DATA / f"{name}.truth.jsonl") if h["event"] in ("depart", "arrive", "start", "end")]
    matched, errors = _matched(truth, given)
    target = 0.995 if TRACES[name] == 0.05 else 0.98  # the issue's precision and recall
    assert matched >= target * len(truth) and matched >= target * len(given), (matched, len(truth), len(given))
    assert sorted(errors, key=abs)[len(errors) // 2] == pytest.approx(0, abs=0.3)
    times = [g["t"] for g in given]
    assert times == sorted(times)  # in time order: hrc dispatch takes them as they are
    assert all(set(g) == {"t", "agent", "action", "phase", "event"} and g["agent"] == "human" for g in given)


def test_hrc_detect_is_deterministic_and_streams_to_stdout(folder, tmp_path):
    trace = DATA / "workshop_015_5hz_drop5.trace.jsonl"
    runs = [subprocess.run([*HRC, "detect", str(folder), "--sensor-sigma", "0.15"], input=trace.read_bytes(),
                           capture_output=True, timeout=120) for _ in range(2)]
    assert runs[0].returncode == 0 and runs[0].stdout == runs[1].stdout and runs[0].stdout


def test_hrc_detect_refuses_bad_lines_in_one_line_each_and_goes_on(folder, tmp_path):
    good = (DATA / "workshop_005_10hz.trace.jsonl").read_bytes().splitlines()
    bad = [b"not json", b'{"t": 1.0, "x": "a", "y": 1}', b'{"t": -1, "x": 1, "y": 1}', b"[1, 2]",
           b'{"t": 2.0, "y": 1}', b"\xff\xfe", b'{"t": 1e400, "x": 1, "y": 2}', b'{"t": 0.0, "x": 1, "y": 1}',
           b'{"t": 3.0, "agent": "robot", "event": "arrive", "action": "cube9", "phase": "fetch"}',
           b"[" * 100000]
    lines = good[:40] + bad + good[40:]
    trace = tmp_path / "bad.jsonl"
    trace.write_bytes(b"\n".join(lines) + b"\n")
    got = subprocess.run([*HRC, "detect", str(folder), str(trace)], capture_output=True, text=True, timeout=120)
    assert got.returncode == 0
    errors = got.stderr.splitlines()
    assert len(errors) == len(bad), got.stderr
    for number, line in zip(range(41, 41 + len(bad)), errors, strict=True):
        assert line.startswith(f"hrc detect: {trace}: line {number}: ") and line.endswith("; skipped"), line
    assert "Traceback" not in got.stderr
    clean = subprocess.run([*HRC, "detect", str(folder), str(DATA / "workshop_005_10hz.trace.jsonl")],
                           capture_output=True, text=True, timeout=120)
    assert got.stdout == clean.stdout  # the bad lines changed nothing


def test_hrc_detect_says_in_one_line_what_is_wrong_with_its_arguments(folder, tmp_path):
    got = subprocess.run([*HRC, "detect", str(folder), str(tmp_path / "missing.jsonl")], capture_output=True,
                         text=True, timeout=60)
    assert got.returncode == 2 and got.stderr.count("\n") == 1 and "missing.jsonl" in got.stderr
    got = subprocess.run([*HRC, "detect", str(tmp_path)], capture_output=True, text=True, timeout=60,
                         input="")
    assert got.returncode == 2 and got.stderr.startswith("error: ") and got.stderr.count("\n") == 1
    got = subprocess.run([*HRC, "detect", str(folder), "--sensor-sigma", "-1"], capture_output=True, text=True,
                         timeout=60, input="")
    assert got.returncode == 2 and got.stderr.count("\n") == 1
    got = subprocess.run([*HRC, "dispatch", str(folder), "--sensor-sigma", "0.1"], capture_output=True, text=True,
                         timeout=60, input="")
    assert got.returncode == 2 and got.stderr == "error: hrc dispatch: --sensor-sigma needs --detect motion\n"


def _dispatch_stream(name: str) -> str:
    """The recorded stream as `hrc dispatch --detect motion` takes it: positions as position messages."""
    out = []
    for msg in _lines(DATA / f"{name}.trace.jsonl"):
        if "event" not in msg:
            msg = {"t": msg["t"], "agent": "human", "event": "position", "x": msg["x"], "y": msg["y"]}
        out.append(json.dumps(msg))
    return "\n".join(out) + "\n"


def test_a_workshop_run_driven_only_by_positions_finishes_and_replays_byte_for_byte(folder, tmp_path):
    log = tmp_path / "run.log"
    stream = _dispatch_stream("workshop_015_5hz_drop5")
    args = [*HRC, "dispatch", str(folder), "--detect", "motion", "--sensor-sigma", "0.15"]
    got = subprocess.run([*args, "--log", str(log)], input=stream, capture_output=True, text=True, timeout=300)
    assert got.returncode == 0 and got.stderr == "", got.stderr
    answers = [json.loads(line) for line in got.stdout.splitlines()]
    assert len(answers) == len(stream.splitlines())
    assert all(a["ok"] for a in answers), [a for a in answers if not a["ok"]][:3]
    assert not any(a.get("detect", {}).get("refused") for a in answers)
    given = [e for a in answers for e in a.get("detect", {}).get("events", [])]
    task_phases = {(h["action"], h["phase"]) for h in _lines(DATA / "workshop_015_5hz_drop5.truth.jsonl")}
    assert {(e["action"], e["phase"]) for e in given if e["event"] == "end"} == task_phases  # the person's part
    assert answers[-1]["robot"] is None and answers[-1]["human"] is None  # the run is over
    replayed = subprocess.run([*args, "--replay", str(log)], capture_output=True, text=True, timeout=300)
    assert replayed.returncode == 0 and replayed.stdout == got.stdout
    other = subprocess.run([*HRC, "dispatch", str(folder), "--replay", str(log)], capture_output=True, text=True,
                           timeout=300)
    assert other.returncode == 2 and other.stderr.count("\n") == 1 and "detector settings" in other.stderr


def test_hrc_dispatch_refuses_a_position_without_the_detector(folder):
    msg = json.dumps({"t": 0.5, "agent": "human", "event": "position", "x": 1.0, "y": 1.0})
    got = subprocess.run([*HRC, "dispatch", str(folder)], input=msg + "\n", capture_output=True, text=True,
                         timeout=120)
    answer = json.loads(got.stdout)
    assert got.returncode == 0 and answer["ok"] is False and "--detect motion" in answer["error"]
    bad = json.dumps({"t": 0.5, "agent": "robot", "event": "position", "x": 1.0, "y": 1.0})
    got = subprocess.run([*HRC, "dispatch", str(folder), "--detect", "motion"], input=bad + "\n",
                         capture_output=True, text=True, timeout=120)
    answer = json.loads(got.stdout)
    assert answer["ok"] is False and "human" in answer["error"]


def test_the_console_takes_positions_from_the_robot_stream_and_shows_the_belief(folder, tmp_path):
    server = open_console(folder, log=tmp_path / "console.jsonl", detect=DetectParams(sigma=0.15))
    session = server.session
    now = [0.0]
    session.clock = RunClock(speed=1.0, monotonic=lambda: now[0])
    session.clock.start()
    beliefs = set()
    for msg in _lines(DATA / "workshop_015_5hz_drop5.trace.jsonl"):
        now[0] = msg["t"] + 0.01
        if "event" in msg:
            reply = session.robot_message({"type": "ack", "t": msg["t"], "action": msg["action"],
                                           "phase": msg["phase"], "event": msg["event"]})
        else:
            reply = session.robot_message({"type": "position", "t": msg["t"], "x": msg["x"], "y": msg["y"]})
        assert reply["ok"], reply
        state = session.state()
        assert state["tracked"]["t"] <= msg["t"] and set(state["belief"]) >= {"doing", "action", "phase", "p"}
        beliefs.add(state["belief"]["doing"])
    assert session.finished
    assert {"walk", "work"} <= beliefs
    now[0] += 1.0
    same = session.robot_message({"t": now[0] - 0.5, "agent": "human", "event": "position", "x": 1.0, "y": 1.0})
    assert same["ok"], same  # the dispatcher protocol's shape is taken too
    session.logged.close()
    replayed = subprocess.run([*HRC, "dispatch", str(folder), "--detect", "motion", "--sensor-sigma", "0.15",
                               "--replay", str(tmp_path / "console.jsonl")], capture_output=True, text=True,
                              timeout=300)
    assert replayed.returncode == 0, replayed.stderr


def test_the_console_refuses_positions_without_the_detector_and_bad_ones(folder, tmp_path):
    plain = open_console(folder, log=tmp_path / "plain.jsonl")
    reply = plain.session.robot_message({"type": "position", "t": 0.0, "x": 1.0, "y": 1.0})
    assert not reply["ok"] and "--detect motion" in reply["error"]
    plain.session.logged.close()
    server = open_console(folder, log=tmp_path / "detect.jsonl", detect=DetectParams())
    for bad in ({"type": "position", "x": "a", "y": 1.0}, {"type": "position", "x": 1.0},
                {"type": "position", "x": 1.0, "y": 1.0, "z": 0}, {"type": "position", "t": 99.0, "x": 1, "y": 1}):
        reply = server.session.robot_message(bad)
        assert not reply["ok"] and "\n" not in reply["error"], reply
    assert server.session.total == 0  # none reached the dispatcher or its log
    server.session.logged.close()
