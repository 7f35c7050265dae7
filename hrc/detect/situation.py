"""What the dispatcher knows of the person, as the detector reads it: the leg under way, where the person
is, what they may do next (`Situation`, from `situation`).

The detector never gives out an event no remaining plan allows: it reads the dispatcher's options
(`Dispatcher.human_options`, the console's buttons) and, for what comes after, the human's remaining
legs in every remaining plan (`Future`): the legs at the place where the person stands (two actions at
one place: no walk between them) and then the first leg elsewhere, whose location is where the person
will walk to. Read-only: it imports the dispatcher's views, never the reverse (DESIGN.md).

Cost: a few numpy operations over the remaining plans' sequences (the dispatch form's ``seq``) and one
`human_options` call, made once per dispatcher state (`Situation` is cached on the decision object by
the caller).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hrc.dispatch import Dispatcher, RobotStep, WaitFor

from .model import DetectorModel

__all__ = ["Future", "Situation", "situation"]

Leg = tuple[str, str]


@dataclass(frozen=True, slots=True)
class Future:
    """What the person may do next, in one or more remaining plans: `legs` (action, phase) in order, all
    at the place where the person stands but the last, which is at `destination` (None: every leg left
    is at that place); `rank`: the best position among the remaining plans of one that has it (0: the
    dispatcher's best plan)."""

    legs: tuple[Leg, ...]
    destination: str | None
    rank: int


@dataclass(frozen=True, slots=True)
class Situation:
    """The person as the dispatcher has them now (see the module docstring).

    `leg`: the leg under way (seen, not ended) or None; `last`: its last event seen; `since`: the time of
    the person's last event (0 before any); `start`: when the leg under way started (None: not yet);
    `place`: where the person stands or last stood (a location id: the leg's location once arrived, its
    origin while walking, the start before anything); `options`: the (action, phase, event) the person
    may report now; `futures`: what may come after the leg under way (or now, when none is), best rank
    first; `hint`: the best plan's next step for the person, ``(action, phase, event, earliest)``, or a
    ``WaitFor`` string, or None; `ready`: per leg, when the task graph let it start (the latest end of
    its predecessors but the leg under way, None: another has not ended); `away`: the person is away (the
    detector waits); `planned`: when the best plan has the person leave for their next place (s; None:
    it does not say), as the console shows it to them; `now`: the dispatcher's clock (its last message)."""

    leg: Leg | None
    last: str | None
    since: float
    start: float | None
    place: str
    options: frozenset[tuple[str, str, str]]
    futures: tuple[Future, ...]
    hint: tuple[str, str, str, float] | str | None
    ready: dict[Leg, float | None]
    away: bool
    planned: float | None = None
    now: float = 0.0


def situation(model: DetectorModel, d: Dispatcher) -> Situation:
    """The `Situation` of the person under dispatcher `d` (see the class)."""
    task = model.task
    human = model.human
    history = d.seen
    legs = history.legs.get(human, ())
    times = history.times
    current = history.current(human)
    last = history.last_event(human, *current) if current is not None else None
    since = max((t for (a, _, _, _), t in times.items() if a == human), default=0.0)
    start = times.get((human, *current, "start")) if current is not None else None
    if current is not None and last in ("arrive", "start"):
        place = model.place[current]
    elif legs:
        done = [leg for leg in legs if leg != current]
        place = model.place[done[-1]] if done else task.agent(human).start
    else:
        place = task.agent(human).start
    options = frozenset((o.action, o.phase, o.event) for o in d.human_options())
    futures = _futures(model, d, legs, current, place if current is None else model.place[current])
    hint_step = d.decision.human
    hint: tuple[str, str, str, float] | str | None = None
    if isinstance(hint_step, RobotStep):
        hint = (hint_step.action, hint_step.phase, hint_step.event, float(hint_step.earliest))
    elif isinstance(hint_step, WaitFor):
        hint = str(hint_step)
    ready: dict[Leg, float | None] = {}
    wanted = {current} if current is not None else set()
    wanted |= {leg for f in futures for leg in f.legs}
    for leg in wanted:
        if leg is None:
            continue
        ends = []
        for p in task.precedence:
            if (p.after.action, p.after.phase) == leg and (p.before.action, p.before.phase) != current:
                before = (p.before.action, p.before.phase)
                t = next((v for (_, a, ph, e), v in times.items() if (a, ph) == before and e == "end"), None)
                ends.append(t)
        ready[leg] = None if any(t is None for t in ends) else max([0.0, *[t for t in ends if t is not None]])
    planned = None
    if futures and futures[0].rank == 0 and futures[0].destination is not None:
        planned = d.planned_times().get((human, *futures[0].legs[-1], "depart"))
    return Situation(current, last, since, start, place, options, futures, hint, ready, history.away, planned,
                     d.now)


def _futures(model: DetectorModel, d: Dispatcher, legs: tuple[Leg, ...], current: Leg | None,
             here: str) -> tuple[Future, ...]:
    """The distinct futures of the remaining plans, best rank first (see `Future`)."""
    task = model.task
    form = d.plan_set.form
    g = task.agent_ids.index(model.human)
    plans = d.candidate_indices
    if not len(plans):
        return ()
    rows = np.asarray(form.seq[plans, g, :])
    uniq, first = np.unique(rows, axis=0, return_index=True)
    out: dict[tuple[Leg, ...], Future] = {}
    skip = len(legs) if current is None else len(legs)  # the legs seen (the one under way included)
    for k in np.argsort(first, kind="stable").tolist():
        seq = [task.action_ids[int(a)] for a in uniq[k] if a >= 0]
        plan_legs = [(a, p.id) for a in seq for p in task.action(a).phases]
        rest = plan_legs[skip:]
        if not rest:
            continue
        chosen: list[Leg] = []
        destination: str | None = None
        for leg in rest:
            chosen.append(leg)
            if model.place[leg] != here:
                destination = model.place[leg]
                break
        key = tuple(chosen)
        if key not in out:
            out[key] = Future(key, destination, int(first[k]))
    return tuple(sorted(out.values(), key=lambda f: f.rank))
