"""Compiled bounded-variable simplex for ``da``'s ray LP (seed Eqs 1.15-1.17).

In the scaled variables of :class:`alloc.methods._direct_lp.RayLP` (``u = c + D x``,
``x`` in ``[-1, 1]``, ``A = Q B D / sigma``, ``q = Q d / |d|``) the ray LP is

    maximise t   subject to   A x - t q = A x0,   lb <= x <= ub,   0 <= t <= t_max,

``x0`` the base point.  Written about the base point, ``x = x0 + p - n`` with ``p, n >= 0``,
it is ``A p - A n - t q + e = 0`` with one artificial ``e_i`` per row fixed at ``[0, 0]``.
Every call starts from the same basis -- the artificials, all at zero, everything else at its
lower bound (``u = u0``, ``t = 0``) -- which is feasible, so there is no phase 1: the first
pivots swap the artificials out at step 0 and never let them back (their bounds are equal).
The pivots are :mod:`alloc._simplex`'s (Dantzig's rule, Bland's after degenerate pivots,
refactorisation every ``REFACTOR_EVERY`` pivots), so the answer is a function of the call's
data, not of earlier calls.

Why not the DAQP model: a proximal-point LP solve costs 86 us at k = 4, m = 24 and 434 us at
m = 96, 2.2 ms at m = 192 (super-linear: its iterations grow with m and each is O(m^2) in the
normal equations); a simplex pivot here is O(k N) with N = 2 m + k + 1 and a ray crosses
few vertices (``benchmarks/bench_da_cost.py --large``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ._simplex import (_BASIC, _LOWER, _UPPER, BLAND_AFTER, DEGENERATE_TOL, DUAL_TOL, FEASIBLE_RTOL,
                       ITERATION_LIMIT, NUMERICAL, OPTIMAL, REFACTOR_EVERY, TIE_RTOL, _eliminate, _reduced_costs,
                       _refactor, _step_to_bound)

__all__ = ["ray_matrix", "solve_ray", "work_sizes", "OPTIMAL", "ITERATION_LIMIT", "NUMERICAL"]


def ray_matrix(A: np.ndarray) -> np.ndarray:
    """``F = [A, -A, 0, I]`` (k x N, N = 2 m + 1 + k); column ``2 m`` (``-q``) is filled per call."""
    k, m = A.shape
    F = np.zeros((k, 2 * m + 1 + k))
    F[:, :m] = A
    F[:, m:2 * m] = -A
    F[:, 2 * m + 1:] = np.eye(k)
    return F


def work_sizes(k: int, m: int) -> tuple[int, int]:
    """Float and integer workspace lengths of :func:`solve_ray`."""
    N = 2 * m + 1 + k
    return k * N + k * (k + N + 1) + 5 * N + k, 2 * N + k


@njit(cache=True, nogil=True, inline="always")
def _ratio(T, basis, x, lb, ub, q, delta):  # pragma: no cover - compiled
    """The ratio test of entering column ``q`` moving in direction ``delta``: the smallest step."""
    t_min = np.inf
    for r in range(T.shape[0]):
        j = basis[r]
        t_min = min(t_min, _step_to_bound(delta * T[r, q], x[j], lb[j], ub[j]))
    return t_min


@njit(cache=True, nogil=True, _nrt=False)
def _flip(T, basis, status, x, lb, ub, q, delta):  # pragma: no cover - compiled
    """Move nonbasic ``q`` to its other bound (the basis stays; reduced costs do not change)."""
    flip = ub[q] - lb[q]
    for r in range(T.shape[0]):
        x[basis[r]] -= flip * delta * T[r, q]
    if status[q] == _LOWER:
        status[q], x[q] = _UPPER, ub[q]
    else:
        status[q], x[q] = _LOWER, lb[q]


@njit(cache=True, nogil=True, _nrt=False)
def _iterate_long(T, basis, status, x, lb, ub, d, budget):  # pragma: no cover - compiled
    """Primal pivots with bound flips taken in passes; ``(done, pivots, flips)``.

    A bound flip leaves the basis and the reduced costs as they are, so one pass over the
    columns flips every improving candidate whose flip fits its ratio test (O(k) each) and
    keeps the best one that does not fit for a basis change.  :func:`alloc._simplex._iterate`
    re-prices all N columns after each flip: starting from the base point, nearly every
    effector flips once on the way to the boundary, O(m N) per call -- the super-linear
    growth of ``da``'s LP path in m.  Here a call costs O(N k) per basis change.
    """
    k, N = T.shape
    degenerate = 0
    flips = 0
    for it in range(budget):
        bland = degenerate >= BLAND_AFTER
        q, best = -1, 0.0
        for j in range(N):
            if status[j] == _BASIC or not ub[j] > lb[j]:
                continue
            dj = d[j]
            score = -dj if status[j] == _LOWER else dj
            if not score > DUAL_TOL:
                continue
            delta = 1.0 if status[j] == _LOWER else -1.0
            if ub[j] - lb[j] <= _ratio(T, basis, x, lb, ub, j, delta):
                _flip(T, basis, status, x, lb, ub, j, delta)
                flips += 1
                continue
            if score > best and not (bland and q >= 0):
                q, best = j, score
        if q < 0:
            return True, it, flips
        delta = 1.0 if status[q] == _LOWER else -1.0
        t_min = _ratio(T, basis, x, lb, ub, q, delta)  # later flips in the pass moved the basics
        if ub[q] - lb[q] <= t_min:
            _flip(T, basis, status, x, lb, ub, q, delta)
            flips += 1
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
    return False, budget, flips


@njit(cache=True, nogil=True)
def solve_ray(F, q, x0, lb, ub, t_max, max_iter, work, iwork, x):  # pragma: no cover - compiled
    """Maximise ``t`` (see the module docstring); write ``x``; return ``(code, t, pivots)``.

    ``F`` from :func:`ray_matrix` (its column ``2 m`` is overwritten with ``-q``), ``x0``
    within ``[lb, ub]``; ``work``/``iwork`` of :func:`work_sizes`.
    """
    k, N = F.shape
    m = x0.shape[0]
    jt = 2 * m
    for i in range(k):
        F[i, jt] = -q[i]
    T = work[:k * N].reshape(k, N)
    o = k * N
    W = work[o:o + k * (k + N + 1)].reshape(k, k + N + 1)
    o += k * (k + N + 1)
    xs = work[o:o + N]
    lo = work[o + N:o + 2 * N]
    hi = work[o + 2 * N:o + 3 * N]
    d = work[o + 3 * N:o + 4 * N]
    cost = work[o + 4 * N:o + 5 * N]
    b = work[o + 5 * N:o + 5 * N + k]
    status = iwork[:N]
    frozen = iwork[N:2 * N]
    basis = iwork[2 * N:2 * N + k]
    for j in range(N):
        lo[j] = 0.0
        xs[j] = 0.0
        cost[j] = 0.0
        status[j] = _LOWER
        frozen[j] = 0
    for j in range(m):
        hi[j] = max(ub[j] - x0[j], 0.0)
        hi[m + j] = max(x0[j] - lb[j], 0.0)
    hi[jt] = t_max
    cost[jt] = -1.0
    for i in range(k):
        j = jt + 1 + i
        hi[j] = 0.0
        basis[i] = j
        status[j] = _BASIC
        b[i] = 0.0
        for jj in range(N):
            T[i, jj] = F[i, jj]
    _reduced_costs(T, basis, cost, d)
    pivots = 0
    since = 0
    while True:
        budget = min(REFACTOR_EVERY, max_iter - pivots)
        done, n, nf = _iterate_long(T, basis, status, xs, lo, hi, d, budget)
        pivots += n
        since += n
        if since > 0 or not done:
            if not _refactor(F, basis, status, xs, b, cost, T, d, W):
                return NUMERICAL, 0.0, pivots
            since = 0
            if not done:
                if pivots >= max_iter:
                    return ITERATION_LIMIT, 0.0, pivots
                continue
            # optimal before the refactorisation: confirm on the fresh reduced costs
            ok = True
            for j in range(N):
                if status[j] != _BASIC and hi[j] > lo[j]:
                    sc = -d[j] if status[j] == _LOWER else d[j]
                    if sc > DUAL_TOL:
                        ok = False
                        break
            if not ok:
                if pivots >= max_iter:
                    return ITERATION_LIMIT, 0.0, pivots
                continue
        break
    for j in range(N):
        tol = FEASIBLE_RTOL * (1.0 + abs(xs[j]))
        if not np.isfinite(xs[j]) or xs[j] < lo[j] - tol or xs[j] > hi[j] + tol:
            return NUMERICAL, 0.0, pivots
    for j in range(m):
        x[j] = min(max(x0[j] + xs[j] - xs[m + j], lb[j]), ub[j])
    return OPTIMAL, max(xs[jt], 0.0), pivots
