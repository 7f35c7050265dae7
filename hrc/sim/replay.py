"""Replay a simulated run against a plan's STNU: which of its constraints did what happened break?

A dispatched schedule is checked against every constraint of its STNU (house style: tests replay, not
trust). The run's happenings give a time to every timepoint of the plan the run carried out (named as
`hrc.compile.temporal_net_creator` names them, ``AGENT.PHASE.ACTION.EVENT``, ``Z`` = 0); each
requirement link ``lb <= T(b) - T(a) <= ub`` (durations of the robot, waits, task graph, passing orders,
temporal constraints, the deadline) and each contingent link (the person's durations within their
bounds) is checked with a tolerance of one tick (1 ms, the core's unit). O(links).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from hrc.compile.compiler import CompiledPlan, CompiledPlanSet
from hrc.compile.temporal_net_creator import ORIGIN, TICKS_PER_SECOND, PlanNetwork, create_stnu
from hrc.sim.detector import Happening

__all__ = ["broken_constraints", "executed", "plan_network", "timepoint_times"]

_TOL = 1.0  # ticks


def plan_network(cps: CompiledPlanSet, cp: CompiledPlan) -> PlanNetwork:
    """The plan's STNU as compiled: its motions and the passing orders it carries. Made once per plan and
    process (every simulated run that kept to its first plan asks for it: 1-2 % of a run's time)."""
    key = (id(cps), id(cp))
    found = _NETWORKS.get(key)
    if found is not None and found[0] is cps and found[1] is cp:
        return found[2]
    seps = [(o.separation, f"passing order: {o.describe()}") for o in cp.pattern.orders if o.how != "implied"]
    net = create_stnu(cps.task, cp.plan, cp.motions, seps, cps.options.human_waits)
    if len(_NETWORKS) >= 256:
        _NETWORKS.clear()
    _NETWORKS[key] = (cps, cp, net)
    return net


_NETWORKS: dict[tuple[int, int], tuple[CompiledPlanSet, CompiledPlan, PlanNetwork]] = {}


def timepoint_times(happenings: Iterable[Happening]) -> dict[str, float]:
    """Seconds of every leg event, by STNU timepoint name (the first time it happened), with ``Z`` = 0."""
    out: dict[str, float] = {ORIGIN: 0.0}
    for h in happenings:
        if h.action is not None and h.phase is not None:
            out.setdefault(f"{h.agent}.{h.phase}.{h.action}.{h.event}", h.t)
    return out


def executed(cp: CompiledPlan, allocation: Mapping[str, str], sequences: Mapping[str, tuple[str, ...]]) -> bool:
    """True when the run carried out exactly `cp`'s allocation and sequences."""
    return (dict(cp.plan.allocation) == dict(allocation)
            and all(tuple(sequences.get(agent, ())) == seq for agent, seq in cp.plan.sequences))


def broken_constraints(net: PlanNetwork, times: Mapping[str, float]) -> list[str]:
    """Each link of `net` the `times` (s) break, in words (its meaning), or missing timepoints."""
    meaning = dict(net.meaning)
    ticks = {k: v * TICKS_PER_SECOND for k, v in times.items()}
    out: list[str] = []
    missing = [t for t in net.stnu.timepoints if t not in ticks]
    if missing:
        return [f"never happened: {', '.join(missing[:3])}" + (" ..." if len(missing) > 3 else "")]
    links = [(r.source, r.target, r.lb, r.ub) for r in net.stnu.requirements]
    links += [(c.source, c.target, c.lb, c.ub) for c in net.stnu.contingents]
    for a, b, lb, ub in links:
        d = ticks[b] - ticks[a]
        if (lb is not None and d < lb - _TOL) or (ub is not None and d > ub + _TOL):
            what = meaning.get((a, b), ("", f"{a} -> {b}"))[1]
            lo = "-inf" if lb is None else f"{lb / 1000:g}"
            hi = "inf" if ub is None else f"{ub / 1000:g}"
            bounds = f"[{lo}, {hi}]"
            out.append(f"{what}: {d / 1000:.3f} s not in {bounds}")
    return out
