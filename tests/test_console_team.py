"""The operator console for a team (issue 37), in a real headless Chromium and over its websockets.

two_workers (two people, one robot, a joint load): alice's and bob's pages each press only their own
offered buttons, the robot simulated, to the end of the run; every press is logged as that person's, the
buttons each page showed were the dispatcher's options for that person at that point (the log replayed
into a fresh dispatcher), the shared view draws a Gantt row and a disc per agent and may not press, and the
log replays through ``hrc dispatch --replay`` byte for byte. kitting_2robots cut to three picks (one
person, two robots): ``--simulate-robot`` drives both robots to the end of a run; real controllers connect
one per robot (``/robot?robot=ID``), each acknowledges its own robot's events only, and an unknown id, a
second controller or an ack for another agent is refused in one line and changes nothing.

Skipped with the reason when playwright or Chromium is missing (as tests/test_console_browser.py).
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
import yaml
from console_harness import ROOT, ConsoleProcess, browser_or_skip, chromium, record_requests

from hrc.io.task_file import load_task

SPEED = 8.0           # run seconds per real second
RUN_TIMEOUT = 120.0   # real seconds for a whole run

pytestmark = pytest.mark.filterwarnings("ignore::ResourceWarning")

_SNAPSHOT = """() => { const c = window.hrcConsole, s = c.state;
  return {seq: s.seq, finished: s.finished, now: c.runNow(), connected: c.connected, busy: c.pending.size > 0,
          hseq: s.persons && c.person ? s.persons[c.person].hseq : -1,
          buttons: [...document.querySelectorAll('#buttons button.act')].map(b =>
            [b.dataset.action, b.dataset.phase, b.dataset.event, b.disabled]),
          error: document.getElementById('error').hidden ? null : document.getElementById('error-text').textContent};
}"""
_PRESS = """([a, p, e]) => { const b = document.querySelector(
  `#buttons button.act[data-action="${a}"][data-phase="${p}"][data-event="${e}"]`);
  if (!b || b.disabled) return null; b.click(); return [a, p, e]; }"""


def _compile(out: Path, task: Path) -> Path:
    from conftest import compiled_folder

    return compiled_folder(out, task, "--jobs", "1")


@pytest.fixture(scope="module")
def workers(tmp_path_factory: pytest.TempPathFactory) -> Path:
    browser_or_skip()
    return _compile(tmp_path_factory.mktemp("tw") / "out", ROOT / "tasks" / "two_workers.yaml")  # 120 plans


def kitting3_task(where: Path) -> Path:
    """tasks/kitting_2robots.yaml cut to its first three picks (60 plans: 3! C(5, 2)), written into `where`."""
    data = yaml.safe_load((ROOT / "tasks" / "kitting_2robots.yaml").read_text())
    data["actions"] = data["actions"][:3]
    data["map"] = str(ROOT / "maps" / "kitting_cell.yaml")
    data["name"] = "kitting_2robots_3picks"
    path = where / "kitting3.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def kitting3(tmp_path_factory: pytest.TempPathFactory) -> Path:
    where = tmp_path_factory.mktemp("k3")
    return _compile(where / "out", kitting3_task(where))


def _min_durations(out_dir: Path) -> dict[tuple[str, str, str, str], float]:
    """Each person's shortest time from an event to the next of the same phase (run seconds): a
    manipulation's lower bound (start -> end) and a walk's free-space time (depart -> arrive)."""
    task = load_task(out_dir / "input" / "task.yaml")
    out: dict[tuple[str, str, str, str], float] = {}
    for agent in (a.id for a in task.agents if a.is_human):
        for action in task.actions:
            for phase in action.phases:
                if agent in action.agents:
                    out[(agent, action.id, phase.id, "end")] = max(iv.lb for _, iv in phase.durations)
    for plan in json.loads((out_dir / "compiled.json").read_text())["plans"]:
        for m in plan["motions"]:
            key = (m["agent"], m["action"], m["phase"], "arrive")
            out[key] = min(out.get(key, m["free_time"]), m["free_time"])
    return out


def _choose(buttons: list[list[Any]], rng: random.Random) -> list[str] | None:
    offered = [b[:3] for b in buttons if not b[3]]
    if not offered:
        return None
    ends = [b for b in offered if b[2] == "end"]
    return ends[0] if ends else rng.choice(offered)


def _play(pages: dict[str, Any], out_dir: Path, seed: int = 0) -> tuple[list[tuple[str, dict[str, Any]]],
                                                                        list[tuple[str, list[str]]]]:
    """Each person presses on their own page, in turns (a seeded choice among their offered buttons, "done"
    first, never before the shortest time the task allows), until the run is finished. Returns every
    snapshot looked at (person, snapshot) and every press (person, [action, phase, event])."""
    rng = random.Random(seed)
    waits = _min_durations(out_dir)
    begun: dict[tuple[str, str, str], float] = {}
    seen: list[tuple[str, dict[str, Any]]] = []
    pressed: list[tuple[str, list[str]]] = []
    stop = time.monotonic() + RUN_TIMEOUT
    while time.monotonic() < stop:
        finished = False
        for person, page in pages.items():
            snap = page.evaluate(_SNAPSHOT)
            seen.append((person, snap))
            assert snap["error"] is None, f"{person}'s page shows an error: {snap['error']}"
            finished = snap["finished"]
            choice = None if snap["busy"] or finished else _choose(snap["buttons"], rng)
            if choice is None:
                continue
            action, phase, event = choice
            ready = begun.get((person, action, phase), 0.0) + waits.get((person, action, phase, event), 0.0) + 0.3
            if snap["now"] < ready or page.evaluate(_PRESS, choice) is None:
                continue
            pressed.append((person, choice))
            page.wait_for_function("h => window.hrcConsole.state.persons[window.hrcConsole.person].hseq > h"
                                   " || !document.getElementById('error').hidden", arg=snap["hseq"],
                                   timeout=15_000, polling=20)
            begun[(person, action, phase)] = page.evaluate("() => window.hrcConsole.runNow()")
        if finished:
            return seen, pressed
        time.sleep(0.02)
    pytest.fail(f"the run did not finish within {RUN_TIMEOUT} s; last view {seen[-1]}")


def _options_after_each(out_dir: Path, log: Path, people: tuple[str, ...]) -> list[dict[str, list[list[str]]]]:
    """Each person's options after k accepted messages of the log (k = 0, 1, ...), from a fresh dispatcher."""
    from hrc.dispatch import Dispatcher
    from hrc.dispatch.logfile import read_log
    from hrc.dispatch.protocol import answer

    fresh = Dispatcher.from_folder(out_dir)

    def now() -> dict[str, list[list[str]]]:
        return {p: sorted([o.action, o.phase, o.event] for o in fresh.human_options(p)) for p in people}

    out = [now()]
    for message in read_log(log).messages:
        if json.loads(answer(fresh, message.data))["ok"]:
            out.append(now())
    return out


def person_urls(console: ConsoleProcess, people: tuple[str, ...]) -> dict[str, str]:
    """The address `hrc console` printed for each person's page (with that person's own secret)."""
    out: dict[str, str] = {}
    while len(out) < len(people):
        line = console.lines.get(timeout=10)
        if "'s page: " in line:
            who, url = line.split("'s page: ")
            out[who.removeprefix("hrc console: ")] = url.strip()
    assert set(out) == set(people) and all(f"&person={p}" in u for p, u in out.items())
    assert len({u.partition("?token=")[2].partition("&")[0] for u in out.values()} | {console.token}) == len(people) + 1
    return out


def _one_page_per_secret(console: ConsoleProcess, urls: dict[str, str]) -> None:
    """alice's secret opens alice's page, not bob's: a press as bob is out of her reach."""
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    alice = {"Authorization": f"Bearer {urls['alice'].partition('?token=')[2].partition('&')[0]}"}
    with pytest.raises(InvalidStatus, match="403"):
        connect(console.ws + "ws?person=bob", open_timeout=10, additional_headers=alice)
    with connect(console.ws + "ws?person=alice", open_timeout=10, additional_headers=alice) as c:
        assert json.loads(c.recv(timeout=10))["type"] == "setup"


def _replays(out_dir: Path, log: Path, outs: list[dict[str, Any]]) -> None:
    done = subprocess.run([sys.executable, "-m", "hrc", "dispatch", str(out_dir), "--replay", str(log)],
                          capture_output=True, text=True, timeout=120, cwd=ROOT,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert done.returncode == 0, done.stderr
    assert [json.loads(x) for x in done.stdout.splitlines()] == outs


def test_two_people_each_press_on_their_own_page_to_the_end_of_a_run(workers: Path, tmp_path: Path) -> None:
    console = ConsoleProcess(workers, tmp_path / "run.jsonl", "--speed", str(SPEED), "--simulate-robot")
    try:
        with chromium() as ctx:
            shared = ctx.new_page()
            requests = record_requests(shared)
            shared.goto(console.url)
            pages = {}
            urls = person_urls(console, ("alice", "bob"))
            _one_page_per_secret(console, urls)
            for person, url in urls.items():
                # each person's device: a browser of its own, with only that person's secret (its cookie)
                page = pages[person] = ctx.browser.new_context().new_page()
                page.goto(url)
            for page in (shared, *pages.values()):
                page.wait_for_function("() => window.hrcConsole && window.hrcConsole.state !== null "
                                       "&& window.hrcConsole.connected", timeout=15_000)
            assert [p.evaluate("() => window.hrcConsole.person") for p in pages.values()] == ["alice", "bob"]
            # the shared view: no buttons, a Gantt row and a disc per agent, and it may not press
            drawn = shared.evaluate("""() => ({person: window.hrcConsole.person,
                buttons: document.querySelectorAll('#buttons button.act').length,
                rows: [...document.querySelectorAll('#gantt .gantt-row')].map(e => e.dataset.agent),
                discs: [...document.querySelectorAll('#map circle.agent')].map(e => e.dataset.agent),
                robots: [...document.querySelectorAll('#robots .robot-row')].map(e => e.dataset.robot)})""")
            assert drawn == {"person": None, "buttons": 0, "rows": ["alice", "bob", "robot"],
                             "discs": ["alice", "bob", "robot"], "robots": ["robot"]}
            shared.evaluate("() => window.hrcConsole.ws.send(JSON.stringify({type: 'away', hseq: 0}))")
            shared.wait_for_function("() => !document.getElementById('error').hidden", timeout=15_000)
            assert "shared view" in shared.evaluate("() => document.getElementById('error-text').textContent")
            seen, pressed = _play(pages, workers, seed=3)
            colours = shared.evaluate("() => [...document.querySelectorAll('#gantt .gantt-row')]"
                                      ".map(e => e.getAttribute('fill'))")
            assert len(set(colours)) == 3  # one colour per agent
            assert requests and all(u.startswith(("http://127.0.0.1:", "ws://127.0.0.1:")) for u in requests)
        state = console.state()
    finally:
        console.stop()
    assert state["finished"] and all(s is None for s in state["decision"]["robots"].values())
    lines = console.log_lines()
    ins, outs = lines[0::2], lines[1::2]
    # the shared view's attempt reached no dispatcher; every press is in the log, as its person's, accepted
    presses = [m for m in ins if m.get("agent") in ("alice", "bob")]
    assert [(m["agent"], [m["action"], m["phase"], m["event"]]) for m in presses] == pressed
    assert {p for p, _ in pressed} == {"alice", "bob"}
    assert all(o["ok"] for o in outs), [o for o in outs if not o["ok"]]
    assert {m["agent"] for m in ins if m.get("agent") not in ("alice", "bob", None)} == {"robot"}
    # each page's buttons were that person's options in the dispatcher at that point of the run
    options = _options_after_each(workers, console.log, ("alice", "bob"))
    checked = 0
    for person, snap in seen:
        if not snap["finished"] and snap["connected"]:
            assert sorted(b[:3] for b in snap["buttons"]) == options[snap["seq"]][person], (person, snap)
            checked += 1
    assert checked > 20
    _replays(workers, console.log, outs)


@pytest.mark.slow  # ~30 s: a whole run; two_workers' run (the default) drives its robot the same way
def test_simulated_robots_drive_both_robots_of_a_team(kitting3: Path, tmp_path: Path) -> None:
    from mcap_check import read_mcap

    recording = tmp_path / "run.mcap"
    console = ConsoleProcess(kitting3, tmp_path / "run.jsonl", "--speed", str(SPEED), "--simulate-robot",
                             "--record", str(recording))
    try:
        with chromium() as ctx:
            page = ctx.new_page()
            page.goto(f"{console.url}&person=human")
            page.wait_for_function("() => window.hrcConsole && window.hrcConsole.state !== null "
                                   "&& window.hrcConsole.connected", timeout=15_000)
            rows = page.evaluate("() => [...document.querySelectorAll('#robots .robot-row')].map(e => e.dataset.robot)")
            assert rows == ["robot", "robot2"]
            _play({"human": page}, kitting3, seed=1)
        state = console.state()
    finally:
        console.stop()
    assert state["finished"] and state["robot_links"] == {"robot": "simulated", "robot2": "simulated"}
    lines = console.log_lines()
    ins, outs = lines[0::2], lines[1::2]
    assert all(o["ok"] for o in outs)
    ends = {(m["agent"], m["action"]) for m in ins if m.get("event") == "end"}
    assert {a for a, _ in ends} >= {"robot", "robot2"}  # both robots were driven (the seed's plan uses both)
    assert {act for _, act in ends} == {"pick_a", "pick_b", "pick_c"}
    _replays(kitting3, console.log, outs)
    # the console's recording: a goal channel per robot, each robot's own drives (tests/test_record_team.py)
    pose = ("foxglove.PoseInFrame", "protobuf", "protobuf")
    topics = {f"/hrc/{a}/pose": pose for a in ("human", "robot", "robot2")} | \
        {f"/hrc/{r}/goal": pose for r in ("robot", "robot2")}
    rec = read_mcap(recording, topics)
    departs = {r: sum(1 for m in ins if m.get("agent") == r and m.get("event") == "depart")
               for r in ("robot", "robot2")}
    # no waiting places on this floor: a goal per departure, then one home goal per robot (as hrc ros2 sends)
    assert {r: rec.counts.get(f"/hrc/{r}/goal", 0) for r in departs} == {r: n + 1 for r, n in departs.items()}
    assert len(rec.of("/hrc/out")) == len(outs)


def test_each_robot_controller_acknowledges_its_own_robot_only(kitting3: Path, tmp_path: Path) -> None:
    from websockets.exceptions import InvalidStatus
    from websockets.sync.client import connect

    console = ConsoleProcess(kitting3, tmp_path / "run.jsonl", "--speed", str(SPEED), "--tick", "0")
    try:
        ws, robot_auth, page_auth = console.ws, console.robot_headers(), console.page_headers()
        for path, expect in (("robot", "names its robot: /robot?robot=ID (robots: robot, robot2)"),
                             ("robot?robot=r9", "unknown robot 'r9' (robots: robot, robot2)"),
                             ("ws?person=zed", "unknown person 'zed' (people: human)")):
            with connect(ws + path, open_timeout=10,
                         additional_headers=robot_auth if path.startswith("robot") else page_auth) as c:
                reply = _recv(c)
                assert not reply["ok"] and expect in reply["error"], (path, reply)
        with pytest.raises(InvalidStatus, match="401"):  # only the robot's secret opens a controller
            connect(ws + "robot?robot=robot2", open_timeout=10, additional_headers=page_auth)
        # the person's own secret: their page and the read-only routes; no shared view, no robot
        own = person_urls(console, ("human",))["human"].partition("?token=")[2].partition("&")[0]
        mine = {"Authorization": f"Bearer {own}"}
        with connect(ws + "ws?person=human", open_timeout=10, additional_headers=mine) as c:
            assert _recv(c)["type"] == "setup"
        assert json.loads(console.get("state", token=own))["type"] == "state"
        for path, status in (("ws", "403"), ("robot?robot=robot", "401")):
            with pytest.raises(InvalidStatus, match=status):
                connect(ws + path, open_timeout=10, additional_headers=mine)
        with connect(ws + "robot?robot=robot", open_timeout=10, additional_headers=robot_auth) as r1, \
                connect(ws + "robot?robot=robot2", open_timeout=10, additional_headers=robot_auth) as r2:
            for r, name in ((r1, "robot"), (r2, "robot2")):
                hello = _recv(r)
                assert hello["type"] == "hello" and hello["robot"] == name, hello
            with connect(ws + "robot?robot=robot2", open_timeout=10, additional_headers=robot_auth) as again:
                assert "already connected" in _recv(again)["error"]
            state = console.state()
            assert state["robot_links"] == {"robot": "connected", "robot2": "connected"}
            steps = {r: s for r, s in state["decision"]["robots"].items() if s and "action" in s}
            assert steps, state["decision"]  # the best plan has some robot leave at once
            robot, step = sorted(steps.items())[0]
            other = "robot2" if robot == "robot" else "robot"
            event = {k: step[k] for k in ("action", "phase", "event")}
            sock, wrong = (r1, r2) if robot == "robot" else (r2, r1)
            seq, total = state["seq"], state["log_total"]
            for client, msg, expect in (
                    (wrong, {"type": "ack", "agent": robot, **event}, f"this controller is {other}'s"),
                    (sock, {"type": "ack", "robot": other, **event}, f"this controller is {robot}'s"),
                    (sock, {"type": "ack", "agent": "human", **event}, "cannot acknowledge for 'human'"),
                    (sock, {"type": "ack", "action": step["action"]}, "must be strings")):
                client.send(json.dumps(msg))
                reply = _drain_reply(client)
                assert not reply["ok"] and expect in reply["error"], reply
            after = console.state()
            assert after["seq"] == seq and after["decision"] == state["decision"]  # nothing changed
            assert after["log_total"] == total  # refused before the dispatcher: not even logged
            time.sleep(max(0.0, step["earliest"] - after["now"]) / SPEED + 0.05)
            sock.send(json.dumps({"type": "ack", "id": 3, **event}))
            reply = _drain_reply(sock)
            assert reply["ok"] and reply["id"] == 3, reply
            pushed = next(m for m in iter(lambda: _recv(wrong), None) if m["type"] == "decision")
            assert pushed["robot"] == other and pushed["decision"] == reply["decision"]
        last = console.log_lines()[-2]
        assert last == {"t": last["t"], "agent": robot, **event}
    finally:
        console.stop()


def _recv(ws: Any) -> dict[str, Any]:
    return json.loads(ws.recv(timeout=10))


def _drain_reply(ws: Any) -> dict[str, Any]:
    """The next reply on a controller's socket (decisions pushed meanwhile skipped)."""
    while True:
        msg = _recv(ws)
        if msg["type"] == "reply":
            return msg


@pytest.mark.slow  # ~15 s: two console processes
def test_a_team_run_resumes_with_each_persons_counter(workers: Path, tmp_path: Path) -> None:
    """Stopped after presses of both people, ``--resume`` shows the run where it was: the same seq, each
    person's counter and buttons, and a page drawn before the stop still presses (its counter is current)."""
    from websockets.sync.client import connect

    log = tmp_path / "run.jsonl"
    console = ConsoleProcess(workers, log, "--speed", str(SPEED), "--tick", "0")  # nothing moves but the presses
    try:
        for person in ("alice", "bob"):
            with connect(console.ws + f"ws?person={person}", open_timeout=10,
                         additional_headers=console.page_headers()) as c:
                _recv(c)
                state = _recv(c)
                option = state["persons"][person]["options"][0]
                c.send(json.dumps({"type": "press", "hseq": 0, **option}))
                reply = next(m for m in iter(lambda: _recv(c), None) if m["type"] == "reply")
                assert reply["ok"], reply
        before = console.state()
    finally:
        console.stop()
    assert [before["persons"][p]["hseq"] for p in ("alice", "bob")] == [1, 1]
    again = ConsoleProcess(workers, log, "--speed", str(SPEED), "--tick", "0", "--resume", str(log),
                           log_option=False)
    try:
        after = again.state()
        for key in ("seq", "hseq", "persons", "decision"):
            assert after[key] == before[key], key
        with connect(again.ws + "ws?person=bob", open_timeout=10, additional_headers=again.page_headers()) as c:
            _recv(c)
            option = _recv(c)["persons"]["bob"]["options"][0]
            c.send(json.dumps({"type": "press", "hseq": 1, **option}))
            reply = next(m for m in iter(lambda: _recv(c), None) if m["type"] == "reply")
            assert reply["ok"], reply
    finally:
        again.stop()
