"""The compiler (Strassmair & Taylor 2014, section V.A, Fig. 4): task in, ranked set of HRC schedules out.

Plan generation -> motion acquisition -> temporal net creator -> classification -> ranking. Free-space
paths are planned once, in this process (OMPL); the per-plan work (conflicts, detours, the choice of the
plan's motion pattern with its STNU and DC check: `hrc.compile.motion_pattern`) is pure data in and out
and runs in an executor: in-process (``jobs=1``), a local process pool (default),
or a Dask distributed scheduler (``executor="dask://HOST:PORT"``). The result does not depend on the
executor, the number of jobs or the order in which plans finish: plans are ranked by a total order.
"""

from __future__ import annotations

import functools
import itertools
import math
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, replace

from hrc.compile.classify import Classification, PlanClass, renamed
from hrc.compile.dispatch_form import plan_record
from hrc.compile.executors import make_executor
from hrc.compile.motion_pattern import (
    RANK_BY,
    MotionPattern,
    PlanChoice,
    apply_pattern,
    choose_pattern,
    pattern_key,
    pattern_network,
)
from hrc.compile.preferences import plan_preference
from hrc.compile.sensing import under_sensing
from hrc.compile.temporal_net_creator import blocked_stnu, relabel_timepoints
from hrc.io.task_file import task_digest
from hrc.model import Plan, Task
from hrc.motion import Motion, PathLibrary, plan_paths
from hrc.plans import count_plans, plan_families, symmetry_factor
from hrc.temporal import STNU, DCResult, Edge
from hrc.temporal.graphml import write_graphml

__all__ = ["ClassStats", "CompileOptions", "CompiledPlan", "CompiledPlanSet", "PlanSetSummary", "compile_chunk",
           "compile_family", "compile_plan", "compile_task", "relabel_check", "relabel_record",
           "rank_key"]

Progress = Callable[[str, int, int], None]  # (stage, done, total)


@dataclass(frozen=True, slots=True)
class CompileOptions:
    """How plans are read and ranked: `human_waits` (the paper's model, in which the robot's strategy
    decides when the human leaves for and starts a step; False: the human never waits for the robot's
    sake, `hrc.compile.temporal_net_creator`) and `rank_by` (the makespan that ranks plans within a class:
    "worst" case by default, "earliest" or "nominal")."""

    human_waits: bool = True
    rank_by: str = "worst"

    def __post_init__(self) -> None:
        if self.rank_by not in RANK_BY:
            raise ValueError(f"rank_by must be one of {', '.join(RANK_BY)}, got {self.rank_by!r}")


@dataclass(frozen=True, slots=True)
class CompiledPlan:
    """One plan with its motion pattern, its STNU (as CSTNU Tool GraphML), its class and its rank (1 = best)."""

    plan: Plan
    pattern: MotionPattern
    classification: Classification
    stnu_size: tuple[int, int, int]  # timepoints, requirement links, contingent links
    graphml: str
    rank: int = 0
    preference: float | None = None  # APA's optimal global preference value (None: no preferences)
    form: bytes = b""  # the plan's record in the dispatch form (`hrc.compile.dispatch_form.plan_record`), with graphml

    @property
    def plan_class(self) -> PlanClass:
        return self.classification.plan_class

    @property
    def blocked(self) -> bool:
        """Motion acquisition found no motion pattern at all: the co-workers would block each other whatever
        the order and route (`hrc.compile.motion_pattern.choose_pattern`). Such a plan is inconsistent, and
        its STNU carries none of its conflicts (its file carries the block instead: `blocked_stnu`; its
        dispatch form record the flag: `PlanEntry.blocked`). What readers test, never the explanation's
        words."""
        return self.pattern.candidates == 0

    @property
    def motions(self) -> tuple[Motion, ...]:
        return self.pattern.motions


@dataclass(frozen=True, slots=True)
class ClassStats:
    """Makespans of one class over every plan of a streamed compile (s; None without a schedule):
    quantiles (min, 25 %, median, 75 %, max) of the earliest and worst-case makespans, and the number of
    plans per bin of `PlanSetSummary.bins` by worst-case makespan."""

    plan_class: str
    plans: int
    no_schedule: int
    earliest: tuple[float, ...] | None
    worst: tuple[float, ...] | None
    histogram: tuple[int, ...]


@dataclass(frozen=True, slots=True)
class PlanSetSummary:
    """What a streamed compile knows of every plan when `CompiledPlanSet.plans` holds only the best
    (`hrc.compile.stream`): the total, the class counts, makespan statistics per class, and the plan
    with the slowest earliest makespan (for the report's sentence on an empty class)."""

    total: int
    counts: tuple[tuple[str, int], ...]
    stats: tuple[ClassStats, ...]
    bins: tuple[float, ...]  # edges of the worst-case makespan histogram (s)
    slowest: tuple[float, str] | None  # (earliest makespan, plan id)
    best: tuple[int, int] | None = None  # only the best K of each allocation kept: (K, plans compiled)


@dataclass(frozen=True, slots=True)
class CompiledPlanSet:
    """The compiler's output: every plan of `task`, ranked best first; or, with `summary` (a streamed
    compile), only the best plans and the best of each class, with their global ranks."""

    task: Task
    seed: int
    digest: str
    paths: PathLibrary
    plans: tuple[CompiledPlan, ...]
    options: CompileOptions = CompileOptions()
    summary: PlanSetSummary | None = None
    stnu_files: str = "graphml"  # how the STNUs were written (`hrc.compile.output.STNU_MODES`)
    search: str = ""  # a search compile's guarantee (`hrc.compile.search`): not every plan was compiled

    @property
    def total(self) -> int:
        """The number of plans compiled (more than ``len(plans)`` when only the best are held)."""
        return len(self.plans) if self.summary is None else self.summary.total

    def counts(self) -> dict[str, int]:
        if self.summary is not None:
            return dict(self.summary.counts)
        out = {c.value: 0 for c in PlanClass}
        for p in self.plans:
            out[p.plan_class.value] += 1
        return out


def compile_plan(task: Task, plan: Plan, paths: PathLibrary, options: CompileOptions = CompileOptions(),
                 graphml: bool = True, pattern: MotionPattern | None = None) -> CompiledPlan:
    """Motion acquisition (routes, conflicts, passing orders), temporal net creator and classification
    for one plan (rank left at 0; `graphml` False leaves its GraphML text empty). With `pattern` (the
    motion pattern of a plan of the same family, `compile_family`) motion acquisition's search is skipped."""
    choice = _choice(task, plan, paths, options, pattern)
    return _sensed(task, [_record(task, plan, choice, graphml)], choice, options)[0]


def _choice(task: Task, plan: Plan, paths: PathLibrary, options: CompileOptions,
            pattern: MotionPattern | None = None) -> PlanChoice:
    if pattern is None:
        return choose_pattern(task, plan, paths, human_waits=options.human_waits, rank_by=options.rank_by)
    return apply_pattern(task, plan, pattern, human_waits=options.human_waits)


def _record(task: Task, plan: Plan, choice: PlanChoice, graphml: bool, text: str | None = None,
            form: bytes | None = None) -> CompiledPlan:
    """The plan's record; its GraphML written from its STNU (or `text`, the same written otherwise), and
    with it its dispatch form record (or `form`: the same, of a plan it is a relabelling of)."""
    stnu = choice.net.stnu
    size = (len(stnu.timepoints), len(stnu.requirements), len(stnu.contingents))
    blocked = choice.pattern.candidates == 0  # `CompiledPlan.blocked`: its file carries the block (`blocked_stnu`)
    if text is None:
        text = write_graphml(blocked_stnu(stnu) if blocked else stnu) if graphml else ""
    if form is None:
        form = plan_record(task, plan, stnu, blocked) if graphml else b""
    return CompiledPlan(plan=plan, pattern=choice.pattern, classification=choice.classification, stnu_size=size,
                        graphml=text, preference=plan_preference(task, plan, choice.net), form=form)


def relabel_record(task: Task, first: CompiledPlan, stnu: STNU, plan: Plan, graphml: bool = True) -> CompiledPlan:
    """`first`'s record (whose STNU is `stnu`) carried over to `plan`, a relabelling of identical actions
    of it (`hrc.plans.relabellings`): the same pattern, class, makespans, idle times and preference value,
    the schedules and the STNU with the timepoints renamed (`relabel_timepoints`). Exactly what
    `compile_plan` gives `plan` with `first`'s pattern (tested), since its STNU is `stnu` up to the names,
    in the same order (and its dispatch form record is `first`'s: it names agents and leg positions, not
    actions); but not for a record with an explanation, whose words name actions (ValueError)."""
    c = first.classification
    if c.explanation:
        raise ValueError(f"plan {first.plan.id}'s explanation names actions: compile {plan.id} instead")
    names = relabel_timepoints(task, first.plan, plan)
    cls = replace(c, schedule=tuple((names[t], v) for t, v in c.schedule),
                  worst_schedule=tuple((names[t], v) for t, v in c.worst_schedule))
    text = write_graphml(stnu, names, f"{task.name}:{plan.id}") if graphml else ""  # of stnu.renamed(...)
    return replace(first, plan=plan, classification=cls, graphml=text)


def relabel_check(result: DCResult, names: Mapping[str, str]) -> DCResult:
    """A DC check's `result` on a network, for that network with its timepoints renamed (`names`): the
    same verdict and the same negative cycle, renamed (the checks work on timepoint indices, in the
    network's order, which renaming keeps)."""
    cycle = tuple(Edge(names[e.source], names[e.target], e.value, e.kind, names[e.label] if e.label else "")
                  for e in result.cycle)
    return DCResult(result.verdict, result.consistent, cycle)


def compile_family(task: Task, family: tuple[Plan, ...], paths: PathLibrary,
                   options: CompileOptions = CompileOptions(), graphml: bool = True) -> list[CompiledPlan]:
    """The plans of one family (`hrc.plans.plan_families`: the same up to the names of identical actions):
    the first compiled in full, the others with its motion pattern (their searches would find the same
    one): a DC plan's record renamed (`relabel_record`); the others' classified on their own STNU, for
    their explanations' words, with the first's DC check renamed (`relabel_check`). The same records as
    `compile_plan` on each."""
    choice = _choice(task, family[0], paths, options)
    first = _record(task, family[0], choice, graphml)
    if not first.classification.explanation:
        family_out = [first, *(relabel_record(task, first, choice.net.stnu, plan, graphml) for plan in family[1:])]
        return _sensed(task, family_out, choice, options)
    out = [first]
    written = blocked_stnu(choice.net.stnu) if first.blocked else choice.net.stnu  # once: `_layout`
    result = choice.check  # the first plan's check, with its negative cycle (None: each member checks)
    for plan in family[1:]:
        names = relabel_timepoints(task, family[0], plan)
        known = None if result is None else relabel_check(result, names)
        if known is None or first.blocked:
            member = apply_pattern(task, plan, first.pattern, human_waits=options.human_waits, known=known)
        else:  # the first's numbers, renamed, and its explanation in this plan's words (`renamed`)
            net = pattern_network(task, plan, first.pattern, options.human_waits)
            member = PlanChoice(first.pattern, net, renamed(first.classification, names, net, known))
        # its STNU is the first's renamed, so its GraphML is written from the first's (`relabel_record`)
        text = write_graphml(written, names, f"{task.name}:{plan.id}") if graphml else ""
        out.append(_record(task, plan, member, graphml, text, first.form))
    return _sensed(task, out, choice, options)


def _sensed(task: Task, family: list[CompiledPlan], choice: PlanChoice, options: CompileOptions) -> list[CompiledPlan]:
    """The family's records classed under the task's sensing (`hrc.compile.sensing`; none: unchanged). The
    delay check runs once, on the first plan (`choice`): the others are relabellings of it (the same
    network up to names, the same verdict); a plan that loses DC gets its explanation in its own words."""
    if task.sensing is None:
        return family
    first = under_sensing(task.sensing, choice.net, family[0].classification)
    out = [replace(family[0], classification=first)]
    lost = first.plan_class is not family[0].classification.plan_class
    for cp in family[1:]:
        c = cp.classification
        net = pattern_network(task, cp.plan, cp.pattern, options.human_waits) if lost and c.plan_class is PlanClass.DC \
            else choice.net
        out.append(replace(cp, classification=under_sensing(task.sensing, net, c, verdict_dc=not lost)))
    return out


def compile_chunk(task: Task, paths: PathLibrary, families: list[tuple[Plan, ...]],
                  options: CompileOptions = CompileOptions()) -> list[CompiledPlan]:
    """The unit of work sent to an executor (a module-level function, so it pickles by name): whole
    families of plans."""
    return [cp for family in families for cp in compile_family(task, family, paths, options)]


def rank_key(cp: CompiledPlan, rank_by: str = "worst") -> tuple:
    """DC < consistent < inconsistent; then the makespan `rank_by` names (worst case by default: a
    production engineer plans around the deadline) to the whole second; then the preference value
    (APA, higher first: among plans that finish in the same second, the one the worker likes best);
    then the exact makespans, total idle time, plan id.

    Why the second: makespans are exact to the millisecond, so a preference after them would only ever
    break exact ties, and a production engineer does not tell 61.2 s from 61.4 s; before them it would
    let a plan seconds slower win on the worker's taste. On the workshop (whose one preference is a
    breather of about 3 s between cube 1 and cube 2) it swaps two consistent plans, ranks 18 and 19:
    42f378b79a (worst case 85.27 s, value 9.0: the breather kept) before 94ba6ad056 (85.04 s, -9.90).
    """
    c = cp.classification
    idle = sum(s for _, s in c.idle) if c.idle else float("inf")
    key = pattern_key(c, rank_by)
    pref = -cp.preference if cp.preference is not None else float("inf")
    second = round(key[1]) if math.isfinite(key[1]) else key[1]  # no schedule at all: last in its class
    return (key[0], second, round(pref, 6), *key[1:], round(idle, 6), cp.plan.id)


def _chunks(items: Iterable[tuple[Plan, ...]], size: int) -> Iterator[list[tuple[Plan, ...]]]:
    it = iter(items)
    while chunk := list(itertools.islice(it, size)):
        yield chunk


def compile_task(task: Task, seed: int = 0, jobs: int | None = None, executor: str | None = None,
                 progress: Progress | None = None, options: CompileOptions = CompileOptions()) -> CompiledPlanSet:
    """Compile every plan of `task`; see the module docstring. Raises `hrc.errors.HrcError` subclasses."""
    total = count_plans(task)
    families = total // symmetry_factor(task)
    chunk_size = max(1, min(64, families // (4 * max(1, jobs or 2)) or 1))
    compiled: list[CompiledPlan] = []
    with make_executor(executor, jobs) as ex:  # first, so a bad executor fails before any planning
        paths = plan_paths(task, seed=seed,
                           progress=(lambda d, t: progress("motion", d, t)) if progress else None)
        work = functools.partial(_chunk_with, options)
        for batch in ex.map_chunks(work, task, paths, _chunks(plan_families(task), chunk_size)):
            compiled.extend(batch)
            if progress:
                progress("plans", len(compiled), total)
    compiled.sort(key=lambda cp: rank_key(cp, options.rank_by))
    ranked = tuple(replace(cp, rank=i + 1) for i, cp in enumerate(compiled))
    return CompiledPlanSet(task=task, seed=seed, digest=task_digest(task), paths=paths, plans=ranked,
                           options=options)


def _chunk_with(options: CompileOptions, task: Task, paths: PathLibrary,
                families: list[tuple[Plan, ...]]) -> list[CompiledPlan]:
    return compile_chunk(task, paths, families, options)
