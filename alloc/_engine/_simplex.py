"""Compiled lexicographic L1 linear program of the ``lp`` method (seed Eqs 1.18-1.19).

One call solves, in scaled variables, the sequence of linear programs

    stage 1, level 1 .. L:  min  sum_{i in level} wv_i |(B u - v)_i|
    stage 2:                min  sum_j wu_j |u_j - up_j|
    tie-break:              min  sum_j t_j u_j / D_j       (fixed generic t_j in [1, 2))

each over the optimal set of the stages before it, subject to ``lo <= u <= hi``.  It is a
dense bounded-variable primal simplex on the tableau of

    A (p - n) - e+ + e- = b,     u = c + D (p - n),

with ``c = clip(up, lo, hi)``, ``D`` the problem's half-widths ``(umax - umin) / 2``,
``p, n`` in ``[0, (hi - c) / D]``, ``[0, (c - lo) / D]``, ``e+, e- >= 0`` the scaled
moment errors, ``A = diag(1/rho) B D`` with ``rho_i`` the largest entry of row ``i`` of
``B D`` (every entry of ``A`` in ``[-1, 1]``, whatever the magnitudes of ``B`` and the
limits) and ``b = (v - B c) / rho``.  Because ``|u_j - up_j| = |c_j - up_j| + D_j (p_j + n_j)``
for admissible ``u``, stage 2 is linear in ``p, n``.

Canonical answer (history independence by construction): every call starts from the same
basis -- all ``p, n`` at zero (``u = c``), the slack of each row basic with the sign of
``b_i`` -- which is feasible, so there is no phase 1.  A later stage optimises over the
earlier stages' optimal set by fixing every nonbasic variable whose reduced cost there is
nonzero (the optimal face of an LP is the feasible set with those variables at their
bounds).  The last stage, a generic linear function of ``u``, makes the optimum unique
except on a measure-zero set of data, so ``u`` is a function of the call's data (not of
the pivot path) wherever the first two stages leave a face of optima.  Pricing is Dantzig's
rule, switching to Bland's smallest-index rule after ``BLAND_AFTER`` consecutive degenerate
pivots (no cycling); the tableau is refactorised from the basis every ``REFACTOR_EVERY``
pivots and at the end of every stage.  The iteration count is bounded: reaching it, or a
singular basis, returns an error code (the allocator answers with its fallback).
"""

from __future__ import annotations

import numpy as np
import alloc._engine._kernel_cache  # noqa: F401 - kernel caches placed before any kernel is decorated
from numba import njit

__all__ = ["OPTIMAL", "ITERATION_LIMIT", "NUMERICAL", "solve_lexicographic", "tie_break_weights"]

OPTIMAL, ITERATION_LIMIT, NUMERICAL = 0, 1, 2
#: consecutive degenerate pivots before Bland's rule takes over (anti-cycling)
BLAND_AFTER = 8
#: pivots between refactorisations of the tableau from the basis
REFACTOR_EVERY = 32
#: reduced-cost tolerance (costs are normalised to a largest entry of 1)
DUAL_TOL = 1e-10
#: smallest admissible pivot element (the tableau's columns are O(1) by the scaling)
PIVOT_TOL = 1e-10
#: largest scaled right-hand side; beyond the reach of any column the sign alone matters
B_CLAMP = 1e200
#: ratio-test ties: steps within this relative distance of the smallest tie (largest pivot wins)
TIE_RTOL = 1e-12
#: a pivot whose step is at most this is degenerate (counted towards Bland's rule)
DEGENERATE_TOL = 1e-12
#: a refactorisation pivot at most this (the basis columns are O(1)) means a singular basis
SINGULAR_TOL = 1e-13
#: the final basic values may leave their bounds by this relative round-off
FEASIBLE_RTOL = 1e-9

_LOWER, _UPPER, _BASIC = 1, 2, 0


def tie_break_weights(m: int) -> np.ndarray:
    """The fixed generic weights ``t_j = 1 + frac((j + 1) phi)`` of the tie-break stage."""
    golden = 0.6180339887498949
    return 1.0 + np.mod((np.arange(m) + 1.0) * golden, 1.0)


@njit(cache=True, nogil=True, _nrt=False)
def _eliminate(T, r, q):  # pragma: no cover - compiled
    """Gauss-Jordan step: scale row ``r`` to ``T[r, q] = 1`` and clear column ``q`` elsewhere."""
    k, n = T.shape
    piv = T[r, q]
    for j in range(n):
        T[r, j] /= piv
    for i in range(k):
        if i != r:
            f = T[i, q]
            if f != 0.0:
                for j in range(n):
                    T[i, j] -= f * T[r, j]


@njit(cache=True, nogil=True, _nrt=False)
def _refactor(F, basis, status, x, b, cost, T, d, W):  # pragma: no cover - compiled
    """Tableau ``T = M^-1 F``, basic values and reduced costs from the basis (Gauss-Jordan
    on ``W = [M | F | b - N x_N]``, partial pivoting); False when ``M`` is numerically singular."""
    k, N = F.shape
    for i in range(k):
        for r in range(k):
            W[i, r] = F[i, basis[r]]
        s = b[i]
        for j in range(N):
            W[i, k + j] = F[i, j]
            if status[j] != _BASIC and x[j] != 0.0:
                s -= F[i, j] * x[j]
        W[i, k + N] = s
    for c in range(k):
        piv, best = c, abs(W[c, c])
        for i in range(c + 1, k):
            if abs(W[i, c]) > best:
                piv, best = i, abs(W[i, c])
        if not best > SINGULAR_TOL:
            return False
        if piv != c:
            for j in range(k + N + 1):
                W[c, j], W[piv, j] = W[piv, j], W[c, j]
        _eliminate(W, c, c)
    for r in range(k):
        x[basis[r]] = W[r, k + N]
        for j in range(N):
            T[r, j] = W[r, k + j]
    for r in range(k):
        for i in range(k):
            T[i, basis[r]] = 1.0 if i == r else 0.0
    _reduced_costs(T, basis, cost, d)
    for j in range(N):
        if not np.isfinite(T[0, j]) or not np.isfinite(d[j]):
            return False
    return True


@njit(cache=True, nogil=True, _nrt=False)
def _reduced_costs(T, basis, cost, d):  # pragma: no cover - compiled
    k, N = T.shape
    for j in range(N):
        s = cost[j]
        for r in range(k):
            s -= cost[basis[r]] * T[r, j]
        d[j] = s
    for r in range(k):
        d[basis[r]] = 0.0


@njit(cache=True, nogil=True, inline="always")
def _step_to_bound(a, xj, lbj, ubj):  # pragma: no cover - compiled
    """Step of the entering variable at which a basic variable moving at rate ``-a``
    reaches a bound (inf when it does not move or moves towards an infinite bound)."""
    if a > PIVOT_TOL:
        return max((xj - lbj) / a, 0.0)
    if a < -PIVOT_TOL and ubj < np.inf:
        return max((ubj - xj) / -a, 0.0)
    return np.inf


@njit(cache=True, nogil=True, _nrt=False)
def _iterate(T, basis, status, x, lb, ub, d, frozen, budget):  # pragma: no cover - compiled
    """Primal simplex pivots (at most ``budget``); ``(done, pivots)``: done when optimal."""
    k, N = T.shape
    degenerate = 0
    for it in range(budget):
        bland = degenerate >= BLAND_AFTER
        q, best = -1, 0.0
        for j in range(N):
            if status[j] == _BASIC or frozen[j] or not ub[j] > lb[j]:
                continue
            dj = d[j]
            score = -dj if status[j] == _LOWER else dj
            if score > DUAL_TOL and score > best:
                q, best = j, score
                if bland:
                    break
        if q < 0:
            return True, it
        delta = 1.0 if status[q] == _LOWER else -1.0
        # ratio test: the smallest step, ties to the largest pivot (Bland: smallest index)
        t_min = np.inf
        for r in range(k):
            j = basis[r]
            t_min = min(t_min, _step_to_bound(delta * T[r, q], x[j], lb[j], ub[j]))
        flip = ub[q] - lb[q]
        if flip <= t_min:
            if not flip < np.inf:
                return False, it  # unbounded: impossible for these stages (costs bounded below)
            for r in range(k):
                x[basis[r]] -= flip * delta * T[r, q]
            if status[q] == _LOWER:
                status[q], x[q] = _UPPER, ub[q]
            else:
                status[q], x[q] = _LOWER, lb[q]
            degenerate = 0
            continue
        tie = t_min + TIE_RTOL * (1.0 + t_min)
        row, big = -1, 0.0
        for r in range(k):
            a = delta * T[r, q]
            j = basis[r]
            if _step_to_bound(a, x[j], lb[j], ub[j]) <= tie:
                if bland:
                    if row < 0 or basis[r] < basis[row]:
                        row = r
                elif abs(a) > big:
                    row, big = r, abs(a)
        r = row
        a = delta * T[r, q]
        for i in range(k):
            x[basis[i]] -= t_min * delta * T[i, q]
        leave = basis[r]
        if a > 0.0:
            status[leave], x[leave] = _LOWER, lb[leave]
        else:
            status[leave], x[leave] = _UPPER, ub[leave]
        x[q] = (lb[q] if delta > 0 else ub[q]) + delta * t_min
        basis[r] = q
        status[q] = _BASIC
        _eliminate(T, r, q)
        f = d[q]
        for j in range(N):
            d[j] -= f * T[r, j]
        for i in range(k):
            T[i, q] = 0.0
        T[r, q] = 1.0
        d[q] = 0.0
        degenerate = degenerate + 1 if t_min <= DEGENERATE_TOL else 0
    return False, budget


@njit(cache=True, nogil=True)
def solve_lexicographic(F, B, rho, D, up, costs, v, lo, hi, max_iter, work, iwork, u):  # pragma: no cover - compiled
    """Solve the stages (rows of ``costs``) in order; write ``u``; return ``(code, pivots)``.

    ``F = [A, -A, -I, I]`` (k x N, N = 2m + 2k), ``costs`` (S x N, largest entry 1 per row),
    ``work`` a float workspace of at least ``k N + k (k + N + 1) + 4 N + k + m`` entries and ``iwork``
    an int workspace of ``2 N + k``.
    """
    k, N = F.shape
    m = D.shape[0]
    T = work[:k * N].reshape(k, N)
    o = k * N
    W = work[o:o + k * (k + N + 1)].reshape(k, k + N + 1)
    o += k * (k + N + 1)
    x = work[o:o + N]
    lb = work[o + N:o + 2 * N]
    ub = work[o + 2 * N:o + 3 * N]
    d = work[o + 3 * N:o + 4 * N]
    b = work[o + 4 * N:o + 4 * N + k]
    c = work[o + 4 * N + k:o + 4 * N + k + m]
    status = iwork[:N]
    frozen = iwork[N:2 * N]
    basis = iwork[2 * N:2 * N + k]
    for j in range(m):
        cj = min(max(up[j], lo[j]), hi[j])
        c[j] = cj
        if D[j] > 0.0:
            ub[j] = max((hi[j] - cj) / D[j], 0.0)
            ub[m + j] = max((cj - lo[j]) / D[j], 0.0)
        else:
            ub[j] = 0.0
            ub[m + j] = 0.0
    for j in range(N):
        lb[j] = 0.0
        x[j] = 0.0
        status[j] = _LOWER
        frozen[j] = 0
    for i in range(k):
        ub[2 * m + i] = np.inf
        ub[2 * m + k + i] = np.inf
        s = v[i]
        for j in range(m):
            s -= B[i, j] * c[j]
        bi = s / rho[i]
        if not bi <= B_CLAMP:
            bi = B_CLAMP if not bi < 0.0 else -B_CLAMP
        if bi < -B_CLAMP:
            bi = -B_CLAMP
        b[i] = bi
        # canonical start: the slack whose sign matches b_i is basic (e- for b_i >= 0)
        j = 2 * m + k + i if bi >= 0.0 else 2 * m + i
        basis[i] = j
        status[j] = _BASIC
        x[j] = abs(bi)
        sgn = 1.0 if bi >= 0.0 else -1.0
        for jj in range(N):
            T[i, jj] = sgn * F[i, jj]
    pivots = 0
    for s in range(costs.shape[0]):
        cost = costs[s]
        _reduced_costs(T, basis, cost, d)
        since = 0
        while True:
            budget = min(REFACTOR_EVERY, max_iter - pivots)
            done, n = _iterate(T, basis, status, x, lb, ub, d, frozen, budget)
            pivots += n
            since += n
            if since > 0 or not done:
                if not _refactor(F, basis, status, x, b, cost, T, d, W):
                    return NUMERICAL, pivots
                since = 0
                if not done:
                    if pivots >= max_iter:
                        return ITERATION_LIMIT, pivots
                    continue
                # optimal before the refactorisation: confirm on the fresh reduced costs
                ok = True
                for j in range(N):
                    if status[j] != _BASIC and not frozen[j] and ub[j] > lb[j]:
                        sc = -d[j] if status[j] == _LOWER else d[j]
                        if sc > DUAL_TOL:
                            ok = False
                            break
                if not ok:
                    if pivots >= max_iter:
                        return ITERATION_LIMIT, pivots
                    continue
            break
        # the next stages stay on this stage's optimal face
        for j in range(N):
            if status[j] == _LOWER and d[j] > DUAL_TOL:
                frozen[j] = 1
            elif status[j] == _UPPER and d[j] < -DUAL_TOL:
                frozen[j] = 1
    for j in range(N):
        if not np.isfinite(x[j]):
            return NUMERICAL, pivots
        tol = FEASIBLE_RTOL * (1.0 + abs(x[j]))
        if x[j] < lb[j] - tol or x[j] > ub[j] + tol:
            return NUMERICAL, pivots
    for j in range(m):
        u[j] = min(max(c[j] + D[j] * (x[j] - x[m + j]), lo[j]), hi[j])
    return OPTIMAL, pivots


def _normalised(c: np.ndarray) -> np.ndarray:
    """``c / max(c)`` computed in logarithms (weights from 1e-50 to 1e50 times row scales
    neither overflow nor underflow before the division); zero rows stay zero."""
    out = np.zeros_like(c)
    pos = c > 0
    if pos.any():
        lg = np.log(c[pos])
        out[pos] = np.exp(lg - lg.max())
    return out


class LexicographicL1:
    """The two-stage weighted L1 allocation LP of one problem, solved by
    :func:`solve_lexicographic` (data scaled and laid out once; no state between calls).

    Parameters
    ----------
    B, umin, umax, up
        The problem's effectiveness matrix, position limits and preferred position.
    wv, wu
        Positive weight vectors of stage 1 (per axis) and stage 2 (per effector).
    groups
        Axis index arrays, most important level first (one group: no priorities).
    """

    def __init__(self, B: np.ndarray, umin: np.ndarray, umax: np.ndarray, up: np.ndarray,
                 wv: np.ndarray, wu: np.ndarray, groups: list[np.ndarray]) -> None:
        k, m = B.shape
        N = 2 * m + 2 * k
        D = (np.asarray(umax, dtype=float) - np.asarray(umin, dtype=float)) / 2.0
        BD = B * D
        rho = np.abs(BD).max(axis=1) if m else np.zeros(k)
        rho = np.where(np.isfinite(rho) & (rho > 0), rho, 1.0)
        A = BD / rho[:, None]
        I = np.eye(k)
        self._F = np.ascontiguousarray(np.hstack([A, -A, -I, I]))
        costs = []
        with np.errstate(divide="ignore", over="ignore", under="ignore", invalid="ignore"):
            for rows in groups:
                c = np.zeros(N)
                c[2 * m + rows] = np.asarray(wv, dtype=float)[rows] * rho[rows]
                c[2 * m + k + rows] = c[2 * m + rows]
                costs.append(_normalised(np.where(np.isfinite(c), c, np.finfo(float).max)))
            c = np.zeros(N)
            c[:m] = np.asarray(wu, dtype=float) * D
            c[m:2 * m] = c[:m]
            costs.append(_normalised(np.where(np.isfinite(c), c, np.finfo(float).max)))
        t = tie_break_weights(m)
        c = np.zeros(N)
        c[:m], c[m:2 * m] = t / 2.0, -t / 2.0  # sum_j t_j (u_j - c_j) / D_j, scaled to max 1
        costs.append(c)
        self._costs = np.ascontiguousarray([c for c in costs if np.abs(c).max() > 0] or [np.zeros(N)])
        self._B = np.ascontiguousarray(B, dtype=float)
        self._rho, self._D = rho, np.ascontiguousarray(D)
        self._up = np.ascontiguousarray(up, dtype=float)
        self._work = np.zeros(k * N + k * (k + N + 1) + 4 * N + k + m)
        self._iwork = np.zeros(2 * N + k, dtype=np.int64)
        self.max_iter = 50 * (N + k)

    # The scaled problem, read by the C generator (alloc.export_data.SimplexData); not to be written.
    @property
    def F(self) -> np.ndarray:
        """The scaled tableau ``[A, -A, -I, I]`` (k x N)."""
        return self._F

    @property
    def rho(self) -> np.ndarray:
        """The row scales of the tableau."""
        return self._rho

    @property
    def D(self) -> np.ndarray:
        """The half-widths of the limits (the column scaling)."""
        return self._D

    @property
    def costs(self) -> np.ndarray:
        """The stages' normalised cost rows."""
        return self._costs

    def solve(self, v: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, int, int]:
        """``(u, code, pivots)`` for demand ``v`` within ``[lo, hi]`` (``code`` 0: optimal)."""
        u = np.empty(self._D.shape[0])
        code, pivots = solve_lexicographic(self._F, self._B, self._rho, self._D, self._up, self._costs,
                                           v, lo, hi, self.max_iter, self._work, self._iwork, u)
        return u, int(code), int(pivots)
