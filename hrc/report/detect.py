"""The motion detector at work, in one figure: the trace on the map, and its belief over time against the
truth (docs/detect.md, made by scripts/plot_detect.py).

Left: the shop floor (`hrc.report.maps.draw_workspace`) with the person's tracked positions, coloured by
time. Right, over time: one row per leg of the person; a light bar where the detector believed the person
was walking to, waiting at or working on that leg (its height the belief's probability), dark ticks
where the leg's events truly happened, and markers where the detector gave them (at their estimated
time, with a thin line back from the moment they were given). Plotting only: the caller runs the detector.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from matplotlib.lines import Line2D

from hrc.model import Task

from .figures import HUMAN_COLOR, new_figure, save_png
from .maps import draw_workspace

__all__ = ["detection_figure"]

Sample = tuple[float, float, float]  # t, x, y
BeliefAt = tuple[float, str, str | None, str | None, float]  # t, doing, action, phase, p
Event = tuple[float, str, str, str]  # t, event, action, phase
Given = tuple[float, float, str, str, str]  # given at, estimated t, event, action, phase

_MARK = {"depart": ">", "arrive": "o", "start": "s", "end": "x"}
_DOING = {"walk": "#9ecae1", "wait": "#fdd0a2", "work": "#a1d99b"}


def detection_figure(task: Task, samples: Sequence[Sample], beliefs: Sequence[BeliefAt], truth: Sequence[Event],
                     given: Sequence[Given], title: str, path: Path) -> None:
    """Write the figure (see the module docstring) to `path` as a PNG."""
    fig = new_figure(13.0, 5.2)
    grid = fig.add_gridspec(1, 2, width_ratios=(1.0, 1.7), wspace=0.32)
    ax = fig.add_subplot(grid[0, 0])
    draw_workspace(ax, task.workspace)
    ts = [s[0] for s in samples]
    points = ax.scatter([s[1] for s in samples], [s[2] for s in samples], c=ts, cmap="viridis", s=5, zorder=4)
    fig.colorbar(points, ax=ax, fraction=0.035, pad=0.02, label="t (s)")
    ax.set_title("tracked positions", fontsize=10)
    tl = fig.add_subplot(grid[0, 1])
    legs: list[tuple[str, str]] = []
    for _, _, a, p in sorted(truth):
        if (a, p) not in legs:
            legs.append((a, p))
    row = {leg: k for k, leg in enumerate(legs)}
    for (t0, doing, action, phase, prob), nxt in zip(beliefs, [*beliefs[1:], None], strict=True):
        if action is None or phase is None or (action, phase) not in row or doing not in _DOING:
            continue
        t1 = nxt[0] if nxt is not None else t0
        y = row[(action, phase)]
        tl.fill_between([t0, t1], y - 0.4 * prob, y + 0.4 * prob, color=_DOING[doing], linewidth=0, zorder=1)
    for t, event, a, p in truth:
        if (a, p) in row and event in _MARK:
            tl.plot([t, t], [row[(a, p)] - 0.42, row[(a, p)] + 0.42], color="#222222", linewidth=1.2, zorder=3)
    for at, est, event, a, p in given:
        if (a, p) in row and event in _MARK:
            y = row[(a, p)]
            tl.plot([est, at], [y, y], color=HUMAN_COLOR, linewidth=0.8, zorder=4)
            tl.plot([est], [y], marker=_MARK[event], color=HUMAN_COLOR, markersize=6, linestyle="none", zorder=5,
                    markerfacecolor="none" if event in ("arrive", "start") else HUMAN_COLOR)
    tl.set_yticks(range(len(legs)), [f"{a}.{p}" for a, p in legs], fontsize=8)
    tl.set_ylim(len(legs) - 0.5, -0.5)
    tl.set_xlabel("t (s)")
    tl.grid(axis="x", color="#e6e6e6", linewidth=0.6)
    handles = [Line2D([], [], color=c, linewidth=6, label=f"belief: {d}") for d, c in _DOING.items()]
    handles.append(Line2D([], [], color="#222222", linewidth=1.2, label="true event"))
    handles += [Line2D([], [], color=HUMAN_COLOR, marker=m, linestyle="none", label=f"given: {e}",
                       markerfacecolor="none" if e in ("arrive", "start") else HUMAN_COLOR)
                for e, m in _MARK.items()]
    tl.legend(handles=handles, loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=4, fontsize=7.5, frameon=False)
    fig.suptitle(title, fontsize=11, y=0.995)
    save_png(fig, path)
