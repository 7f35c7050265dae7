"""Independent oracles shared by tests: truth computed without the code under test."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linprog

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
