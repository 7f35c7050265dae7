"""Reports of a compiled plan set: ``report.md``, ``report.html`` and ``figures/*.png``.

The last stage of the flow (../shared/DESIGN.md): the only place that plots. `write_report` collects
what to say once (`summary.build_report_data`), draws the figures of the featured plans only (the three
best and the best of each class: a report of thousands of plans still has a handful of figures), and
renders each format in `FORMATS` from the same data. Output is deterministic: the same compiled set
gives the same bytes (no timestamps; PNGs without software/date metadata).

Figures: ``counts.png`` (plans per class), ``makespans.png`` (worst-case makespans of all plans per
class, only when the ranked table holds the best plans only: `hrc.compile.stream`), ``gantt_ID.png``
(earliest schedule per agent), ``gantt_worst_ID.png`` (the same with every human duration at its
maximum), ``map_ID.png`` (workspace, both agents' routes with detours, the places where a passing order
makes one wait).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from hrc.report.html import render_html
from hrc.report.markdown import render_markdown
from hrc.report.summary import ReportData, build_report_data, featured_plans

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from hrc.compile.compiler import CompiledPlanSet

__all__ = ["FORMATS", "REPORT_FILES", "write_figures", "write_report"]

FORMATS: dict[str, Callable[[ReportData, dict[str, str]], str]] = {
    "report.md": render_markdown,
    "report.html": render_html,
}
"""Report file name -> renderer ``(data, figures) -> text``; `write_report` writes each of them."""

REPORT_FILES = (*FORMATS, "figures")
"""What `write_report` writes into an output folder (files and the figures' folder)."""


def write_figures(cps: CompiledPlanSet, out_dir: Path) -> dict[str, str]:
    """Draw the figures into ``out_dir/figures``; returns figure key -> path relative to `out_dir`.

    One Gantt and one map figure are reused for all featured plans: the plan-independent part (axes,
    workspace) is drawn once and each plan's artists are removed after saving, which saves about a third
    of the drawing time (ticks and text layouts are cached). The bytes are those of a fresh figure.
    """
    from hrc.report.figures import counts_figure, makespans_figure, save_png
    from hrc.report.gantt import draw_gantt, gantt_base
    from hrc.report.maps import draw_map, map_base

    fig_dir = out_dir / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    written: dict[str, str] = {}

    def save(key: str, fig: Figure, clear: bool = True) -> None:
        save_png(fig, fig_dir / f"{key}.png", clear=clear)
        written[key] = f"figures/{key}.png"

    save("counts", counts_figure(cps.counts()))
    if cps.summary is not None and cps.total > len(cps.plans):  # a large set: its distribution, not its rows
        save("makespans", makespans_figure(cps.summary.bins,
                                           {st.plan_class: st.histogram for st in cps.summary.stats}))
    featured = featured_plans(cps)
    for which, prefix in (("earliest", "gantt_"), ("worst", "gantt_worst_")):
        gantt_fig, gantt_ax = gantt_base(cps.task, which)
        for cp in featured:
            if cp.classification.schedule:
                added = draw_gantt(gantt_ax, cps.task, cp, which)
                save(f"{prefix}{cp.plan.id}", gantt_fig, clear=False)
                for artist in added:
                    artist.remove()
        gantt_fig.clear()
    map_fig, map_ax = map_base(cps.task)
    for cp in featured:
        added = draw_map(map_ax, cps, cp)
        save(f"map_{cp.plan.id}", map_fig, clear=False)
        for artist in added:
            artist.remove()
    map_fig.clear()
    return dict(sorted(written.items()))


def write_report(cps: CompiledPlanSet, out_dir: Path, margin: CompiledPlanSet | None = None) -> None:
    """Write ``report.md``, ``report.html`` and ``figures/`` into `out_dir` (the caller's staging folder);
    `margin`: the task compiled with its fixed margin, to show what the protective separation costs."""
    out_dir = Path(out_dir)
    data = build_report_data(cps, margin)
    figures = write_figures(cps, out_dir)
    for name, render in FORMATS.items():
        (out_dir / name).write_text(render(data, figures), encoding="utf-8")
