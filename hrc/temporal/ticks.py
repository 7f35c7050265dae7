"""Exact conversion of seconds and decimal text to integer ticks: the one place where numbers from the
outside world become the temporal core's integers (STYLE.md rule 4).

* `to_ticks(seconds, ticks_per_second)` rounds model seconds (floats) to the nearest tick; the compiler
  picks the resolution (milliseconds: ``1000``).
* `scale_to_integers(texts)` turns decimal strings (HEATlab's JSON bounds such as ``"12.5"``) into integers
  exactly: each text is read as a `fractions.Fraction` and everything is multiplied by the least common
  denominator, which is returned so that results can be converted back. A verdict (DC, consistent) does
  not change under such a positive scaling.

>>> scale_to_integers(["1.5", "2", "0.25"])
([6, 8, 1], 4)
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterable
from decimal import Decimal
from fractions import Fraction

__all__ = ["from_ticks", "scale_to_integers", "to_ticks"]


@functools.lru_cache(maxsize=1 << 16)
def to_ticks(seconds: float, ticks_per_second: int = 1000) -> int:
    """``round(seconds * ticks_per_second)`` computed on the exact decimal value of ``seconds``.

    Cached: a compile converts the same few hundred travel times and bounds for every plan, and the
    exact decimal reading through `Fraction` costs about 30 us each."""
    if not math.isfinite(seconds):
        raise ValueError(f"cannot convert {seconds!r} seconds to ticks")
    return round(Fraction(str(seconds)) * ticks_per_second)


def from_ticks(ticks: int, ticks_per_second: int = 1000) -> float:
    """Seconds for ``ticks`` (for reports; the core never goes back to floats)."""
    return ticks / ticks_per_second


def scale_to_integers(texts: Iterable[str | int | Fraction | Decimal]) -> tuple[list[int], int]:
    """Exact values of ``texts`` times their least common denominator, and that denominator."""
    values = [Fraction(t) for t in texts]
    den = math.lcm(*(v.denominator for v in values)) if values else 1
    return [int(v * den) for v in values], den
