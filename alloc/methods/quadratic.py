"""Quadratic-programming allocation (seed section 1.3.4.4, Eqs 1.20-1.21).

``qp``
    Two-stage sequential least squares.  Stage 1 (Eq 1.20): minimise
    ``(B u - v)' Wv (B u - v)`` over the limits; the achieved moment ``B u1`` is unique.
    Stage 2 (Eq 1.21): minimise ``(u - up)' Wu (u - up)`` subject to the limits and
    ``B u = B u1`` (``= v`` when ``v`` was attainable), so the answer is unique.  With
    ``priorities`` stage 1 runs once per level, most important first, each level keeping
    the moments of the levels before it.
``wls``
    Single-stage weighted least squares
    ``min (B u - v)' Wv (B u - v) + gamma^2 (u - up)' Wu (u - up)`` over the limits.  It
    approaches ``qp`` as ``gamma -> 0``; for attainable demands ``B u`` differs from ``v``
    by O(gamma^2), so tiny gammas are needed for an ``exact`` status.

Both run on DAQP models built once (``backend="daqp"``), or on any qpsolvers backend.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..exceptions import SolverError
from ..problem import Problem
from ..registry import FloatArray, Method, register
from ..result import exact_tolerance
from ..solvers import backends, make_backend
from ._common import KEEP_RTOL, check_backend, row_basis
from .._linalg import check_real_option
from .cascade import check_priorities

STAGE1_RIDGE = 1e-10

_BACKEND_DOC = "solver backend: 'daqp' (default) or a qpsolvers name such as 'osqp', 'clarabel'"


@register("qp")
class TwoStageQP(Method):
    equation = "Eqs 1.20-1.21"
    summary = "stage 1 min moment error (Wv), stage 2 min (u-up)'Wu(u-up) at that moment"
    options = {"backend": _BACKEND_DOC, "priorities": "priority level per axis; larger levels are met first"}

    def __init__(self, problem: Problem, *, backend: str = "daqp", priorities: Sequence[int] | None = None) -> None:
        super().__init__(problem)
        name = check_backend(backend, backends(), "qp")
        p = self.problem
        m = p.m
        self.groups = check_priorities(priorities, p.k) or [np.arange(p.k)]
        lo, hi = p.umin, p.umax
        # Stage 1, one model per priority level: keep the moments of the levels before it.
        self._stage1 = []
        done: list[int] = []
        for rows in self.groups:
            Wl = p.Wv[np.ix_(rows, rows)]
            Bl = p.B[rows]
            H = Bl.T @ Wl @ Bl
            # B'WvB is singular (rank k < m); a 1e-10 relative ridge makes it definite and
            # measured more accurate than DAQP's proximal iterations (1e-8 vs 3e-6 relative
            # moment error on ICE).  Only the stage-1 moment is used, so the ridge's pull
            # on u1 does not reach the answer.
            H = H + STAGE1_RIDGE * max(float(np.trace(H)) / m, 1e-300) * np.eye(m)
            Q = row_basis(p.B[done]) @ np.eye(p.k)[done] if done else np.zeros((0, p.k))
            Aeq = Q @ p.B if done else np.zeros((0, m))
            z = Aeq @ p.up  # feasible at set-up
            model = make_backend(name, H, np.zeros(m), Aeq, z, z, lo, hi)
            self._stage1.append((rows, Bl.T @ Wl, Q, model))
            done.extend(rows.tolist())
        # Stage 2: min (u-up)'Wu(u-up) s.t. Q'B u = Q'B u1 (row-reduced), limits.
        self._Q = row_basis(p.B)
        self._BQ = self._Q @ p.B
        z = self._BQ @ p.up  # feasible at set-up; a band, not an equality (KEEP_RTOL)
        self._f2 = -p.Wu @ p.up
        self._stage2 = make_backend(name, p.Wu, self._f2, self._BQ, z - 1.0, z + 1.0, lo, hi)
        # Attainable demands: B u = v as an exact equality (interior feasible sets are not
        # degenerate; when DAQP calls it infeasible the two-stage path takes over).
        self._stage2_eq = make_backend(name, p.Wu, self._f2, self._BQ, z, z, lo, hi)

    def _in_range(self, v) -> bool:
        r = v - self._Q.T @ (self._Q @ v)
        return float(np.abs(r).max()) <= exact_tolerance(v)

    def stage1(self, v, lo, hi) -> tuple[FloatArray, int]:
        """Eq 1.20 (lexicographically per priority level): a minimiser ``u1``."""
        iters = 0
        u1 = None
        for rows, BWl, Q, model in self._stage1:
            rhs = Q @ (self.problem.B @ u1) if Q.shape[0] else None
            u1, it = model.solve(f=-BWl @ v[rows], lb=lo, ub=hi, bl=rhs, bu=rhs)
            iters += it
        return np.minimum(np.maximum(u1, lo), hi), iters

    def solve(self, v, lo, hi, u_prev):
        # Attainable demands (the common case in flight) need only stage 2 with B u = v;
        # when that is infeasible, stage 1 finds the closest attainable moment first.
        if self._in_range(v):
            rhs = self._Q @ v
            try:
                return self._stage2_eq.solve(lb=lo, ub=hi, bl=rhs, bu=rhs)
            except SolverError:
                pass
        u1, it1 = self.stage1(v, lo, hi)
        m1 = self.problem.B @ u1
        target = v if np.abs(m1 - v).max() <= exact_tolerance(v) else m1
        rhs = self._Q @ target
        band = KEEP_RTOL * max(1.0, float(np.abs(target).max()))
        u, it2 = self._stage2.solve(lb=lo, ub=hi, bl=rhs - band, bu=rhs + band)
        return u, it1 + it2


@register("wls")
class WeightedLeastSquares(Method):
    equation = "Eqs 1.20-1.21 (single-stage weighted form)"
    summary = "min (Bu-v)'Wv(Bu-v) + gamma^2 (u-up)'Wu(u-up) over the limits"
    options = {"backend": _BACKEND_DOC, "gamma": "weight of the preference term (default 1e-4)"}

    def __init__(self, problem: Problem, *, backend: str = "daqp", gamma: float = 1e-4) -> None:
        super().__init__(problem)
        name = check_backend(backend, backends(), "wls")
        g = check_real_option(gamma, "wls", "gamma", 0.0, 1e6, open_lo=True)  # OptionError naming gamma
        p = self.problem
        self.gamma = g
        H = p.B.T @ p.Wv @ p.B + g * g * p.Wu
        self._BWv = p.B.T @ p.Wv
        self._f0 = -g * g * (p.Wu @ p.up)
        empty = np.zeros((0, p.m))
        self._model = make_backend(name, H, self._f0, empty, np.zeros(0), np.zeros(0), p.umin, p.umax)

    def solve(self, v, lo, hi, u_prev):
        return self._model.solve(f=self._f0 - self._BWv @ v, lb=lo, ub=hi)
