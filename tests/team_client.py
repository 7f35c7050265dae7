"""An independent client of the dispatcher's JSON-lines protocol for any team (issue 37): it plays every
person and every robot controller, reading nothing but the answers (JSON lines, through
`hrc.dispatch.protocol.handle_line`, as ``hrc dispatch`` reads them) and, to draw nature's durations, the
STNU the compile wrote for the plan an answer names (`stnus`: plan id -> STNU, from the compile's GraphML).

- each **robot** does the event its entry of ``"robots"`` gives it at a time drawn inside its window
  (`_pick`), and reports it at once; told to wait (``wait_for``) or nothing (null), it waits;
- each **person** does the event of their hint (``"people"``) at a time drawn in its window (the paper's
  model: a person waits when asked), unless something of theirs is under way;
- **nature**: after an observed event that starts a contingent link of the plan named then (a person's
  walk or work, a joint action's duration after its lead's start), its end is drawn inside the link's bounds
  and reported when it comes (by the person, or the joint action's lead for its end).

`TeamRun.play` returns the observed times and every answer; a one-robot, one-person task is read through
``"robot"`` and ``"human"``, the same loop.
"""

from __future__ import annotations

import json
import random
from dataclasses import dataclass, field
from typing import Any

from hrc.dispatch.protocol import handle_line
from hrc.temporal import STNU
from hrc.temporal.graphml import tool_name

Key = tuple[str, str, str, str]  # (agent, action, phase, event)
EVENTS = ("depart", "park", "unpark", "arrive", "start", "end")


def timepoint(key: Key) -> str:
    agent, action, phase, event = key
    return tool_name(f"{agent}.{phase}.{action}.{event}")


@dataclass
class TeamRun:
    dispatcher: Any  # only ever handed to `handle_line`
    stnus: dict[str, STNU]
    robots: tuple[str, ...]
    people: tuple[str, ...]
    rng: random.Random
    times: dict[Key, float] = field(default_factory=dict)
    answers: list[dict[str, Any]] = field(default_factory=list)
    sent: list[str] = field(default_factory=list)

    def send(self, message: dict[str, Any]) -> dict[str, Any]:
        line = json.dumps(message)
        self.sent.append(line)
        out = json.loads(handle_line(self.dispatcher, line))
        self.answers.append(out)
        return out

    def _pick(self, step: dict[str, Any], now: float) -> float:
        lo = max(step["earliest"], now)
        hi = lo + 3.0 if step["latest"] is None else max(lo, step["latest"])
        return round(lo + self.rng.random() * (hi - lo), 3)

    def _steps(self, answer: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
        if "robots" in answer:
            return answer["robots"], answer["people"]
        return {self.robots[0]: answer["robot"]}, {self.people[0]: answer["human"]}

    def _nature(self, plan: str | None, key: Key, t: float, nature: dict[Key, float]) -> None:
        """Draw the ends of the contingent links `key` starts in the plan named (none: nothing drawn)."""
        if plan is None:
            return
        source = timepoint(key)
        agent, action, phase, _ = key
        names = {timepoint((agent, action, phase, e)): e for e in EVENTS}
        for c in self.stnus[plan].contingents:
            if c.source == source and c.target in names:
                nature[(agent, action, phase, names[c.target])] = round(t + self.rng.uniform(c.lb, c.ub) / 1000, 3)

    def play(self, limit: int = 600) -> dict[Key, float]:
        answer = self.send({"t": 0, "event": "tick"})
        assert answer["ok"], answer
        nature: dict[Key, float] = {}
        now = 0.0
        for _ in range(limit):
            robots, people = self._steps(answer)
            due: list[tuple[float, Key]] = [(t, k) for k, t in nature.items()]
            for r, step in robots.items():
                if step is not None and "event" in step:
                    due.append((self._pick(step, now), (r, step["action"], step["phase"], step["event"])))
            for h, step in people.items():
                if step is not None and "event" in step and not any(k[0] == h for k in nature):
                    due.append((self._pick(step, now), (h, step["action"], step["phase"], step["event"])))
            if not due:
                return self.times
            t, key = min(due)
            nature.pop(key, None)
            now = t
            self.times[key] = t
            agent, action, phase, event = key
            answer = self.send({"t": t, "agent": agent, "action": action, "phase": phase, "event": event})
            assert answer["ok"] is True, (key, answer)
            self._nature(answer["plan"], key, t, nature)
        raise AssertionError(f"no end after {limit} messages")
