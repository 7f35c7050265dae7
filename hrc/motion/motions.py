"""A plan's motions: each agent's travel per leg, along the shortest route, a detour, or via a place to wait.

Strassmair & Taylor 2014, section V.A: motion durations "vary from plan to plan as the co-workers
influence each other". Here a motion's *duration* depends only on its route; what the co-worker costs is
a *passing order* at each place their occupancies meet (`hrc.motion.conflicts`), which the temporal net
carries as a constraint. A leg's `Route` is the shortest path, a detour round the co-worker
(`hrc.motion.detours`), or a stop on the way at a *waiting place* (`park`: the agent's own start, its
home), where it waits out of the way while the co-worker uses the places it would otherwise block.
"""

from __future__ import annotations

from dataclasses import dataclass

from hrc.model import Plan, Task
from hrc.motion.paths import Path, PathLibrary
from hrc.plans import agent_legs

__all__ = ["Motion", "Route", "plan_motions"]

Point = tuple[float, float]


@dataclass(frozen=True, slots=True)
class Route:
    """How an agent travels one leg: along `path`, or along `path` to the waiting place `park`, then,
    after waiting there as long as the plan needs, along `onward` to the leg's target; at `speed` (m/s)
    when set (the robot in a reduced-speed zone, `hrc.motion.separation`), else at the agent's own."""

    path: Path
    park: str = ""
    onward: Path | None = None
    speed: float = 0.0

    @property
    def time(self) -> float:
        if self.speed:
            return (self.path.length + (self.onward.length if self.onward is not None else 0.0)) / self.speed
        return self.path.duration + (self.onward.duration if self.onward is not None else 0.0)

    @property
    def points(self) -> tuple[Point, ...]:
        return self.path.points + (self.onward.points[1:] if self.onward is not None else ())


@dataclass(frozen=True, slots=True)
class Motion:
    """One travel of one agent in a plan (s): the robot drives its route in exactly `time`; a person
    walks it in ``[time, time * travel_slack]`` (`hrc.model.Agent.travel_slack`).

    `free_time` is the time along the shortest route; `time` the moving time along the route taken
    (`points`), longer for a detour, whose `via` says what it goes round (empty for the shortest route),
    or for a stop at the waiting place `park`, reached after `park_time` of the moving time; `speed` is
    the reduced speed the robot drives it at (m/s; 0: its own speed).
    """

    agent: str
    leg: int
    origin: str
    target: str
    free_time: float
    time: float
    via: str = ""
    points: tuple[Point, ...] = ()
    park: str = ""
    park_time: float = 0.0
    speed: float = 0.0

    @property
    def detour(self) -> bool:
        return bool(self.via)


Routes = dict[tuple[str, int], Route]
"""Route choices by ``(agent, leg index)``; legs not in it take the shortest route."""


def plan_motions(task: Task, plan: Plan, paths: PathLibrary, routes: Routes | None = None) -> tuple[Motion, ...]:
    """One `Motion` per leg of every agent (`agent_legs` order, agents in task order). A leg on its
    shortest route moves as every leg of that agent, index and places does, in any plan: those motions
    are kept per process (in ``paths.samples``; a compile asks for them hundreds of thousands of times)."""
    routes = routes or {}
    out = []
    shortest = paths.samples.setdefault(("motions",), {})
    for agent in task.agents:
        for leg in agent_legs(task, plan, agent.id):
            route = routes.get((agent.id, leg.index))
            if route is None:
                key = (agent.id, leg.index, leg.origin, leg.location)
                motion = shortest.get(key)
                if motion is None:
                    motion = shortest[key] = _motion(agent.id, leg.index, leg.origin, leg.location, paths, None)
                else:
                    paths.gets += 1  # as `_motion` counts it
                out.append(motion)
            else:
                out.append(_motion(agent.id, leg.index, leg.origin, leg.location, paths, route))
    return tuple(out)


def _motion(agent: str, index: int, origin: str, target: str, paths: PathLibrary, route: Route | None) -> Motion:
    free = paths.get(agent, origin, target)
    route = route or Route(free)
    park_time = 0.0
    if route.park:
        park_time = route.path.length / route.speed if route.speed else route.path.duration
    return Motion(agent, index, origin, target, free.duration, route.time, route.path.via, route.points, route.park,
                  park_time, route.speed)
