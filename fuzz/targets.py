"""The fuzz targets (issue 34, item 6): every parser and protocol entry point of hrc, driven by atheris
(coverage-guided, libFuzzer) through its public functions, and the four C cores through theirs.

Each target is a function of one input (bytes) that feeds it to one entry point and checks the
contract: only the project's own errors (`hrc.errors.HrcError` and its children) may escape, never
anything else (a ``KeyError``, a ``RecursionError``, an ``OverflowError`` is a crash), and where the
entry point promises an answer (a dispatch line, a console frame) it returns one, well formed. The time
per input is bounded by the runner (libFuzzer's ``-timeout``): a hang is a crash too. The native
targets also compare the C core with the Python implementation of the same definition (a differential
oracle): the verdict of an STNU, the answers of a dispatcher.

`TARGETS` is the registry (name -> target); ``scripts/fuzz.py`` runs them, `setup` prepares what a
target needs once per process (a compiled folder, a console session). No target writes outside the
temporary folder `setup` makes.
"""

from __future__ import annotations

import contextlib
import functools
import json
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
COMPILED_VARIABLE = "HRC_FUZZ_COMPILED"
"""The environment variable naming the compiled workshop folder the protocol targets dispatch on."""
TEAM_VARIABLE = "HRC_FUZZ_TEAM"
CREW_VARIABLE = "HRC_FUZZ_CREW"
"""The environment variable naming a compiled team folder (two people, one robot: ``tasks/two_workers.yaml``)."""

_STATE: dict[str, Any] = {}


def _scratch() -> Path:
    if "scratch" not in _STATE:
        # under the runner's work folder (removed when the run ends), or the system's temporary folder
        _STATE["scratch"] = Path(tempfile.mkdtemp(prefix="hrc-fuzz-", dir=os.environ.get("HRC_FUZZ_SCRATCH")))
    return Path(_STATE["scratch"])


def _write(name: str, data: bytes) -> Path:
    path = _scratch() / name
    path.write_bytes(data)
    return path


def _text(data: bytes) -> str | None:
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return None


# --- files ------------------------------------------------------------------------------------------

def task_yaml(data: bytes) -> None:
    """`hrc.io.task_file.load_task` on the input as a task file, beside the workshop's map and DXF."""
    from hrc.errors import HrcError
    from hrc.io.task_file import load_task

    folder = _scratch()
    for name in ("workshop.yaml", "floorplan.dxf"):
        if not (folder / name).exists():
            shutil.copy(ROOT / "maps" / name, folder / name)
    with contextlib.suppress(HrcError):
        load_task(_write("task.yaml", data))


def map_yaml(data: bytes) -> None:
    """`hrc.io.map_file.load_workspace` on the input as a map file (its floor plan the bundled DXF)."""
    from hrc.errors import HrcError
    from hrc.io.map_file import load_workspace

    folder = _scratch()
    if not (folder / "floorplan.dxf").exists():
        shutil.copy(ROOT / "maps" / "floorplan.dxf", folder / "floorplan.dxf")
    with contextlib.suppress(HrcError):
        load_workspace(_write("map.yaml", data))


def dxf(data: bytes) -> None:
    """A map whose floor plan is the input (a DXF file), through `load_workspace`."""
    from hrc.errors import HrcError
    from hrc.io.map_file import load_workspace

    _write("fuzzed.dxf", data)
    map_file = _write("dxfmap.yaml", b"name: fuzz\nbounds: [0, 0, 40, 30]\nfloorplan: fuzzed.dxf\n"
                                     b"locations:\n  A: [1, 1]\n")
    with contextlib.suppress(HrcError):
        load_workspace(map_file)


def stnu_text(data: bytes) -> None:
    """`hrc.temporal.stnu_text.read_stnu_text` (the CSTNU Tool's text format)."""
    from hrc.errors import HrcError
    from hrc.temporal.stnu_text import read_stnu_text

    text = _text(data)
    if text is not None:
        with contextlib.suppress(HrcError):
            read_stnu_text(text)


def graphml(data: bytes) -> None:
    """`hrc.temporal.graphml.read_graphml` (the CSTNU Tool's GraphML, what the compile writes)."""
    from hrc.errors import HrcError
    from hrc.temporal.graphml import read_graphml

    with contextlib.suppress(HrcError):
        read_graphml(data)


def heatlab(data: bytes) -> None:
    """`hrc.temporal.heatlab.read_heatlab` (HEATlab's JSON STNUs)."""
    from hrc.errors import HrcError
    from hrc.temporal.heatlab import read_heatlab

    text = _text(data)
    if text is not None:
        with contextlib.suppress(HrcError):
            read_heatlab(text)


def network_file(data: bytes) -> None:
    """`hrc.temporal.graphml.read_network` on a file (what ``hrc check`` reads: the format detected)."""
    from hrc.errors import HrcError
    from hrc.temporal.graphml import read_network

    with contextlib.suppress(HrcError):
        read_network(_write("net.stnu", data))


def apa(data: bytes) -> None:
    """`hrc.apa.io.parse_stpp` (APA's STPP JSON files)."""
    from hrc.apa.io import parse_stpp
    from hrc.errors import HrcError

    text = _text(data)
    if text is not None:
        with contextlib.suppress(HrcError):
            parse_stpp(text)


# --- protocols --------------------------------------------------------------------------------------

def _plan_set(variable: str = COMPILED_VARIABLE) -> Any:
    if (variable, "plan_set") not in _STATE:
        from hrc.dispatch.plan_set import load_plan_set

        folder = os.environ.get(variable)
        if not folder:
            raise SystemExit(f"{variable} must name a compiled folder (scripts/fuzz.py sets it)")
        _STATE[variable, "plan_set"] = load_plan_set(folder)
    return _STATE[variable, "plan_set"]


def _lines(data: bytes, most: int = 24) -> list[bytes]:
    return data.split(b"\n")[:most]


def _answer_ok(answer: Any) -> None:
    assert isinstance(answer, str) and "\n" not in answer, answer
    obj = json.loads(answer)
    assert isinstance(obj, dict) and isinstance(obj.get("ok"), bool), answer


def dispatch_lines(data: bytes) -> None:
    """`hrc.dispatch.protocol.answer` on each line of the input, in order, on a fresh dispatcher of the
    compiled workshop: it never raises, and every answer is one JSON object with ``ok``."""
    from hrc.dispatch import Dispatcher
    from hrc.dispatch.protocol import answer

    d = Dispatcher(_plan_set())
    for line in _lines(data):
        _answer_ok(answer(d, line))


def console_frames(data: bytes) -> None:
    """The console's frames (`hrc.console.session.parse`, ``page_message``, ``robot_message``) on a session
    of the compiled workshop (unlogged): each line of the input a frame, to the page and the robot in
    turn; each gets a `Reply`, never an exception. A fresh session every 500 inputs."""
    from hrc.console.session import Reply, parse

    session = _console()
    for k, line in enumerate(_lines(data, 12)):
        parse(line)
        reply = (session.page_message if k % 2 == 0 else session.robot_message)(line)
        assert isinstance(reply, Reply), reply


def _console(variable: str = COMPILED_VARIABLE) -> Any:
    """A console session (unlogged) of the compiled folder `variable` names; a fresh one every 500 uses."""
    count = _STATE[f"{variable}_uses"] = _STATE.get(f"{variable}_uses", 0) + 1
    if (variable, "console") not in _STATE or count % 500 == 0:
        from hrc.compile.output import read_header
        from hrc.console.clock import RunClock
        from hrc.console.session import ConsoleSession
        from hrc.dispatch import Dispatcher
        from hrc.dispatch.durable import LoggedDispatcher
        from hrc.dispatch.routes import PlanRoutes, plan_motions
        from hrc.motion import plan_paths

        plan_set = _plan_set(variable)
        folder = os.environ[variable]
        header = read_header(folder)
        if (variable, "paths") not in _STATE:
            _STATE[variable, "paths"] = plan_paths(plan_set.task, seed=int(header.get("seed", 0)))
        routes = PlanRoutes(plan_motions(folder, plan_set), _STATE[variable, "paths"])
        _STATE[variable, "console"] = ConsoleSession(LoggedDispatcher(Dispatcher(plan_set)), header, routes,
                                                     RunClock(1.0))
    return _STATE[variable, "console"]


def team_frames(data: bytes) -> None:
    """A team's console (issue 37: two people, one robot) and its dispatcher, one frame per line of the
    input: in turn to alice's page, bob's page, the shared view, the robot's controller and the
    dispatcher's protocol. Each gets a `Reply` (or a well-formed answer), never an exception, and a frame
    refused changes nothing the dispatcher holds: its history, its answer."""
    from hrc.console.session import Reply

    session = _console(TEAM_VARIABLE)
    people, robots = session.people, session.robots
    senders: list[Callable[[bytes], Any]] = [
        *(functools.partial(session.page_message, person=p) for p in people), session.page_message,
        *(functools.partial(session.robot_message, robot=r) for r in robots),
        session.logged.submit]
    for k, line in enumerate(_lines(data, 12)):
        d = session.dispatcher
        before = (len(d.history), d.decision.to_json())
        reply = senders[k % len(senders)](line)
        if isinstance(reply, str):
            _answer_ok(reply)
            ok = json.loads(reply)["ok"]
        else:
            assert isinstance(reply, Reply), reply
            ok = reply["ok"]
        if not ok:
            assert (len(d.history), d.decision.to_json()) == before, line


def dispatch_log(data: bytes) -> None:
    """`hrc.dispatch.logfile.read_log` on the input as a log file, then (a log it reads) the check of its
    header and the replay against the compiled workshop (`hrc.dispatch.protocol.replay`)."""
    from hrc.dispatch import Dispatcher
    from hrc.dispatch.logfile import read_log
    from hrc.dispatch.protocol import replay
    from hrc.errors import HrcError

    try:
        contents = read_log(_write("run.jsonl", data))
        for got, _logged in replay(Dispatcher(_plan_set()), contents):
            _answer_ok(got)
    except HrcError:
        pass


def detect_trace(data: bytes) -> None:
    """`hrc.detect.trace.read_line` on each line (a tracker's positions); the lines it reads fed to the
    motion detector on the compiled workshop (`hrc.detect.trace.detect_lines`)."""
    from hrc.detect import DetectingDispatcher
    from hrc.detect.trace import Refusal, detect_lines, read_line
    from hrc.errors import DispatchError

    lines = _lines(data, 40)
    for line in lines:
        with contextlib.suppress(DispatchError):
            read_line(line)
    if "detector" not in _STATE:
        _STATE["detector"] = DetectingDispatcher(_plan_set())
    d = _STATE["detector"].__class__(_plan_set())
    for out in detect_lines(d, lines):
        assert isinstance(out, dict | Refusal), out


# --- the C cores, through their Python entry points ---------------------------------------------------

def _network(data: bytes) -> Any:
    """A random STNU from the input: 2-9 timepoints, requirement links with bounds in [-60, 60], up to
    three contingent links (distinct contingent timepoints), as `atheris.FuzzedDataProvider` reads it."""
    import atheris

    from hrc.temporal.network import STNU, ContingentLink, RequirementLink

    fdp = atheris.FuzzedDataProvider(data)
    n = fdp.ConsumeIntInRange(2, 9)
    names = tuple(f"t{i}" for i in range(n))
    conts = []
    used = set()
    for _ in range(fdp.ConsumeIntInRange(0, 3)):
        a, c = fdp.ConsumeIntInRange(0, n - 1), fdp.ConsumeIntInRange(1, n - 1)
        if a == c or c in used or a in used:
            continue
        used.add(c)
        lo = fdp.ConsumeIntInRange(0, 30)
        conts.append(ContingentLink(names[a], names[c], lo, lo + fdp.ConsumeIntInRange(0, 30)))
    reqs = []
    for _ in range(fdp.ConsumeIntInRange(0, 16)):
        a, b = fdp.ConsumeIntInRange(0, n - 1), fdp.ConsumeIntInRange(0, n - 1)
        if a == b:
            continue
        lo = fdp.ConsumeIntInRange(-60, 60)
        hi = lo + fdp.ConsumeIntInRange(0, 60) if fdp.ConsumeBool() else None
        reqs.append(RequirementLink(names[a], names[b], lo if fdp.ConsumeBool() else None, hi))
    return STNU(names, tuple(reqs), tuple(conts))


def rul_verdict(data: bytes) -> None:
    """`hrc.temporal.rul.rul2021_check` on a random STNU: the C core's verdict (``_rulcore.c``) equals the
    Python implementation's, and (a second opinion) Morris 2014's (`hrc.temporal.dc.check_dc`)."""
    from hrc.errors import HrcError
    from hrc.temporal.dc import check_dc
    from hrc.temporal.rul import rul2021_check

    try:
        stnu = _network(data)
    except HrcError:
        return
    native = rul2021_check(stnu)[0]
    python = rul2021_check(stnu, accelerated=False)[0]
    assert native == python, (native, python, stnu)
    assert check_dc(stnu, "morris2014").verdict.value == native, stnu


def stn_distances(data: bytes) -> None:
    """`hrc.temporal.native_stn.native_distances` and ``native_apsp`` (``_stncore.c``) on a random distance
    graph (edges ``u -> v`` of weight w; no self-loops): a negative cycle exactly when Bellman-Ford finds
    one, else the same distances (to a virtual node every node reaches by a 0 edge; all pairs)."""
    import atheris
    import numpy as np

    from hrc.temporal.native_stn import native_apsp, native_distances

    fdp = atheris.FuzzedDataProvider(data)
    n = fdp.ConsumeIntInRange(1, 10)
    edges = []
    for _ in range(fdp.ConsumeIntInRange(0, 30)):
        u, v = fdp.ConsumeIntInRange(0, n - 1), fdp.ConsumeIntInRange(0, n - 1)
        if u != v:
            edges.append((u, v, fdp.ConsumeIntInRange(-50, 100)))
    src, dst, wt = [e[0] for e in edges], [e[1] for e in edges], [e[2] for e in edges]
    if fdp.ConsumeBool():  # an end outside 0..n-1 is refused before the core reads anything
        bad = fdp.ConsumeIntInRange(-3, n + 3)
        if not 0 <= bad < n:
            at = fdp.ConsumeIntInRange(0, len(src))
            (src if fdp.ConsumeBool() else dst).insert(at, bad)
            (dst if len(dst) < len(src) else src).insert(at, 0)
            wt.insert(at, 1)
            for call in (lambda: native_distances(n, src, dst, wt, None), lambda: native_apsp(n, src, dst, wt)):
                try:
                    got = call()
                except ValueError:
                    continue
                assert got is None, (src, dst)  # only without the native core
            return
    inf = float("inf")
    table = [[0.0 if i == j else inf for j in range(n)] for i in range(n)]  # Floyd-Warshall: the truth
    for u, v, w in edges:
        table[u][v] = min(table[u][v], w)
    for k in range(n):
        for i in range(n):
            for j in range(n):
                table[i][j] = min(table[i][j], table[i][k] + table[k][j])
    negative = any(table[i][i] < 0 for i in range(n))
    got = native_distances(n, src, dst, wt, None)
    if got is not None:
        assert got[0] == (not negative), (got, edges)
        if got[0]:
            assert got[1] == [int(min(0.0, *row)) for row in table], (got, table)
    full = native_apsp(n, src, dst, wt)
    if full is not None:
        assert full[0] == (not negative), (full, edges)
        if full[0]:
            assert np.asarray(full[1]).tolist() == table, (full, table)


def dispatch_history(data: bytes) -> None:
    """Random histories of a run on the compiled workshop (``_dispatchcore.c``): each step the input
    picks one of the events the person may report now, the robot's next step, a tick or a refusal, and
    a time; a dispatcher with the C core and one without (the Python definitions, `hrc.dispatch.fastnet`)
    give the same answer to every message."""
    import atheris

    from hrc.dispatch import Dispatcher
    from hrc.dispatch.protocol import answer
    from hrc.dispatch.ranking import Ranker

    plan_set = _plan_set()
    fast = Dispatcher(plan_set)
    ranker = Ranker(plan_set, 1)
    ranker.native = None
    slow = Dispatcher(plan_set, ranker=ranker)
    fdp = atheris.FuzzedDataProvider(data)
    t = 0.0
    for _ in range(fdp.ConsumeIntInRange(1, 30)):
        t += fdp.ConsumeIntInRange(0, 4000) / 100
        options = fast.human_options()
        robot = fast.decision.to_json().get("robot") or {}
        pick = fdp.ConsumeIntInRange(0, len(options) + 2)
        if pick < len(options):
            o = options[pick]
            msg: dict[str, Any] = {"t": t, "agent": "human", "action": o.action, "phase": o.phase, "event": o.event}
        elif pick == len(options) and "action" in robot:
            msg = {"t": t, "agent": "robot", **{k: robot[k] for k in ("action", "phase", "event")}}
        elif pick == len(options) + 1:
            msg = {"t": t, "event": "tick"}
        else:
            msg = {"t": t, "agent": "human", "event": "away"} if fdp.ConsumeBool() else {"t": -t, "event": "tick"}
        line = json.dumps(msg).encode()
        a, b = answer(fast, line), answer(slow, line)
        _answer_ok(a)
        assert a == b, (msg, a, b)


def team_messages(d: Any, person: str, t: float) -> list[dict[str, Any]]:
    """What a random team history may send `d` at `t` (`crew_history`, tests/test_dispatch_parity.py): an
    event `person` may report now (`human_options`), each robot's step, a tick, `person` away, back."""
    robots = d.decision.to_json().get("robots") or {}
    return [*({"t": t, "agent": person, "action": o.action, "phase": o.phase, "event": o.event}
              for o in d.human_options(person)),
            *({"t": t, "agent": r, **{k: s[k] for k in ("action", "phase", "event")}}
              for r, s in sorted(robots.items()) if isinstance(s, dict) and "action" in s),
            {"t": t, "event": "tick"}, {"t": t, "agent": person, "event": "away"},
            {"t": t, "agent": person, "event": "back"}]


def crew_history(data: bytes) -> None:
    """Random histories of a team whose joint action's crew is a choice of the plan (issue 37,
    ``tasks/two_workers_joint.yaml``: either worker lifts with the robot), under a sensing path the input
    picks (on time; a detector's estimates within 0.15 or 0.4 s, `bound_tolerance`; buttons up to 0.5 s
    late): each step an event some person may report now (`human_options`), a robot's step, a tick, an
    away, a back or a refused line, at a time that never or sometimes goes back. A dispatcher with the C
    core and one without (the Python readings) give the same answer to every message: the readings of an
    estimate after the message's time among them (`Dispatcher._estimates`; they once differed there)."""
    import atheris

    from hrc.dispatch import Dispatcher
    from hrc.dispatch.protocol import answer
    from hrc.dispatch.ranking import Ranker

    plan_set = _plan_set(CREW_VARIABLE)
    fdp = atheris.FuzzedDataProvider(data)
    sensing = fdp.ConsumeIntInRange(0, 3)
    options: dict[str, Any] = ({"bound_tolerance": (0.15, 0.4)[sensing - 1]} if sensing in (1, 2)
                               else {"max_observation_delay": 0.5} if sensing == 3 else {})
    fast = Dispatcher(plan_set, **options)
    ranker = Ranker(plan_set, 1)
    ranker.native = None
    slow = Dispatcher(plan_set, ranker=ranker, **options)
    people = [a.id for a in plan_set.task.agents if a.is_human]
    t = 0.0
    for _ in range(fdp.ConsumeIntInRange(1, 30)):
        t += fdp.ConsumeIntInRange(0, 4000) / 100
        person = people[fdp.ConsumeIntInRange(0, len(people) - 1)]
        messages = [*team_messages(fast, person, t), {"t": -t, "event": "tick"}]  # the last one refused
        msg = messages[fdp.ConsumeIntInRange(0, len(messages) - 1)]
        line = json.dumps(msg).encode()
        a, b = answer(fast, line), answer(slow, line)
        _answer_ok(a)
        assert a == b, (options, msg, a, b)


def pattern_search(data: bytes) -> None:
    """Motion acquisition's search over passing orders (``_patterncore.c``, through
    `hrc.compile.motion_pattern.choose_pattern`) on a random variant of the workshop: the input picks a
    plan, every phase's durations for both agents (0-30 s, widths 0-30 s), the reading (``human_waits``,
    ``rank_by``); the search in C and the search in Python choose the same passing orders and class."""
    import dataclasses

    import atheris

    import hrc.compile.motion_pattern as mp
    from hrc.model import Interval

    if "workshop" not in _STATE:
        from hrc.io.task_file import load_task
        from hrc.motion import plan_paths
        from hrc.plans import generate_plans

        task = load_task(ROOT / "tasks" / "cube_stacking.yaml")
        _STATE["workshop"] = (task, list(generate_plans(task)), plan_paths(task, seed=0))
    task, plans, paths = _STATE["workshop"]
    fdp = atheris.FuzzedDataProvider(data)
    plan = plans[fdp.ConsumeIntInRange(0, len(plans) - 1)]
    human_waits, rank_by = fdp.ConsumeBool(), ("worst", "earliest")[fdp.ConsumeIntInRange(0, 1)]

    def durations(phase: Any) -> Any:
        out = []
        for agent, _ in phase.durations:
            lo = fdp.ConsumeIntInRange(0, 60) / 2
            out.append((agent, Interval(lo, lo + fdp.ConsumeIntInRange(0, 60) / 2)))
        return dataclasses.replace(phase, durations=tuple(out))

    actions = tuple(dataclasses.replace(a, phases=tuple(durations(ph) for ph in a.phases)) for a in task.actions)
    variant = dataclasses.replace(task, actions=actions)
    native = mp.choose_pattern(variant, plan, paths, human_waits, rank_by)
    kept, mp._NATIVE = mp._NATIVE, None
    try:
        python = mp.choose_pattern(variant, plan, paths, human_waits, rank_by)
    finally:
        mp._NATIVE = kept
    assert native.pattern.orders == python.pattern.orders, (plan, native.pattern, python.pattern)
    assert native.classification == python.classification, (plan, native.classification, python.classification)


TARGETS: dict[str, Callable[[bytes], None]] = {
    "task_yaml": task_yaml,
    "map_yaml": map_yaml,
    "dxf": dxf,
    "stnu_text": stnu_text,
    "graphml": graphml,
    "heatlab": heatlab,
    "network_file": network_file,
    "apa": apa,
    "dispatch_lines": dispatch_lines,
    "console_frames": console_frames,
    "team_frames": team_frames,
    "dispatch_log": dispatch_log,
    "detect_trace": detect_trace,
    "rul_verdict": rul_verdict,
    "stn_distances": stn_distances,
    "dispatch_history": dispatch_history,
    "crew_history": crew_history,
    "pattern_search": pattern_search,
}
"""Every target, by name (the corpus of target NAME is ``fuzz/corpus/NAME/``)."""

NATIVE = ("rul_verdict", "stn_distances", "dispatch_history", "crew_history", "pattern_search")
"""The targets that drive the C cores (run again with the sanitizer build: ``scripts/fuzz.py --sanitize``)."""

COMPILED = ("dispatch_lines", "console_frames", "dispatch_log", "detect_trace", "dispatch_history")
"""The targets that need the compiled workshop (`COMPILED_VARIABLE`)."""

TEAM = ("team_frames",)
"""The targets that need a compiled team (`TEAM_VARIABLE`)."""

CREW = ("crew_history",)
"""The targets that need a compiled team with a crew choice (`CREW_VARIABLE`)."""
