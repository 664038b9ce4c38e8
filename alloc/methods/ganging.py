"""Ganging (seed section 1.3.4.1): a static distribution matrix, clipped to limits."""

from __future__ import annotations

import numpy as np

from .._engine._inverse_kernels import affine, affine_clip_batch
from ..exceptions import ProblemError
from ..export_data import AffineData
from ..options import matrix
from ..problem import Problem, as_float_array, check_magnitude
from ..method import Method, register
from .pseudo_inverse import distribution_matrix


@register("ganging", affine=True, supports_batch=True, export="affine")
class Ganging(Method):
    """``u = up + G (v - B up)`` clipped to the limits.

    ``G`` (m x k) is the user's static distribution matrix, e.g. the seed's Eq 4.19
    for the F-18/HARV lateral-directional model.  Without ``G`` the design-time
    pseudo-inverse of Eq 1.23 is frozen as the gang (as the seed does for ICE, Eq 4.24).
    ``G`` acts on the demand's increment about what the preferred position already
    produces, ``B up``: with ``B G = I`` the command meets ``B u = v`` wherever it is
    admissible, for any ``up`` (hover thrust, mid-range surfaces).  The map is affine,
    ``u = c + G v`` with ``c = up - G B up``.
    """

    equation = "section 1.3.4.1"
    summary = "static distribution matrix G (default: Eq 1.23 frozen at design time), clipped"
    options = {"G": matrix("static distribution matrix, shape (m, k); default: Eq 1.23 at design time")}
    distribution_option = "G"

    def __init__(self, problem: Problem, *, G=None) -> None:
        super().__init__(problem)
        if G is None:
            G_arr = distribution_matrix(problem)
        else:
            G_arr = as_float_array("G", G)
            if G_arr.shape != (problem.m, problem.k):
                raise ProblemError(f"G: expected shape ({problem.m}, {problem.k}), got {G_arr.shape}")
            check_magnitude("G", G_arr)  # the valid input domain, as for B
        self.G = G_arr
        self._G = np.ascontiguousarray(G_arr)
        self._c = problem.up - self._G @ (problem.B @ problem.up)
        self.fused = (self._c, self._G)

    def solve(self, v, lo, hi, u_prev):
        return affine(self._c, self._G, v), 0  # clipped by the allocator

    def solve_batch(self, V, lo, hi):
        return affine_clip_batch(self._c, self._G, np.ascontiguousarray(V), lo, hi)

    def export_data(self) -> AffineData:
        return AffineData(c=self._c, P=self._G)
