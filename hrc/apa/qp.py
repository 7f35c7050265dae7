"""The STPP as a convex quadratic program (APA Fig. 5 line 3) and the solvers that may solve it.

Maximise ``F(x) = sum_k c0_k + c1_k d_k + c2_k d_k**2`` with ``d_k = x[j_k] - x[i_k]`` subject to the
interval constraints ``lb <= x[j] - x[i] <= ub``. As a minimisation in the solvers' standard form::

    minimise 1/2 x'Px + q'x   subject to   h_l <= G x <= h_u

with ``P = sum_k -2 c2_k a_k a_k'`` and ``q = sum_k -c1_k a_k`` for ``a_k = e_j - e_i``. ``P`` is positive
semidefinite (every ``c2 <= 0``) and singular: events that appear in no preference have no curvature,
and ``F`` only sees differences of times. The second is removed here by fixing one *anchor* event per
connected part of the constraint graph at 0 (the STPP's reference event for its part); the first is
what interior-point solvers handle and HiGHS's QP does not (../shared/notes). Events tied by rigid
links share one variable (`QuadraticProgram.standard_form`).

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

    def standard_form(self) -> tuple[sp.csc_matrix, np.ndarray, sp.csc_matrix, np.ndarray, np.ndarray,
                                      np.ndarray, np.ndarray]:
        """``(P, q, G, h_l, h_u, col, shift)``: the problem over free variables ``z``, with every event's
        time ``x[v] = shift[v] + (z[col[v]] if col[v] >= 0 else 0)``; ``P`` upper triangular (as both
        solvers read it).

        Rigid rows (``lb == ub``, e.g. the past the dispatcher made rigid) are contracted: the events
        they tie share one variable, at fixed offsets. Left as rows they have no interior, and together
        with other rigid links they can be linearly dependent equalities; piqp then called a feasible
        problem infeasible. Anchors fix their class at 0. Raises `ApaError` if rigid rows conflict.
        """
        n = self.n
        parent = list(range(n))
        offset = [0.0] * n  # x[v] = x[parent[v]] + offset[v]

        def find(v: int) -> tuple[int, float]:
            path = []
            while parent[v] != v:
                path.append(v)
                v = parent[v]
            acc = 0.0
            for u in reversed(path):  # compress: each u now hangs directly from the root
                acc += offset[u]
                parent[u], offset[u] = v, acc
            return v, (offset[path[0]] if path else 0.0)

        rigid = np.isfinite(self.lb) & (self.lb == self.ub)
        for a, b, d in zip(self.src[rigid].tolist(), self.dst[rigid].tolist(), self.lb[rigid].tolist(), strict=True):
            ra, oa = find(a)
            rb, ob = find(b)  # x[b] - x[a] = d
            if ra == rb:
                if abs((ob - oa) - d) > 1e-9 * max(1.0, abs(d)):
                    raise ApaError("rigid constraints of the STPP contradict each other")
                continue
            parent[rb], offset[rb] = ra, oa + d - ob
        root = np.empty(n, dtype=np.int64)
        off = np.empty(n)
        for v in range(n):
            root[v], off[v] = find(v)
        fixed = np.full(n, np.nan)  # value of a fixed class's root
        for a in self.anchors.tolist():
            fixed[root[a]] = -off[a]
        roots = np.unique(root)
        free_roots = roots[np.isnan(fixed[roots])]
        col_of_root = np.full(n, -1, dtype=np.int64)
        col_of_root[free_roots] = np.arange(len(free_roots))
        col = col_of_root[root]
        shift = off + np.where(np.isnan(fixed[root]), 0.0, fixed[root])
        m = len(free_roots)

        keep = (np.isfinite(self.lb) | np.isfinite(self.ub)) & ~rigid & (root[self.src] != root[self.dst])
        s, t = col[self.src[keep]], col[self.dst[keep]]
        delta = shift[self.dst[keep]] - shift[self.src[keep]]
        rows = np.arange(int(keep.sum()))
        r = np.concatenate([rows[t >= 0], rows[s >= 0]])
        c = np.concatenate([t[t >= 0], s[s >= 0]])
        vals = np.concatenate([np.ones(int((t >= 0).sum())), -np.ones(int((s >= 0).sum()))])
        g = _csc(r, c, vals, len(rows), m)  # a row's two columns differ (rows within a class were dropped)
        h_l, h_u = self.lb[keep] - delta, self.ub[keep] - delta
        inside = (root[self.src] == root[self.dst]) & ~rigid  # a non-rigid row within a class: a constant
        d_in = shift[self.dst[inside]] - shift[self.src[inside]]
        if np.any(d_in < self.lb[inside] - 1e-9) or np.any(d_in > self.ub[inside] + 1e-9):
            raise ApaError("rigid constraints of the STPP break one of its intervals")

        # a preference on d = z[j] - z[i] + delta: c1 d + c2 d^2 = c2 y^2 + (c1 + 2 c2 delta) y + const
        i, j = col[self.pi], col[self.pj]
        delta_p = shift[self.pj] - shift[self.pi]
        lin = self.c1 + 2 * self.c2 * delta_p
        q = np.zeros(m)
        np.add.at(q, j[j >= 0], -lin[j >= 0])
        np.add.at(q, i[i >= 0], lin[i >= 0])
        w = -2.0 * self.c2  # >= 0
        pr, pc, pv = [], [], []
        for a_, b_, sign in ((j, j, 1.0), (i, i, 1.0), (i, j, -1.0), (j, i, -1.0)):
            ok = (a_ >= 0) & (b_ >= 0) & (w != 0) & (a_ <= b_)  # the upper triangle
            pr.append(a_[ok])
            pc.append(b_[ok])
            pv.append(sign * w[ok])
        pr_, pc_ = np.concatenate(pr), np.concatenate(pc)
        key, where = np.unique(pc_ * max(m, 1) + pr_, return_inverse=True)  # duplicates summed, in CSC order
        p = _csc(key % max(m, 1), key // max(m, 1), np.bincount(where, np.concatenate(pv), len(key)), m, m)
        return p, q, g, h_l.astype(float), h_u.astype(float), col, shift

    def times(self, z: np.ndarray, col: np.ndarray, shift: np.ndarray) -> np.ndarray:
        """Event times from the free variables (see `standard_form`)."""
        return shift + np.where(col >= 0, z[np.maximum(col, 0)] if len(z) else 0.0, 0.0)


def _csc(rows: np.ndarray, cols: np.ndarray, vals: np.ndarray, n_rows: int, n_cols: int) -> sp.csc_matrix:
    """The CSC matrix of distinct ``(rows[k], cols[k]) -> vals[k]``, built from its arrays directly (the
    COO route sorts and checks again: most of the cost of a small QP's setup)."""
    order = np.lexsort((rows, cols))
    indptr = np.zeros(n_cols + 1, dtype=np.int32)
    np.cumsum(np.bincount(cols, minlength=n_cols), out=indptr[1:])
    return sp.csc_matrix((vals[order].astype(float), rows[order].astype(np.int32), indptr), shape=(n_rows, n_cols))


def _piqp(qp: QuadraticProgram) -> np.ndarray:
    import piqp

    p, q, g, h_l, h_u, col, shift = qp.standard_form()
    if p.shape[0] == 0:
        return qp.times(np.zeros(0), col, shift)
    kw: dict[str, object] = {"P": p, "c": q}
    if g.shape[0]:
        kw.update(G=g, h_l=h_l, h_u=h_u)
    status = None
    for eps_abs, eps_rel in ((1e-10, 1e-10), (1e-8, 1e-9)):  # retried at looser accuracy before giving up
        solver = piqp.SparseSolver()
        solver.settings.eps_abs = eps_abs
        solver.settings.eps_rel = eps_rel
        solver.settings.max_iter = 500
        solver.setup(**kw)
        status = solver.solve()
        if status == piqp.PIQP_SOLVED:
            return qp.times(np.asarray(solver.result.x), col, shift)
    raise ApaError(f"piqp could not solve the STPP's QP: {status}")


def _clarabel(qp: QuadraticProgram) -> np.ndarray:
    import clarabel

    p, q, g, h_l, h_u, col, shift = qp.standard_form()
    m = p.shape[0]
    if m == 0:
        return qp.times(np.zeros(0), col, shift)
    up, lo = np.isfinite(h_u), np.isfinite(h_l)
    a = sp.vstack([g[up], -g[lo]], format="csc")  # G x <= h_u ; -G x <= -h_l
    b = np.concatenate([h_u[up], -h_l[lo]])
    settings = clarabel.DefaultSettings()
    settings.verbose = False
    settings.tol_gap_abs = settings.tol_gap_rel = settings.tol_feas = 1e-10
    cones = [clarabel.NonnegativeConeT(a.shape[0])] if a.shape[0] else []
    if not a.shape[0]:
        a = sp.csc_matrix((0, m))
    solution = clarabel.DefaultSolver(p, q, a, b, cones, settings).solve()
    if str(solution.status) not in ("Solved", "AlmostSolved"):
        raise ApaError(f"clarabel could not solve the STPP's QP: {solution.status}")
    return qp.times(np.asarray(solution.x), col, shift)


SOLVERS: dict[str, Callable[[QuadraticProgram], np.ndarray]] = {"piqp": _piqp, "clarabel": _clarabel}
"""Solver name -> function from a `QuadraticProgram` to optimal event times (s)."""


def solve_qp(qp: QuadraticProgram, solver: str = "piqp") -> np.ndarray:
    """Optimal event times (s) of `qp` by the named solver; raises `ApaError` if it fails."""
    if solver not in SOLVERS:
        raise ApaError(f"unknown QP solver {solver!r} (known: {', '.join(SOLVERS)})")
    return SOLVERS[solver](qp)
