"""The report's figures drawn beside the compile, in two processes of their own (issue 38).

Drawing the figures is most of a small compile's report (matplotlib's import and 16 PNGs: about 2 s of
the workshop's 5), and it needs only what the figures show (`hrc.report.plan_figures.FigureWork`). A
`FigureDrawer` is started (forked) as soon as the command starts, before the task is read (`task` sends
it) and before the compile's imports: while this process reads and plans, it imports matplotlib and
draws each figure's plan-independent base (axes, the workspace), on the core the path planning leaves
idle, until the work comes (a compile taken from the cache asks at once, and its figures are all in the
disk cache: no base is drawn then). Once the plans
are ranked, `draw` hands it the work; it forks once more, so that the figures are drawn half each
(`hrc.report.plan_figures.draw_figures`' share) at once on both cores, while this process writes the
report's text (whose figure names are known in advance: `hrc.report.plan_figures.figure_names`); `wait`
returns when every file is written. The files are those `hrc.report.write_figures` writes, byte for byte:
the same functions draw them, each figure on a base drawn the same way (tests/test_report_drawer.py).

Like the compile's pool workers (`hrc.compile.executors`), the drawer ignores SIGINT and SIGTERM (the
compile alone decides how to stop) and dies with its parent; `close` stops it if the report was never
asked for (an interrupted compile). A failure in it is raised here as `RuntimeError` with its traceback.
"""

from __future__ import annotations

import contextlib
import importlib
import multiprocessing as mp
import os
import pickle
import signal
import traceback
from collections.abc import Callable
from multiprocessing.connection import Connection
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hrc.report.figures import shares

if TYPE_CHECKING:
    from hrc.model import Task
    from hrc.report.plan_figures import Bases, FigureWork

__all__ = ["WORK_SOON", "FigureDrawer", "draw_in_two", "shares"]

WORK_SOON = 1.0
"""Seconds the figure process waits for its work, once the bases are drawn, before it imports what reading
the work needs (a warm compile asks within them; a cold one takes seconds more)."""


class FigureDrawer:
    """A process that draws a report's figures when asked (module docstring). Use as a context manager
    around the compile; at most one `draw` then `wait`."""

    def __init__(self, task: Task | None = None) -> None:
        ctx = mp.get_context("fork")  # the imports so far come with the fork, not pickled
        self._conn, theirs = ctx.Pipe()
        self._proc = ctx.Process(target=_serve, args=(task, theirs, os.getpid()), name="hrc-figures", daemon=True)
        self._proc.start()
        theirs.close()
        self._asked = False

    def task(self, task: Task) -> None:
        """The task whose figures will be drawn, for a drawer started before it was read (without one, the
        bases are drawn only once the work comes)."""
        self._conn.send(("task", task))

    def __enter__(self) -> FigureDrawer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close(at_once=exc[0] is not None)  # a failure (a bad task file): no report is coming

    def draw(self, work: FigureWork, out_dir: Path) -> None:
        """Start drawing `work`'s figures into ``out_dir/figures``; `wait` for them."""
        from hrc.report.plan_figures import figure_digests

        # the figures' cache keys, and the work as bytes: the process copies them all from the cache
        # without importing what the work is made of (the compiler), and reads the work only to draw
        self._conn.send(("work", figure_digests(work), pickle.dumps(work, protocol=pickle.HIGHEST_PROTOCOL),
                         str(out_dir)))
        self._asked = True

    def wait(self) -> None:
        """Return once the figures `draw` asked for are written; raise `RuntimeError` if drawing failed."""
        try:
            answer = self._conn.recv()
        except EOFError:
            answer = f"the figure process ended (exit status {self._proc.exitcode}) before its figures were written"
        self._asked = False
        if answer is not None:
            raise RuntimeError(f"drawing the report's figures failed:\n{answer}")

    def close(self, at_once: bool = False) -> None:
        """Stop the process (at once if it is still drawing: the staging folder is thrown away then; or if
        `at_once`: no report is coming)."""
        if self._proc.is_alive():
            if self._asked or at_once:
                self._proc.kill()
            else:
                self._conn.send(None)  # nothing to draw: it ends
        self._conn.close()
        self._proc.join(timeout=5)
        if self._proc.is_alive():  # pragma: no cover - it ends on the message above
            self._proc.kill()
            self._proc.join()


def _serve(task: Task | None, conn: Connection, parent: int) -> None:
    from hrc.compile.executors import _die_with_parent

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    _die_with_parent(parent, direct=True)
    failed: str | None = None
    bases: Bases = {}
    try:
        _import_drawing()
        from hrc.report.plan_figures import drawing_digest

        drawing_digest()  # matplotlib's settings and font read: what every figure's cache key needs
    except BaseException:  # noqa: BLE001 - said when the work is asked for
        failed = traceback.format_exc()
    job: Any = ("task", task)
    while job[0] == "task":  # the task (maybe more than once), then the work or None
        if job[1] is not None and failed is None:
            failed = _bases(job[1], bases, conn)
            if failed is None and not conn.poll(WORK_SOON):
                # a compile that takes a while: what reading the work needs (the compiler's records), imported
                # now on the idle core rather than once the report waits for it (a compile taken from the
                # cache asks sooner, and its figures are copied without reading the work)
                with contextlib.suppress(Exception):  # reading the work then says what is wrong
                    importlib.import_module("hrc.compile.compiler")
        job = conn.recv()
        if job is None:
            return
    if failed is not None:
        conn.send(failed)
        return
    _, digests, blob, out = job
    from hrc.report.plan_figures import copy_cached, draw_figures

    try:
        if copy_cached(digests, Path(out)):
            conn.send(None)
            return
    except BaseException:  # noqa: BLE001 - said to the caller
        conn.send(traceback.format_exc())
        return
    work = pickle.loads(blob)
    conn.send(_draw_in_two(lambda share: draw_figures(work, Path(out), share, bases)))


def _import_drawing() -> None:
    """Import what drawing a figure needs (matplotlib's figure, Agg canvas and artists; the report's
    drawing modules), without the text of matplotlib's generated ``Artist.set`` docstrings.

    Each `matplotlib.artist.Artist` subclass, as it is defined, gets a ``set`` method whose docstring
    lists every property with its accepted values (`matplotlib.artist.kwdoc`, through an
    `~matplotlib.artist.ArtistInspector` reading each setter's docstring): about 0.2 s of CPU of
    matplotlib's 0.7 s import, for text that only ``help()`` reads. This process only draws, so that
    text is left empty here (`kwdoc` answers "" while these modules are imported, and is put back after;
    the signatures, which matplotlib builds beside, are as ever). The figures' bytes do not depend on it
    (tests/test_report.py draws them both ways)."""
    import matplotlib.artist

    kwdoc = matplotlib.artist.kwdoc
    matplotlib.artist.kwdoc = lambda artist: ""
    try:
        import matplotlib.backends.backend_agg
        import matplotlib.figure  # noqa: F401

        importlib.import_module("hrc.report.gantt")
        importlib.import_module("hrc.report.maps")
    finally:
        matplotlib.artist.kwdoc = kwdoc


def _bases(task: Task, bases: Bases, conn: Connection) -> str | None:
    """The bases every plan's figure is drawn on, drawn one by one into `bases` while the compile runs
    (with the font cache and the text layouts they warm), until a message comes: both drawing processes
    reuse them; one not drawn by then is drawn only if a figure needs it (none does when all are in the
    disk cache). None, or what went wrong."""
    try:
        from hrc.report.plan_figures import BASE_KINDS, figure_bases

        for kind in BASE_KINDS:
            if conn.poll():
                break
            fig, _ = figure_bases(task, bases, (kind,))[kind]
            fig.canvas.draw()
    except BaseException:  # noqa: BLE001 - said when the work is asked for
        return traceback.format_exc()
    return None


def _draw_in_two(draw: Callable[[tuple[int, int]], None]) -> str | None:
    """``draw((1, 2))`` in a forked child and ``draw((0, 2))`` here, at once; None, or what went wrong."""
    read, write = os.pipe()
    child = os.fork()
    if child == 0:  # the child: its share, then out without the parent's exit handlers
        os.close(read)
        code = 0
        try:
            from hrc.compile.executors import _die_with_parent

            _die_with_parent(os.getppid(), direct=True)
            draw((1, 2))
        except BaseException:  # noqa: BLE001 - handed to the parent
            os.write(write, traceback.format_exc().encode())
            code = 1
        finally:
            os.close(write)
            os._exit(code)
    os.close(write)
    failed = None
    try:
        draw((0, 2))
    except BaseException:  # noqa: BLE001 - handed to the caller
        failed = traceback.format_exc()
    with os.fdopen(read, "rb") as pipe:
        theirs = pipe.read().decode()
    _, status = os.waitpid(child, 0)
    if theirs or status:
        failed = (failed or "") + (theirs or f"the second figure process ended with status {status}")
    return failed


def draw_in_two(draw: Callable[[tuple[int, int]], None]) -> None:
    """``draw(share)`` for the shares ``(0, 2)`` and ``(1, 2)`` at once: the second in a process forked
    from this one (it has what this one has), the first here; returns when both are done, raises
    `RuntimeError` with the failure's traceback if either failed."""
    failed = _draw_in_two(draw)
    if failed is not None:
        raise RuntimeError(f"drawing the figures failed:\n{failed}")
