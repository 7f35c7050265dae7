"""What the protective separation costs each plan, against the fixed safety margin (ISO/TS 15066, 5.5.4).

A task with a `safety:` section is compiled twice by ``hrc compile`` (with the separation, and without it:
the task's `safety_margin` between the co-workers, today's model); `separation_costs` pairs the plans by
id and says, per plan, what the class, the worst-case makespan, the detours, the passing orders and the
reduced-speed legs became. Both reports render the same rows (`cost_cells`). O(plans).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from hrc.motion.separation import protective_separation

if TYPE_CHECKING:
    from hrc.compile.compiler import CompiledPlanSet
    from hrc.model import Task

__all__ = ["COST_HEADER", "SeparationCost", "cost_cells", "model_words", "separation_costs"]

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


def model_words(task: Task) -> str:
    """Which co-worker model the compile used, in one line (both reports' option list)."""
    robot = next(a for a in task.agents if not a.is_human)
    if task.safety is None:
        return (f"the fixed safety margin, {task.safety_margin:g} m between the two discs (the task has no "
                "safety: section)")
    moving, standing = protective_separation(task.safety, robot.speed), protective_separation(task.safety, 0.0)
    terms = (f"S_h {moving.human:.3f} + S_r {moving.robot:.3f} + S_s {moving.stopping:.3f} + C {moving.intrusion:g} "
             f"+ Z_d {moving.sensor:g} + Z_r {moving.robot_position:g}")
    slow = task.safety.reduced_speed
    zone = "; no reduced-speed zone"
    if slow:
        zone = (f"; a reduced-speed zone at {slow:g} m/s allowed: "
                f"S_p {protective_separation(task.safety, slow).total:.3f} m")
    return (f"the protective separation of ISO/TS 15066 (speed and separation monitoring): at the robot's "
            f"{robot.speed:g} m/s S_p = {terms} = {moving.total:.3f} m, standing {standing.total:.3f} m{zone}")


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
