"""Distribution-free tolerance intervals from order statistics.

Given ``n`` independent observations of a continuous quantity, sorted ``x(1) <= ... <= x(n)``, the
interval ``[x(r), x(n+1-r)]`` contains at least a fraction `coverage` ``p`` of the whole distribution
with probability

    P(coverage >= p) = P(Binomial(n, p) <= n - 2r) = binom.cdf(n - 2r, n, p)  (scipy.special.bdtr)

whatever the distribution (Wilks 1941; the coverage of the interval between two order statistics is
``Beta(n + 1 - 2r, 2r)``, and a Beta tail is a binomial sum). `tolerance_interval` takes the largest
``r >= 1`` for which this reaches the `confidence` ``gamma``: the narrowest symmetric interval that keeps
the promise. With fewer than `min_observations` observations even ``[min, max]`` (``r = 1``) does not, and
there is no bound to give: the caller keeps the one it had (``hrc learn``'s guard rail).

Why not a fitted distribution: a person's manipulation times are bounded, skewed and multi-modal (a
fumble, a second try), and no family is known to hold on a given cell; a fitted family's quantile is only
as good as the family, while the order statistics' promise holds for any continuous distribution. The
price is sample size: ``p = 0.90, gamma = 0.95`` needs 46 observations (``p = 0.95``: 93), the classic
table values (e.g. NIST/SEMATECH e-Handbook, section 7.2.6.3).

>>> min_observations(0.90, 0.95), min_observations(0.95, 0.95)
(46, 93)
>>> tolerance_interval([float(i) for i in range(1, 47)], 0.90, 0.95)[:3]
(1.0, 46.0, 1)
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from scipy.special import bdtr  # the binomial CDF (scipy.stats' binom.cdf is it, at 20 times the import)

__all__ = ["confidence_of", "min_observations", "tolerance_interval"]


def _check(coverage: float, confidence: float) -> None:
    if not (0.0 < coverage < 1.0 and 0.0 < confidence < 1.0):
        raise ValueError(f"coverage and confidence must be in (0, 1), found {coverage!r}, {confidence!r}")


def confidence_of(n: int, r: int, coverage: float) -> float:
    """The probability that ``[x(r), x(n+1-r)]`` of `n` observations covers at least `coverage` of the
    distribution (0 when the interval is empty, ``2r > n``)."""
    if r < 1 or 2 * r > n:
        return 0.0
    return float(bdtr(n - 2 * r, n, coverage))


def min_observations(coverage: float, confidence: float) -> int:
    """The fewest observations for which ``[min, max]`` is a (`coverage`, `confidence`) tolerance interval.
    O(log) evaluations of the binomial CDF."""
    _check(coverage, confidence)
    lo, hi = 2, 4
    while confidence_of(hi, 1, coverage) < confidence:
        lo, hi = hi, hi * 2
    while lo < hi:  # the confidence of [min, max] grows with n
        mid = (lo + hi) // 2
        if confidence_of(mid, 1, coverage) >= confidence:
            hi = mid
        else:
            lo = mid + 1
    return lo


def tolerance_interval(samples: Sequence[float], coverage: float, confidence: float
                       ) -> tuple[float, float, int, float] | None:
    """``(lower, upper, r, achieved confidence)``: ``[x(r), x(n+1-r)]`` with the largest such `r`, or
    None when there are too few samples (`min_observations`). O(n log n) for the sort and O(log n)
    binomial CDFs for `r`."""
    _check(coverage, confidence)
    xs = sorted(samples)
    n = len(xs)
    if any(not math.isfinite(x) for x in xs):
        raise ValueError("samples must be finite numbers")
    if confidence_of(n, 1, coverage) < confidence:
        return None
    lo, hi = 1, n // 2  # the confidence falls as r grows: the largest r that still reaches it
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if confidence_of(n, mid, coverage) >= confidence:
            lo = mid
        else:
            hi = mid - 1
    return xs[lo - 1], xs[n - lo], lo, confidence_of(n, lo, coverage)
