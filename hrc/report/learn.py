"""The report of ``hrc learn``: what the runs showed, what changed in the task, which plans' classes move.

``report.md`` (tables: per phase and agent the observations, the old and new bounds, the overruns; the
legs' travel times; a motion detector's delays; the warnings; the plans whose class moves between the
old and the new task's compile) and ``figures/durations-AGENT.png``: per phase a histogram of the
observed durations with the old bound (grey, dashed) and the new one (the agent's colour). The same
input gives the same bytes (`hrc.report.figures.save_png`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from hrc.learn.estimate import Learned
from hrc.model import Task
from hrc.report.figures import agent_color, new_figure, save_png

__all__ = ["durations_figure", "learn_markdown", "write_learn_report"]


def durations_figure(task: Task, learned: Learned, agent: str, path: Path) -> bool:
    """Per phase of `agent` with observations, a histogram with the old and the new bound; False (nothing
    written) when `agent` was never observed."""
    shown = [b for b in learned.bounds if b.agent == agent and b.n]
    if not shown:
        return False
    cols = min(4, len(shown))
    rows = (len(shown) + cols - 1) // cols
    fig = new_figure(3.0 * cols, 2.2 * rows)
    color = agent_color(task, agent)
    for i, b in enumerate(shown):
        ax = fig.add_subplot(rows, cols, i + 1)
        lo = min(b.samples[0], b.old.lb, b.new.lb)
        hi = max(b.samples[-1], b.old.ub, b.new.ub)
        pad = 0.05 * (hi - lo + 1e-9)
        bins = [float(x) for x in np.linspace(lo - pad, hi + pad, 25)]
        ax.hist(b.samples, bins=bins, color=color, alpha=0.45)
        for x in (b.old.lb, b.old.ub):
            ax.axvline(x, color="#555555", linestyle="--", linewidth=1.2)
        if not b.kept:
            for x in (b.new.lb, b.new.ub):
                ax.axvline(x, color=color, linewidth=1.8)
        ax.set_title(f"{b.action}.{b.phase} (n={b.n})", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.set_xlabel("s", fontsize=7)
    fig.suptitle(f"{agent}: observed durations, old bound dashed, new bound solid", fontsize=9)
    fig.subplots_adjust(left=0.06, right=0.98, bottom=0.12 / rows, top=1 - 0.12 / rows, hspace=0.6, wspace=0.25)
    save_png(fig, path)
    return True


def _f(x: float) -> str:
    return f"{x:.2f}"


def learn_markdown(task: Task, learned: Learned, sources: int, skipped: Sequence[str],
                   moves: Mapping[str, tuple[str | None, str | None]] | None, counts: tuple[dict, dict] | None,
                   figures: Sequence[str], types: str = "") -> str:
    """The report's text (see the module docstring). `moves`: plan id -> (old class, new class) for the
    plans whose class changed (None: not compiled); `counts`: the two compiles' class counts."""
    out = [f"# What the runs of {task.name} showed", "",
           f"{learned.runs} runs from {sources} records. Bounds: distribution-free tolerance intervals from order "
           f"statistics, each covering at least {learned.coverage:g} of the durations with confidence "
           f"{learned.confidence:g} (needs at least {learned.min_n} observations; fewer keep the old bound), "
           "rounded outward to 0.01 s.", "",
           "## Manipulation durations", "",
           "| agent | phase | n | observed min / median / max (s) | old | new | r | confidence "
           "| overruns below / above |",
           "|---|---|---:|---|---|---|---:|---:|---|"]
    for b in learned.bounds:
        if not b.n and b.kept:
            continue
        obs = f"{_f(b.samples[0])} / {_f(float(np.median(b.samples)))} / {_f(b.samples[-1])}" if b.n else "-"
        new = "kept" if b.kept else f"[{b.new.lb:g}, {b.new.ub:g}]"
        rate = f" ({100 * b.overruns / b.n:.1f} %)" if b.n else ""
        out.append(f"| {b.agent} | {b.action}.{b.phase} | {b.n} | {obs} | [{b.old.lb:g}, {b.old.ub:g}] | {new} | "
                   f"{b.order or '-'} | {f'{b.confidence:.3f}' if b.order else '-'} | {b.below} / {b.above}{rate} |")
    total = sum(b.n for b in learned.bounds)
    over = sum(b.overruns for b in learned.bounds)
    out += ["", f"Overruns of today's bounds: {over} of {total} observed durations"
                + (f" ({100 * over / total:.1f} %)." if total else "."), ""]
    if learned.travels:
        out += ["## Travel times (departure to arrival, less waits at a waiting place)", "",
                "| agent | leg to | n | min / median / p90 / max (s) |", "|---|---|---:|---|"]
        for tr in learned.travels:
            out.append(f"| {tr.agent} | {tr.action}.{tr.phase} | {len(tr.samples)} | {_f(tr.samples[0])} / "
                       f"{_f(tr.quantile(0.5))} / {_f(tr.quantile(0.9))} / {_f(tr.samples[-1])} |")
        out.append("")
    out += ["## Sensing delays", ""]
    if learned.delays.by_event:
        out += ["A motion detector's events: given with the tracked position of time `at`, estimated to have "
                "happened at `t`.", "",
                "| event | n | median / p90 / max of at - t (s) |", "|---|---:|---|"]
        for ev, xs in learned.delays.by_event:
            out.append(f"| {ev} | {len(xs)} | {_f(float(np.median(xs)))} / {_f(float(np.quantile(xs, 0.9)))} / "
                       f"{_f(xs[-1])} |")
    else:
        out.append("Not measurable from these runs: their events came from buttons (no estimated times).")
    out.append("")
    if types:
        out += [types, ""]
    out += ["## Plans whose class moves", ""]
    if moves is None or counts is None:
        out.append("Not compiled (`--no-compile`).")
    else:
        before, after = counts
        out.append(f"Old task: {before}; new task: {after}.")
        out.append("")
        if moves:
            out += ["| plan | old class | new class |", "|---|---|---|"]
            out += [f"| {pid} | {a or '-'} | {b or '-'} |" for pid, (a, b) in sorted(moves.items())]
        else:
            out.append("No plan changes class.")
    out.append("")
    if learned.warnings or skipped:
        out += ["## Warnings", ""] + [f"- {w}" for w in (*learned.warnings, *skipped)] + [""]
    if figures:
        out += ["## Figures", ""] + [f"![{f}]({f})" for f in figures] + [""]
    return "\n".join(out)


def write_learn_report(folder: Path, task: Task, learned: Learned, sources: int, skipped: Sequence[str],
                       moves: Mapping[str, tuple[str | None, str | None]] | None,
                       counts: tuple[dict, dict] | None, types: str = "") -> None:
    """``report.md`` and ``figures/`` into `folder` (which exists and is empty: the caller's stage)."""
    (folder / "figures").mkdir()
    figures = []
    for agent in task.agent_ids:
        name = f"figures/durations-{agent}.png"
        if durations_figure(task, learned, agent, folder / name):
            figures.append(name)
    (folder / "report.md").write_text(learn_markdown(task, learned, sources, skipped, moves, counts, figures, types),
                                      encoding="utf-8")
