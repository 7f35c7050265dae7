"""Co-worker interference: per plan and motion, ``[free-space time, time with the co-worker in the way]``.

Strassmair & Taylor 2014, section V.A: motion durations "vary from plan to plan as the co-workers
influence each other: e.g. in a particular plan one worker might block the other's way". This module
approximates that influence from the planned free-space paths (`hrc.motion.paths`) and a nominal
schedule; it is a screening model, not a simulation.

**Nominal schedule.** Each phase's manipulation takes the *midpoint* of the doing agent's duration
bounds; each travel takes its free-space time. Phases are scheduled as early as possible in a
topological order of the plan's phase graph (`hrc.plans.phase_graph`): an agent departs for a leg as
soon as its previous manipulation ends (at time 0 for its first leg), arrives after the free-space
time, and starts the manipulation at ``max(arrival, end of every predecessor phase)``, waiting at the
location meanwhile (it may travel to the table early and wait there).

**Occupancy.** Each agent is a disc; two agents conflict when their centres are closer than
``r_human + r_robot + safety_margin``. The human occupies its nominal trajectory from time 0 until the
end of its last manipulation (moving along its paths at constant speed, standing at a location while
waiting and manipulating); after its last phase it is assumed to step out of the way. Times are
quantised to `DT` (50 ms) for the search.

**Resolution: the robot yields by waiting.** For each robot travel, the robot's occupancy is its path
from the nominal departure plus its standing at the target until the manipulation may start (so it
does not park on the spot where the human works). If that meets the human, the robot delays its
departure by the least multiple of `DT` for which nothing meets the human (waiting at the origin, or,
equivalently for the arrival time, outside the human's disc): ``max_time = free_time + delay``. The
blamed human motion is the leg whose travel, or standing at its target afterwards, is in the way
(`Interference.other_leg`, index as in `hrc.plans.agent_legs`); each cause's `extra_time` is the least
delay that clears that cause alone, and `point` the robot's position at the first contact. Detours are
not generated (``kind`` is always ``"wait"``): on the workshop map the alternative way round the shelf
row is several metres longer, which at the robot's speed costs more than waiting for a walking human.

**Assumptions, stated as limits of the approximation.** One pass: delays are not propagated to later
motions of either agent, and the human's schedule is its nominal one (its variability is the temporal
net's business, which adds the human's own slack). Human motions keep ``max_time == free_time`` (the
robot yields); a human approaching a robot that stands still manipulating is assumed to wait for the
task's precedence anyway. A robot standing at its origin while waiting to depart is not checked.
Legs with ``origin == target`` have zero time and no interference.

Cost: O(legs x samples) numpy work per plan, plus O(shifts x samples) for a robot motion that
conflicts; the path samples are cached in the `PathLibrary` (a few ms per workshop plan).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import networkx as nx
import numpy as np

from hrc.model import Plan, Task
from hrc.motion.paths import Path, PathLibrary
from hrc.plans import Leg, agent_legs, phase_graph

__all__ = ["DT", "Interference", "Motion", "NominalLeg", "nominal_schedule", "plan_motions"]

DT = 0.05  # s, time step of the conflict search
_CHUNK = 64  # delays tried per numpy batch


@dataclass(frozen=True, slots=True)
class Interference:
    """The co-worker's motion `other_leg` (``other_origin -> other_target``) is in this motion's way."""

    other_agent: str
    other_leg: int
    other_origin: str
    other_target: str
    extra_time: float  # s added to this motion in the worst case (by this cause alone)
    kind: str  # "wait" | "detour"
    point: tuple[float, float]  # where they meet (the yielding agent's position), for plots


@dataclass(frozen=True, slots=True)
class Motion:
    """One travel of one agent in a plan: ``free_time <= duration <= max_time`` (s)."""

    agent: str
    leg: int
    origin: str
    target: str
    free_time: float
    max_time: float
    interference: tuple[Interference, ...]


@dataclass(frozen=True, slots=True)
class NominalLeg:
    """A leg's nominal times (s): departure, arrival, manipulation start and end."""

    leg: Leg
    depart: float
    arrive: float
    start: float
    end: float


def _nominal(interval_lb: float, interval_ub: float) -> float:
    return interval_lb if math.isinf(interval_ub) else (interval_lb + interval_ub) / 2


def nominal_schedule(task: Task, plan: Plan, paths: PathLibrary) -> dict[str, tuple[NominalLeg, ...]]:
    """Each agent's legs with nominal times (see the module docstring); agents in task order."""
    legs = {a: agent_legs(task, plan, a) for a in task.agent_ids}
    by_node = {f"{lg.action}.{lg.phase}": lg for a in legs for lg in legs[a]}
    g = phase_graph(task, plan)
    end: dict[str, float] = {}
    out: dict[str, list[NominalLeg]] = {a: [] for a in task.agent_ids}
    free_at = dict.fromkeys(task.agent_ids, 0.0)
    for node in nx.lexicographical_topological_sort(g):
        if node not in by_node:
            continue
        lg = by_node[node]
        depart = free_at[lg.agent]
        arrive = depart + paths.get(lg.agent, lg.origin, lg.location).duration
        start = max([arrive] + [end[p] for p in g.predecessors(node)])
        iv = task.action(lg.action).phase(lg.phase).duration(lg.agent)
        end[node] = start + _nominal(iv.lb, iv.ub)
        free_at[lg.agent] = end[node]
        out[lg.agent].append(NominalLeg(lg, depart, arrive, start, end[node]))
    return {a: tuple(sorted(out[a], key=lambda n: n.leg.index)) for a in task.agent_ids}


def _samples(paths: PathLibrary, path: Path) -> np.ndarray:
    """Positions along `path` every `DT` seconds at its free-space speed, arrival included (cached)."""
    key = (path.agent, path.origin, path.target)
    cached = paths.samples.get(key)
    if cached is not None:
        return cached
    pts = np.asarray(path.points, dtype=float)
    if len(pts) == 1 or path.duration == 0:
        out = pts[:1].copy()
    else:
        seg = np.hypot(*(pts[1:] - pts[:-1]).T)
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        n = max(1, math.ceil(path.duration / DT))
        s = np.minimum(np.arange(n + 1) * DT, path.duration) * (path.length / path.duration)
        out = np.column_stack([np.interp(s, cum, pts[:, 0]), np.interp(s, cum, pts[:, 1])])
    paths.samples[key] = out
    return out


def _timeline(paths: PathLibrary, sched: tuple[NominalLeg, ...]) -> tuple[np.ndarray, np.ndarray]:
    """The agent's position every DT from 0 to its last phase end (NaN after) and the blamed leg index."""
    if not sched:
        return np.full((1, 2), np.nan), np.full(1, -1)
    last = round(sched[-1].end / DT) + 1
    pos = np.full((last + 1, 2), np.nan)
    label = np.full(last + 1, -1)
    for i, nl in enumerate(sched):
        lg = nl.leg
        d = round(nl.depart / DT)
        smp = _samples(paths, paths.get(lg.agent, lg.origin, lg.location))
        stop = round(sched[i + 1].depart / DT) if i + 1 < len(sched) else last
        k = min(len(smp), stop - d)
        pos[d:d + k] = smp[:k]
        pos[max(d + k, round(nl.start / DT)):stop] = smp[-1]  # waiting aside until the start: absent
        label[d:stop] = lg.index
    return pos, label


def _yield(paths: PathLibrary, nl: NominalLeg, other_pos: np.ndarray, other_label: np.ndarray,
           reach: float) -> tuple[int, dict[int, tuple[int, tuple[float, float]]]]:
    """The least delay (steps) that clears the other agent, and per blamed leg (its delay, first contact)."""
    lg = nl.leg
    smp = _samples(paths, paths.get(lg.agent, lg.origin, lg.location))
    d0 = round(nl.depart / DT)
    horizon = len(other_pos)
    if d0 >= horizon:
        return 0, {}
    traj = smp
    m = len(traj)
    pad = np.full((m + _CHUNK, 2), np.nan)
    other = np.vstack([other_pos, pad])
    lab = np.concatenate([other_label, np.full(m + _CHUNK, -1)])
    reach2 = reach * reach
    first = other[d0:d0 + m] - traj
    if not ((first[:, 0] ** 2 + first[:, 1] ** 2) < reach2).any():
        return 0, {}  # the common case: nothing in the way at the nominal departure
    causes: dict[int, tuple[int, tuple[float, float]]] = {}  # leg -> (delay that clears it, contact)
    open_: set[int] = set()  # seen, not cleared yet
    for k0 in range(0, horizon - d0 + 1, _CHUNK):
        ks = np.arange(k0, k0 + _CHUNK)
        idx = d0 + ks[:, None] + np.arange(m)[None, :]  # (delays, samples) time indices
        diff = other[idx] - traj[None, :, :]
        hit = (diff[..., 0] ** 2 + diff[..., 1] ** 2) < reach2
        labels = lab[idx]
        busy = hit.any(axis=1)
        free_rows = np.flatnonzero(~busy)
        stop = int(free_rows[0]) if len(free_rows) else _CHUNK  # rows beyond are not needed
        for h in sorted(set(labels[:stop][hit[:stop]].tolist()) | open_):
            rows = (hit & (labels == h)).any(axis=1)
            if h not in causes:
                r0 = int(np.flatnonzero(rows)[0])
                i0 = int(np.flatnonzero(hit[r0] & (labels[r0] == h))[0])
                causes[h] = (-1, (float(traj[i0, 0]), float(traj[i0, 1])))
                open_.add(h)
            else:
                r0 = 0
            gone = np.flatnonzero(~rows[r0:])
            if len(gone) and r0 + int(gone[0]) <= stop:
                causes[h] = (int(ks[r0 + int(gone[0])]), causes[h][1])
                open_.discard(h)
        if len(free_rows):
            return int(ks[stop]), causes
    return horizon - d0, causes  # unreachable in practice: the other agent is gone by then


def plan_motions(task: Task, plan: Plan, paths: PathLibrary) -> tuple[Motion, ...]:
    """One `Motion` per leg of every agent (`agent_legs` order, agents in task order).

    Deterministic; human motions have ``max_time == free_time``; see the module docstring for the model.
    """
    sched = nominal_schedule(task, plan, paths)
    human = next(a for a in task.agents if a.is_human)
    robot = next(a for a in task.agents if not a.is_human)
    h_pos, h_label = _timeline(paths, sched[human.id])
    h_legs = {nl.leg.index: nl.leg for nl in sched[human.id]}
    reach = human.radius + robot.radius + task.safety_margin
    out: list[Motion] = []
    for agent in task.agents:
        for nl in sched[agent.id]:
            lg = nl.leg
            free = paths.get(agent.id, lg.origin, lg.location).duration
            inter: tuple[Interference, ...] = ()
            delay = 0
            if agent.id == robot.id and lg.origin != lg.location:
                pos = h_pos
                # the robot was at its origin first: a human manipulation there that starts as the robot
                # leaves waits for it (the human approaches once the robot is gone), so it is not in the way
                late = [h for h in sched[human.id] if h.leg.location == lg.origin and h.start >= nl.depart - 1e-9]
                if late:
                    pos = h_pos.copy()
                    for h in late:
                        pos[round(h.start / DT):round(h.end / DT) + 1] = np.nan
                delay, causes = _yield(paths, nl, pos, h_label, reach)
                items = []
                for h_leg, (k, point) in sorted(causes.items()):
                    if h_leg < 0 or k <= 0:
                        continue
                    hl = h_legs[h_leg]
                    items.append(Interference(human.id, h_leg, hl.origin, hl.location, k * DT, "wait", point))
                inter = tuple(items)
                if not inter:
                    delay = 0
            out.append(Motion(agent.id, lg.index, lg.origin, lg.location, free, free + delay * DT, inter))
    return tuple(out)
