"""An Agg canvas whose text is rendered once per process and replayed: the report's figures draw the
same strings in the same places again and again (a Gantt chart's and a map's axes, ticks, labels and
legend are the same for every featured plan; issue 38).

Matplotlib's Agg backend (3.11) lays out each string (``FT2Font._layout``) and renders each of its glyphs
with FreeType from Python at every draw: about 45 % of a report figure's CPU. `TextCachingCanvas` keeps,
per process, what a string drawn at a given place sent to the Agg rasteriser (the glyph bitmaps and
where they go, as `RendererAgg.draw_text` handed them to the C renderer's ``draw_text_image``) and hands
the same bitmaps to the same places when the same string is drawn there again: the pixels, and so the
PNG bytes, are those of a fresh render, since a glyph's bitmap depends only on what the key holds
(string, font, size, DPI, position, angle, hinting, antialiasing), never on the colour or the clip,
which ``draw_text_image`` takes from the graphics context of each draw. On the workshop's 16 report
figures 274 of 454 strings are found again, saving about 0.4 s of CPU of 2.0.

Only plain text is cached; mathtext (which also draws rules as paths) is drawn as matplotlib does.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import matplotlib as mpl
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg, RendererAgg
from matplotlib.font_manager import findfont

if TYPE_CHECKING:
    from matplotlib.backend_bases import GraphicsContextBase
    from matplotlib.font_manager import FontProperties
    from matplotlib.text import Text

__all__ = ["CACHE_MAX", "TextCachingCanvas", "TextCachingRenderer", "cached_strings", "clear_text_cache"]

CACHE_MAX = 20_000
"""Strings kept at most (a few kB each); the cache is emptied when it is full (a report draws some
hundreds of distinct ones)."""

_Draws = list[tuple[np.ndarray, int, int, float]]
_CACHE: dict[tuple[Any, ...], _Draws] = {}


def clear_text_cache() -> None:
    """Forget every rendered string (tests; nothing else needs it: keys hold everything the pixels
    depend on)."""
    _CACHE.clear()


def cached_strings() -> int:
    """How many drawn strings the cache holds."""
    return len(_CACHE)


class _Recorder:
    """Stands in for the C renderer while a string is drawn: passes each ``draw_text_image`` through
    and keeps a copy of its arguments."""

    def __init__(self, inner: Any, draws: _Draws) -> None:
        self._inner, self._draws = inner, draws

    def draw_text_image(self, image: Any, x: int, y: int, angle: float, gc: GraphicsContextBase) -> None:
        self._draws.append((np.array(image), x, y, angle))
        self._inner.draw_text_image(image, x, y, angle, gc)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)


class TextCachingRenderer(RendererAgg):
    """`RendererAgg` whose plain text draws are replayed from the process's cache (module docstring)."""

    def draw_text(self, gc: GraphicsContextBase, x: float, y: float, s: str, prop: FontProperties, angle: float,
                  ismath: bool | str = False, mtext: Text | None = None) -> None:
        if ismath:
            super().draw_text(gc, x, y, s, prop, angle, ismath, mtext)
            return
        rc = mpl.rcParams
        key = (s, x, y, angle, self.dpi, self.height, tuple(prop.__dict__.items()), findfont(prop),
               rc["text.hinting"], rc["text.hinting_factor"], rc["text.kerning_factor"], gc.get_antialiased(),
               None if mtext is None else (tuple(mtext.get_fontfeatures() or ()), mtext.get_language()))
        draws = _CACHE.get(key)
        if draws is None:
            draws = []
            inner = self._renderer
            self._renderer = _Recorder(inner, draws)
            try:
                super().draw_text(gc, x, y, s, prop, angle, ismath, mtext)
            finally:
                self._renderer = inner
            if len(_CACHE) >= CACHE_MAX:
                _CACHE.clear()
            _CACHE[key] = draws
            return
        for image, ix, iy, a in draws:
            self._renderer.draw_text_image(image, ix, iy, a, gc)


class TextCachingCanvas(FigureCanvasAgg):
    """`FigureCanvasAgg` drawing with a `TextCachingRenderer` (made again, as Agg's, when the figure's
    size or DPI changes)."""

    def get_renderer(self) -> RendererAgg:
        w, h = self.get_width_height(physical=True)
        key = w, h, self.figure.dpi
        if self._lastKey != key:
            self.renderer = TextCachingRenderer(w, h, self.figure.dpi)
            self._lastKey = key  # type: ignore[assignment]
        return self.renderer
