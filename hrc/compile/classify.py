"""Classify and measure one plan's STNU: DC > consistent > inconsistent (Strassmair & Taylor, V.B).

Besides the class, ranking needs the plan's makespan and idle times. Both come from the earliest
(ASAP) schedule of the plan's STN with the makespan deadline left out (a plan that breaks the
deadline still has a makespan; that is what ranks it among the inconsistent ones):

- ``makespan[0]``, the earliest achievable makespan: the human at their fastest where it helps;
- ``makespan[1]``, the worst case: every human duration (travel, manipulation) at its upper bound,
  the robot as early as it can.

Where the plan's other constraints conflict even so, the schedule falls back to the ASAP longest-path
schedule over the lower bounds alone.

Idle time of an agent, in the earliest schedule: the part of ``[0, makespan]`` in which it is neither
travelling nor manipulating (waiting for the co-worker, or done early).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from hrc.compile.temporal_net_creator import ORIGIN, TICKS_PER_SECOND, PlanNetwork
from hrc.model import Task
from hrc.temporal import STNU, RequirementLink, Verdict, check_dc
from hrc.temporal.stn import earliest_times

__all__ = ["Classification", "PlanClass", "classify", "explain"]


class PlanClass(enum.Enum):
    """The three classes of section V.B, best first."""

    DC = "DC"
    CONSISTENT = "consistent"
    INCONSISTENT = "inconsistent"

    @property
    def order(self) -> int:
        return list(PlanClass).index(self)


@dataclass(frozen=True, slots=True)
class Classification:
    plan_class: PlanClass
    explanation: str  # "" for DC plans
    makespan: tuple[float, float] | None  # s; None when even without the deadline no schedule exists
    idle: tuple[tuple[str, float], ...]  # (agent, s) in the earliest schedule
    schedule: tuple[tuple[str, float], ...]  # earliest time (s) of every timepoint, in STNU order


def _without_deadline(stnu: STNU, fix_contingents: bool, lower_bounds_only: bool = False) -> STNU:
    reqs = tuple(r for r in stnu.requirements if not (r.source == ORIGIN and r.ub is not None))
    if lower_bounds_only:  # an ASAP longest-path schedule, for plans whose other constraints conflict
        reqs = tuple(RequirementLink(r.source, r.target, r.lb, None) for r in reqs if r.lb is not None)
    conts = stnu.contingents
    if fix_contingents:
        reqs += tuple(RequirementLink(c.source, c.target, c.ub, c.ub) for c in conts)
        conts = ()
    return STNU(stnu.timepoints, reqs, conts, stnu.name)


def explain(net: PlanNetwork, cycle: tuple, inconsistent: bool) -> str:
    """Say in words what a negative cycle (from the DC or consistency check) runs through.

    Not DC: which human durations, at their worst, break which deadline or
    constraint. `inconsistent`: which limits cannot be met even with every duration at its shortest.
    """
    meaning = dict(net.meaning)
    position = {t: i for i, t in enumerate(net.stnu.timepoints)}
    seen: dict[str, set[tuple[int, str]]] = {"human": set(), "robot": set(), "limit": set(), "order": set()}
    for edge in cycle:
        key = (edge.source, edge.target) if (edge.source, edge.target) in meaning else (edge.target, edge.source)
        if key in meaning:
            kind, text = meaning[key]
            seen[kind].add((min(position[key[0]], position[key[1]]), text))
    # in timeline order (STNU order), whatever node the checker's cycle happened to start from
    found = {kind: list(dict.fromkeys(text for _, text in sorted(items))) for kind, items in seen.items()}
    limits = "; ".join(found["limit"]) or "the plan's ordering"
    if not inconsistent:
        durations = "; ".join(found["human"]) or "the human's durations"
        return f"{limits} cannot be guaranteed by the robot alone if the human takes long on: {durations}"
    durations = "; ".join(found["human"] + found["robot"]) or "the plan's durations"
    return f"{limits} cannot be met even at the shortest: {durations}"


def classify(task: Task, net: PlanNetwork) -> Classification:
    """Class (DC check), explanation, makespan bounds, idle times and the earliest schedule."""
    result = check_dc(net.stnu)
    if result.verdict is Verdict.DC:
        plan_class, explanation = PlanClass.DC, ""
    elif result.verdict is Verdict.NOT_DC:
        plan_class = PlanClass.CONSISTENT
        explanation = explain(net, result.cycle, inconsistent=False)
    else:
        plan_class = PlanClass.INCONSISTENT
        explanation = explain(net, result.cycle, inconsistent=True)

    early = earliest_times(_without_deadline(net.stnu, fix_contingents=False), ORIGIN)
    if early is None:
        early = earliest_times(_without_deadline(net.stnu, fix_contingents=False, lower_bounds_only=True), ORIGIN)
    late = earliest_times(_without_deadline(net.stnu, fix_contingents=True), ORIGIN)
    if late is None:
        late = earliest_times(_without_deadline(net.stnu, fix_contingents=True, lower_bounds_only=True), ORIGIN)
    makespan = None
    idle: tuple[tuple[str, float], ...] = ()
    schedule: tuple[tuple[str, float], ...] = ()
    if early is not None:
        end = max((early[t] for t in net.last_ends), default=0)
        worst = max((late[t] for t in net.last_ends), default=0) if late is not None else end
        makespan = (end / TICKS_PER_SECOND, worst / TICKS_PER_SECOND)
        schedule = tuple((t, early[t] / TICKS_PER_SECOND) for t in net.stnu.timepoints)
        idle = tuple((agent.id, _idle(early, agent.id, end) / TICKS_PER_SECOND) for agent in task.agents)
    return Classification(plan_class, explanation, makespan, idle, schedule)


def _idle(times: dict[str, int], agent: str, makespan: int) -> int:
    busy = 0
    for name, t in times.items():
        if not name.startswith(agent + "."):
            continue
        base, what = name.rsplit(".", 1)
        if what == "arrive":
            busy += t - times[base + ".depart"]
        elif what == "end":
            busy += t - times[base + ".start"]
    return makespan - busy
