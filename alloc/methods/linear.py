"""Linear-programming allocation (seed section 1.3.4.3, Eqs 1.18-1.19).

Stage 1 (Eq 1.18) minimises the weighted 1-norm of the moment error
``sum_i wv_i |(B u - v)_i|`` over the limits; stage 2 (Eq 1.19) minimises the
weighted 1-norm distance to the preferred position ``sum_j wu_j |u_j - up_j|``
subject to the limits and ``B u =`` the moment stage 1 reached.  The weights are the
diagonals of ``Wv`` and ``Wu`` (the seed's weight vectors).  With ``priorities``,
stage 1 runs per level, most important first, earlier levels keeping their errors.

Slack form: stage 1 has variables ``[u, e+, e-]`` with ``B u - e+ + e- = v``; stage 2
``[u, d+, d-]`` with ``u - d+ + d- = up`` and ``Q' B u = Q' B u1`` (row-reduced).  Only
bounds and costs change between calls, so the solver models are built once.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..exceptions import SolverError
from ..problem import Problem
from ..registry import Method, register
from ..result import exact_tolerance
from ..solvers import backends, make_backend
from ._common import check_backend, check_diagonal, row_basis
from .cascade import check_priorities


@register("lp")
class TwoStageLP(Method):
    equation = "Eqs 1.18-1.19"
    summary = "stage 1 min weighted 1-norm moment error, stage 2 min weighted 1-norm |u-up|"
    options = {
        "backend": "LP solver: 'daqp' (default) or 'highs'",
        "priorities": "priority level per axis; larger levels are met first",
    }

    def __init__(self, problem: Problem, *, backend: str = "daqp", priorities: Sequence[int] | None = None) -> None:
        super().__init__(problem)
        name = check_backend(backend, backends(lp=True), "lp")
        p = problem
        k, m = p.k, p.m
        self.wv = check_diagonal(p.Wv, "Wv", "lp")
        self.wu = check_diagonal(p.Wu, "Wu", "lp")
        self.groups = check_priorities(priorities, k) or [np.arange(k)]
        inf = np.full(2 * k, np.inf)
        A1 = np.hstack([p.B, -np.eye(k), np.eye(k)])
        z = np.zeros(k)
        self._lb1 = np.concatenate([p.umin, np.zeros(2 * k)])
        self._ub1 = np.concatenate([p.umax, inf])
        self._stage1 = make_backend(name, None, np.zeros(m + 2 * k), A1, z, z, self._lb1, self._ub1)
        self._Q = row_basis(p.B)
        r = self._Q.shape[0]
        A2 = np.vstack([
            np.hstack([np.eye(m), -np.eye(m), np.eye(m)]),
            np.hstack([self._Q @ p.B, np.zeros((r, 2 * m))]),
        ])
        f2 = np.concatenate([np.zeros(m), self.wu, self.wu])
        self._lb2 = np.concatenate([p.umin, np.zeros(2 * m)])
        self._ub2 = np.concatenate([p.umax, np.full(2 * m, np.inf)])
        b2 = np.concatenate([p.up, np.zeros(r)])
        self._b2 = b2
        self._stage2 = make_backend(name, None, f2, A2, b2, b2, self._lb2, self._ub2)

    def solve(self, v, lo, hi, u_prev):
        p = self.problem
        k, m = p.k, p.m
        lb1, ub1 = self._lb1.copy(), self._ub1.copy()
        lb1[:m], ub1[:m] = lo, hi
        iters = 0
        x = None
        for rows in self.groups:
            c = np.zeros(m + 2 * k)
            c[m + rows] = self.wv[rows]
            c[m + k + rows] = self.wv[rows]
            x, it = self._stage1.solve(f=c, lb=lb1, ub=ub1, bl=v, bu=v)
            iters += it
            # freeze this level's errors for the levels after it
            for off in (m, m + k):
                e = np.maximum(x[off + rows], 0.0)
                lb1[off + rows] = e
                ub1[off + rows] = e
        u1 = np.minimum(np.maximum(x[:m], lo), hi)
        m1 = p.B @ u1
        target = v if np.abs(m1 - v).max() <= exact_tolerance(v) else m1
        b2 = self._b2.copy()
        b2[m:] = self._Q @ target
        lb2, ub2 = self._lb2.copy(), self._ub2.copy()
        lb2[:m], ub2[:m] = lo, hi
        try:
            x2, it2 = self._stage2.solve(lb=lb2, ub=ub2, bl=b2, bu=b2)
        except SolverError:
            if target is not v:
                raise
            b2[m:] = self._Q @ m1  # v met only to tolerance: keep stage 1's exact moment
            x2, it2 = self._stage2.solve(lb=lb2, ub=ub2, bl=b2, bu=b2)
        return x2[:m], iters + it2
