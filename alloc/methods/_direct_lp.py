"""The LP formulation of direct allocation (seed section 1.3.4.2, Eqs 1.15-1.17).

``da``'s LP backends (:class:`alloc.methods.direct.DirectAllocation` is this class with the
facet search as a further backend) and the facet searches' fallback where their tables
cannot be built (:mod:`alloc.methods.facet_search`): both build on this module, which
imports neither, so the two method modules do not import each other.

    maximise a   subject to   B (u - u0) = a d,   lo <= u <= hi,   a >= 0,

``d = v - B u0`` measured from the base point ``u0 = clip(up, lo, hi)``; ``a* >= 1`` gives
``u = u0 + (u* - u0) / a*`` (Eq 1.15, so ``B u = v``), otherwise ``u = u*``.
"""

from __future__ import annotations

import math

import numpy as np

from .._engine import _ray_simplex
from .._engine._kernels import facet_polish, matvec, rmatvec
from ..exceptions import SolverError
from ..facet_cost import lp_build_bytes, lp_build_seconds
from ..method import FloatArray, Method
from ..problem import Problem
from ..solvers import backends, make_backend
from ._common import check_backend, row_basis

__all__ = ["RayLP"]


class RayLP(Method):
    """Direct allocation as an LP on a persistent DAQP (or HiGHS) model, polished on the
    facet it finds (not registered: ``da`` and the facet searches use it)."""

    equation = "Eqs 1.15-1.17"
    summary = "largest admissible moment along v as an LP, scaled back when attainable"

    @classmethod
    def build_cost(cls, problem: Problem, **options: object) -> float:
        """The ray LP's set-up, measured (:func:`alloc.facet_cost.lp_build_seconds`)."""
        return lp_build_seconds(problem.k, problem.m)

    @classmethod
    def build_memory(cls, problem: Problem, **options: object) -> int:
        """The ray LP's set-up, measured (:func:`alloc.facet_cost.lp_build_bytes`)."""
        return lp_build_bytes(problem.k, problem.m)

    def __init__(self, problem: Problem, *, backend: str = "daqp", simplex: bool = False) -> None:
        super().__init__(problem)
        name = check_backend(backend, backends(lp=True), "da")
        #: the compiled ray simplex (:mod:`alloc._engine._ray_simplex`) answers first; the backend's
        #: model only where it stops at its iteration bound or on a singular basis
        self.simplex = bool(simplex)
        self.simplex_fallbacks = 0
        p = problem
        # The LP is solved in scaled variables so that its data are O(1) whatever the
        # magnitudes of B and the limits (1e-30 to 1e48 in the adversarial suite):
        #   u = c + D x, x in [-1, 1] (c the centre of the box, D its half-widths),
        #   t = distance along the unit ray in moment units / sigma,
        #   (Q B D / sigma) x - t Q d_hat = Q B (u0 - c) / sigma,
        # with sigma the largest entry of Q B D.  Equalities on the row space of B only
        # (a rank-deficient B has dependent rows; directions below 1e-8 of the largest
        # singular value carry less moment than the exact tolerance and are dropped).
        self._Q = np.array(row_basis(p.B, rtol=1e-8), order="C")  # own, contiguous: one kernel signature
        self._c0 = (p.umax + p.umin) / 2.0
        self._D = (p.umax - p.umin) / 2.0
        self._moving = self._D > 0
        QBD = (self._Q @ p.B) * self._D
        self._sigma = float(np.abs(QBD).max()) if QBD.size and np.abs(QBD).max() > 0 else 1.0
        self._QBs = np.array(self._Q @ p.B / self._sigma, order="C")  # applied to u - c
        self._A = np.hstack([QBD / self._sigma, np.zeros((self._Q.shape[0], 1))])
        self._c = np.zeros(p.m + 1)
        self._c[-1] = -1.0
        reach = float(np.linalg.norm(p.B, axis=0) @ (p.umax - p.umin))
        self._B = np.array(p.B, order="C")  # writable: a pickled copy's arrays are, one kernel signature
        self._lb = np.concatenate([np.where(self._moving, -1.0, 0.0), [0.0]])
        # along a unit direction, the distance to the AMS boundary never exceeds its extent
        self._ub = np.concatenate([np.where(self._moving, 1.0, 0.0), [2.0 * reach / self._sigma + 1.0]])
        self._lb.setflags(write=False)
        self._ub.setflags(write=False)
        self._u0 = np.array(p.up)  # base point without rate limits (up is within the limits)
        self._Bu0 = p.B @ self._u0
        self._rhs0 = self._QBs @ (self._u0 - self._c0)
        self._x0 = self._to_x(self._u0)
        if self.simplex:
            kq = self._Q.shape[0]
            self._F = _ray_simplex.ray_matrix(self._A[:, :-1])
            self._xlo, self._xhi = self._lb[:-1].copy(), self._ub[:-1].copy()
            Ax = self._A[:, :-1]
            # the ellipsoid (A A')^-1 behind the starting basis; a pseudo-inverse, since every
            # effector may be jammed (A = 0): only the start depends on it, never the answer
            G = np.linalg.pinv(Ax @ Ax.T) if kq and np.isfinite(Ax).all() else np.zeros((kq, kq))
            self._G = np.array(G if np.isfinite(G).all() else np.zeros((kq, kq)), order="C")
            self._cnorm = np.linalg.norm(Ax, axis=0)
            self._Ax = np.array(Ax, order="C")
            # writable copies (one compiled signature; a pickled copy's arrays are writable)
            self._umin, self._umax = np.array(p.umin), np.array(p.umax)
            nw, ni = _ray_simplex.work_sizes(kq, p.m)
            self._work, self._iwork = np.empty(nw), np.empty(ni, dtype=np.int64)
            # a ray crosses few vertices; the bound only stops a pathological pivot path
            self._max_pivots = 50 * (kq + 1) + 4 * p.m
        z = self._rhs0  # feasible at set-up: u = up, t = 0
        try:
            self._model = make_backend(name, None, self._c, self._A, z, z, self._lb, self._ub)
        except SolverError:
            if name == "highs":
                raise
            # DAQP's proximal LP can refuse a nearly dependent equality set at set-up;
            # HiGHS' simplex is the documented second backend of the same LP.
            self._model = make_backend("highs", None, self._c, self._A, z, z, self._lb, self._ub)

    def _to_x(self, u: FloatArray) -> FloatArray:
        """Scaled coordinates ``x = (u - c) / D`` (0 for jammed effectors)."""
        return np.divide(u - self._c0, self._D, out=np.zeros_like(u), where=self._moving)

    def boundary(self, d, u0, lo, hi):
        """``(a*, u*)``: the largest ``a`` with ``B(u - u0) = a d`` admissible, and its ``u``.

        The LP runs along the unit direction ``d / |d|`` in scaled variables (see
        ``__init__``) so that its bound on the distance (the AMS's extent) is a constant
        and, without rate limits, no bound is re-sent per call.  With ``simplex`` the compiled
        solvers of :mod:`alloc._engine._ray_simplex` answer first (exact vertices); the LP (DAQP's
        proximal iterations) meets the equality to ~1e-8 relative; on a facet hit (``k - 1``
        effectors strictly inside their limits) the point is then re-solved exactly from
        Eq 1.16 on that facet (:func:`alloc._engine._kernels.facet_polish`).  Edges and degenerate
        facets keep the LP's answer.
        """
        p = self.problem
        # fixed-order products (alloc._engine._kernels.matvec): numpy's ``@`` rounds by the operands'
        # layout, and a copy of this allocator must answer bit for bit
        dmax = float(np.abs(d).max())
        ds = d / dmax  # |d| without overflow or underflow of its square
        ds2 = float(matvec(ds.reshape(1, -1), ds)[0])
        norm = dmax * math.sqrt(ds2)
        A = self._A
        A[:, -1] = -matvec(self._Q, ds / math.sqrt(ds2))
        if lo is p.umin and hi is p.umax:
            # read-only: the backend re-sends them only after a rate-limited call changed them
            lb, ub = self._lb, self._ub
            rhs = self._rhs0
        else:
            lb, ub = self._lb.copy(), self._ub.copy()
            lb[:-1], ub[:-1] = self._to_x(lo), self._to_x(hi)
            rhs = matvec(self._QBs, u0 - self._c0)
        x = None
        if self.simplex:
            # writable, contiguous arrays only: one compiled signature (a pickled copy's arrays are writable)
            if lb is self._lb:
                x0, xlo, xhi = self._x0, self._xlo, self._xhi
            else:
                xlo, xhi = lb[:-1].copy(), ub[:-1].copy()
                x0 = np.minimum(np.maximum(self._to_x(u0), xlo), xhi)
            xs = np.empty(p.m)
            qd = -A[:, -1]
            code, t, it = _ray_simplex.dual_ray(self._Ax, qd, x0, xlo, xhi, self._G, self._cnorm,
                                                self._max_pivots, xs)
            if code != _ray_simplex.OPTIMAL:
                code, t, it = _ray_simplex.solve_ray(self._F, -A[:, -1], x0, xlo, xhi, float(ub[-1]),
                                                     self._max_pivots, self._work, self._iwork, xs, self._G,
                                                     self._cnorm)
            if code == _ray_simplex.OPTIMAL:
                x = np.append(xs, t)
            else:
                self.simplex_fallbacks += 1
        if x is None:
            x, it = self._model.solve(A=A, lb=lb, ub=ub, bl=rhs, bu=rhs)
        ustar = np.minimum(np.maximum(self._c0 + self._D * x[:-1], lo), hi)
        a = float(x[-1]) * (self._sigma / norm)
        if self._Q.shape[0] == p.k:
            a, ustar, _ = facet_polish(self._B, ustar, d, u0, lo, hi, a)
        return a, ustar, it

    def solve_batch(self, V, lo, hi):
        return None

    def solve(self, v, lo, hi, u_prev):
        p = self.problem
        if self.simplex and lo is p.umin and hi is p.umax:
            # the nominal call in one compiled pass (alloc._engine._ray_simplex.ray_call); the path below
            # only when the dual walk stops
            code, u, it = _ray_simplex.ray_call(v, self._Bu0, self._u0, self._B, self._Q, self._Ax, self._G,
                                                self._cnorm, self._x0, self._xlo, self._xhi, self._c0, self._D,
                                                self._umin, self._umax, self._sigma, self._max_pivots)
            if code == _ray_simplex.OPTIMAL:
                return u, it
        if lo is p.umin and hi is p.umax:
            u0, Bu0 = self._u0, self._Bu0
        else:
            u0 = np.minimum(np.maximum(p.up, lo), hi)
            Bu0 = matvec(self._B, u0)
        d = v - Bu0
        if self._Q.shape[0] != p.k:
            # Only the part of the demand in the range of B can be reached; the rest is
            # reported as unallocated (rank-deficient B).
            d = rmatvec(self._Q, matvec(self._Q, d))
        if not float(np.abs(d).max()) > 1e-14 * max(1.0, float(np.abs(v).max())):
            return u0, 0
        a, ustar, it = self.boundary(d, u0, lo, hi)
        if a >= 1.0:
            return u0 + (ustar - u0) / a, it  # Eq 1.15: scale the boundary solution back
        return ustar, it
