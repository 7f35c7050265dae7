"""The STPP: a simple temporal problem with preferences (Wilcox, Nikolaidis & Shah 2012, section IV).

An STPP has *events*, binary *interval constraints* ``lb <= T(target) - T(source) <= ub`` and, on some
of those intervals, a *preference function* of ``d = T(target) - T(source)``. The global preference
value of a schedule is ``F = sum of f(d)`` over the preferred intervals (the paper's objective for
manufacturing, section III.B: fairness is no concern, so values add up).

Preference functions are the paper's three shapes, ``f(d) = c0 + c1*d + c2*d**2``: constant, linear and
quadratic; a quadratic one must be concave (``c2 <= 0``, so that maximising ``F`` is a convex QP), and
every preference must sit on a finite interval. The paper permits only "positive-valued" preferences
(its own worked example is 0 at both ends of its intervals): the STPP file format holds files to
that (`hrc.apa.io`: non-negative on the interval), but the algorithm does not need it, so the model
does not, and preferences from task files (the workshop's is negative on most of its domain) work.

Values are in seconds here (floats); `hrc.apa.compile` turns them into the temporal core's integer
ticks in one place. Misuse raises `hrc.errors.ApaError`; `hrc.apa.io` reports bad files with their path.

>>> f = PreferenceFunction.quadratic(-50, 15, -1)     # the worked example's f_AD, peak at d = 7.5
>>> f.value(7.5), f.peak()
(6.25, 7.5)
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from hrc.errors import ApaError
from hrc.model import PreferenceKind

__all__ = ["Constraint", "PreferenceFunction", "STPP"]

_COEFFS = {PreferenceKind.CONSTANT: 1, PreferenceKind.LINEAR: 2, PreferenceKind.QUADRATIC: 3}


@dataclass(frozen=True, slots=True)
class PreferenceFunction:
    """``f(d) = c0 + c1*d + c2*d**2`` (higher is better); `coefficients` has 1, 2 or 3 entries by `kind`."""

    kind: PreferenceKind
    coefficients: tuple[float, ...]

    def __post_init__(self) -> None:
        want = _COEFFS[self.kind]
        if len(self.coefficients) != want:
            raise ApaError(f"a {self.kind.value} preference takes {want} coefficient(s), "
                           f"found {len(self.coefficients)}")
        if not all(math.isfinite(c) for c in self.coefficients):
            raise ApaError(f"preference coefficients must be finite, found {list(self.coefficients)}")
        if self.kind is PreferenceKind.QUADRATIC and self.coefficients[2] > 0:
            raise ApaError(f"a quadratic preference must be concave (c2 <= 0), found c2 = {self.coefficients[2]:g}")

    @classmethod
    def constant(cls, c0: float) -> PreferenceFunction:
        return cls(PreferenceKind.CONSTANT, (float(c0),))

    @classmethod
    def linear(cls, c0: float, c1: float) -> PreferenceFunction:
        return cls(PreferenceKind.LINEAR, (float(c0), float(c1)))

    @classmethod
    def quadratic(cls, c0: float, c1: float, c2: float) -> PreferenceFunction:
        return cls(PreferenceKind.QUADRATIC, (float(c0), float(c1), float(c2)))

    @property
    def c(self) -> tuple[float, float, float]:
        """``(c0, c1, c2)`` padded with zeros."""
        padded = (*self.coefficients, 0.0, 0.0)
        return (padded[0], padded[1], padded[2])

    def value(self, d: float) -> float:
        c0, c1, c2 = self.c
        return c0 + c1 * d + c2 * d * d

    def slope(self, d: float) -> float:
        """``f'(d)``."""
        _, c1, c2 = self.c
        return c1 + 2 * c2 * d

    def peak(self) -> float | None:
        """Where an unconstrained maximum lies (``-c1 / 2 c2``), or None when `f` has none."""
        _, c1, c2 = self.c
        return -c1 / (2 * c2) if c2 < 0 else None

    def min_on(self, lb: float, ub: float) -> float:
        """The least value on ``[lb, ub]``: at an end, since `f` is concave or linear."""
        return min(self.value(lb), self.value(ub))

    def max_slope_on(self, lb: float, ub: float) -> float:
        """``max |f'|`` on ``[lb, ub]`` (at an end: `f'` is affine)."""
        return max(abs(self.slope(lb)), abs(self.slope(ub)))


@dataclass(frozen=True, slots=True)
class Constraint:
    """``lb <= T(target) - T(source) <= ub`` (s; ``-inf`` / ``inf`` for an open side), optionally with a
    preference on ``d = T(target) - T(source)``."""

    source: str
    target: str
    lb: float
    ub: float
    preference: PreferenceFunction | None = None

    def __post_init__(self) -> None:
        where = f"constraint {self.source} -> {self.target}"
        if math.isnan(self.lb) or math.isnan(self.ub) or self.lb == math.inf or self.ub == -math.inf:
            raise ApaError(f"{where}: bounds must be numbers, lb < inf, ub > -inf; found [{self.lb}, {self.ub}]")
        if self.lb > self.ub:
            raise ApaError(f"{where}: lb {self.lb:g} > ub {self.ub:g}")
        if self.source == self.target:
            raise ApaError(f"{where}: an event constrained against itself")
        if self.preference is not None:
            if not (math.isfinite(self.lb) and math.isfinite(self.ub)):
                raise ApaError(f"{where}: a preference needs a finite interval, found [{self.lb:g}, {self.ub:g}]")


@dataclass(frozen=True, slots=True)
class STPP:
    """Events (their order fixes every output's order; the first is the *reference*, at time 0) and
    constraints between them. Validated on construction (raises `ApaError`)."""

    events: tuple[str, ...]
    constraints: tuple[Constraint, ...]
    name: str = ""
    _index: dict[str, int] = field(default_factory=dict, init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "events", tuple(self.events))
        object.__setattr__(self, "constraints", tuple(self.constraints))
        if not self.events:
            raise ApaError("an STPP needs at least one event")
        index: dict[str, int] = {}
        for e in self.events:
            if not isinstance(e, str) or not e:
                raise ApaError(f"event names are non-empty strings, found {e!r}")
            if e in index:
                raise ApaError(f"event {e!r} is listed twice")
            index[e] = len(index)
        for c in self.constraints:
            for end in (c.source, c.target):
                if end not in index:
                    raise ApaError(f"constraint {c.source} -> {c.target} names unknown event {end!r}")
        self._index.update(index)

    def index(self, event: str) -> int:
        try:
            return self._index[event]
        except KeyError:
            raise ApaError(f"unknown event {event!r}") from None

    @property
    def reference(self) -> str:
        """The event at time 0 (the first listed)."""
        return self.events[0]

    @property
    def preferred(self) -> tuple[Constraint, ...]:
        """The constraints that carry a preference (the paper's *given_prefs*, Fig. 5 line 4)."""
        return tuple(c for c in self.constraints if c.preference is not None)

    def value(self, times: Mapping[str, float]) -> float:
        """``F``: the global preference value of a schedule (event -> seconds)."""
        return sum(c.preference.value(times[c.target] - times[c.source])
                   for c in self.constraints if c.preference is not None)

    def violation(self, times: Mapping[str, float]) -> float:
        """The largest amount (s) by which `times` breaks a constraint; ``<= 0`` when it meets all."""
        worst = -math.inf
        for c in self.constraints:
            d = times[c.target] - times[c.source]
            worst = max(worst, c.lb - d, d - c.ub)
        return worst if self.constraints else 0.0

    def without_preferences(self) -> STPP:
        """The hard constraints alone (the STP the shadow dispatcher keeps)."""
        return STPP(self.events, tuple(Constraint(c.source, c.target, c.lb, c.ub) for c in self.constraints),
                    self.name)

    def with_preferences(self, preferences: Iterable[Constraint]) -> STPP:
        """The hard constraints of this STPP plus `preferences` (preferred intervals): how a worker
        type's preference set is put on a plan (`hrc.apa.workers`)."""
        return STPP(self.events, (*self.without_preferences().constraints, *preferences), self.name)


    def with_commitments(self, executed: Mapping[str, float], now: float | None = None) -> STPP:
        """Fig. 8 line 7: past intervals replaced by rigid links. Every executed event (event ->
        seconds) is tied rigidly to the first one executed, and, with `now`, every other event comes no
        earlier than `now`. Constraints between executed events are kept (they hold already)."""
        if not executed:
            return self
        first = min(executed, key=lambda e: (executed[e], self.index(e)))
        t0 = executed[first]
        extra = [Constraint(first, e, t - t0, t - t0) for e, t in executed.items() if e != first]
        if now is not None:
            extra += [Constraint(first, e, now - t0, math.inf) for e in self.events if e not in executed]
        return STPP(self.events, (*self.constraints, *extra), self.name)
