"""A discrete-event client that plays the person and the robot controller against a `Dispatcher` in
process, for tasks with joint actions (issue 37): it knows the plans only through the answers and the
best plan's STNU (its contingent bounds, to draw nature's durations), nothing of the dispatcher's insides.

- the **robot** does each event the last answer gives it at a time drawn inside the window (`pick`), and
  reports it at once; told to wait, it waits. A joint phase's end is nature's (the last role done): the
  client draws it inside the phase's contingent link when the robot has started it, and the robot reports
  it (the lead ends a joint action: `hrc.dispatch.validation.History`);
- the **person** leaves for and starts each step when their hint says (at a drawn time in its window:
  the paper's model, the person waits when asked), walks and works for durations drawn inside the best
  plan's contingent links; on a joint action they only walk there: the robot starts and ends it.

`JointRun.play` returns the observed times and every answer with the history it answered; the tests
check them against the task and the executed plan's STNU.
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field

from hrc.dispatch import Dispatcher
from hrc.dispatch.messages import Decision, Observation, RobotStep
from hrc.temporal.graphml import tool_name

Key = tuple[str, str, str, str]  # (agent, action, phase, event)


@dataclass
class JointRun:
    dispatcher: Dispatcher
    rng: random.Random
    times: dict[Key, float] = field(default_factory=dict)
    answers: list[tuple[Decision, frozenset[Key]]] = field(default_factory=list)

    def _bounds(self, plan_id: str, a: Key, b: Key) -> tuple[float, float]:
        """The contingent link between two events' timepoints in the plan (seconds); (0, 0) for a leg
        without travel (already there: a requirement ``[0, 0]``)."""
        entry = self.dispatcher.plan_set.entry(self.dispatcher.plan_set.index(plan_id))
        names = {tool_name(f"{k[0]}.{k[2]}.{k[1]}.{k[3]}") for k in (a, b)}
        for c in entry.stnu.contingents:
            if {c.source, c.target} == names:
                return c.lb / 1000, c.ub / 1000
        zero = {(r.source, r.target) for r in entry.stnu.requirements if {r.source, r.target} == names and r.ub == 0}
        if len(zero) == 2:  # T(b) - T(a) <= 0 and T(a) - T(b) <= 0, as the dispatch form keeps [0, 0]
            return 0.0, 0.0
        raise AssertionError(f"no contingent link {a} -> {b} in {plan_id}")

    def _pick(self, step: RobotStep, now: float) -> float:
        lo = max(step.earliest, now)
        hi = lo + 3.0 if step.latest is None else max(lo, step.latest)
        return round(lo + self.rng.random() * (hi - lo), 3)

    def play(self, limit: int = 400) -> dict[Key, float]:
        d = self.dispatcher
        task = d.task
        human = next(a.id for a in task.agents if a.is_human)
        robot = next(a.id for a in task.agents if not a.is_human)
        lead = {a.id: task.lead(a.id) for a in task.actions if a.joint}
        nature: dict[Key, float] = {}  # contingent events under way -> when they happen
        dec = d.decision
        now = 0.0
        for _ in range(limit):
            self.answers.append((dec, frozenset(d.seen.times)))
            due: list[tuple[float, Key]] = [(t, k) for k, t in nature.items()]
            r = dec.robot
            if isinstance(r, RobotStep):
                due.append((self._pick(r, now), (robot, r.action, r.phase, r.event)))
            h = dec.human
            if isinstance(h, RobotStep) and not any(k[0] == human for k in nature):
                due.append((self._pick(h, now), (human, h.action, h.phase, h.event)))
            if not due:
                break
            t, key = min(due)
            nature.pop(key, None)
            now = t
            self.times[key] = t
            dec = d.observe(Observation(t, key[3], key[0], key[1], key[2]))
            agent, action, phase, event = key
            plan = dec.plan or ""
            if agent == human and event == "depart":
                lo, hi = self._bounds(plan, key, (agent, action, phase, "arrive"))
                nature[(agent, action, phase, "arrive")] = round(t + self.rng.uniform(lo, hi), 3)
            elif event == "start" and (agent == human or lead.get(action) == agent):
                lo, hi = self._bounds(plan, key, (agent, action, phase, "end"))
                nature[(agent, action, phase, "end")] = round(t + self.rng.uniform(lo, hi), 3)
        return self.times
