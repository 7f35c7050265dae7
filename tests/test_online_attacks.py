"""Issue 34's attacks on ``hrc dispatch``, ``hrc ros2``, the detector and the one JSON reader they share,
each followed by a watchdog: the process still answers the next message.

The console's are in tests/test_console_attacks.py (through a real server).
"""

from __future__ import annotations

import json
import math
import signal
from pathlib import Path
from typing import Any

import pytest
from conftest import compiled_folder
from hypothesis import given, settings
from hypothesis import strategies as st
from test_online_faults import Dispatch

from hrc.detect import DetectingDispatcher
from hrc.detect.filter import MAX_SAMPLES
from hrc.detect.trace import Refusal, detect_lines
from hrc.dispatch.limits import MAX_INT, read_json
from hrc.dispatch.logfile import read_log
from hrc.errors import InputError, MessageError

HUGE_T = b'{"t": -1' + b"0" * 309 + b', "event": "tick"}'
TICK = b'{"t": 1, "event": "tick"}'


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return compiled_folder(tmp_path_factory.mktemp("attacks") / "ws")


# -- the reader ------------------------------------------------------------------------------------
@pytest.mark.parametrize(("text", "message"), [
    ('{"agent": "robot", "agent": "human", "t": 0}', "key 'agent': given twice in one object"),
    ('{"a": [1, {"b": 2, "b": 3}]}', "key 'a[1].b': given twice in one object"),
    ('{"t": NaN}', "key 't': NaN is not a number JSON allows"),
    ('{"t": -Infinity}', "key 't': -Infinity is not a number JSON allows"),
    ('{"x": 1e400}', "key 'x': 1e400 is beyond the range of a double"),
    ('{"t": -1' + "0" * 309 + "}", "key 't': an integer of 310 digits (at most 2**53 in magnitude)"),
    ('{"t": ' + "9" * 5000 + "}", "key 't': an integer of 5000 digits"),
    (f'{{"n": {MAX_INT + 1}}}', "key 'n': an integer of 16 digits"),
    ("[" * 17 + "]" * 17, "nested deeper than 16 levels"),
    ("{", "not JSON: "),
    (b"\xff", "message is not UTF-8"),
])
def test_the_reader_refuses_in_one_line_naming_the_key(text: str | bytes, message: str) -> None:
    with pytest.raises(MessageError) as caught:
        read_json(text)
    assert message in str(caught.value) and "\n" not in str(caught.value)


def test_the_reader_takes_what_json_takes_within_the_bounds() -> None:
    for value in (MAX_INT, -MAX_INT, 0, 1.5e308, -0.0, "\ud800", {"a": [1, {"b": None}]}, [True, False]):
        text = json.dumps(value)
        assert read_json(text) == json.loads(text) and read_json(text.encode("utf-8", "surrogatepass")) == value


@settings(max_examples=150, deadline=None)
@given(st.one_of(st.binary(max_size=300), st.text(max_size=300),
                 st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
                              lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=3), kids,
                                                                                        max_size=4),
                              max_leaves=20).map(json.dumps)))
def test_the_reader_gives_a_value_or_one_message_error_never_anything_else(data: str | bytes) -> None:
    try:
        value = read_json(data)
    except MessageError as err:
        assert "\n" not in str(err)
        return
    text = data.decode("utf-8") if isinstance(data, bytes) else data
    assert value == json.loads(text) or value != value  # (a float NaN cannot get through: see above)


# -- hrc dispatch ------------------------------------------------------------------------------------
def test_hrc_dispatch_refuses_a_huge_number_and_repeated_keys_by_the_parser_and_goes_on(folder: Path,
                                                                                         tmp_path: Path) -> None:
    attacks = [
        (HUGE_T, "key 't': an integer of 310 digits"),
        (b'{"t": 0, "agent": "robot", "agent": "human", "action": "cube1", "phase": "fetch", "event": "depart"}',
         "key 'agent': given twice in one object"),
        (b'{"t": 0, "event": "tick", "event": "undo"}', "key 'event': given twice"),
        (b'{"t": 1e400, "event": "tick"}', "key 't': 1e400 is beyond the range of a double"),
    ]
    with Dispatch(folder, "--log", str(tmp_path / "run.log")) as run:
        for n, (line, message) in enumerate(attacks, 1):
            run.send([line])
            (got,) = run.answers(1, timeout=10)
            out = json.loads(got)
            assert out == {"t": None, "ok": False, "error": out["error"]} and message in out["error"], got
            assert "internal error" not in out["error"]
            run.send([b'{"t": %d, "event": "tick"}' % n])  # the watchdog: the next one is answered and taken
            assert json.loads(run.answers(1, timeout=10)[0])["ok"] is True
        run.close_input()
        assert run.proc.wait(timeout=30) == 0


@pytest.mark.slow
def test_hrc_dispatch_with_the_detector_refuses_a_position_beyond_any_float(folder: Path) -> None:
    with Dispatch(folder, "--detect", "motion") as run:
        position = b'{"t": 0.5, "agent": "human", "event": "position", "x": X, "y": 1}'
        for i, line in enumerate([position.replace(b"X", b"1" + b"0" * 400), position.replace(b"X", b"1e300")]):
            run.send([line])
            out = json.loads(run.answers(1, timeout=10)[0])
            assert out["ok"] is False and "internal error" not in out["error"], out
            assert ("key 'x'" if i == 0 else "within ±1e+06") in out["error"], out
            run.send([b'{"t": %d, "agent": "human", "event": "position", "x": 1.0, "y": 1.0}' % (i + 1)])
            assert json.loads(run.answers(1, timeout=10)[0])["ok"] is True
        run.close_input()
        assert run.proc.wait(timeout=30) == 0


# -- the detector ------------------------------------------------------------------------------------
def test_positions_that_all_carry_one_t_keep_the_detectors_memory_and_cost_bounded(folder: Path) -> None:
    d = DetectingDispatcher.from_folder(folder)
    sizes = []
    for n in range(MAX_SAMPLES + 100):
        d.take_position(1.0, 1.0 + (n % 7) * 0.01, 1.0)
        sizes.append(len(d.track.samples))
    # before: one more kept with every position, and each cost more than the last (the fits are
    # O(samples)); now the newest MAX_SAMPLES, so a position's cost is bounded too
    assert sizes[:3] == [1, 2, 3] and max(sizes) == MAX_SAMPLES and sizes[-100:] == [MAX_SAMPLES] * 100


def test_a_trace_line_beyond_any_float_is_refused_and_the_trace_goes_on(folder: Path) -> None:
    d = DetectingDispatcher.from_folder(folder)
    lines = [b'{"t": 0.0, "x": 1.0, "y": 1.0}', b'{"t": 0.2, "x": 1' + b"0" * 400 + b', "y": 1.0}',
             b'{"t": 0.2, "x": 1e300, "y": 1.0}', b'{"t": 0.4, "x": 1.0, "y": 1.0}']
    out = list(detect_lines(d, lines))
    refusals = [x for x in out if isinstance(x, Refusal)]
    assert [r.line for r in refusals] == [2, 3] and "key 'x'" in refusals[0].why and "1e+06" in refusals[1].why
    assert d.track.t == 0.4  # the line after them was taken


# -- hrc ros2 ----------------------------------------------------------------------------------------
@pytest.mark.slow
def test_the_ros2_node_refuses_huge_numbers_and_an_infinite_pose_and_still_answers(folder: Path,
                                                                                    tmp_path: Path) -> None:
    from ros2_client import Client, NodeProcess, ros_env

    env = ros_env(tmp_path)
    node = NodeProcess(folder, env, "--detect", "motion")
    client = Client(env)
    try:
        client.wait_matched()
        refusal = json.loads(client.send(HUGE_T.decode()))
        assert refusal["ok"] is False and "key 't': an integer of 310 digits" in refusal["error"], refusal
        assert json.loads(client.send(TICK.decode()))["ok"] is True
        pose = client.PoseStamped()
        pose.header.frame_id = "map"
        pose.header.stamp.sec = 2
        pose.pose.position.x = math.inf
        before = len(client.answers)
        client.poses.publish(pose)
        client.spin_until(lambda: len(client.answers) > before, 20, "the pose's refusal")
        refusal = json.loads(client.answers[-1])
        assert refusal["ok"] is False and "Infinity is not a number JSON allows" in refusal["error"], refusal
        assert json.loads(client.send('{"t": 3, "event": "tick"}'))["ok"] is True
        assert node.stop(signal.SIGINT) == 0
    finally:
        client.close()
        node.kill()
    assert "internal error" not in node.stderr() and "Traceback" not in node.stderr()


# -- the log -----------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def thirty(folder: Path, tmp_path_factory: pytest.TempPathFactory) -> bytes:
    """A log of 30 accepted messages (ticks a second apart), written by ``hrc dispatch --log``."""
    log = tmp_path_factory.mktemp("log") / "run.log"
    with Dispatch(folder, "--log", str(log)) as run:
        run.send([b'{"t": %d, "event": "tick"}' % t for t in range(30)])
        assert all(json.loads(a)["ok"] for a in run.answers(30))
        run.close_input()
        assert run.proc.wait(timeout=30) == 0
    return log.read_bytes()


def _lines(data: bytes) -> list[bytes]:
    return data.splitlines(keepends=True)  # the log is ASCII: no other line ends in it


def _edited(thirty: bytes) -> bytes:
    lines = _lines(thirty)
    lines[20] = lines[20].replace(b'\\"ok\\": true', b'\\"ok\\": true ', 1)  # message 10's answer, edited
    assert lines[20] != _lines(thirty)[20] and lines[20].startswith(b'{"out"')
    return b"".join(lines)


@pytest.mark.parametrize(("damage", "line", "message"), [
    (lambda d: d + _lines(d)[0], 62, "a header line inside the log"),  # the attack: 30 messages lost
    (lambda d: b"".join(_lines(d)[:31] + _lines(d)[:1] + _lines(d)[31:]), 32, "a header line inside the log"),
    (lambda d: d + b'{"resumed": 3}\n', 62, "resumed after 3 messages, but 30 came before"),
    (lambda d: d + b'{"out": "{}"}\n', 62, "damaged record (an answer without its message)"),
    (lambda d: d + b'{"in": "{}", "in": "[]"}\n', 62, "key 'in': given twice"),
    (lambda d: d + b'{"in": "{}", "out": "{}"}\n', 62, "not a log record (keys in, out)"),
    (lambda d: d + b'{"in": "{}"}\n{"in": "{}"}\n', 63, "a message after a message without its answer"),
])
def test_a_damaged_log_is_refused_in_one_line_never_read_as_a_shorter_one(tmp_path: Path, thirty: bytes, damage: Any,
                                                                        line: int, message: str) -> None:
    log = tmp_path / "damaged.log"
    log.write_bytes(damage(thirty))
    with pytest.raises(InputError) as caught:
        read_log(log)
    assert caught.value.line == line and message in str(caught.value) and "\n" not in str(caught.value)
    # what is still a torn end: an incomplete last line, a message without its answer, NUL padding
    for torn in (thirty + b'{"in": "{\\"t\\": 3', thirty + b'{"in": "{}"}\n', thirty + b"\x00" * 100):
        log.write_bytes(torn)
        assert read_log(log).torn is not None and len(read_log(log).messages) == 30


@pytest.mark.slow
def test_resume_and_replay_refuse_a_log_with_its_header_appended_or_an_answer_edited(folder: Path, tmp_path: Path,
                                                                                     thirty: bytes) -> None:
    from test_online_faults import _hrc_dispatch

    log = tmp_path / "damaged.log"
    log.write_bytes(thirty + _lines(thirty)[0])  # the attack: --resume said "after 0 messages"
    for option in ("--resume", "--replay"):
        done = _hrc_dispatch(folder, option, str(log))
        err = done.stderr.decode()
        assert done.returncode == 2 and err.count("\n") == 1 and done.stdout == b"", (option, err)
        assert err.startswith(f"error: {log}:62: a header line inside the log"), (option, err)
    assert log.read_bytes() == thirty + _lines(thirty)[0]  # left as it was
    log.write_bytes(_edited(thirty))
    done = _hrc_dispatch(folder, "--resume", str(log))
    err = done.stderr.decode()
    assert done.returncode == 2 and err == f"error: {log}:21: message 10's answer differs from the logged one " \
                                           "(an edited log, another hrc, or the compiled folder changed?): " \
                                           "not resuming\n", err
    done = _hrc_dispatch(folder, "--replay", str(log))
    assert done.returncode == 1 and done.stderr.decode() == f"error: {log}:21: answer 10 differs from the logged one\n"
    assert log.read_bytes() == _edited(thirty)
