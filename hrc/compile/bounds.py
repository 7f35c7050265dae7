"""Sound lower bounds on a family of plans' rank key, for the search compile (`hrc.compile.search`).

A *node* of the plan tree fixes part of a plan: the agent of each of the first actions (task order) and,
once every action has one, a prefix of each agent's sequence. `NodeBounds.bound` gives, for every plan
below a node, a key no plan's `rank_key` beats (compared on its first four parts: class, the ranked
makespan to the whole second, the preference term, the ranked makespan).

**Why interference only ever adds time** (checked in the code it relies on): a plan's makespans are read
off the earliest schedules of its STNU without the task's limits (`hrc.compile.classify.measure`). Its
links are, per leg, a wait ``[0, inf)`` before departing, the travel, a wait ``[0, inf)`` before the step
and the step's duration, then the task graph ``end -> start >= 0`` (`hrc.compile.temporal_net_creator`).
What the co-worker costs is (a) passing orders, requirement links *added* to that network
(`hrc.compile.motion_pattern._network`): adding a link to an STN never makes an earliest time earlier;
(b) a detour: a longer route for the robot, still a collision-free path with its clearance, so at least
the shortest such path; (c) a stop at a waiting place: two such paths through the agent's start, at
least the shortest path by the triangle inequality; (d) ``--human-waits no``: ``[0, 0]`` links, again
added. So the relaxation below (every upper bound dropped, no passing order, every travel at most as
long as the shortest collision-free path) has earliest times no later than any plan's, in either reading.

**The relaxation**, per reading (``lo``: every duration at its lower bound, the earliest makespan;
``hi``: the human's durations and walks at their upper bounds, the robot's at their lower bounds, the
worst case of `measure`), in milliseconds rounded down (the STNU's ticks round the same numbers to the
nearest tick or outward, never lower):

- travel: the exact shortest path of a disc of the agent's clearance among the map's obstacles
  (visibility graph, `hrc.motion.exact.ExactPlanner`, whose corners, cut by chords, keep it below the
  optimum), less 1 cm
  for the motion planner's collision-check resolution, never below the straight line; the human's
  upper reading times its ``travel_slack``;
- critical path (Kelley & Walker's CPM) over the phases: each action's phases in order with the travel
  between them, the task graph, each agent's sequence prefix, and every action of an agent not yet
  sequenced after the end of that agent's prefix plus its cheapest way in; an action with no agent yet
  after the cheapest way in of any agent that may do it. A cycle: no plan below the node is valid;
- load: each agent's end is at least its prefix's end plus the work (steps, the travel inside each
  action, the cheapest way in) of its actions not yet sequenced; and the agents' ends sum to at least
  all of that plus the cheapest work of each action not yet allocated, so the makespan is at least
  that sum over the agents (the classic parallel-machine bound, e.g. Pinedo, *Scheduling*, 5th ed.,
  section 5.1).

**The class.** Class ranks before makespan, so a makespan bound prunes only where the class is known
not to be better: a DC plan meets the deadline with every human duration at its maximum, so if the
``hi`` bound already breaks the deadline no plan below is DC (class at least consistent); a consistent
plan has a schedule within the deadline, so if the ``lo`` bound breaks it, every plan below is
inconsistent. The bound's class is the best one not ruled out; its makespan the ``hi`` bound for DC
under ``--rank-by worst`` (a DC plan's worst case is measured with every human duration at its maximum)
and the ``lo`` bound otherwise (a plan whose upper reading has no schedule measures its worst case as
its earliest). The preference term is unbounded (minus infinity) when the task has preferences.

**Joint actions** (issue 37): allocated a crew (`hrc.model.Action.crews`; ``Node.alloc`` holds its number,
a choice of the plan when there are several), in the sequence of each agent of the crew; their first
phase starts when the last of the crew is there (one edge or time per agent in the critical path), each
phase lasts the crew's roles' ``[max lb, max ub]`` (the ``hi`` reading takes the upper end when a person of
the crew takes part: the STNU's contingent link, `hrc.compile.temporal_net_creator`), and it loads every
agent of the crew. Before the crew is chosen, each of these is the least over the crews (start, duration,
travel between phases: the least of lower bounds is one), an agent in every crew is loaded with its least
work over them, and the least over the crews of the other agents' work goes to the sum over the agents.

Cost: O(phases + precedence + agents * actions) per node.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from hrc.compile.temporal_net_creator import seconds_to_ticks
from hrc.model import Task
from hrc.plans import identical_actions, must_precede

if TYPE_CHECKING:
    from hrc.motion import PathLibrary
    from hrc.motion.exact import ExactPlanner

__all__ = ["Bound", "Node", "NodeBounds", "PLANNER_SLACK_M"]

PLANNER_SLACK_M = 0.01
"""Metres a travel's lower bound gives away below the exact shortest path: the motion planner checks
collisions at a finite resolution, so one of its paths may cut an inflated corner by a hair."""

_TICKS = 1000  # the temporal core's ticks per second (`hrc.compile.temporal_net_creator.TICKS_PER_SECOND`)


@dataclass(frozen=True, slots=True)
class Node:
    """Part of a plan: `alloc[i]` is the agent (index in task order) of action i for the first
    ``len(alloc)`` actions; once all are allocated, `seqs[a]` is agent a's sequence prefix (action indices)."""

    alloc: tuple[int, ...]
    seqs: tuple[tuple[int, ...], ...]


@dataclass(frozen=True, slots=True)
class Bound:
    """A node's bound: `key`, the first four parts of `rank_key` that no plan below beats; `lo` and `hi`
    the two readings' makespan bounds (ticks); `ends` each agent's prefix end in the ``lo`` reading."""

    key: tuple
    lo: int
    hi: int
    ends: tuple[int, ...]


def _all_pairs(exact: ExactPlanner, points: dict[str, tuple[float, float]]) -> dict[tuple[str, str], float]:
    """Shortest lengths between `points` in `exact`'s visibility graph (`ExactPlanner.shortest` for every
    pair, with the graph extended once instead of once per pair)."""
    import networkx as nx
    from shapely.geometry import LineString

    g = exact.graph.copy()
    names = list(points)
    for name in names:
        g.add_node(("at", name))
        for i in exact._visible(points[name]):
            g.add_edge(("at", name), i, weight=math.dist(points[name], exact.vertices[i]))
    for a, b in itertools.combinations(names, 2):
        if exact._free_tol.covers(LineString([points[a], points[b]])):
            g.add_edge(("at", a), ("at", b), weight=math.dist(points[a], points[b]))
    out = {}
    for a in names:
        dist = nx.single_source_dijkstra_path_length(g, ("at", a))
        for b in names:
            if (("at", b)) in dist:
                out[(a, b)] = float(dist[("at", b)])
    return out


class NodeBounds:
    """What the bounds need of a task, built once (the module docstring says what they are)."""

    def __init__(self, task: Task, paths: PathLibrary, rank_by: str = "worst") -> None:
        from hrc.motion.exact import ExactPlanner  # shapely's visibility graph: only when a search runs

        self.task, self.rank_by = task, rank_by
        self.n, self.m = len(task.actions), len(task.agents)
        self.agent_ids = task.agent_ids
        self.index = {a: i for i, a in enumerate(task.action_ids)}
        # a joint action (issue 37) is allocated a crew (`hrc.model.Action.crews`: `alloc[i]` is the crew's number
        # there, a choice of the plan when it has several, `Action.crew_choice`) and is in the sequence of every
        # agent of that crew; `takers`: every agent that may take part in it (any crew), `does`: who may work
        # on each action (allocated or taking part)
        self.crews = [tuple(tuple(task.agent_ids.index(x) for x in crew) for crew in a.crews) if a.joint else ()
                      for a in task.actions]
        self.takers = [tuple(ag for ag, agent in enumerate(task.agents) if agent.id in a.agents) if a.joint else ()
                       for a in task.actions]
        self.may = [list(range(len(crews))) if crews else
                    [ag for ag, agent in enumerate(task.agents) if agent.id in a.agents]
                    for a, crews in zip(task.actions, self.crews, strict=True)]
        self.does = [list(t) if t else may for t, may in zip(self.takers, self.may, strict=True)]
        self.slots = sum(len(c[0]) if c else 1 for c in self.crews)  # a leaf's sequence entries, all agents together
        self.phases = [[p.location for p in a.phases] for a in task.actions]
        self.at = [0]  # each action's first phase's number among all phases (task order); at[n]: the count
        for ph in self.phases:
            self.at.append(self.at[-1] + len(ph))
        self.owner = [(i, k) for i, ph in enumerate(self.phases) for k in range(len(ph))]
        locs = {loc.id: loc.xy for loc in task.workspace.locations}
        self.deadline = None if task.deadline is None else seconds_to_ticks(task.deadline)  # as the STNU has it
        self.pref = -math.inf if task.preferences else math.inf
        # travel lower bounds per reading, agent and (origin, target), in ticks
        self.travel: list[list[dict[tuple[str, str], int]]] = [[{} for _ in task.agents] for _ in range(2)]
        planners: dict[float, ExactPlanner] = {}
        for ag, agent in enumerate(task.agents):
            clearance = agent.radius + task.safety_margin
            if clearance not in planners:
                planners[clearance] = ExactPlanner(task.workspace, clearance, quad_segs=2)
            wanted = sorted({agent.start} | {loc for i in range(self.n) if ag in self.does[i]
                                             for loc in self.phases[i]})
            exact = _all_pairs(planners[clearance], {w: locs[w] for w in wanted})
            for o in wanted:
                for t in wanted:
                    if o == t:
                        lb = 0.0
                    else:
                        line = math.dist(locs[o], locs[t])
                        best = exact.get((o, t), math.inf)
                        try:
                            best = min(best, paths.get(agent.id, o, t).length)
                        except KeyError:
                            pass
                        lb = max(line, best - PLANNER_SLACK_M) if math.isfinite(best) else line
                    secs = lb / agent.speed
                    self.travel[0][ag][(o, t)] = math.floor(secs * _TICKS)
                    slack = agent.travel_slack if agent.is_human else 1.0
                    self.travel[1][ag][(o, t)] = math.floor(secs * slack * _TICKS)
        # step durations per reading, action, phase and agent (ticks; None: the agent may not do it); a joint
        # action's per crew (`jdur[r][i][c][k]`): a joint phase lasts until its crew's last role is done,
        # ``[max lb, max ub]`` over the crew, contingent with a person in it (`hrc.compile.temporal_net_creator`)
        self.dur: list[list[list[list[int | None]]]] = [[], []]
        self.jdur: list[list[list[list[int]]]] = [[], []]
        for r in range(2):
            for a, crews in zip(task.actions, self.crews, strict=True):
                rows = []
                for p in a.phases:
                    row: list[int | None] = []
                    for agent in task.agents:
                        if agent.id not in a.agents or a.joint:
                            row.append(None)
                            continue
                        iv = p.duration(agent.id)
                        row.append(math.floor((iv.ub if r and agent.is_human else iv.lb) * _TICKS))
                    rows.append(row)
                self.dur[r].append(rows)
                by_crew = []
                for crew in crews:
                    people = any(task.agents[ag].is_human for ag in crew)
                    by_crew.append([math.floor(max(p.duration(self.agent_ids[ag]).ub if r and people else
                                                   p.duration(self.agent_ids[ag]).lb for ag in crew) * _TICKS)
                                    for p in a.phases])
                self.jdur[r].append(by_crew)
        # an action's own work by an agent (steps and the travel between its phases; a joint action's per crew,
        # `jwork[r][i][c]`, for the crew's agents), and its cheapest way in: from the agent's start or the last
        # place of any other action the agent may do
        self.work = [[[0] * self.n for _ in range(self.m)] for _ in range(2)]
        self.jwork: list[list[list[dict[int, int]]]] = [[[] for _ in range(self.n)] for _ in range(2)]
        self.way_in = [[[0] * self.n for _ in range(self.m)] for _ in range(2)]
        for r in range(2):
            for ag, agent in enumerate(task.agents):
                places = {agent.start} | {self.phases[j][-1] for j in range(self.n) if ag in self.does[j]}
                for i in range(self.n):
                    if ag not in self.does[i]:
                        continue
                    inside = sum(self.travel[r][ag][(x, y)] for x, y in itertools.pairwise(self.phases[i]))
                    if not self.crews[i]:
                        self.work[r][ag][i] = sum(d[ag] or 0 for d in self.dur[r][i]) + inside
                    first = self.phases[i][0]
                    self.way_in[r][ag][i] = min(self.travel[r][ag][(e, first)] for e in places)
            for i, crews in enumerate(self.crews):
                self.jwork[r][i] = [{ag: sum(self.jdur[r][i][c]) + sum(self.travel[r][ag][(x, y)] for x, y in
                                                                      itertools.pairwise(self.phases[i]))
                                     for ag in crew} for c, crew in enumerate(crews)]
        prec: list[list[tuple[int, int, int]]] = [[] for _ in range(self.n)]  # (phase k, before j, its phase)
        for pr in task.precedence:
            i, j = self.index[pr.after.action], self.index[pr.before.action]
            k = [p.id for p in task.actions[i].phases].index(pr.after.phase)
            q = [p.id for p in task.actions[j].phases].index(pr.before.phase)
            prec[i].append((k, j, q))
        self.prec = prec
        self.before = must_precede(task)
        self.before_idx = {(self.index[a], self.index[b]) for a, b in self.before}
        self.preds = [frozenset(j for j in range(self.n) if (j, i) in self.before_idx) for i in range(self.n)]
        self.groups = [tuple(self.index[a] for a in g) for g in identical_actions(task)]
        self.group_prev: dict[int, int] = {}  # action -> the action before it in its group of identical actions
        # identical joint actions with a crew to choose: the tree's order rules (agents in task order, then
        # task order within an agent) do not hold for them (`hrc.plans.is_canonical` places a joint action
        # at the last agent of its crew, which crews do not order), so their leaves are checked whole
        # (`_canonical`) instead
        self.in_every = [tuple(ag for ag in c[0] if all(ag in o for o in c)) if c else () for c in self.crews]
        self.crew_groups = tuple(g for g in self.groups if task.actions[g[0]].crew_choice)
        for g in self.groups:
            if g in self.crew_groups:
                continue
            for x, y in itertools.pairwise(g):
                self.group_prev[y] = x

    def crew(self, i: int, alloc: tuple[int, ...]) -> tuple[int, ...]:
        """The agents (task order) whose sequences hold action `i` under `alloc`, allocated: its crew for a
        joint action, else its one agent."""
        return self.crews[i][alloc[i]] if self.crews[i] else (alloc[i],)

    def lead(self, i: int, alloc: tuple[int, ...]) -> int:
        """The agent a plan's allocation names for action `i` (`hrc.model.Task.lead` for a joint action:
        its crew's first robot)."""
        crew = self.crew(i, alloc)
        return crew[0] if len(crew) == 1 else next(ag for ag in crew if not self.task.agents[ag].is_human)

    def _canonical(self, node: Node) -> bool:
        """Whether a leaf is canonical in its groups of identical joint actions with a crew choice
        (`hrc.plans.is_canonical`: an action's slot is the last agent holding it, and its place there)."""
        slot: dict[int, tuple[int, int]] = {}
        for ag, seq in enumerate(node.seqs):
            for pos, x in enumerate(seq):
                slot[x] = (ag, pos)
        return all(slot[a] < slot[b] for g in self.crew_groups for a, b in itertools.pairwise(g))

    def root(self) -> Node:
        return Node((), tuple(() for _ in range(self.m)))

    def _times(self, node: Node, r: int) -> tuple[int, list[int]] | None:
        """The relaxation's critical path in reading `r` over the phases (topological order, Kahn): the
        latest phase end and each agent's prefix end; None on a cycle (no valid plan below)."""
        n, alloc, seqs = self.n, node.alloc, node.seqs
        full = len(alloc) == n
        travel, dur, jdur, way_in, at = self.travel[r], self.dur[r], self.jdur[r], self.way_in[r], self.at
        crews = self.crews
        # per action's first phase: where its agents' sequences let it start, as (phase it follows, gap)
        # or a time from 0; actions of an agent not in its prefix follow the prefix's last phase (a joint
        # action, issue 37, starts when every agent of it is there: one such edge or time per agent)
        follows: dict[int, list[tuple[int, int]]] = {}
        from_zero: dict[int, int] = {}
        for ag, seq in enumerate(seqs):
            here = self.task.agents[ag].start
            prev = -1
            for x in seq:
                gap = travel[ag][(here, self.phases[x][0])]
                if prev < 0:
                    from_zero[x] = max(from_zero.get(x, 0), gap)
                else:
                    follows.setdefault(x, []).append((at[prev] + len(self.phases[prev]) - 1, gap))
                prev, here = x, self.phases[x][-1]
        if full:
            placed = [set(seq) for seq in seqs]
            for i in range(n):
                for ag in crews[i][alloc[i]] if crews[i] else (alloc[i],):
                    if i in placed[ag]:
                        continue
                    own = seqs[ag]
                    if own:
                        follows.setdefault(i, []).append((at[own[-1]] + len(self.phases[own[-1]]) - 1, way_in[ag][i]))
                    else:
                        from_zero[i] = max(from_zero.get(i, 0), way_in[ag][i])
        total = at[n]
        preds: list[list[tuple[int, int]]] = [[] for _ in range(total)]  # phase -> (phase, gap)
        for i in range(n):
            agent = alloc[i] if i < len(alloc) else -1
            base = at[i]
            if i in follows:
                preds[base].extend(follows[i])
            for k in range(1, len(self.phases[i])):
                a, b = self.phases[i][k - 1], self.phases[i][k]
                if crews[i]:  # every agent of a joint action's crew goes on to its next phase (any crew: the least)
                    gap = (max(travel[ag][(a, b)] for ag in crews[i][alloc[i]]) if agent >= 0 else
                           min(max(travel[ag][(a, b)] for ag in crew) for crew in crews[i]))
                else:
                    gap = travel[agent][(a, b)] if agent >= 0 else min(travel[ag][(a, b)] for ag in self.may[i])
                preds[base + k].append((base + k - 1, gap))
            for k, j, ph in self.prec[i]:
                preds[base + k].append((at[j] + ph, 0))
        indeg = [len(p) for p in preds]
        users: list[list[tuple[int, int]]] = [[] for _ in range(total)]
        for v, ps in enumerate(preds):
            for u, gap in ps:
                users[u].append((v, gap))
        start = [0] * total
        for i in range(n):
            agent = alloc[i] if i < len(alloc) else -1
            if i in from_zero:
                start[at[i]] = from_zero[i]
            elif crews[i] and i not in follows:  # a joint action no agent has sequenced yet: all its crew must come
                start[at[i]] = (max(way_in[ag][i] for ag in crews[i][alloc[i]]) if agent >= 0 else
                                min(max(way_in[ag][i] for ag in crew) for crew in crews[i]))
            elif i not in follows:  # allocated but not sequenced yet, or not allocated
                start[at[i]] = way_in[agent][i] if agent >= 0 else min(way_in[ag][i] for ag in self.may[i])
        end = [0] * total
        ready = [v for v in range(total) if not indeg[v]]
        done = 0
        while ready:
            v = ready.pop()
            done += 1
            i, k = self.owner[v]
            agent = alloc[i] if i < len(alloc) else -1
            if crews[i]:  # a joint action: its crew's duration (not allocated: the least crew's)
                d: int | None = jdur[i][agent][k] if agent >= 0 else min(c[k] for c in jdur[i])
            else:
                d = dur[i][k][agent] if agent >= 0 else min(dur[i][k][ag] or 0 for ag in self.may[i])
            end[v] = start[v] + (d or 0)
            for u, gap in users[v]:
                if end[v] + gap > start[u]:
                    start[u] = end[v] + gap
                indeg[u] -= 1
                if not indeg[u]:
                    ready.append(u)
        if done < total:
            return None
        prefix_end = [0] * self.m
        for ag, seq in enumerate(seqs):
            if seq:
                prefix_end[ag] = end[at[seq[-1]] + len(self.phases[seq[-1]]) - 1]
        return max(end, default=0), prefix_end

    def _load(self, node: Node, r: int, prefix_end: list[int]) -> int:
        """The load bound of reading `r` (module docstring)."""
        n, alloc, seqs = self.n, node.alloc, node.seqs
        full = len(alloc) == n
        in_prefix = {x for seq in seqs for x in seq}
        load = list(prefix_end) if full else [0] * self.m
        spare = 0
        work, way_in = self.work[r], self.way_in[r]
        for i in range(n):
            crews = self.crews[i]
            if crews:  # a joint action: each agent of its crew works it
                if i < len(alloc):
                    c = alloc[i]
                    for ag in crews[c]:
                        if i not in seqs[ag]:
                            load[ag] += self.jwork[r][i][c][ag] + way_in[ag][i]
                    continue
                # no crew yet (then nothing is sequenced): an agent of every crew works it at least its least;
                # the others' part of the least crew's work goes to the sum over the agents
                every = self.in_every[i]
                for ag in every:
                    load[ag] += min(w[ag] for w in self.jwork[r][i]) + way_in[ag][i]
                if len(crews) > 1:
                    spare += min(sum(w[ag] + way_in[ag][i] for ag in crew if ag not in every)
                                 for crew, w in zip(crews, self.jwork[r][i], strict=True))
                continue
            if i in in_prefix:
                continue
            if i < len(alloc):
                ag = alloc[i]
                load[ag] += work[ag][i] + way_in[ag][i]
            else:
                spare += min(work[ag][i] + way_in[ag][i] for ag in self.may[i])
        return max(max(load), -(-(sum(load) + spare) // self.m))

    def bound(self, node: Node) -> Bound | None:
        """The node's `Bound`; None when no valid plan lies below it (a cycle)."""
        found = []
        for r in range(2):
            got = self._times(node, r)
            if got is None:
                return None
            latest, ends = got
            found.append((max(latest, self._load(node, r, ends)), ends))
        (lo, ends), (hi, _) = found
        cls = 0
        if self.deadline is not None and hi > self.deadline:
            cls = 2 if lo > self.deadline else 1
        first = hi if cls == 0 and self.rank_by == "worst" else lo
        s = round(first / _TICKS, 6)
        return Bound((cls, round(s), self.pref, s), lo, hi, tuple(ends))

    def children(self, node: Node, ends: tuple[int, ...],
                 cover: tuple[int, tuple[int, ...]] | None = None) -> list[Node]:
        """The node's children (`hrc.compile.search` says how the tree is laid out): allocate the next
        action, or extend the sequence of the agent whose prefix ends first (`ends`; ties: task order).
        Identical actions (`hrc.plans.identical_actions`) only in their canonical order
        (`hrc.plans.is_canonical`), except with `cover` ``(agent, actions)``: that agent's sequence starts
        so (its prefix may name any of identical actions; the search compiles the leaf's whole family)."""
        n, alloc, seqs = self.n, node.alloc, node.seqs
        who, forced = cover if cover is not None else (-1, ())
        if len(alloc) < n:
            i = len(alloc)
            out = []
            mine = self.crews[i]
            for ag in self.may[i]:  # an agent, or a joint action's crew (its number)
                prev = None if cover is not None else self.group_prev.get(i)
                if prev is not None and alloc[prev] > ag:
                    continue  # identical actions: agents in task order
                takes = who in mine[ag] if mine else ag == who  # the action is in the covered agent's sequence
                if i in forced and not takes:
                    continue
                if takes and not self._fits(alloc + (ag,), i, who, forced):
                    continue  # the forced prefix would need an action of its agent before it that it lacks
                out.append(Node(alloc + (ag,), seqs))
            return out
        crews = self.crews
        placed = [set(seq) for seq in seqs]  # per agent (a joint action is placed once per agent of its crew)

        def todo(i: int, ag: int) -> bool:  # action i is for agent ag's sequence and not in it yet
            return (alloc[i] == ag if not crews[i] else ag in crews[i][alloc[i]]) and i not in placed[ag]

        busy = [ag for ag in range(self.m) if any(todo(i, ag) for i in range(n))]
        if not busy:
            return []
        if who >= 0 and len(seqs[who]) < len(forced):  # the covered agent's prefix first
            ag = who
            options = [forced[len(seqs[who])]]
        else:
            ag = min(busy, key=lambda a: (ends[a], a))
            options = [i for i in range(n) if todo(i, ag)]
        out = []
        for i in options:
            if any(todo(j, ag) for j in self.preds[i]):
                continue  # a must-precede action of the same agent is still to come
            prev = None if cover is not None else self.group_prev.get(i)
            if prev is not None and todo(prev, ag):
                continue  # identical actions: in task order within an agent
            child = Node(alloc, seqs[:ag] + (seqs[ag] + (i,),) + seqs[ag + 1:])
            if self.crew_groups and cover is None and self.is_leaf(child) and not self._canonical(child):
                continue  # its canonical relabelling is another leaf (`crew_groups`)
            out.append(child)
        return out

    def _fits(self, alloc: tuple[int, ...], i: int, who: int, forced: tuple[int, ...]) -> bool:
        """Whether giving action `i` to `who` (as `alloc` does) keeps a sequence of `who` that starts with
        `forced` possible: an action of `who` that must precede ``forced[p]`` (`hrc.plans.must_precede`)
        must be one of ``forced[:p]``. Checked when either is allocated, so that a dive does not learn it
        only after trying every order below an allocation (the allocations are the deep part of its
        backtracking)."""
        for p, x in enumerate(forced):
            if (i, x) in self.before_idx and i not in forced[:p]:
                return False
            if x == i and any(who in self.crew(j, alloc) and (j, i) in self.before_idx
                              and j not in forced[:p] for j in range(len(alloc))):
                return False
        return True

    def is_leaf(self, node: Node) -> bool:
        return len(node.alloc) == self.n and sum(len(s) for s in node.seqs) == self.slots
