"""Travel paths and durations for every location pair an agent may travel (motion acquisition, part 1).

Strassmair & Taylor 2014, section V.A ("Motion Acquisition"): the durations of the co-workers' motions
are approximated with motion planners on the workspace instead of being guessed. `plan_paths` plans,
once per compile, every ordered ``(agent, origin, target)`` an agent may travel in any plan: origins are
the agent's start and the locations of the phases of actions it may do, targets the latter.

- Agents with the same clearance (radius + the task's safety margin) share one OMPL PRM* roadmap
  (`hrc.motion.planner.Roadmap`); each unordered location pair is planned once per clearance and the
  path reversed for the other direction (a shortest path reversed is a shortest path). A pair the
  roadmap cannot join falls back to a single BIT* query.
- **Duration model**: constant speed. An agent travels at its nominal ``speed`` along the polyline,
  turning on the spot, with no acceleration phase: ``duration = length / speed``. (Acceleration limits
  would add ``v / a`` per stop; the task format has no acceleration, so none is modelled.)
- Seeds: each roadmap / fallback query gets its own OMPL seed derived from ``(seed, clearance,
  locations)`` by SHA-256, so results do not depend on planning order; same seed, same library.
- **Beside** (``apart``, issue 38): the roadmaps of distinct clearances do not depend on each other (each
  has its own seed), so a caller with a second core can have every other one planned in another process
  at once (`hrc.compile.executors.run_apart`); the library is the same, byte for byte.
- **Cache** (`hrc.caches`, on disk, ``~/.cache/hrc/roadmaps``): a clearance's roadmap and its routes
  are kept, keyed by the obstacles and bounds, the clearance, the seed, the routed locations (ids and
  coordinates) and the digest of this code (planner, world, paths), so a compile of the same map and
  agents (a duration edited, a deadline, a preference) plans nothing again and gets the same paths.

Raises `hrc.errors.UnreachableLocationError` when a location pair has no collision-free path.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import itertools
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

from hrc.caches import cache_folder, disk_load, disk_store, source_digest
from hrc.errors import UnreachableLocationError
from hrc.model import Task
from hrc.motion.planner import Roadmap, plan_points
from hrc.motion.world import World

__all__ = ["Path", "PathLibrary", "agent_pairs", "plan_paths"]

Point = tuple[float, float]


@dataclass(frozen=True, slots=True)
class Path:
    """A planned free-space route of `agent` from location `origin` to `target`.

    `points` is a polyline (m) from the origin's to the target's coordinates; `length` its length (m);
    `duration` the free-space travel time ``length / speed`` (s). ``origin == target`` gives one point.
    `via` is empty for the shortest route and, for a detour (`hrc.motion.detours`), says what it goes
    around.
    """

    agent: str
    origin: str
    target: str
    points: tuple[Point, ...]
    length: float
    duration: float
    via: str = ""

    def reversed(self) -> Path:
        return Path(self.agent, self.target, self.origin, self.points[::-1], self.length, self.duration, self.via)


@dataclass(slots=True)
class PathLibrary:
    """Every planned path of a task, by ``(agent, origin, target)``; plain picklable data.

    `get` serves zero-length paths for ``origin == target`` and counts its calls (`gets`) for the
    cache-hit statistics; `stats` holds planning counts and wall time (not part of equality).
    `roadmaps` keeps each clearance's roadmap (plain data) for detours; `samples` is a per-process
    cache of derived geometry (route samples, conflicts, detours), filled lazily, never compared.
    """

    seed: int
    paths: dict[tuple[str, str, str], Path]
    locations: dict[str, Point]
    stats: dict[str, float] = field(default_factory=dict, compare=False)
    gets: int = field(default=0, compare=False)
    samples: dict = field(default_factory=dict, compare=False, repr=False)
    roadmaps: dict[float, Roadmap] = field(default_factory=dict, compare=False, repr=False)

    def __getstate__(self) -> dict:
        """Pickled without the derived-geometry cache (rebuilt lazily where the library is used)."""
        return {f: ({} if f == "samples" else getattr(self, f)) for f in self.__slots__}

    def __setstate__(self, state: dict) -> None:
        for f, v in state.items():
            setattr(self, f, v)

    def get(self, agent: str, origin: str, target: str) -> Path:
        """The path of `agent` from `origin` to `target` (or the reverse of the one planned the other way,
        e.g. back to the agent's start to wait there); raises KeyError for a pair never planned."""
        self.gets += 1
        if origin == target:
            xy = self.locations[origin]
            return Path(agent, origin, target, (xy,), 0.0, 0.0)
        found = self.paths.get((agent, origin, target))
        if found is None:
            return self.paths[(agent, target, origin)].reversed()
        return found

    def __iter__(self):
        return iter(self.paths.values())


def agent_pairs(task: Task, agent_id: str) -> list[tuple[str, str]]:
    """Ordered ``(origin, target)`` pairs (origin != target) `agent_id` may travel in some plan."""
    targets: list[str] = []
    for action in task.actions:
        if agent_id in action.agents:
            for phase in action.phases:
                if phase.location not in targets:
                    targets.append(phase.location)
    start = task.agent(agent_id).start
    origins = [start] + [t for t in targets if t != start]
    return [(o, t) for o in origins for t in targets if o != t]


def _seed(*parts: object) -> int:
    """A positive 31-bit seed from `parts` (OMPL ignores a seed of 0)."""
    digest = hashlib.sha256(repr(parts).encode()).digest()
    return 1 + int.from_bytes(digest[:4], "big") % (2**31 - 2)


def _cache_key(task: Task, clearance: float, seed: int, ends: list[str], pairs: list[tuple[str, str]]) -> str:
    """Everything a clearance's roadmap and routes are computed from (see the module docstring)."""
    ws = task.workspace
    locs = {loc.id: loc.xy for loc in ws.locations}
    return repr(("roadmaps-1", _code_digest(), ws.bounds, [(o.id, o.polygon) for o in ws.obstacles], clearance,
                 seed, [(e, locs[e]) for e in ends], pairs))


@functools.cache
def _code_digest() -> str:
    return source_digest("hrc.motion.planner", "hrc.motion.world", "hrc.motion.paths")


Planned = tuple[Roadmap, dict[tuple[str, str], "tuple[Point, ...] | None"], int]
"""A clearance's roadmap, its routes by unordered location pair (None: not joined) and the fallback
queries it took (`_plan_clearance`)."""

Apart = Callable[[Callable[[], Planned]], Callable[[], "Planned | None"]]
"""Runs a function in another process at once and returns what waits for its result (None: it failed,
and the caller computes it itself); `plan_paths`' ``apart``."""


def _plan_clearance(task: Task, world: World | None, c: float, seed: int, ends: list[str],
                    pairs: list[tuple[str, str]]) -> Planned:
    """The roadmap of clearance `c` and the routes of `pairs` on it (`plan_paths`)."""
    locs = {loc.id: loc.xy for loc in task.workspace.locations}
    world = world or World(task.workspace)
    roadmap = Roadmap.build(world, c, _seed(seed, c))
    routes = roadmap.routes(world, [locs[e] for e in ends])
    these: dict[tuple[str, str], tuple[Point, ...] | None] = {}
    fallbacks = 0
    for a, b in pairs:
        pts = routes[(ends.index(a), ends.index(b))]
        if pts is None:
            fallbacks += 1
            pts = plan_points(world, locs[a], locs[b], c, _seed(seed, c, a, b))
        these[(a, b)] = None if pts is None else tuple(pts)
    return roadmap, these, fallbacks


def plan_paths(task: Task, seed: int = 0, progress: Callable[[int, int], None] | None = None,
               cache: bool = True, apart: Apart | None = None) -> PathLibrary:
    """Plan every path of `task` (see the module docstring); `progress(done, total)` per planned pair.
    `cache`: keep and reuse each clearance's roadmap and routes on disk (`hrc.caches.cache_folder`).
    `apart`: with two or more roadmaps to plan, every other one is planned through it (in another
    process, at once: the module docstring); the result is the same.

    Cost: one roadmap per distinct clearance plus one roadmap query (and shortening) per unordered
    location pair and clearance; with the cache, on the same map and agents, reading one file per
    clearance. Raises `UnreachableLocationError` naming agent and locations.
    """
    t0, c0 = time.perf_counter(), time.process_time()
    world: World | None = None  # built only to plan (a roadmap from the cache needs none)
    locs = {loc.id: loc.xy for loc in task.workspace.locations}
    wanted: dict[float, list[tuple[str, str]]] = {}  # clearance -> unordered pairs (sorted ids)
    requested = 0
    for agent in task.agents:
        c = agent.radius + task.safety_margin
        for o, t in agent_pairs(task, agent.id):
            requested += 1
            key = (min(o, t), max(o, t))
            if key not in wanted.setdefault(c, []):
                wanted[c].append(key)
    total = sum(len(v) for v in wanted.values())
    planned: dict[tuple[float, str, str], tuple[Point, ...] | None] = {}
    roadmaps = fallbacks = 0
    milestones = 0
    done = 0
    kept: dict[float, Roadmap] = {}
    folder = cache_folder("roadmaps") if cache else None
    cached = 0
    ends_of = {c: sorted({x for pair in wanted[c] for x in pair}) for c in wanted}
    keys = {c: _cache_key(task, c, seed, ends_of[c], wanted[c]) if folder is not None else "" for c in wanted}
    found_of = {c: disk_load(folder, keys[c]) for c in sorted(wanted)}
    todo = [c for c in sorted(wanted) if found_of[c] is None]
    elsewhere: dict[float, Callable[[], Planned | None]] = {}
    if apart is not None and len(todo) > 1:
        for c in todo[1::2]:
            elsewhere[c] = apart(functools.partial(_plan_clearance, task, None, c, seed, ends_of[c], wanted[c]))
    try:
        for c in sorted(wanted):
            found = found_of[c]
            if found is not None:
                kept[c], these = found
                cached += 1
            else:
                got = elsewhere.pop(c)() if c in elsewhere else None
                if got is None:  # here (or the other process failed: the same, planned here)
                    world = world or World(task.workspace)
                    got = _plan_clearance(task, world, c, seed, ends_of[c], wanted[c])
                kept[c], these, more = got
                fallbacks += more
                disk_store(folder, keys[c], (kept[c], these))
            roadmaps += 1
            milestones += len(kept[c].points)
            for a, b in wanted[c]:
                planned[(c, a, b)] = these[(a, b)]
                done += 1
                if progress is not None:
                    progress(done, total)
    finally:
        for wait in elsewhere.values():  # interrupted: the other process is stopped
            with contextlib.suppress(Exception):
                getattr(wait, "cancel", lambda: None)()
    paths: dict[tuple[str, str, str], Path] = {}
    for agent in task.agents:
        c = agent.radius + task.safety_margin
        for o, t in agent_pairs(task, agent.id):
            a, b = min(o, t), max(o, t)
            found = planned[(c, a, b)]
            if found is None:
                raise UnreachableLocationError(
                    f"{task.workspace.source}: {agent.id} cannot reach {t} from {o}: no path keeping {c:g} m "
                    f"(radius {agent.radius:g} + safety margin {task.safety_margin:g}) from obstacles and walls")
            route = found if (o, t) == (a, b) else found[::-1]
            length = sum(math.dist(p, q) for p, q in itertools.pairwise(route))
            paths[(agent.id, o, t)] = Path(agent.id, o, t, route, length, length / agent.speed)
    stats = {"requested": requested, "planned": total, "roadmaps": roadmaps, "milestones": milestones,
             "fallbacks": fallbacks, "cached": cached, "apart": len(todo[1::2]) if apart is not None and len(todo) > 1
             else 0, "seconds": time.perf_counter() - t0,
             "cpu_seconds": time.process_time() - c0}
    return PathLibrary(seed=seed, paths=paths, locations=locs, stats=stats, roadmaps=kept)
