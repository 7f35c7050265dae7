"""What the human action detector knows before it sees anyone: the floor, the person, the durations,
and how far to trust the tracker.

`DetectParams` are the detector's own settings (the tracker's noise it assumes, how sure it must be
before it names a destination, ...); `detector_model` builds a `DetectorModel` from a `Task`: the
walking distance field of every location (`hrc.detect.field`), the person's speed and the bounds of
their manipulation durations (the compile's contingent links). It is built once per task (about
20 ms) and shared, read-only, by every run and every copy of a dispatcher.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType

from hrc.errors import DetectError
from hrc.model import Task

from .field import GeodesicMap, geodesic_map

__all__ = ["DetectParams", "DetectorModel", "detector_model"]


@dataclass(frozen=True, slots=True)
class DetectParams:
    """The detector's settings (see docs/detect.md for each and how it was chosen).

    `sigma` (m): the tracker's position noise (standard deviation per axis) the detector assumes;
    `stand` (m): how far from a location's point a person stands while there; `smooth` (s): positions
    averaged to tell where the person is; `window` (s): positions kept for the change-point fits;
    `commit`: the posterior probability a destination needs before the departure is given out;
    `beta` (1/m): how closely people keep to shortest routes (the goal filter's rationality: each metre
    of progress toward one destination more than toward another multiplies its odds by e^beta);
    `prior` (log-odds): the head start of the best plan's next leg; `min_walk` (m): how far the person
    must have walked from a place before a destination is named from the posterior (a step or two and
    back is no departure), unless only one place is possible or they stopped at one."""

    sigma: float = 0.05
    stand: float = 0.10
    smooth: float = 0.2
    window: float = 4.0
    commit: float = 0.9
    beta: float = 5.0
    prior: float = 3.0
    min_walk: float = 1.0

    def __post_init__(self) -> None:
        for name in ("sigma", "stand", "smooth", "window", "beta", "prior", "min_walk"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) \
                    or value < 0:
                raise DetectError(f"detector parameter {name!r} must be a finite number >= 0, found {value!r}")
        if not 0.5 < self.commit < 1:
            raise DetectError(f"detector parameter 'commit' must lie in (0.5, 1), found {self.commit!r}")
        if self.window < 1.0 or self.smooth > self.window:
            raise DetectError(f"detector parameter 'window' must be at least 1 s and 'smooth' at most the "
                              f"window, found window {self.window!r}, smooth {self.smooth!r}")

    def to_json(self) -> dict[str, float]:
        return {"sigma": self.sigma, "stand": self.stand, "smooth": self.smooth, "window": self.window,
                "commit": self.commit, "beta": self.beta, "prior": self.prior, "min_walk": self.min_walk}


@dataclass(frozen=True, slots=True, eq=False)
class DetectorModel:
    """A task as the detector reads it, for one person: the person (`human`, their `speed` in m/s and `slack`: their
    walks take between 1 and `slack` times the time at full speed), every location's point (`xy`) and
    walking distance field (`geo`), and each (action, phase) the person may do with its duration bounds
    (`durations`, s) and location (`place`); `phases`: each action's phases in order."""

    task: Task
    human: str
    speed: float
    slack: float
    geo: GeodesicMap
    xy: Mapping[str, tuple[float, float]]
    durations: Mapping[tuple[str, str], tuple[float, float]]
    place: Mapping[tuple[str, str], str]
    params: DetectParams
    phases: Mapping[str, tuple[str, ...]]
    joint: frozenset[str] = frozenset()  # the joint actions (issue 37): their start and end are the lead robot's

    def distance(self, location: str, x: float, y: float) -> float:
        """Walking distance (m) from (x, y) to `location`."""
        return self.geo.distance(self.geo.index(location), x, y)

    @property
    def tolerance(self) -> float:
        """s: the error of an event time estimated from positions, three standard deviations of the
        position noise in this person's walking time (`hrc.detect.online.DetectingDispatcher` gives a
        dispatcher the slowest person's as its `bound_tolerance`)."""
        return round(3 * self.params.sigma / self.speed, 3)

    def mid(self, leg: tuple[str, str]) -> float:
        """The middle of the person's duration bounds for `leg` (the mode of the simulator's triangle)."""
        lb, ub = self.durations.get(leg, (0.0, 0.0))
        return (lb + ub) / 2


def detector_model(task: Task, params: DetectParams | None = None, person: str | None = None,
                   geo: GeodesicMap | None = None) -> DetectorModel:
    """The `DetectorModel` of `person` in `task` (default: its first person; a team has one per person,
    issue 37); `DetectError` when the task has no such person. `geo`: share another person's distance
    fields (built for the same radius)."""
    human = next((a for a in task.agents if a.is_human and person in (None, a.id)), None)
    if human is None:
        raise DetectError(f"task {task.name!r} has no human: there is nobody to detect" if person is None else
                          f"task {task.name!r} has no person {person!r}")
    if geo is None:
        geo = geodesic_map(task.workspace, human.radius)
    durations: dict[tuple[str, str], tuple[float, float]] = {}
    place: dict[tuple[str, str], str] = {}
    for action in task.actions:
        for phase in action.phases:
            place[(action.id, phase.id)] = phase.location
            if human.id in action.agents:
                d = phase.duration(human.id)
                durations[(action.id, phase.id)] = (float(d.lb), float(d.ub))
    xy = {loc.id: (float(loc.x), float(loc.y)) for loc in task.workspace.locations}
    phases = {a.id: tuple(p.id for p in a.phases) for a in task.actions}
    return DetectorModel(task, human.id, float(human.speed), float(human.travel_slack), geo,
                         MappingProxyType(xy), MappingProxyType(durations), MappingProxyType(place),
                         params or DetectParams(), MappingProxyType(phases),
                         frozenset(a.id for a in task.actions if a.joint))
