"""What the dispatcher knows of a person (a team's: one `Situation` per person, issue 37), as the detector
reads it: the leg under way, where the person is, what they may do next (`Situation`, from `situation`).

The detector never gives out an event no remaining plan allows: it asks the dispatcher's history whether
the task allows an event now (`Situation.allows`, what `Dispatcher.human_options` asks for the console's
buttons) and, for what comes after, reads the human's remaining legs in every remaining plan (`Future`):
the legs at the place where the person stands (two actions at one place: no walk between them) and then
the first leg elsewhere, whose location is where the person will walk to. Read-only: it imports the
dispatcher's views, never the reverse (DESIGN.md).

Cost: the cheap parts at once; the futures (a few numpy operations over the remaining plans' next
actions in the dispatch form's ``seq``) and each question `allows` answers only when the filter asks, and
once per dispatcher state (the caller keeps one `Situation` per decision).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from hrc.dispatch import Dispatcher, Observation, RobotStep, WaitFor
from hrc.errors import DispatchError

from .model import DetectorModel

__all__ = ["Future", "Situation", "situation"]

Leg = tuple[str, str]


@dataclass(frozen=True, slots=True)
class Future:
    """What the person may do next, in one or more remaining plans: `legs` (action, phase) in order, all
    at the place where the person stands but the last, which is at `destination` (None: every leg left
    is at that place); `rank`: 0 for the dispatcher's best plan's, else the best compile rank among the
    remaining plans that have it."""

    legs: tuple[Leg, ...]
    destination: str | None
    rank: int


class Situation:
    """The person as the dispatcher has them now.

    `leg`: the leg under way (seen, not ended) or None; `last`: its last event seen; `since`: the time of
    the person's last event (0 before any); `start`: when the leg under way started (None: not yet);
    `place`: where the person stands or last stood (a location id: the leg's location once arrived, its
    origin while walking, the start before anything); `hint`: the best plan's next step for the person,
    ``(action, phase, event, earliest)``, or a ``WaitFor`` string, or None; `away`: the person is away (the
    detector waits); `now`: the dispatcher's clock (its last message). Asked for: `futures` (what may come
    after the leg under way, or now when none is, best first), `allows` (the task allows the person's event
    now), `ready` (when the task graph let a leg start)."""

    def __init__(self, model: DetectorModel, d: Dispatcher) -> None:
        self._model = model
        self._d = d
        human = model.human
        history = d.seen
        self._history = history
        legs = history.legs.get(human, ())
        self._legs = legs
        current = history.current(human)
        self.leg: Leg | None = current
        self.last: str | None = history.last_event(human, *current) if current is not None else None
        self.since: float = max((t for (a, _, _, _), t in history.times.items() if a == human), default=0.0)
        self.start: float | None = history.times.get((human, *current, "start")) if current is not None else None
        if current is not None and self.last in ("arrive", "start"):
            self.place: str = model.place[current]
        else:
            done = [leg for leg in legs if leg != current]
            self.place = model.place[done[-1]] if done else model.task.agent(human).start
        decision = d.decision
        # a team's person reads their own entry of the answer (issue 37); one person, `Decision.human`
        step = decision.human if decision.people is None else decision.people.get(human)
        self.hint: tuple[str, str, str, float] | str | None = None
        if isinstance(step, RobotStep):
            self.hint = (step.action, step.phase, step.event, float(step.earliest))
        elif isinstance(step, WaitFor):
            self.hint = str(step)
        self.away: bool = human in history.absent  # this person (a team's others may be away meanwhile)
        self.now: float = d.now
        self._allowed: dict[tuple[str, str, str], bool] = {}

    def with_since(self, since: float) -> Situation:
        """This situation with the person's last event at `since` (the detector's estimate of it)."""
        other = copy.copy(self)
        other.since = since
        return other

    def allows(self, action: str, phase: str, event: str) -> bool:
        """Whether the task allows the person's `event` of `action`.`phase` now (`History.add` accepts it)."""
        key = (action, phase, event)
        if key not in self._allowed:
            try:
                self._history.add(Observation(self.now, event, self._model.human, action, phase))
                self._allowed[key] = self._model.human not in self._history.absent
            except DispatchError:
                self._allowed[key] = False
        return self._allowed[key]

    def ready(self, leg: Leg) -> float | None:
        """When the task graph let `leg` start: the latest end of its predecessors but the leg under way
        (0: none), None while another has not ended."""
        latest = 0.0
        for p in self._model.task.precedence:
            before = (p.before.action, p.before.phase)
            if (p.after.action, p.after.phase) != leg or before == self.leg:
                continue
            ends = [t for (_, a, ph, e), t in self._history.times.items() if (a, ph) == before and e == "end"]
            if not ends:
                return None
            latest = max(latest, ends[0])
        return latest

    @cached_property
    def futures(self) -> tuple[Future, ...]:
        """The distinct futures of the remaining plans, best first (see `Future`)."""
        model, d = self._model, self._d
        task = model.task
        form = d.plan_set.form
        g = task.agent_ids.index(model.human)
        plans = d.remaining
        if not len(plans):
            return ()
        seen = self._history.actions_seen(model.human)
        k = len(seen) - (1 if seen and self._unfinished(seen[-1]) else 0)
        here = self.place if self.leg is None else model.place[self.leg]
        width = min(form.seq.shape[2] - k, 4)  # enough actions for the legs here and the next one elsewhere
        if width <= 0:
            return ()
        rows = np.asarray(form.seq[plans, g, k:k + width])
        phases = model.phases
        skip = len(self._legs) - sum(len(phases[a]) for a in seen[:k])  # legs of the first action begun
        uniq, first = np.unique(rows, axis=0, return_index=True)
        best = int(np.searchsorted(plans, d.best_index)) if d.best_index >= 0 else -1
        out: dict[tuple[Leg, ...], Future] = {}
        for u in np.argsort(first, kind="stable").tolist():
            actions = [task.action_ids[int(a)] for a in uniq[u] if a >= 0]
            plan_legs = [(a, p) for a in actions for p in phases[a]]
            rest = plan_legs[skip:]
            chosen: list[Leg] = []
            destination: str | None = None
            for leg in rest:
                chosen.append(leg)
                if model.place[leg] != here:
                    destination = model.place[leg]
                    break
            if not chosen:
                continue
            key = tuple(chosen)
            rank = int(first[u]) + 1
            if best >= 0 and np.array_equal(rows[best], uniq[u]):
                rank = 0
            if key not in out or rank < out[key].rank:
                out[key] = Future(key, destination, rank)
        return tuple(sorted(out.values(), key=lambda f: f.rank))

    def _unfinished(self, action: str) -> bool:
        """Whether the person has legs of `action` still to do (or under way)."""
        done = [leg for leg in self._legs if leg[0] == action and leg != self.leg]
        return len(done) < len(self._model.phases[action])


def situation(model: DetectorModel, d: Dispatcher) -> Situation:
    """The `Situation` of the person under dispatcher `d`."""
    return Situation(model, d)
