"""What the protective separation costs each plan, against the fixed safety margin (ISO/TS 15066, 5.5.4).

A task with a `safety:` section is compiled twice by ``hrc compile`` (with the separation, and without it:
the task's `safety_margin` between the co-workers, today's model); `separation_costs` pairs the plans by
id and says, per plan, what the class, the worst-case makespan, the detours, the passing orders and the
reduced-speed legs became. Both reports render the same rows (`cost_cells`). O(plans).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hrc.compile.compiler import CompiledPlanSet

__all__ = ["COST_HEADER", "SeparationCost", "cost_cells", "separation_costs"]

COST_HEADER = ("Rank", "Plan", "Class (margin \u2192 S_p)", "Worst makespan (s)", "Change (s)", "Detours",
               "Passing orders", "Reduced-speed legs")


@dataclass(frozen=True, slots=True)
class SeparationCost:
    """One plan under both models: `before` with the fixed margin, `after` with the protective separation."""

    rank: int
    plan_id: str
    class_before: str
    class_after: str
    worst_before: float | None
    worst_after: float | None
    detours_before: int
    detours_after: int
    passing_before: int
    passing_after: int
    slow_legs: int


def separation_costs(iso: CompiledPlanSet, margin: CompiledPlanSet) -> tuple[SeparationCost, ...]:
    """Per plan of `iso` (rank order), the same plan in `margin`, the compile with the fixed margin."""
    before = {cp.plan.id: cp for cp in margin.plans}
    out = []
    for cp in iso.plans:
        old = before.get(cp.plan.id)
        if old is None:
            continue
        c, o = cp.classification, old.classification
        out.append(SeparationCost(
            rank=cp.rank, plan_id=cp.plan.id, class_before=o.plan_class.value, class_after=c.plan_class.value,
            worst_before=None if o.makespan is None else o.makespan[1],
            worst_after=None if c.makespan is None else c.makespan[1],
            detours_before=len(old.pattern.detours), detours_after=len(cp.pattern.detours),
            passing_before=len(old.pattern.constrained), passing_after=len(cp.pattern.constrained),
            slow_legs=sum(1 for m in cp.pattern.motions if m.speed)))
    return tuple(out)


def cost_cells(row: SeparationCost) -> tuple[str, ...]:
    """`row` as the cells of `COST_HEADER`."""
    def ms(x: float | None) -> str:
        return "\u2014" if x is None else f"{x:.1f}"

    change = ("\u2014" if row.worst_before is None or row.worst_after is None
              else f"{row.worst_after - row.worst_before:+.1f}")
    cls = row.class_after if row.class_before == row.class_after else f"{row.class_before} \u2192 {row.class_after}"
    return (str(row.rank), f"`{row.plan_id}`", cls, f"{ms(row.worst_before)} \u2192 {ms(row.worst_after)}", change,
            f"{row.detours_before} \u2192 {row.detours_after}", f"{row.passing_before} \u2192 {row.passing_after}",
            str(row.slow_legs))
