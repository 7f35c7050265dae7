"""Reports of a compiled plan set: ``report.md``, ``report.html`` and ``figures/*.png``.

The last stage of the flow (../shared/DESIGN.md): the only place that plots. `write_report` collects
what to say once (`summary.build_report_data`), draws the figures of the featured plans only (the three
best and the best of each class: a report of thousands of plans still has a handful of figures), and
renders each format in `FORMATS` from the same data. Output is deterministic: the same compiled set
gives the same bytes (no timestamps; PNGs without software/date metadata).

What a person waits for (issue 38): ``hrc compile`` starts a `hrc.report.drawer.FigureDrawer` before it
plans its paths (matplotlib is imported there, never in the command's own process), and `write_report`
hands it the figures (`FigureWork`, `figure_names`: their names are known before any is drawn) while
it writes the text; the drawer draws them half each in two processes. Each PNG is also kept in the disk
cache (`draw_figures`). The files are those `write_figures` draws in one process, byte for byte.

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
from hrc.report.plan_figures import Bases, FigureWork, draw_figures, figure_bases, figure_names, figure_work
from hrc.report.summary import ReportData, build_report_data

if TYPE_CHECKING:
    from hrc.compile.compiler import CompiledPlanSet
    from hrc.report.drawer import FigureDrawer

__all__ = ["FORMATS", "REPORT_FILES", "Bases", "FigureWork", "draw_figures", "figure_bases", "figure_names",
           "figure_work", "write_figures", "write_report"]

FORMATS: dict[str, Callable[[ReportData, dict[str, str]], str]] = {
    "report.md": render_markdown,
    "report.html": render_html,
}
"""Report file name -> renderer ``(data, figures) -> text``; `write_report` writes each of them."""

REPORT_FILES = (*FORMATS, "figures")
"""What `write_report` writes into an output folder (files and the figures' folder)."""


def write_figures(cps: CompiledPlanSet, out_dir: Path) -> dict[str, str]:
    """Draw the figures into ``out_dir/figures`` in this process; returns figure key -> path relative to
    `out_dir` (`figure_names`)."""
    work = figure_work(cps)
    draw_figures(work, out_dir)
    return figure_names(work)


def write_report(cps: CompiledPlanSet, out_dir: Path, margin: CompiledPlanSet | None = None,
                 drawer: FigureDrawer | None = None) -> None:
    """Write ``report.md``, ``report.html`` and ``figures/`` into `out_dir` (the caller's staging folder);
    `margin`: the task compiled with its fixed margin, to show what the protective separation costs.
    `drawer`: a `FigureDrawer` started earlier (matplotlib imported there meanwhile): it draws the figures
    in two processes while this one writes the text, and this returns once they are written."""
    out_dir = Path(out_dir)
    work = figure_work(cps)
    if drawer is not None:
        drawer.draw(work, out_dir)
    else:
        draw_figures(work, out_dir)
    data = build_report_data(cps, margin)
    figures = figure_names(work)
    for name, render in FORMATS.items():
        (out_dir / name).write_text(render(data, figures), encoding="utf-8")
    if drawer is not None:
        drawer.wait()
