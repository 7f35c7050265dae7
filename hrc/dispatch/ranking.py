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

Plans rank by class (DC, consistent, inconsistent), then, among DC plans, those that keep the person's
part of the plan being followed first (`hrc.dispatch.dispatcher`: a switch never rests on a choice the
person has not made while the plan they follow is DC), then remaining makespan, then idle time, then APA
preference value (higher first; the compile's value, `hrc.compile.preferences`), then plan id.

A plan for which the compile found no motion pattern at all (`PlanEntry.blocked`: the two would block
each other whatever the passing orders) is inconsistent whatever its STNU's check says, since that STNU
carries none of its conflicts, and comes after every other inconsistent plan: kept, so that the robot
can still finish when nothing else is left, but never promised (found by `hrc simulate` on kitting,
whose dispatcher used to start every run on such a plan, re-checked as DC).

What an observation can change. Only the plans still in the set are looked at (set validation drops the
rest by index, `hrc.dispatch.validation.agreeing`), and their number falls fast as the human's choices
come in. Plans whose networks are the same arrays (the compile's `shape`: plans that differ only by which
of two identical actions comes where) have the same residual network under any history they both agree
with (an observed leg is at the same position in both), so each shape among the candidates is evaluated
once (`Ranker.evaluate`). An evaluation is one residual network, its class and one or two longest-path
searches, in the C core over the dispatch form's arrays (`hrc.dispatch.native`, many plans per call: a
residual that is strongly controllable is DC, one whose STN has no schedule is inconsistent, each found by
a longest-path pass, and only the rest take the RUL check; docs/dispatch.md, "Speed"),
else in Python (`hrc.dispatch.fastnet`): the same results as `reference_evaluate`, the definition on the
residual network, which the tests compare on every message of many runs. The best plan is found by
successive minima over the rank key's columns, the full ranking only when asked for (`Ranker.order`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from hrc.temporal import STNU, ContingentLink, RequirementLink, Verdict, check_dc, earliest_times, residual_network

from . import native
from .fastnet import PlanNet
from .plan_set import PlanEntry, PlanSet

__all__ = ["CLASS_NAMES", "CLASS_ORDER", "NO_FINISH", "Evaluation", "Ranker", "rank_key", "reference_evaluate",
           "schedule"]

CLASS_NAMES = {Verdict.DC: "DC", Verdict.NOT_DC: "consistent", Verdict.INCONSISTENT: "inconsistent"}
CLASS_ORDER = ("DC", "consistent", "inconsistent")
"""Class names by their code in the arrays (0 best)."""
_CLASS_ORDER = {c: i for i, c in enumerate(CLASS_ORDER)}
NO_FINISH = native.NO_FINISH
"""The finish of a plan with no schedule at all, in the arrays (ranks after every finish)."""
_TWINS_KEPT = (512, 1024)
"""`Ranker._twins` keeps candidate lists of up to this many plans, this many lists (a few MB at most)."""
_NO_FINISH_LAST = np.iinfo(np.int64).max  # a plan without a schedule ranks last by finish (`_columns`)


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
            if "end" in points:  # a joint phase another agent leads: its part ends with its arrival there
                busy += times[points["end"]] - times[points["start"]]
            last = times[points.get("end", points["arrive"])]
        total += max(0, last - busy)
    return total


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


class Ranker:
    """Set ranking over one plan set (see the module docstring): `evaluate` many candidates under one
    state, `best` and `order` them by the rank key. Read-only after it is made; forks of a dispatcher
    share one."""

    def __init__(self, plan_set: PlanSet, threads: int | None = None) -> None:
        self.plan_set = plan_set
        self.threads = native.default_threads() if threads is None else max(1, threads)
        form = plan_set.form
        self.native = native.NativeForm(form) if native.available() else None
        self._nets: dict[int, PlanNet] = {}  # the Python path's, made as needed
        self._reps: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}  # candidates -> one plan per shape (`_twins`)
        rows = form.plans
        self.shape = np.ascontiguousarray(rows["shape"], dtype=np.int64)
        self.blocked = np.ascontiguousarray(rows["blocked"], dtype=np.int8)
        pref = np.asarray(rows["preference"], dtype=np.float64)
        self.pref_key = np.where(np.isnan(pref), np.inf, -pref)  # higher preference first; none last
        ids = rows["id"]
        self.id_rank = np.empty(len(ids), dtype=np.int64)  # plans ordered by id (the last tie-break)
        self.id_rank[np.argsort(ids, kind="stable")] = np.arange(len(ids))

    def evaluate(self, plans: np.ndarray, seen: np.ndarray, legs_seen: np.ndarray,
                 now: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(cls, finish, idle)`` of each of `plans` (indices) under the state (`seen`, `legs_seen`: what
        `hrc.dispatch.validation.seen_arrays` makes of the history; `now` in ticks): class codes
        (`CLASS_ORDER`), finish ticks (`NO_FINISH`: no schedule at all), idle ticks. The plans must agree
        with the history (set validation): twins by shape are evaluated once."""
        plans = np.asarray(plans, dtype=np.int64)
        if not len(plans):
            empty = np.zeros(0, dtype=np.int64)
            return empty.astype(np.int8), empty, empty
        reps, back = self._twins(plans)
        if self.native is not None:
            cls, finish, idle = self.native.evaluate(reps, seen, legs_seen, now, self.plan_set.rank_by,
                                                     threads=self.threads)
            for k in np.flatnonzero(cls < 0):  # the core ran out of memory: this plan in Python
                cls[k], finish[k], idle[k] = self._python(int(reps[k]), seen, legs_seen, now)
        else:
            found = [self._python(int(p), seen, legs_seen, now) for p in reps.tolist()]
            cls = np.array([f[0] for f in found], dtype=np.int8)
            finish = np.array([f[1] for f in found], dtype=np.int64)
            idle = np.array([f[2] for f in found], dtype=np.int64)
        return cls[back], finish[back], idle[back]

    def _twins(self, plans: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One plan of each shape among `plans` (the first) and, per plan, its shape's position among them;
        kept by the plans' bytes (a run's candidates change only when set validation drops some: most
        messages evaluate the same candidates again, and a simulator's forks share them)."""
        key = plans.tobytes() if len(plans) <= _TWINS_KEPT[0] else None
        found = None if key is None else self._reps.get(key)
        if found is None:
            _, first, back = np.unique(self.shape[plans], return_index=True, return_inverse=True)
            found = (plans[first], back)
            if key is not None:
                if len(self._reps) >= _TWINS_KEPT[1]:
                    self._reps.clear()
                self._reps[key] = found
        return found

    def _net(self, p: int) -> PlanNet:
        net = self._nets.get(p)
        if net is None:
            if len(self._nets) > 4096:
                self._nets.clear()
            net = self._nets[p] = PlanNet(self.plan_set.form.arrays(p))
        return net

    def _python(self, p: int, seen: np.ndarray, legs_seen: np.ndarray, now: int) -> tuple[int, int, int]:
        """Plan `p`'s evaluation in Python (`hrc.dispatch.fastnet`); the verdict from the C verdict alone,
        else from `check_dc` on its residual network."""
        net = self._net(p)
        ex = net.executed(seen, legs_seen)

        def check() -> str:
            names = self.plan_set.form.timepoint_names(p)
            done = {names[x]: t for x, t in enumerate(ex) if t is not None}
            return CLASS_NAMES[check_dc(residual_network(self.plan_set.entry(p).stnu, done, now)).verdict]

        cls = "inconsistent" if self.blocked[p] else net.verdict(ex, now, check)
        times = net.schedule(ex, now, self.plan_set.rank_by)
        if times is None:
            return _CLASS_ORDER[cls], int(NO_FINISH), 0
        return _CLASS_ORDER[cls], max(times), net.idle(times)

    def schedule(self, p: int, seen: np.ndarray, legs_seen: np.ndarray, now: int) -> list[int] | None:
        """Plan `p`'s earliest schedule under the state (ticks per timepoint, in the form's numbering), as
        its evaluation computes it; None when it has none."""
        if self.native is not None:
            times = np.zeros(int(self.plan_set.form.plans["n"][p]), dtype=np.int64)
            cls, finish, _ = self.native.evaluate(np.array([p]), seen, legs_seen, now, self.plan_set.rank_by, times)
            if cls[0] >= 0:
                return None if finish[0] == NO_FINISH else times.tolist()
        net = self._net(p)
        return net.schedule(net.executed(seen, legs_seen), now, self.plan_set.rank_by)

    def _columns(self, plans: np.ndarray, cls: np.ndarray, finish: np.ndarray,
                 idle: np.ndarray, lead: np.ndarray | None = None) -> list[np.ndarray]:
        """The rank key's columns (`rank_key`), most significant first; `lead` (after the class): 1 for a
        plan that gives up the person's part of the plan being followed (`hrc.dispatch.dispatcher`)."""
        fin = np.where(finish == NO_FINISH, _NO_FINISH_LAST, finish)
        head = [cls.astype(np.int64)] + ([] if lead is None else [lead.astype(np.int64)])
        return [*head, self.blocked[plans], fin, idle, self.pref_key[plans], self.id_rank[plans]]

    def best(self, plans: np.ndarray, cls: np.ndarray, finish: np.ndarray, idle: np.ndarray,
             lead: np.ndarray | None = None) -> int:
        """The position in `plans` of the best plan by `rank_key` (-1 if `plans` is empty): successive
        minima over the key's columns, O(len(plans))."""
        if len(plans) <= 1:
            return len(plans) - 1
        if len(plans) <= 64:  # a few plans: one stable sort by the whole key (the same first one) costs less
            return int(np.lexsort(self._columns(plans, cls, finish, idle, lead)[::-1])[0])
        at = np.arange(len(plans))
        for column in self._columns(plans, cls, finish, idle, lead):
            values = column[at]
            at = at[values == values.min()]
            if len(at) == 1:
                break
        return int(at[0])

    def order(self, plans: np.ndarray, cls: np.ndarray, finish: np.ndarray, idle: np.ndarray,
              lead: np.ndarray | None = None) -> np.ndarray:
        """Positions in `plans`, best first by `rank_key`."""
        return np.lexsort(list(reversed(self._columns(plans, cls, finish, idle, lead))))
