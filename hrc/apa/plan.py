"""APA on `hrc`'s own objects: a plan's STNU read as an STP, and a task read as an STPP.

* `plan_preference_value` is the entry point for the compiler and dispatcher (issue 11, item 5): the
  optimal global preference value of a compiled plan, one optimal schedule and its DO form. The STNU
  is read the way APA reads a plan: contingent links as requirements (an STP), timepoints as named in
  the STNU (the plan's origin first, so the DO windows are times from the task's start). A preference's
  `domain` is its interval, a hard constraint as every preferred interval is in the paper; a plan
  that cannot meet it is a result with ``consistent=False``.
* `task_stpp` builds the STPP of a task whose every action has one agent (so the allocation is given;
  the spar assembly is such a task), with one event per phase start and end after an origin event
  ``start``. Travel between locations is left out: this is the STPP of the task's own timing, which
  the worker-type demo needs; a plan with motions goes through `plan_preference_value` instead.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from hrc.apa.compile import CompileResult, compile_stpp
from hrc.apa.model import STPP, Constraint, PreferenceFunction
from hrc.errors import ApaError
from hrc.model import Event, Preference, Task
from hrc.temporal.network import STNU

__all__ = ["ORIGIN", "plan_preference_value", "preference_constraint", "task_stpp"]

ORIGIN = "start"
"""The origin event of `task_stpp` (time 0)."""


def preference_constraint(source: str, target: str, preference: Preference) -> Constraint:
    """A task `Preference` as a preferred interval constraint between the named events."""
    return Constraint(source, target, preference.domain.lb, preference.domain.ub,
                      PreferenceFunction(preference.kind, tuple(preference.coefficients)))


def plan_preference_value(stn: STNU, preferences: Sequence[tuple[str, str, Preference]], *,
                          ticks_per_second: int = 1000, solver: str = "piqp") -> CompileResult:
    """APA (Fig. 5) on `stn` read as an STP, with `preferences` as ``(source timepoint, target
    timepoint, Preference)``; `ticks_per_second` is the STNU's own (the plans' is 1000), so the
    conversion to seconds and back is exact. Raises `ApaError` for an unknown timepoint.

    The result's ``value`` is the plan's optimal preference value; ``times`` one optimal schedule;
    ``windows`` / ``do_network`` its DO form (``hrc.apa.compile.do_apsp`` / ``do_form`` for the rest).
    """
    tps = ticks_per_second
    bounds = [(r.source, r.target, r.lb, r.ub) for r in stn.requirements]
    bounds += [(c.source, c.target, c.lb, c.ub) for c in stn.contingents]
    constraints = [Constraint(a, b, -math.inf if lb is None else lb / tps, math.inf if ub is None else ub / tps)
                   for a, b, lb, ub in bounds]
    constraints += [preference_constraint(a, b, p) for a, b, p in preferences]
    return compile_stpp(STPP(stn.timepoints, tuple(constraints), stn.name), solver=solver, ticks_per_second=tps)


def task_stpp(task: Task, preference_set: str | None = None) -> STPP:
    """The STPP of `task` (see the module docstring) with its shared preferences and, if named, one
    of its `preference_sets`. Raises `ApaError` for an action more than one agent may do, or an
    unknown set."""
    events = [ORIGIN]
    cons: list[Constraint] = []
    for action in task.actions:
        if len(action.agents) != 1:
            raise ApaError(f"action {action.id!r} may be done by {', '.join(action.agents)}: task_stpp needs "
                           f"one agent per action (use plan_preference_value on a plan's STNU)")
        agent = action.agents[0]
        for k, phase in enumerate(action.phases):
            start, end = (str(Event(action.id, phase.id, b)) for b in ("start", "end"))
            events += [start, end]
            dur = phase.duration(agent)
            cons.append(Constraint(ORIGIN, start, 0.0, math.inf))
            cons.append(Constraint(start, end, dur.lb, dur.ub))
            if task.deadline is not None:
                cons.append(Constraint(ORIGIN, end, 0.0, task.deadline))
            if k:
                cons.append(Constraint(str(Event(action.id, action.phases[k - 1].id, "end")), start, 0.0, math.inf))
    for pr in task.precedence:
        cons.append(Constraint(str(Event(pr.before.action, pr.before.phase, "end")),
                               str(Event(pr.after.action, pr.after.phase, "start")), 0.0, math.inf))
    for c in task.constraints:
        cons.append(Constraint(str(c.source), str(c.target), c.bounds.lb, c.bounds.ub))
    prefs = list(task.preferences)
    if preference_set is not None:
        try:
            prefs += task.preference_set(preference_set)
        except KeyError:
            known = ", ".join(n for n, _ in task.preference_sets) or "none"
            raise ApaError(f"task {task.name!r} has no preference set {preference_set!r} (it has: {known})") from None
    cons += [preference_constraint(str(p.source), str(p.target), p) for p in prefs]
    return STPP(tuple(events), tuple(cons), task.name)
