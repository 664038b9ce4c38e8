"""Weighted pseudo-inverse family (seed section 1.3.4.5, Eq 1.23).

``pinv``
    ``u = up + P (v - B up)``, ``P = Wu^-1 B' (B Wu^-1 B')^-1`` (Eq 1.23).  The unconstrained
    solution is returned where it is admissible; where it is not, the individual commands
    are clipped (so ``pinv`` and ``pinv_clip`` return the same command; ``pinv`` is the
    seed's name for the design distribution of Eq 4.23/4.24).
``pinv_clip``
    Eq 1.23 with the individual commands clipped to their limits (does not preserve the
    direction of the moment).
``pinv_scale``
    The direction-preserving weighted pseudo-inverse: the whole increment from the
    preferred position is scaled by one factor until every effector is admissible.

Jammed effectors (``umin == umax``) are removed from the inverse and held at their
position; axes no free effector reaches (singular values below ``rcond * s_max``) get
no command, and the unreached part of ``v`` is reported as ``Result.unallocated``.

Option ``incremental=True`` is the discrete-time weighted pseudo-inverse that Page and
Steinberg found best in closed loop (seed section 1.3.4.9): with ``u_prev`` given, the
bias point is the previous command, ``u = u_prev + P (v - B u_prev)``.
"""

from __future__ import annotations

import numpy as np

from .._engine._inverse_kernels import (affine, affine_clip_batch, fused_scaled, increment, scaled_increment,
                                scaled_increment_batch)
from .._engine._linalg import RCOND, check_rcond, max_scale, weighted_pinv
from ..exceptions import OptionError, SolverError
from ..export_data import AffineData, ScaledData
from ..options import flag, real
from ..problem import MAX_MAGNITUDE, Problem
from ..method import FloatArray, Method, register
from ..result import EXACT_RTOL

_OPTIONS = {
    "rcond": real(RCOND, "relative singular-value cut-off of the inverse", low=0.0, high=1.0, high_open=True),
    "incremental": flag(False, "bias at u_prev instead of up when u_prev is given (discrete-time pseudo-inverse)"),
}


def distribution_matrix(problem: Problem, rcond: float = RCOND) -> FloatArray:
    """Eq 1.23 distribution matrix ``P`` (m x k) over the non-jammed effectors."""
    P = np.zeros((problem.m, problem.k))
    free = ~problem.jammed
    if free.any():
        P[free] = weighted_pinv(problem.B[:, free], problem.Wu[np.ix_(free, free)], problem.Wv, rcond=rcond)
    return P


class _PinvBase(Method):
    equation = "Eq 1.23"
    options = _OPTIONS

    def __init__(self, problem: Problem, *, rcond: float = RCOND, incremental: bool = False) -> None:
        super().__init__(problem)
        rcond = check_rcond(rcond, self.name)
        self.P = distribution_matrix(problem, rcond)
        if not isinstance(incremental, (bool, np.bool_)):
            raise OptionError(f"{self.name}: incremental must be True or False, got {incremental!r}")
        self.incremental = bool(incremental)
        # u = c + P v with c = up - P B up: one matrix-vector product per call.
        self.c = problem.up - self.P @ (problem.B @ problem.up)
        self._P = np.ascontiguousarray(self.P)
        # writable contiguous copies: the compiled kernels see one array type (no recompiles)
        self._B = np.array(problem.B)
        self._up = np.array(problem.up)

    def _unconstrained(self, v: FloatArray, u_prev: FloatArray | None) -> FloatArray:
        if self.incremental and u_prev is not None:
            return increment(self._P, self._B, u_prev, v)  # fixed order: bit for bit in any copy
        return affine(self.c, self.P, v)


@register("pinv", affine=True, supports_batch=True, export="affine")
class Pinv(_PinvBase):
    summary = "biased weighted pseudo-inverse, min (u-up)'Wu(u-up) s.t. Bu=v; clipped where inadmissible"

    def __init__(self, problem: Problem, **options) -> None:
        super().__init__(problem, **options)
        self.fused = (self.c, self._P)

    def solve(self, v, lo, hi, u_prev):
        # clipping to [lo, hi] is done by the allocator's compiled finish step
        return self._unconstrained(v, u_prev), 0

    def solve_batch(self, V, lo, hi):
        return affine_clip_batch(self.c, self._P, np.ascontiguousarray(V), lo, hi)

    def export_data(self) -> AffineData:
        return AffineData(c=self.c, P=self._P)


@register("pinv_clip", affine=True, supports_batch=True, export="affine")
class PinvClip(Pinv):
    summary = "Eq 1.23 with individual commands clipped to their limits"


@register("pinv_scale", supports_batch=True, export="scaled")
class PinvScale(_PinvBase):
    summary = "direction-preserving weighted pseudo-inverse: the increment scaled by one factor"

    def _bias(self, u_prev: FloatArray | None) -> FloatArray:
        return u_prev if (self.incremental and u_prev is not None) else self._up

    def _base(self, lo: FloatArray, hi: FloatArray, u_prev: FloatArray | None) -> FloatArray:
        return np.minimum(np.maximum(self._bias(u_prev), lo), hi)

    def __init__(self, problem: Problem, **options) -> None:
        super().__init__(problem, **options)
        # without rate limits (bias up): one compiled call through the allocator's fast path
        base = np.ascontiguousarray(self._base(problem.umin, problem.umax, None), dtype=float)
        self.packed = (fused_scaled, (self._P, self._B, base, np.array(problem.umin), np.array(problem.umax),
                                      EXACT_RTOL, MAX_MAGNITUDE))

    def affine_map(self):
        # unscaled where admissible: u = base + P (v - B base), base = up clipped to the limits
        base = self._base(self.problem.umin, self.problem.umax, None)
        return base - self.P @ (self.problem.B @ base), self.P

    def solve(self, v, lo, hi, u_prev):
        return scaled_increment(self._P, self._B, self._bias(u_prev), v, lo, hi), 0

    def _solve_reference(self, v, lo, hi, u_prev):
        """The scaling in numpy (what :func:`alloc._engine._inverse_kernels.scaled_increment` computes, compiled)."""
        base = self._base(lo, hi, u_prev)
        du = self.P @ (v - self.problem.B @ base)
        return base + max_scale(base, du, lo, hi) * du, 0

    def solve_batch(self, V, lo, hi):
        return scaled_increment_batch(self._P, self._B, self._up, np.ascontiguousarray(V), lo, hi)

    def export_data(self) -> ScaledData:
        return ScaledData(P=self._P)


class SafeCommand:
    """The documented safe answer returned with ``status="fallback"``.

    The weighted pseudo-inverse of Eq 1.23 clipped to the call's bounds: closed form,
    always finite and admissible, and close to the optimisers' answers for attainable
    demands.  It never raises: where even the pseudo-inverse cannot be formed (or its
    command is not finite) the answer is the preferred position clipped to the bounds.
    """

    def __init__(self, problem: Problem) -> None:
        self._up = problem.up
        try:
            self._pinv: Pinv | None = Pinv(problem)
        except SolverError:
            self._pinv = None

    def __call__(self, v: FloatArray, lo: FloatArray, hi: FloatArray) -> FloatArray:
        u = self._up if self._pinv is None else self._pinv.solve(v, lo, hi, None)[0]
        if not np.isfinite(u).all():
            u = self._up
        return np.minimum(np.maximum(u, lo), hi)

    def affine_map(self) -> AffineData | None:
        """``u = clip(c + P v)`` of the safe answer (the preferred position clipped where the
        pseudo-inverse could not be formed: ``None``)."""
        return None if self._pinv is None else self._pinv.export_data()
