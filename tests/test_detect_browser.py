"""The console with the motion detector, in Debian's headless Chromium (issue 28): a tracker sends the
person's recorded positions on the robot's websocket (with the robot's token, through the same checks),
and the page shows the tracked position on the map with the detector's belief."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import pytest
from console_harness import ROOT, ConsoleProcess, browser_or_skip, chromium, compiled_workshop

SPEED = 5.0
TRACE = ROOT / "tests" / "data" / "detect" / "workshop_015_5hz_drop5.trace.jsonl"
# HRC_UPDATE_SCREENSHOT=1 refreshes docs/console-detect.png; otherwise the shot goes beside the test's files.
SCREENSHOT = ROOT / "docs" / "console-detect.png" if os.environ.get("HRC_UPDATE_SCREENSHOT") == "1" else None

pytestmark = pytest.mark.filterwarnings("ignore::ResourceWarning")


@pytest.fixture(scope="module")
def workshop(tmp_path_factory: pytest.TempPathFactory) -> Path:
    browser_or_skip()
    return compiled_workshop(tmp_path_factory.mktemp("ws"))


def test_the_page_shows_the_tracked_person_and_the_belief(workshop: Path, tmp_path: Path) -> None:
    from websockets.sync.client import connect

    console = ConsoleProcess(workshop, tmp_path / "run.jsonl", "--speed", str(SPEED), "--detect", "motion",
                             "--sensor-sigma", "0.15", "--tick", "0")
    messages = [json.loads(x) for x in TRACE.read_text(encoding="utf-8").splitlines()]
    messages = [m for m in messages if m["t"] <= 24.0]  # to the person fetching cube 3
    try:
        with chromium() as context:
            page = context.new_page()
            page.goto(console.url)
            page.wait_for_selector("#map circle", timeout=15000)
            with connect(console.ws + "robot", open_timeout=10, close_timeout=5,
                         additional_headers=console.robot_headers()) as tracker:
                assert json.loads(tracker.recv(timeout=10))["type"] == "hello"
                start = time.monotonic()
                for n, m in enumerate(messages):
                    time.sleep(max(0.0, m["t"] / SPEED - (time.monotonic() - start)) + 0.02)  # not in the future
                    if "event" in m:
                        msg = {"type": "ack", "id": n, "t": m["t"], "action": m["action"], "phase": m["phase"],
                               "event": m["event"]}
                    else:
                        msg = {"type": "position", "id": n, "t": m["t"], "x": m["x"], "y": m["y"]}
                    tracker.send(json.dumps(msg))
                    while True:  # decisions are pushed too: read up to this message's reply
                        reply = json.loads(tracker.recv(timeout=10))
                        if reply["type"] == "reply":
                            break
                    assert reply["ok"] and reply["id"] == n, reply
            state = console.state()
            assert state["tracked"]["t"] == messages[-1 if "x" in messages[-1] else -2]["t"]
            page.wait_for_function("() => document.querySelector('#belief') && "
                                   "document.querySelector('#belief').textContent.length > 0", timeout=15000)
            text = page.text_content("#belief") or ""
            belief = state["belief"]
            assert text.startswith(belief["doing"]), (text, belief)
            if belief["action"]:
                assert f"{belief['action']}.{belief['phase']}" in text
            cx = float(page.get_attribute("#tracked", "cx") or "nan")
            assert abs(cx - state["tracked"]["x"]) < 1e-6
            log_rows = page.text_content("#log") or ""
            assert "detected depart cube1.fetch" in log_rows  # the detector's events in the engineer's log
            shot = SCREENSHOT or tmp_path / "console-detect.png"
            page.screenshot(path=str(shot), full_page=True)
    finally:
        console.stop()
    lines = console.log_lines()
    positions = [x for x in lines if x.get("event") == "position"]
    assert len(positions) == sum(1 for m in messages if "x" in m)  # every position in the log
