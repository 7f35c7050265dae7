"""An outside driver that plays the person under the motion detector, from the answers alone (issue 32).

`WalkingRun` extends the independent client of tests/dispatch_client.py (its robot: each event anywhere
in the window the last answer gave it, or near its opening) with a person who is *seen*, not heard: the
driver never sends the person's events, only their position, as a tracker would, in the protocol's
position lines (``{"t", "agent": "human", "event": "position", "x", "y"}``, `hrc dispatch --detect
motion`), and reads nothing but the answers:

- **what**: the first answer's plan's actions for the person, in its order (the plan being followed);
- **where**: each leg along the route of the plan the answers showed when they left (``compiled.json``'s
  motions: the shortest path, a detour's points, or the way to the waiting place and on from it;
  `hrc.dispatch.routes.PlanRoutes`), at a constant pace that makes the walk last a duration drawn inside
  that plan's contingent travel bounds; at a place, standing on the location's point; after the last
  action, walking home at their speed (so that the detector sees the last end);
- **how long**: each manipulation a duration drawn inside its contingent bounds (`Run._duration`);
- **when** (their own departures, starts and moves on from a waiting place): the answer's hint when it
  names the step (at its earliest), nothing while it says to wait for a robot event; while a step of
  theirs is under way, the instruction ahead (``ahead``: `gap` seconds after the robot's event it names,
  which the driver knows because it sent it; at once when it names none), also for the steps of a stay
  at the place its first step is at (a motion detector cannot tell those apart); when no answer says
  anything of the step (the dispatcher has not learnt where they are yet), at once (`unguided` counts
  those).

The tracker is `hrc.detect.sensor.Sensor` (the simulator's model: Gaussian noise per axis, a rate, lost
positions, a latency from measurement to delivery; its own generator, ``(seed, 28)``). `PressingRun`:
the same person heard through buttons pressed late instead. The true times of the person's events are the driver's
own (`Outcome.times`, beside the robot's), so the promise is checked on what happened, never on what
the detector estimated.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from dispatch_client import Outcome, Run

from hrc.detect.sensor import Sensor, SensorModel
from hrc.dispatch.plan_set import PlanSet
from hrc.motion import PathLibrary

Point = tuple[float, float]


class _Walk:
    """A stretch walked from `t0` to `t1` along `points` at a constant pace."""

    def __init__(self, t0: float, t1: float, points: Sequence[Sequence[float]]) -> None:
        self.t0, self.t1 = t0, t1
        self.points = [(float(p[0]), float(p[1])) for p in points]
        self.cum = [0.0]
        for p, q in zip(self.points, self.points[1:], strict=False):
            self.cum.append(self.cum[-1] + math.dist(p, q))

    @property
    def length(self) -> float:
        return self.cum[-1]

    def at(self, t: float) -> Point:
        if self.t1 <= self.t0 or self.length == 0.0:
            return self.points[-1]
        s = min(max((t - self.t0) / (self.t1 - self.t0), 0.0), 1.0) * self.length
        for k in range(1, len(self.points)):
            if s <= self.cum[k] or k == len(self.points) - 1:
                seg = self.cum[k] - self.cum[k - 1]
                f = 0.0 if seg == 0 else (s - self.cum[k - 1]) / seg
                p, q = self.points[k - 1], self.points[k]
                return (p[0] + f * (q[0] - p[0]), p[1] + f * (q[1] - p[1]))
        return self.points[-1]


class WalkingRun(Run):
    """One run of the person walking, seen by a tracker (module docstring); `play(cap)` returns the
    `Outcome` (`times`: the true times, the person's and the robot's)."""

    def __init__(self, plan_set: PlanSet, send: Callable[[str], str], seed: int, *,
                 routes: Callable[[str], Mapping[str, list[dict[str, Any]]]], paths: PathLibrary,
                 sensor: SensorModel, robot_window: str = "anywhere") -> None:
        super().__init__(plan_set, send, seed, human_choice="plan", timing="hinted", announce=False,
                         robot_window=robot_window)
        self.routes = routes
        self.paths = paths
        self.sensor = Sensor(sensor, np.random.default_rng([seed, 28]))
        agent = self.task.agent(self.human)
        self.speed = agent.speed
        self.start = agent.start
        self.xy: Point = tuple(paths.locations[self.start])  # type: ignore[assignment]
        self.walk: _Walk | None = None
        self.leg_plan: str | None = None
        self.leg_route: tuple[list[Sequence[float]], list[Sequence[float]] | None] = ([], None)
        self.last_own: tuple[str, str] | None = None  # the (action, phase) of the person's last event
        self.home_at: float | None = None  # when the walk home ends (after the last action)
        self.unguided = 0  # the person's steps no answer said anything of (taken at once)
        self.positions = 0
        self._unguided = False
        # robot windows already over when the answer giving them came (a position answered after the
        # robot's last message: the dispatcher's clock is that message's); the robot then acts at once
        self.closed: list[tuple[float, dict]] = []

    # -------------------------------------------------------------------------------------------- the person
    def _leg_plan(self) -> str:
        return self.leg_plan if self.leg_plan is not None else super()._leg_plan()

    def _where(self, action: str, phase: str) -> Point:
        return tuple(self.paths.locations[self.task.action(action).phase(phase).location])  # type: ignore[return-value]

    def _route(self, action: str, phase: str) -> tuple[list[Sequence[float]], list[Sequence[float]] | None]:
        """The leg's points (to the waiting place, and on from it) in the plan shown when the person left."""
        legs = self.routes(self._leg_plan()).get(self.human, [])
        leg = next((lg for lg in legs if (lg["action"], lg["phase"]) == (action, phase)), None)
        if leg is None or leg["from"] == leg["to"]:
            return [], None
        if leg.get("park"):
            return (list(self.paths.get(self.human, leg["from"], leg["park"]).points),
                    list(self.paths.get(self.human, leg["park"], leg["to"]).points))
        return list(leg["points"]), None

    def _in_stay(self, named: str, action: str, phase: str, event: str) -> bool:
        """Whether `event` is a step of the stay whose first step, a departure for a leg without a walk, the
        instruction ahead names: a start at that place or the departure from it, the person's last event
        having been there."""
        if event not in ("depart", "start") or not named.endswith(".depart") or self.last_own is None:
            return False
        _, n_action, n_phase, _ = named.split(".")
        here = self.task.action(n_action).phase(n_phase).location
        if self.task.action(self.last_own[0]).phase(self.last_own[1]).location != here:
            return False
        return event == "depart" or self.task.action(action).phase(phase).location == here

    def _when(self, action: str, phase: str, event: str) -> float | None:
        """When the person does their step, from the last answer (module docstring); None: not yet."""
        dec = self.decision
        hint = dec.get("human")
        if hint is not None:
            if "wait_for" in hint:
                return None
            if (hint["action"], hint["phase"], hint["event"]) == (action, phase, event):
                return float(hint["earliest"])
        ahead = dec.get("ahead")
        if hint is None and ahead is not None and (ahead["next"] == f"{self.human}.{action}.{phase}.{event}"
                                                   or self._in_stay(ahead["next"], action, phase, event)):
            if ahead["wait_for"] is None:
                return self.now
            seen = self.out.times.get(tuple(ahead["wait_for"].split(".")))  # type: ignore[arg-type]
            return None if seen is None else seen + float(ahead["gap"])
        return math.nan  # nothing said of it

    def _executable(self, action: str, phase: str, event: str) -> tuple[float, dict] | None:
        if event == "start":
            for p in self.task.precedence:
                if (p.after.action, p.after.phase) == (action, phase) and \
                        (p.before.action, p.before.phase) not in self.ended:
                    return None  # the task graph makes the person wait (they see the robot's work)
        at = self._when(action, phase, event)
        if at is None:
            return None
        if math.isnan(at):
            at = self.now
            self._unguided = True
        at = round(max(self.now, at), 3)
        return (at, {"t": at, "agent": self.human, "action": action, "phase": phase, "event": event})

    def _human_step(self) -> tuple[float, dict] | None:
        self._unguided = False
        step = super()._human_step()
        if step is None and self.h_leg is None and self.home_at is None and self.walk is None \
                and self._next_action() is None:
            here = self.xy
            home = self.paths.locations[self.start]
            if self.last_own is not None and math.dist(here, home) > 1e-6:  # done: walk home
                loc = self.task.action(self.last_own[0]).phase(self.last_own[1]).location
                points = self.paths.get(self.human, loc, self.start).points
                walk = _Walk(self.now, self.now, points)
                walk.t1 = self.now + walk.length / self.speed
                self.walk, self.home_at = walk, walk.t1
            else:
                self.home_at = self.now
        return step

    def _human_did(self, msg: dict) -> None:
        """The person's own event `msg` happened (true time ``msg["t"]``): recorded, never sent."""
        action, phase, event = msg["action"], msg["phase"], msg["event"]
        msg = {**msg, "t": round(msg["t"], 3)}
        self.now = msg["t"]
        self.unguided += self._unguided and event in ("depart", "unpark", "start")
        self.out.times[(self.human, action, phase, event)] = msg["t"]
        self.out.doer.setdefault(action, self.human)
        if event == "end":
            self.ended.add((action, phase))
        if event == "depart":
            self.leg_plan = self.decision["plan"]
        super()._human_did(msg)
        if self.h_at is not None:
            self.h_at = round(self.h_at, 3)
        self.last_own = (action, phase)
        if event == "depart":
            self.leg_route = self._route(action, phase)
        nxt = self.h_events[0] if self.h_leg is not None and self.h_events else None
        if event in ("depart", "unpark") and nxt in ("park", "arrive") and self.h_at is not None:
            first, onward = self.leg_route
            points = onward if event == "unpark" else first
            self.walk = _Walk(self.now, self.h_at, points) if points and len(points) > 1 else None
        elif event in ("park", "arrive"):
            if self.walk is not None:
                self.xy = self.walk.points[-1]
            elif event == "arrive":
                self.xy = self._where(action, phase)
            self.walk = None

    def position(self, t: float) -> Point:
        if self.walk is not None:
            xy = self.walk.at(t)
            if self.home_at is not None and t >= self.walk.t1:
                self.xy, self.walk = self.walk.points[-1], None
            return xy
        return self.xy

    # -------------------------------------------------------------------------------------------- the robot
    def _robot_step(self) -> tuple[float, dict] | None:
        step = self.decision.get("robot")
        if step and "wait_for" not in step and step["latest"] is not None and step["latest"] < self.now - 1e-9:
            key = (step["action"], step["phase"], step["event"], step["earliest"], step["latest"])
            if key != self.r_key:
                self.closed.append((self.now, dict(step)))
                self.r_key, self.r_at = key, self.now
                self.out.windows.append((self.now, step["earliest"], step["latest"]))
            return (self.now, {"t": self.now, "agent": self.robot, "action": step["action"],
                               "phase": step["phase"], "event": step["event"]})
        return super()._robot_step()

    # -------------------------------------------------------------------------------------------- the loop
    def play(self, max_messages: int = 100_000, cap: float = 600.0) -> Outcome:  # type: ignore[override]
        self.out.first = self._say({"t": 0.0, "event": "tick"})
        self.follow = self.decision["plan"]
        for _ in range(max_messages):
            human = self._human_step()
            robot = self._robot_step()
            if human is None and robot is None and self.home_at is not None and self.now >= self.home_at \
                    and self.decision.get("robot") is None:
                return self.out
            if self.now > cap:
                return self.out  # stuck: what never happened shows in `broken_links`
            sample = self.sensor.next_time
            if robot is not None and robot[0] <= sample and (human is None or robot[0] <= human[0]):
                answer = self._say(robot[1])
                assert answer["ok"], (robot[1], answer)
                self.r_key = None
                continue
            if human is not None and human[0] <= sample:
                self._human_did(human[1])
                continue
            self.sensor.measure(sample, self.position(sample))
            before = self.now  # a position lagging by the tracker's latency does not move the clock back
            for t, x, y in self.sensor.due(sample):
                self.positions += 1
                answer = self._say({"t": t, "agent": self.human, "event": "position", "x": x, "y": y})
                assert answer["ok"], answer
            self.now = max(before, self.now, sample)
        raise AssertionError("the run did not end")


class PressingRun(WalkingRun):
    """The person of `WalkingRun` (the same steps, read from the answers alone), heard through buttons
    pressed late instead of seen: each of their events (departure, arrival, stop, start, end) is pressed
    `late` seconds after it truly happened (`uniform`: a delay drawn uniformly in ``[0, late]`` with the
    driver's own generator, ``(seed, 29)``), each press no earlier than the one before (a later press of
    an earlier event holds the next back: still within ``late`` of it), saying its ``delay`` as the
    simulator's buttons do, and announcing the next action of the followed plan on each action's end
    press. The dispatcher's clock moves with a tick every `tick` seconds (a console's clock) besides the
    robot's messages and the presses. `Outcome.times` holds the true times; the presses never enter it."""

    def __init__(self, plan_set: PlanSet, send: Callable[[str], str], seed: int, *,
                 routes: Callable[[str], Mapping[str, list[dict[str, Any]]]], paths: PathLibrary,
                 late: float, uniform: bool = False, tick: float = 0.5, robot_window: str = "anywhere") -> None:
        super().__init__(plan_set, send, seed, routes=routes, paths=paths, sensor=SensorModel(),
                         robot_window=robot_window)
        self.late, self.uniform, self.tick = late, uniform, tick
        self.delays = np.random.default_rng([seed, 29])
        self.presses: list[tuple[float, dict]] = []  # (when pressed, the message), in time order
        self.pressed: list[float] = []  # each press's delay (s)

    def _human_did(self, msg: dict) -> None:
        super()._human_did(msg)
        t = self.out.times[(self.human, msg["action"], msg["phase"], msg["event"])]
        delay = float(self.delays.uniform(0.0, self.late)) if self.uniform else self.late
        at = round(max(t + delay, self.presses[-1][0] if self.presses else 0.0, self.now), 3)
        press = {"t": at, "agent": self.human, "action": msg["action"], "phase": msg["phase"],
                 "event": msg["event"], "delay": round(at - t, 3)}
        phases = [p.id for p in self.task.action(msg["action"]).phases]
        if msg["event"] == "end" and msg["phase"] == phases[-1]:
            nxt = self._next_action()
            if nxt is not None:
                press["next"] = nxt
        self.presses.append((at, press))
        self.pressed.append(press["delay"])

    def _say(self, obj: dict) -> dict:
        key = (obj.get("agent"), obj.get("action"), obj.get("phase"), obj.get("event"))
        true = self.out.times.get(key) if obj.get("agent") == self.human else None  # type: ignore[arg-type]
        answer = super()._say(obj)
        if true is not None:  # a press: the event's time stays the true one
            self.out.times[key] = true  # type: ignore[index]
        return answer

    def play(self, max_messages: int = 100_000, cap: float = 600.0) -> Outcome:  # type: ignore[override]
        self.out.first = self._say({"t": 0.0, "event": "tick"})
        self.follow = self.decision["plan"]
        next_tick = self.tick
        for _ in range(max_messages):
            human = self._human_step()
            robot = self._robot_step()
            if human is None and robot is None and not self.presses and self.home_at is not None \
                    and self.now >= self.home_at and self.decision.get("robot") is None:
                return self.out
            if self.now > cap:
                return self.out  # stuck: what never happened shows in `broken_links`
            press = self.presses[0][0] if self.presses else math.inf
            first = min(press, robot[0] if robot is not None else math.inf,
                        human[0] if human is not None else math.inf, next_tick)
            if press <= first:
                answer = self._say(self.presses.pop(0)[1])
                assert answer["ok"], answer
            elif robot is not None and robot[0] <= first:
                answer = self._say(robot[1])
                assert answer["ok"], (robot[1], answer)
                self.r_key = None
            elif human is not None and human[0] <= first:
                self._human_did(human[1])
            else:
                if next_tick >= self.now:
                    answer = self._say({"t": round(next_tick, 3), "event": "tick"})
                    assert answer["ok"], answer
                next_tick = round(next_tick + self.tick, 3)
        raise AssertionError("the run did not end")
