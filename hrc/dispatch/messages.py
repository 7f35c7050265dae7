"""What the dispatcher is told and what it answers: observations, decisions, and their JSON shapes.

An `Observation` is one thing seen at time ``t`` (seconds from the task's start): an agent's event on a
phase of an action (``depart``, ``park``, ``unpark``, ``arrive``, ``start``, ``end``; the robot's are its
controller's acknowledgements, the human's come from a human action detector), the human leaving
(``away``) or coming back (``back``), time passing with nothing seen (``tick``), or the withdrawal of the
last human observation (``undo``). A `Decision` tells the robot its next step (`RobotStep`: an event
and the window ``[earliest, latest]`` in which to do it), or to wait for a named event of the human
(`WaitFor`), or nothing (None: its part is done, or the dispatcher has stopped). docs/dispatch.md
describes the JSON-lines protocol these shapes make.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from hrc.errors import DispatchError

__all__ = ["EVENTS", "LEG_EVENTS", "SIGNALS", "Ahead", "Candidate", "Decision", "HumanOption", "Observation",
           "RobotStep", "WaitFor", "ack_note", "observation_from_json"]

LEG_EVENTS = ("depart", "park", "unpark", "arrive", "start", "end")
"""An agent's events on one leg, in the order they happen (park/unpark only where the plan stops at a
waiting place on the way; depart, park, unpark and arrive may go unreported)."""
SIGNALS = ("away", "back", "tick", "undo")
EVENTS = LEG_EVENTS + SIGNALS

_MAX_T = 1e9  # seconds; ~31 years: beyond it a time is a mistake, and ticks stay exact integers


@dataclass(frozen=True, slots=True)
class Observation:
    """Something seen at `t` seconds: a leg event of `agent` on `action`.`phase`, or a signal (then only
    `agent` may be set: the human for away/back). `next`: the human's announced next action. `delay`:
    how many seconds after the event happened it was learnt (a sensing path that says so: a detector's
    back-dated event, a late button), None when not said; an observation of the human later than the
    dispatcher's stated maximum voids the guarantee (`Decision.deviation`)."""

    t: float
    event: str
    agent: str | None = None
    action: str | None = None
    phase: str | None = None
    next: str | None = None
    delay: float | None = None

    @property
    def key(self) -> tuple[str, str, str, str]:
        """``(agent, action, phase, event)`` of a leg event."""
        return (self.agent or "", self.action or "", self.phase or "", self.event)

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"t": self.t}
        for name in ("agent", "action", "phase"):
            value = getattr(self, name)
            if value is not None:
                out[name] = value
        out["event"] = self.event
        if self.next is not None:
            out["next"] = self.next
        if self.delay is not None:
            out["delay"] = self.delay
        return out


@dataclass(frozen=True, slots=True)
class RobotStep:
    """Do `event` of `action`.`phase` at a time in ``[earliest, latest]`` (seconds; latest None: no bound).
    (Also the shape of the human's hint in `Decision.human`.) `separation`: the speed and separation
    limits the plan assumed of the robot's safety controller (`hrc.motion.separation.limits`; a task
    with `safety:` only)."""

    action: str
    phase: str
    event: str
    earliest: float
    latest: float | None
    separation: Mapping[str, float] | None = None

    def to_json(self) -> dict[str, Any]:
        out = {"action": self.action, "phase": self.phase, "event": self.event, "earliest": self.earliest,
               "latest": self.latest}
        if self.separation is not None:
            out["separation"] = dict(self.separation)
        return out


@dataclass(frozen=True, slots=True)
class WaitFor:
    """Wait until `agent`'s `event` of `action`.`phase` has been seen (``str``: ``human.cube2.put.end``)."""

    agent: str
    action: str
    phase: str
    event: str

    def __str__(self) -> str:
        return f"{self.agent}.{self.action}.{self.phase}.{self.event}"

    def to_json(self) -> dict[str, Any]:
        return {"wait_for": str(self)}


@dataclass(frozen=True, slots=True)
class Ahead:
    """The person's instruction for their next step, given while a walk or a manipulation of theirs is
    under way (when `Decision.human` has nothing to say yet): after `after` (their event now due, e.g.
    ``human.cube3.fetch.end``), their next step is `next` (e.g. ``human.cube3.put.depart``), not before
    the robot's `wait_for` (e.g. ``robot.cube2.fetch.end``; None: nothing of the robot's to wait for) and
    `gap` seconds after it (0 when there is nothing to wait for)."""

    after: str
    next: str
    wait_for: str | None
    gap: float = 0.0

    def to_json(self) -> dict[str, Any]:
        return {"after": self.after, "next": self.next, "wait_for": self.wait_for, "gap": self.gap}


@dataclass(frozen=True, slots=True)
class Decision:
    """The dispatcher's answer at `t`: the best plan and its class, the number of candidate plans per
    class, and the robot's next step (None: nothing left for it, or `stopped`). `human_away`: the human
    has left and the candidates are the plans in which the robot finishes alone. `stopped`: no plan is
    left that the dispatcher may follow (only with ``feasible_only``). `human`: a hint, the human's next
    departure or start in the best plan and the window in which it keeps the plan's promise (the paper's
    model lets the robot's strategy time them: the human waits when asked), or the robot event it has to
    wait for; None while the human is busy (a walk or a manipulation under way), away, or done.
    `ack`: set when the message was a robot acknowledgement outside what it had been told (`ack_note`).
    `deviation`: set when the message voided the guarantee of every class: ``{"late": {"event", "delay",
    "max"}}``, an observation of the human learnt later than the stated maximum delay (the run goes on with
    the best remaining plan, as after an overrun). `ahead`: the person's instruction for the step after
    the one under way (`Ahead`), so that they know it before it is due. `fallback`: no plan agrees with
    what was seen (the person left every compiled plan) and the robot's step is the safe fallback
    (`hrc.dispatch.fallback`): ``"continue"`` its leg under way, or ``"wait"`` (robot None) while plans that
    extend the history are compiled (`hrc.dispatch.on_demand`).

    A team (issue 37: other than one person and one robot) is answered per agent: `robots` names each
    robot's next step by its id, `people` each person's hint, `aheads` the instruction ahead of each person
    under way; `robot`, `human` and `ahead` are then the first robot's and the first person's (what the
    sensing paths read); `away` names the people away (`human_away`: some person is). For one person and
    one robot the three are None and the JSON is as it always was."""

    t: float
    plan: str | None
    plan_class: str | None
    candidates: Mapping[str, int]
    robot: RobotStep | WaitFor | None
    human_away: bool = False
    stopped: bool = False
    human: RobotStep | WaitFor | None = None
    ack: Mapping[str, Any] | None = None
    deviation: Mapping[str, Any] | None = None
    ahead: Ahead | None = None
    fallback: str | None = None
    robots: Mapping[str, RobotStep | WaitFor | None] | None = None
    people: Mapping[str, RobotStep | WaitFor | None] | None = None
    aheads: Mapping[str, Ahead] | None = None
    away: tuple[str, ...] = ()  # a team's: the people away, in task order

    def to_json(self) -> dict[str, Any]:
        if self.robots is not None:
            return self._team_json()
        out = {"t": self.t, "ok": True, "plan": self.plan, "class": self.plan_class,
               "candidates": dict(self.candidates),
               "robot": None if self.robot is None else self.robot.to_json(),
               "human": None if self.human is None else self.human.to_json(),
               "human_away": self.human_away, "stopped": self.stopped}
        if self.ack is not None:
            out["ack"] = dict(self.ack)
        if self.ahead is not None:
            out["ahead"] = self.ahead.to_json()
        return self._tail(out)

    def _team_json(self) -> dict[str, Any]:
        """A team's answer (docs/dispatch.md, "Teams"): each robot's step and each person's hint by id."""
        out: dict[str, Any] = {"t": self.t, "ok": True, "plan": self.plan, "class": self.plan_class,
                               "candidates": dict(self.candidates),
                               "robots": {r: _json(s) for r, s in (self.robots or {}).items()},
                               "people": {h: _json(s) for h, s in (self.people or {}).items()},
                               "away": list(self.away), "stopped": self.stopped}
        if self.ack is not None:
            out["ack"] = dict(self.ack)
        if self.aheads:
            out["ahead"] = {h: a.to_json() for h, a in self.aheads.items()}
        return self._tail(out)

    def _tail(self, out: dict[str, Any]) -> dict[str, Any]:
        if self.deviation is not None:
            out["deviation"] = {k: dict(v) if isinstance(v, Mapping) else v for k, v in self.deviation.items()}
        if self.fallback is not None:
            out["fallback"] = self.fallback
        return out


def _json(step: RobotStep | WaitFor | None) -> dict[str, Any] | None:
    return None if step is None else step.to_json()


def ack_note(told: RobotStep | WaitFor | None, obs: Observation) -> Mapping[str, Any] | None:
    """How a robot acknowledgement `obs` stands to what the robot had been told (`told`, the decision's
    robot step when it came), or None when it is what it was told, in its window.

    The policy (docs/dispatch.md): an acknowledgement says the event happened, so it is accepted however
    it stands (refusing a fact would leave the dispatcher's picture wrong and keep telling the robot to do
    what it has done); the set is re-ranked from what happened, so the class says what it cost; and the
    answer says so: ``{"early": s, "window": [earliest, latest]}`` (this many seconds before its window
    opened), ``{"late": s, "window": [...]}`` (after it closed), or ``{"unasked": true, "told": ...}``
    (the robot was told to wait, or to do another event, or nothing)."""
    step = (obs.action, obs.phase, obs.event)
    if isinstance(told, RobotStep) and (told.action, told.phase, told.event) == step:
        window = [told.earliest, told.latest]
        t = round(obs.t, 3)
        if t < told.earliest:
            return {"early": round(told.earliest - t, 3), "window": window}
        if told.latest is not None and t > told.latest:
            return {"late": round(t - told.latest, 3), "window": window}
        return None
    return {"unasked": True, "told": None if told is None else told.to_json()}


@dataclass(frozen=True, slots=True)
class Candidate:
    """A plan still in the set, as ranked now: its class given what was seen, its remaining makespan
    (seconds from the task's start to its last end, as the compile's ``rank_by`` reads durations; None
    when it has no schedule), total idle time of both agents, APA preference value (None: none)."""

    plan: str
    plan_class: str
    makespan: float | None
    idle: float
    preference: float | None
    allocation: Mapping[str, str] = field(default_factory=dict)
    sequences: Mapping[str, tuple[str, ...]] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class HumanOption:
    """An event the human may report now that some remaining plan allows (a console button)."""

    action: str
    phase: str
    event: str


def _text(obj: Mapping[str, Any], key: str) -> str | None:
    value = obj.get(key)
    if value is None:
        return None
    if not isinstance(value, str) or not value or len(value) > 200:
        raise DispatchError(f"{key!r} must be a non-empty string of at most 200 characters")
    return value


def observation_from_json(obj: Any) -> Observation:
    """An `Observation` from a decoded JSON message; `DispatchError` saying what is wrong in one line.

    Checks only the message's shape (types, known event names, a finite time); whether the task and the
    remaining plans allow it is the dispatcher's to say.
    """
    if not isinstance(obj, dict):
        raise DispatchError(f"a message must be a JSON object, found {type(obj).__name__}")
    unknown = sorted(set(obj) - {"t", "event", "agent", "action", "phase", "next", "delay"})
    if unknown:
        raise DispatchError(f"unknown key {unknown[0][:40]!r} (keys: t, event, agent, action, phase, next, delay)")
    t = obj.get("t")
    # compared, not converted: an integer of 310 digits overflows float() and math.isfinite (issue 34);
    # NaN fails every comparison, the infinities fail the bound
    if isinstance(t, bool) or not isinstance(t, int | float) or not 0 <= t <= _MAX_T:
        raise DispatchError("'t' must be a number of seconds from the task's start (0 to 1e9)")
    event = obj.get("event")
    if event not in EVENTS:
        raise DispatchError(f"'event' must be one of {', '.join(EVENTS)}")
    agent, action, phase, nxt = (_text(obj, k) for k in ("agent", "action", "phase", "next"))
    if event in LEG_EVENTS:
        missing = [k for k, v in (("agent", agent), ("action", action), ("phase", phase)) if v is None]
        if missing:
            raise DispatchError(f"a {event!r} message needs {', '.join(missing)}")
    elif action is not None or phase is not None or nxt is not None:
        raise DispatchError(f"a {event!r} message takes no action, phase or next")
    delay = obj.get("delay")
    if delay is not None:
        # compared, never converted: NaN fails the comparison, and no integer can overflow (issue 34)
        if isinstance(delay, bool) or not isinstance(delay, int | float) or not 0 <= delay <= _MAX_T or \
                event not in LEG_EVENTS:
            raise DispatchError("'delay' must be the seconds (>= 0) between a leg event and when it was learnt")
        delay = float(delay)
    return Observation(float(t), event, agent, action, phase, nxt, delay)
