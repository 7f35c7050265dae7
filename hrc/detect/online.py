"""The dispatcher with the motion detector in front of it: position messages in, the person's events out
to the dispatcher, one answer per message (``hrc dispatch --detect motion``, the console, the
simulator).

`DetectingDispatcher` is a `hrc.dispatch.Dispatcher` that also takes the person's tracked position,
``{"t": 12.3, "agent": "human", "event": "position", "x": 4.1, "y": 2.0}`` (`position`): the detector
(`hrc.detect.filter`) reads it against what the dispatcher knows (`hrc.detect.situation`) and gives the
events it now is sure of, each with the time it estimates the event happened; each goes to the
dispatcher as if the person had pressed its button (`Dispatcher.observe`). Every other message goes to
the dispatcher as it is, so a tracker and a robot controller share one stream.

**Time.** A position's ``t`` is when it was measured (a tracker's latency makes it lag); positions come
in time order, but may lag behind the robot's messages. An event goes to the dispatcher at the time the
detector estimates, or at the dispatcher's last accepted message when that is later (its clock never
goes back): the answer says both (``detect.events[i].t`` and ``.at``). A position does not move the
dispatcher's clock.

**Replay.** The detector's state (`hrc.detect.filter.Track`) is immutable, replaced whole with each
position, and part of this object's state: `fork` copies it with the dispatcher's, so the write-ahead
log (`hrc.dispatch.durable`) and ``--replay`` treat a position like any other message, and a run
replays byte for byte.

**A team** (issue 37: more than one person): one detector per person, each with that person's own
distance fields, duration bounds, track and belief, reading the dispatcher's history and that person's
own hint (`Decision.people`); a position names its person (``"agent": "alice"``) and goes to their
detector only, so an event is only ever given as the person's whose positions showed it. The dispatcher
reads each person's estimated events within the detector's stated span of them (`_span`, per person).

An event the dispatcher refuses (it should not happen: the detector offers only what the dispatcher's
options allow) is left out and named in the answer (``detect.refused``), and the detector goes on.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from types import MappingProxyType
from typing import Any

from hrc.dispatch import Dispatcher, Observation
from hrc.dispatch.plan_set import PlanSet
from hrc.dispatch.validation import MAX_JUMP
from hrc.errors import DispatchError

from .filter import Detected, Track, decide, ingest
from .model import DetectorModel, DetectParams, detector_model
from .situation import Situation, situation

__all__ = ["MAX_METRES", "POSITION_KEYS", "DetectingDispatcher", "position_from_json", "position_message"]

POSITION_KEYS = ("t", "agent", "event", "x", "y")
MAX_METRES = 1e6
"""A coordinate beyond this many metres from the map's origin is a tracker's error, refused."""
_MAX_ROUNDS = 12  # events one position may give (a walk's end, the legs on the way, the departure)


def position_from_json(obj: Any, human: str = "human") -> tuple[float, float, float]:
    """``(t, x, y)`` of a position message of the one person `human`; `DispatchError` saying in one line what
    is wrong."""
    return position_message(obj, (human,))[1:]  # type: ignore[return-value]


def position_message(obj: Any, people: tuple[str, ...]) -> tuple[str, float, float, float]:
    """``(person, t, x, y)`` of a position message; `DispatchError` saying in one line what is wrong. With
    one person (`people`) ``agent`` may be left out; a team's (issue 37) must name one of them."""
    if not isinstance(obj, dict):
        raise DispatchError(f"a message must be a JSON object, found {type(obj).__name__}")
    unknown = sorted(set(obj) - set(POSITION_KEYS))
    if unknown:
        raise DispatchError(f"unknown key {unknown[0][:40]!r} in a position (keys: {', '.join(POSITION_KEYS)})")
    if len(people) == 1:
        agent = obj.get("agent", people[0])
        if agent != people[0]:
            raise DispatchError(f"a position is the human's ({people[0]!r}), not {str(agent)[:40]!r}'s")
    else:
        agent = obj.get("agent")
        if agent not in people:
            raise DispatchError(f"a position must name its person, 'agent': one of {', '.join(people)} "
                                f"(found {'nothing' if agent is None else repr(str(agent)[:40])})")
    out = []
    for key in ("t", "x", "y"):
        value = obj.get(key)
        # compared, never converted first: float(10**400) overflows (issue 34); NaN fails the comparison
        if isinstance(value, bool) or not isinstance(value, int | float) or not -MAX_METRES <= value <= MAX_METRES:
            raise DispatchError(f"a position needs {key!r}, a finite number" + (" of seconds" if key == "t" else
                                                                                f" of metres (within ±{MAX_METRES:g})"))
        out.append(float(value))
    if not 0 <= out[0] <= 1e9:
        raise DispatchError("'t' must be a number of seconds from the task's start (0 to 1e9)")
    return str(agent), out[0], out[1], out[2]


class DetectingDispatcher(Dispatcher):
    """A `Dispatcher` that also takes positions (see the module docstring). `params`: the detector's
    settings (`DetectParams`); `model`: share an already built `DetectorModel` of the same task (its
    person's; a team's others are built). A team (issue 37) has one detector per person: each person's
    own `DetectorModel` (`models`) and `Track` (`tracks`), their positions naming them; `model` and
    `track` are the first person's."""

    def __init__(self, plan_set: PlanSet, *, params: DetectParams | None = None,
                 model: DetectorModel | None = None, **options: Any) -> None:
        # the error of an estimated event time: three standard deviations of the position noise in walking
        # time. Within it of a bound of the person's hint an event is read as on it (`Dispatcher._on_bound`),
        # and the robot's windows hold for every time within it (`Dispatcher._windows`). Measured (issue 32,
        # workshop, 40 runs each): departures estimated -0.13..+0.12 s off at sigma 0.05 m, -0.41..+0.32 s
        # at 0.15 m (p1..p99: -0.11..+0.10, -0.31..+0.28), speed 1.2 m/s; two sigma (0.083, 0.25 s) left 4
        # and 2 of 40 runs breaking a passing order, three sigma none. A team's: the slowest person's (the
        # dispatcher has one tolerance; a slower walker's time errs more for the same position noise)
        people = [a for a in plan_set.task.agents if a.is_human]
        sigma = (params or (model.params if model is not None else DetectParams())).sigma
        if people:
            options.setdefault("bound_tolerance", round(3 * sigma / min(a.speed for a in people), 3))
        super().__init__(plan_set, **options)
        first = model if model is not None and model.task is plan_set.task else \
            detector_model(plan_set.task, params)
        models = {first.human: first}
        for a in people:
            if a.id not in models:
                same = next((m for m in models.values() if plan_set.task.agent(m.human).radius == a.radius), None)
                models[a.id] = detector_model(plan_set.task, first.params, a.id,
                                              None if same is None else same.geo)
        self.models: Mapping[str, DetectorModel] = MappingProxyType(models)
        self.model = first
        # each replaced whole, never changed in place: a fork (`take_position`) shares them until it does
        self.tracks: Mapping[str, Track] = MappingProxyType(dict.fromkeys(models, Track()))
        self._situations: Mapping[str, tuple[object, Situation]] = MappingProxyType({})
        self._pending: tuple[str, tuple[float, float] | None] | None = None  # (person, span) being given (`_span`)

    @property
    def people(self) -> tuple[str, ...]:
        """The people tracked, in task order."""
        return tuple(self.models)

    @property
    def track(self) -> Track:
        """The first person's track (the one person's)."""
        return self.tracks[self.model.human]

    def _span(self, obs: Observation) -> tuple[float, float] | None:
        """Where the event being given may truly have happened, as the detector states it
        (`hrc.detect.filter.Detected.span`), or None (the dispatcher's `bound_tolerance` alone)."""
        pending = self._pending
        return pending[1] if pending is not None and obs.agent == pending[0] else None

    def detect_settings(self) -> dict[str, Any]:
        """What a log records of the detector (`hrc.dispatch.protocol.log_header`): a replay needs the same."""
        return {"detector": "motion", "params": self.model.params.to_json()}

    def situation(self, person: str | None = None) -> Situation:
        """What the dispatcher knows of `person` (default: the first) now (cached per decision)."""
        person = self.model.human if person is None else person
        cached = self._situations.get(person)
        if cached is None or cached[0] is not self.decision:
            cached = (self.decision, situation(self.models[person], self))
            self._situations = MappingProxyType({**self._situations, person: cached})
        return cached[1]

    def position(self, t: float, x: float, y: float, person: str | None = None
                 ) -> tuple[list[tuple[Detected, float]], list[str]]:
        """Take `person`'s (default: the first's) position (x, y) measured at `t`: the events given to the
        dispatcher, each with the time it went in (``(event, t_in)``), and those it refused (one line each).
        Raises `DispatchError` (nothing changed) when `t` is before that person's last position or a clock
        error."""
        person = self.model.human if person is None else person
        model = self.models.get(person)
        if model is None:
            raise DispatchError(f"{person!r} is not a person of this task (people: {', '.join(self.models)})")
        track = self.tracks[person]
        last = track.t
        if last is not None and t < last:
            raise DispatchError(f"position time goes backwards: t = {t:g} s is before the last position ({last:g} s)"
                                + ("" if len(self.models) == 1 else f" of {person}"))
        if t > max(last or 0.0, self.now) + MAX_JUMP:
            raise DispatchError(f"position t = {t:g} s is more than {MAX_JUMP:g} s after the last message: "
                                "a clock error?")
        track = ingest(model, track, t, x, y)
        given: list[tuple[Detected, float]] = []
        refused: list[str] = []
        for _ in range(_MAX_ROUNDS):
            track, events = decide(model, track, self.situation(person))
            if not events:
                break
            stop = False
            for ev in events:
                at = max(round(ev.t, 3), self.now)  # the clock never goes back (a rounded time might)
                try:
                    if ev.event == "undo":  # a departure given for the wrong place, withdrawn
                        self.observe(Observation(at, "undo"))
                    else:
                        # learnt now, from the position measured at t: how late it is said (`delay`)
                        self._pending = (person, ev.span)
                        try:
                            self.observe(Observation(at, ev.event, person, ev.action, ev.phase,
                                                     delay=round(max(0.0, t - ev.t), 3)))
                        finally:
                            self._pending = None
                except DispatchError as err:
                    what = ev.event if ev.event == "undo" else f"{ev.event} {ev.action}.{ev.phase}"
                    refused.append(f"{what}: {str(err).splitlines()[0]}")
                    stop = True
                    break
                given.append((ev, at))
                if ev.event != "undo":  # (a withdrawal keeps the times of what stands)
                    track = replace(track, last=max(track.last, ev.t), given_at=t)
            if stop:
                break
        self.tracks = MappingProxyType({**self.tracks, person: track})
        return given, refused

    def take_position(self, t: float, x: float, y: float, person: str | None = None
                      ) -> tuple[list[tuple[Detected, float]], list[str]]:
        """`position`, on a copy that becomes the state only when it returns: whatever goes wrong (a
        refusal, or a defect), the state is as it was."""
        work = self.fork()
        assert isinstance(work, DetectingDispatcher)
        given, refused = work.position(t, x, y, person)
        self._state, self.tracks, self._situations = work._state, work.tracks, work._situations
        return given, refused

    def answer_position(self, obj: Any) -> dict[str, Any]:
        """The protocol's answer to a position message (`hrc.dispatch.protocol`): the decision, with
        ``t`` the position's and ``detect``: the events given (``t``: estimated, ``at``: as given to the
        dispatcher), any refused, and the belief (of the person the position is of: a team's answer names
        them, ``detect.agent``). `DispatchError` when the message is refused."""
        person, t, x, y = position_message(obj, self.people)
        given, refused = self.take_position(t, x, y, person)
        return self.position_answer(person, t, given, refused)

    def position_answer(self, person: str, t: float, given: list[tuple[Detected, float]], refused: list[str]
                        ) -> dict[str, Any]:
        """The answer to `person`'s position at `t` once taken (`answer_position`; the simulator's log)."""
        out = self.decision.to_json()
        out["t"] = t
        detect: dict[str, Any] = {"events": [{**ev.to_json(person), "at": at} for ev, at in given],
                                  "belief": self.tracks[person].belief.to_json()}
        if len(self.models) > 1:
            detect = {"agent": person, **detect}
        if refused:
            detect["refused"] = refused
        out["detect"] = detect
        return out
