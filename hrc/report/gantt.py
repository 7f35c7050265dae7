"""Gantt chart of one plan's schedule: a row per agent, travel, manipulation and waiting bars per phase.

Times come from `Classification.schedule` (the earliest time of every STNU timepoint, in seconds) or
`Classification.worst_schedule` (the same with every human duration at its maximum): ``which`` picks.
A leg's bars span ``depart -> arrive`` (travel: the agent's colour, lighter, hatched ``///``) and
``start -> end`` (manipulation, labelled ``cube2 fetch``); the agent standing still (waiting for the
co-worker, for a passing order or for the task graph, or at a waiting place on its way: then its travel
is split there) is a pale dotted box (`WAIT_STYLE`) labelled ``waits 12.0 s at H`` where that fits, so
idle time shows and is never mistaken for a walk. Colours are the agents' (`agent_color`: the person
orange, the robot blue), named in the legend above the chart. A dashed red line marks the
makespan deadline and a dotted one the worst-case makespan. O(legs) artists.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import MaxNLocator

from hrc.compile.temporal_net_creator import leg_names
from hrc.plans import agent_legs
from hrc.report.figures import DPI, agent_color, new_figure
from hrc.report.summary import MIN_WAIT

if TYPE_CHECKING:
    from hrc.compile.compiler import CompiledPlan
    from hrc.model import Task

__all__ = ["MIN_WAIT", "WAIT_STYLE", "draw_gantt", "gantt_bars", "gantt_base", "gantt_figure", "wait_label"]

def gantt_bars(task: Task, cp: CompiledPlan, which: str = "earliest") -> dict[str, list[tuple[str, float, float, str]]]:
    """Per agent, ``(kind, start, end, label)`` with kind ``travel``, ``work`` or ``wait``, in time order.

    `which`: "earliest" or "worst" schedule. A leg whose route stops at a waiting place is travel there, a
    wait there (labelled ``at H``), travel on: the wait is never drawn as travel. Waits shorter than
    `MIN_WAIT` seconds and zero-length travel are left out; legs missing from the schedule too.
    """
    times = dict(cp.classification.schedule if which == "earliest" else cp.classification.worst_schedule)
    bars: dict[str, list[tuple[str, float, float, str]]] = {}
    for agent in task.agent_ids:
        rows: list[tuple[str, float, float, str]] = []
        free_since: float | None = 0.0  # when the agent last finished something
        parks = {m.leg: m.park for m in cp.motions if m.agent == agent and m.park}
        names = leg_names(task, cp.plan)[agent]  # a joint action's start and end are its lead's (issue 37)
        for k, leg in enumerate(agent_legs(task, cp.plan, agent)):
            label = f"{leg.action} {leg.phase}"
            dep, park, unpark, arr, st, en = (times.get(names[k][w])
                                              for w in ("depart", "park", "unpark", "arrive", "start", "end"))
            place = f"at {parks[k]}" if k in parks else ""
            spans: list[tuple[str, float | None, float | None, str]] = [("wait", free_since, dep, "")]
            if park is not None and unpark is not None:
                spans += [("travel", dep, park, f"to {parks.get(k, '')}"), ("wait", park, unpark, place),
                          ("travel", unpark, arr, f"to {leg.location}")]
            else:
                spans.append(("travel", dep, arr, f"to {leg.location}"))
            spans.append(("wait", arr, st, ""))
            for kind, a, b, text in spans:
                if a is not None and b is not None and b - a >= (MIN_WAIT if kind == "wait" else 1e-9):
                    rows.append((kind, a, b, text))
            if st is not None and en is not None:
                rows.append(("work", st, en, label))
            free_since = en
        bars[agent] = rows
    return bars


WAIT_STYLE: dict[str, Any] = {"facecolor": "#f2f2f2", "edgecolor": "#616161", "hatch": "....", "linewidth": 0.6}
"""How every Gantt draws a wait: a pale box dotted grey, unlike travel (the agent's colour, hatched ///)."""


_TEXT_BOX = {"boxstyle": "square,pad=0.1", "facecolor": "#f2f2f2", "edgecolor": "none"}


def wait_label(start: float, end: float, place: str, seconds_per_char: float) -> str:
    """``waits 12.0 s at H`` (or shorter), whichever fits inside the bar; "" when none does."""
    for text in (f"waits {end - start:.1f} s {place}".strip(), f"waits {end - start:.1f} s", f"{end - start:.0f} s"):
        if (len(text) + 1) * seconds_per_char <= end - start:
            return text
    return ""


_WIDTH, _LEFT, _AXES_W = 10.0, 0.075, 0.905  # figure width (in), axes left and width (figure fractions)
_LABEL_PT = 7.5  # label font size (pt)
_CHAR_EM = 0.62  # average DejaVu Sans character width (em), to estimate label widths without drawing
_LANE = 0.13  # label lane height (y units; one agent row is 1)
_LANES = ((1, 0), (-1, 0), (1, 1), (-1, 1))  # (above = 1 / below = -1, distance from the bar)


def _label_lanes(work: list[tuple[float, float, str]], seconds_per_char: float) -> list[tuple[int, int]]:
    """A lane per bar label so that labels in one lane do not overlap (greedy, in start order).

    A label takes the first lane whose last label ends before it begins; when all four are taken it
    goes to the one that frees up first. Label widths are estimated from their length, not measured.
    """
    last = [-math.inf] * len(_LANES)
    out = []
    for start, end, label in work:
        half = (len(label) + 1) * seconds_per_char / 2
        centre = (start + end) / 2
        free = [i for i, t in enumerate(last) if t <= centre - half]
        i = free[0] if free else min(range(len(_LANES)), key=last.__getitem__)
        last[i] = centre + half
        out.append(_LANES[i])
    return out


def gantt_base(task: Task, which: str = "earliest") -> tuple[Figure, Axes]:
    """The plan-independent part: figure, axes, agent rows, grid (reused for every plan's chart)."""
    agents = task.agent_ids
    bottom, top, per_row = 0.55, 0.4, 1.0  # inches: x axis and its label, legend, one agent row
    fig_h = bottom + top + per_row * len(agents)
    fig = new_figure(_WIDTH, fig_h)
    ax = fig.add_axes((_LEFT, bottom / fig_h, _AXES_W, per_row * len(agents) / fig_h))
    ax.set_yticks(range(len(agents)), labels=list(reversed(agents)))
    ax.set_ylim(-0.62, len(agents) - 0.38)
    ax.xaxis.set_major_locator(MaxNLocator(nbins=10, steps=[1, 2, 5, 10]))
    ax.set_xlabel("time (s), earliest schedule" if which == "earliest"
                  else "time (s), worst case: every human duration at its maximum")
    ax.grid(axis="x", color="#dddddd", linewidth=0.6)
    ax.set_axisbelow(True)
    ax.spines[["top", "right"]].set_visible(False)
    return fig, ax


def draw_gantt(ax: Axes, task: Task, cp: CompiledPlan, which: str = "earliest") -> list[Artist]:
    """Draw `cp`'s bars, labels, deadline and legend on a `gantt_base` axes; returns what it added."""
    bars = gantt_bars(task, cp, which)
    agents = task.agent_ids
    ms = cp.classification.makespan
    horizon = max([e for rows in bars.values() for _, _, e, _ in rows]
                  + [ms[1] if ms else 0.0, task.deadline or 0.0, 1.0])
    ax.set_xlim(0, horizon * 1.03)
    height = 0.34
    seconds_per_char = horizon * 1.03 / (_AXES_W * _WIDTH * DPI) * _CHAR_EM * _LABEL_PT * DPI / 72
    added: list[Artist] = []
    for row, agent in enumerate(agents):
        y = len(agents) - 1 - row
        color = agent_color(task, agent)
        travel = [(start, end - start) for kind, start, end, _ in bars[agent] if kind == "travel"]
        work = [(start, end, label) for kind, start, end, label in bars[agent] if kind == "work"]
        waits = [(start, end, label) for kind, start, end, label in bars[agent] if kind == "wait"]
        added.append(ax.broken_barh([(start, end - start) for start, end, _ in waits],
                                    (y - height * 0.22, height * 0.44), **WAIT_STYLE))
        for start, end, place in waits:
            text = wait_label(start, end, place, seconds_per_char)
            if text:
                added.append(ax.text((start + end) / 2, y, text, ha="center", va="center", fontsize=_LABEL_PT - 0.5,
                                     color="#424242", bbox=_TEXT_BOX))
        # one collection per agent and kind (far cheaper to draw than a patch per bar)
        added.append(ax.broken_barh(travel, (y - height * 0.3, height * 0.6), facecolor=color, alpha=0.28,
                                    hatch="///", edgecolor=color, linewidth=0.0))
        added.append(ax.broken_barh([(start, max(end - start, 0.15)) for start, end, _ in work],
                                    (y - height / 2, height), facecolor=color, edgecolor="white", linewidth=0.6))
        for (start, end, label), (side, lane) in zip(work, _label_lanes(work, seconds_per_char), strict=True):
            added.append(ax.text((start + end) / 2, y + side * (height / 2 + 0.04 + lane * _LANE), label,
                                 ha="center", va="bottom" if side > 0 else "top", fontsize=_LABEL_PT,
                                 color="#222222"))
    if task.deadline is not None:
        added.append(ax.axvline(task.deadline, color="#c62828", linestyle="--", linewidth=1.2))
        right = task.deadline < horizon * 0.85  # label to the right of the line, unless near the edge
        label = f" deadline {task.deadline:g} s" if right else f"deadline {task.deadline:g} s "
        added.append(ax.text(task.deadline, len(agents) - 0.42, label, color="#c62828", fontsize=8, va="center",
                             ha="left" if right else "right"))
    handles: list[Artist] = [Patch(facecolor=agent_color(task, a), label=a) for a in agents]
    handles += [Patch(facecolor="#888888", label="manipulation"),
                Patch(facecolor="#888888", alpha=0.28, hatch="///", edgecolor="#888888", linewidth=0.0, label="travel"),
                Patch(label="waiting", **WAIT_STYLE)]
    if ms is not None and ms[1] > ms[0]:
        added.append(ax.axvline(ms[1], color="#555555", linestyle=":", linewidth=1.0))
        handles.append(Line2D([], [], color="#555555", linestyle=":", label=f"worst-case makespan {ms[1]:.1f} s"))
    added.append(ax.legend(handles=handles, loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=len(handles),
                           fontsize=8, frameon=False, borderaxespad=0.3))
    return added


def gantt_figure(task: Task, cp: CompiledPlan, which: str = "earliest") -> Figure:
    """The Gantt chart of `cp` on a figure of its own (see the module docstring); x axis in seconds."""
    fig, ax = gantt_base(task, which)
    draw_gantt(ax, task, cp, which)
    return fig
