"""The search compile: the best K plans by the ranking's own order, without enumerating every plan (issue 35).

Where the exhaustive compile (`hrc.compile.stream`) takes every plan of `hrc.plans.generate_plans`, this
one searches the same plan space, best first (A*-like branch and bound: Land & Doig 1960; Lawler &
Wood, "Branch-and-bound methods: a survey", Oper. Res. 14, 1966), and compiles a plan only when no
unexplored family of plans can still beat it. Every plan it compiles goes through exactly the per-plan
compile of the exhaustive stream (`hrc.compile.stream.compile_records`: motion acquisition, the
temporal net creator, the DC check), and into the same `hrc.compile.sink.PlanSink`, so its output
(``compiled.json``, STNUs, the dispatch form) reads and dispatches as any other.

**The plan tree.** A node fixes the agent of the first actions (task order); once every action has
one, it extends the sequence of the agent whose sequence prefix ends first in the relaxation (ties:
task order). Which agent is extended is a function of the node, so every plan has exactly one path
from the root: no plan is reached twice. Identical actions (`hrc.plans.identical_actions`) are taken
in their canonical order only, and a leaf's whole family (its relabellings) is compiled, as
`hrc.plans.plan_families` groups them. A joint action (issue 37) is allocated a crew (`hrc.model.Action.crews`:
where the crew is a choice of the plan, each crew is a child of its own; the plan's allocation names its
lead, `hrc.model.Task.lead`) and it enters the sequence of every agent of that crew, each in its turn;
orders that disagree on when close a cycle, which the bound finds (no plan below). Identical joint
actions with a crew choice are not put in canonical order by the tree (`NodeBounds.crew_groups`): their
non-canonical leaves are dropped instead, so each family is still reached once.

**Bounds.** `hrc.compile.bounds.NodeBounds`: a relaxation in which the co-worker costs nothing
(interference only ever adds time: that module says where in the code this holds), per-agent loads
and the critical path of the task graph; class before makespan (a family is known not to be DC only
when even its bound breaks the deadline with the human at their slowest).

**What it guarantees** (`SearchOutcome`, written to ``compiled.json``'s ``"search"``): *closed* when every
family it did not compile has a bound worse than the K-th best plan found, by the ranking's order
(class, makespan to the second, preference, makespan): the first K ranks of the output are then the K
best of all plans. Otherwise (its time budget ran out first) the best found, with the best bound of
what was left: the gap says how much better, in seconds of the ranked makespan, an uncompiled plan of
the same class could be at most, or that one of a better class may exist. Never "exhaustive" unless
closed.

**Coverage of the person's choices.** Besides the best K: for each action the person could start next,
at the start and after each of their first ``cover - 1`` choices, one plan in which they do it (the best
the bound finds first, by a depth-first dive with the bound's order; not claimed optimal), so that the
dispatcher has a plan for what the person actually does. A choice no valid plan allows is not one
(the dive's tree is exhausted: reported as such). A team's people (issue 37) are covered each in turn,
in task order, each one's own choices (the other agents' parts free); the counts are summed over them.
A person's choices that depend on another person's (two people after the same part) are left to compile
on demand (`hrc.dispatch.on_demand`), which extends every agent's observed prefix at once.

Why branch and bound and not CP-SAT: the rank key is the *compiled* plan's (class by the DC check of
the STNU with its passing orders, makespans from its motion pattern), which no solver model holds; a
CP-SAT model would still be a relaxation whose answers must each go through the compile, and the
search needs the K best plus a proof of what was skipped, which best-first order with a bound gives
directly, with no new dependency. The bound is cheap (tens of microseconds per node).
"""

from __future__ import annotations

import heapq
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

from hrc.compile.bounds import Bound, Node, NodeBounds
from hrc.compile.compiler import CompiledPlan, CompiledPlanSet, CompileOptions, rank_key
from hrc.compile.defaults import COVER_DEPTH, DEFAULT_K, SEARCH_FAMILIES  # here too, as before
from hrc.compile.output import write_input
from hrc.compile.sink import REPORT_TOP, PlanSink
from hrc.compile.stream import compile_records
from hrc.model import Plan, Task
from hrc.motion import PathLibrary, plan_paths
from hrc.plans import family_of, identical_actions, relabellings

__all__ = ["COVER_DEPTH", "DEFAULT_K", "DIVE_NODES", "NODES_PER_FAMILY", "SEARCH_FAMILIES", "SearchOutcome",
           "SearchResult", "compile_search", "search_in_memory", "search_plans"]


NODES_PER_FAMILY = 400
"""Nodes the search may expand per family of its budget."""


DIVE_NODES = 5000
"""Most nodes one coverage dive expands before it gives that choice up (reported)."""

Progress = Callable[[str, int, int], None]


@dataclass(frozen=True, slots=True)
class SearchOutcome:
    """What a search compile did and guarantees (module docstring)."""

    k: int
    found: int  # plans compiled
    families: int  # leaves compiled (a family each)
    nodes: int  # nodes whose children were bounded
    seconds: float
    closed: bool  # the first min(k, found) ranks are the best of all plans
    kth: tuple | None  # the K-th best key found (its first four parts), None with fewer than K plans
    best: tuple | None  # the best key found (first four parts)
    open_bound: tuple | None  # the best bound left unexplored (None: nothing left)
    cover_depth: int = 0
    choices: int = 0  # person's choices looked at
    covered: int = 0  # of them, with a compiled plan
    impossible: int = 0  # no valid plan allows them
    given_up: int = 0  # the dive's node cap or the time ran out first
    cover_seconds: float = 0.0
    seconds_to_best: float = 0.0  # from the search's start to the compile of its best plan

    def gap(self, key: tuple | None) -> float | None:
        """Seconds by which an uncompiled plan of `key`'s class could beat `key`'s ranked makespan at most
        (0 when closed; None when a plan of a better class may exist)."""
        if self.closed:
            return 0.0
        if key is None:  # fewer plans found than asked for: nothing is known of the missing ones
            return None
        if self.open_bound is None:
            return 0.0
        if self.open_bound[0] < key[0]:
            return None
        if self.open_bound[0] > key[0]:
            return 0.0
        return max(0.0, round(key[3] - self.open_bound[3], 3))

    def guarantee(self) -> str:
        """One line saying what is guaranteed."""
        if self.closed:
            return (f"optimal: the first {min(self.k, self.found)} ranks are the best of all plans (every family "
                    "not compiled has a bound worse than the K-th plan found)")
        best = self.gap(self.best)
        worst = self.gap(self.kth)
        assert self.open_bound is not None
        cls = ("DC", "consistent", "inconsistent")[self.open_bound[0]]
        if best is None:
            return (f"best found, not proven: the time ran out with families left whose bound is {cls} "
                    f"{self.open_bound[3]:.1f} s, so a plan of a better class than the best found may exist")
        kth = (f" and the K-th by at most {worst:.1f} s" if worst is not None else
               f"; only {self.found} of the {self.k} plans asked for were found" if self.kth is None else
               "; a plan of a better class than the K-th may exist")
        return (f"best found, not proven: a plan not compiled could beat the best by at most {best:.1f} s{kth}"
                f" (the best bound left: {cls}, {self.open_bound[3]:.1f} s)")

    def header(self) -> dict:
        """``compiled.json``'s ``"search"`` entry."""
        return {"method": "branch and bound (hrc.compile.search)", "k": self.k, "closed": self.closed,
                "guarantee": self.guarantee(), "plans_compiled": self.found, "families": self.families,
                "nodes": self.nodes, "best_gap_s": self.gap(self.best), "kth_gap_s": self.gap(self.kth),
                "open_bound": None if self.open_bound is None else
                {"class": ("DC", "consistent", "inconsistent")[self.open_bound[0]],
                 "makespan_s": self.open_bound[3]},
                "coverage": {"depth": self.cover_depth, "choices": self.choices, "covered": self.covered,
                             "impossible": self.impossible, "given_up": self.given_up}}


@dataclass(frozen=True, slots=True)
class SearchResult:
    """`compile_search`'s result: the report's view of the plans and what the search did."""

    plan_set: CompiledPlanSet
    outcome: SearchOutcome


def _plan(task: Task, node: Node) -> Plan:
    """A leaf's plan. A joint action's `Node.alloc` is its crew's number (`NodeBounds.crews`): the plan's
    allocation names its lead, the first robot (task order) whose sequence holds it (`hrc.model.Task.lead`)."""
    sequences = tuple((agent, tuple(task.action_ids[i] for i in seq))
                      for agent, seq in zip(task.agent_ids, node.seqs, strict=True))
    agents = task.agents
    allocation = []
    for i, (action, ag) in enumerate(zip(task.actions, node.alloc, strict=True)):
        if action.joint:
            ag = next(g for g, seq in enumerate(node.seqs) if i in seq and not agents[g].is_human)
        allocation.append((action.id, task.agent_ids[ag]))
    return Plan(allocation=tuple(allocation), sequences=sequences)


@dataclass
class _State:
    """The plans compiled so far (mutable, the search's own)."""

    keys: list[tuple] = field(default_factory=list)  # best first, at most k (first four parts of rank_key)
    ids: set[str] = field(default_factory=set)
    # each person's sequence prefixes compiled, ``(person, (action, ...))``
    prefixes: set[tuple[str, tuple[str, ...]]] = field(default_factory=set)
    families: int = 0
    best_at: float = 0.0  # time.perf_counter() when the best key so far was found


def search_plans(task: Task, bounds: NodeBounds, k: int, families: int, seconds: float | None,
                 compile_family: Callable[[tuple[Plan, ...]], list[tuple]],
                 stop: Callable[[], None] | None = None, state: _State | None = None,
                 progress: Progress | None = None,
                 children: Callable[[Node, tuple[int, ...]], list[Node]] | None = None,
                 batch: int = 1,
                 compile_batch: Callable[[list[tuple[Plan, ...]]], list[list[tuple]]] | None = None
                 ) -> SearchOutcome:
    """Best-first branch and bound for the `k` best plans (module docstring). `compile_family(family)`
    compiles a family and returns each plan's `rank_key`. Stops (then not closed) once `families` families
    were compiled or ``NODES_PER_FAMILY * families`` nodes expanded (a budget in work: the same output on
    any machine), or after `seconds` if given (then it depends on the machine's pace). `children`: the
    tree below a node (default `NodeBounds.children`; `hrc.compile.extend` gives a subtree): a leaf
    reached through a non-canonical path is compiled with its family (`hrc.plans.family_of`).

    `batch` > 1 (with `compile_batch`, which compiles a list of families, maybe in parallel, and returns
    their keys in the same order): the dives collect up to `batch` leaves against the bar of the plans
    compiled so far, then all are compiled at once and taken in the order they were found. The output is
    a function of `batch`, not of how many workers compile a batch (sound: a bar that is not yet lowered
    by the batch's own plans prunes less, never more)."""
    t0 = time.perf_counter()
    kids_of = children or bounds.children
    state = state or _State()
    groups = identical_actions(task)
    root = bounds.root()
    rb = bounds.bound(root)
    heap: list[tuple[tuple, int, int, Node, Bound]] = []
    counter = 0
    nodes = 0
    if rb is not None:
        heap.append((rb.key, 0, counter, root, rb))
    closed = False
    open_bound = None
    pending: list[tuple[Plan, ...]] = []

    def flush() -> None:
        if not pending:
            return
        found = compile_batch(list(pending)) if compile_batch is not None else [compile_family(f) for f in pending]
        for family, keys in zip(pending, found, strict=True):
            _take(state, task, family, keys, k)
        pending.clear()
        if progress is not None:
            progress("search", len(state.ids), k)

    while heap:
        if stop is not None:
            stop()
        kth = state.keys[k - 1] if len(state.keys) >= k else None
        key, depth, _, node, b = heap[0]
        if kth is not None and key > kth:
            if pending:  # the batch's plans may lower the bar further: take them first
                flush()
                continue
            closed = True
            open_bound = key
            break
        if (state.families + len(pending) >= families or nodes >= NODES_PER_FAMILY * families
                or (seconds is not None and time.perf_counter() - t0 > seconds)):
            if pending:
                flush()
                continue
            open_bound = key
            break
        heapq.heappop(heap)
        # dive: from the best open node, follow the best child down to a leaf, the other children into the
        # queue (best-first with diving, as MIP solvers do: a large tree's frontier is too wide for pure
        # best-first to reach a leaf soon). A leaf reached has a bound no worse than the K-th plan so far,
        # so a closed search would have had to compile it anyway (or prove it worse later)
        while True:
            if bounds.is_leaf(node):
                plan = _plan(task, node)
                family = (family_of(task, plan) if children is not None else
                          relabellings(task, plan, groups) if groups else (plan,))
                pending.append(family)
                if len(pending) >= batch:
                    flush()
                break
            nodes += 1
            kids: list[tuple[tuple, int, int, Node, Bound]] = []
            for child in kids_of(node, b.ends):
                cb = bounds.bound(child)
                if cb is None:
                    continue
                ckey = max(cb.key, key)
                if kth is not None and ckey > kth:
                    continue
                counter += 1
                kids.append((ckey, depth - 1, counter, child, cb))
            if not kids:
                break
            kids.sort()
            for entry in kids[1:]:
                heapq.heappush(heap, entry)
            key, depth, _, node, b = kids[0]
            kth = state.keys[k - 1] if len(state.keys) >= k else None
    flush()
    if not heap:
        closed, open_bound = True, None
    kth = state.keys[k - 1] if len(state.keys) >= k else None
    return SearchOutcome(k=k, found=len(state.ids), families=state.families, nodes=nodes,
                         seconds=round(time.perf_counter() - t0, 3), closed=closed, kth=kth,
                         best=state.keys[0] if state.keys else None, open_bound=open_bound,
                         seconds_to_best=round(max(0.0, state.best_at - t0), 3))


def _compile_leaf(task: Task, paths: PathLibrary, work: tuple) -> tuple[int, list[tuple[CompiledPlan, str]]]:
    """An executor's unit of work for a batched search: one family (`hrc.compile.stream.compile_records`)."""
    index, options, stnu, family = work
    return index, compile_records(options, stnu, task, paths, [family])


def _take(state: _State, task: Task, family: tuple[Plan, ...], keys: list[tuple], k: int) -> None:
    state.families += 1
    people = _people(task)
    for plan, key in zip(family, keys, strict=True):
        if plan.id in state.ids:
            continue
        state.ids.add(plan.id)
        state.keys.append(key[:4])
        for human in people:
            seq = plan.sequence(human)
            state.prefixes.update((human, seq[:n]) for n in range(1, len(seq) + 1))
    first = state.keys[0] if state.keys else None
    state.keys.sort()
    del state.keys[k:]
    if state.keys[0] != first:
        state.best_at = time.perf_counter()


def _people(task: Task) -> tuple[str, ...]:
    """The task's people, in task order (each one's choices are covered: a team's too, issue 37)."""
    return tuple(a.id for a in task.agents if a.is_human)


def _dive(task: Task, bounds: NodeBounds, agent: int, cover: tuple[int, ...], budget: int) -> Node | None | bool:
    """Depth-first, children best bound first, to the first leaf whose sequence of the person `agent`
    (index in task order) starts with `cover`: the leaf; None when no valid plan does (the tree is
    exhausted); False when `budget` nodes were expanded first."""
    root = bounds.root()
    rb = bounds.bound(root)
    stack = [] if rb is None else [(root, rb)]
    expanded = 0
    while stack:
        node, b = stack.pop()
        if bounds.is_leaf(node):
            return node
        expanded += 1
        if expanded > budget:
            return False
        kids: list[tuple[tuple, int, int, Node, Bound]] = []
        for child in bounds.children(node, b.ends, (agent, cover)):
            cb = bounds.bound(child)
            if cb is not None:
                kids.append((cb.key, cb.lo, len(kids), child, cb))
        kids.sort(reverse=True)  # the best popped first
        stack.extend((child, cb) for *_, child, cb in kids)
    return None


def _cover(task: Task, bounds: NodeBounds, state: _State, depth: int, deadline: float,
           compile_family: Callable[[tuple[Plan, ...]], list[tuple]],
           stop: Callable[[], None] | None) -> tuple[int, int, int, int]:
    """Coverage (module docstring), of every person in turn (task order): (choices, covered, impossible,
    given up), summed over them."""
    found = (0, 0, 0, 0)
    for human in _people(task) if depth >= 1 else ():
        mine = _cover_person(task, bounds, state, task.agent_ids.index(human), depth, deadline, compile_family, stop)
        found = tuple(a + b for a, b in zip(found, mine, strict=True))  # type: ignore[assignment]
    return found


def _cover_person(task: Task, bounds: NodeBounds, state: _State, h: int, depth: int, deadline: float,
                  compile_family: Callable[[tuple[Plan, ...]], list[tuple]],
                  stop: Callable[[], None] | None) -> tuple[int, int, int, int]:
    """`_cover` for the person `h` (index in task order)."""
    human = task.agent_ids[h]
    mine = [i for i in range(bounds.n) if h in bounds.does[i]]  # (a joint action of theirs too)
    choices = covered = impossible = given_up = 0
    level: list[tuple[int, ...]] = [()]
    for _ in range(depth):
        nxt = []
        for prefix in level:
            for x in mine:
                if x in prefix:
                    continue
                if stop is not None:
                    stop()
                target = (*prefix, x)
                choices += 1
                names = tuple(task.action_ids[i] for i in target)
                if (human, names) in state.prefixes:
                    covered += 1
                    nxt.append(target)
                    continue
                if time.perf_counter() > deadline:
                    given_up += 1
                    continue
                leaf = _dive(task, bounds, h, target, DIVE_NODES)
                if leaf is None:
                    impossible += 1
                elif leaf is False:
                    given_up += 1
                else:
                    assert isinstance(leaf, Node)
                    family = family_of(task, _plan(task, leaf))  # the leaf may not be canonical
                    _take(state, task, family, compile_family(family), len(state.keys) or 1)
                    covered += 1
                    nxt.append(target)
        level = nxt
    return choices, covered, impossible, given_up


def compile_search(task: Task, out_dir: Path, k: int = DEFAULT_K, *, seed: int = 0,
                   options: CompileOptions | None = None, stnu: str = "graphml", keep: int = REPORT_TOP,
                   families: int | None = None, seconds: float | None = None, cover: int = COVER_DEPTH,
                   progress: Progress | None = None,
                   stop: Callable[[], None] | None = None, paths: PathLibrary | None = None,
                   collect: dict[str, CompiledPlan] | None = None, batch: int = 1, jobs: int | None = None,
                   executor: str | None = None) -> SearchResult:
    """Search `task`'s best `k` plans (and the coverage of the person's first `cover` choices) and write
    them into `out_dir` as `hrc.compile.stream.compile_stream` writes a compile. `families`: the best-K
    search's budget in families compiled (default ``SEARCH_FAMILIES * k``); `seconds`: a wall-clock limit
    for it and as much again for the coverage (the output then depends on the machine's pace). `collect`:
    every plan compiled goes in it whole, by id. `batch` > 1: the best-K search compiles up to that many
    leaves at a time on the executor (`hrc.compile.executors.make_executor(executor, jobs)`: serial, a
    local pool, or Dask), the same output for any executor and number of workers (`search_plans`).
    Raises `hrc.errors.HrcError`."""
    if k < 1:
        raise ValueError(f"k must be at least 1, got {k}")
    options = options or CompileOptions()
    out_dir = Path(out_dir)
    write_input(task, out_dir)
    sink = PlanSink(task, out_dir, stnu, keep, options.rank_by)
    try:
        if paths is None:
            paths = plan_paths(task, seed=seed,
                               progress=(lambda d, t: progress("motion", d, t)) if progress else None)
        bounds = NodeBounds(task, paths, options.rank_by)

        def take(records: list[tuple[CompiledPlan, str]]) -> list[tuple]:
            keys = []
            for cp, tail in records:
                if collect is not None:  # whole, GraphML and dispatch form record with it (the simulator's)
                    collect[cp.plan.id] = cp
                sink.add(cp, tail)
                keys.append(rank_key(cp, options.rank_by))
            return keys

        def compile_family(family: tuple[Plan, ...]) -> list[tuple]:
            return take(compile_records(options, stnu, task, paths, [family]))

        state = _State()
        budget = families or SEARCH_FAMILIES * k
        if batch > 1:
            from hrc.compile.executors import make_executor

            with make_executor(executor, jobs) as ex:
                def compile_batch(found: list[tuple[Plan, ...]]) -> list[list[tuple]]:
                    work = [(i, options, stnu, family) for i, family in enumerate(found)]
                    done = dict(ex.map_chunks(_compile_leaf, task, paths, work, stop))
                    return [take(done[i]) for i in range(len(found))]  # in the order found: any executor

                best = search_plans(task, bounds, k, budget, seconds, compile_family, stop, state, progress,
                                    batch=batch, compile_batch=compile_batch)
        else:
            best = search_plans(task, bounds, k, budget, seconds, compile_family, stop, state, progress)
        t1 = time.perf_counter()
        deadline = math.inf if seconds is None else t1 + seconds
        found = _State(list(state.keys), state.ids, state.prefixes, state.families)
        choices, covered, impossible, given_up = _cover(task, bounds, found, cover, deadline, compile_family, stop)
        outcome = SearchOutcome(best.k, len(found.ids), found.families, best.nodes, best.seconds, best.closed,
                                best.kth, best.best, best.open_bound, cover, choices, covered, impossible,
                                given_up, round(time.perf_counter() - t1, 3), best.seconds_to_best)
        sink.extra = {"search": outcome.header()}
    except BaseException:
        sink.abandon()
        raise
    return SearchResult(replace(sink.finish(seed, paths, options), search=outcome.guarantee()), outcome)


def search_in_memory(task: Task, k: int = DEFAULT_K, *, seed: int = 0, cover: int = COVER_DEPTH,
                     families: int | None = None, options: CompileOptions | None = None) -> CompiledPlanSet:
    """`compile_search` for a caller that needs every plan it compiled in memory, whole (the simulator on a
    task beyond enumeration): written to a scratch folder (removed), ranked as there."""
    import tempfile

    found: dict[str, CompiledPlan] = {}
    with tempfile.TemporaryDirectory(prefix="hrc-search-") as scratch:
        result = compile_search(task, Path(scratch) / "out", k, seed=seed, options=options, keep=1 << 30,
                                families=families, cover=cover, collect=found)
    cps = result.plan_set
    return replace(cps, plans=tuple(replace(found[cp.plan.id], rank=cp.rank) for cp in cps.plans))
