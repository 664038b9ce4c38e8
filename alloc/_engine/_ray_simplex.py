"""Compiled solvers of ``da``'s ray LP (seed Eqs 1.15-1.17): a dual facet walk, a primal simplex behind it.

In the scaled variables of :class:`alloc.methods._direct_lp.RayLP` (``u = c + D x``,
``x`` in ``[-1, 1]``, ``A = Q B D / sigma``, ``q = Q d / |d|``) the ray LP is

    maximise t   subject to   A x - t q = A x0,   lb <= x <= ub,   0 <= t <= t_max,

``x0`` the base point.  :func:`dual_ray` answers first: it walks the attainable set's facet
normals (the LP's dual) from the facet an ellipsoid approximation predicts, a few O(k m) steps.
Where it stops (a degenerate vertex, its step bound), :func:`solve_ray`, a bounded-variable
primal simplex, solves the same LP; the caller's DAQP model is the last resort.

:func:`solve_ray`: written about the base point, ``x = x0 + p - n`` with ``p, n >= 0``, the LP
is ``A p - A n - t q + e = 0`` with one artificial ``e_i`` per row fixed at ``[0, 0]``.  Every
call starts from the same basis (history independent): ``t`` and the ``k - 1`` columns nearest
the predicted facet, or the artificials when those are singular, every variable at zero
(``u = u0``, ``t = 0``), which is feasible, so there is no phase 1.  The pivots are
:mod:`alloc._engine._simplex`'s rules (Dantzig's, Bland's after degenerate pivots, refactorisation every
``REFACTOR_EVERY`` pivots) with bound flips taken in passes (:func:`_iterate_long`).

Why not the DAQP model alone: a proximal-point LP solve per call cost 86 us at k = 4, m = 24,
432 us at m = 96 and 2.2 ms at m = 192 (super-linear in m); the primal walk from ``u0`` takes a
pivot per few effectors (32-42 at m = 96, 121 us a call); the dual walk a median of one to three
steps, and a nominal call is one compiled pass (:func:`ray_call`): 30 us a call at m = 96 and
61 us at m = 192 under load 7 (``python -m benchmarks.bench_da_cost --large``).
"""

from __future__ import annotations

import numpy as np
import alloc._engine._kernel_cache  # noqa: F401 - kernel caches placed before any kernel is decorated
from numba import njit

from ._kernels import facet_polish
from ._simplex import (_BASIC, _LOWER, _UPPER, BLAND_AFTER, DEGENERATE_TOL, DUAL_TOL, FEASIBLE_RTOL,
                       ITERATION_LIMIT, NUMERICAL, OPTIMAL, REFACTOR_EVERY, TIE_RTOL, _eliminate, _reduced_costs,
                       _refactor, _step_to_bound)

__all__ = ["ray_matrix", "solve_ray", "dual_ray", "ray_call", "work_sizes", "OPTIMAL", "ITERATION_LIMIT",
           "NUMERICAL"]


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
    keeps the best one that does not fit for a basis change.  :func:`alloc._engine._simplex._iterate`
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


@njit(cache=True, nogil=True, _nrt=False)
def _crash(F, G, cnorm, q, hi, basis, status, m, jt, n0):  # pragma: no cover - compiled
    """A starting basis near the optimal facet: ``t`` and the ``k - 1`` moving effectors whose
    columns lie nearest the tangent plane where the ray leaves the ellipsoid ``{A z : |z| <= 1}``
    that approximates the set (normal ``G q``, ``G = (A A')^-1``).  Every variable is still at
    zero (``u = u0``, ``t = 0``), so the basis is feasible whatever it is; a good one saves the
    walk across the set's facets (32-42 pivots from the artificial basis at k = 4, m = 96)."""
    k = F.shape[0]
    for i in range(k):
        n0[i] = 0.0
        for r in range(k):
            n0[i] += G[i, r] * q[r]
    basis[0] = jt
    status[jt] = _BASIC
    for slot in range(1, k):
        best, pick = np.inf, -1
        for j in range(m):
            if status[j] == _BASIC or not (hi[j] > 0.0 or hi[m + j] > 0.0) or not cnorm[j] > 0.0:
                continue
            s = 0.0
            for i in range(k):
                s += n0[i] * F[i, j]
            s = abs(s) / cnorm[j]
            if s < best:
                best, pick = s, j
        if pick < 0:
            return False
        basis[slot] = pick
        status[pick] = _BASIC
    return True


@njit(cache=True, nogil=True)
def solve_ray(F, q, x0, lb, ub, t_max, max_iter, work, iwork, x, G, cnorm):  # pragma: no cover - compiled
    """Maximise ``t`` (see the module docstring); write ``x``; return ``(code, t, pivots)``.

    ``F`` from :func:`ray_matrix` (its column ``2 m`` is overwritten with ``-q``), ``x0``
    within ``[lb, ub]``; ``work``/``iwork`` of :func:`work_sizes`; ``G = (A A')^-1`` and the
    columns' norms ``cnorm`` for the starting basis (:func:`_crash`).
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
    basis = iwork[2 * N:2 * N + k]
    for j in range(N):
        lo[j] = 0.0
        xs[j] = 0.0
        cost[j] = 0.0
        status[j] = _LOWER
    for j in range(m):
        hi[j] = max(ub[j] - x0[j], 0.0)
        hi[m + j] = max(x0[j] - lb[j], 0.0)
    hi[jt] = t_max
    cost[jt] = -1.0
    for i in range(k):
        hi[jt + 1 + i] = 0.0
        b[i] = 0.0
    # (d's first k entries hold the ellipsoid normal until _refactor writes the reduced costs)
    crashed = _crash(F, G, cnorm, q, hi, basis, status, m, jt, d[:k]) and _refactor(F, basis, status, xs, b, cost, T, d, W)
    if not crashed:  # a singular guess: the artificial basis, always valid
        for j in range(N):
            status[j] = _LOWER
            xs[j] = 0.0
        for i in range(k):
            j = jt + 1 + i
            basis[i] = j
            status[j] = _BASIC
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


@njit(cache=True, nogil=True, _nrt=False)
def _solve_small(M, rhs, out, piv_tol):  # pragma: no cover - compiled
    """``out = M^-1 rhs`` by Gaussian elimination with partial pivoting (``M`` is overwritten);
    False when a pivot is at most ``piv_tol``."""
    n = M.shape[0]
    for i in range(n):
        out[i] = rhs[i]
    for c in range(n):
        p, best = c, abs(M[c, c])
        for i in range(c + 1, n):
            if abs(M[i, c]) > best:
                p, best = i, abs(M[i, c])
        if not best > piv_tol:
            return False
        if p != c:
            for j in range(n):
                M[c, j], M[p, j] = M[p, j], M[c, j]
            out[c], out[p] = out[p], out[c]
        for i in range(c + 1, n):
            f = M[i, c] / M[c, c]
            if f != 0.0:
                for j in range(c, n):
                    M[i, j] -= f * M[c, j]
                out[i] -= f * out[c]
    for c in range(n - 1, -1, -1):
        s = out[c]
        for j in range(c + 1, n):
            s -= M[c, j] * out[j]
        out[c] = s / M[c, c]
    return True


@njit(cache=True, nogil=True)
def dual_ray(A, q, x0, lb, ub, G, cnorm, max_iter, x):  # pragma: no cover - compiled
    """The ray LP from its dual side; write ``x``; return ``(code, t, iterations)``.

    By LP duality ``t* = min h(y)`` over ``y . q = 1``, ``h(y) = sum_j max(y.a_j hi_j,
    -y.a_j lo_j)`` (``hi = ub - x0``, ``lo = x0 - lb``): a convex piecewise-linear function of
    the facet normal ``y``.  A vertex holds ``k - 1`` columns ``F`` with ``y . a_j = 0`` (a facet's
    free effectors); every other effector sits at the bound the sign of ``y . a_j`` picks, and
    ``[A_F, -q] (w_F, t) = -A_N w_N`` gives the free ones.  When one of them is outside its
    range it leaves ``F``: ``y`` moves along the edge that makes it reach the violated bound, past
    every kink (bound flip) while ``h`` still decreases, and the column at the kink where it
    stops increasing enters (the long-step dual ratio test).  Each step is O(k m + m log m +
    k^3), and the walk starts at the facet an ellipsoid approximation predicts (:func:`_crash`'s
    rule), so a call takes a few steps where the primal walk from ``u0`` took one pivot per
    few effectors.  Codes as :func:`solve_ray`'s; any failure is left to that solver.
    """
    k, m = A.shape
    if k < 1:
        return NUMERICAL, 0.0, 0
    hi = np.empty(m)
    lo = np.empty(m)
    moving = np.empty(m, dtype=np.bool_)
    for j in range(m):
        hi[j] = max(ub[j] - x0[j], 0.0)
        lo[j] = max(x0[j] - lb[j], 0.0)
        moving[j] = hi[j] + lo[j] > 0.0 and cnorm[j] > 0.0
    F = np.empty(max(k - 1, 0), dtype=np.int64)
    inF = np.zeros(m, dtype=np.bool_)
    n0 = G @ q
    for slot in range(k - 1):
        best, pick = np.inf, -1
        for j in range(m):
            if inF[j] or not moving[j]:
                continue
            s = 0.0
            for i in range(k):
                s += n0[i] * A[i, j]
            s = abs(s) / cnorm[j]
            if s < best:
                best, pick = s, j
        if pick < 0:
            return NUMERICAL, 0.0, 0
        F[slot] = pick
        inF[pick] = True
    M = np.empty((k, k))
    e = np.zeros(k)
    y = np.empty(k)
    delta = np.empty(k)
    z = np.empty(k)
    rhs = np.empty(k)
    ya = np.empty(m)
    da = np.empty(m)
    w = np.empty(m)
    brk = np.empty(m)
    scale = 0.0
    for j in range(m):
        scale = max(scale, cnorm[j])
    tol = 1e-12 * max(scale, 1.0)
    # y: y . a_F = 0, y . q = 1
    for s in range(k - 1):
        for i in range(k):
            M[s, i] = A[i, F[s]]
    for i in range(k):
        M[k - 1, i] = q[i]
    e[k - 1] = 1.0
    if not _solve_small(M, e, y, tol):
        return NUMERICAL, 0.0, 0
    for it in range(max_iter):
        for j in range(m):
            s = 0.0
            for i in range(k):
                s += y[i] * A[i, j]
            ya[j] = s
            w[j] = 0.0 if inF[j] or not moving[j] else (hi[j] if s > 0.0 else (-lo[j] if s < 0.0 else 0.0))
        # the free effectors and t: [A_F, -q] (w_F, t) = -A_N w_N
        for i in range(k):
            s = 0.0
            for j in range(m):
                if w[j] != 0.0:
                    s -= A[i, j] * w[j]
            rhs[i] = s
            for c in range(k - 1):
                M[i, c] = A[i, F[c]]
            M[i, k - 1] = -q[i]
        if not _solve_small(M, rhs, z, tol):
            return NUMERICAL, 0.0, it
        # the most violated free effector (a tie at y . a_j = 0 counts as no violation)
        r, worst, sgn = -1, 0.0, 0.0
        for c in range(k - 1):
            j = F[c]
            span = 1e-9 * (1.0 + hi[j] + lo[j])
            if z[c] - hi[j] > max(worst, span):
                r, worst, sgn = c, z[c] - hi[j], 1.0
            elif -lo[j] - z[c] > max(worst, span):
                r, worst, sgn = c, -lo[j] - z[c], -1.0
        if r < 0:
            t = z[k - 1]
            if not (t >= -1e-9) or not np.isfinite(t):
                return NUMERICAL, 0.0, it
            for c in range(k - 1):
                w[F[c]] = z[c]
            for j in range(m):
                x[j] = min(max(x0[j] + w[j], lb[j]), ub[j])
            return OPTIMAL, max(t, 0.0), it
        # direction: delta . a_F[r] = sgn, delta . a_F[other] = 0, delta . q = 0
        for s in range(k - 1):
            for i in range(k):
                M[s, i] = A[i, F[s]]
            e[s] = 0.0
        for i in range(k):
            M[k - 1, i] = q[i]
        e[k - 1] = 0.0
        e[r] = sgn
        if not _solve_small(M, e, delta, tol):
            return NUMERICAL, 0.0, it
        e[r] = 0.0
        e[k - 1] = 1.0
        jr = F[r]
        slope = hi[jr] if sgn > 0.0 else lo[jr]
        nb = 0
        for j in range(m):
            if inF[j] or not moving[j]:
                da[j] = 0.0
                continue
            s = 0.0
            for i in range(k):
                s += delta[i] * A[i, j]
            da[j] = s
            if ya[j] > 0.0 or (ya[j] == 0.0 and s > 0.0):
                slope += hi[j] * s
            else:
                slope -= lo[j] * s
            if (ya[j] > 0.0 and s < 0.0) or (ya[j] < 0.0 and s > 0.0):
                brk[nb] = -ya[j] / s
                nb += 1
        if not slope < 0.0:
            return NUMERICAL, 0.0, it  # no descent (degenerate vertex): the primal walk instead
        # the long step: pass kinks in order while h still decreases
        order = np.argsort(brk[:nb])
        idx = np.empty(nb, dtype=np.int64)
        c = 0
        for j in range(m):
            if not inF[j] and moving[j] and ((ya[j] > 0.0 and da[j] < 0.0) or (ya[j] < 0.0 and da[j] > 0.0)):
                idx[c] = j
                c += 1
        enter, step = -1, 0.0
        for o in range(nb):
            j = idx[order[o]]
            slope += abs(da[j]) * (hi[j] + lo[j])
            if slope >= 0.0:
                enter, step = j, brk[order[o]]
                break
        if enter < 0:
            return NUMERICAL, 0.0, it  # unbounded dual: impossible with u0 feasible; round-off
        for i in range(k):
            y[i] += step * delta[i]
        inF[jr] = False
        inF[enter] = True
        F[r] = enter
    return ITERATION_LIMIT, 0.0, max_iter


@njit(cache=True, nogil=True)
def ray_call(v, Bu0, u0, B, Q, Ax, G, cnorm, x0, xlo, xhi, c0, D, lo, hi, sigma, max_iter):  # pragma: no cover - compiled
    """One nominal ``da`` call through :func:`dual_ray` in one compiled pass: the demand measured
    from the base point, the unit ray in the row basis ``Q``, the walk, the boundary control,
    the exact re-solve on its facet (:func:`alloc._engine._kernels.facet_polish`) and Eq 1.15's scaling
    back.  Returns ``(code, u, iterations)``; any code but ``OPTIMAL`` leaves the call to the
    caller's slower path (the primal simplex, then DAQP).  The same arithmetic, in the same
    order, as :meth:`alloc.methods._direct_lp.RayLP.solve` without rate limits.
    """
    k, m = B.shape
    r = Q.shape[0]
    d = v - Bu0
    if r != k:  # the part of d in the range of B (rank-deficient B)
        z = np.zeros(r)
        for i in range(r):
            for j in range(k):
                z[i] += Q[i, j] * d[j]
        for j in range(k):
            s = 0.0
            for i in range(r):
                s += Q[i, j] * z[i]
            d[j] = s
    vmax, dmax = 0.0, 0.0
    for i in range(k):
        vmax = max(vmax, abs(v[i]))
        dmax = max(dmax, abs(d[i]))
    if not dmax > 1e-14 * max(1.0, vmax):
        return OPTIMAL, u0.copy(), 0
    ds = d / dmax
    ds2 = 0.0
    for i in range(k):
        ds2 += ds[i] * ds[i]
    norm = dmax * np.sqrt(ds2)
    dsn = ds / np.sqrt(ds2)
    q = np.zeros(r)
    for i in range(r):
        for j in range(k):
            q[i] += Q[i, j] * dsn[j]
    xs = np.empty(m)
    code, t, it = dual_ray(Ax, q, x0, xlo, xhi, G, cnorm, max_iter, xs)
    if code != OPTIMAL:
        return code, xs, it
    ustar = np.minimum(np.maximum(c0 + D * xs, lo), hi)
    a = t * (sigma / norm)
    if r == k:
        a, ustar, _ = facet_polish(B, ustar, d, u0, lo, hi, a)
    if a >= 1.0:
        return OPTIMAL, u0 + (ustar - u0) / a, it
    return OPTIMAL, ustar, it
