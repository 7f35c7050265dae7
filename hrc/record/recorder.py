"""A run into an MCAP file that Foxglove opens: the floor, the agents, their routes, every message and
answer, the robot's window and goal, the plan and its class over time (channels: `hrc.record`).

`RunRecorder` is fed what a dispatcher was given and what it answered, one exchange at a time
(`exchange`, the bytes of the message and the answer's line, as the log keeps them), and, in a
simulation, the agents' measured positions (`positions`). Everything it writes follows from those and
the task: no clock is read, times are the run's (seconds from the task's start, written as nanoseconds
from the epoch, so Foxglove shows the task's start as 1970-01-01 00:00:00 UTC), and the MCAP writer
(Foxglove's SDK, zstd chunks compressed on the calling thread) adds nothing else: the same exchanges give
the same bytes, so a live run's recording equals the one made from its log (``hrc dispatch --replay LOG
--record FILE``).

Each robot's goal is its next drive (`hrc.ros2.drive.next_drive`) and, once its part is done, its way home
(`hrc.ros2.drive.home_drive`, read off the robots' observations that stand): what ``hrc ros2`` sends.

A team (issue 37: other than one person and one robot) has a pose channel per agent (``/hrc/ID/pose``)
and a goal channel per robot (``/hrc/ROBOT/goal``, its entry of the answers' ``robots``: `scene.goal_topic`);
``/hrc/decision`` then names each robot's step (``robots``) and ``/hrc/agents`` labels each robot with its own.

Where the agents are: in a simulation, where the floor had them (`positions`, at most every
`FRAME_PERIOD` run seconds); otherwise where they were last seen (`Places`: an agent is put at a phase's
location when it arrives, starts or ends there, at its waiting place when it parks, and stays where it
was while it drives: a dispatcher is told events, not positions).

`Recording` puts a recorder into a new file (`hrc.io.atomic.AtomicFile`: it takes its name only when
closed, so that a recording is whole or absent) and keeps a failure to write it (a full disk) from the
run: it stops recording, says so once, and the run goes on (its log is the record; the recording can
be made again from it). `open_folder_recording` is what ``hrc dispatch``, ``hrc console`` and ``hrc
ros2`` call.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
from collections.abc import Callable, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any, BinaryIO

import foxglove
from foxglove.channels import LogChannel, PoseInFrameChannel, SceneUpdateChannel
from foxglove.mcap import MCAPCompression, MCAPWriteOptions
from foxglove.messages import Log, LogLevel

from hrc import __version__
from hrc.dispatch.limits import parse_message
from hrc.dispatch.messages import Observation
from hrc.errors import MessageError
from hrc.io.atomic import AtomicFile
from hrc.io.task_file import task_digest
from hrc.model import Task
from hrc.record import scene
from hrc.ros2.drive import Ways, home_drive, next_drive

__all__ = ["CLASS_RANK", "FORMATS", "FRAME_PERIOD", "Places", "Recording", "RunRecorder", "Routes", "check_new",
           "open_folder_recording"]

Routes = Callable[[str], Mapping[str, Sequence[Mapping[str, Any]]]]
"""A plan's legs per agent by plan id (`hrc.dispatch.routes.PlanRoutes.routes`)."""

FRAME_PERIOD = 0.1
"""Run seconds: measured positions are written at most this often (and the last one of a run)."""
CLASS_RANK = {"DC": 2, "consistent": 1, "inconsistent": 0}
"""``/hrc/decision``'s ``class_rank`` (-1: no plan), so that a plot shows the class over time."""
_SHOWN = 1000  # characters of a message that is not a JSON object kept in /hrc/in

_OBJECT = {"type": "object"}
SCHEMAS: dict[str, dict[str, Any]] = {
    "hrc.Message": {"title": "a message given to the dispatcher (docs/dispatch.md), or the text of one that "
                             "is not a JSON object", "type": "object",
                    "properties": {"t": {"type": "number"}, "agent": {"type": "string"},
                                   "action": {"type": "string"}, "phase": {"type": "string"},
                                   "event": {"type": "string"}, "next": {"type": "string"},
                                   "text": {"type": "string"}}},
    "hrc.Answer": {"title": "the dispatcher's answer, as given out (docs/dispatch.md)", "type": "object",
                   "properties": {"t": {"type": ["number", "null"]}, "ok": {"type": "boolean"},
                                  "plan": {"type": ["string", "null"]}, "class": {"type": ["string", "null"]},
                                  "candidates": _OBJECT, "robot": {"type": ["object", "null"]},
                                  "human": {"type": ["object", "null"]}, "human_away": {"type": "boolean"},
                                  "stopped": {"type": "boolean"}, "ack": _OBJECT, "error": {"type": "string"}}},
    "hrc.Decision": {"title": "the best plan, its class and the robot's next step after an accepted message",
                     "type": "object",
                     "properties": {"t": {"type": "number"}, "plan": {"type": ["string", "null"]},
                                    "class": {"type": ["string", "null"]},
                                    "class_rank": {"type": "integer", "description": "2 DC, 1 consistent, "
                                                                                     "0 inconsistent, -1 none"},
                                    "candidates": {"type": "object",
                                                   "properties": {k: {"type": "integer"} for k in CLASS_RANK}},
                                    "robot": {"type": "string", "description": "the robot's next step in words"},
                                    "earliest": {"type": ["number", "null"]}, "latest": {"type": ["number", "null"]},
                                    "human_away": {"type": "boolean"}, "stopped": {"type": "boolean"}}},
}


def _dumps(obj: Any) -> bytes:
    return json.dumps(obj, ensure_ascii=False, separators=(",", ":"), allow_nan=False).encode("utf-8")


def _step_words(step: Any) -> str:
    if step is None:
        return "nothing left"
    if "wait_for" in step:
        return f"wait for {step['wait_for']}"
    latest = "open" if step.get("latest") is None else f"{step['latest']:g}"
    return f"{step['event']} {step['action']}.{step['phase']} in [{step['earliest']:g}, {latest}] s"


class Places:
    """Where each agent was last seen, from the observations that stand (see the module docstring).

    `see(obs)` takes an accepted message (a decoded JSON object); an ``undo`` withdraws the person's last
    observation, as the dispatcher does. `where` and `doing` then say where each agent is and what it is
    at; `present` whether it is on the floor (the person may be away).
    """

    def __init__(self, task: Task, park: Callable[[str, str, str], str | None], team: bool = False) -> None:
        self.task = task
        self.park = park  # (agent, action, phase) -> the leg's waiting place in the current plan, or None
        self.human = next(a.id for a in task.agents if a.is_human)
        # a team's undo withdraws the last observation, some person's (or an away/back of theirs)
        self.undone = {a.id for a in task.agents if a.is_human} | {None} if team else {self.human}
        self.kept: list[Mapping[str, Any]] = []
        self._fold()

    def see(self, obs: Mapping[str, Any]) -> None:
        if obs.get("event") == "undo":
            for k in range(len(self.kept) - 1, -1, -1):
                if self.kept[k].get("agent") in self.undone:
                    del self.kept[k]
                    break
        elif obs.get("event") != "tick":
            self.kept.append(obs)
        self._fold()

    def _fold(self) -> None:
        ws = self.task.workspace
        self.where = {a.id: ws.location(a.start).xy for a in self.task.agents}
        self.doing = {a.id: f"at {a.start}" for a in self.task.agents}
        self.present = {a.id: True for a in self.task.agents}
        for o in self.kept:
            agent, event = str(o.get("agent", "")), o.get("event")
            if agent not in self.where:
                continue
            if event in ("away", "back"):
                self.present[agent] = event == "back"
                self.doing[agent] = "away" if event == "away" else "back"
                continue
            action, phase = str(o.get("action")), str(o.get("phase"))
            try:
                location = self.task.action(action).phase(phase).location
            except KeyError:
                continue
            if event == "park":
                place = self.park(agent, action, phase)
                if place is not None:
                    self.where[agent] = ws.location(place).xy
                self.doing[agent] = f"waiting at {place or '?'} ({action}.{phase})"
            elif event in ("depart", "unpark"):
                self.doing[agent] = f"-> {location} ({action}.{phase})"
            else:
                self.where[agent] = ws.location(location).xy
                self.doing[agent] = {"arrive": f"at {location} ({action}.{phase})", "start": f"{action}.{phase}",
                                     "end": f"done {action}.{phase}"}[str(event)]


class _FoxgloveOut:
    """The writing end of `RunRecorder` in Foxglove's well-known schemas (`hrc.record.scene`) and JSON
    (`SCHEMAS`), by Foxglove's SDK; `hrc.record.ros2msg.Ros2Out` is the ROS 2 one, with the same calls."""

    def __init__(self, sink: BinaryIO, task: Task) -> None:
        self.task = task
        ctx = self._context = foxglove.Context()
        # zstd on this thread (0 worker threads): the same bytes whatever the machine
        options = MCAPWriteOptions(compression=MCAPCompression.Zstd, compression_threads=0)
        self._writer = foxglove.open_mcap(sink, context=ctx, writer_options=options)
        self._map = SceneUpdateChannel("/hrc/map", context=ctx)
        self._routes = SceneUpdateChannel("/hrc/routes", context=ctx)
        self._agents = SceneUpdateChannel("/hrc/agents", context=ctx)
        self._pose = {a.id: PoseInFrameChannel(scene.pose_topic(task, a.id), context=ctx) for a in task.agents}
        robots = scene.team_robots(task)  # a team's robots: a goal channel each (issue 37)
        self._goals: dict[str | None, PoseInFrameChannel] = \
            {r: PoseInFrameChannel(scene.goal_topic(r), context=ctx) for r in robots} if robots else \
            {None: PoseInFrameChannel(scene.goal_topic(), context=ctx)}
        self._in = self._json("/hrc/in", "hrc.Message")
        self._out = self._json("/hrc/out", "hrc.Answer")
        self._decision = self._json("/hrc/decision", "hrc.Decision")
        self._log = LogChannel("/hrc/log", context=ctx)

    def _json(self, topic: str, name: str) -> Any:
        schema = foxglove.Schema(name=name, encoding="jsonschema", data=_dumps(SCHEMAS[name]))
        return foxglove.Channel(topic, schema=schema, message_encoding="json", context=self._context)

    def metadata(self, info: Mapping[str, str]) -> None:
        self._writer.write_metadata("hrc", dict(info))

    def map(self) -> None:
        self._map.log(scene.map_update(self.task), log_time=0)

    def message(self, data: bytes, ns: int) -> None:
        self._in.log(data, log_time=ns)

    def answer(self, data: bytes, ns: int) -> None:
        self._out.log(data, log_time=ns)

    def log(self, t: float, ok: bool, text: str, name: str, ns: int) -> None:
        self._log.log(Log(timestamp=scene.stamp(t), level=LogLevel.Info if ok else LogLevel.Warning, message=text,
                          name=name), log_time=ns)

    def decision(self, data: bytes, ns: int) -> None:
        self._decision.log(data, log_time=ns)

    def routes(self, t: float, legs: Mapping[str, Sequence[Mapping[str, Any]]], ns: int) -> None:
        self._routes.log(scene.routes_update(self.task, t, legs), log_time=ns)

    def pose(self, agent: str, t: float, x: float, y: float, ns: int) -> None:
        self._pose[agent].log(scene.pose_in_frame(t, x, y), log_time=ns)

    def goal(self, t: float, x: float, y: float, heading: float, ns: int, robot: str | None = None) -> None:
        self._goals[robot].log(scene.pose_in_frame(t, x, y, heading), log_time=ns)

    def agents(self, t: float, where: Mapping[str, tuple[float, float]], labels: Mapping[str, str],
               present: Mapping[str, bool], ns: int) -> None:
        self._agents.log(scene.agents_update(self.task, t, where, labels, present), log_time=ns)

    def close(self) -> None:
        self._writer.close()


FORMATS = ("foxglove", "ros2")
"""Recording formats (``--record-format``): Foxglove's schemas (the default), or ROS 2 message types
(`hrc.record.ros2msg`: ``ros2 bag`` and RViz read it; Foxglove reads both)."""


class RunRecorder:
    """Writes one run to `sink` as MCAP (see the module docstring; channels: `hrc.record`).

    `routes` gives a plan's legs by plan id (None: no routes drawn, goals at the phases' locations);
    `ways` the planned way between two locations (`hrc.dispatch.routes.PlanRoutes.way`: the heading of a
    robot's home goal, as ``hrc ros2`` sends it; None: heading 0); `measured`: positions come from
    `positions` (a simulation), not from the observations. `metadata` goes into the file's ``hrc``
    metadata record beside the generator and the task's name. `fmt`: one of `FORMATS`. Call `finish` at
    the end (it writes MCAP's summary; the sink is left open).
    """

    def __init__(self, sink: BinaryIO, task: Task, routes: Routes | None = None, *, measured: bool = False,
                 metadata: Mapping[str, str] | None = None, fmt: str = "foxglove", ways: Ways | None = None) -> None:
        self.task = task
        self.routes = routes
        self.ways = ways
        self.measured = measured
        self.human = next(a.id for a in task.agents if a.is_human)
        self.robot = next(a.id for a in task.agents if not a.is_human)
        self.team = scene.team_robots(task)  # a team's robots (issue 37), () for one of each
        self.goals: dict[str, tuple[str, str, str]] = {}  # a team's robot -> its last drive
        if fmt == "ros2":
            from hrc.record.ros2msg import Ros2Out

            self._sink: _FoxgloveOut | Ros2Out = Ros2Out(sink, task)
        elif fmt == "foxglove":
            self._sink = _FoxgloveOut(sink, task)
        else:
            raise ValueError(f"unknown recording format {fmt!r} (expected one of {', '.join(FORMATS)})")
        info = {"generator": f"hrc {__version__}", "task": task.name, **(metadata or {})}
        self._sink.metadata({k: str(v) for k, v in sorted(info.items())})
        self.t = 0.0
        self.plan: str | None = None
        self.answer: Mapping[str, Any] = {}
        self.goal: tuple[str, str, str] | None = None
        self.places = Places(task, self._park, bool(self.team))
        self.where = dict(self.places.where)
        self.present = dict(self.places.present)
        self.frame_t: float | None = None
        self.exchanges = 0
        self._sink.map()
        self._draw_agents()

    def _ns(self) -> int:
        return round(self.t * 1e9)

    def _legs(self) -> Mapping[str, Sequence[Mapping[str, Any]]]:
        return self.routes(self.plan) if self.routes is not None and self.plan is not None else {}

    def _park(self, agent: str, action: str, phase: str) -> str | None:
        leg = next((lg for lg in self._legs().get(agent, ()) if (lg["action"], lg["phase"]) == (action, phase)), None)
        return None if leg is None or not leg.get("park") else str(leg["park"])

    def _advance(self, t: Any) -> None:
        """The run's time moves to `t` when it is a later number (messages refused as early keep it)."""
        if not isinstance(t, bool) and isinstance(t, int | float) and math.isfinite(t) and t > self.t:
            self.t = float(t)

    # -- what is fed in ----------------------------------------------------------------------------
    def exchange(self, data: bytes, answer: str) -> None:
        """One message (its bytes, as received) and the answer given to it."""
        try:
            obs = parse_message(data.decode("utf-8"))
        except (UnicodeDecodeError, ValueError, MessageError):
            obs = None
        out = json.loads(answer)
        self._advance(out.get("t") if out.get("t") is not None else obs.get("t") if isinstance(obs, dict) else None)
        ns = self._ns()
        text = data.decode("utf-8", "replace")
        self._sink.message(data if isinstance(obs, dict) else _dumps({"text": text[:_SHOWN]}), ns)
        self._sink.answer(answer.encode("utf-8"), ns)
        self._sink.log(self.t, True, text[:_SHOWN], "in", ns)
        self._sink.log(self.t, bool(out.get("ok")), answer, "out", ns)
        self.exchanges += 1
        if not out.get("ok"):
            return
        self.answer = out
        cls = out.get("class")
        robot = out.get("robot")
        window = robot if isinstance(robot, dict) and "earliest" in robot else {}
        if self.team:  # each robot's step by id (issue 37); the first robot's window for a plot
            steps = out.get("robots") or {}
            robot = steps.get(self.robot)
            window = robot if isinstance(robot, dict) and "earliest" in robot else {}
            self._sink.decision(_dumps({"t": self.t, "plan": out.get("plan"), "class": cls,
                                       "class_rank": CLASS_RANK.get(str(cls), -1),
                                       "candidates": out.get("candidates", {}), "robot": _step_words(robot),
                                       "earliest": window.get("earliest"), "latest": window.get("latest"),
                                       "robots": {r: _step_words(steps.get(r)) for r in self.team},
                                       "human_away": bool(out.get("away")), "away": list(out.get("away") or []),
                                       "stopped": bool(out.get("stopped"))}), ns)
        else:
            self._sink.decision(_dumps({"t": self.t, "plan": out.get("plan"), "class": cls,
                                       "class_rank": CLASS_RANK.get(str(cls), -1),
                                       "candidates": out.get("candidates", {}), "robot": _step_words(robot),
                                       "earliest": window.get("earliest"), "latest": window.get("latest"),
                                       "human_away": bool(out.get("human_away")), "stopped": bool(out.get("stopped"))}),
                                ns)
        if out.get("plan") != self.plan:
            self.plan = out.get("plan")
            self._sink.routes(self.t, self._legs(), ns)
        if isinstance(obs, dict):
            self.places.see(obs)
        if not self.measured:
            self.where, self.present = dict(self.places.where), dict(self.places.present)
            for agent, (x, y) in self.where.items():
                self._sink.pose(agent, self.t, x, y, ns)
        self._draw_agents()
        # each robot's drive, and once its part is done its way home (`home_drive`), as `hrc ros2` sends them
        history = self._robot_history()
        for r in self.team:  # a team: each robot's drive on its own channel
            drive = next_drive(self.task, out, self._legs(), r) or home_drive(self.task, out, history, r, self.ways)
            if drive is not None and drive.leg != self.goals.get(r):
                self.goals[r] = drive.leg
                self._sink.goal(self.t, *drive.target, drive.heading, ns, r)
        if self.team:
            return
        drive = next_drive(self.task, out, self._legs()) or home_drive(self.task, out, history, None, self.ways)
        if drive is not None and drive.leg != self.goal:
            self.goal = drive.leg
            self._sink.goal(self.t, *drive.target, drive.heading, ns)

    def _robot_history(self) -> list[Observation]:
        """The robots' observations that stand (`Places.kept`), as the dispatcher's history has them: what
        `home_drive` reads (a robot's last event)."""
        robots = {a.id for a in self.task.agents if not a.is_human}
        out = []
        for o in self.places.kept:
            if o.get("agent") in robots and isinstance(o.get("action"), str) and isinstance(o.get("phase"), str):
                t = o.get("t")
                out.append(Observation(float(t) if isinstance(t, int | float) else self.t, str(o.get("event")),
                                       str(o["agent"]), str(o["action"]), str(o["phase"])))
        return out

    def positions(self, t: float, where: Mapping[str, tuple[float, float]], present: Mapping[str, bool],
                  last: bool = False) -> None:
        """The agents' measured positions at `t` (a simulation's floor): written when `FRAME_PERIOD` has
        passed since the last ones written, or when `last`."""
        if self.frame_t is not None and t - self.frame_t < FRAME_PERIOD - 1e-9 and not last:
            return
        self.frame_t = t
        self._advance(t)
        self.where, self.present = dict(where), dict(present)
        ns = self._ns()
        for agent, (x, y) in self.where.items():
            self._sink.pose(agent, self.t, x, y, ns)
        self._draw_agents()

    def _draw_agents(self) -> None:
        labels = {a: f"{a}: {self.places.doing.get(a, '')}" for a in self.where}
        robot = self.answer.get("robot", None) if self.answer else None
        if self.answer and self.team:
            for r in self.team:
                labels[r] += f"\nnext: {_step_words((self.answer.get('robots') or {}).get(r))}"
        elif self.answer:
            labels[self.robot] += f"\nnext: {_step_words(robot)}"
        self._sink.agents(self.t, self.where, labels, self.present, self._ns())

    def finish(self) -> None:
        """Write MCAP's summary and end the file (the sink stays open)."""
        self._sink.close()


class Recording:
    """A `RunRecorder` into the new file `path` (`AtomicFile`: under its name only once `close`d).

    `listener(data, answer)` is what a `hrc.dispatch.durable.LoggedDispatcher` calls after each commit;
    it never raises: a failure to record (a full disk, a bug) stops the recording, is said once through
    `report`, and leaves the run alone. Raises `FileExistsError` / `IsADirectoryError` at once when
    `path` is taken.
    """

    def __init__(self, path: str | os.PathLike[str], task: Task, routes: Routes | None = None, *,
                 report: Callable[[str], None] | None = None, **options: Any) -> None:
        self.file = AtomicFile(path)
        self.report = report
        self.error: str | None = None
        for stale in self.file.cleaned:
            if report is not None:
                report(f"removed {stale.name}: the unfinished recording of a run that was killed")
        try:
            self.recorder = RunRecorder(self.file.file, task, routes, **options)
        except BaseException:
            self.file.discard()
            raise

    @property
    def path(self) -> Path:
        return self.file.path

    def _failed(self, err: BaseException) -> None:
        self.error = " ".join(str(err).split()) if not isinstance(err, OSError) else (err.strerror or str(err))
        if self.report is not None:
            self.report(f"{self.path}: cannot record ({self.error}): recording stopped; the run goes on "
                        "(its log can be recorded again with hrc dispatch --replay LOG --record FILE)")

    def listener(self, data: bytes, answer: str) -> None:
        if self.error is not None:
            return
        try:
            self.recorder.exchange(data, answer)
        except Exception as err:  # noqa: BLE001 - a recording must never end the run it records
            self._failed(err)

    def feed(self, exchanges: Iterable[tuple[bytes, str]]) -> None:
        """Several exchanges (a resumed run's replayed ones)."""
        for data, answer in exchanges:
            self.listener(data, answer)

    def close(self) -> Path | None:
        """End the file and give it its name; the path, or None when the recording had failed (then
        nothing is left behind)."""
        if self.error is not None:
            self.file.discard()
            return None
        try:
            self.recorder.finish()
            return self.file.commit()
        except Exception as err:  # noqa: BLE001 - the SDK raises RuntimeError for the file's I/O errors
            self.file.discard()
            self._failed(err)
            return None

    def abort(self) -> None:
        """Drop the recording (nothing is left behind)."""
        with contextlib.suppress(Exception):  # the writer ends before its file goes (else it ends later, loudly)
            self.recorder.finish()
        self.file.discard()


def check_new(path: str | os.PathLike[str]) -> None:
    """Raise `FileExistsError` / `IsADirectoryError` at once when `path` is taken (before any work)."""
    AtomicFile.check(path)


def open_folder_recording(path: str | os.PathLike[str], out_dir: str | os.PathLike[str], dispatcher: Any,
                          report: Callable[[str], None] | None = None, routes: Routes | None = None,
                          fmt: str = "foxglove", ways: Ways | None = None) -> Recording:
    """A recording of a run of the dispatcher on the compiled folder `out_dir`. `routes`: the plans' routes
    (default: the ones the console draws, `hrc.dispatch.routes.PlanRoutes`: free-space paths planned again
    with the compile's seed, about 2 s for the workshop; detours from ``compiled.json``). The same run
    gives the same bytes whichever command records it (``hrc dispatch``, ``hrc console``, ``hrc ros2``).
    `fmt`: one of `FORMATS`. `ways`: the planned way between two locations (the heading of a robot's home
    goal; default with the default `routes`: theirs, `PlanRoutes.way`)."""
    check_new(path)
    if routes is None:
        from hrc.compile.output import read_header
        from hrc.dispatch.routes import PlanRoutes, plan_motions
        from hrc.motion import plan_paths

        compiled = read_header(out_dir)
        planned = PlanRoutes(plan_motions(out_dir, dispatcher.plan_set),
                             plan_paths(dispatcher.task, seed=int(compiled.get("seed", 0))))
        routes, ways = planned.routes, ways or planned.way
    return Recording(path, dispatcher.task, routes, report=report, ways=ways,
                     metadata={"compiled": dispatcher.plan_set.digest, "plans": str(len(dispatcher.plan_set)),
                               "task_digest": task_digest(dispatcher.task)},  # checked by `hrc learn`
                     fmt=fmt)
