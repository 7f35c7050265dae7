"""Map of one plan: the workspace, its labelled locations, each agent's route and where one waits.

Routes are the ones the plan's motion pattern takes (`Motion.points`: the shortest route, or a detour,
drawn dashed), one per travelling leg, in the agent's colour with an arrow at the middle of each leg;
the agents' routes are offset a few centimetres apart so that shared corridors show both. Each place
where a passing order holds an agent back in the earliest schedule is an X labelled with who waits, for
how long and for what (`summary.motion_notes`). O(path points) artists.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Polygon, Rectangle
from matplotlib.ticker import MaxNLocator

from hrc.report.figures import agent_color, new_figure
from hrc.report.summary import plan_motion_notes

if TYPE_CHECKING:
    from hrc.compile.compiler import CompiledPlan, CompiledPlanSet
    from hrc.model import Task, Workspace

__all__ = ["draw_map", "draw_workspace", "map_base", "map_figure", "route_points", "workspace_figure"]

_OFFSET = 0.06  # m, how far apart the agents' routes are drawn


def draw_workspace(ax: Axes, workspace: Workspace) -> None:
    """Bounds, obstacles (grey, with their ids) and locations (dots with their ids), equal aspect."""
    xmin, ymin, xmax, ymax = workspace.bounds
    ax.add_patch(Rectangle((xmin, ymin), xmax - xmin, ymax - ymin, fill=False, edgecolor="#333333", linewidth=1.2))
    for ob in workspace.obstacles:
        ax.add_patch(Polygon(ob.polygon, closed=True, facecolor="#c8c8c8", edgecolor="#8a8a8a", linewidth=0.6))
    for loc in workspace.locations:
        ax.plot([loc.x], [loc.y], marker="o", markersize=5, color="#222222", zorder=5)
        ax.annotate(loc.id, (loc.x, loc.y), xytext=(5, 4), textcoords="offset points", fontsize=9,
                    fontweight="bold", color="#222222", zorder=6)
    pad = 0.2
    ax.set_xlim(xmin - pad, xmax + pad)
    ax.set_ylim(ymin - pad, ymax + pad)
    ax.set_aspect("equal")
    # few ticks: creating tick artists is most of the cost of drawing an axis
    ax.xaxis.set_major_locator(MaxNLocator(nbins=6, steps=[1, 2, 5, 10]))
    ax.yaxis.set_major_locator(MaxNLocator(nbins=6, steps=[1, 2, 5, 10]))
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")


def route_points(cp: CompiledPlan, agent: str) -> list[tuple[list[tuple[float, float]], bool]]:
    """The agent's travelled routes in leg order (legs without travel left out), each with "is a detour"."""
    out = []
    for m in sorted((m for m in cp.motions if m.agent == agent), key=lambda m: m.leg):
        if m.origin == m.target or len(m.points) < 2:
            continue
        out.append(([(float(x), float(y)) for x, y in m.points], bool(m.via)))
    return out


def _midpoint_arrow(ax: Axes, pts: list[tuple[float, float]], color: str) -> list[Artist]:
    lengths = [math.dist(a, b) for a, b in zip(pts, pts[1:], strict=False)]
    total = sum(lengths)
    if total <= 0:
        return []
    half = total / 2
    for (a, b), seg in zip(zip(pts, pts[1:], strict=False), lengths, strict=True):
        if seg > 0 and half <= seg:
            t = half / seg
            mid = (a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t)
            d = ((b[0] - a[0]) / seg * 0.01, (b[1] - a[1]) / seg * 0.01)
            return [ax.annotate("", xy=(mid[0] + d[0], mid[1] + d[1]), xytext=mid,
                                arrowprops={"arrowstyle": "-|>,head_length=0.7,head_width=0.35", "color": color,
                                            "linewidth": 0, "shrinkA": 0, "shrinkB": 0}, zorder=4)]
        half -= seg
    return []


def workspace_figure(task: Task, legend_rows: int = 1) -> tuple[Figure, Axes]:
    """A figure sized to the task's floor, with the workspace drawn on its one axes and room above it for a
    legend of `legend_rows` rows (inside the figure, over neither title nor data)."""
    ws = task.workspace
    xmin, ymin, xmax, ymax = ws.bounds
    width = 6.4
    top = 0.15 + 0.18 * legend_rows  # inches
    plot = min(9.0 - 0.7 - top, max(2.0, (width - 0.9) * (ymax - ymin + 0.4) / (xmax - xmin + 0.4)))
    height = 0.7 + plot + top
    fig = new_figure(width, height)
    ax = fig.add_axes((0.1, 0.7 / height, 0.86, plot / height))
    draw_workspace(ax, ws)
    return fig, ax


MAP_LEGEND_ROWS = 4
"""Rows of legend a plan's map has room for above the floor (routes, detours, numbered waits: two a row)."""


def map_base(task: Task) -> tuple[Figure, Axes]:
    """The plan-independent part: the workspace and the agents' start markers (reused for every plan)."""
    ws = task.workspace
    fig, ax = workspace_figure(task, MAP_LEGEND_ROWS)
    for agent in task.agents:
        start = ws.location(agent.start)
        ax.plot([start.x], [start.y], marker="s", markersize=9, markerfacecolor="none",
                markeredgecolor=agent_color(task, agent.id), markeredgewidth=1.6, zorder=5)
    return fig, ax


def draw_map(ax: Axes, task: Task, cp: CompiledPlan) -> list[Artist]:
    """Draw `cp` (a plan of `task`): its routes, interference points and legend on a `map_base` axes;
    returns what it added."""
    added: list[Artist] = []
    handles: list[Artist] = []
    n = len(task.agents)
    for i, agent in enumerate(task.agents):
        color = agent_color(task, agent.id)
        shift = (i - (n - 1) / 2) * _OFFSET * 2
        any_detour = False
        for pts, is_detour in route_points(cp, agent.id):
            moved = [(x + shift, y - shift) for x, y in pts]
            xs, ys = zip(*moved, strict=True)
            added += ax.plot(xs, ys, color=color, linewidth=1.6, alpha=0.85, solid_capstyle="round", zorder=3,
                             linestyle=(0, (4, 2)) if is_detour else "-")
            added += _midpoint_arrow(ax, moved, color)
            any_detour = any_detour or is_detour
        handles.append(Line2D([], [], color=color, linewidth=1.6, marker="s", markerfacecolor="none",
                              label=f"{agent.id} route (\u25a1 start)"))
        if any_detour:
            handles.append(Line2D([], [], color=color, linewidth=1.6, linestyle=(0, (4, 2)),
                                  label=f"{agent.id} detour"))
    # one X per distinct point; a point several waits share gets one line per wait
    at: dict[tuple[float, float], list[str]] = {}
    for note in plan_motion_notes(task, cp)[1]:
        key = (round(float(note.point[0]), 2), round(float(note.point[1]), 2))
        at.setdefault(key, []).append(f"{note.waiting} waits {note.wait:.1f} s")
    # each place numbered on the map, its waits said in the legend: words never overprint routes or each other
    for k, ((x, y), lines) in enumerate(sorted(at.items(), key=lambda kv: (-kv[0][1], kv[0][0])), start=1):
        added += ax.plot([x], [y], marker="X", markersize=11, color="#c62828", markeredgecolor="white", zorder=7)
        added.append(ax.annotate(str(k), (x, y), xytext=(6, 4), textcoords="offset points", fontsize=8,
                                 fontweight="bold", color="#c62828", zorder=7))
        handles.append(Line2D([], [], color="#c62828", marker="X", linestyle="none", markersize=8,
                              label=f"{k}: " + "; ".join(lines)))
    if len(handles) > 2 * MAP_LEGEND_ROWS:  # no more than the room above the floor: the rest in the report
        more = len(handles) - 2 * MAP_LEGEND_ROWS + 1
        handles = handles[:2 * MAP_LEGEND_ROWS - 1] + [Line2D([], [], color="#c62828", marker="X", linestyle="none",
                                                              markersize=8, label=f"{more} more: see the list")]
    added.append(ax.legend(handles=handles, loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=2,
                           fontsize=7.5, frameon=False, borderaxespad=0.2, handlelength=1.6, columnspacing=1.0))
    return added


def map_figure(cps: CompiledPlanSet, cp: CompiledPlan) -> Figure:
    """The map of `cp` on a figure of its own (see the module docstring)."""
    fig, ax = map_base(cps.task)
    draw_map(ax, cps.task, cp)
    return fig
