"""Set ranking (Strassmair & Taylor 2014, section V.B): each remaining plan re-checked with what was seen.

A plan's state is its STNU with every executed timepoint pinned at its time, contingent links in
progress shortened by what they have already lasted (past their upper bound: an overrun, "any moment
now", not an error) and everything else at ``now`` or later: the residual network of
`hrc.temporal.execution.residual_network`. Its class is the residual's DC check (DC, else consistent,
else inconsistent); its *remaining makespan* is the end of the residual's earliest schedule with the
durations nature has not yet revealed read as the compile read them (``rank_by``: "worst" at their upper
bound, "earliest" at their lower bound, "nominal" at the midpoint), falling back to lower bounds only when
no schedule keeps every bound (a plan that broke a deadline still has a finish time: finishing beats
refusing); its *idle time* is the time both agents stand still in that schedule.

Plans rank by class (DC, consistent, inconsistent), then remaining makespan, then idle time, then APA
preference value (higher first; the compile's value, `hrc.compile.preferences`), then plan id.

A plan for which the compile found no motion pattern at all (`PlanEntry.blocked`: the two would block
each other whatever the passing orders) is inconsistent whatever its STNU's check says, since that STNU
carries none of its conflicts, and comes after every other inconsistent plan: kept, so that the robot
can still finish when nothing else is left, but never promised (found by `hrc simulate` on kitting,
whose dispatcher used to start every run on such a plan, re-checked as DC).

What an observation can change. Only the plans still in the set are looked at, and their number falls
fast as the human's choices come in. A plan is re-checked only when something that enters its residual
network changed: the executed timepoints of *that* plan, or ``now`` for a plan with something still to
do (`evaluation_key`); a tick when every remaining timepoint of a plan is already pinned changes nothing.
Cost per re-check: one residual network, one DC check (the RUL2021 verdict, in C where built) and one
earliest-schedule search; see scripts/bench_dispatch.py.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from hrc.temporal import STNU, ContingentLink, RequirementLink, Verdict, check_dc, earliest_times, residual_network

from .plan_set import PlanEntry

__all__ = ["CLASS_NAMES", "Evaluation", "evaluate", "rank_key", "reference_evaluate", "schedule"]

CLASS_NAMES = {Verdict.DC: "DC", Verdict.NOT_DC: "consistent", Verdict.INCONSISTENT: "inconsistent"}
_CLASS_ORDER = {"DC": 0, "consistent": 1, "inconsistent": 2}


@dataclass(frozen=True, slots=True)
class Evaluation:
    """One plan's standing in one state: class name, finish (ticks from the task's start; None: no
    schedule even on lower bounds) and idle ticks of both agents."""

    plan_class: str
    finish: int | None
    idle: int


def _fixed(c: ContingentLink, rank_by: str) -> int:
    if rank_by == "earliest":
        return c.lb
    if rank_by == "nominal":
        return (c.lb + c.ub) // 2
    return c.ub


def schedule(residual: STNU, rank_by: str) -> dict[str, int] | None:
    """The residual's earliest schedule (ticks after its origin) with each contingent duration fixed as
    `rank_by` reads it; when no schedule keeps every bound, the earliest one on the lower bounds of what has
not happened yet (pins kept); None if even that fails."""
    origin = residual.timepoints[0]
    fixed = tuple(RequirementLink(c.source, c.target, d, d)
                  for c in residual.contingents for d in (_fixed(c, rank_by),))
    full = STNU(residual.timepoints, residual.requirements + fixed, ())
    times = earliest_times(full, origin)
    if times is not None:
        return times
    pinned = {r.target for r in residual.requirements if r.source == origin and r.lb == r.ub}
    # what is left (as `ExecutionMode.EARLIEST` reads it): pins, and the orderings and lower bounds (distance
    # edges of weight <= 0, whichever way the link was written) that still bind what has not happened yet
    lower: list[RequirementLink] = []
    for r in residual.requirements:
        if r.source == origin:
            lower.append(r)
            continue
        if r.ub is not None and r.ub <= 0 and r.source not in pinned:  # T(target) <= T(source) + ub
            lower.append(RequirementLink(r.source, r.target, None, r.ub))
        if r.lb is not None and r.lb >= 0 and r.target not in pinned:  # T(target) >= T(source) + lb
            lower.append(RequirementLink(r.source, r.target, r.lb, None))
    lower += [RequirementLink(c.source, c.target, _fixed(c, rank_by), None) for c in residual.contingents]
    return earliest_times(STNU(residual.timepoints, tuple(lower), ()), origin)


def _idle(entry: PlanEntry, times: Mapping[str, int]) -> int:
    """Ticks each agent stands still between the task's start and its last end, summed over agents."""
    total = 0
    for agent, legs in entry.legs.items():
        if not legs:
            continue
        busy = 0
        last = 0
        for action, phase in legs:
            points = dict(entry.leg_points[(agent, action, phase)])
            busy += times[points["arrive"]] - times[points["depart"]]
            if "park" in points:  # the wait at a waiting place is standing still
                busy -= times[points["unpark"]] - times[points["park"]]
            busy += times[points["end"]] - times[points["start"]]
            last = times[points["end"]]
        total += max(0, last - busy)
    return total


def evaluate(entry: PlanEntry, executed: Mapping[str, int], now: int, rank_by: str = "worst") -> Evaluation:
    """The plan's class, finish and idle time with `executed` seen by tick `now` (module docstring),
    on the plan's index arrays (`hrc.dispatch.fastnet.PlanNet`); the same as `reference_evaluate`."""
    net = entry.net
    ex: list[int | None] = [None] * net.n
    for name, t in executed.items():
        ex[net.index[name]] = t
    plan_class = "inconsistent" if entry.blocked else net.verdict(ex, now)
    if plan_class is None:  # no C core: the residual network's DC check
        plan_class = CLASS_NAMES[check_dc(residual_network(entry.stnu, executed, now)).verdict]
    times = net.schedule(ex, now, rank_by)
    if times is None:
        return Evaluation(plan_class, None, 0)
    return Evaluation(plan_class, max(times), net.idle(times))


def reference_evaluate(entry: PlanEntry, executed: Mapping[str, int], now: int,
                       rank_by: str = "worst") -> Evaluation:
    """`evaluate` from the residual network (`residual_network`, `check_dc`, `schedule`): slower, and
    the definition the fast path is tested against."""
    residual = residual_network(entry.stnu, executed, now)
    plan_class = "inconsistent" if entry.blocked else CLASS_NAMES[check_dc(residual).verdict]
    found = schedule(residual, rank_by)
    if found is None:
        return Evaluation(plan_class, None, 0)
    origin = residual.timepoints[0]
    times = {v: t - found[origin] for v, t in found.items() if v != origin}
    return Evaluation(plan_class, max(times.values()), _idle(entry, times))


def rank_key(entry: PlanEntry, ev: Evaluation) -> tuple:
    """Class, blocked last (see the module docstring), remaining makespan, idle time, preference (higher
    first), plan id."""
    finish = ev.finish if ev.finish is not None else float("inf")
    pref = -entry.preference if entry.preference is not None else float("inf")
    return (_CLASS_ORDER[ev.plan_class], entry.blocked, finish, ev.idle, pref, entry.id)
