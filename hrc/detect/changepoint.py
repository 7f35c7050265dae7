"""Change points: when a person left a place or reached one, from their noisy positions.

A person standing still, then walking off at a walker's pace (or walking in, then standing) traces a
hinge in time: ``p = c + w * max(0, t - t0)``. `hinge` fits it by least squares to the positions of the
last `_SPAN` seconds (on the positions themselves, not on distances, whose noise is biased away from
zero) and gives the break point t0: the time the departure or arrival happened, not the time it was
seen (the detector sees it a few positions later). `left_at` and `arrived_at` are the two uses
(`hrc.detect.filter`). A two-phase segmented regression with a known form (Hinkley 1969 and after).
"""

from __future__ import annotations

import numpy as np

from .model import DetectorModel

__all__ = ["CONFIDENCE", "arrived_at", "arrived_span", "hinge", "hinge_span", "left_at", "left_span", "pace"]

Samples = tuple[tuple[float, float, float], ...]  # (t, x, y), oldest first


def hinge(ts: np.ndarray, xs: np.ndarray, ys: np.ndarray, rising: bool, lo: float, hi: float,
          pace: tuple[float, float]) -> float:
    """The break point t0 of the hinge best fitted (least squares) to positions (xs, ys) at times `ts`:
    ``p = c + w * max(0, t - t0)`` when `rising` (standing at c, then walking off at velocity w: a
    departure at t0), ``p = c + w * max(0, t0 - t)`` otherwise (walking in, then standing at c: an
    arrival), with the speed ``|w|`` within `pace` (m/s: a walker's); t0 searched in [lo, hi] on a 100 ms
    grid, then on a 20 ms one around the best. Fitted on the positions themselves, not on distances
    (whose noise is biased away from zero),
    so the noise does not shift it. O(n k) for n positions and k grid points.

    >>> ts = np.arange(0.0, 3.0, 0.1)
    >>> xs = 2.0 + 1.2 * np.maximum(0.0, ts - 1.0)
    >>> round(hinge(ts, xs, np.zeros_like(ts), True, 0.0, 3.0, (0.8, 1.3)), 2)
    1.0
    """
    if hi <= lo or len(ts) < 3:
        return hi
    coarse = _hinge_best(ts, xs, ys, rising, np.arange(lo, hi + 1e-9, 0.1), pace)  # then 20 ms around it
    return _hinge_best(ts, xs, ys, rising, np.arange(max(lo, coarse - 0.12), min(hi, coarse + 0.12) + 1e-9, 0.02),
                       pace)


def _hinge_best(ts: np.ndarray, xs: np.ndarray, ys: np.ndarray, rising: bool, grid: np.ndarray,
                pace: tuple[float, float]) -> float:
    """The grid point whose hinge fits best (see `hinge`)."""
    return float(grid[int(np.argmin(_hinge_rss(ts, xs, ys, rising, grid, pace)))])


CONFIDENCE = 15.14
"""The chi-square quantile (1 degree of freedom, 1 - 1e-4) that bounds a break point's profile-likelihood
interval (`hinge_span`): a run gives out a few dozen dated events, a simulation of 200 runs a few
thousand, and none should fall outside its stated interval by chance."""


def hinge_span(ts: np.ndarray, xs: np.ndarray, ys: np.ndarray, rising: bool, lo: float, hi: float,
               pace: tuple[float, float], t0: float, sigma: float) -> tuple[float, float]:
    """Where the break point of the hinge (`hinge`) fitted at `t0` may truly be, ``(earliest, latest)``:
    every t on a 20 ms grid over [lo, hi] whose best hinge leaves a residual sum of squares within
    `CONFIDENCE` times ``sigma**2`` of the least (the profile-likelihood confidence set of a change point
    with known noise, Hinkley 1970, "Inference about the change-point in a sequence of random
    variables", Biometrika 57, section 4: ``2 log LR = (RSS(t) - RSS(t_hat)) / sigma**2``, referred to
    chi-square with one degree of freedom), and `t0` itself. What the noise and the number of positions
    after the break allow, not a constant: 3 sigma of the noise in walking time was exceeded by a few
    departures in 1,000 (issue 32: estimates 127-154 ms early at 0.05 m, 376-508 ms at 0.15 m, each
    breaking a passing order)."""
    if hi <= lo or len(ts) < 3 or sigma <= 0:
        return t0, t0
    grid = np.arange(lo, hi + 1e-9, 0.02)
    a, b = _profile_span(ts, xs, ys, rising, grid, pace, t0, sigma)
    # one wild position among the few nearest the break can move the fit and its interval together (issue
    # 32: a tracker reading 3.3 sigma off a place, 0.2 s before the person left it, dated the departure
    # 0.41 s early, outside its interval): the interval is the union of those left out one at a time
    # (a jackknife over the positions that decide the break), each with its own best break
    near = np.argsort(np.abs(ts - t0))[:_JACKKNIFE]
    for k in near:
        keep = np.arange(len(ts)) != k
        if keep.sum() < 3:
            continue
        sub = ts[keep], xs[keep], ys[keep]
        t1 = float(grid[int(np.argmin(_hinge_rss(*sub, rising, grid, pace)))])
        c, d = _profile_span(*sub, rising, grid, pace, t1, sigma)
        a, b = min(a, c), max(b, d)
    return a, b


_JACKKNIFE = 3
"""How many positions nearest the fitted break `hinge_span` leaves out one at a time."""


def _profile_span(ts: np.ndarray, xs: np.ndarray, ys: np.ndarray, rising: bool, grid: np.ndarray,
                  pace: tuple[float, float], t0: float, sigma: float) -> tuple[float, float]:
    """The profile-likelihood interval of `hinge_span` on these positions, and `t0`."""
    rss = _hinge_rss(ts, xs, ys, rising, grid, pace)
    at0 = float(_hinge_rss(ts, xs, ys, rising, np.array([t0]), pace)[0])
    inside = grid[rss <= min(float(rss.min()), at0) + CONFIDENCE * sigma * sigma]
    if not len(inside):
        return t0, t0
    return min(float(inside.min()), t0), max(float(inside.max()), t0)


def _hinge_rss(ts: np.ndarray, xs: np.ndarray, ys: np.ndarray, rising: bool, grid: np.ndarray,
               pace: tuple[float, float]) -> np.ndarray:
    """The residual sum of squares of the best hinge (speed within `pace`) breaking at each grid point."""
    h = np.maximum(0.0, ts[None, :] - grid[:, None]) if rising else np.maximum(0.0, grid[:, None] - ts[None, :])
    n = len(ts)
    sh = h.sum(axis=1)
    shh = (h * h).sum(axis=1)
    det = n * shh - sh * sh
    ok = det > 1e-12
    safe = np.where(ok, det, 1.0)
    w = np.stack([np.where(ok, (n * (h @ z) - sh * z.sum()) / safe, 0.0) for z in (xs, ys)], axis=1)
    speed = np.hypot(w[:, 0], w[:, 1])
    want = np.clip(speed, pace[0], pace[1])
    w *= np.where(speed > 1e-9, want / np.where(speed > 1e-9, speed, 1.0), 0.0)[:, None]
    fix = speed <= 1e-9  # no direction to scale: walk along the line from the first to the last position
    if fix.any():
        d = np.array([xs[-1] - xs[0], ys[-1] - ys[0]]) * (1 if rising else -1)
        w[fix] = d / max(float(np.hypot(*d)), 1e-9) * pace[0]
    resid = np.zeros(len(grid))
    for k, z in enumerate((xs, ys)):
        c = (z.sum() - w[:, k] * sh) / n
        resid += ((z[None, :] - c[:, None] - w[:, k][:, None] * h) ** 2).sum(axis=1)
    return resid


def pace(model: DetectorModel) -> tuple[float, float]:
    """The walking paces (m/s) the hinges allow: the person's speed over their slack, to their speed (a
    little beyond both: a real walker speeds up and slows down)."""
    return 0.8 * model.speed / model.slack, 1.1 * model.speed


def _fit_rows(samples: Samples, since: float, span: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = samples[-1][0]
    rows = [s for s in samples if s[0] >= max(since, t - span)]
    return np.array([s[0] for s in rows]), np.array([s[1] for s in rows]), np.array([s[2] for s in rows])


_SPAN = 2.5  # s of positions a change-point fit reads: the walk near a place is about straight


def left_at(model: DetectorModel, samples: Samples, place: str, since: float) -> float:
    """When the person left `place` (a departure hinge on the positions since `since`)."""
    ts, xs, ys = _fit_rows(samples, since, _SPAN)
    t = samples[-1][0]
    lo = max(since, t - _SPAN)
    return min(max(hinge(ts, xs, ys, True, lo, t, pace(model)), since), t)


def arrived_at(model: DetectorModel, samples: Samples, since: float) -> float:
    """When the person stopped (an arrival hinge on the positions since `since`); later than the last
    position when they are still coming."""
    ts, xs, ys = _fit_rows(samples, since, _SPAN)
    t = samples[-1][0]
    lo = max(since, t - _SPAN)
    return max(hinge(ts, xs, ys, False, lo, t + 0.5, pace(model)), since)


def left_span(model: DetectorModel, samples: Samples, place: str, since: float, t0: float) -> tuple[float, float]:
    """Where the departure `left_at` estimated at `t0` (from the same positions) may truly be (`hinge_span`)."""
    del place
    ts, xs, ys = _fit_rows(samples, since, _SPAN)
    t = samples[-1][0]
    lo = max(since, t - _SPAN)
    a, b = hinge_span(ts, xs, ys, True, lo, t, pace(model), t0, model.params.sigma)
    return max(a, since), min(b, t)


def arrived_span(model: DetectorModel, samples: Samples, since: float, t0: float) -> tuple[float, float]:
    """Where the arrival `arrived_at` estimated at `t0` (from the same positions) may truly be (`hinge_span`)."""
    ts, xs, ys = _fit_rows(samples, since, _SPAN)
    t = samples[-1][0]
    lo = max(since, t - _SPAN)
    a, b = hinge_span(ts, xs, ys, False, lo, t + 0.5, pace(model), t0, model.params.sigma)
    return max(a, since), b
