"""The report's plan figures (the counts, the makespans, a Gantt chart per schedule and a map per
featured plan): what they show (`FigureWork`), their names, and drawing them, in one process or in
shares over several (`hrc.report.drawer`), with each PNG kept in the disk cache."""

from __future__ import annotations

import functools
import hashlib
import io
import pickle
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from hrc.caches import cache_folder, disk_load, disk_store, source_digest
from hrc.model import Task

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from hrc.compile.compiler import CompiledPlan, CompiledPlanSet

__all__ = ["BASE_KINDS", "FIGURE_COST", "Bases", "FigureWork", "copy_cached", "draw_figures", "drawing_digest",
           "figure_bases", "figure_digests", "figure_names", "figure_work"]


@dataclass(frozen=True, slots=True)
class FigureWork:
    """What the report's figures show, and nothing else: small enough to hand to another process
    (`hrc.report.drawer`). `histogram`: the bins and per-class counts of every plan's worst-case makespan,
    drawn only when the ranked table holds the best plans only; `featured`: `featured_plans`."""

    task: Task
    counts: dict[str, int]
    histogram: tuple[tuple[float, ...], dict[str, tuple[int, ...]]] | None
    featured: tuple[CompiledPlan, ...]


def figure_work(cps: CompiledPlanSet) -> FigureWork:
    """`cps`'s `FigureWork`."""
    histogram = None
    if cps.summary is not None and cps.total > len(cps.plans):  # a large set: its distribution, not its rows
        histogram = (cps.summary.bins, {st.plan_class: st.histogram for st in cps.summary.stats})
    from hrc.report.summary import featured_plans  # here: the figure process imports this module early

    return FigureWork(cps.task, cps.counts(), histogram, featured_plans(cps))


def figure_names(work: FigureWork) -> dict[str, str]:
    """Figure key -> path relative to the output folder, of every figure `draw_figures` writes for `work`
    (known before any is drawn: the report's text does not wait for the pictures)."""
    keys = ["counts"] + ["makespans"] * (work.histogram is not None)
    for prefix in ("gantt_", "gantt_worst_"):
        keys += [f"{prefix}{cp.plan.id}" for cp in work.featured if cp.classification.schedule]
    keys += [f"map_{cp.plan.id}" for cp in work.featured]
    return {key: f"figures/{key}.png" for key in sorted(keys)}


Bases = dict[str, "tuple[Figure, Axes]"]
"""The plan-independent figures by kind (``gantt_earliest``, ``gantt_worst``, ``map``), drawn once each
and reused for every plan (`draw_figures`, `figure_bases`)."""


FIGURE_COST = {"counts": 0.6, "makespans": 0.8, "gantt_earliest": 1.0, "gantt_worst": 1.0, "map": 0.7}
"""Each kind of figure's drawing time, relative to a Gantt chart's (the workshop's: about 0.15 s of CPU):
`draw_figures` splits a report's figures into shares of about equal cost (`hrc.report.figures.shares`;
every second figure in drawing order gave one process a map more, 0.1-0.2 s of waiting for the other)."""

BASE_KINDS = ("gantt_earliest", "gantt_worst", "map")
"""The kinds of plan figure, each drawn on its own base (`Bases`)."""


def figure_bases(task: Task, bases: Bases | None = None, kinds: tuple[str, ...] = BASE_KINDS) -> Bases:
    """`bases` (a new dict if None) with the base of each of `kinds` (default: every kind of plan figure)
    for `task` in it."""
    from hrc.report.gantt import gantt_base
    from hrc.report.maps import map_base

    bases = {} if bases is None else bases
    for kind in kinds:
        if kind not in bases:
            bases[kind] = map_base(task) if kind == "map" else gantt_base(task, kind.removeprefix("gantt_"))
    return bases


def draw_figures(work: FigureWork, out_dir: Path, share: tuple[int, int] = (0, 1),
                 bases: Bases | None = None) -> None:
    """Draw `work`'s figures into ``out_dir/figures`` (`figure_names`): with `share` ``(k, n)`` only the
    k-th of every n, so that n processes draw them all at once (`hrc.report.drawer`).

    One Gantt (per schedule) and one map figure are reused for all featured plans (`bases`, drawn here if
    not given): the plan-independent part (axes, workspace) is drawn once and each plan's artists are
    removed after saving, which saves about a third of the drawing time (ticks and text layouts are
    cached). The bytes are those of a fresh figure.

    Each PNG is also kept in the disk cache (`hrc.caches.cache_folder` ``figures``) under everything its
    bytes depend on (`_figure_key`): a compile of the same task again copies its figures from there.
    """
    from hrc.report.figures import counts_figure, makespans_figure, save_png, shares

    fig_dir = Path(out_dir) / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    task = work.task
    k, n = share
    folder = cache_folder("figures")
    mine = []
    todo = _todo(work)  # split the same way in every process, by each kind's usual cost
    for kind, key, cp in (todo[i] for i in shares([FIGURE_COST[kind] for kind, _, _ in todo], n)[k]):
        payload = work.counts if kind == "counts" else work.histogram if kind == "makespans" else (task, cp)
        ckey = _figure_key(kind, payload) if folder is not None else ""
        found = disk_load(folder, ckey)
        if isinstance(found, bytes):
            (fig_dir / f"{key}.png").write_bytes(found)
        else:
            mine.append((kind, key, cp, ckey))
    if any(cp is not None for _, _, cp, _ in mine):
        from hrc.report.gantt import draw_gantt
        from hrc.report.maps import draw_map

        bases = figure_bases(task, bases)
    for kind, key, cp, ckey in mine:
        if cp is None:
            fig = counts_figure(work.counts) if kind == "counts" else makespans_figure(*work.histogram)  # type: ignore[misc]
            disk_store(folder, ckey, save_png(fig, fig_dir / f"{key}.png"))
            continue
        fig, ax = bases[kind]  # type: ignore[index]
        if kind == "map":
            added = draw_map(ax, task, cp)
        else:
            added = draw_gantt(ax, task, cp, kind.removeprefix("gantt_"))
        disk_store(folder, ckey, save_png(fig, fig_dir / f"{key}.png", clear=False))
        for artist in added:
            artist.remove()


def _todo(work: FigureWork) -> list[tuple[str, str, CompiledPlan | None]]:
    """Every figure of `work` as (kind, name, the plan it shows or None), in drawing order."""
    todo: list[tuple[str, str, CompiledPlan | None]] = [("counts", "counts", None)]
    if work.histogram is not None:
        todo.append(("makespans", "makespans", None))
    for which, prefix in (("earliest", "gantt_"), ("worst", "gantt_worst_")):
        todo += [(f"gantt_{which}", f"{prefix}{cp.plan.id}", cp) for cp in work.featured if cp.classification.schedule]
    todo += [("map", f"map_{cp.plan.id}", cp) for cp in work.featured]
    return todo


def figure_digests(work: FigureWork) -> tuple[tuple[str, str, str], ...]:
    """Each figure of `work` as (kind, name, the digest of what it shows): with `drawing_digest`, its key in
    the disk cache (`_figure_key`), computed without matplotlib, so that the figure process can copy
    every figure from the cache before it has imported what a `FigureWork` is made of (`copy_cached`)."""
    task = work.task
    return tuple((kind, key, _content_digest(work.counts if kind == "counts" else work.histogram
                                             if kind == "makespans" else (task, cp)))
                 for kind, key, cp in _todo(work))


def copy_cached(digests: tuple[tuple[str, str, str], ...], out_dir: Path) -> bool:
    """Write every figure of `digests` (`figure_digests`) into ``out_dir/figures`` from the disk cache, if
    all are there (True); else write none (False: they are drawn, `draw_figures`)."""
    folder = cache_folder("figures")
    if folder is None:
        return False
    found = [disk_load(folder, repr(("figure-1", drawing_digest(), kind, digest))) for kind, _, digest in digests]
    if not all(isinstance(png, bytes) for png in found):
        return False
    fig_dir = Path(out_dir) / "figures"
    fig_dir.mkdir(parents=True, exist_ok=True)
    for (_, key, _), png in zip(digests, found, strict=True):
        (fig_dir / f"{key}.png").write_bytes(png)
    return True


def _figure_key(kind: str, payload: object) -> str:
    """A figure's key in the disk cache (``figures``): everything its bytes depend on. The report's code,
    matplotlib's and Pillow's versions, matplotlib's settings (``rcParams``, a user's matplotlibrc
    included) and the font it finds, and what the figure shows (`_content_digest`)."""
    return repr(("figure-1", drawing_digest(), kind, _content_digest(payload)))


def _content_digest(value: object) -> str:
    """SHA-256 of `value`'s pickle without the memo (``fast``): equal content gives equal bytes, whether
    or not its parts are shared objects (a plan compiled in a worker and one from the estimate's sample
    share different parts)."""
    buf = io.BytesIO()
    pickler = pickle.Pickler(buf, protocol=5)
    pickler.fast = True  # no memo: a shared part is written again, as an equal unshared one is
    pickler.dump(value)
    return hashlib.sha256(buf.getvalue()).hexdigest()


_DRAWING_CODE = ("hrc.report.plan_figures", "hrc.report.figures", "hrc.report.gantt", "hrc.report.maps",
                 "hrc.report.summary", "hrc.report.separation", "hrc.compile.temporal_net_creator",
                 "hrc.compile.motion_pattern", "hrc.motion.separation", "hrc.plans", "hrc.model")
"""The modules whose code draws a report figure (`_figure_key`)."""


@functools.cache
def drawing_digest() -> str:
    """What every figure's bytes depend on besides what it shows (`_figure_key`); imports matplotlib (not
    pyplot)."""
    import matplotlib
    import PIL
    from matplotlib.font_manager import FontProperties, findfont

    # every setting but the backend: the figures are drawn on their own Agg canvas whatever it says, and
    # reading it resolves the default backend, which imports pyplot and probes for a GUI toolkit
    params = matplotlib.rcParams
    settings = repr(sorted((k, repr(params[k])) for k in params if k != "backend"))
    return hashlib.sha256(repr((source_digest(*_DRAWING_CODE),
                                matplotlib.__version__, PIL.__version__, settings,
                                findfont(FontProperties()))).encode()).hexdigest()
