"""Independent oracles shared by tests: truth computed without the code under test."""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import Bounds, LinearConstraint, linprog, milp

from hrc.temporal import STNU


def lp_consistent(stnu: STNU, origin: str | None = None) -> bool:
    """Is there a schedule meeting every link, contingent ones taken as requirements? (an LP, HiGHS)

    With `origin`, it is fixed at 0 and every other timepoint comes at or after it.
    """
    index = {t: i for i, t in enumerate(stnu.timepoints)}
    rows, rhs = [], []
    links = [(r.source, r.target, r.lb, r.ub) for r in stnu.requirements]
    links += [(c.source, c.target, c.lb, c.ub) for c in stnu.contingents]
    for a, b, lb, ub in links:
        row = np.zeros(len(index))
        row[index[b]] += 1.0
        row[index[a]] -= 1.0
        if ub is not None:
            rows.append(row)
            rhs.append(ub)
        if lb is not None:
            rows.append(-row)
            rhs.append(-lb)
    if origin is None:
        bounds = [(None, None)] * len(index)
    else:
        bounds = [(0, 0) if t == origin else (0, None) for t in stnu.timepoints]
    if not rows:
        return True
    res = linprog(np.zeros(len(index)), A_ub=np.array(rows), b_ub=np.array(rhs, dtype=float), bounds=bounds,
                  method="highs")
    assert res.status in (0, 2), res.message  # feasible or infeasible; nothing else is possible here
    return res.status == 0


def _rows(stnu: STNU, index: dict[str, int], width: int) -> tuple[list[np.ndarray], list[float]]:
    """``row @ x <= rhs`` for every bound of every link (contingent links as requirements)."""
    rows, rhs = [], []
    links = [(r.source, r.target, r.lb, r.ub) for r in stnu.requirements]
    links += [(c.source, c.target, c.lb, c.ub) for c in stnu.contingents]
    for a, b, lb, ub in links:
        row = np.zeros(width)
        row[index[b]] += 1.0
        row[index[a]] -= 1.0
        if ub is not None:
            rows.append(row)
            rhs.append(float(ub))
        if lb is not None:
            rows.append(-row)
            rhs.append(-float(lb))
    return rows, rhs


def routes_of(paths, motions):  # noqa: ANN001, ANN201
    """The route choices (`hrc.motion.motions.Routes`) that a plan's motions took: detours and waits."""
    from hrc.motion import Path
    from hrc.motion.motions import Route

    out = {}
    for m in motions:
        if m.park:
            out[(m.agent, m.leg)] = Route(paths.get(m.agent, m.origin, m.park), m.park, paths.get(m.agent, m.park,
                                                                                                  m.target))
        elif m.via:
            out[(m.agent, m.leg)] = Route(Path(m.agent, m.origin, m.target, m.points, 0.0, m.time, m.via))
    return out


def orders_schedulable(task, plan, paths, motions=()) -> bool:  # noqa: ANN001
    """Is there a schedule of `plan` (its task limits included) with, at every place where the co-workers'
    occupancies meet, one of the two passing orders? A MILP (HiGHS) with one binary per conflict and
    big-M disjunctions, over the conflicts motion acquisition finds for the routes `motions` took
    (default: the shortest ones); independent of the compiler's order search.
    """
    from hrc.compile.temporal_net_creator import ORIGIN, create_stnu, ref_timepoint
    from hrc.motion import find_conflicts, plan_motions

    routes = routes_of(paths, motions)
    motions = plan_motions(task, plan, paths, routes)
    conflicts = find_conflicts(task, plan, paths, routes)
    stnu = create_stnu(task, plan, motions).stnu
    n, k = len(stnu.timepoints), len(conflicts)
    index = {t: i for i, t in enumerate(stnu.timepoints)}
    rows, rhs = _rows(stnu, index, n + k)
    big = 10.0 * (sum(abs(b) for r in stnu.requirements for b in (r.lb, r.ub) if b is not None)
                  + sum(c.ub for c in stnu.contingents) + 1000.0)
    for j, c in enumerate(conflicts):
        # binary 1: robot first, T(later) - T(earlier) >= gap, i.e. T(earlier) - T(later) - M (1 - b) <= -gap
        for sep, sign in ((c.robot_first, 1), (c.human_first, -1)):
            e, later = index[ref_timepoint(task, plan, sep.earlier)], index[ref_timepoint(task, plan, sep.later)]
            row = np.zeros(n + k)
            row[e] += 1.0
            row[later] -= 1.0
            gap = math.ceil(sep.gap * 1000 - 1e-9)
            if sign == 1:
                row[n + j] = big
                rows.append(row)
                rhs.append(-gap + big)
            else:
                row[n + j] = -big
                rows.append(row)
                rhs.append(-gap)
    lo = np.array([0.0 if t == ORIGIN else 0.0 for t in stnu.timepoints] + [0.0] * k)
    hi = np.array([0.0 if t == ORIGIN else np.inf for t in stnu.timepoints] + [1.0] * k)
    integrality = np.array([0] * n + [1] * k)
    res = milp(np.zeros(n + k), constraints=LinearConstraint(np.array(rows), -np.inf, np.array(rhs)),
               bounds=Bounds(lo, hi), integrality=integrality)
    assert res.status in (0, 2), res.message
    return res.status == 0
