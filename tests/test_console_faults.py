"""Fault injection for the console (issue 26, items 3, 4 and 6), in Debian's headless Chromium against a
real ``hrc console`` process: a flood of impossible presses from a page while the robot acknowledges,
bad frames (deep nesting, a lone surrogate, an oversized frame), a full file system under the run's log,
and ``kill -9`` followed by ``--resume``.

The robot controller is a real websocket client with the robot's token (``websockets``), the person a
page in Chromium with the page's. Memory is the console process's resident set (``/proc/PID/status``).
Skipped with the reason when playwright or Chromium is missing (failed under HRC_REQUIRE_BROWSER=1).
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from console_harness import ROOT, ConsoleProcess, browser_or_skip, chromium, compiled_workshop, connected_page
from test_online_faults import _fill, small_file_system

from hrc.dispatch import Dispatcher
from hrc.dispatch.logfile import read_log
from hrc.dispatch.protocol import replay

SPEED = 5.0
pytestmark = pytest.mark.filterwarnings("ignore::ResourceWarning")


@pytest.fixture(scope="module")
def workshop(tmp_path_factory: pytest.TempPathFactory) -> Path:
    browser_or_skip()
    return compiled_workshop(tmp_path_factory.mktemp("ws"))


def _rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise AssertionError("no VmRSS")


class Robot:
    """The robot controller: a websocket with the robot's token; keeps the last decision it was sent."""

    def __init__(self, console: ConsoleProcess) -> None:
        from websockets.sync.client import connect

        self.ws = connect(console.ws + "robot", open_timeout=10, close_timeout=5,
                          additional_headers=console.robot_headers()).__enter__()
        assert json.loads(self.ws.recv(timeout=10))["type"] == "hello"
        self.decision = json.loads(self.ws.recv(timeout=10))

    def step(self) -> dict[str, Any] | None:
        robot = self.decision["decision"]["robot"]
        return robot if robot and "action" in robot else None

    def wait_for_step(self, timeout: float = 15.0) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        while self.step() is None:
            self.decision = self._next("decision", deadline)
        step = self.step()
        assert step is not None
        return step

    def _next(self, kind: str, deadline: float, reply_id: str | None = None) -> dict[str, Any]:
        while True:
            msg = json.loads(self.ws.recv(timeout=max(0.01, deadline - time.monotonic())))
            if msg["type"] == "decision":
                self.decision = msg
            if msg["type"] == kind and (reply_id is None or msg.get("id") == reply_id):
                return msg

    def ack(self, step: dict[str, Any], t: float, reply_id: str) -> tuple[dict[str, Any], float]:
        """Acknowledge `step` as done at run time `t`; the reply and how long it took (s)."""
        message = {"type": "ack", "id": reply_id, "t": t, **{k: step[k] for k in ("action", "phase", "event")}}
        start = time.perf_counter()
        self.ws.send(json.dumps(message))
        reply = self._next("reply", time.monotonic() + 10, reply_id)
        took = time.perf_counter() - start
        if reply["ok"]:  # the decision that follows it
            seq = self.decision["seq"]
            while self.decision["seq"] <= seq:
                self.decision = self._next("decision", time.monotonic() + 10)
        return reply, took

    def close(self) -> None:
        self.ws.__exit__(None, None, None)


def _press_first_option(console: ConsoleProcess) -> None:
    from websockets.sync.client import connect

    with connect(console.ws + "ws", open_timeout=10, close_timeout=5, additional_headers=console.page_headers()) as p:
        state = console.state()
        p.send(json.dumps({"type": "press", "hseq": state["hseq"], "id": 1, **state["options"][0]}))
        while (msg := json.loads(p.recv(timeout=10)))["type"] != "reply":
            pass
        assert msg["ok"], msg


def _wait_run_time(console: ConsoleProcess, t: float, timeout: float = 30.0) -> float:
    deadline = time.monotonic() + timeout
    while (now := console.state()["now"]) < t:
        assert time.monotonic() < deadline, f"run time {now} never reached {t}"
        time.sleep(0.02)
    return now


_FLOOD = """([n, hseq]) => { const ws = window.hrcConsole.ws, flood = window.flood = {sent: 0, answered: 0};
  ws.addEventListener("message", (e) => { if (JSON.parse(e.data).type === "reply") flood.answered++; });
  (async () => { for (let i = 0; i < n; i++) {
      ws.send(JSON.stringify({type: "press", hseq, action: "cube9", phase: "fetch", event: "start", id: "f" + i}));
      flood.sent++;
      if (i % 50 === 49) await new Promise((r) => setTimeout(r, 10));  // 5,000 a second for 2 s
  } })(); }"""


@pytest.mark.serial  # a latency bound: measured with nothing else running (Makefile)
def test_a_flood_of_impossible_presses_never_delays_the_robot_and_memory_stays_flat(workshop: Path,
                                                                                      tmp_path: Path) -> None:
    console = ConsoleProcess(workshop, tmp_path / "run.jsonl", "--tick", "0", "--speed", str(SPEED))
    try:
        robot = Robot(console)
        while robot.step() is None:  # the workshop's robot waits for the person's first move
            _press_first_option(console)
            robot.wait_for_step()
        latencies: list[float] = []
        memory: list[float] = []
        with chromium() as ctx:
            page = connected_page(ctx, console.url)
            memory.append(_rss_mb(console.proc.pid))
            before = console.state()
            for flood in range(3):  # the robot's next three events, each acknowledged during a flood
                step = robot.wait_for_step()
                _wait_run_time(console, step["earliest"])  # the robot's event is due: now the flood
                page.evaluate(_FLOOD, [10_000, console.state()["hseq"]])
                page.wait_for_function("() => window.flood.sent >= 1500", timeout=30_000, polling=10)
                reply, seconds = robot.ack(step, step["earliest"], f"ack{flood}")
                received_at_ack = console.state()["traffic"]["received"]
                assert reply["ok"], reply
                latencies.append(seconds)
                page.wait_for_function("() => window.flood.sent >= 10000", timeout=60_000, polling=50)
                time.sleep(1.0)  # what is still in flight
                assert console.state()["traffic"]["received"] > received_at_ack, "acknowledged after the flood"
                memory.append(_rss_mb(console.proc.pid))
                if not page.evaluate("() => window.hrcConsole.connected"):  # dropped as too slow a reader
                    page.wait_for_function("() => window.hrcConsole.connected", timeout=15_000)
            after = console.state()
            page_replies = page.evaluate("() => window.flood.answered")
        reached = after["log_total"] - before["log_total"] - 3
        received = after["traffic"]["received"] - before["traffic"]["received"] - 3
        limited = after["traffic"]["limited"] - before["traffic"]["limited"]
        print(f"\nrobot acks under a flood of 10,000 impossible presses each: {[round(x * 1000, 1) for x in latencies]}"
              f" ms; console RSS {' -> '.join(f'{m:.1f}' for m in memory)} MB; of 30,000 presses sent, {received}"
              f" arrived: {limited} refused at the door, {reached} reached the dispatcher (and the log)")
        # on a shared 2-core machine a scheduler pause can land on any one of them: the median must keep the
        # promise, and none may come near the 16 s of issue 26
        assert statistics.median(latencies) < 0.100 and max(latencies) < 0.5, latencies
        assert memory[-1] - memory[1] < 5 and memory[-1] - memory[0] < 20, memory  # flat: no growth per message
        # the rate limit let few of them reach the dispatcher: its burst, then its rate while the floods lasted
        assert 0 < reached < 3 * 10 + 5 * 60, reached
        # the last flood's page was told in one line a second, not once a message
        assert page_replies < 100, page_replies
        assert len(after["log"]) <= 300 and after["seq"] == before["seq"] + 3
        robot.close()
    finally:
        console.stop()


def test_bad_frames_get_one_line_refusals_and_never_break_the_state(workshop: Path, tmp_path: Path) -> None:
    console = ConsoleProcess(workshop, tmp_path / "run.jsonl", "--tick", "0")
    try:
        with chromium() as ctx:
            page = connected_page(ctx, console.url)
            hseq = console.state()["hseq"]
            cases = [
                ("[" * 20_000, "longer than 4096 bytes"),
                ("[" * 4000, "nested deeper than 16 levels"),
                ('{"type": "press", "hseq": 0, "x": ' + "[" * 17 + "]" * 17 + "}", "nested deeper"),
                ('{"type": "press", "hseq": HSEQ, "action": "\\ud800", "phase": "\\udfff", "event": "start"}'
                 .replace("HSEQ", str(hseq)), "unknown action"),
                ('{"type": "ack", "hseq": 0}', "unknown message type"),
                ('{"type": "press", "hseq": 1' + "0" * 5000 + "}", "longer than 4096 bytes"),
            ]
            for frame, expected in cases:
                answer = page.evaluate("""(t) => new Promise((done) => { const ws = window.hrcConsole.ws;
                    const on = (e) => { const m = JSON.parse(e.data);
                      if (m.type === "reply") { ws.removeEventListener("message", on); done(m); } };
                    ws.addEventListener("message", on); ws.send(t); })""", frame)
                assert answer["ok"] is False and expected in answer["error"], (frame[:40], answer)
                assert "\n" not in answer["error"]
                assert page.evaluate("() => fetch('/state').then(r => r.status)") == 200
            # the lone surrogate's press is in the log and in the state, escaped, and /state still answers
            state = console.state()
            assert state["log"][-1]["in"]["action"] == "\ud800" and state["hseq"] == hseq
            assert page.evaluate("() => window.hrcConsole.connected") and page.evaluate(
                "() => window.hrcConsole.stats.reconnects") == 0
            # a frame larger than the server reads at all closes the connection; the page reconnects
            page.evaluate("() => window.hrcConsole.ws.send('x'.repeat(70000))")
            page.wait_for_function("() => window.hrcConsole.stats.reconnects >= 1 && window.hrcConsole.connected",
                                   timeout=15_000)
            assert console.state()["seq"] == state["seq"]
    finally:
        console.stop()
    assert "Traceback" not in console.stderr()


def test_a_full_file_system_is_said_on_the_page_and_nothing_changes(workshop: Path, tmp_path: Path) -> None:
    with small_file_system(tmp_path, "1m") as mnt:
        console = ConsoleProcess(workshop, mnt / "run.jsonl", "--tick", "0")
        try:
            with chromium() as ctx:
                page = connected_page(ctx, console.url)
                filler = _fill(mnt)
                refused = None
                for _ in range(60):  # the log's last page may hold a few more records: away, back, ...
                    before = console.state()
                    button = "#back" if before["decision"]["human_away"] else "#away"
                    page.click(button)
                    page.wait_for_function("h => window.hrcConsole.state.hseq > h || !document.getElementById("
                                           "'error').hidden", arg=before["hseq"], timeout=15_000)
                    if not page.is_hidden("#error"):
                        refused = page.text_content("#error-text")
                        break
                assert refused is not None and "cannot be written" in refused and "No space left" in refused
                page.wait_for_selector("#log-error", state="visible", timeout=15_000)
                assert "No space left on device" in page.text_content("#log-error")
                after = console.state()
                assert (after["seq"], after["hseq"], after["decision"]) == (before["seq"], before["hseq"],
                                                                            before["decision"])
                assert after["log_error"] and "No space left" in after["log_error"]
                # room again: the same press is taken, and the banner goes
                filler.unlink()
                page.click("#error-close")
                page.click(button)
                page.wait_for_function("h => window.hrcConsole.state.hseq > h", arg=before["hseq"], timeout=15_000)
                page.wait_for_selector("#log-error", state="hidden", timeout=15_000)
        finally:
            console.stop()
        contents = read_log(mnt / "run.jsonl")
        assert contents.torn is None and len(contents.messages) == after["log_total"] + 1
        assert all(a == b for a, b in replay(Dispatcher.from_folder(workshop), contents))


def test_kill_9_then_resume_goes_on_with_the_same_run(workshop: Path, tmp_path: Path) -> None:
    log = tmp_path / "run.jsonl"
    console = ConsoleProcess(workshop, log, "--tick", "0", "--speed", str(SPEED))
    try:
        robot = Robot(console)
        while robot.step() is None:
            _press_first_option(console)
            robot.wait_for_step()
        step = robot.step()
        assert step is not None
        now = _wait_run_time(console, step["earliest"])
        assert robot.ack(step, max(step["earliest"], now), "a")[0]["ok"]
        _press_first_option(console)
        before = console.state()
        robot.close()
    finally:
        if console.proc.poll() is None:
            console.proc.kill()  # SIGKILL: no clean-up at all
        console.proc.wait(timeout=30)
        console.stop()
    resumed = ConsoleProcess(workshop, log, "--tick", "0", "--speed", str(SPEED), "--resume", str(log),
                             log_option=False)
    try:
        after = resumed.state()
        for key in ("seq", "hseq", "decision", "options", "under_way", "log_total", "finished"):
            assert after[key] == before[key], key
        assert after["now"] >= before["decision"]["t"]
        assert [e["in"] for e in after["log"]] == [e["in"] for e in before["log"]]
        with chromium() as ctx:  # the page shows the run where it was, and the person goes on
            page = ctx.new_page()
            page.goto(resumed.url)
            page.wait_for_function("h => window.hrcConsole && window.hrcConsole.connected && "
                                   "window.hrcConsole.state.hseq === h", arg=before["hseq"], timeout=15_000)
            page.locator("#buttons button.act").first.click()
            page.wait_for_function("h => window.hrcConsole.state.hseq === h + 1", arg=before["hseq"],
                                   timeout=15_000)
        # a second console on the same log is refused while this one runs
        done = subprocess.run([sys.executable, "-m", "hrc", "console", str(workshop), "--port", "0", "--resume",
                               str(log)], capture_output=True, text=True, timeout=60, cwd=ROOT,
                              env=dict(os.environ, PYTHONPATH=str(ROOT)))
        assert done.returncode == 2 and done.stderr.count("\n") == 1 and "in use" in done.stderr, done.stderr
    finally:
        resumed.stop()
    contents = read_log(log)
    assert contents.resumed == 1 and contents.torn is None
    answers = [a for a, _ in replay(Dispatcher.from_folder(workshop), contents)]
    assert answers == [m.answer for m in contents.messages]
    assert statistics.mean(json.loads(a)["ok"] for a in answers) > 0.5
