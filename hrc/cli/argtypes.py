"""Argument types for the command line: a number within bounds, said in one line when it is not.

argparse calls a type with the option's text and turns an `argparse.ArgumentTypeError` into one
``error: hrc CMD: argument --OPT: MESSAGE`` line and exit status 2, so each type here raises that with a
message that names what was wanted (``must lie in [0, 3600] seconds, got 5000``).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from fractions import Fraction

__all__ = ["delay_range", "real", "whole"]


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


_DELAY_MAX = 10**9  # units: a delay past a billion seconds (or ticks) is a typing error, not a sensor
_DELAY_DECIMALS = 6


def delay_range(text: str) -> tuple[Fraction, Fraction | None]:
    """An observation delay: ``D`` (fixed), ``inf`` (never observed) or ``LO:HI`` (anywhere in between;
    ``HI`` may be ``inf``), non-negative decimals with at most 6 decimal places, read exactly. Returns
    ``(lo, hi)``, ``hi`` None for never."""

    def number(part: str, what: str) -> Fraction | None:
        part = part.strip()
        if part.lower() in ("inf", "infinity"):
            return None
        try:
            value = Fraction(part)
        except (ValueError, ZeroDivisionError):
            raise argparse.ArgumentTypeError(f"{what}: not a number or inf: {part!r}") from None
        if "/" in part:
            raise argparse.ArgumentTypeError(f"{what}: a decimal, not a fraction: {part!r}")
        if value < 0:
            raise argparse.ArgumentTypeError(f"{what}: a delay cannot be negative, got {part}")
        if value > _DELAY_MAX or value.denominator > 10**_DELAY_DECIMALS or \
                10**_DELAY_DECIMALS % value.denominator:
            raise argparse.ArgumentTypeError(f"{what}: at most {_DELAY_MAX:g} with {_DELAY_DECIMALS} decimals, "
                                             f"got {part}")
        return value

    if text.count(":") > 1:
        raise argparse.ArgumentTypeError(f"expected D, inf or LO:HI, got {text!r}")
    if ":" in text:
        low, high = text.split(":")
        lo, hi = number(low, "LO"), number(high, "HI")
        if lo is None:
            raise argparse.ArgumentTypeError(f"LO must be finite, got {text!r}")
        if hi is not None and lo > hi:
            raise argparse.ArgumentTypeError(f"LO must not exceed HI, got {text!r}")
        return lo, hi
    one = number(text, "delay")
    return (Fraction(0), None) if one is None else (one, one)
