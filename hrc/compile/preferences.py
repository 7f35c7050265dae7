"""A compiled plan's preference value (Wilcox, Nikolaidis & Shah 2012, APA), for ranking within a class.

The task's preferences (`hrc.model.Preference`: a function of ``T(target) - T(source)`` on its domain)
are read on the plan's STNU as APA reads a plan: contingent links as requirements (an STP), every
preferred interval a hard constraint, and `hrc.apa.plan.plan_preference_value` (Fig. 5: QP, tightening,
DO form) gives the optimal global value ``F``: how well the team can please the worker in this plan.
A plan whose STN cannot meet the task's limits is read without them (it finishes late anyway, and
still ranks among the inconsistent ones); a plan that cannot keep a preferred interval at all has no
value and ranks after those that can.
"""

from __future__ import annotations

from hrc.compile.temporal_net_creator import PlanNetwork, event_timepoint
from hrc.model import Plan, Task

__all__ = ["plan_preference"]


def plan_preference(task: Task, plan: Plan, net: PlanNetwork) -> float | None:
    """The plan's optimal global preference value, or None (no preferences, or none can be kept)."""
    if not task.preferences:
        return None
    from hrc.apa.plan import plan_preference_value  # the QP solver is imported only where it is used
    from hrc.temporal import check_consistency

    prefs = [(event_timepoint(plan, p.source), event_timepoint(plan, p.target), p) for p in task.preferences]
    stn = net.stnu if check_consistency(net.stnu).consistent else net.without_limits()
    result = plan_preference_value(stn, prefs)
    return result.value if result.consistent else None
