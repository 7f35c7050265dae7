"""Reports of a compiled plan set: ``report.md``, ``report.html`` and ``figures/*.png``.

The last stage of the flow (../shared/DESIGN.md): the only place that plots. `write_report` collects
what to say once (`summary.build_report_data`), draws the figures of the featured plans only (the three
best and the best of each class: a report of thousands of plans still has a handful of figures), and
renders each format in `FORMATS` from the same data. Output is deterministic: the same compiled set
gives the same bytes (no timestamps; PNGs without software/date metadata).

What a person waits for (issue 38): ``hrc compile`` starts a `hrc.report.drawer.FigureDrawer` first,
before it reads the task (matplotlib is imported there, never in the command's own process), and
`write_report` hands it the figures (`FigureWork`, `figure_names`: their names are known before any is
drawn) while it writes the text; the drawer copies them from the disk cache (`copy_cached`) or draws
them half each in two processes. Each PNG is also kept in the disk cache (`draw_figures`). The files
are those `write_figures` draws in one process, byte for byte.

Figures: ``counts.png`` (plans per class), ``makespans.png`` (worst-case makespans of all plans per
class, only when the ranked table holds the best plans only: `hrc.compile.stream`), ``gantt_ID.png``
(earliest schedule per agent), ``gantt_worst_ID.png`` (the same with every human duration at its
maximum), ``map_ID.png`` (workspace, both agents' routes with detours, the places where a passing order
makes one wait).
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from hrc.compile.compiler import CompiledPlanSet
    from hrc.report.drawer import FigureDrawer
    from hrc.report.plan_figures import Bases, FigureWork, draw_figures, figure_bases, figure_names, figure_work
    from hrc.report.summary import ReportData

__all__ = ["FORMATS", "REPORT_FILES", "Bases", "FigureWork", "draw_figures", "figure_bases", "figure_names",
           "figure_work", "write_figures", "write_report"]

FORMATS: dict[str, Callable[[ReportData, dict[str, str]], str]]
"""Report file name -> renderer ``(data, figures) -> text``; `write_report` writes each of them. Like the
names from `hrc.report.plan_figures`, imported when first read (`__getattr__`): ``hrc compile`` imports
this package for `REPORT_FILES` and the figure process (`hrc.report.drawer`) before it needs the rest."""

REPORT_FILES = ("report.md", "report.html", "figures")
"""What `write_report` writes into an output folder: each of `FORMATS` and the figures' folder."""

_PLAN_FIGURES = ("Bases", "FigureWork", "draw_figures", "figure_bases", "figure_names", "figure_work")


def __getattr__(name: str) -> Any:
    """`FORMATS` and the names of `hrc.report.plan_figures`, imported on first use (PEP 562) and kept."""
    if name == "FORMATS":
        from hrc.report.html import render_html
        from hrc.report.markdown import render_markdown

        value: Any = {"report.md": render_markdown, "report.html": render_html}
    elif name in _PLAN_FIGURES:
        value = getattr(importlib.import_module("hrc.report.plan_figures"), name)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value
    return value


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
    from hrc.report.plan_figures import draw_figures, figure_names, figure_work
    from hrc.report.summary import build_report_data

    out_dir = Path(out_dir)
    work = figure_work(cps)
    if drawer is not None:
        drawer.draw(work, out_dir)
    else:
        draw_figures(work, out_dir)
    data = build_report_data(cps, margin)
    figures = figure_names(work)
    formats = globals().get("FORMATS") or __getattr__("FORMATS")
    for name, render in formats.items():
        (out_dir / name).write_text(render(data, figures), encoding="utf-8")
    if drawer is not None:
        drawer.wait()
