"""Direct allocation (seed section 1.3.4.2, Eqs 1.15-1.17) as a linear program.

The attainable moment set (AMS) is the image of the effector box under ``B``.  Direct
allocation finds the largest ``a`` with ``a d`` attainable, ``d = v - B u0`` the demand
measured from the base point ``u0`` (the preferred position clipped into the call's
bounds; ``u0 = 0`` in the seed):

    maximise a   subject to   B (u - u0) = a d,   lo <= u <= hi,   a >= 0.

The solution ``u*`` lies on the AMS boundary.  When ``a* >= 1`` the demand is attainable
and the boundary solution is scaled back along the ray (Eq 1.15):
``u = u0 + (u* - u0) / a*``, so ``B u = v``.  Otherwise ``u = u*``, the boundary point in
the demanded direction (status ``unattainable``).  With a rank-deficient ``B`` the ray
follows the part of ``d`` in the range of ``B``; the rest is reported as unallocated.  When the ray leaves the AMS through an
edge or a degenerate facet, ``u*`` is not unique (the moment is).  The facet-search
versions (``da_facet``, ``da_bisect``) live in :mod:`alloc.ams`.
"""

from __future__ import annotations

import numpy as np

from ..problem import Problem
from ..registry import Method, register
from ..solvers import backends, make_backend
from ._common import check_backend, row_basis


@register("da")
class DirectAllocationLP(Method):
    equation = "Eqs 1.15-1.17"
    summary = "largest admissible moment along v (AMS boundary), scaled back when attainable"
    options = {"backend": "LP solver: 'daqp' (default) or 'highs'"}

    def __init__(self, problem: Problem, *, backend: str = "daqp") -> None:
        super().__init__(problem)
        name = check_backend(backend, backends(lp=True), "da")
        p = problem
        # Equalities on the row space of B only (a rank-deficient B has dependent rows).
        self._Q = row_basis(p.B)
        self._QB = self._Q @ p.B
        self._A = np.hstack([self._QB, np.zeros((self._Q.shape[0], 1))])
        self._c = np.zeros(p.m + 1)
        self._c[-1] = -1.0
        self._colnorm = np.linalg.norm(p.B, axis=0)
        self._lb = np.concatenate([p.umin, [0.0]])
        self._ub = np.concatenate([p.umax, [1.0]])
        z = self._QB @ p.up  # feasible at set-up: u = up, a = 0
        self._model = make_backend(name, None, self._c, self._A, z, z, self._lb, self._ub)

    def boundary(self, d, u0, lo, hi):
        """``(a*, u*)``: the largest ``a`` with ``B(u - u0) = a d`` admissible, and its ``u``."""
        p = self.problem
        # a is bounded by the AMS's extent from B u0: |a d| <= sum_j |b_j| max|u_j - u0_j|.
        reach = float(self._colnorm @ np.maximum(hi - u0, u0 - lo))
        a_cap = 2.0 * reach / float(np.linalg.norm(d)) + 1.0
        A = self._A
        A[:, -1] = -(self._Q @ d)
        lb, ub = self._lb, self._ub
        lb[:-1], ub[:-1] = lo, hi
        ub[-1] = a_cap
        rhs = self._QB @ u0
        x, it = self._model.solve(A=A, lb=lb, ub=ub, bl=rhs, bu=rhs)
        a, ustar = float(x[-1]), np.minimum(np.maximum(x[:-1], lo), hi)
        return (*self._polish(a, ustar, d, u0, lo, hi), it)

    def _polish(self, a, ustar, d, u0, lo, hi):
        """Re-solve Eq 1.16 exactly on the facet the LP found.

        The LP (DAQP's proximal iterations) meets ``B(u - u0) = a d`` to ~1e-8 relative.
        On a facet hit, ``k - 1`` effectors are strictly inside their limits and the rest
        saturated; the ``k x k`` system for those effectors and ``a`` gives the exact point.
        Kept only if admissible and on the ray; otherwise (edges, degenerate facets) the LP
        answer stands.
        """
        p = self.problem
        span = np.maximum(hi - lo, 1e-300)
        inside = ((ustar - lo) > 1e-7 * span) & ((hi - ustar) > 1e-7 * span)
        F = np.flatnonzero(inside)
        if F.size != p.k - 1 or self._Q.shape[0] != p.k:
            return a, ustar
        M = np.empty((p.k, p.k))
        M[:, :-1] = p.B[:, F]
        M[:, -1] = -d
        fixed = ustar.copy()
        fixed[F] = 0.0
        try:
            sol = np.linalg.solve(M, p.B @ u0 - p.B @ fixed)
        except np.linalg.LinAlgError:
            return a, ustar
        uF, a_new = sol[:-1], float(sol[-1])
        if not (np.all(uF >= lo[F]) and np.all(uF <= hi[F]) and a_new >= 0 and abs(a_new - a) <= 1e-6 * max(1.0, a)):
            return a, ustar
        fixed[F] = uF
        return a_new, fixed

    def solve(self, v, lo, hi, u_prev):
        p = self.problem
        u0 = np.minimum(np.maximum(p.up, lo), hi)
        # Only the part of the demand in the range of B can be reached; the rest is
        # reported as unallocated (it is zero unless B is rank deficient).
        d = self._Q.T @ (self._Q @ (v - p.B @ u0))
        if np.abs(d).max() <= 1e-14 * max(1.0, float(np.abs(v).max())):
            return u0, 0
        a, ustar, it = self.boundary(d, u0, lo, hi)
        if a >= 1.0:
            return u0 + (ustar - u0) / a, it  # Eq 1.15: scale the boundary solution back
        return ustar, it
