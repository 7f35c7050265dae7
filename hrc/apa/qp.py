"""The STPP as a convex quadratic program (APA Fig. 5 line 3) and the solvers that may solve it.

Maximise ``F(x) = sum_k c0_k + c1_k d_k + c2_k d_k**2`` with ``d_k = x[j_k] - x[i_k]`` subject to the
interval constraints ``lb <= x[j] - x[i] <= ub``. As a minimisation in the solvers' standard form::

    minimise 1/2 x'Px + q'x   subject to   h_l <= G x <= h_u

with ``P = sum_k -2 c2_k a_k a_k'`` and ``q = sum_k -c1_k a_k`` for ``a_k = e_j - e_i``. ``P`` is positive
semidefinite (every ``c2 <= 0``) and singular: events that appear in no preference have no curvature,
and ``F`` only sees differences of times. The second is removed here by fixing one *anchor* event per
connected part of the constraint graph at 0 (the STPP's reference event for its part) and dropping its
column; the first is what interior-point solvers handle and HiGHS's QP does not (../shared/notes).

Solvers (an explicit registry, `SOLVERS`): ``piqp`` (proximal interior point; fastest measured at
10,000 events) and ``clarabel`` (interior point for conic programs; the independent cross-check).
piqp's arguments are passed by keyword: their positional order changed between versions.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from hrc.errors import ApaError

__all__ = ["SOLVERS", "QuadraticProgram", "solve_qp"]


@dataclass(frozen=True, slots=True)
class QuadraticProgram:
    """An STPP's QP over `n` event times (s). Rows are interval constraints ``lb <= x[dst] - x[src] <= ub``
    (``-inf`` / ``inf`` for an open side); preference terms are ``c1 d + c2 d**2`` on ``d = x[pj] - x[pi]``
    (the constants do not move the optimum). `anchors` are fixed at 0."""

    n: int
    src: np.ndarray
    dst: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    pi: np.ndarray
    pj: np.ndarray
    c1: np.ndarray
    c2: np.ndarray
    anchors: np.ndarray

    def standard_form(self) -> tuple[sp.csc_matrix, np.ndarray, sp.csc_matrix, np.ndarray, np.ndarray, np.ndarray]:
        """``(P, q, G, h_l, h_u, free)``: the reduced problem over the `free` (non-anchor) events;
        ``P`` upper triangular (as both solvers read it)."""
        col = np.full(self.n, -1, dtype=np.int64)
        free = np.setdiff1d(np.arange(self.n), self.anchors)
        col[free] = np.arange(len(free))
        m = len(free)

        keep = np.isfinite(self.lb) | np.isfinite(self.ub)
        s, t = col[self.src[keep]], col[self.dst[keep]]
        rows = np.arange(int(keep.sum()))
        r = np.concatenate([rows[t >= 0], rows[s >= 0]])
        c = np.concatenate([t[t >= 0], s[s >= 0]])
        v = np.concatenate([np.ones(int((t >= 0).sum())), -np.ones(int((s >= 0).sum()))])
        g = sp.csc_matrix((v, (r, c)), shape=(len(rows), m))

        i, j = col[self.pi], col[self.pj]
        q = np.zeros(m)
        np.add.at(q, j[j >= 0], -self.c1[j >= 0])
        np.add.at(q, i[i >= 0], self.c1[i >= 0])
        w = -2.0 * self.c2  # >= 0
        pr, pc, pv = [], [], []
        for a, b, sign in ((j, j, 1.0), (i, i, 1.0), (i, j, -1.0), (j, i, -1.0)):
            ok = (a >= 0) & (b >= 0) & (w != 0)
            pr.append(a[ok])
            pc.append(b[ok])
            pv.append(sign * w[ok])
        p = sp.coo_matrix((np.concatenate(pv), (np.concatenate(pr), np.concatenate(pc))), shape=(m, m)).tocsc()
        p.sum_duplicates()
        p = sp.triu(p, format="csc")
        return p, q, g, self.lb[keep].astype(float), self.ub[keep].astype(float), free


def _piqp(qp: QuadraticProgram) -> np.ndarray:
    import piqp

    p, q, g, h_l, h_u, free = qp.standard_form()
    x = np.zeros(qp.n)
    if len(free) == 0:
        return x
    # rigid rows (lb == ub, e.g. the past made rigid by the dispatcher) go in as equalities: as
    # two-sided inequalities with no interior, piqp called a feasible problem infeasible
    eq = h_l == h_u
    kw: dict[str, object] = {"P": p, "c": q}
    if eq.any():
        kw.update(A=g[np.nonzero(eq)[0]], b=h_l[eq])
    if (~eq).any():
        kw.update(G=g[np.nonzero(~eq)[0]], h_l=h_l[~eq], h_u=h_u[~eq])
    status = None
    for eps_abs, eps_rel in ((1e-10, 1e-10), (1e-8, 1e-9)):  # retried at looser accuracy before giving up
        solver = piqp.SparseSolver()
        solver.settings.eps_abs = eps_abs
        solver.settings.eps_rel = eps_rel
        solver.settings.max_iter = 500
        solver.setup(**kw)
        status = solver.solve()
        if status == piqp.PIQP_SOLVED:
            x[free] = np.asarray(solver.result.x)
            return x
    raise ApaError(f"piqp could not solve the STPP's QP: {status}")


def _clarabel(qp: QuadraticProgram) -> np.ndarray:
    import clarabel

    p, q, g, h_l, h_u, free = qp.standard_form()
    x = np.zeros(qp.n)
    if len(free) == 0:
        return x
    up, lo = np.isfinite(h_u), np.isfinite(h_l)
    a = sp.vstack([g[up], -g[lo]], format="csc")  # G x <= h_u ; -G x <= -h_l
    b = np.concatenate([h_u[up], -h_l[lo]])
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = 1e-10
    cones = [clarabel.NonnegativeConeT(a.shape[0])] if a.shape[0] else []
    if not a.shape[0]:
        a = sp.csc_matrix((0, len(free)))
    solution = clarabel.DefaultSolver(p, q, a, b, cones, settings).solve()
    if str(solution.status) not in ("Solved", "AlmostSolved"):
        raise ApaError(f"clarabel could not solve the STPP's QP: {solution.status}")
    x[free] = np.asarray(solution.x)
    return x


SOLVERS: dict[str, Callable[[QuadraticProgram], np.ndarray]] = {"piqp": _piqp, "clarabel": _clarabel}
"""Solver name -> function from a `QuadraticProgram` to optimal event times (s)."""


def solve_qp(qp: QuadraticProgram, solver: str = "piqp") -> np.ndarray:
    """Optimal event times (s) of `qp` by the named solver; raises `ApaError` if it fails."""
    if solver not in SOLVERS:
        raise ApaError(f"unknown QP solver {solver!r} (known: {', '.join(SOLVERS)})")
    return SOLVERS[solver](qp)
