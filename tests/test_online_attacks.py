"""Issue 34's attacks on ``hrc dispatch``, ``hrc ros2``, the detector and the one JSON reader they share,
each followed by a watchdog: the process still answers the next message.

The console's are in tests/test_console_attacks.py (through a real server).
"""

from __future__ import annotations

import json
import math
import signal
from pathlib import Path

import pytest
from conftest import compiled_folder
from hypothesis import given, settings
from hypothesis import strategies as st
from test_online_faults import Dispatch

from hrc.detect import DetectingDispatcher
from hrc.detect.filter import MAX_SAMPLES
from hrc.detect.trace import Refusal, detect_lines
from hrc.dispatch.limits import MAX_INT, read_json
from hrc.errors import MessageError

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


@settings(max_examples=300, deadline=None)
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
