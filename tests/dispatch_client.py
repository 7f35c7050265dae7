"""A client that plays the human and the robot controller against the dispatcher's JSON-lines protocol.

It knows the task and the compiled plans from the output folder (read here, independently of the
dispatcher process), and nothing of the dispatcher's insides: it sends observation lines and reads the
answers. A discrete-event loop in simulated time:

- the **robot** carries out each event the last answer gave it at a time inside that window (drawn by
  `robot_pick`), or waits when told to wait;
- the **human** picks its next action by `human_choice` ("plan": the order of a given plan, "random": any
  order the task allows, retried when refused), walks and works for durations drawn inside the bounds
  of the current best plan's STNU (its contingent links), and leaves or starts either at once ("eager")
  or when the dispatcher's hint says so ("hinted", the paper's model: the human waits when asked);
- optionally the human leaves (``away``) after finishing `away_after` actions and never comes back;
- `announce`: on the end of each action the human announces the next one of the plan they follow
  (``"next"``), as the paper's detector does ("the currently performed and the predicted next action");
- `robot_window`: "near" acts within 2 s of the window's opening, "anywhere" anywhere in it (a window
  with no latest bound: within 3 s of its opening), "earliest" at its opening (as `hrc simulate`'s robot).

The human's route is the one the best plan shows when they leave (its waiting place, if any: they stop
there and go on when the hint says); that plan, `Run.told`, is what they were told.

`Run.play` returns what happened; the tests check it against the task and the plans' STNUs.
"""

from __future__ import annotations

import json
import random
from collections.abc import Callable
from dataclasses import dataclass, field

from hrc.dispatch.plan_set import PlanSet
from hrc.temporal import STNU
from hrc.temporal.graphml import tool_name


class _ById:
    """A plan's entry by its id, made when asked for (a large set has tens of thousands)."""

    def __init__(self, plan_set: PlanSet) -> None:
        self.plan_set = plan_set

    def __getitem__(self, plan_id: str):  # noqa: ANN204
        return self.plan_set.entry(self.plan_set.index(plan_id))


@dataclass
class Outcome:
    times: dict[tuple[str, str, str, str], float] = field(default_factory=dict)  # (agent, action, phase, event)
    doer: dict[str, str] = field(default_factory=dict)  # action -> agent that did it
    answers: list[dict] = field(default_factory=list)
    windows: list[tuple[float, float, float | None]] = field(default_factory=list)  # robot: (t, earliest, latest)
    refused: list[tuple[str, str]] = field(default_factory=list)  # (line in, error)
    first: dict | None = None


class Run:
    def __init__(self, plan_set: PlanSet, send: Callable[[str], str], seed: int, *, human_choice: str = "plan",
                 timing: str = "hinted", follow: str | None = None, away_after: int | None = None,
                 announce: bool = False, robot_window: str = "near") -> None:
        self.ps = plan_set
        self.task = plan_set.task
        self.send = send
        self.rng = random.Random(seed)
        self.human_choice = human_choice
        self.timing = timing
        self.follow = follow  # the plan whose order the human follows ("plan" choice)
        self.away_after = away_after
        self.announce = announce
        self.robot_window = robot_window
        self.by_id = _ById(plan_set)
        self.human = next(a.id for a in self.task.agents if a.is_human)
        self.robot = next(a.id for a in self.task.agents if not a.is_human)
        self.out = Outcome()
        self.now = 0.0
        self.decision: dict = {}
        self.ended: set[tuple[str, str]] = set()
        # the human: its leg under way, the events of that leg still to come, and their planned times
        self.h_leg: tuple[str, str] | None = None
        self.h_events: list[str] = []
        self.h_at: float | None = None  # when the next contingent event comes (nature)
        self.h_refused: set[str] = set()
        self.h_done_actions: list[str] = []
        self.away = False
        self.r_at: float | None = None
        self.r_key: tuple | None = None

    # -------------------------------------------------------------------------------------------- protocol
    def _say(self, obj: dict) -> dict:
        line = json.dumps(obj)
        answer = json.loads(self.send(line))
        if not answer["ok"]:
            self.out.refused.append((line, answer["error"]))
            return answer
        self.now = obj["t"]
        self.decision = answer
        self.out.answers.append(answer)
        if obj.get("agent") and obj.get("action"):
            key = (obj["agent"], obj["action"], obj["phase"], obj["event"])
            self.out.times[key] = obj["t"]
            self.out.doer.setdefault(obj["action"], obj["agent"])
            if obj["event"] == "end":
                self.ended.add((obj["action"], obj["phase"]))
        return answer

    # -------------------------------------------------------------------------------------------- the human
    def _leg_plan(self) -> str:
        """The plan whose leg the human walks and works (its events, its bounds): the best one now."""
        return str(self.decision["plan"])

    def _stnu(self) -> STNU:
        return self.by_id[self._leg_plan()].stnu

    def _leg_events(self, action: str, phase: str) -> list[str]:
        entry = self.by_id[self._leg_plan()]
        return [e for e, _ in entry.leg_points[(self.human, action, phase)]]

    def _duration(self, action: str, phase: str, event: str) -> float:
        """Nature's duration of the contingent link ending at this event, inside its bounds (ticks -> s)."""
        node = tool_name(f"{self.human}.{phase}.{action}.{event}")
        stnu = self._stnu()
        link = next((c for c in stnu.contingents if c.target == node), None)
        if link is None:  # a fixed duration (no travel: [0, 0]) is written as requirement links
            points = [n for _, n in self.by_id[self._leg_plan()].leg_points[(self.human, action, phase)]]
            prev = points[points.index(node) - 1]
            for r in stnu.requirements:
                if (r.source, r.target) == (prev, node):
                    return (r.lb if r.lb is not None else r.ub) / 1000
                if (r.source, r.target) == (node, prev):
                    return -(r.ub if r.ub is not None else r.lb) / 1000
            raise AssertionError(f"no link ends at {node}")
        return self.rng.choice([link.lb, link.ub, self.rng.randint(link.lb, link.ub)]) / 1000

    def _next_action(self) -> str | None:
        done = set(self.h_done_actions) | set(self.out.doer)
        if self.human_choice == "plan":
            seq = dict(self.by_id[self.follow].plan.sequences)[self.human] if self.follow else ()
            rest = [a for a in seq if a not in done]
            return rest[0] if rest else None
        options = [a.id for a in self.task.actions if a.id not in done and self.human in a.agents
                   and a.id not in self.h_refused]
        return self.rng.choice(options) if options else None

    def _human_step(self) -> tuple[float, dict] | None:
        """The human's next message and when, or None (waiting, done or away)."""
        if self.away:
            return None
        if self.h_leg is None:
            if self.away_after is not None and len(self.h_done_actions) >= self.away_after:
                return (self.now, {"t": self.now, "agent": self.human, "event": "away"})
            action = self._next_action()
            if action is None:
                return None
            phase = self.task.action(action).phases[0].id
            return self._executable(action, phase, "depart")
        action, phase = self.h_leg
        event = self.h_events[0]
        if event in ("depart", "unpark", "start"):
            return self._executable(action, phase, event)
        assert self.h_at is not None
        return (self.h_at, {"t": self.h_at, "agent": self.human, "action": action, "phase": phase, "event": event})

    def _executable(self, action: str, phase: str, event: str) -> tuple[float, dict] | None:
        msg = {"t": 0.0, "agent": self.human, "action": action, "phase": phase, "event": event}
        if event == "start":
            for p in self.task.precedence:
                if (p.after.action, p.after.phase) == (action, phase) and \
                        (p.before.action, p.before.phase) not in self.ended:
                    return None  # the task graph makes the human wait
        at = self.now
        if self.timing == "hinted":
            hint = self.decision.get("human")
            if not hint or "wait_for" in hint:
                return None
            if (hint["action"], hint["phase"], hint["event"]) != (action, phase, event):
                return None
            at = max(self.now, hint["earliest"])
        msg["t"] = at
        return (at, msg)

    def _human_did(self, msg: dict) -> None:
        if msg["event"] == "away":
            self.away = True
            return
        action, phase, event = msg["action"], msg["phase"], msg["event"]
        if event == "depart":
            self.h_leg = (action, phase)
            self.h_events = self._leg_events(action, phase)[1:]
        else:
            self.h_events.pop(0)
        if not self.h_events:  # the leg ended
            self.h_leg = None
            action_phases = [p.id for p in self.task.action(action).phases]
            if phase == action_phases[-1]:
                self.h_done_actions.append(action)
            else:  # the action's next phase is the next leg
                nxt = action_phases[action_phases.index(phase) + 1]
                self.h_leg = (action, nxt)
                self.h_events = self._leg_events(action, nxt)
            self.h_at = None
            return
        if self.h_events[0] in ("park", "arrive", "end"):
            self.h_at = self.now + self._duration(action, phase, self.h_events[0])

    # -------------------------------------------------------------------------------------------- the robot
    def _robot_step(self) -> tuple[float, dict] | None:
        step = self.decision.get("robot")
        if not step or "wait_for" in step:
            self.r_at = self.r_key = None
            return None
        key = (step["action"], step["phase"], step["event"], step["earliest"], step["latest"])
        if key != self.r_key:  # a new window: choose a time in it
            lo = max(self.now, step["earliest"])
            hi = step["latest"] if step["latest"] is not None else lo + 3.0
            assert hi >= lo - 1e-9, f"window over before it is given: now {self.now}, {step}"
            reach = hi if self.robot_window == "anywhere" else lo if self.robot_window == "earliest" \
                else min(hi, lo + 2.0)
            self.r_at = round(self.rng.uniform(lo, reach), 3)
            self.r_at = min(max(self.r_at, lo), hi)
            self.r_key = key
            self.out.windows.append((self.r_at, step["earliest"], step["latest"]))
        assert self.r_at is not None
        return (self.r_at, {"t": self.r_at, "agent": self.robot, "action": step["action"], "phase": step["phase"],
                            "event": step["event"]})

    # -------------------------------------------------------------------------------------------- the loop
    def play(self, max_messages: int = 2000) -> Outcome:
        self.out.first = self._say({"t": 0.0, "event": "tick"})
        self.follow = self.follow or self.decision["plan"]
        for _ in range(max_messages):
            human = self._human_step()
            robot = self._robot_step()
            if human is None and robot is None:
                if self.h_refused and self.h_leg is None:  # try the refused choices again later
                    self.h_refused.clear()
                    human = self._human_step()
                if human is None:
                    return self.out
            if robot is not None and (human is None or robot[0] < human[0]):
                answer = self._say(robot[1])
                assert answer["ok"], (robot[1], answer)
                self.r_key = None
                continue
            assert human is not None
            msg = human[1]
            if self.announce and msg.get("event") == "end" and self.human_choice == "plan":
                phases = [p.id for p in self.task.action(msg["action"]).phases]
                if msg["phase"] == phases[-1]:
                    self.h_done_actions.append(msg["action"])
                    nxt = self._next_action()
                    self.h_done_actions.pop()
                    if nxt is not None:
                        msg = {**msg, "next": nxt}
                        human = (human[0], msg)
            answer = self._say(human[1])
            if answer["ok"]:
                self._human_did(human[1])
                self.h_refused.clear()
            elif human[1]["event"] == "depart" and self.human_choice == "random":
                self.h_refused.add(human[1]["action"])
            else:
                raise AssertionError((human[1], answer))
        raise AssertionError("the run did not end")


def broken_links(stnu: STNU, times: dict[tuple[str, str, str, str], float]) -> list[str]:
    """Every link of `stnu` that the observed times break (each timepoint must have been observed)."""
    at = {"Z": 0}
    for (agent, action, phase, event), t in times.items():
        at[tool_name(f"{agent}.{phase}.{action}.{event}")] = round(t * 1000)
    missing = [v for v in stnu.timepoints if v not in at]
    out = [f"{v} never happened" for v in missing]
    for link in (*stnu.requirements, *stnu.contingents):
        if link.source in at and link.target in at:
            d = at[link.target] - at[link.source]
            if (link.lb is not None and d < link.lb) or (link.ub is not None and d > link.ub):
                out.append(f"{link.source} -> {link.target}: {d} outside [{link.lb}, {link.ub}]")
    return out
