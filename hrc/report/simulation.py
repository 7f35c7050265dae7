"""Figures of a simulation (`hrc simulate`): makespans per policy, one run's Gantt, its trajectories, a GIF.

- ``makespans.png``: per policy, the distribution of the makespan over finished runs (box: quartiles,
  whiskers: 5th-95th percentile, dots: every run), the deadline as a dashed red line and, beside each
  box, the deadline-met rate and the unfinished runs;
- ``gantt_run.png``: one run, for each agent the *planned* bars (the first plan's earliest schedule,
  `hrc.report.gantt.gantt_bars`) above what *happened* (travel, manipulation, waiting, from the run's
  happenings), so that where the run fell behind its plan shows; a joint phase on each agent's rows;
- ``trajectories.png``: the workspace (`hrc.report.maps.draw_workspace`) with the path each agent's
  disc actually took, and the place where they came closest (outside co-work at a joint spot, issue 37);
  a team's: every agent's path, and the closest robot-person pair;
- ``run.gif``: the run animated, every disc at every half second of simulated time, with the time and
  what each agent is doing.

Each agent has one colour in every view (`hrc.report.figures.agent_color`: the first person orange, the
first robot blue, a second of a kind teal, a third brown), the Gantt one row pair per agent.

Deterministic: PNGs as the report writes them (`hrc.report.figures.save_png`), the GIF from Agg
frames quantized by Pillow (no timestamps in either). Only this layer plots (house style).
"""

from __future__ import annotations

import functools
import io
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import matplotlib
import numpy as np
from matplotlib.artist import Artist
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch

from hrc.report.figures import agent_color, new_figure, save_png
from hrc.report.gantt import WAIT_STYLE, gantt_bars, wait_label
from hrc.report.maps import workspace_figure

# `vert` is deprecated from Matplotlib 3.11 (warnings are errors in the tests); `orientation` exists from 3.10
_HORIZONTAL: dict = ({"orientation": "horizontal"} if tuple(int(x) for x in matplotlib.__version__.split(".")[:2])
                     >= (3, 10) else {"vert": False})

if TYPE_CHECKING:
    from hrc.compile.compiler import CompiledPlan
    from hrc.model import Task
    from hrc.sim.montecarlo import Simulation
    from hrc.sim.run import RunResult

__all__ = ["actual_bars", "actual_spans", "animation_gif", "makespan_figure", "run_gantt_figure", "trajectories_figure",
           "write_simulation_figures"]

GIF_STEP = 0.5  # s of simulated time per GIF frame
GIF_MS = 100  # ms per GIF frame on screen (5x real time)


def makespan_figure(sim: Simulation) -> Figure:
    """Box and dots of the makespan per policy, the deadline, deadline-met rates (module docstring)."""
    task = sim.context.task
    names = list(sim.policies)
    fig = new_figure(7.5, 0.9 + 0.65 * len(names))
    ax = fig.add_axes((0.17, 0.75 / (0.9 + 0.65 * len(names)), 0.62, 1 - 0.95 / (0.9 + 0.65 * len(names))))
    data = [[r.makespan for r in sim.results[n] if r.makespan is not None] for n in names]
    ys = list(range(len(names)))[::-1]
    rng = np.random.default_rng(0)  # jitter of the dots only (fixed: the same figure for the same runs)
    for y, values, name in zip(ys, data, names, strict=True):
        if values:
            ax.bxp([_box(values)], positions=[y], **_HORIZONTAL, widths=0.5, showfliers=False,
                   boxprops={"color": "#444444"}, medianprops={"color": "#c62828", "linewidth": 1.6})
            ax.scatter(values, y + rng.uniform(-0.18, 0.18, len(values)), s=4, color="#1f5fa8", alpha=0.35,
                       linewidths=0, zorder=3)
        runs = sim.results[name]
        met = sum(r.deadline_met for r in runs) / len(runs) if runs else 0.0
        left = sum(not r.finished for r in runs)
        note = f"{100 * met:.1f} % on time" + (f", {left} unfinished" if left else "")
        ax.annotate(note, (1.01, y), xycoords=("axes fraction", "data"), va="center", fontsize=8)
    ax.set_yticks(ys, labels=names)
    ax.set_ylim(-0.6, len(names) - 0.4)
    if task.deadline is not None:
        ax.axvline(task.deadline, color="#c62828", linestyle="--", linewidth=1.2)
    ax.set_xlabel("makespan (s) of finished runs")
    ax.set_title(f"{task.name}: {sim.runs} runs per policy", fontsize=10)
    ax.grid(axis="x", color="#dddddd", linewidth=0.6)
    ax.set_axisbelow(True)
    ax.spines[["top", "right"]].set_visible(False)
    return fig


def _box(values: Sequence[float]) -> dict:
    q = np.percentile(values, [5, 25, 50, 75, 95])
    return {"whislo": q[0], "q1": q[1], "med": q[2], "q3": q[3], "whishi": q[4], "fliers": []}


def actual_bars(result: RunResult, agent: str, joint: frozenset[str] = frozenset()) -> list[tuple[str, float, float]]:
    """What `agent` did in the run: ``(kind, start, end)`` with kind travel / work / wait / away."""
    return [(kind, start, end) for kind, start, end, _ in actual_spans(result, agent, joint)]


def actual_spans(result: RunResult, agent: str, joint: frozenset[str] = frozenset()
                 ) -> list[tuple[str, float, float, str]]:
    """`actual_bars` with a label each: the action and phase of a manipulation (``cube2 fetch``). A `joint`
    action (issue 37) the agent went to is drawn on its row too, from its one start to its one end (its
    lead's happenings)."""
    out: list[tuple[str, float, float, str]] = []
    since = 0.0  # when the agent last finished something (or started moving)
    moving_since: float | None = None
    mine = {h.action for h in result.happenings if h.agent == agent and h.event == "depart"} & joint
    for h in result.happenings:
        if h.agent != agent and not (h.action in mine and h.event in ("start", "end")):
            continue
        if h.event in ("depart", "unpark", "start", "away"):
            if h.t > since + 1e-6:
                out.append(("wait", since, h.t, ""))
            since = h.t
            moving_since = h.t if h.event in ("depart", "unpark") else None
        elif h.event in ("park", "arrive") and moving_since is not None:
            out.append(("travel", moving_since, h.t, ""))
            since, moving_since = h.t, None
        elif h.event in ("end", "back"):
            label = f"{h.action} {h.phase}" if h.event == "end" and h.action else ""
            out.append(("work" if h.event == "end" else "away", since, h.t, label))
            since = h.t
    return out


def run_gantt_figure(task: Task, cp: CompiledPlan | None, result: RunResult) -> Figure:
    """Planned (the first plan's earliest schedule) above actual, per agent (module docstring): the title
    and the legend in the figure's top margin, one above the other, never over the bars; manipulations
    carry their action's name where it fits, waits are drawn as every Gantt draws them."""
    agents = task.agent_ids
    rows = [(a, kind) for a in agents for kind in ("planned", "actual")]
    bottom, top, per_row = 0.55, 0.75, 0.55  # inches: x axis, title and legend, one row
    height = bottom + top + per_row * len(rows)
    fig = new_figure(10.0, height)
    ax = fig.add_axes((0.13, bottom / height, 0.85, per_row * len(rows) / height))
    planned = gantt_bars(task, cp) if cp is not None and cp.classification.schedule else {}
    alpha = {"travel": 0.3, "work": 1.0}
    joint = frozenset(a.id for a in task.actions if a.joint)
    spans = {(agent, kind): (planned.get(agent, []) if kind == "planned" else actual_spans(result, agent, joint))
             for agent, kind in rows}
    horizon = max([1.0, task.deadline or 0.0, result.makespan or 0.0]
                  + [e for bars in spans.values() for _, _, e, _ in bars])
    seconds_per_char = horizon * 1.03 / (0.85 * 10.0 * 72) * 0.62 * 7
    for i, (agent, kind) in enumerate(rows):
        y = len(rows) - 1 - i
        color = agent_color(task, agent)
        for k, s, e, label in spans[(agent, kind)]:
            if k == "wait":
                ax.broken_barh([(s, e - s)], (y - 0.15, 0.3), **WAIT_STYLE)
                text = wait_label(s, e, label, seconds_per_char)
                if text:
                    ax.text((s + e) / 2, y, text, ha="center", va="center", fontsize=6.5, color="#424242",
                            bbox={"boxstyle": "square,pad=0.1", "facecolor": "#f2f2f2", "edgecolor": "none"})
            elif k == "away":
                ax.broken_barh([(s, e - s)], (y - 0.3, 0.6), facecolor="none", edgecolor="#c62828", hatch="xx",
                               linewidth=0.6)
            else:
                ax.broken_barh([(s, max(e - s, 0.1))], (y - 0.3, 0.6), facecolor=color, alpha=alpha[k],
                               edgecolor=color if k == "travel" else "white", hatch="///" if k == "travel" else None,
                               linewidth=0.0 if k == "travel" else 0.5)
                fits = [t for t in (label, label.split(" ")[0]) if t and (len(t) + 1) * seconds_per_char <= e - s]
                if k == "work" and fits:  # the action and phase, or the action alone, where it fits
                    ax.text((s + e) / 2, y, fits[0], ha="center", va="center", fontsize=6.5, color="white")
    if task.deadline is not None:
        ax.axvline(task.deadline, color="#c62828", linestyle="--", linewidth=1.2)
    if result.makespan is not None:
        ax.axvline(result.makespan, color="#222222", linestyle=":", linewidth=1.0)
    ax.set_xlim(0, horizon * 1.03)
    ax.set_yticks(range(len(rows)), labels=[f"{a} {k}" for a, k in reversed(rows)])
    ax.set_ylim(-0.6, len(rows) - 0.4)
    ax.set_xlabel("time (s)")
    made = f"makespan {result.makespan:.1f} s" if result.makespan is not None else f"unfinished ({result.reason})"
    plan = f"plan {cp.plan.id} ({cp.plan_class.value})" if cp is not None else "no plan"
    fig.text(0.13, 1 - 0.12 / height, f"{result.policy}, run {result.run}: {plan} planned vs what happened; {made}",
             fontsize=9, va="top")
    ax.grid(axis="x", color="#dddddd", linewidth=0.6)
    ax.set_axisbelow(True)
    ax.spines[["top", "right"]].set_visible(False)
    handles: list[Artist] = [Patch(facecolor=agent_color(task, a), label=a) for a in agents]
    handles += [Patch(facecolor="#888888", label="manipulation"),
                Patch(facecolor="#888888", alpha=0.3, hatch="///", label="travel"),
                Patch(label="waiting", **WAIT_STYLE),
                Patch(facecolor="none", edgecolor="#c62828", hatch="xx", label="away"),
                Line2D([], [], color="#c62828", linestyle="--", label="deadline"),
                Line2D([], [], color="#222222", linestyle=":", label="makespan")]
    fig.legend(handles=handles, loc="upper left", bbox_to_anchor=(0.13, 1 - 0.38 / height), ncol=len(handles),
               fontsize=7.5, frameon=False, borderaxespad=0.0, handlelength=1.6, columnspacing=1.2)
    return fig


def _map_figure(task: Task) -> tuple[Figure, object]:
    return workspace_figure(task)


def trajectories_figure(task: Task, result: RunResult) -> Figure:
    """Where each disc went in the run, and where they came closest (module docstring)."""
    if result.agent_frames:
        return _team_trajectories(task, result)
    fig, ax = _map_figure(task)
    frames = result.frames
    handles = []
    human = next(a for a in task.agents if a.is_human)
    robot = next(a for a in task.agents if not a.is_human)
    for agent, cols in ((human, (1, 2)), (robot, (3, 4))):
        color = agent_color(task, agent.id)
        xs = [f[cols[0]] for f in frames]
        ys = [f[cols[1]] for f in frames]
        ax.plot(xs, ys, color=color, linewidth=1.4, alpha=0.8, zorder=3)  # type: ignore[attr-defined]
        handles.append(Line2D([], [], color=color, linewidth=1.4, label=f"{agent.id}"))
    cowork = result.cowork_frames or (False,) * len(frames)  # a joint task's co-work: not a separation (issue 37)
    close = [(math.hypot(f[1] - f[3], f[2] - f[4]) - human.radius - robot.radius, f)
             for f, shared in zip(frames, cowork, strict=True) if f[5] and not shared]
    if close:
        d, f = min(close, key=lambda c: c[0])
        for (x, y), agent in (((f[1], f[2]), human), ((f[3], f[4]), robot)):
            ax.add_patch(Circle((x, y), agent.radius, fill=False, edgecolor=agent_color(task, agent.id),  # type: ignore[attr-defined]
                                linewidth=1.2, linestyle="--", zorder=6))
        handles.append(Line2D([], [], color="#555555", linestyle="--",
                              label=f"closest: {d:.2f} m apart at {f[0]:.1f} s"))
    ax.legend(handles=handles, loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=3, fontsize=8,  # type: ignore[attr-defined]
              frameon=False, borderaxespad=0.2)
    return fig


def _team_trajectories(task: Task, result: RunResult) -> Figure:
    """A team's run (issue 37): every agent's path in its colour, and the closest robot-person approach
    outside co-work (both discs dashed), as for one pair."""
    fig, ax = _map_figure(task)
    frames = result.agent_frames
    handles = []
    for k, agent in enumerate(task.agents):
        color = agent_color(task, agent.id)
        ax.plot([f[1][k][0] for f in frames], [f[1][k][1] for f in frames], color=color,  # type: ignore[attr-defined]
                linewidth=1.4, alpha=0.8, zorder=3)
        handles.append(Line2D([], [], color=color, linewidth=1.4, label=agent.id))
    pairs = [(i, j) for i, a in enumerate(task.agents) for j, b in enumerate(task.agents)
             if a.is_human and not b.is_human]
    close = []
    for f in frames:
        for i, j in pairs:
            (x, y, here), (u, v, _) = f[1][i], f[1][j]
            if here and (task.agents[i].id, task.agents[j].id) not in f[2]:
                close.append((math.hypot(x - u, y - v) - task.agents[i].radius - task.agents[j].radius, f, i, j))
    if close:
        d, f, i, j = min(close, key=lambda c: c[0])
        for k in (i, j):
            agent = task.agents[k]
            ax.add_patch(Circle(f[1][k][:2], agent.radius, fill=False, edgecolor=agent_color(task, agent.id),  # type: ignore[attr-defined]
                                linewidth=1.2, linestyle="--", zorder=6))
        handles.append(Line2D([], [], color="#555555", linestyle="--",
                              label=f"closest robot-person: {d:.2f} m ({task.agents[i].id}, {task.agents[j].id}) "
                                    f"at {f[0]:.1f} s"))
    ax.legend(handles=handles, loc="lower left", bbox_to_anchor=(0.0, 1.0), ncol=3,  # type: ignore[attr-defined]
              fontsize=8, frameon=False, borderaxespad=0.2)
    return fig


def _doing(result: RunResult, agent: str, t: float) -> str:
    last = ""
    for h in result.happenings:
        if h.t > t:
            break
        if h.agent == agent:
            last = {"depart": f"to {h.action} {h.phase}", "arrive": f"at {h.action} {h.phase}",
                    "start": f"{h.action} {h.phase}", "end": "", "park": "waiting out of the way",
                    "unpark": f"to {h.action} {h.phase}", "away": "away", "back": ""}.get(h.event, "")
    return last


def animation_gif(task: Task, result: RunResult, path: Path, step: float = GIF_STEP) -> None:
    """Write the run as an animated GIF (a frame every `step` s of simulated time) to `path`.

    The map is drawn once by matplotlib; each frame is that picture with the two discs and a caption
    drawn on it by Pillow (a few ms a frame instead of a full matplotlib redraw)."""
    from PIL import Image, ImageDraw

    frames: list[tuple[float, tuple[tuple[float, float], ...], tuple[bool, ...]]]
    if result.agent_frames:  # a team (issue 37): every agent's disc, in its colour
        frames = [(f[0], tuple((x, y) for x, y, _ in f[1]), tuple(here for _, _, here in f[1]))
                  for f in result.agent_frames]
    else:
        frames = [(f[0], ((f[1], f[2]), (f[3], f[4])), (f[5], True)) for f in result.frames]
    if not frames:
        return
    fig, ax = _map_figure(task)
    fig.canvas.draw()
    base = Image.fromarray(np.asarray(fig.canvas.buffer_rgba())[:, :, :3].copy())  # type: ignore[attr-defined]
    height = base.height
    to_px = ax.transData.transform  # type: ignore[attr-defined]
    scale = float(to_px((1.0, 0.0))[0] - to_px((0.0, 0.0))[0])  # pixels per metre
    if result.agent_frames:
        shown_agents = list(task.agents)
    else:
        shown_agents = [next(a for a in task.agents if a.is_human), next(a for a in task.agents if not a.is_human)]
    colors = {a.id: agent_color(task, a.id) for a in shown_agents}
    start = tuple(task.workspace.location(a.start).xy for a in shown_agents)
    ft = np.array([f[0] for f in frames])
    swatch = base.copy()  # one palette for every frame: the map plus the discs' colours
    sd = ImageDraw.Draw(swatch)
    for k, c in enumerate(list(colors.values()) + ["#222222", "#ffffff"]):
        sd.rectangle((k * 12, 0, k * 12 + 11, 11), fill=c)
    palette = swatch.quantize(colors=48, dither=Image.Dither.NONE)
    images = []
    for t in np.arange(0.0, frames[-1][0] + step / 2, step):
        i = int(np.searchsorted(ft, t, side="right")) - 1
        f = frames[i] if i >= 0 else (0.0, start, (True,) * len(shown_agents))
        img = base.copy()
        draw = ImageDraw.Draw(img)
        for agent, (x, y), shown in zip(shown_agents, f[1], f[2], strict=True):
            if not shown:
                continue
            px, py = to_px((x, y))
            r = agent.radius * scale
            py = height - py
            draw.ellipse((px - r, py - r, px + r, py + r), fill=colors[agent.id], outline="white")
        # the caption is the legend too: each agent's name after a disc of its colour
        x0 = 8.0
        draw.text((x0, 6), f"t = {t:5.1f} s", fill="#222222")
        x0 += draw.textlength(f"t = {t:5.1f} s") + 14
        for agent in shown_agents:
            draw.ellipse((x0, 7, x0 + 9, 16), fill=colors[agent.id])
            text = f"{agent.id}: {_doing(result, agent.id, t) or '-'}"
            draw.text((x0 + 13, 6), text, fill="#222222")
            x0 += 13 + draw.textlength(text) + 16
        images.append(img.quantize(palette=palette, dither=Image.Dither.NONE))
    fig.clear()
    buf = io.BytesIO()
    images[0].save(buf, format="GIF", save_all=True, append_images=images[1:], duration=GIF_MS, loop=0,
                   optimize=False)
    path.write_bytes(buf.getvalue())


def write_simulation_figures(sim: Simulation, featured: dict[str, RunResult], out_dir: Path,
                             gif: bool = True) -> dict[str, str]:
    """Write the figures into ``out_dir/figures`` (and ``run.gif``); `featured` maps a policy to a
    recorded run of it. Returns figure key -> path relative to `out_dir`.

    Drawn in two processes at once (`hrc.report.drawer.draw_in_two`, the figures split by their usual
    cost: the GIF, each Gantt, each map): this is the last, serial step of ``hrc simulate``, and the
    files are those one process draws, byte for byte (each figure is drawn on a figure of its own)."""
    from hrc.report.drawer import draw_in_two, shares
    from hrc.sim.policies import POLICIES

    fig_dir = out_dir / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    written: dict[str, str] = {}
    task = sim.context.task
    todo: list[tuple[float, Callable[[], object]]] = [  # (CPU seconds on the workshop, draw and save)
        (0.23, lambda: save_png(makespan_figure(sim), fig_dir / "makespans.png"))]
    written["makespans"] = "figures/makespans.png"
    for policy, result in featured.items():
        cps = sim.context.compiles[POLICIES[policy].compile]
        cp = next((c for c in cps.plans if c.plan.id == result.first_plan), None)
        gantt, traj = f"gantt_{policy}_run{result.run}.png", f"trajectories_{policy}_run{result.run}.png"
        todo.append((0.35, functools.partial(_save, run_gantt_figure, (task, cp, result), fig_dir / gantt)))
        written[f"gantt_{policy}"] = f"figures/{gantt}"
        todo.append((0.13, functools.partial(_save, trajectories_figure, (task, result), fig_dir / traj)))
        written[f"trajectories_{policy}"] = f"figures/{traj}"
    if gif and featured:
        policy, result = next(iter(featured.items()))
        name = f"run_{policy}_run{result.run}.gif"
        todo.append((0.6, functools.partial(animation_gif, task, result, fig_dir / name)))
        written["gif"] = f"figures/{name}"
    groups = shares([w for w, _ in todo])

    def draw(share: tuple[int, int]) -> None:
        for i in groups[share[0]]:
            todo[i][1]()

    draw_in_two(draw)
    return dict(sorted(written.items()))


def _save(make: Callable[..., Figure], args: tuple, path: Path) -> None:
    save_png(make(*args), path)
