"""Linear-programming allocation (seed section 1.3.4.3, Eqs 1.18-1.19).

Stage 1 (Eq 1.18) minimises the weighted 1-norm of the moment error
``sum_i wv_i |(B u - v)_i|`` over the limits; stage 2 (Eq 1.19) minimises the
weighted 1-norm distance to the preferred position ``sum_j wu_j |u_j - up_j|``
over the minimisers of stage 1 (``simplex``), or subject to the limits and ``B u =`` the
moment stage 1 reached (``daqp``, ``highs``).  The two are the same set whenever stage 1's
optimal moment is unique (every attainable demand); where an L1 stage 1 leaves a face of
equally good moments, ``simplex``'s stage-2 optimum is never worse.  The weights are the
diagonals of ``Wv`` and ``Wu`` (the seed's weight vectors).  With ``priorities``,
stage 1 runs per level, most important first, earlier levels keeping their errors.

Backends.  ``simplex`` (default): the compiled lexicographic simplex of
:mod:`alloc._engine._simplex` -- both stages (and the priority levels) in one compiled call, in
scaled variables, cold-started from a canonical basis on every call, stage 2 over the
whole optimal set of stage 1 and a final generic linear tie-break, so that ``u`` is a
function of the call's data alone (see that module for the canonical choice).  ``daqp``
and ``highs``: the formulation below, solved by those libraries (the cross-check).

Slack form (``daqp``, ``highs``): stage 1 has variables ``[u, e+, e-]`` with ``B u - e+ + e- = v``; stage 2
``[d+, d-]`` with ``u = c + d+ - d-`` (``c`` = ``up`` clipped into the bounds) and
``Q' B u = Q' B u1`` (row-reduced), all else simple bounds.  Only
bounds and costs change between calls, so the solver models are built once.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .._engine._simplex import OPTIMAL, LexicographicL1
from ..exceptions import SolverError
from ..export_data import SimplexData
from ..options import choice, levels
from ..problem import Problem
from ..method import Method, register
from ..result import exact_tolerance
from ._common import KEEP_RTOL
from ..solvers import backends, make_backend
from ._common import check_backend, check_diagonal, row_basis
from .cascade import check_priorities


@register("lp", supports_priorities=True, export="simplex")
class TwoStageLP(Method):
    equation = "Eqs 1.18-1.19"
    summary = "stage 1 min weighted 1-norm moment error, stage 2 min weighted 1-norm |u-up|"
    options = {
        "backend": choice("simplex", "'simplex' (compiled, canonical) or an LP library",
                          lambda: ["simplex", *backends(lp=True)]),
        "priorities": levels("priority level per axis; larger levels are met first"),
    }

    def __init__(self, problem: Problem, *, backend: str = "simplex", priorities: Sequence[int] | None = None) -> None:
        super().__init__(problem)
        name = check_backend(backend, ["simplex", *backends(lp=True)], "lp")
        p = problem
        k, m = p.k, p.m
        self.wv = check_diagonal(p.Wv, "Wv", "lp")
        self.wu = check_diagonal(p.Wu, "Wu", "lp")
        self.groups = check_priorities(priorities, k) or [np.arange(k)]
        self._lex: LexicographicL1 | None = None
        if name == "simplex":
            self._lex = LexicographicL1(p.B, p.umin, p.umax, p.up, self.wv, self.wu, self.groups)
            return
        self._Bpos, self._Bneg = np.maximum(p.B, 0.0), np.minimum(p.B, 0.0)
        inf = np.full(2 * k, np.inf)
        A1 = np.hstack([p.B, -np.eye(k), np.eye(k)])
        z = np.zeros(k)
        self._lb1 = np.concatenate([p.umin, np.zeros(2 * k)])
        self._ub1 = np.concatenate([p.umax, inf])
        self._stage1 = make_backend(name, None, np.zeros(m + 2 * k), A1, z, z, self._lb1, self._ub1)
        # Stage 2 in deviation form: u = c + d+ - d-, c = up clipped into the call's bounds
        # (for u on one side of up, |u - up| = |u - c| + |c - up|, so the argmin is the same):
        # only the r row-reduced moment equalities, everything else simple bounds.
        self._Q = row_basis(p.B)
        self._QB = self._Q @ p.B
        A2 = np.hstack([self._QB, -self._QB])
        f2 = np.concatenate([self.wu, self.wu])
        b2 = np.ones(self._Q.shape[0])  # a band, not an equality (see KEEP_RTOL)
        # attainable demands: the moment as an exact equality (the band model takes over
        # when the solver calls it infeasible)
        self._stage2_eq = make_backend(name, None, f2, A2, 0 * b2, 0 * b2, np.zeros(2 * m),
                                       np.concatenate([p.umax - p.up, p.up - p.umin]))
        self._stage2 = make_backend(name, None, f2, A2, -b2, b2, np.zeros(2 * m),
                                    np.concatenate([p.umax - p.up, p.up - p.umin]))

    def export_data(self) -> SimplexData | None:
        """The compiled simplex's scaled problem; ``None`` on an LP library backend (not exported)."""
        lex = self._lex
        if lex is None:
            return None

        def pivots(v: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> int:
            return lex.solve(v, lo, hi)[2]

        return SimplexData(F=lex.F, rho=lex.rho, D=lex.D, costs=lex.costs, max_iter=int(lex.max_iter), pivots=pivots)

    def solve(self, v, lo, hi, u_prev):
        if self._lex is not None:
            u, code, pivots = self._lex.solve(v, lo, hi)
            if code != OPTIMAL:
                raise SolverError(f"simplex: {('', 'iteration limit', 'singular basis or non-finite data')[code]} "
                                  f"after {pivots} pivots")
            return u, pivots
        p = self.problem
        k, m = p.k, p.m
        lb1, ub1 = self._lb1.copy(), self._ub1.copy()
        lb1[:m], ub1[:m] = lo, hi
        iters = 0
        x = None
        # A demand component beyond the row's range over the box [bot, top] adds a constant
        # to its error term (|B_i u - v_i| = v_i - B_i u for every admissible u): clamping it
        # to [bot - w, top + w] (w = top - bot) keeps the minimisers and keeps the moment rows
        # on the scale of B u (a demand 1e30 times the attainable set otherwise reaches the
        # solver as bounds that HiGHS reads as infinite, >= 1e20).
        Bp, Bn = self._Bpos, self._Bneg
        top, bot = Bp @ hi + Bn @ lo, Bp @ lo + Bn @ hi
        w = top - bot
        v1 = np.minimum(np.maximum(v, bot - w), top + w)
        for rows in self.groups:
            c = np.zeros(m + 2 * k)
            c[m + rows] = self.wv[rows]
            c[m + k + rows] = self.wv[rows]
            x, it = self._stage1.solve(f=c, lb=lb1, ub=ub1, bl=v1, bu=v1)
            iters += it
            # freeze this level's errors for the levels after it
            for off in (m, m + k):
                e = np.maximum(x[off + rows], 0.0)
                lb1[off + rows] = e
                ub1[off + rows] = e
        u1 = np.minimum(np.maximum(x[:m], lo), hi)
        m1 = p.B @ u1
        target = v if np.abs(m1 - v).max() <= exact_tolerance(v) else m1
        c = np.minimum(np.maximum(p.up, lo), hi)
        ub2 = np.concatenate([hi - c, c - lo])
        lb2 = np.zeros(2 * m)
        rhs = self._Q @ target - self._QB @ c
        x2 = None
        if target is v:
            try:
                x2, it2 = self._stage2_eq.solve(lb=lb2, ub=ub2, bl=rhs, bu=rhs)
            except SolverError:
                x2 = None
        if x2 is None:
            band = KEEP_RTOL * max(1.0, float(np.abs(target).max()))
            x2, it2 = self._stage2.solve(lb=lb2, ub=ub2, bl=rhs - band, bu=rhs + band)
        return c + x2[:m] - x2[m:], iters + it2
