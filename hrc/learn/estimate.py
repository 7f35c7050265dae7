"""What the runs say about the task's numbers: per action phase and agent, the observed manipulation
durations and travel times, bounds for them, overruns of today's bounds, and the sensing path's delays.

"The durations can be learned from observing human robot teams in the particular workspace"
(Strassmair & Taylor 2014, section V.A). A phase's **duration** is ``T(end) - T(start)`` of one agent's
manipulation in one run; its **travel** is ``T(arrive) - T(depart)`` less any wait at a waiting place
(``T(unpark) - T(park)``). Its new bound is a distribution-free tolerance interval
(`hrc.learn.tolerance`): ``[x(r), x(n+1-r)]`` covers at least `coverage` of the durations with
probability `confidence`, widened outward to the hundredth of a second (`ROUND`) so that the written
number never narrows it.

**Guard rails.** Too few observations for that promise (`hrc.learn.tolerance.min_observations`) keep
the old bound, with a warning; a narrower guess is never written. By default only the person's
durations get new bounds (``agents=("human",)``): a robot's durations are *controllable* (the
dispatcher tells it when to end within its bounds, so its observed times say what it was told, not
what it can do); its observations are still reported.

An **overrun** is an observed duration outside today's bounds (below ``lb`` or above ``ub``): each
breaks the contingent link the compile's promise rests on. The **observation delay** of a motion
detector is ``at - t`` of each event it gave (given with the position of time `at`, estimated to have
happened at `t`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from hrc.learn.runs import Run
from hrc.learn.tolerance import min_observations, tolerance_interval
from hrc.model import Interval, Task

__all__ = ["ROUND", "Delays", "Learned", "PhaseBound", "Travel", "durations_of", "learn", "phase_bound",
           "travels_of"]

ROUND = 0.01
"""s: new bounds are rounded outward to this (the task file's readable resolution; never narrower)."""

Key = tuple[str, str, str]
"""(agent, action, phase)."""


@dataclass(frozen=True, slots=True)
class PhaseBound:
    """One agent's manipulation time at one phase: the sorted `samples` (s), the bound the task had
    (`old`) and the one to write (`new`: `old` when `kept`, with `why`); `order` ``r`` and the achieved
    `confidence` of the tolerance interval; `below` / `above`: observations outside `old`."""

    agent: str
    action: str
    phase: str
    samples: tuple[float, ...]
    old: Interval
    new: Interval
    kept: bool
    why: str
    order: int
    confidence: float
    below: int
    above: int

    @property
    def n(self) -> int:
        return len(self.samples)

    @property
    def overruns(self) -> int:
        return self.below + self.above

    @property
    def changed(self) -> bool:
        return (self.new.lb, self.new.ub) != (self.old.lb, self.old.ub)


@dataclass(frozen=True, slots=True)
class Travel:
    """One agent's legs to one phase: the observed travel times (s, sorted) and their quantiles."""

    agent: str
    action: str
    phase: str
    samples: tuple[float, ...]

    def quantile(self, q: float) -> float:
        return float(np.quantile(self.samples, q))


@dataclass(frozen=True, slots=True)
class Delays:
    """A motion detector's delays (s, ``at - t``) per event kind, sorted."""

    by_event: tuple[tuple[str, tuple[float, ...]], ...]


@dataclass(frozen=True, slots=True)
class Learned:
    """Everything `learn` found: per phase and agent the bounds, the travels, the detector's delays, the
    settings, the number of runs and the warnings (one line each)."""

    coverage: float
    confidence: float
    min_n: int
    runs: int
    bounds: tuple[PhaseBound, ...]
    travels: tuple[Travel, ...]
    delays: Delays
    warnings: tuple[str, ...]

    def bound(self, agent: str, action: str, phase: str) -> PhaseBound:
        for b in self.bounds:
            if (b.agent, b.action, b.phase) == (agent, action, phase):
                return b
        raise KeyError((agent, action, phase))


def _outward(lo: float, hi: float) -> Interval:
    """``[lo, hi]`` widened to multiples of `ROUND` (never narrower: floor the lower, ceil the upper)."""
    steps = 1 / ROUND
    lb = math.floor(round(lo * steps, 6)) / steps
    ub = math.ceil(round(hi * steps, 6)) / steps
    return Interval(max(0.0, lb), ub)


def durations_of(runs: Iterable[Run]) -> dict[Key, list[float]]:
    """Every observed manipulation time, by (agent, action, phase), in run order."""
    out: dict[Key, list[float]] = {}
    for run in runs:
        start: dict[Key, float] = {}
        for e in run.events:
            key = (e.agent, e.action, e.phase)
            if e.event == "start":
                start[key] = e.t
            elif e.event == "end" and key in start:
                out.setdefault(key, []).append(e.t - start.pop(key))
    return out


def travels_of(runs: Iterable[Run]) -> dict[Key, list[float]]:
    """Every observed leg's travel time (less waits at a waiting place), by (agent, action, phase)."""
    out: dict[Key, list[float]] = {}
    for run in runs:
        depart: dict[Key, float] = {}
        parked: dict[Key, float] = {}
        waited: dict[Key, float] = {}
        for e in run.events:
            key = (e.agent, e.action, e.phase)
            if e.event == "depart":
                depart[key], waited[key] = e.t, 0.0
            elif e.event == "park":
                parked[key] = e.t
            elif e.event == "unpark" and key in parked:
                waited[key] = waited.get(key, 0.0) + e.t - parked.pop(key)
            elif e.event == "arrive" and key in depart:
                out.setdefault(key, []).append(e.t - depart.pop(key) - waited.pop(key, 0.0))
    return out


def phase_bound(key: Key, samples: Sequence[float], old: Interval, coverage: float, confidence: float,
                min_n: int) -> PhaseBound:
    """The bound to write for one phase and agent (see the module docstring)."""
    xs = tuple(sorted(samples))
    below = sum(1 for x in xs if x < old.lb - 1e-9)
    above = sum(1 for x in xs if x > old.ub + 1e-9)
    got = tolerance_interval(xs, coverage, confidence) if xs else None
    if got is None:
        why = f"{len(xs)} observations, fewer than the {min_n} a ({coverage:g}, {confidence:g}) bound needs: kept"
        return PhaseBound(*key, xs, old, old, True, why, 0, 0.0, below, above)
    lo, hi, r, conf = got
    return PhaseBound(*key, xs, old, _outward(lo, hi), False, "", r, conf, below, above)


def learn(task: Task, runs: Sequence[Run], coverage: float = 0.90, confidence: float = 0.95,
          agents: Sequence[str] | None = None) -> Learned:
    """Bounds, travels, overruns and delays from `runs` of `task` (module docstring). `agents`: whose
    bounds may change (default: the human's); the others are reported with their old bounds kept."""
    min_n = min_observations(coverage, confidence)
    human = next(a.id for a in task.agents if a.is_human)
    learnable = set(agents if agents is not None else (human,))
    durations = durations_of(runs)
    bounds: list[PhaseBound] = []
    warnings: list[str] = []
    for action in task.actions:
        for phase in action.phases:
            for agent in action.agents:
                key = (agent, action.id, phase.id)
                old = phase.duration(agent)
                b = phase_bound(key, durations.get(key, ()), old, coverage, confidence, min_n)
                if agent not in learnable and not b.kept:
                    b = PhaseBound(*key, b.samples, old, old, True, "controllable (the robot is told when to "
                                   "end): reported, not learned", 0, 0.0, b.below, b.above)
                elif b.kept and agent in learnable:
                    warnings.append(f"{agent} {action.id}.{phase.id}: {b.why} [{old.lb:g}, {old.ub:g}]")
                bounds.append(b)
    travels = [Travel(*k, tuple(sorted(v))) for k, v in sorted(travels_of(runs).items())]
    by_event: dict[str, list[float]] = {}
    for run in runs:
        for e in run.events:
            if e.at is not None:
                by_event.setdefault(e.event, []).append(e.at - e.t)
    delays = Delays(tuple((ev, tuple(sorted(v))) for ev, v in sorted(by_event.items())))
    return Learned(coverage, confidence, min_n, len(runs), tuple(bounds), tuple(travels), delays, tuple(warnings))
