"""What the report says, as plain values: the ranked rows, the featured plans, why a class is empty.

The Markdown and HTML writers render the same `ReportData`, so the two reports cannot disagree. No
plotting here (figures live in `gantt`, `maps` and `figures`). Building it is O(plans x actions).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from hrc.plans import agent_legs

if TYPE_CHECKING:
    from hrc.compile.compiler import CompiledPlan, CompiledPlanSet

__all__ = ["FEATURED_TOP", "Cause", "MotionNote", "ReportData", "Row", "agent_letters", "allocation_legend",
           "build_report_data", "empty_class_reason", "featured_plans", "fmt_cause", "fmt_idle", "fmt_makespan",
           "fmt_motion", "fmt_sequence", "fmt_stnu", "motion_notes", "split_explanation"]

FEATURED_TOP = 3
"""The best plans given a section of their own (plus the best of each class)."""


@dataclass(frozen=True, slots=True)
class Row:
    """One line of the ranked table; times in seconds, None where the plan has no schedule."""

    rank: int
    plan_id: str
    plan_class: str
    allocation: str  # one letter per action, task order: "H H R R H"
    sequences: tuple[tuple[str, tuple[str, ...]], ...]
    makespan: tuple[float, float] | None
    idle: tuple[tuple[str, float], ...]
    stnu_size: tuple[int, int, int]
    stnu_link: str
    featured: bool


@dataclass(frozen=True, slots=True)
class Cause:
    """A co-worker's motion that costs this motion `extra_time` seconds (kind: wait, detour, ...)."""

    agent: str
    step: str  # "cube1 fetch": what the co-worker travels to do
    origin: str
    target: str
    extra_time: float
    kind: str
    point: tuple[float, float]


@dataclass(frozen=True, slots=True)
class MotionNote:
    """A motion with interference: one agent's travel `origin -> target` to do `step`."""

    agent: str
    step: str
    origin: str
    target: str
    free_time: float
    max_time: float
    causes: tuple[Cause, ...]


@dataclass(frozen=True, slots=True)
class ReportData:
    """Everything both report formats show, in display order."""

    title: str
    task_name: str
    digest: str
    seed: int
    deadline: float | None
    agents: tuple[str, ...]
    actions: tuple[str, ...]
    letters: tuple[tuple[str, str], ...]  # agent -> allocation letter
    counts: tuple[tuple[str, int], ...]  # class -> plans, best class first
    empty_reasons: tuple[tuple[str, str], ...]  # class -> why no plan is in it
    rows: tuple[Row, ...]
    featured: tuple[str, ...]  # plan ids, rank order
    notes: tuple[tuple[str, tuple[MotionNote, ...]], ...]  # featured plan id -> interfering motions
    explanations: tuple[tuple[str, str], ...]  # featured plan id -> explanation ("" for DC)


def agent_letters(agents: tuple[str, ...]) -> dict[str, str]:
    """One upper-case letter per agent (its id's first), or the whole id when two would share one."""
    firsts = [a[:1].upper() for a in agents]
    return {a: (f if firsts.count(f) == 1 else a) for a, f in zip(agents, firsts, strict=True)}


def featured_plans(cps: CompiledPlanSet, top: int = FEATURED_TOP) -> tuple[CompiledPlan, ...]:
    """The `top` best plans plus the best plan of each class, in rank order (plans are ranked already)."""
    chosen = {cp.plan.id: cp for cp in cps.plans[:top]}
    seen: set[str] = set()
    for cp in cps.plans:
        cls = cp.plan_class.value
        if cls not in seen:
            seen.add(cls)
            chosen.setdefault(cp.plan.id, cp)
    return tuple(sorted(chosen.values(), key=lambda cp: cp.rank))


def _fmt(s: float) -> str:
    return f"{s:g}"


def empty_class_reason(cls: str, cps: CompiledPlanSet) -> str:
    """One sentence saying why no plan of `cps` is in class `cls` (a `PlanClass` value)."""
    plans = cps.plans
    deadline = cps.task.deadline
    if not plans:
        return f"no plan is {cls}: the task has no valid plan."
    if cls == "DC":
        best = plans[0]
        verdict, key, _ = split_explanation(best.classification.explanation)
        detail = verdict + (f" \u2014 {'; '.join(key)}" if key else "")
        return (f"no plan is DC: in every plan the robot depends on the human's timing (the best plan, "
                f"{best.plan.id}: {detail}).")
    if cls == "consistent":
        n_dc = sum(1 for p in plans if p.plan_class.value == "DC")
        if n_dc == len(plans):
            return ("no plan is merely consistent: every plan is DC, the robot alone can meet every "
                    "constraint whatever the human's timing within its bounds.")
        if n_dc == 0:
            return "no plan is consistent: not even human and robot together can meet every constraint."
        return ("no plan is merely consistent: where the team can meet every constraint, the robot can "
                "do so alone, whatever the human's timing.")
    if cls == "inconsistent":
        timed = [(p.classification.makespan[0], p.rank, p.plan.id) for p in plans
                 if p.classification.makespan is not None]
        if deadline is not None and timed:
            slowest_ms, _, slowest_id = max(timed)
            return (f"no plan is inconsistent: even the slowest allocation ({slowest_id}, earliest "
                    f"makespan {slowest_ms:.1f} s) meets the {_fmt(deadline)} s deadline and every other "
                    "constraint.")
        return "no plan is inconsistent: every plan has a schedule that meets every constraint."
    return f"no plan is {cls}."


def _step(action: str, phase: str) -> str:
    return f"{action} {phase}"


def motion_notes(cps: CompiledPlanSet, cp: CompiledPlan) -> tuple[MotionNote, ...]:
    """The plan's motions that the co-worker slows down, with who and by how much (agent, leg order)."""
    task = cps.task
    legs = {(leg.agent, leg.index): leg for a in task.agents for leg in agent_legs(task, cp.plan, a.id)}
    notes = []
    for m in sorted(cp.motions, key=lambda m: (task.agent_ids.index(m.agent), m.leg)):
        if not m.interference:
            continue
        leg = legs[(m.agent, m.leg)]
        causes = []
        for i in m.interference:
            other = legs.get((i.other_agent, i.other_leg))
            step = _step(other.action, other.phase) if other is not None else f"leg {i.other_leg}"
            causes.append(Cause(i.other_agent, step, i.other_origin, i.other_target, float(i.extra_time),
                                str(i.kind), (float(i.point[0]), float(i.point[1]))))
        notes.append(MotionNote(m.agent, _step(leg.action, leg.phase), m.origin, m.target, float(m.free_time),
                                float(m.max_time), tuple(causes)))
    return tuple(notes)


def build_report_data(cps: CompiledPlanSet) -> ReportData:
    """Collect what the reports show (see the module docstring)."""
    task = cps.task
    letters = agent_letters(task.agent_ids)
    featured = featured_plans(cps)
    featured_ids = {cp.plan.id for cp in featured}
    counts = cps.counts()
    rows = tuple(
        Row(rank=cp.rank, plan_id=cp.plan.id, plan_class=cp.plan_class.value,
            allocation=" ".join(letters[agent] for _, agent in cp.plan.allocation),
            sequences=cp.plan.sequences, makespan=cp.classification.makespan, idle=cp.classification.idle,
            stnu_size=cp.stnu_size, stnu_link=f"stnu/{cp.plan.id}.graphml", featured=cp.plan.id in featured_ids)
        for cp in cps.plans)
    return ReportData(
        title=f"Compiled schedules for {task.name}",
        task_name=task.name,
        digest=cps.digest,
        seed=cps.seed,
        deadline=task.deadline,
        agents=task.agent_ids,
        actions=task.action_ids,
        letters=tuple(letters.items()),
        counts=tuple(counts.items()),
        empty_reasons=tuple((c, empty_class_reason(c, cps)) for c, n in counts.items() if n == 0),
        rows=rows,
        featured=tuple(cp.plan.id for cp in featured),
        notes=tuple((cp.plan.id, motion_notes(cps, cp)) for cp in featured),
        explanations=tuple((cp.plan.id, cp.classification.explanation) for cp in featured),
    )


# Text shared by both formats (plain Unicode; the writers escape it for their own syntax).

def fmt_makespan(makespan: tuple[float, float] | None) -> str:
    """``52.3–61.0`` (earliest–worst case, s), or ``—`` when the plan has no schedule."""
    return "\u2014" if makespan is None else f"{makespan[0]:.1f}\u2013{makespan[1]:.1f}"


def fmt_idle(idle: tuple[tuple[str, float], ...]) -> str:
    """Idle seconds per agent in task order: ``3.2 / 10.1``."""
    return " / ".join(f"{s:.1f}" for _, s in idle) if idle else "\u2014"


def fmt_sequence(seq: tuple[str, ...]) -> str:
    return " \u2192 ".join(seq) if seq else "\u2014"


def fmt_stnu(size: tuple[int, int, int]) -> str:
    """Timepoints / requirement links / contingent links."""
    return " / ".join(str(n) for n in size)


def fmt_cause(cause: Cause) -> str:
    """``waits 2.5 s for human H → S1 (cube1 fetch) at (5.0, 5.4)``: what the delayed agent does, why."""
    who = f"{cause.agent} {cause.origin} \u2192 {cause.target} ({cause.step})"
    where = f"at ({cause.point[0]:.1f}, {cause.point[1]:.1f})"
    if cause.kind == "wait":
        return f"waits {cause.extra_time:.1f} s for {who} {where}"
    if cause.kind == "detour":
        return f"detours around {who} {where}: +{cause.extra_time:.1f} s"
    return f"{cause.kind} because of {who} {where}: +{cause.extra_time:.1f} s"


def fmt_motion(note: MotionNote) -> str:
    """``robot S3 → T (cube3 put): 9.1 s free, up to 12.3 s``."""
    return (f"{note.agent} {note.origin} \u2192 {note.target} ({note.step}): {note.free_time:.1f} s free, "
            f"up to {note.max_time:.1f} s")


def allocation_legend(data: ReportData) -> str:
    letters = ", ".join(f"{letter} = {agent}" for agent, letter in data.letters)
    return f"one letter per action in task order ({' '.join(data.actions)}): {letters}"


def split_explanation(text: str) -> tuple[str, tuple[str, ...], tuple[str, ...]]:
    """``(verdict, constraints, links)`` of a classification's explanation.

    The compiler writes ``"VERDICT: link; link; ..."``, the links of the cycle that breaks the plan in
    words. The few that are task constraints rather than steps of the plan (the makespan deadline, a
    temporal constraint, a task-graph edge) are the ones a reader wants first; all links go into a
    collapsed list. Text without that shape is returned whole as the verdict.
    """
    head, sep, rest = text.partition(": ")
    if not sep:
        return text, (), ()
    links = tuple(part.strip() for part in rest.split("; ") if part.strip())
    key = tuple(part for part in links if "deadline" in part or part.startswith(("constraint", "task graph")))
    return head, key, links
