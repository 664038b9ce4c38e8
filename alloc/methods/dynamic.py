"""Dynamic control allocation (Härkegård 2002, "Dynamic control allocation using
constrained quadratic programming", AIAA GNC; after seed Eqs 1.20-1.21).

``dynamic``
    Two-stage like ``qp``.  Stage 1 (Eq 1.20): the moments closest to ``v`` in the ``Wv``
    norm over the (rate-limited) box.  Stage 2: over the commands achieving that moment,

        minimise  ||W1 (u - u_s)||^2 + ||W2 (u - u_prev)||^2,

    where ``u_s = up + P (v - B up)`` is the static distribution (Eq 1.23, the weighted
    pseudo-inverse of the problem's ``Wu``) and ``u_prev`` the previous command.  The
    ``W2`` term penalises movement, so actuator usage becomes frequency dependent: without
    active limits the part of ``u`` that does not change the moment is a first-order filter
    of ``u_s`` (for scalar weights, ``u_N(t) = a u_N(t-T) + (1-a) u_s,N(t)`` with
    ``a = w2^2 / (w1^2 + w2^2)``), so slow demands are met with the static distribution
    and fast ones by whichever effectors the weights make cheap to move.

    The cost is ``(u - c)' Wd (u - c)`` plus a constant, ``Wd = W1'W1 + W2'W2``,
    ``c = Wd^-1 (W1'W1 u_s + W2'W2 u_prev)``: stage 2 of ``qp`` with ``Wu = Wd`` and
    ``up = c``, solved by the same compiled active set (:mod:`alloc._engine._active_set`).
    Without ``u_prev`` (the first call) the ``W2`` term is absent and ``u`` is the
    two-stage allocation closest to ``u_s``.  The method keeps no state between calls:
    the caller (the simulator's loop) passes ``u_prev``.
"""

from __future__ import annotations

import math

import numpy as np

from .._engine._linalg import sqrt_factor
from ..exceptions import OptionError, ProblemError
from ..export_data import ActiveSetData
from ..domain import singular_within_round_off
from ..problem import MAX_MAGNITUDE, MIN_WEIGHT, Problem, as_float_array, check_magnitude
from ..options import flag, weight
from ..method import FloatArray, Method, register
from .pseudo_inverse import distribution_matrix
from .quadratic import ACTIVE_SET, WARM_START_DOC, LexicoLS, check_warm_backend


#: Range of the singular values of ``W1`` and ``W2``: their squares ``W'W`` and the sum
#: ``Wd = W1'W1 + W2'W2`` (the stages' preference weights) then have eigenvalues within the
#: valid domain ``[MIN_WEIGHT, MAX_MAGNITUDE]`` with a factor 10 to spare for round-off.
W_MIN = math.sqrt(10.0 * MIN_WEIGHT)
W_MAX = math.sqrt(MAX_MAGNITUDE / 20.0)


def _weight(value: object, m: int, field: str) -> FloatArray:
    """``W`` (m x m) from None (identity), a positive scalar, a vector (diagonal) or a matrix.

    Every singular value must lie in ``[W_MIN, W_MAX]``; OptionError naming ``field`` otherwise.
    """
    if value is None:
        return np.eye(m)
    arr = as_float_array(field, value, OptionError)
    check_magnitude(field, arr, OptionError)
    if arr.ndim == 0:
        arr = np.full(m, float(arr))
    if arr.ndim == 1:
        if arr.shape != (m,):
            raise OptionError(f"{field}: expected {m} weights, got {arr.shape[0]}")
        if (arr <= 0).any():
            i = int(np.argmax(arr <= 0))
            raise OptionError(f"{field}: weight {field}[{i}] = {arr[i]:g} is not positive")
        sv, out = arr, np.diag(arr)
    elif arr.shape == (m, m):
        sv, out = np.linalg.svd(arr, compute_uv=False), arr
        if singular_within_round_off(arr, float(sv.min()), float(sv.max())):
            raise OptionError(f"{field}: matrix is singular within round-off (singular values "
                              f"[{sv.min():.3g}, {sv.max():.3g}], ratio below {m} x machine epsilon)")
    else:
        raise OptionError(f"{field}: expected a scalar, {m} weights or a {m} x {m} matrix, got shape {arr.shape}")
    lo, hi = float(sv.min()), float(sv.max())
    if lo < W_MIN or hi > W_MAX:
        raise OptionError(f"{field}: singular values must lie in [{W_MIN:.3g}, {W_MAX:.3g}] (so that {field}'{field} "
                          f"is a weight of the valid domain), got [{lo:.3g}, {hi:.3g}]")
    return out


@register("dynamic", supports_batch=True, export="active_set")
class DynamicAllocation(Method):
    equation = "Eqs 1.20-1.21 with Härkegård (2002) dynamic cost"
    summary = "stage 1 min moment error, stage 2 min ||W1(u-u_s)||^2 + ||W2(u-u_prev)||^2 at that moment"
    options = {
        "W1": weight("weight of the distance to the static distribution u_s (scalar, vector or matrix; default I)"),
        "W2": weight("weight of the movement from u_prev (scalar, vector or matrix; default I)"),
        "warm_start": flag(False, WARM_START_DOC + "; one working set each for calls with and without u_prev"),
    }

    def __init__(self, problem: Problem, *, W1: object = None, W2: object = None, warm_start: bool = False) -> None:
        super().__init__(problem)
        warm = check_warm_backend(warm_start, ACTIVE_SET, "dynamic")
        p = problem
        m = p.m
        W1m = _weight(W1, m, "W1")
        W2m = _weight(W2, m, "W2")
        Q1, Q2 = W1m.T @ W1m, W2m.T @ W2m
        Wd = Q1 + Q2
        Wd = 0.5 * (Wd + Wd.T)
        sqrt_factor(Wd)  # raises LinAlgError if not positive definite (cannot happen: W1 nonsingular)
        self.P = distribution_matrix(p)  # the static distribution u_s = up + P (v - B up)
        Wd_inv = np.linalg.inv(Wd)
        self._M1 = Wd_inv @ Q1
        self._M2 = Wd_inv @ Q2
        # the target, linear in v and u_prev, is formed in the compiled call:
        # u_s = c0 + P v, c = M1 u_s + M2 u_prev
        c0 = p.up - self.P @ (p.B @ p.up)
        try:  # the stages check Q1 and Wd as a problem's Wu: name the options the caller gave
            self._static = LexicoLS(p, [np.arange(p.k)], [0.0], final=True, Wu=Q1,  # no u_prev
                                    target=(c0, self.P, np.zeros((m, m))), warm_start=warm)
            self._dynamic = LexicoLS(p, [np.arange(p.k)], [0.0], final=True, Wu=Wd,
                                     target=(self._M1 @ c0, self._M1 @ self.P, self._M2), warm_start=warm)
        except ProblemError as exc:
            if exc.field != "Wu":
                raise
            raise OptionError(f"W1/W2: {str(exc).removeprefix('Wu: ')} (the stage weight formed from W1 and W2)",
                              field="W1") from exc
        self.packed, self.packed_rate = self._static.packed, self._dynamic.packed

    def static_command(self, v: FloatArray) -> FloatArray:
        """``u_s``: the static distribution of Eq 1.23 (not clipped)."""
        up = self.problem.up
        return up + self.P @ (v - self.problem.B @ up)

    def target(self, v: FloatArray, u_prev: FloatArray | None) -> FloatArray:
        """``c``: the unconstrained minimiser of the stage-2 cost."""
        us = self.static_command(v)
        if u_prev is None:
            return us
        return self._M1 @ us + self._M2 @ u_prev

    def solve(self, v, lo, hi, u_prev):
        if u_prev is None:
            return self._static.solve(v, lo, hi)
        return self._dynamic.solve(v, lo, hi, u_prev)  # a non-finite target: SolverError (fallback)

    def solve_batch(self, V: FloatArray, lo: FloatArray, hi: FloatArray) -> FloatArray:
        """Rows without ``u_prev`` (a batch has no history): the static stage's compiled batch."""
        return self._static.solve_batch(V, lo, hi)

    def batch_finished(self, V: FloatArray) -> tuple[FloatArray, FloatArray, np.ndarray]:
        """The static stage's compiled solve-and-classify pass (rows without ``u_prev``)."""
        return self._static.batch_finished(V)

    def export_data(self) -> ActiveSetData:
        """The two solver instances' states: without ``u_prev`` (static), then with it."""
        return ActiveSetData(states=(self._static.state, self._dynamic.state))
