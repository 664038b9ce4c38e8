"""Ganging (seed section 1.3.4.1): a static distribution matrix, clipped to limits."""

from __future__ import annotations

import numpy as np

from .._kernels import affine
from ..exceptions import ProblemError
from ..options import matrix
from ..problem import Problem
from ..registry import Method, register
from .pseudo_inverse import distribution_matrix


@register("ganging", affine=True, supports_batch=True)
class Ganging(Method):
    """``u = up + G v`` clipped to the limits.

    ``G`` (m x k) is the user's static distribution matrix, e.g. the seed's Eq 4.19
    for the F-18/HARV lateral-directional model.  Without ``G`` the design-time
    pseudo-inverse of Eq 1.23 is frozen as the gang (as the seed does for ICE, Eq 4.24).
    The bias ``up`` is added so that ``G`` acts on increments about the preferred
    position (``up = 0`` for surfaces whose limits contain zero).
    """

    equation = "section 1.3.4.1"
    summary = "static distribution matrix G (default: Eq 1.23 frozen at design time), clipped"
    options = {"G": matrix("static distribution matrix, shape (m, k); default: Eq 1.23 at design time")}

    def __init__(self, problem: Problem, *, G=None) -> None:
        super().__init__(problem)
        if G is None:
            G_arr = distribution_matrix(problem)
        else:
            try:
                G_arr = np.array(G, dtype=float)
            except (TypeError, ValueError) as exc:
                raise ProblemError(f"G: not a numeric matrix ({exc})") from exc
            if G_arr.shape != (problem.m, problem.k):
                raise ProblemError(f"G: expected shape ({problem.m}, {problem.k}), got {G_arr.shape}")
            if not np.isfinite(G_arr).all():
                raise ProblemError("G: non-finite values")
        self.G = G_arr
        self._GT = np.ascontiguousarray(G_arr.T)
        self.fused = (np.array(problem.up), np.ascontiguousarray(G_arr))

    def solve(self, v, lo, hi, u_prev):
        return affine(self.problem.up, self.G, v), 0  # clipped by the allocator

    def solve_batch(self, V, lo, hi):
        return np.minimum(np.maximum(self.problem.up + V @ self._GT, lo), hi)
