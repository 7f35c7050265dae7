"""One console run: the one `hrc.dispatch.Dispatcher`, the run's clock and log, and what the page and
the robot controller may ask of them.

Every press of the person, every acknowledgement of the robot and every tick goes to the dispatcher
as one JSON line of the protocol `hrc dispatch` speaks, through a `hrc.dispatch.durable.LoggedDispatcher`:
the line and its answer are in the run's log (synced) before the state changes or anyone is told, so
that the log replays with ``hrc dispatch OUT_DIR --replay LOG`` and a crashed run resumes with
``hrc console OUT_DIR --resume LOG``. If the log cannot be written, the message is refused, nothing
changes, and the page says so (`ConsoleSession.log_error`). Messages from the page and the robot are
checked here first (size, nesting, shape, type, the page's view of the run being current) and a
message refused here or by the dispatcher changes nothing but the reply.

Memory is bounded: the page is shown the last `LOG_SHOWN` messages (the log file keeps all).

A team (issue 37: other than one person and one robot) is served per agent: each person's page is that
person's buttons (`page_message` with the person's id: their observations, their ``away``/``back``, an undo
of their own last observation only), each robot controller acknowledges for its own id only
(`robot_message` with the robot's id), and the state carries each person's buttons and counter
(``"persons"``) beside the shared view of every agent. An id not of the team is refused in one line and
changes nothing. One person and one robot are served exactly as before (the same lines into the log).
A joint action whose crew is a choice of the plan (`hrc.model.Action.crew_choice`) is offered to every
candidate the remaining plans may still have in its crew (`Dispatcher.human_options`); a candidate's press
keeps the plans whose crew has them, and the views draw it for the crew that came (`crews`).
With the motion detector (``--detect motion``) a team's tracker sends its positions on a robot
controller's link, each naming its person (``"agent": "alice"``, as ``hrc dispatch --detect motion``'s
protocol), to that person's own detector; one naming no one (but in a team of one person, as there), a
robot or an id not of the team is refused in one line and changes nothing. Each person's state has
their tracked position, belief and the last events their detector gave (``persons[P].detected``: their
page shows them).

The session is not thread-safe: the server calls it from its one event loop, which serializes the
messages of every tab and of the robot.
"""

from __future__ import annotations

import json
from collections import deque
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from hrc.console.clock import RunClock
from hrc.console.views import gantt_bars, map_view, under_way
from hrc.detect.online import MAX_METRES
from hrc.dispatch import Dispatcher, RobotStep
from hrc.dispatch.durable import LoggedDispatcher
from hrc.dispatch.limits import parse_message
from hrc.dispatch.logfile import Message
from hrc.dispatch.routes import PlanRoutes
from hrc.errors import LogWriteError, MessageError

__all__ = ["DETECTED_SHOWN", "LOG_SHOWN", "MAX_RUN_SECONDS", "PAGE_MESSAGES", "UNDO_WINDOW", "ConsoleSession", "Reply",
           "parse"]

# How long after a press of the person the page offers to undo it, in run seconds (the dispatcher
# itself accepts an undo within 10 s of the observation it withdraws).
UNDO_WINDOW = 8.0
# The page's messages and the keys each needs besides "type" and "hseq".
PAGE_MESSAGES: dict[str, tuple[str, ...]] = {"press": ("action", "phase", "event"), "away": (), "back": (),
                                             "undo": ()}
MAX_RUN_SECONDS = 1e9
"""A message's ``t`` (run seconds) beyond this is refused, as the dispatcher refuses it."""
LOG_SHOWN = 300
"""Log entries kept for the page (the file keeps all)."""
DETECTED_SHOWN = 12
"""A team's person's last events given by their motion detector, shown on their page."""


class Reply(dict[str, Any]):
    """The answer to one message: ``{"ok": True, ...}`` or ``{"ok": False, "error": "one line"}``."""

    @classmethod
    def error(cls, message: str) -> Reply:
        return cls(ok=False, error=message)


def parse(text: str | bytes | Mapping[str, Any]) -> dict[str, Any] | str:
    """The message as a JSON object (bounded: `hrc.dispatch.limits`), or why it is not one (a line for
    the page). A mapping is taken as already parsed."""
    if isinstance(text, Mapping):
        return dict(text)
    try:
        msg = parse_message(text)  # strict: a repeated key, NaN, 1e400 or a 310-digit number refused
    except MessageError as err:
        return f"malformed message ({err})"
    if not isinstance(msg, dict):
        return f"malformed message (a JSON object was expected, got {type(msg).__name__})"
    return msg


class ConsoleSession:
    """The state of one run as the console sees it.

    `hseq` counts the person's accepted messages: a page sends the `hseq` it has drawn with each press,
    and a press made on a page that has not yet shown the previous one (two tabs pressing at once) is
    refused, so that no one confirms what they have not seen. `seq` counts every accepted message (an
    answer marked ``unchanged`` accepted none).
    """

    def __init__(self, logged: LoggedDispatcher, compiled: Mapping[str, Any], routes: PlanRoutes,
                 clock: RunClock, robot_link: str = "none") -> None:
        self.logged = logged
        self.compiled = compiled
        self.routes = routes
        self.clock = clock
        self.robot_link = robot_link  # "simulated" | "connected" | "none"
        self.seq = 0
        self.hseq = 0
        self.total = 0  # messages that reached the dispatcher (and the log)
        self.entries: deque[dict[str, Any]] = deque(maxlen=LOG_SHOWN)
        self.log_error: str | None = None  # why the log could not be written, until it can again
        self.recording: Any = None  # an `hrc.record.Recording` fed by the log's listener (``--record``), or None
        self._phases = {(a.id, p.id) for a in logged.dispatcher.task.actions for p in a.phases}
        self._joint = {a.id: a.agents for a in logged.dispatcher.task.actions if a.joint}  # issue 37
        self._choice = tuple(a.id for a in logged.dispatcher.task.actions if a.crew_choice)  # crews to choose
        agents = logged.dispatcher.task.agents
        self.people = tuple(a.id for a in agents if a.is_human)
        self.robots = tuple(a.id for a in agents if not a.is_human)
        self.team = (len(self.people), len(self.robots)) != (1, 1)  # served per agent (issue 37)
        self.hseqs = dict.fromkeys(self.people, 0)  # a team's: each person's accepted messages
        self.robot_links = dict.fromkeys(self.robots, "none")  # a team's: each robot's link
        # with the motion detector, a team's: the events each person's detector gave (their page shows them)
        self.detected: dict[str, deque[dict[str, Any]]] = {p: deque(maxlen=DETECTED_SHOWN) for p in self.people}

    @property
    def dispatcher(self) -> Dispatcher:
        """The dispatcher's state as committed to the log."""
        return self.logged.dispatcher

    @property
    def log_path(self) -> Path | None:
        return self.logged.path

    def restore(self, messages: Iterable[Message]) -> None:
        """Count and show the messages of a resumed run's log (`LoggedDispatcher.resume` replayed them)."""
        for message in messages:
            line = message.data.decode("utf-8", "replace")
            try:
                obs = parse_message(line)  # the console's own lines; bounded all the same
            except (ValueError, MessageError):
                obs = {"raw": line[:200]}
            out = json.loads(message.answer)
            obs = obs if isinstance(obs, dict) else {"raw": line[:200]}
            self._record(obs, out, self._source(obs), obs.get("agent") if self.team else None)

    def _source(self, obs: Mapping[str, Any]) -> str:
        """Who sent a logged message: "tracker", "person", "robot" or "clock"."""
        agent = obs.get("agent")
        if obs.get("event") == "position":
            return "tracker"
        if not self.team:
            return ("person" if agent == "human" or obs.get("event") == "undo"
                    else "robot" if agent == "robot" else "clock")
        return ("person" if agent in self.people or obs.get("event") == "undo"
                else "robot" if agent in self.robots else "clock")

    # -- time -------------------------------------------------------------------------------------
    def now(self) -> float:
        """The run's time for a new message: never before the dispatcher's last accepted message."""
        return max(self.clock.now(), self.dispatcher.now)

    # -- the one way into the dispatcher ----------------------------------------------------------
    def _submit(self, message: dict[str, Any], source: str, person: str | None = None) -> Reply:
        line = json.dumps(message, separators=(",", ":"))  # ASCII: a lone surrogate stays escaped
        out_line = self.logged.take_line(line)
        try:
            self.logged.commit()  # in the log (synced if accepted) before the state changes
        except LogWriteError as err:
            self.log_error = str(err)
            return Reply.error(f"refused: {err}; nothing changed")
        self.log_error = None
        out = json.loads(out_line)
        self._record(message, out, source, person)
        if not out.get("ok"):
            return Reply.error(str(out.get("error", "refused by the dispatcher")))
        return Reply(ok=True, decision=out)

    def _record(self, message: dict[str, Any], out: dict[str, Any], source: str, person: Any = None) -> None:
        self.total += 1
        self.entries.append({"n": self.total, "source": source, "in": message, "out": out})
        detect = out.get("detect") if out.get("ok") and self.team else None
        if isinstance(detect, dict):  # a person's detector gave these (one person's answer names no one)
            who = str(detect.get("agent", self.people[0] if len(self.people) == 1 else ""))
            for ev in detect.get("events", ()) if who in self.detected else ():
                self.detected[who].append(ev)
        if out.get("ok") and not out.get("unchanged"):  # a redundant message is answered, changes nothing
            self.seq += 1
            if source == "person":
                self.hseq += 1
                if person in self.hseqs:
                    self.hseqs[person] += 1

    # -- the person (the page) --------------------------------------------------------------------
    def page_message(self, text: str | bytes | Mapping[str, Any], person: str | None = None) -> Reply:
        """A message from a page (see `PAGE_MESSAGES`); refused here when malformed or stale. `person`: a
        team's person whose page it is (their id; None: the shared view, which may not press); ignored for
        one person and one robot."""
        msg = parse(text)
        if isinstance(msg, str):
            return Reply.error(msg)
        if not self.team:
            return self._page(msg, "human", self.hseq)
        if person is None:
            return Reply.error("refused: this page is the shared view; a person presses on their own page "
                               "(the address hrc console printed for them)")
        if person not in self.hseqs:
            return Reply.error(f"refused: unknown person {str(person)[:40]!r} (people: {', '.join(self.people)})")
        return self._page(msg, person, self.hseqs[person])

    def _page(self, msg: dict[str, Any], person: str, hseq: int) -> Reply:
        """`person`'s page message (``"human"`` for one person and one robot), drawn at their `hseq`. A
        team's page presses for its own person only, and undoes only that person's last observation (issue
        37); the dispatcher withdraws the last one, whoever's it is."""
        kind = msg.get("type")
        if kind not in PAGE_MESSAGES:
            return Reply.error(f"unknown message type {kind!r} (expected one of {', '.join(PAGE_MESSAGES)})")
        missing = [k for k in ("hseq", *PAGE_MESSAGES[kind]) if k not in msg]
        if missing:
            return Reply.error(f"malformed {kind} message: missing {', '.join(missing)}")
        if self.team and "agent" in msg and msg["agent"] != person:
            return Reply.error(f"refused: this is {person}'s page; it cannot press for {str(msg['agent'])[:40]!r}")
        if msg["hseq"] != hseq:
            return Reply.error("refused: the run moved on since this page was drawn (another press); "
                               "look again and press again")
        if self.finished:
            return Reply.error("refused: the run is over")
        t = self.now()
        if kind == "press":
            fields = {k: msg[k] for k in PAGE_MESSAGES["press"]}
            if not all(isinstance(v, str) for v in fields.values()):
                return Reply.error("malformed press message: action, phase and event must be strings")
            obs: dict[str, Any] = {"t": t, "agent": person, **fields}
        elif kind == "undo":
            if self.team:
                last = next((o for o in reversed(self.dispatcher.history) if o.event != "tick"), None)
                if last is None or last.agent != person:
                    return Reply.error(f"refused: nothing of {person}'s to undo (the last observation is not theirs)")
            obs = {"t": t, "event": "undo"}
        else:
            obs = {"t": t, "agent": person, "event": kind}
        return self._submit(obs, "person", person if self.team else None)

    # -- the robot (its controller, or the simulated robot) ---------------------------------------
    def robot_message(self, text: str | bytes | Mapping[str, Any], source: str = "robot",
                      robot: str | None = None) -> Reply:
        """An acknowledgement ``{"type": "ack", "action", "phase", "event"[, "t"]}`` from the robot.

        ``t`` (run seconds, optional) is when the event happened; it may not lie in the future nor before
        the dispatcher's last accepted message. Without it the event happened now. With ``hrc console
        --detect motion`` the same stream also takes the person's tracked position, ``{"type":
        "position", "x", "y"[, "t"]}`` (`position_message`).

        `robot`: a team's robot whose controller sent it (its id); an ack naming another agent
        (``"robot"`` or ``"agent"``) is refused: a controller acknowledges its own robot's events only.
        """
        msg = parse(text)
        if isinstance(msg, str):
            return Reply.error(msg)
        agent = "robot"
        position = msg.get("type") == "position" or ("type" not in msg and msg.get("event") == "position")
        if self.team:
            if robot not in self.robot_links:
                return Reply.error(f"refused: unknown robot {str(robot)[:40]!r} (robots: {', '.join(self.robots)})")
            if position:  # the tracker's, on a controller's link: its "agent" names the person (issue 37)
                return self.position_message(msg)
            named = [msg[k] for k in ("robot", "agent") if k in msg]
            if any(n != robot for n in named):
                return Reply.error(f"refused: this controller is {robot}'s; it cannot acknowledge for "
                                   f"{str(next(n for n in named if n != robot))[:40]!r}")
            agent = robot
        if position:
            return self.position_message(msg)  # the console's shape, or the dispatcher protocol's
        if msg.get("type") != "ack":
            return Reply.error(f"unknown message type {msg.get('type')!r} (the robot sends only ack)")
        fields = {k: msg.get(k) for k in ("action", "phase", "event")}
        if not all(isinstance(v, str) for v in fields.values()):
            return Reply.error("malformed ack: action, phase and event must be strings")
        now = self.now()
        t = msg.get("t", now)
        # compared, never converted first: float() of a 310-digit integer overflows (issue 34)
        if isinstance(t, bool) or not isinstance(t, int | float) or not 0 <= t <= MAX_RUN_SECONDS:
            return Reply.error(f"malformed ack: t must be a number of run seconds (0 to {MAX_RUN_SECONDS:g})")
        if t > now:
            return Reply.error(f"refused: t = {t} lies in the future (the run's time is {now})")
        return self._submit({"t": round(float(t), 3), "agent": agent, **fields}, source)

    def position_message(self, msg: Mapping[str, Any]) -> Reply:
        """The person's tracked position ``{"type": "position", "x", "y"[, "t"]}``, or the dispatcher
        protocol's ``{"t", "agent": "human", "event": "position", "x", "y"}`` (metres in the map's frame;
        ``t``: run seconds when it was measured, not in the future; default now), for the motion detector
        in front of the dispatcher (docs/detect.md); refused when the console was started without
        ``--detect motion``."""
        if getattr(self.dispatcher, "answer_position", None) is None:
            return Reply.error("refused: a position needs the motion detector (hrc console --detect motion)")
        unknown = sorted(set(msg) - {"type", "id", "t", "x", "y", "agent", "event"})
        if unknown:
            return Reply.error(f"malformed position: unknown key {unknown[0][:40]!r} (keys: type, id, agent, t, x, y)")
        if not self.team:
            person = "human"
            if msg.get("agent", "human") != "human":
                return Reply.error("malformed position: a position is the human's")
        else:  # a team's names its person, as `hrc dispatch --detect motion`'s protocol (issue 37; as there,
            # a team of one person and several robots may leave it out)
            named = msg.get("agent", self.people[0] if len(self.people) == 1 else None)
            if named not in self.people:
                found = "nothing" if named is None else repr(str(named)[:40])
                return Reply.error(f"refused: a team's position names its person, \"agent\": one of "
                                   f"{', '.join(self.people)} (found {found}); nothing changed")
            person = str(named)
        now = self.now()
        t = msg.get("t", now)
        values = {"t": t, "x": msg.get("x"), "y": msg.get("y")}
        for key, value in values.items():
            bound = MAX_RUN_SECONDS if key == "t" else MAX_METRES  # compared, never converted first
            if isinstance(value, bool) or not isinstance(value, int | float) or not -bound <= value <= bound:
                return Reply.error(f"malformed position: {key} must be a finite number (within ±{bound:g})")
        if t > now:
            return Reply.error(f"refused: t = {t} lies in the future (the run's time is {now})")
        return self._submit({"t": round(float(t), 3), "agent": person, "event": "position",
                             "x": float(values["x"]), "y": float(values["y"])}, "tracker")

    def tick(self) -> Reply:
        """Tell the dispatcher that time passed with nothing seen."""
        return self._submit({"t": self.now(), "event": "tick"}, "clock")

    # -- what the page and the robot are shown ----------------------------------------------------
    @property
    def finished(self) -> bool:
        ended = {(o.action, o.phase) for o in self.dispatcher.history if o.event == "end"}
        return self._phases <= ended

    def robot_step(self, robot: str | None = None) -> RobotStep | None:
        """The robot's next step (a team's: `robot`'s), or None (it waits, or has nothing to do)."""
        decision = self.dispatcher.decision
        step = decision.robot if not self.team else (decision.robots or {}).get(robot or "")
        return step if isinstance(step, RobotStep) else None

    def setup(self) -> dict[str, Any]:
        """What does not change during a run (sent once per connection)."""
        task = self.dispatcher.task
        return {"type": "setup", "task": {"name": task.name, "deadline": task.deadline,
                                          "actions": {a.id: {"name": a.name,
                                                             "phases": {p.id: p.location for p in a.phases}}
                                                      for a in task.actions}},
                "map": map_view(task), "speed": self.clock.speed, "undo_window": UNDO_WINDOW,
                "log_file": str(self.log_path)} | ({"team": {"people": list(self.people), "robots": list(self.robots)}}
                                                   if self.team else {})

    def _undo(self, now: float, person: str | None = None) -> dict[str, Any] | None:
        if person is None:
            last = next((o for o in reversed(self.dispatcher.history) if o.agent == "human"), None)
        else:  # a team's person: their own observation, when it is the last one (what an undo withdraws)
            last = next((o for o in reversed(self.dispatcher.history) if o.event != "tick"), None)
            last = last if last is not None and last.agent == person else None
        if last is None or now - last.t > UNDO_WINDOW:
            return None
        what = " ".join(x for x in (last.event, last.action, last.phase) if x)
        return {"until": round(last.t + UNDO_WINDOW, 3), "what": what}

    def state(self) -> dict[str, Any]:
        """The whole view of the run now (sent after every change, and on every (re)connection)."""
        d = self.dispatcher
        now = self.now()
        decision = d.decision.to_json()
        best = d.best
        plan = decision.get("plan")
        if self.team:
            return self._team_state(now, decision, plan)
        return {
            "type": "state", "seq": self.seq, "hseq": self.hseq, "now": now, "finished": self.finished,
            "decision": decision,
            "options": [{"action": o.action, "phase": o.phase, "event": o.event} for o in d.human_options()],
            "under_way": [list(x) for x in under_way(d.history, "human", self.crews())],
            "undo": self._undo(now),
            "best": None if best is None else {"plan": best.plan, "class": best.plan_class,
                                               "makespan": best.makespan, "sequences": dict(best.sequences)},
            "gantt": gantt_bars(d.planned_times(plan) if plan else {}, d.history, now, self.crews()),
            "routes": self.routes.routes(plan),
            "log": list(self.entries), "log_total": self.total, "log_error": self.log_error,
            "robot_link": self.robot_link, "where": self._where(), **self._tracked(),
        }

    def _team_state(self, now: float, decision: dict[str, Any], plan: str | None) -> dict[str, Any]:
        """A team's view (issue 37): the shared view of every agent, and per person their buttons, what
        they have under way, their undo and their counter (``"persons"``); per robot its link."""
        d = self.dispatcher
        best = d.best
        joint = self.crews()
        persons = {p: {"hseq": self.hseqs[p],
                       "options": [{"action": o.action, "phase": o.phase, "event": o.event}
                                   for o in d.human_options(p)],
                       "under_way": [list(x) for x in under_way(d.history, p, joint)],
                       "undo": self._undo(now, p), **self._tracked(p)} for p in self.people}
        return {
            "type": "state", "seq": self.seq, "hseq": self.hseq, "now": now, "finished": self.finished,
            "decision": decision, "persons": persons,
            "best": None if best is None else {"plan": best.plan, "class": best.plan_class,
                                               "makespan": best.makespan, "sequences": dict(best.sequences)},
            "gantt": gantt_bars(d.planned_times(plan) if plan else {}, d.history, now, joint),
            "routes": self.routes.routes(plan),
            "log": list(self.entries), "log_total": self.total, "log_error": self.log_error,
            "robot_link": self.robot_link, "robot_links": dict(self.robot_links), "where": self._where(),
        }

    def crews(self) -> dict[str, tuple[str, ...]]:
        """Each joint action's crew as the run has it now (issue 37): its agents when the task fixes them;
        when its crew is a choice of the plan (`hrc.model.Action.crew_choice`), the crew of the plan
        followed (the best remaining one, `hrc.model.Task.crew`) and every agent seen on it (a press by a
        candidate keeps only the plans whose crew has them, so the two agree once someone has joined)."""
        if not self._choice:
            return self._joint
        d = self.dispatcher
        best = d.best
        sequences = best.sequences if best is not None else {}
        seen = {(o.agent, o.action) for o in d.history if o.agent and o.action}
        out = dict(self._joint)
        for action in self._choice:
            out[action] = tuple(ag for ag in self._joint[action]
                                if action in sequences.get(ag, ()) or (ag, action) in seen)
        return out

    def lead(self, action: str) -> str | None:
        """Who starts and ends joint `action` in the run now: the first robot of its crew (`crews`; task
        order, as `hrc.model.Task.lead`), or None when the action is not joint or its crew has no robot."""
        return self.dispatcher.task.crew_lead(self.crews().get(action, ()))

    def _tracked(self, person: str | None = None) -> dict[str, Any]:
        """With the motion detector: the person's (a team's `person`'s) last tracked position and the
        detector's belief; a team's person also the events their detector gave (``detected``, the last
        `DETECTED_SHOWN`, oldest first)."""
        tracks = getattr(self.dispatcher, "tracks", None)
        if tracks is None:
            return {}
        track = tracks[person] if person is not None else self.dispatcher.track  # type: ignore[attr-defined]
        last = track.samples[-1] if track.samples else None
        shown = {"tracked": None if last is None else {"t": last[0], "x": round(last[1], 3), "y": round(last[2], 3)},
                 "belief": track.belief.to_json()}
        return shown if person is None else {**shown, "detected": list(self.detected[person])}

    def _where(self) -> dict[str, str]:
        """Each agent's last known location: its start, or where it last arrived or worked."""
        task = self.dispatcher.task
        at = {a.id: a.start for a in task.agents}
        for o in self.dispatcher.history:
            if o.agent in at and o.action and o.phase and o.event in ("arrive", "start", "end"):
                at[o.agent] = task.action(o.action).phase(o.phase).location
        return at
