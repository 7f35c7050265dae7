"""Worker types (Wilcox, Nikolaidis & Shah 2012, section VI): which of several named preference sets
explains a person's observed timing better.

"APA tracks the two different sets of preference functions and switches to the set that achieves the
maximum possible global preference value." Given the plan's hard constraints, the events observed so
far (rigid, as Fig. 8 line 7 makes them) and the current time, each set's value is the optimum of its
STPP under those commitments (`compile_stpp`); a set that the observations make infeasible (its
preferred intervals are hard, as every preference sits on an interval) scores nothing. The best set
wins; the current one is kept on a tie (within `TIE` relative), so a dispatcher does not flap.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from hrc.apa.compile import TICKS_PER_SECOND, compile_stpp
from hrc.apa.model import STPP, Constraint
from hrc.errors import ApaError

__all__ = ["TIE", "best_worker_type", "worker_type_values"]

TIE = 1e-9
"""Relative difference below which two sets' values count as equal."""


def worker_type_values(hard: STPP, preference_sets: Mapping[str, Sequence[Constraint]],
                       observed: Mapping[str, float], now: float | None = None, *, solver: str = "piqp",
                       ticks_per_second: int = TICKS_PER_SECOND) -> dict[str, float | None]:
    """``{set name: the largest global preference value achievable given the observations}``, None
    where the observations leave that set no schedule. `observed` maps events to seconds."""
    out: dict[str, float | None] = {}
    for name in sorted(preference_sets):
        stpp = hard.with_preferences(preference_sets[name]).with_commitments(observed, now)
        result = compile_stpp(stpp, solver=solver, ticks_per_second=ticks_per_second)
        out[name] = result.value if result.consistent else None
    return out


def best_worker_type(hard: STPP, preference_sets: Mapping[str, Sequence[Constraint]],
                     observed: Mapping[str, float], now: float | None = None, *, current: str | None = None,
                     solver: str = "piqp", ticks_per_second: int = TICKS_PER_SECOND) -> str:
    """The set achieving the larger value (`worker_type_values`); `current` on a tie; the first name
    in sorted order otherwise. Raises `ApaError` if no set admits a schedule."""
    values = worker_type_values(hard, preference_sets, observed, now, solver=solver,
                                ticks_per_second=ticks_per_second)
    scored = {k: v for k, v in values.items() if v is not None}
    if not scored:
        raise ApaError("no worker type's preferences admit a schedule given the observations")
    top = max(scored.values())
    if current in scored and scored[current] >= top - TIE * max(1.0, abs(top)):
        return current
    return min(k for k, v in scored.items() if v == top)
