"""Argument types for the command line: a number within bounds, said in one line when it is not.

argparse calls a type with the option's text and turns an `argparse.ArgumentTypeError` into one
``error: hrc CMD: argument --OPT: MESSAGE`` line and exit status 2, so each type here raises that with a
message that names what was wanted (``must lie in [0, 3600] seconds, got 5000``).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

__all__ = ["real", "whole"]


def real(lo: float = -math.inf, hi: float = math.inf, *, unit: str = "",
         low_open: bool = False) -> Callable[[str], float]:
    """A finite number in ``[lo, hi]`` (``(lo, hi]`` with `low_open`); `unit` names it in the message."""
    interval = f"{'(' if low_open else '['}{lo:g}, {hi:g}]" + (f" {unit}" if unit else "")

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"not a finite number: {text!r}")
        if not ((lo < value) if low_open else (lo <= value)) or value > hi:
            raise argparse.ArgumentTypeError(f"must lie in {interval}, got {text}")
        return value

    return parse


def whole(lo: int = 1, hi: int | None = None, *, what: str = "a whole number") -> Callable[[str], int]:
    """An integer in ``lo..hi`` (no upper bound when `hi` is None); `what` names it when the text is none."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what}, found {text!r}") from None
        if value < lo or (hi is not None and value > hi):
            bounds = f"be at least {lo}" if hi is None else f"lie in {lo}..{hi}"
            raise argparse.ArgumentTypeError(f"must {bounds}, found {text}")
        return value

    return parse
