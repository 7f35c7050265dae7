"""Pictures of planned paths (matplotlib, Agg backend): the map, obstacles, locations and routes.

Plotting lives only in the report layer; `hrc paths --out` uses it.
Returns PNG bytes so the caller writes them atomically.
"""

from __future__ import annotations

import io
from typing import TYPE_CHECKING

from hrc.model import Plan, Task
from hrc.motion.paths import PathLibrary

if TYPE_CHECKING:
    from hrc.compile.motion_pattern import PlanChoice

__all__ = ["paths_png"]

_COLOURS = {"human": "tab:blue", "robot": "tab:orange"}


def paths_png(task: Task, paths: PathLibrary, plan: Plan | None = None,
              choice: PlanChoice | None = None, dpi: int = 110) -> bytes:
    """PNG of every planned path, or (with `plan` and its motion pattern `choice`) that plan's two routes,
    detours dashed, and the places where a passing order makes one agent wait."""
    from matplotlib.figure import Figure  # a Figure on its own canvas: no pyplot, no global backend
    from matplotlib.patches import Circle, Polygon, Rectangle

    ws = task.workspace
    xmin, ymin, xmax, ymax = ws.bounds
    fig = Figure(figsize=(2 + (xmax - xmin) * 0.8, 1.2 + (ymax - ymin) * 0.8))
    ax = fig.add_subplot()
    ax.add_patch(Rectangle((xmin, ymin), xmax - xmin, ymax - ymin, fill=False, lw=2, ec="black"))
    for ob in ws.obstacles:
        ax.add_patch(Polygon(ob.polygon, closed=True, fc="0.75", ec="0.35"))
    colours = {a.id: _COLOURS.get(a.kind.value, "tab:green") for a in task.agents}
    if plan is None:
        title = f"{task.name}: planned paths (seed {paths.seed})"
        for agent in task.agents:
            first = True
            for p in paths:
                if p.agent != agent.id or p.origin > p.target:
                    continue
                xs, ys = zip(*p.points, strict=True)
                ax.plot(xs, ys, color=colours[agent.id], lw=1.2, alpha=0.6,
                        label=f"{agent.id} (clearance {agent.radius + task.safety_margin:g} m)" if first else None)
                first = False
    elif choice is not None:
        title = f"{task.name}: plan {plan.id} ({choice.classification.plan_class.value})"
        motions = choice.pattern.motions
        for agent in task.agents:
            first = True
            for m in (m for m in motions if m.agent == agent.id):
                if len(m.points) < 2:
                    continue
                xs, ys = zip(*m.points, strict=True)
                ax.plot(xs, ys, color=colours[agent.id], lw=2, alpha=0.8, linestyle="--" if m.via else "-",
                        label=f"{agent.id}: {' '.join(plan.sequence(agent.id)) or '(idle)'}" if first else None)
                first = False
                mid = m.points[len(m.points) // 2]
                ax.annotate(str(m.leg), mid, color=colours[agent.id], fontsize=8, ha="center", va="center",
                            bbox={"boxstyle": "circle,pad=0.15", "fc": "white", "ec": colours[agent.id]})
        from hrc.report.summary import binding_orders

        for o in binding_orders(task, plan, choice.pattern, choice.classification):
            ax.plot(*o.conflict.point, marker="X", color="red", ms=11, mec="black")
            waiting, first_one = (("robot", o.conflict.human) if o.first == "human" else ("human", o.conflict.robot))
            ax.annotate(f"{waiting} waits for {first_one.describe()}", o.conflict.point, xytext=(6, -14),
                        textcoords="offset points", fontsize=7, color="darkred")
    for loc in ws.locations:
        ax.plot(loc.x, loc.y, "ko", ms=4)
        ax.annotate(loc.id, loc.xy, xytext=(4, 4), textcoords="offset points", fontsize=9, weight="bold")
    for agent in task.agents:
        start = ws.location(agent.start)
        ax.add_patch(Circle(start.xy, agent.radius, fc=colours[agent.id], alpha=0.3))
    ax.set_xlim(xmin - 0.2, xmax + 0.2)
    ax.set_ylim(ymin - 0.2, ymax + 0.2)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(title, fontsize=10)
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight", metadata={"Software": None})
    return buf.getvalue()
