"""Plans that extend an observed history: the search compile under a fixed prefix (issue 35, compile on demand).

When what the person does leaves every compiled plan, the dispatcher (`hrc.dispatch.on_demand`) asks for
plans that continue what was seen: each agent has done (or begun) the actions of its `Prefix`, in that
order. The plans wanted are the plans of the task's plan tree whose allocation gives each of those
actions to its agent and whose agents' sequences start with them; everything after is searched. A joint
action seen in an agent's prefix (issue 37) puts that agent in its crew: where the crew is a choice of
the plan (`hrc.model.Action.crews`), only crews that hold every agent seen at it are searched, so the
plans agree with the crew the dispatcher saw.

The search is `hrc.compile.search.search_plans` (best-first branch and bound with diving, Land & Doig
1960; its bounds `hrc.compile.bounds.NodeBounds`) on that subtree: `NodeBounds.children` filtered to the
nodes that fit the prefix (an allocation that gives a seen action to another agent, or a sequence that
leaves the seen order, has no plan that agrees with the history below it, so cutting it loses nothing).
The tree's canonical order of identical actions is lifted (the history names the very actions done,
not their canonical representatives), and each leaf is compiled with its family (`hrc.plans.family_of`),
so the plans come out as the exhaustive compile would write them.

**Deterministic.** The budget is in work (`families` compiled, and `NODES_PER_FAMILY` nodes per family),
never in seconds, and nothing else varies: the same task, paths (the compile's seed), options and
prefix give the same plans, byte for byte, in any process. This is what lets a dispatcher's log name
the plans it added and a replay compile them again (`hrc.dispatch.on_demand`).

Each plan goes through the compile's own per-plan step (`hrc.compile.compiler.compile_family`: motion
acquisition, the temporal net creator, the DC check), so its dispatch form record (`CompiledPlan.form`)
is what a compile would have written.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from hrc.model import Plan, Task

if TYPE_CHECKING:  # the compile itself only when plans are compiled: a dispatcher imports `Prefix` alone
    from hrc.compile.bounds import Node, NodeBounds
    from hrc.compile.compiler import CompiledPlan, CompileOptions
    from hrc.compile.search import SearchOutcome
    from hrc.motion import PathLibrary

__all__ = ["EXTEND_FAMILIES", "EXTEND_K", "Extension", "Prefix", "extend_plans"]

EXTEND_K = 3
"""Plans asked for per history: the best few that extend it (the dispatcher needs one; a few give it room)."""
EXTEND_FAMILIES = 6
"""Default budget of one extension, in families compiled (2 per plan asked for, as the search's default)."""


@dataclass(frozen=True, slots=True)
class Prefix:
    """What the plans must extend: each agent's actions seen, in order (``((agent, (action, ...)), ...)``,
    agents in task order)."""

    sequences: tuple[tuple[str, tuple[str, ...]], ...]

    def to_json(self) -> dict[str, list[str]]:
        return {agent: list(seq) for agent, seq in self.sequences}

    @classmethod
    def from_json(cls, task: Task, obj: object) -> Prefix:
        """From `to_json`'s shape; `ValueError` when it does not fit `task`."""
        if not isinstance(obj, dict) or set(obj) - set(task.agent_ids):
            raise ValueError("a prefix names the task's agents")
        known = set(task.action_ids)
        seqs = []
        for agent in task.agent_ids:
            seq = obj.get(agent, [])
            if not isinstance(seq, list) or not all(isinstance(a, str) and a in known for a in seq):
                raise ValueError(f"{agent}'s prefix must be a list of the task's actions")
            seqs.append((agent, tuple(seq)))
        return cls(tuple(seqs))


@dataclass(frozen=True, slots=True)
class Extension:
    """`extend_plans`' result: the `plans` compiled (best first by `rank_key`), and what the search did."""

    prefix: Prefix
    plans: tuple[CompiledPlan, ...]
    outcome: SearchOutcome


def _fits(node: Node, forced: list[tuple[int, ...]], owner: dict[int, int], crews: dict[int, frozenset[int]]) -> bool:
    """Whether `node` can still lead to a plan that extends the prefix (`forced`: per agent, its action
    indices in order; `owner`: action -> agent; `crews`: joint action -> the crews, by number in
    `NodeBounds.crews`, that hold every agent seen at it)."""
    for i, ag in enumerate(node.alloc):
        if owner.get(i, ag) != ag:
            return False
        if i in crews and ag not in crews[i]:
            return False
    for ag, seq in enumerate(node.seqs):
        want = forced[ag]
        n = min(len(seq), len(want))
        if seq[:n] != want[:n]:
            return False
    return True


def extend_plans(task: Task, paths: PathLibrary, prefix: Prefix, *, k: int = EXTEND_K,
                 families: int = EXTEND_FAMILIES, options: CompileOptions | None = None,
                 bounds: NodeBounds | None = None) -> Extension:
    """The best `k` plans the search finds within `families` families compiled whose allocation and
    per-agent orders extend `prefix` (module docstring); each compiled with its GraphML and dispatch
    form record. `bounds`: `NodeBounds(task, paths, options.rank_by)` when the caller keeps one.
    Deterministic (no clock is read for what is compiled)."""
    from hrc.compile.bounds import NodeBounds
    from hrc.compile.compiler import CompileOptions, compile_family, rank_key
    from hrc.compile.search import search_plans

    options = options or CompileOptions()
    bounds = bounds or NodeBounds(task, paths, options.rank_by)
    index = {a: i for i, a in enumerate(task.action_ids)}
    agents = {a: g for g, a in enumerate(task.agent_ids)}
    forced: list[tuple[int, ...]] = [() for _ in task.agent_ids]
    owner: dict[int, int] = {}
    for agent, seq in prefix.sequences:
        g = agents[agent]
        forced[g] = tuple(index[a] for a in seq)
        owner.update((i, g) for i in forced[g] if not task.actions[i].joint)  # a joint one: its crew's
    # a joint action seen with some of its agents (issue 37): only crews that hold all of them (a crew is a
    # choice of the plan, `hrc.model.Action.crews`; an agent whose prefix has it is in the plan's crew)
    crews: dict[int, frozenset[int]] = {}
    for i, action in enumerate(task.actions):
        seen = {g for g, f in enumerate(forced) if i in f}
        if action.joint and seen:
            crews[i] = frozenset(c for c, crew in enumerate(bounds.crews[i]) if seen <= set(crew))
    # `cover` lifts the canonical order of identical actions (the prefix names the very actions done) and
    # prunes allocations of the most constrained agent's prefix early; the filter keeps every agent's prefix
    lead = max(range(len(forced)), key=lambda g: (len(forced[g]), -g))

    def children(node: Node, ends: tuple[int, ...]) -> list[Node]:
        return [c for c in bounds.children(node, ends, (lead, forced[lead])) if _fits(c, forced, owner, crews)]

    compiled: dict[str, tuple[tuple, CompiledPlan]] = {}

    def compile_one(family: tuple[Plan, ...]) -> list[tuple]:
        keys = []
        for cp in compile_family(task, family, paths, options, True):
            key = rank_key(cp, options.rank_by)
            keys.append(key)
            compiled.setdefault(cp.plan.id, (key, cp))
        return keys

    outcome = search_plans(task, bounds, k, families, None, compile_one, children=children)
    wanted = dict(prefix.sequences)
    plans = tuple(cp for _, cp in sorted(compiled.values(), key=lambda x: x[0])
                  if all(cp.plan.sequence(a)[:len(s)] == s for a, s in wanted.items()))
    return Extension(prefix, plans, outcome)

