"""The report's Agg canvas that replays a string's rendered glyphs (`hrc.report.text_cache`): the pixels are
those of matplotlib's own Agg canvas, whatever was drawn before, and strings are really found again."""

from __future__ import annotations

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from hrc.report.text_cache import TextCachingCanvas, cached_strings, clear_text_cache


def _pixels(canvas_class: type, shift: float, color: str, angle: float) -> bytes:
    """A figure with an axes (ticks, labels, title, legend) and free text, rendered on `canvas_class`."""
    fig = Figure(figsize=(3.2, 2.0), dpi=100)
    canvas = canvas_class(fig)
    ax = fig.add_axes((0.15, 0.2, 0.8, 0.65))
    ax.plot([0, 1, 2], [1, 3, 2], label="route")
    ax.set_xlabel("time (s)")
    ax.set_title("Plans per class", color=color)
    ax.legend(loc="upper right", fontsize=7)
    ax.text(0.4 + shift, 2.2, "waits 1.5 s", color=color, fontsize=8, rotation=angle)
    ax.text(1.0, 1.5, "deadline", color="#c62828", fontsize=8, alpha=0.6)
    fig.text(0.02, 0.02, "$x^2$ math", fontsize=7)  # mathtext: drawn by matplotlib, not cached
    canvas.draw()
    return bytes(np.asarray(canvas.buffer_rgba()))


def test_replayed_text_is_agg_s_own_pixels() -> None:
    clear_text_cache()
    first = _pixels(TextCachingCanvas, 0.0, "#222222", 0.0)
    assert first == _pixels(FigureCanvasAgg, 0.0, "#222222", 0.0)
    n = cached_strings()
    assert n > 10  # ticks, labels, title, legend, the two texts
    # the same figure again: every string found (nothing new kept), the same pixels
    assert _pixels(TextCachingCanvas, 0.0, "#222222", 0.0) == first
    assert cached_strings() == n
    # other colours, a text moved by a fraction of a pixel and one turned: replayed where the key matches,
    # rendered again where it does not; still matplotlib's pixels
    for shift, color, angle in ((0.0, "#1f6fb2", 0.0), (0.0013, "#222222", 0.0), (0.0, "#222222", 30.0)):
        mine = _pixels(TextCachingCanvas, shift, color, angle)
        assert mine == _pixels(FigureCanvasAgg, shift, color, angle)
        assert mine != first
    assert cached_strings() == n + 2  # the moved and the turned text; a colour is no part of a glyph
