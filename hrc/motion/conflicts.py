"""Where the two co-workers can meet in one plan, and the two ways of keeping them apart there.

Strassmair & Taylor 2014, section V.A: "in a particular plan one worker might block the other's way".
This module turns that into constraints the temporal net can carry, for every human timing at once
(not one nominal schedule), in four steps:

1. **Occupancies.** In a plan each agent is, one after the other, *staying* at a location (its start
   until it first departs; each phase's location from its arrival until it departs again, waiting and
   manipulating there; a waiting place on a leg that stops at one, `hrc.motion.motions.Route`) and
   *travelling* a route between two of them. An occupancy is bounded by two of the agent's timepoints
   (`TimeRef`): a stay by ``arrive`` (or the origin, or ``park``) and the next ``depart`` (or
   ``unpark``, or the ``end`` of its last phase: an agent with nothing left to do steps out of the way);
   a travel by its ``depart`` (or ``unpark``) and ``arrive`` (or ``park``).
2. **Motion model.** The robot drives its route at its speed without stopping: it is at arc length `s`
   exactly at ``T(depart) + s / v_r`` (it waits only where it stands, before departing or after
   arriving). A person walks at most at their speed and may dawdle anywhere within the contingent travel
   time, so the human is at arc length `u` some time within ``[T(depart) + u / v_h,
   T(arrive) - (L - u) / v_h]`` and nothing more is assumed.
3. **Conflict set.** Two discs overlap when their centres are closer than
   ``reach = r_human + r_robot + safety_margin`` (with the task's `safety`, ``r_human + r_robot + S_p(v)``,
   the protective separation at the robot's speed there, `hrc.motion.separation`). For a robot travel and a
   human travel the conflict set is ``C = {(s, u): |P_r(s) - P_h(u)| < reach}``; for a travel and a stay,
   the arc lengths of the travel within reach of the location; two stays conflict when their locations are
   within reach. Each connected component of C is one `Conflict`, since the two can pass each other in a
   different order at each place where their routes meet.
4. **Two separations per conflict.** A schedule keeps the discs apart at a component iff one agent is
   through it before the other gets there. With the motion model this is one difference constraint on
   the agents' timepoints, `Separation` ``T(later) - T(earlier) >= gap``:

   - *robot first*: for every ``(s, u)`` in the component, ``T_r(depart) + s / v_r <= T_h(depart) + u / v_h``,
     so ``T_h(depart) - T_r(depart) >= max(s / v_r - u / v_h)``;
   - *human first*: for every ``(s, u)``, ``T_r(depart) + s / v_r >= T_h(arrive) - (L - u) / v_h``, so
     ``T_r(depart) - T_h(arrive) >= max(-(L - u) / v_h - s / v_r)``;

   and for stays the same with the stay's bounding timepoints (robot first: the robot is through before
   the human arrives, or has left before the human can reach the place; human first: the other way).
   An agent's *final* stay ends at the end of its last phase, but the agent does not vanish there: it
   leaves, and needs ``reach / speed`` to be `reach` away from the spot, so a separation whose earlier
   timepoint ends a final stay has that clearing time added (measured by `hrc simulate`: without it a
   person who follows a DC plan walked up to within 3 cm of the robot leaving the table after its last
   put, and had to stop).
   If either holds the discs never overlap (proof: an overlap at time t would put ``(s(t), u(t))`` in C
   at a time both before and after itself). Which one a plan uses is the plan's choice
   (`hrc.compile.motion_pattern`); the temporal net creator adds it as a requirement link.

**Joint actions** (issue 37): for a task with joint actions, the pairs of the two working together at a
joint action's spot are no conflicts (`_coworking`: the robot's stay there against the person's walk up,
stay and walk away); the robot's drives keep their separations, so it arrives first and leaves last.
A co-worker who stands at the spot from the start therefore blocks the robot's drive in, whatever the
order (`joint_spot_starts` names such pairs, for the blocked plan's explanation).

**More agents** (issue 37): every pair of agents that shares the floor (`floor_pairs`). A robot and a
person as above; two robots alike, both controllable, so the plan chooses which passes first as it does
for a robot and a person (the second robot in the person's place: its exact motion is a special case of
the person's model, and the two separations are then exact); two people are left to themselves, their
meeting places reported (`people_meetings`), never constrained.

**Exactness.** Routes are sampled every `STEP` metres; a pair closer than `reach` has samples within
``STEP / 2`` of each, so the sampled set uses ``reach + STEP`` and every gap is widened by the time
``STEP / 2`` takes at each agent's speed: the separations are sufficient for the true (continuous)
routes, at the price of a few centimetres. Cost per route pair: O(n log n) with a k-d tree over the
samples plus the component labelling; results are cached per route pair in the `PathLibrary`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hrc.model import Agent, Plan, Task
from hrc.motion import separation
from hrc.motion.motions import Route, Routes
from hrc.motion.paths import Path, PathLibrary
from hrc.plans import Leg, agent_legs

__all__ = ["STEP", "Conflict", "JointSpotStart", "Occupancy", "Separation", "TimeRef", "find_conflicts", "floor_pairs",
           "joint_spot_starts", "occupancies", "people_meetings", "route_samples"]

STEP = 0.02  # m, arc-length spacing of route samples


@dataclass(frozen=True, slots=True, order=True)
class TimeRef:
    """A timepoint of a plan's STNU by meaning: `agent`'s leg `leg`, event `what` (depart / arrive /
    start / end, and park / unpark on a leg that stops at a waiting place); ``TimeRef.ORIGIN`` (agent "",
    leg -1, "origin") is the task's start, T = 0."""

    agent: str
    leg: int
    what: str

    def __getstate__(self) -> list:
        """The list `dataclasses`' own ``__getstate__`` of a frozen slotted class makes (so the same
        pickle bytes), without its ``fields()`` call per object: a small compile pickles some 20,000
        timepoints, separations, occupancies, conflicts and passing orders (the results cache, the
        figures' digests, the workers' answers), 0.1-0.2 s of CPU in ``fields()`` (issue 38)."""
        return [self.agent, self.leg, self.what]

    def __str__(self) -> str:
        return "origin" if self.agent == "" else f"{self.agent}[{self.leg}].{self.what}"


TimeRef.ORIGIN = TimeRef("", -1, "origin")  # type: ignore[attr-defined]
ORIGIN_REF: TimeRef = TimeRef.ORIGIN  # type: ignore[attr-defined]


@dataclass(frozen=True, slots=True)
class Separation:
    """``T(later) - T(earlier) >= gap`` (s): one way of keeping the discs apart at one conflict."""

    earlier: TimeRef
    later: TimeRef
    gap: float

    def __getstate__(self) -> list:
        return [self.earlier, self.later, self.gap]  # see `TimeRef.__getstate__`


@dataclass(frozen=True, slots=True)
class Occupancy:
    """Where an agent is between two of its timepoints: ``kind`` "travel" (leg `leg`'s route, or its
    `part` 1 / 2 to and from a waiting place) or "stay" (at `location` after leg `leg`'s arrival,
    ``leg == -1`` for the start location; `part` 1 for the waiting place of leg `leg`)."""

    agent: str
    kind: str
    leg: int
    location: str  # a stay's location; a travel's target
    origin: str  # a travel's origin; a stay's location
    begin: TimeRef
    finish: TimeRef
    part: int = 0

    def __getstate__(self) -> list:
        # see `TimeRef.__getstate__`
        return [self.agent, self.kind, self.leg, self.location, self.origin, self.begin, self.finish, self.part]

    def describe(self) -> str:
        if self.kind == "travel":
            return f"{self.agent} {self.origin}->{self.location}"
        return f"{self.agent} at {self.location}"


@dataclass(frozen=True, slots=True)
class Conflict:
    """A place where `robot` and `human` occupancies would overlap, and the two ways to avoid it.

    With more than one robot (`floor_pairs`), `human` is the other agent's occupancy: a person's, or a
    second robot's; "robot first" and "human first" then mean the first and the second robot first."""

    robot: Occupancy
    human: Occupancy
    component: int  # index among the components of this occupancy pair
    robot_first: Separation
    human_first: Separation
    point: tuple[float, float]  # where they would meet (the robot's position at the closest pair)
    shape: tuple[tuple[float, float], ...]  # the human's positions involved: a polyline, or one point
    route: str = ""  # the robot route's `Path.via` this conflict was computed for

    def __getstate__(self) -> list:
        # see `TimeRef.__getstate__`
        return [self.robot, self.human, self.component, self.robot_first, self.human_first, self.point, self.shape,
                self.route]

    @property
    def key(self) -> tuple:
        """Identifies the conflict within a plan (stable across runs), the pair's agents first (a task of more
        than two agents has several pairs, `floor_pairs`)."""
        return (self.robot.agent, self.human.agent, self.robot.kind, self.robot.leg, self.robot.part, self.human.kind,
                self.human.leg, self.human.part, self.component)


def occupancies(task: Task, plan: Plan, agent: Agent, routes: Routes | None = None) -> tuple[Occupancy, ...]:
    """The agent's stays and travels in time order (none for an agent without legs)."""
    legs = agent_legs(task, plan, agent.id)
    if not legs:
        return ()
    routes = routes or {}
    out: list[Occupancy] = []
    where = agent.start
    begin, stay_leg, stay_part = ORIGIN_REF, -1, 0
    for leg in legs:
        def ref(what: str, i: int = leg.index) -> TimeRef:
            return TimeRef(agent.id, i, what)

        route = routes.get((agent.id, leg.index))
        if route is not None and route.park:
            p = route.park
            out.append(Occupancy(agent.id, "stay", stay_leg, where, where, begin, ref("depart"), stay_part))
            out.append(Occupancy(agent.id, "travel", leg.index, p, leg.origin, ref("depart"), ref("park"), 1))
            out.append(Occupancy(agent.id, "stay", leg.index, p, p, ref("park"), ref("unpark"), 1))
            out.append(Occupancy(agent.id, "travel", leg.index, leg.location, p, ref("unpark"), ref("arrive"), 2))
            begin, stay_leg, stay_part = ref("arrive"), leg.index, 0
        elif leg.origin != leg.location:
            out.append(Occupancy(agent.id, "stay", stay_leg, where, where, begin, ref("depart"), stay_part))
            out.append(Occupancy(agent.id, "travel", leg.index, leg.location, leg.origin, ref("depart"),
                                 ref("arrive")))
            begin, stay_leg, stay_part = ref("arrive"), leg.index, 0
        where = leg.location
    last: Leg = legs[-1]
    out.append(Occupancy(agent.id, "stay", stay_leg, where, where, begin, TimeRef(agent.id, last.index, "end"),
                         stay_part))
    return tuple(out)


def route_samples(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Points every `STEP` m along `path` (ends included) and their arc lengths."""
    pts = np.asarray(path.points, dtype=float)
    if len(pts) == 1 or path.length == 0:
        return pts[:1].copy(), np.zeros(1)
    seg = np.hypot(*(pts[1:] - pts[:-1]).T)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    n = max(1, math.ceil(path.length / STEP))
    s = np.linspace(0.0, cum[-1], n + 1)
    xy = np.column_stack([np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])])
    return xy, s


def _samples(paths: PathLibrary, path: Path) -> tuple[np.ndarray, np.ndarray]:
    key = ("conflict-samples", path.agent, path.origin, path.target, path.via)
    got = paths.samples.get(key)
    if got is None:
        got = paths.samples[key] = route_samples(path)
    return got


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """Maximal runs ``[i, j]`` of True in a 1-D mask, in order (where a run starts, where it ends)."""
    edges = np.flatnonzero(np.diff(np.concatenate(([False], mask, [False])).astype(np.int8)))
    return list(zip(edges[::2].tolist(), (edges[1::2] - 1).tolist(), strict=True))


def _components(rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, int]:
    """The 8-connected components of the grid cells ``(rows[k], cols[k])`` (distinct cells, any
    order): each cell's component number (1 to n) and n, numbered in raster order of each
    component's first cell, as ``scipy.ndimage.label`` numbers them on the whole grid with a 3 x 3
    structure. Labelled on the cells' bounding box only (a route pair's grid holds 10^5 cells, its close
    ones a corner of it; raster order within the box is raster order in the grid)."""
    from scipy import ndimage  # here: a compile taken from the cache finds no conflict (issue 38)

    r0, c0 = int(rows.min()), int(cols.min())
    box = np.zeros((int(rows.max()) - r0 + 1, int(cols.max()) - c0 + 1), dtype=bool)
    box[rows - r0, cols - c0] = True
    labels, n = ndimage.label(box, structure=np.ones((3, 3), dtype=int))
    return labels[rows - r0, cols - c0], int(n)


# Geometry, per route pair, in route coordinates. Each component: (value for robot first, value for
# human first, meeting point, the human's positions), the values being the gaps of the docstring before
# timepoints are named.
_Component = tuple[float, float, tuple[float, float], tuple[tuple[float, float], ...]]


def _travel_travel(paths: PathLibrary, rp: Path, hp: Path, reach: float, vr: float, vh: float) -> list[_Component]:
    key = ("tt", rp.agent, rp.origin, rp.target, rp.via, hp.agent, hp.origin, hp.target, hp.via, reach, vr, vh)
    cached = paths.samples.get(key)
    if cached is not None:
        return cached
    rxy, rs = _samples(paths, rp)
    hxy, hu = _samples(paths, hp)
    out: list[_Component] = []
    if _boxes_meet(rxy, hxy, reach + STEP):
        from scipy.spatial import cKDTree  # here: a compile taken from the cache finds no conflict (issue 38)

        pairs = cKDTree(rxy).sparse_distance_matrix(cKDTree(hxy), reach + STEP, output_type="ndarray")
        close = pairs[pairs["v"] < reach + STEP]
        if len(close):
            lab, n = _components(close["i"], close["j"])
            pad = STEP / 2 / vr + STEP / 2 / vh
            length = hu[-1]
            for k in range(1, n + 1):
                sel = close[lab == k]
                s, u = rs[sel["i"]], hu[sel["j"]]
                robot_first = float(np.max(s / vr - u / vh)) + pad
                human_first = float(np.max(-(length - u) / vh - s / vr)) + pad
                m = int(np.argmin(sel["v"]))
                j0, j1 = int(sel["j"].min()), int(sel["j"].max())
                idx = sorted({*range(j0, j1 + 1, 10), j1})
                shape = tuple((float(hxy[j, 0]), float(hxy[j, 1])) for j in idx)
                out.append((robot_first, human_first, (float(rxy[sel["i"][m], 0]), float(rxy[sel["i"][m], 1])),
                            shape))
    paths.samples[key] = out
    return out


def _travel_stay(paths: PathLibrary, tp: Path, xy: tuple[float, float], reach: float) -> list[tuple[float, float]]:
    """Arc-length runs ``(s_min, s_max)`` of a travel within `reach` of a point (widened by STEP / 2)."""
    key = ("ts", tp.agent, tp.origin, tp.target, tp.via, xy, reach)
    cached = paths.samples.get(key)
    if cached is not None:
        return cached
    pxy, ps = _samples(paths, tp)
    d = np.hypot(pxy[:, 0] - xy[0], pxy[:, 1] - xy[1])
    out = [(max(0.0, float(ps[i]) - STEP / 2), min(float(ps[-1]), float(ps[j]) + STEP / 2))
           for i, j in _runs(d < reach + STEP / 2)]
    paths.samples[key] = out
    return out


def _boxes_meet(a: np.ndarray, b: np.ndarray, reach: float) -> bool:
    lo_a, hi_a = a.min(axis=0), a.max(axis=0)
    lo_b, hi_b = b.min(axis=0), b.max(axis=0)
    return bool(np.all(lo_a - reach < hi_b) and np.all(lo_b - reach < hi_a))


def floor_pairs(task: Task) -> tuple[tuple[Agent, Agent], ...]:
    """The pairs of agents whose conflicts a plan must settle, as ``(robot, other)``: every robot with every
    person, then every two robots (the first in task order in the `Conflict.robot` slot), robots in task
    order. A 1+1 task has one pair, ``(robot, human)``. Two people are left to themselves
    (`people_meetings`)."""
    robots = [a for a in task.agents if not a.is_human]
    humans = [a for a in task.agents if a.is_human]
    out = [(r, h) for r in robots for h in humans]
    out += [(r, q) for i, r in enumerate(robots) for q in robots[i + 1:]]
    return tuple(out)


def find_conflicts(task: Task, plan: Plan, paths: PathLibrary, routes: Routes | None = None) -> tuple[Conflict, ...]:
    """Every conflict between a robot's occupancies and another agent's in `plan` (see the docstring), for
    every pair of `floor_pairs`: robot and person as the module docstring says; two robots alike, the
    second in the person's slot (`Conflict.human`) with its exact motion (a robot's travel lasts exactly
    its route at its speed, which the person's model contains: ``T(arrive) - T(depart) = L / v``, so the
    two separations are exact) and the plain reach ``r_a + r_b + safety_margin`` (the protective
    separation keeps robots from people, `separation.reach`). Both orders of two robots are the plan's
    to choose, as the person-robot order is (`hrc.compile.motion_pattern`).

    `routes` maps ``(agent, leg)`` to the `Route` taken there (default: the library's shortest route).
    Deterministic; ordered by pair (`floor_pairs`), then robot then other occupancy (time order) and
    component.
    """
    out: list[Conflict] = []
    for robot, other in floor_pairs(task):
        out.extend(_pair_conflicts(task, plan, paths, routes or {}, robot, other))
    return tuple(out)


def people_meetings(task: Task, plan: Plan, paths: PathLibrary, routes: Routes | None = None) -> tuple[Conflict, ...]:
    """Where two people's occupancies in `plan` come within ``r_a + r_b + safety_margin`` of each other:
    the `Conflict`s of every two people (task order: the first in the `Conflict.robot` slot, read with
    the person's model on both sides). Not constraints: people give way to each other as they always do
    (issue 37, "human-human left to the people"); the compile reports them with the plan."""
    humans = [a for a in task.agents if a.is_human]
    out: list[Conflict] = []
    for i, a in enumerate(humans):
        for b in humans[i + 1:]:
            out.extend(_pair_conflicts(task, plan, paths, routes or {}, a, b))
    return tuple(out)


def _pair_conflicts(task: Task, plan: Plan, paths: PathLibrary, routes: Routes, robot: Agent,
                    human: Agent) -> list[Conflict]:
    """The conflicts of one pair (`robot` in the robot's slot, `human` in the other: a person, or a second
    robot, or for `people_meetings` two people)."""
    # the robot driving keeps the protective separation at its speed, standing at speed 0 (`separation`)
    reach = (separation.reach(task, robot.speed, human, robot), separation.reach(task, 0.0, human, robot))
    locs = paths.locations

    def route(occ: Occupancy) -> Path:
        chosen: Route | None = routes.get((occ.agent, occ.leg))
        if chosen is not None:
            if occ.part == 2 and chosen.onward is not None:
                return chosen.onward
            return chosen.path
        return paths.get(occ.agent, occ.origin, occ.location)

    def speed(occ: Occupancy) -> float:
        """The speed of a travel: a reduced one chosen for its leg (`Route.speed`), else the agent's."""
        chosen: Route | None = routes.get((occ.agent, occ.leg))
        if chosen is not None and chosen.speed:
            return chosen.speed
        return robot.speed if occ.agent == robot.id else human.speed

    def signature(occ: Occupancy) -> tuple:
        """What `_pair` reads of an occupancy, as a flat tuple (hashed in C, unlike the dataclass)."""
        b, f = occ.begin, occ.finish
        sig = (occ.agent, occ.kind, occ.leg, occ.part, occ.location, occ.origin, b.agent, b.leg, b.what, f.agent,
               f.leg, f.what)
        if occ.kind != "travel":
            return sig
        return (*sig, *_path_key(route(occ)), speed(occ))

    # the conflicts of an occupancy pair depend on the two occupancies and their routes only, and the
    # same pairs recur across the plans of a task: kept per process, like the geometry they come from
    # (by a number per signature: a plan has a few dozen occupancies but hundreds of pairs)
    cache = paths.samples.setdefault(("pairs", reach, robot.speed, human.speed), {})
    ids = paths.samples.setdefault(("pair-ids", reach, robot.speed, human.speed), {})
    # an agent's occupancies on its shortest routes depend on its legs' places only, and recur too
    agents = paths.samples.setdefault(("occupancies", reach, robot.speed, human.speed), {})
    # a robot occupancy's conflicts with a whole itinerary of the other (below), by number and itinerary
    rows = paths.samples.setdefault(("pair-rows", reach, robot.speed, human.speed), {})
    itineraries = paths.samples.setdefault(("itineraries", reach, robot.speed, human.speed), {})
    if max(len(cache), len(ids), len(rows), len(itineraries)) > _PAIR_CACHE:
        cache.clear()
        ids.clear()  # the numbers the others hold
        agents.clear()
        rows.clear()
        itineraries.clear()
    elif len(agents) > _OCCUPANCY_CACHE:
        agents.clear()

    def number(occ: Occupancy) -> int:
        sig = signature(occ)
        found = ids.get(sig)
        if found is None:
            found = ids[sig] = len(ids)
        return found

    def numbered(agent: Agent) -> tuple[list[tuple[Occupancy, int]], tuple]:
        # the route choices of the agent's legs, by what `signature` reads of them (a route trial's
        # itinerary recurs across the plans that share the agent's legs too)
        chosen = tuple(sorted((leg, _route_key(r)) for (a, leg), r in routes.items() if a == agent.id))
        key = (agent.id, chosen, *((leg.origin, leg.location) for leg in agent_legs(task, plan, agent.id)))
        found = agents.get(key)
        if found is None:
            found = agents[key] = [(o, number(o)) for o in occupancies(task, plan, agent, routes)]
        return found, key

    out: list[Conflict] = []
    h_occ, h_key = numbered(human)
    cowork = _coworking(task, plan, robot.id, human.id) if task.has_joint else None
    # a robot occupancy's conflicts with the whole of the other's itinerary, kept as one row: that
    # itinerary recurs across every plan that gives the other agent the same legs and routes (each of
    # the other's orders of the robot's actions), so a plan looks up a row per robot occupancy, not a
    # pair per two occupancies (a few hundred a plan); the same conflicts in the same order
    row_of = None
    if cowork is None:
        h_number = itineraries.setdefault(h_key, len(itineraries))
        row_of = rows
    for r, rn in numbered(robot)[0]:
        rk = rn << 32
        if row_of is not None:
            row = row_of.get((rk, h_number))
            if row is not None:
                out.extend(row)
                continue
        start = len(out)
        for h, hk in h_occ:
            if cowork is not None and cowork(r, h):
                continue
            found = cache.get(rk | hk)
            if found is None:
                vr = speed(r) if r.kind == "travel" else robot.speed
                reaches = reach if vr == robot.speed else (separation.reach(task, vr, human, robot), reach[1])
                vh = speed(h) if h.kind == "travel" else human.speed
                found = cache[rk | hk] = tuple(_pair(r, h, route, locs, reaches, vr, vh, paths))
            out.extend(found)
        if row_of is not None:
            row_of[(rk, h_number)] = tuple(out[start:])
    return out


def _at_spot(legs: tuple[Leg, ...], first: int, last: int, spot: str) -> bool:
    """Whether legs `first` .. `last` (inclusive) are all at `spot` (the agent does not move between them)."""
    return all(legs[k].location == spot for k in range(max(first, 0), last + 1))


def _coworking(task: Task, plan: Plan, robot: str, human: str):  # noqa: ANN202
    """For a task with joint actions: whether a (robot, human) occupancy pair is the two of them working
    together at a joint action's place, where the separation is not kept (`hrc.motion.separation`,
    "joint actions"): the robot's stay there, over the joint phase, against the person's walk up to
    the place, their stay there over the phase, and their walk away from it. The robot's own drives to
    and from the place keep the separation from the person standing there, so the robot arrives first
    and the person leaves first: the robot never moves within reach of a person at the joint spot."""
    r_legs, h_legs = agent_legs(task, plan, robot), agent_legs(task, plan, human)
    h_index = {(leg.action, leg.phase): leg.index for leg in h_legs}
    joint = [(leg.index, h_index[(leg.action, leg.phase)], leg.location) for leg in r_legs
             if task.action(leg.action).joint and (leg.action, leg.phase) in h_index]

    def covers(occ: Occupancy, j: int) -> bool:  # a stay that lasts over leg j
        return occ.kind == "stay" and occ.part == 0 and occ.leg <= j and (
            occ.finish.what == "end" or occ.finish.leg > j)

    def together(r: Occupancy, h: Occupancy) -> bool:
        for j, i, spot in joint:
            if r.location != spot or not covers(r, j):
                continue
            if h.location == spot and (covers(h, i) or h.kind == "travel" and h.leg <= i
                                       and _at_spot(h_legs, h.leg, i, spot)):
                return True
            if h.kind == "travel" and h.origin == spot and h.leg > i and _at_spot(h_legs, i, h.leg - 1, spot):
                return True
        return False

    return together


@dataclass(frozen=True, slots=True)
class JointSpotStart:
    """`agent` starts at `spot` and stays there (no leg takes it elsewhere) until the joint phase
    ``action.phase`` it does there with `robot`, which drives in for it (`joint_spot_starts`)."""

    agent: str
    robot: str
    action: str
    phase: str
    spot: str


def joint_spot_starts(task: Task, plan: Plan) -> tuple[JointSpotStart, ...]:
    """Where `plan` asks a robot to drive into a joint action's spot while a co-worker of that phase stands
    there from the start: the co-worker starts at the spot and every leg of theirs up to the joint phase is
    at the spot, and the robot is not at the spot all along (it starts elsewhere, or leaves and comes back).

    No order of passing can keep such a pair apart (`_coworking`): the robot's drive in keeps the
    separation from the co-worker standing at the spot, "robot first" would need the robot there before
    the task's start (the co-worker stands there from T = 0) and "co-worker first" would need the
    co-worker gone before the joint phase ends, which waits for the robot. So the plan is blocked, and the
    compile names the cause (`hrc.compile.motion_pattern`). Pairs of `floor_pairs` only (two people are
    left to themselves); in task order of the robots, then of the co-workers; () for a task without
    joint actions."""
    if not task.has_joint:
        return ()
    out: list[JointSpotStart] = []
    for robot, other in floor_pairs(task):
        r_legs, o_legs = agent_legs(task, plan, robot.id), agent_legs(task, plan, other.id)
        o_index = {(leg.action, leg.phase): leg.index for leg in o_legs}
        for leg in r_legs:
            i = o_index.get((leg.action, leg.phase))
            if i is None or not task.action(leg.action).joint:
                continue
            spot = leg.location
            there = other.start == spot and _at_spot(o_legs, 0, i, spot)
            robot_there = robot.start == spot and _at_spot(r_legs, 0, leg.index, spot)
            if there and not robot_there:
                out.append(JointSpotStart(other.id, robot.id, leg.action, leg.phase, spot))
    return tuple(out)


def _path_key(p: Path) -> tuple[str, str, str, float]:
    """A path as `find_conflicts` tells paths apart in its signatures: ends, detour label, length."""
    return (p.origin, p.target, p.via, p.length)


def _route_key(route: Route) -> tuple:
    """A route choice by its paths' `_path_key` and its waiting place."""
    q = route.onward
    return (*_path_key(route.path), route.park, None if q is None else _path_key(q), route.speed)


_PAIR_CACHE = 200_000  # occupancy pairs kept per process (a few tens of MB at most)
_OCCUPANCY_CACHE = 10_000  # agents' itineraries kept per process (about 7.5 kB each: 75 MB at most)


def _pair(r: Occupancy, h: Occupancy, route, locs, reaches: tuple[float, float], vr: float,  # noqa: ANN001
          vh: float, paths: PathLibrary) -> list[Conflict]:
    out: list[Conflict] = []
    reach = reaches[0] if r.kind == "travel" else reaches[1]
    r_clear, h_clear = _clearing(r, reach, vr), _clearing(h, reach, vh)
    if r.kind == "travel" and h.kind == "travel":
        rp, hp = route(r), route(h)
        for k, (rf, hf, point, shape) in enumerate(_travel_travel(paths, rp, hp, reach, vr, vh)):
            out.append(Conflict(r, h, k, Separation(r.begin, h.begin, rf), Separation(h.finish, r.begin, hf),
                                point, shape, rp.via))
    elif r.kind == "travel":  # the human stays at h.location from h.begin to h.finish
        rp = route(r)
        for k, (s0, s1) in enumerate(_travel_stay(paths, rp, locs[h.location], reach)):
            # robot first: through before the human arrives; human first: enters after the human left
            out.append(Conflict(r, h, k, Separation(r.begin, h.begin, s1 / vr),
                                Separation(h.finish, r.begin, -s0 / vr + h_clear), _point_at(paths, rp, s0),
                                (locs[h.location],), rp.via))
    elif h.kind == "travel":  # the robot stays at r.location from r.begin to r.finish
        hp = route(h)
        length = hp.length
        for k, (u0, u1) in enumerate(_travel_stay(paths, hp, locs[r.location], reach)):
            out.append(Conflict(r, h, k, Separation(r.finish, h.begin, -u0 / vh + r_clear),
                                Separation(h.finish, r.begin, -(length - u1) / vh), locs[r.location],
                                (_point_at(paths, hp, u0), _point_at(paths, hp, u1))))
    elif math.dist(locs[r.location], locs[h.location]) < reach:
        out.append(Conflict(r, h, 0, Separation(r.finish, h.begin, r_clear), Separation(h.finish, r.begin, h_clear),
                            locs[r.location], (locs[h.location],)))
    return out


def _clearing(occ: Occupancy, reach: float, speed: float) -> float:
    """Seconds an agent needs to clear a place after its last phase there: ``reach / speed`` for its final
    stay (it drives or walks away, at its speed, until it is `reach` from the spot), 0 for any other
    occupancy (whose end is the departure itself)."""
    return reach / speed if occ.kind == "stay" and occ.finish.what == "end" else 0.0


def _point_at(paths: PathLibrary, path: Path, s: float) -> tuple[float, float]:
    xy, arc = _samples(paths, path)
    i = min(int(np.searchsorted(arc, s)), len(arc) - 1)
    return (float(xy[i, 0]), float(xy[i, 1]))
