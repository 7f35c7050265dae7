"""The simulated human: a seeded choice and duration model of the person on the shop floor.

Strassmair & Taylor 2014 model the human's durations as contingent (the robot cannot choose them) and
give the person free choice of the next action (section V.B, footnote 3: non-preemptive, a choice is
not reverted). The simulator needs a person who actually makes those choices and takes those times;
`HumanModel` says how, `HumanDraws` is one person's random numbers for one run:

- **choice** (`CHOICES`): ``follow`` takes the next human action of the robot's current plan and leaves
  and starts when that plan says (as a person reading the console would); ``preferred`` takes the first
  action of a fixed preferred order that the task graph allows; ``free`` picks uniformly among them.
  The task graph allows an action when it is not started and every action that must precede it
  (`hrc.plans.must_precede`) is started: a person builds the pile in order.
- **manipulation durations** inside the phase's bounds, ``triangular`` (mode at the middle, default) or
  ``uniform``; with probability `overrun_rate` one goes beyond its upper bound, by up to `overrun_max`
  times the bound (an overrun the STNU does not allow: the dispatcher has to cope).
- **walking pace** per leg, uniform between the agent's speed and ``speed / travel_slack`` (the
  contingent travel bounds of `hrc.compile.temporal_net_creator`).
- **a hidden true duration model** (`truth`, default none): the person's manipulation times lie on these
  bounds (per action and phase, absolute seconds), not on the task's as typed: what ``hrc learn`` should
  find; the same truth then holds for a task with other (learned) bounds. Overruns go beyond it.
- **absences**: with probability `absence_rate` the person leaves once, between two actions, at a time
  uniform in the first `absence_window` seconds, for `absence_seconds` (uniform in the range); with
  probability `leave_for_good_rate` such an absence is for good.

Common random numbers: every quantity is drawn from the run's generator in a fixed order, per action and
phase (not per decision), so that the same seed gives the same person under every policy (the same
durations for the same steps, whoever ends up doing which), which is what makes policies comparable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from hrc.errors import SimulationError
from hrc.model import Interval, Task

__all__ = ["CHOICES", "DURATIONS", "HumanDraws", "HumanModel", "draw_human", "draw_people", "sample_duration",
           "scaled_truth"]

CHOICES = ("follow", "preferred", "free")
DURATIONS = ("triangular", "uniform")


@dataclass(frozen=True, slots=True)
class HumanModel:
    """How the simulated person chooses and how long they take (see the module docstring)."""

    choice: str = "follow"
    preferred: tuple[str, ...] = ()  # action order for "preferred" (default: the task's order)
    durations: str = "triangular"
    overrun_rate: float = 0.0
    overrun_max: float = 0.5
    absence_rate: float = 0.0
    absence_window: float | None = None  # s; default: the task's deadline (or 60 s)
    absence_seconds: tuple[float, float] = (10.0, 30.0)
    leave_for_good_rate: float = 0.0
    truth: tuple[tuple[str, str, float, float], ...] = ()  # hidden true bounds (action, phase, lb, ub); (): the task's

    def __post_init__(self) -> None:
        if self.choice not in CHOICES:
            raise SimulationError(f"--human must be one of {', '.join(CHOICES)}, found {self.choice!r}")
        if self.durations not in DURATIONS:
            raise SimulationError(f"--durations must be one of {', '.join(DURATIONS)}, found {self.durations!r}")
        for name in ("overrun_rate", "absence_rate", "leave_for_good_rate"):
            value = getattr(self, name)
            if not (0.0 <= value <= 1.0):
                raise SimulationError(f"--{name.replace('_', '-')} must be in [0, 1], found {value:g}")
        if not (self.overrun_max >= 0 and math.isfinite(self.overrun_max)):
            raise SimulationError(f"--overrun-max must be a finite number >= 0, found {self.overrun_max:g}")
        for action, phase, lb, ub in self.truth:
            if not (0 <= lb <= ub and math.isfinite(ub)):
                raise SimulationError(f"the true duration of {action}.{phase} must be 0 <= LB <= UB, "
                                      f"found {lb:g} {ub:g}")
        lo, hi = self.absence_seconds
        if not (0 <= lo <= hi and math.isfinite(hi)):
            raise SimulationError(f"--absence-seconds must be 0 <= LO <= HI, found {lo:g} {hi:g}")

    def check(self, task: Task) -> None:
        """Raise `SimulationError` if `preferred` or `truth` names an action or phase the task does not have."""
        known = set(task.action_ids)
        for a in self.preferred:
            if a not in known:
                raise SimulationError(f"--prefer names {a!r}, which is not an action of {task.name} "
                                      f"(expected some of: {', '.join(task.action_ids)})")
        phases = {(a.id, p.id) for a in task.actions for p in a.phases}
        for action, phase, _, _ in self.truth:
            if (action, phase) not in phases:
                raise SimulationError(f"the true durations name {action}.{phase}, not a phase of {task.name}")

    def to_json(self) -> dict:
        return {"choice": self.choice, "preferred": list(self.preferred), "durations": self.durations,
                "overrun_rate": self.overrun_rate, "overrun_max": self.overrun_max,
                "absence_rate": self.absence_rate, "absence_window": self.absence_window,
                "absence_seconds": list(self.absence_seconds), "leave_for_good_rate": self.leave_for_good_rate,
                **({"truth": [list(x) for x in self.truth]} if self.truth else {})}  # as before by default

    def true_bounds(self, action: str, phase: str, bounds: Interval) -> Interval:
        """Where the person's manipulation durations at `action`.`phase` really lie (the hidden truth
        `hrc learn` is measured against): `truth`'s bounds for it, else the task's `bounds`."""
        for a, p, lb, ub in self.truth:
            if (a, p) == (action, phase):
                return Interval(lb, ub)
        return bounds


def scaled_truth(task: Task, scale: float) -> tuple[tuple[str, str, float, float], ...]:
    """A hidden truth (`HumanModel.truth`): the person's bounds of `task` times `scale` (``--true-scale``)."""
    if not (scale > 0 and math.isfinite(scale)):
        raise SimulationError(f"--true-scale must be a finite number > 0, found {scale:g}")
    human = next(a.id for a in task.agents if a.is_human)
    return tuple((a.id, p.id, p.duration(human).lb * scale, p.duration(human).ub * scale)
                 for a in task.actions if human in a.agents for p in a.phases)


def sample_duration(bounds: Interval, u: float, shape: str) -> float:
    """The `u`-quantile (0 <= u < 1) of the duration distribution on ``[lb, ub]``.

    >>> sample_duration(Interval(2, 4), 0.5, "triangular")
    3.0
    """
    lb, ub = bounds.lb, bounds.ub
    if ub <= lb:
        return lb
    if shape == "uniform":
        return lb + u * (ub - lb)
    mode = (lb + ub) / 2  # symmetric triangle: inverse CDF
    if u < 0.5:
        return lb + math.sqrt(u * (ub - lb) * (mode - lb))
    return ub - math.sqrt((1 - u) * (ub - lb) * (ub - mode))


@dataclass(frozen=True, slots=True)
class HumanDraws:
    """One person's random numbers for one run, drawn up front (common random numbers across policies).

    `durations[(action, phase)]` is the person's manipulation time (s) if they do that phase, already
    with any overrun; `overrun` the phases that overrun; `pace[(action, phase)]` the factor (>= 1) by
    which their walk to that phase is slower than at full speed; `choice` one uniform number per choice;
    `absence` ``(at, seconds)`` or None, ``seconds`` None for good; `robot[(action, phase)]` the robot's
    duration quantile for that phase (the robot is part of the same run).
    """

    durations: dict[tuple[str, str], float]
    overrun: frozenset[tuple[str, str]]
    pace: dict[tuple[str, str], float]
    choice: tuple[float, ...]
    absence: tuple[float, float | None] | None
    robot: dict[tuple[str, str], float]


def draw_human(task: Task, model: HumanModel, rng: np.random.Generator) -> HumanDraws:
    """Draw everything random about one run, in a fixed order (see `HumanDraws`)."""
    human = next(a for a in task.agents if a.is_human)
    durations: dict[tuple[str, str], float] = {}
    overrun: set[tuple[str, str]] = set()
    pace: dict[tuple[str, str], float] = {}
    robot: dict[tuple[str, str], float] = {}
    for action in task.actions:
        for phase in action.phases:
            key = (action.id, phase.id)
            u, v, w, p, r = rng.random(5)
            if human.id in action.agents:
                bounds = model.true_bounds(action.id, phase.id, phase.duration(human.id))
                d = sample_duration(bounds, float(u), model.durations)
                if v < model.overrun_rate:
                    d = bounds.ub * (1.0 + float(w) * model.overrun_max)
                    overrun.add(key)
                durations[key] = d
            pace[key] = 1.0 + float(p) * (human.travel_slack - 1.0)
            robot[key] = float(r)
    choice = tuple(float(x) for x in rng.random(len(task.actions) + 1))
    absence = _absence(task, model, rng)
    return HumanDraws(durations, frozenset(overrun), pace, choice, absence, robot)


def _absence(task: Task, model: HumanModel, rng: np.random.Generator) -> tuple[float, float | None] | None:
    """One person's absence (`HumanDraws.absence`) from four numbers of `rng`."""
    a, b, c, d = rng.random(4)
    if a >= model.absence_rate:
        return None
    window = model.absence_window if model.absence_window is not None else (task.deadline or 60.0)
    lo, hi = model.absence_seconds
    return float(b) * window, None if c < model.leave_for_good_rate else lo + float(d) * (hi - lo)


def draw_people(task: Task, model: HumanModel, rng: np.random.Generator) -> dict[str, HumanDraws]:
    """Every person's random numbers for one run of a team (issue 37), by person id, drawn in a fixed order
    (per action and phase: each person's four numbers in task order, then the robots' one quantile, shared
    by every robot; then each person's choices): the same people under every policy, as `draw_human` for
    one person; then each person's absence, in task order (after everything else: a run without absences
    draws what it drew before they were simulated for a team, issue 37)."""
    people = [a for a in task.agents if a.is_human]
    durations: dict[str, dict[tuple[str, str], float]] = {p.id: {} for p in people}
    overrun: dict[str, set[tuple[str, str]]] = {p.id: set() for p in people}
    pace: dict[str, dict[tuple[str, str], float]] = {p.id: {} for p in people}
    robot: dict[tuple[str, str], float] = {}
    for action in task.actions:
        for phase in action.phases:
            key = (action.id, phase.id)
            for person in people:
                u, v, w, p = rng.random(4)
                if person.id in action.agents:
                    bounds = model.true_bounds(action.id, phase.id, phase.duration(person.id))
                    d = sample_duration(bounds, float(u), model.durations)
                    if v < model.overrun_rate:
                        d = bounds.ub * (1.0 + float(w) * model.overrun_max)
                        overrun[person.id].add(key)
                    durations[person.id][key] = d
                pace[person.id][key] = 1.0 + float(p) * (person.travel_slack - 1.0)
            robot[key] = float(rng.random())
    out = {}
    for person in people:
        choice = tuple(float(x) for x in rng.random(len(task.actions) + 1))
        out[person.id] = HumanDraws(durations[person.id], frozenset(overrun[person.id]), pace[person.id], choice,
                                    None, robot)
    for person in people:
        out[person.id] = replace(out[person.id], absence=_absence(task, model, rng))
    if not out:  # robots alone: their quantiles only
        out[""] = HumanDraws({}, frozenset(), {}, (), None, robot)
    return out
