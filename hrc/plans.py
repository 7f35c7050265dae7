"""Plan generation (Strassmair & Taylor 2014, section V.A): every allocation, then every valid sequence.

A plan is an allocation of actions to agents plus one sequence of actions per agent. It is *valid* when
its phase graph is acyclic: each action's phases in order, each agent's actions one after the other
(an action is done whole before the agent's next one starts, non-preemptive), and the task graph's
precedence edges. Plans are streamed in a deterministic order (allocations in lexicographic order of
the task's agent order, then sequences in lexicographic order of the task's action order); plan ids come
from the plan itself (`Plan.id`), not from that order.

Cost: ``prod(|agents(a)|)`` allocations; per allocation, the linear extensions of each agent's actions
under the "must precede" relation, filtered by a joint acyclicity check (O(phases + edges) each).
"""

from __future__ import annotations

import functools
import itertools
import math
from array import array
from collections.abc import Callable, Hashable, Iterator
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, TypeVar

from hrc.errors import InputError
from hrc.model import PhaseRef, Plan, Task, is_acyclic

if TYPE_CHECKING:  # networkx only for `phase_graph`'s callers: a compile does not import it (issue 38)
    import networkx as nx
    import numpy as np  # only `code_sequences` uses it (imported there): this module is read without numpy

__all__ = ["COUNT_STATES", "Leg", "PlanCount", "agent_legs", "allocation_count", "allocation_key", "allocations",
           "code_sequences",
           "count_plans",
           "estimate_plan_count", "family_of", "generate_plans", "identical_actions", "is_canonical",
           "must_precede", "per_plan", "phase_graph", "pin_actions", "plan_code", "plan_count_bound", "plan_families",
           "plan_from_code", "relabellings", "spread_families", "symmetry_factor"]

R = TypeVar("R")

COUNT_STATES = 100_000
"""Most run states `estimate_plan_count` memoizes before it falls back to `plan_count_bound` (about
40 MB and 1-2 s; the exact count of 14 independent actions needs millions)."""


class _TooManyStates(Exception):
    """The exact count would memoize more run states than allowed."""


def _doer_choices(task: Task) -> list[list[tuple[str, ...]]]:
    """Per action (task order), who may do it, each choice as the agents doing it (task order): one agent
    of its `agents`, or for a joint action one of its `Action.crews` (every agent of the crew takes part;
    with one crew, there is nothing to choose)."""
    return [list(action.crews) if action.joint else [(ag,) for ag in task.agent_ids if ag in action.agents]
            for action in task.actions]


def _named(task: Task, doers: tuple[tuple[str, ...], ...]) -> tuple[tuple[str, str], ...]:
    """The allocation of a choice of doers per action: each action to its one agent, a joint action to
    its crew's lead (`Task.lead`: the first robot of the crew in task order)."""
    robots = {a.id for a in task.agents if not a.is_human}
    return tuple((action, crew[0] if len(crew) == 1 else next(ag for ag in crew if ag in robots))
                 for action, crew in zip(task.action_ids, doers, strict=True))


def allocation_count(task: Task) -> int:
    """How many allocations `allocations` yields (a joint action's crew is part of its allocation)."""
    return math.prod(len(c) for c in _doer_choices(task))


def _allocations(task: Task) -> Iterator[tuple[tuple[tuple[str, str], ...], tuple[tuple[str, ...], ...]]]:
    """Every allocation and the doers it stands for (per action, its agent or its joint crew), in
    lexicographic order of the choices (agents in task order, crews in `Action.crews` order)."""
    for doers in itertools.product(*_doer_choices(task)):
        yield _named(task, doers), doers


def allocation_key(task: Task, plan: Plan) -> tuple:
    """What tells `plan`'s allocation apart from the others': its `Plan.allocation`, and with a crew to
    choose (`Task.has_crew_choice`) each such joint action's crew too (two crews with one lead share an
    allocation's names, not its choice). What ``hrc compile --best-per-allocation`` groups plans by."""
    if not task.has_crew_choice:
        return plan.allocation
    return plan.allocation + tuple((a.id, task.crew(a.id, plan)) for a in task.actions if a.crew_choice)


def allocations(task: Task) -> Iterator[tuple[tuple[str, str], ...]]:
    """Every allocation ``((action, agent), ...)`` in task order, each action to one agent that may do it
    (a joint action to its crew's lead: two crews with one lead give the same allocation twice)."""
    for allocation, _ in _allocations(task):
        yield allocation


Graph = dict[str, list[str]]
"""A directed graph as successor lists by node, nodes and edges in insertion order (networkx's
``DiGraph`` had this role; a compile no longer imports networkx, about 0.3 s of its start-up)."""


def _edge(g: Graph, u: str, v: str) -> None:
    """Add the edge ``u -> v`` to `g` (and either node it does not hold yet), at most once."""
    succ = g.setdefault(u, [])
    g.setdefault(v, [])
    if v not in succ:
        succ.append(v)


def _task_phase_graph(task: Task) -> Graph:
    g: Graph = {}
    for a in task.actions:
        for p in a.phases:
            g.setdefault(str(PhaseRef(a.id, p.id)), [])
        for p, q in itertools.pairwise(a.phases):
            _edge(g, str(PhaseRef(a.id, p.id)), str(PhaseRef(a.id, q.id)))
    for pr in task.precedence:
        _edge(g, str(pr.before), str(pr.after))
    return g


def _descendants(g: Graph, node: str) -> set[str]:
    """The nodes reachable from `node` by one or more edges, `node` itself never (as networkx's
    ``descendants``)."""
    seen: set[str] = set()
    todo = list(g[node])
    while todo:
        u = todo.pop()
        if u not in seen:
            seen.add(u)
            todo.extend(g[u])
    seen.discard(node)
    return seen


def must_precede(task: Task) -> frozenset[tuple[str, str]]:
    """Action pairs ``(a, b)``: some phase of `a` reaches some phase of `b` in the task graph.

    If one agent does both, it must do `a` before `b` (doing `b` first would close a cycle).
    """
    g = _task_phase_graph(task)
    owner = {str(PhaseRef(a.id, p.id)): a.id for a in task.actions for p in a.phases}
    pairs = set()
    for node in g:
        for reached in _descendants(g, node):
            if owner[node] != owner[reached]:
                pairs.add((owner[node], owner[reached]))
    return frozenset(pairs)


def _linear_extensions(items: tuple[str, ...], before: frozenset[tuple[str, str]]) -> Iterator[tuple[str, ...]]:
    """Orders of `items` respecting `before`, in lexicographic order of positions in `items`."""
    if not items:
        yield ()
        return
    for i, head in enumerate(items):
        if any((other, head) in before for other in items if other != head):
            continue
        for tail in _linear_extensions(items[:i] + items[i + 1:], before):
            yield (head, *tail)


def phase_graph(task: Task, plan: Plan) -> nx.DiGraph:
    """The plan's phase graph (nodes ``ACTION.PHASE``); edges: phase order, agent sequence, task graph."""
    import networkx as nx

    g: nx.DiGraph = nx.DiGraph()
    for u, succ in _task_phase_graph(task).items():
        g.add_node(u)
        g.add_edges_from((u, v) for v in succ)
    for _, seq in plan.sequences:
        for a, b in itertools.pairwise(seq):
            g.add_edge(str(PhaseRef(a, task.action(a).phases[-1].id)),
                       str(PhaseRef(b, task.action(b).phases[0].id)))
    return g


def _sequences(task: Task, doers: tuple[tuple[str, ...], ...],
               before: frozenset[tuple[str, str]]) -> Iterator[tuple[tuple[str, tuple[str, ...]], ...]]:
    """Every valid combination of the agents' sequences, each agent doing the actions `doers` (per action
    in task order: the agents doing it) give it."""
    per_agent = []
    joint = task.has_joint
    for agent in task.agent_ids:
        mine = tuple(a for a, crew in zip(task.action_ids, doers, strict=True) if agent in crew)
        per_agent.append([(agent, seq) for seq in _linear_extensions(mine, before)])
    base = _task_phase_graph(task)
    last = {a.id: str(PhaseRef(a.id, a.phases[-1].id)) for a in task.actions}
    first = {a.id: str(PhaseRef(a.id, a.phases[0].id)) for a in task.actions}
    # a cycle through two agents' sequences needs a task-graph edge between two actions: without one
    # (independent actions, as in the kitting tasks) every combination is valid, and checking each
    # with networkx was most of the time plan generation took
    # (a joint action is in two agents' sequences: two of them can close a cycle on their own, and the
    # check is what makes the agents' orders of their joint actions agree)
    linked = (any(pr.before.action != pr.after.action for pr in task.precedence)
              or not is_acyclic(base) or joint)
    for combo in itertools.product(*per_agent):
        if linked and len(combo) > 1:  # cross-agent cycles need two or more busy agents
            g = {u: list(succ) for u, succ in base.items()}
            for _, seq in combo:
                for a, b in itertools.pairwise(seq):
                    _edge(g, last[a], first[b])
            if not is_acyclic(g):
                continue
        yield tuple(combo)


def generate_plans(task: Task, symmetry: bool = False) -> Iterator[Plan]:
    """Stream every valid plan of `task` (allocation x sequences), in a deterministic order; with
    `symmetry`, one plan per class of plans that differ only by swapping identical actions
    (`identical_actions`, `is_canonical`)."""
    before = must_precede(task)
    groups = identical_actions(task) if symmetry else ()
    for allocation, doers in _allocations(task):
        for sequences in _sequences(task, doers, before):
            plan = Plan(allocation=allocation, sequences=sequences)
            if not groups or is_canonical(task, plan, groups):
                yield plan


def identical_actions(task: Task) -> tuple[tuple[str, ...], ...]:
    """Groups (two or more, in task order) of actions that nothing tells apart but their ids: the same
    agents, the same phases (ids, locations, durations) and named by no precedence, temporal constraint
    or preference. Swapping two of them in a plan gives a plan with the same schedule, class and
    makespan (its STNU is the same up to the names)."""
    named = {pr.before.action for pr in task.precedence} | {pr.after.action for pr in task.precedence}
    named |= {c.source.action for c in task.constraints} | {c.target.action for c in task.constraints}
    prefs = list(task.preferences) + [p for _, ps in task.preference_sets for p in ps]
    named |= {p.source.action for p in prefs} | {p.target.action for p in prefs}
    by_shape: dict[tuple, list[str]] = {}
    for a in task.actions:
        if a.id not in named:
            shape = (a.agents, a.roles, a.needed, tuple((p.id, p.location, p.durations) for p in a.phases))
            by_shape.setdefault(shape, []).append(a.id)
    return tuple(tuple(ids) for ids in by_shape.values() if len(ids) > 1)


def is_canonical(task: Task, plan: Plan, groups: tuple[tuple[str, ...], ...]) -> bool:
    """Whether, in every group of identical actions, the actions in task order take the plan's slots in
    order (a slot: the agent, in task order, and the position in its sequence). Of the ``m!`` plans that
    differ only by relabelling a group of ``m``, exactly this one is canonical."""
    slot = {}
    for n, agent in enumerate(task.agent_ids):
        for pos, action in enumerate(plan.sequence(agent)):
            slot[action] = (n, pos)
    return all(slot[a] < slot[b] for group in groups for a, b in itertools.pairwise(group))


def symmetry_factor(task: Task) -> int:
    """How many plans each canonical plan stands for: the product of ``m!`` over the groups of
    `identical_actions` (each relabelling of a plan is a distinct, valid plan)."""
    return math.prod(math.factorial(len(g)) for g in identical_actions(task))


def count_plans(task: Task, max_states: int | None = None) -> int:
    """The number of plans `generate_plans` yields, counted without enumerating them.

    A plan is valid iff its phase graph is acyclic, iff this greedy execution never gets stuck: an agent
    that is between actions first reveals its next action (or that it is done); otherwise the first
    agent (task order) whose next phase has all its task-graph predecessors done completes it. If every
    busy agent's next phase waits for a phase still ahead of another agent, those waits close a cycle.
    The greedy run is a function of the plan, and the choices it reveals are the plan, so valid plans and
    complete runs correspond one to one; a memoized count over run states ``(phases done, each agent's
    action and phase)`` counts them. The states are the task's order ideals times the agents' positions,
    far fewer than the plans when actions are independent (2,880 plans of tasks/kitting.yaml: 2,086
    states, 4 ms instead of 0.2 s), but still exponential in the number of independent actions (14 of
    them: millions of states). With `max_states`, raises `_TooManyStates` past that many
    (`estimate_plan_count` then falls back to a bound).
    """
    actions = task.actions
    index = {(a.id, p.id): (i, k) for i, a in enumerate(actions) for k, p in enumerate(a.phases)}
    bit: dict[tuple[int, int], int] = {}
    for i, a in enumerate(actions):
        for k in range(len(a.phases)):
            bit[(i, k)] = 1 << len(bit)
    needs = {ik: 0 for ik in bit}  # bitmask of the task-graph predecessors of each phase
    for pr in task.precedence:
        needs[index[(pr.after.action, pr.after.phase)]] |= bit[index[(pr.before.action, pr.before.phase)]]
    first_bit = [bit[(i, 0)] for i in range(len(actions))]
    all_done = (1 << len(bit)) - 1
    allowed = [[i for i, a in enumerate(actions) if ag.id in a.agents] for ag in task.agents]
    # a joint action (`Action.roles`) is revealed by each of its agents in turn, and its phases are done
    # only when all of them are at that phase: they are done together, and a plan in which the agents'
    # orders of their joint actions disagree gets stuck (a cycle, as in the phase graph)
    # with a crew to choose (`Action.crews`), the crew is the agents that revealed it: its first phase is
    # done when the agents at it are one of its crews (all crews have the same size, so none is done
    # with part of its crew there; an agent that would join a full crew later finds the phase done)
    number = {ag: n for n, ag in enumerate(task.agent_ids)}
    takers = [frozenset(frozenset(number[ag] for ag in crew) for crew in a.crews) for a in actions]
    choosing, finished = -1, -2  # agent states besides (action, phase index)

    memo: dict[tuple[int, tuple], int] = {}

    def count(done: int, states: tuple) -> int:
        key = (done, states)
        found = memo.get(key)
        if found is None:
            if max_states is not None and len(memo) >= max_states:
                raise _TooManyStates
            found = memo[key] = step(done, states)
        return found

    def step(done: int, states: tuple) -> int:
        if done == all_done:
            return 1  # every agent is between actions: its only choice left is "done"
        busy = {st[0] for st in states if isinstance(st, tuple)}
        for n, st in enumerate(states):
            if st == choosing:  # reveal this agent's next action, or that its sequence ends here
                total = count(done, states[:n] + (finished,) + states[n + 1:])
                for i in allowed[n]:
                    if not done & first_bit[i] and (i not in busy or takers[i]):
                        total += count(done, states[:n] + ((i, 0),) + states[n + 1:])
                return total
        for n, st in enumerate(states):
            if isinstance(st, tuple) and needs[st] & ~done == 0:
                i, k = st
                after = (i, k + 1) if k + 1 < len(actions[i].phases) else choosing
                if not takers[i]:
                    return count(done | bit[st], states[:n] + (after,) + states[n + 1:])
                there = frozenset(m for m, x in enumerate(states) if x == st)
                if there in takers[i]:  # every agent of one of its crews is there
                    return count(done | bit[st], tuple(after if m in there else x for m, x in enumerate(states)))
        return 0  # stuck: the plan's phase graph has a cycle, or actions are left that nobody will do

    return count(0, (choosing,) * len(task.agents))


def plan_count_bound(task: Task) -> int:
    """An upper bound of the plan count, exact when the task has no precedence: the sum over
    allocations of the product of each agent's number of orders of its actions (``k!`` for ``k``
    actions), as if no order were forbidden. A dynamic program over the actions whose state is each
    agent's number of actions: O(actions x states x agents), states at most ``(actions + 1) ** agents``.
    """
    ways: dict[tuple[int, ...], int] = {(0,) * len(task.agents): 1}
    for action in task.actions:
        nxt: dict[tuple[int, ...], int] = {}
        for counts, n in ways.items():
            if action.joint:  # in the sequence of every agent of its crew, one of its crews
                for crew in action.crews:
                    key = tuple(k + (agent.id in crew) for k, agent in zip(counts, task.agents, strict=True))
                    nxt[key] = nxt.get(key, 0) + n
                continue
            for i, agent in enumerate(task.agents):
                if agent.id in action.agents:
                    key = counts[:i] + (counts[i] + 1,) + counts[i + 1:]
                    nxt[key] = nxt.get(key, 0) + n
        ways = nxt
    return sum(n * math.prod(math.factorial(k) for k in counts) for counts, n in ways.items())


@dataclass(frozen=True, slots=True)
class PlanCount:
    """How many plans a task has: `value`, exact or (``exact`` False) an upper bound."""

    value: int
    exact: bool

    def __str__(self) -> str:
        return f"{self.value:,}" if self.exact else f"at most {self.value:,}"


def estimate_plan_count(task: Task, max_states: int = COUNT_STATES, symmetry: bool = False) -> PlanCount:
    """The plan count in bounded time and memory: `count_plans` if it needs at most `max_states` run
    states, else `plan_count_bound` (exact when the task has no precedence, an upper bound otherwise);
    with `symmetry`, of the canonical plans only (divided by `symmetry_factor`)."""
    factor = symmetry_factor(task) if symmetry else 1
    try:
        return PlanCount(count_plans(task, max_states) // factor, True)
    except _TooManyStates:
        return PlanCount(plan_count_bound(task) // factor, not task.precedence)


@dataclass(frozen=True, slots=True)
class Leg:
    """One phase of an agent's itinerary: travel from `origin` to `location`, then do `action.phase`."""

    agent: str
    index: int
    origin: str
    location: str
    action: str
    phase: str


def per_plan(size: int) -> Callable[[Callable[..., R]], Callable[..., R]]:
    """Remember ``fn(task, plan, *args)`` for the last `size` or so calls: what a plan's compile asks for
    many times (its legs, its timepoint names). Keyed by the task's identity, the plan and `args`; each
    entry holds its task, which it must be (not a namesake at a reused address). Safe across tasks and
    threads (an entry is only ever added whole)."""
    def wrap(fn: Callable[..., R]) -> Callable[..., R]:
        memo: dict[tuple, tuple[Task, R]] = {}

        @functools.wraps(fn)
        def remembered(task: Task, plan: Plan, *args: Hashable) -> R:
            key = (id(task), plan, *args)
            hit = memo.get(key)
            if hit is not None and hit[0] is task:
                return hit[1]
            value = fn(task, plan, *args)
            if len(memo) >= size:
                memo.clear()
            memo[key] = (task, value)
            return value
        return remembered
    return wrap


@per_plan(512)
def agent_legs(task: Task, plan: Plan, agent_id: str) -> tuple[Leg, ...]:
    """The agent's legs in order, starting at its start location (a leg may have origin == location).
    Remembered per plan (`per_plan`): a plan's compile asks for them a dozen times."""
    here = task.agent(agent_id).start
    legs: list[Leg] = []
    for action_id in plan.sequence(agent_id):
        for phase in task.action(action_id).phases:
            legs.append(Leg(agent_id, len(legs), here, phase.location, action_id, phase.id))
            here = phase.location
    return tuple(legs)


def pin_actions(task: Task, pins: dict[str, str]) -> Task:
    """`task` with each action in `pins` given to its one agent (``hrc compile --pin ACTION=AGENT``).

    Fewer plans where the choice is already made: an action pinned to one of two agents halves the
    allocations. What it gives up: the plans in which another agent does that action are not compiled,
    so neither the ranking nor the dispatcher can fall back on them (the dispatcher sees the pinned task:
    it is the task as compiled, in ``input/task.yaml``). Raises `InputError` for an unknown action, or an
    agent that may not do it.
    """
    actions = {a.id: a for a in task.actions}
    for action_id, agent_id in pins.items():
        where = f"--pin {action_id}={agent_id}"
        if action_id not in actions:
            raise InputError(task.source, where, f"no action '{action_id}' (actions: {', '.join(actions)})")
        if actions[action_id].joint:
            raise InputError(task.source, where, f"{action_id} is a joint action: every agent of it takes part")
        if agent_id not in actions[action_id].agents:
            raise InputError(task.source, where, f"'{agent_id}' may not do {action_id} (its agents: "
                                                 f"{', '.join(actions[action_id].agents)})")
    new = []
    for a in task.actions:
        if a.id in pins:
            ag = pins[a.id]
            a = replace(a, agents=(ag,), phases=tuple(replace(p, durations=tuple((x, iv) for x, iv in p.durations
                                                                                   if x == ag)) for p in a.phases))
        new.append(a)
    return replace(task, actions=tuple(new))


def relabellings(task: Task, plan: Plan, groups: tuple[tuple[str, ...], ...]) -> tuple[Plan, ...]:
    """`plan` and every other plan obtained by permuting the actions within each group of
    `identical_actions` (`plan` first, then in the order of the permutations; ``prod(m!)`` plans when
    `plan` is canonical). Each is valid when `plan` is: the actions swapped are told apart by nothing."""
    out = [plan]
    seen = {plan}
    for combo in itertools.product(*(itertools.permutations(g) for g in groups)):
        rename = {a: b for g, p in zip(groups, combo, strict=True) for a, b in zip(g, p, strict=True)}
        agent = {rename.get(a, a): ag for a, ag in plan.allocation}
        other = Plan(allocation=tuple((a, agent[a]) for a, _ in plan.allocation),
                     sequences=tuple((ag, tuple(rename.get(x, x) for x in seq)) for ag, seq in plan.sequences))
        if other not in seen:
            seen.add(other)
            out.append(other)
    return tuple(out)


def plan_families(task: Task) -> Iterator[tuple[Plan, ...]]:
    """Every plan of `generate_plans`, grouped: each canonical plan (`is_canonical`) followed by its
    `relabellings`. A family's plans have the same STNU up to the names of identical actions, so
    motion acquisition's search (`hrc.compile.motion_pattern`) runs once per family, not once per plan.
    The same set of plans as `generate_plans`, in another order (the compile ranks them anyway)."""
    groups = identical_actions(task)
    for plan in generate_plans(task, symmetry=bool(groups)):
        yield relabellings(task, plan, groups) if groups else (plan,)


def family_of(task: Task, plan: Plan, symmetry: bool = False) -> tuple[Plan, ...]:
    """The family `plan` is compiled in: as `plan_families` yields it (its canonical plan, then the
    canonical plan's `relabellings`), or with `symmetry` (one plan per family) the canonical plan alone.
    `plan` is a member (with `symmetry`, only when canonical)."""
    groups = identical_actions(task)
    if not groups:
        return (plan,)
    canonical = next(p for p in relabellings(task, plan, groups) if is_canonical(task, p, groups))
    return (canonical,) if symmetry else relabellings(task, canonical, groups)


_AGENT_BREAK = 0xFFFF


def plan_code(task: Task, plan: Plan) -> bytes:
    """`plan` as ``len(actions) + len(agents) - 1`` 16-bit numbers (native byte order): each agent's
    sequence (agents in task order) as action indices, the agents' sequences parted by 0xFFFF. What a
    streamed compile keeps of each plan when it may need the plan again (`plan_from_code`); every plan
    of a task has a code of the same length."""
    index = {a: i for i, a in enumerate(task.action_ids)}
    out = array("H")
    for n, agent in enumerate(task.agent_ids):
        if n:
            out.append(_AGENT_BREAK)
        out.extend(index[a] for a in plan.sequence(agent))
    return out.tobytes()


def code_sequences(task: Task, codes: np.ndarray) -> np.ndarray:
    """(k, G, A) int16: each agent's actions in order (task action indices), -1 after its last, of the
    plans whose `plan_code`s are the rows of `codes` ((k, W) uint16): what
    ``plan_sequences(task, plan_from_code(task, code))`` gives each (`hrc.compile.dispatch_form`), read
    off the codes as arrays, without a `Plan` per plan."""
    import numpy as np

    k, width = codes.shape
    out = np.full((k, len(task.agents), len(task.actions)), -1, dtype=np.int16)
    parts = codes == _AGENT_BREAK
    column = np.arange(width)
    agent = np.cumsum(parts, axis=1)  # an action's agent: the breaks before it
    last = np.maximum.accumulate(np.where(parts, column, -1), axis=1)  # the last break before it (-1: none)
    rows, cols = np.nonzero(~parts)
    out[rows, agent[rows, cols], (column - last - 1)[rows, cols]] = codes[rows, cols]
    return out


def plan_from_code(task: Task, code: bytes) -> Plan:
    """The plan `plan_code` wrote as `code`."""
    numbers = array("H")
    numbers.frombytes(code)
    sequences: list[tuple[str, tuple[str, ...]]] = []
    part: list[str] = []
    for x in numbers:
        if x == _AGENT_BREAK:
            sequences.append((task.agent_ids[len(sequences)], tuple(part)))
            part = []
        else:
            part.append(task.action_ids[x])
    sequences.append((task.agent_ids[len(sequences)], tuple(part)))
    agent_of = {a: agent for agent, seq in sequences for a in seq}
    if task.has_joint:  # a joint action: its crew's lead (its crew: the agents whose sequences hold it)
        robots = {ag.id for ag in task.agents if not ag.is_human}
        for a in task.actions:
            if a.joint:
                agent_of[a.id] = next(ag for ag, seq in sequences if ag in robots and a.id in seq)
    return Plan(allocation=tuple((a, agent_of[a]) for a in task.action_ids), sequences=tuple(sequences))


def spread_families(task: Task, count: int, symmetry: bool = False) -> list[tuple[Plan, ...]]:
    """Up to `count` families of `plan_families` (with `symmetry`, canonical plans alone) from allocations
    spread evenly over the allocation space: the first family of each. A sample of the plans that is not
    all of one corner of the space, as the stream's first plans are (allocations come in lexicographic
    order: the first ones give the human everything), for `hrc compile`'s up-front estimate."""
    choices = _doer_choices(task)
    total = allocation_count(task)
    before = must_precede(task)
    groups = identical_actions(task)
    # a stride near total / golden ratio, coprime with total, visits every allocation once, spread out
    stride = max(1, round(total / 1.618033988749895))
    while math.gcd(stride, total) != 1:
        stride += 1
    out: list[tuple[Plan, ...]] = []
    for k in range(min(total, 50 * count)):  # allocations without a canonical plan are passed over
        if len(out) >= count:
            break
        i = k * stride % total
        combo = []
        for c in reversed(choices):  # mixed radix, the last action fastest, as itertools.product
            i, digit = divmod(i, len(c))
            combo.append(c[digit])
        doers = tuple(reversed(combo))
        allocation = _named(task, doers)
        for sequences in _sequences(task, doers, before):
            plan = Plan(allocation=allocation, sequences=sequences)
            if not groups or is_canonical(task, plan, groups):
                out.append((plan,) if symmetry or not groups else relabellings(task, plan, groups))
                break
    return out
