"""Pictures of planned paths (matplotlib, Agg backend): the map, obstacles, locations and routes.

Plotting lives only in the report layer; `hrc paths --out` uses it.
Returns PNG bytes so the caller writes them atomically.
"""

from __future__ import annotations

import io
import textwrap
from typing import TYPE_CHECKING

from hrc.model import Plan, Task
from hrc.motion.paths import PathLibrary
from hrc.report.figures import agent_color

if TYPE_CHECKING:
    from hrc.compile.motion_pattern import PlanChoice

__all__ = ["paths_png"]


def paths_png(task: Task, paths: PathLibrary, plan: Plan | None = None,
              choice: PlanChoice | None = None, dpi: int = 110) -> bytes:
    """PNG of every planned path, or (with `plan` and its motion pattern `choice`) that plan's two routes,
    detours dashed, and its passing orders: each numbered where it holds and said once in words in the
    legend below the map (`hrc.report.summary.passing_words`). Agents in their colours (`agent_color`)."""
    from matplotlib.figure import Figure  # a Figure on its own canvas: no pyplot, no global backend
    from matplotlib.patches import Circle, Polygon, Rectangle

    ws = task.workspace
    xmin, ymin, xmax, ymax = ws.bounds
    fig = Figure(figsize=(2 + (xmax - xmin) * 0.8, 1.2 + (ymax - ymin) * 0.8))
    ax = fig.add_subplot()
    ax.add_patch(Rectangle((xmin, ymin), xmax - xmin, ymax - ymin, fill=False, lw=2, ec="black"))
    for ob in ws.obstacles:
        ax.add_patch(Polygon(ob.polygon, closed=True, fc="0.75", ec="0.35"))
    colours = {a.id: agent_color(task, a.id) for a in task.agents}
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
        from hrc.report.summary import passing_words

        # the compile's choices numbered on the map and said in words in the legend below it (never over the
        # map); what they force, small marks and one legend line (the text output lists each once)
        words = passing_words(choice.pattern.constrained)
        for k, (how, text, points) in enumerate(words, start=1):
            chosen = how == "chosen"
            for x, y in points:
                ax.plot(x, y, marker="X" if chosen else "x", color="#c62828", ms=10 if chosen else 6,
                        mec="white" if chosen else "#c62828", zorder=6 if chosen else 5)
                if chosen:
                    ax.annotate(str(k), (x, y), xytext=(5, 3), textcoords="offset points", fontsize=8,
                                weight="bold", color="#c62828", zorder=6)
            if chosen:
                ax.plot([], [], marker="X", color="#c62828", ls="none", ms=8,
                        label=textwrap.fill(f"{k}: {text} (chosen)", 80, subsequent_indent="    "))
        ax.plot([], [], marker="o", mfc="white", mec="#555555", ls="none", ms=8,
                label="n: the agent's leg n on its route (0 = its first)")
        forced = sum(how != "chosen" for how, _, _ in words)
        if forced:
            ax.plot([], [], marker="x", color="#c62828", ls="none", ms=6,
                    label=f"{forced} passing orders these force (`hrc paths --plan` lists each)")
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
    ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.1), fontsize=7.5, frameon=False, ncol=1)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight", metadata={"Software": None})
    return buf.getvalue()
