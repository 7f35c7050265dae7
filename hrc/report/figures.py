"""Figure plumbing shared by the report's charts: colours, an Agg canvas, byte-stable PNG output.

Figures are `matplotlib.figure.Figure` objects on their own `FigureCanvasAgg`, never pyplot, so no
global backend or figure registry is touched. PNGs are written with fixed size and DPI and without the
"Software" text chunk (matplotlib writes no date into PNGs), so the same input gives the same bytes.
"""

from __future__ import annotations

import io
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from hrc.model import Task

if TYPE_CHECKING:  # matplotlib is imported where a figure is made (`new_figure`): the colours come without it
    from matplotlib.figure import Figure

__all__ = ["AGENT_COLORS", "CLASS_COLORS", "DPI", "HUMAN_COLOR", "ROBOT_COLOR", "agent_color", "counts_figure",
           "makespans_figure", "new_figure", "save_png", "shares"]

DPI = 100

CLASS_COLORS: dict[str, str] = {"DC": "#2e7d32", "consistent": "#e0a000", "inconsistent": "#c62828"}
"""Badge and bar colours per plan class (green, amber, red), shared with the HTML report."""

HUMAN_COLOR, ROBOT_COLOR = "#d9731a", "#1f6fb2"
"""The person orange, the robot blue: in every figure, the simulation's GIF and the console (whose page
names the same two, ``hrc/console/page/console.css`` ``--human`` and ``--robot``)."""
AGENT_COLORS: tuple[str, ...] = (HUMAN_COLOR, ROBOT_COLOR, "#00897b", "#6d4c41")
"""The first person's and the first robot's colours, then teal and brown for a second of either kind."""


def agent_color(task: Task, agent_id: str) -> str:
    """`agent_id`'s colour, by its kind: the person orange, the robot blue (`HUMAN_COLOR`, `ROBOT_COLOR`);
    a second agent of one kind teal, a third brown. The same agent has the same colour everywhere."""
    agent = next(a for a in task.agents if a.id == agent_id)
    same = [a.id for a in task.agents if a.is_human == agent.is_human]
    k = same.index(agent_id)
    if k == 0:
        return HUMAN_COLOR if agent.is_human else ROBOT_COLOR
    return AGENT_COLORS[2 + (k - 1) % 2]


def new_figure(width: float, height: float) -> Figure:
    """A figure of `width` x `height` inches attached to its own Agg canvas (one that renders a string
    drawn in the same place again from the process's cache: `hrc.report.text_cache`; the same pixels)."""
    from matplotlib.figure import Figure

    from hrc.report.text_cache import TextCachingCanvas

    fig = Figure(figsize=(width, height), dpi=DPI)
    TextCachingCanvas(fig)
    return fig


def save_png(fig: Figure, path: Path, clear: bool = True) -> bytes:
    """Render `fig` to `path` as a PNG whose bytes depend only on the figure, then (`clear`) free it;
    returns the bytes written."""
    buf = io.BytesIO()
    # compress_level 3: a third faster than the default 6 for some 10 % more bytes
    fig.savefig(buf, format="png", dpi=DPI, metadata={"Software": None}, pil_kwargs={"compress_level": 3})
    if clear:
        fig.clear()
    data = buf.getvalue()
    path.write_bytes(data)
    return data


def counts_figure(counts: Mapping[str, int]) -> Figure:
    """Bar chart: plans per class, best class first, each bar in its class colour with its count."""
    fig = new_figure(4.2, 2.4)
    ax = fig.add_axes((0.17, 0.16, 0.79, 0.72))  # room for four-digit counts on the y axis
    names = list(counts)
    values = [counts[n] for n in names]
    bars = ax.bar(names, values, color=[CLASS_COLORS.get(n, "#777777") for n in names], width=0.6)
    top = max(values, default=0)
    for bar, v in zip(bars, values, strict=True):
        ax.text(bar.get_x() + bar.get_width() / 2, v + max(top, 1) * 0.02, str(v), ha="center", va="bottom",
                fontsize=9)
    ax.set_ylim(0, max(top, 1) * 1.18)
    ax.set_ylabel("plans")
    ax.set_title("Plans per class")
    ax.spines[["top", "right"]].set_visible(False)
    return fig


def makespans_figure(bins: tuple[float, ...], histograms: Mapping[str, tuple[int, ...]]) -> Figure:
    """Stacked histogram of worst-case makespans over all plans, one colour per class (a large plan
    set's report shows this instead of every row)."""
    fig = new_figure(6.4, 2.8)
    ax = fig.add_axes((0.1, 0.17, 0.86, 0.7))
    lefts, widths = bins[:-1], [b - a for a, b in zip(bins[:-1], bins[1:], strict=True)]
    bottom = [0] * len(lefts)
    for cls, counts in histograms.items():
        if any(counts):
            ax.bar(lefts, counts, width=widths, bottom=bottom, align="edge", color=CLASS_COLORS.get(cls, "#777777"),
                   label=cls, edgecolor="white", linewidth=0.4)
            bottom = [b + c for b, c in zip(bottom, counts, strict=True)]
    ax.set_xlabel("worst-case makespan (s)")
    ax.set_ylabel("plans")
    ax.set_title("Worst-case makespans of all plans")
    ax.legend(frameon=False, fontsize=8)
    ax.spines[["top", "right"]].set_visible(False)
    return fig


def shares(weights: list[float], n: int = 2) -> list[list[int]]:
    """Indices of `weights` in `n` groups of about equal total (longest first, each to the lightest
    group so far; ties to the first): a fixed split, the same for the same weights."""
    groups: list[list[int]] = [[] for _ in range(n)]
    load = [0.0] * n
    for i in sorted(range(len(weights)), key=lambda i: (-weights[i], i)):
        k = load.index(min(load))
        groups[k].append(i)
        load[k] += weights[i]
    return [sorted(g) for g in groups]
