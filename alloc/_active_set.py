"""Compiled lexicographic least-squares active-set solver (``qp``, ``wls``, ``dynamic``).

One primal active-set method on the least-squares form (Härkegård 2002, "Efficient active
set algorithms for solving constrained least squares problems in aircraft control
allocation": sequential least squares), compiled with numba so that an allocation is one
compiled call.  It solves a short sequence of *levels*, each lexicographically below the
ones before it:

    level l:   minimise  ||A_l u - b_l||^2 + g_l^2 (u - up)' Wu (u - up)
               subject to  lo <= u <= hi  and  A_i u = A_i u*_i  for the levels i < l

where ``u*_i`` is the answer of level ``i`` (the moments ``A_i u`` an optimum reaches are
unique, so holding them keeps every earlier level optimal).  The two-stage ``qp`` is a
level ``A = Lv' B`` with ``g = 0`` (Eq 1.20) followed by a level with no rows and ``g = 1``
(Eq 1.21); ``priorities`` split the first level by axis; ``wls`` is one level with
``g = gamma``.

Why not the normal equations: stage 1 of ``qp`` has the singular Hessian ``B'WvB`` (rank
``k < m``, worse with collinear columns); a solver working on it needs a ridge and stops
short (moment errors of 1e-6 on unattainable rate-limited demands).  Here every step is
the minimum-norm least-squares solution on the free effectors, computed from a one-sided
Jacobi SVD of the small ``rows x free`` matrix in the ``Wu`` metric, so rank deficiency
is handled by dropping singular values at round-off level and the residual, the gradient
and the multipliers are recomputed from the data at every iterate (no drift).
Multipliers are tested against tolerances scaled to the round-off of their own
computation (``MU_EPS`` times the magnitudes that formed them): near-degenerate cases then
pick the right active set (SOLVER-NOTES, "Lessons").

Every loop is bounded; a level that hits its iteration cap returns ``ok = False`` and the
caller raises :class:`~alloc.exceptions.SolverError` (the allocator's safe fallback).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["lexico_ls", "lexico_ls_batch", "lexico_packed", "lexico_packed_batch", "pack", "SIGMA_RTOL", "MU_EPS"]

#: Singular values below this fraction of the largest are round-off (dropped).
SIGMA_RTOL = 1e-12
#: Multiplier tolerance in units of the round-off bound of the multiplier's computation.
MU_EPS = 1e3 * np.finfo(float).eps


@njit(cache=True, nogil=True)
def _jacobi(X, n, p, V, sig, ref):  # pragma: no cover - compiled
    """One-sided (Hestenes) Jacobi SVD of ``X[:n, :p]`` in place.

    On return the columns of ``X`` are ``U * sig`` (mutually orthogonal), ``V`` is the
    ``p x p`` rotation with ``X_in V = X_out``; ``sig`` holds the column norms.  So
    ``X_in = U diag(sig) V'``.  Singular values at or below ``SIGMA_RTOL`` times the
    larger of the largest one and ``ref`` (the scale of ``X`` before a projection made
    it small) are round-off: set to 0, their columns left unnormalised.
    """
    for i in range(p):
        for j in range(p):
            V[i, j] = 0.0
        V[i, i] = 1.0
    for _sweep in range(40):
        rotated = False
        for i in range(p - 1):
            for j in range(i + 1, p):
                a = 0.0
                b = 0.0
                c = 0.0
                for r in range(n):
                    xi = X[r, i]
                    xj = X[r, j]
                    a += xi * xi
                    b += xj * xj
                    c += xi * xj
                if c == 0.0 or abs(c) <= 1e-15 * np.sqrt(a * b):
                    continue
                rotated = True
                zeta = (b - a) / (2.0 * c)
                t = (1.0 if zeta >= 0.0 else -1.0) / (abs(zeta) + np.sqrt(1.0 + zeta * zeta))
                cs = 1.0 / np.sqrt(1.0 + t * t)
                sn = cs * t
                for r in range(n):
                    xi = X[r, i]
                    xj = X[r, j]
                    X[r, i] = cs * xi - sn * xj
                    X[r, j] = sn * xi + cs * xj
                for r in range(p):
                    vi = V[r, i]
                    vj = V[r, j]
                    V[r, i] = cs * vi - sn * vj
                    V[r, j] = sn * vi + cs * vj
        if not rotated:
            break
    smax = 0.0
    for j in range(p):
        s = 0.0
        for r in range(n):
            s += X[r, j] * X[r, j]
        s = np.sqrt(s)
        sig[j] = s
        if s > smax:
            smax = s
    # normalise the kept columns to U; mark the dropped ones with sig = 0
    smax = max(smax, ref)
    for j in range(p):
        if sig[j] > SIGMA_RTOL * smax and sig[j] > 1e-290:
            inv = 1.0 / sig[j]
            for r in range(n):
                X[r, j] *= inv
        else:
            sig[j] = 0.0


@njit(cache=True, nogil=True)
def _level(A, b, r0, r1, gam, Wu, diag, up, lo, hi, u, free, pinned, maxit,
           F, L, Yc, Vc, sc, Ya, Va, sa, e, g, h, y, tmp, lam, tabu, scale):  # pragma: no cover - compiled
    """Solve one level in place on ``u`` (feasible on entry) and ``free`` (working set).

    Rows ``A[r0:r1]`` are this level's least-squares rows, rows ``A[:r0]`` its equality
    constraints (held at their values on entry).  ``pinned`` effectors are never freed:
    an earlier level proved them at their bound on its whole optimal set (a strictly
    nonzero, unique multiplier); on return this level adds its own.  Without pinning, the
    stage-2 multipliers at a stage-1 vertex are not unique and a minimum-norm estimate
    frees effectors that cannot move.  An effector freed and then blocked by a zero step
    (a degenerate multiplier) is not freed again until the iterate moves.  The remaining
    arguments are work arrays (allocated once per call by :func:`lexico_ls`).  Returns
    the iteration count, or -1 when the cap was hit.
    """
    m = u.shape[0]
    nl = r1 - r0
    nc = r0
    tabu[:] = False
    last = -1
    gam2 = gam * gam
    for it in range(maxit):
        # --- residual e = b - A u of this level's rows.  A pure least-squares level whose
        # residual is zero to round-off is at its global minimum (the objective is >= 0):
        # done, with zero multipliers (the common attainable case from the Eq 1.23 start).
        zero = nl > 0 and gam2 == 0.0
        for i in range(nl):
            acc = b[r0 + i]
            mag = abs(b[r0 + i])
            for j in range(m):
                t = A[r0 + i, j] * u[j]
                acc -= t
                mag += abs(t)
            e[i] = acc
            if abs(acc) > MU_EPS * mag:
                zero = False
        if zero:
            return it + 1
        nf = 0
        for j in range(m):
            if free[j]:
                F[nf] = j
                nf += 1
        # --- L L' = Wu[F, F] (Cholesky; diagonal fast path)
        if diag:
            for q in range(nf):
                L[q, q] = np.sqrt(Wu[F[q], F[q]])
        else:
            for q in range(nf):
                for s in range(q + 1):
                    acc = Wu[F[q], F[s]]
                    for t in range(s):
                        acc -= L[q, t] * L[s, t]
                    if q == s:
                        L[q, q] = np.sqrt(max(acc, 1e-300))
                    else:
                        L[q, s] = acc / L[s, s]
        # --- the preference gradient Wu (u - up)
        for j in range(m):
            tmp[j] = u[j] - up[j]
        for q in range(nf):
            j = F[q]
            acc = 0.0
            if diag:
                acc = Wu[j, j] * tmp[j]
            else:
                for s in range(m):
                    acc += Wu[j, s] * tmp[s]
            h[q] = acc
        _lsolve(L, nf, diag, h)  # h = L^-1 (Wu (u - up))_F
        # --- equality rows in the L metric: Yc = L^-1 A[:r0, F]'  (nf x nc), then its SVD
        for c in range(nc):
            for q in range(nf):
                Yc[q, c] = A[c, F[q]]
            _lsolve_col(L, nf, diag, Yc, c)
        if nc > 0:
            _jacobi(Yc, nf, nc, Vc, sc, 0.0)
        # --- this level's rows, projected onto the null space of the equalities
        ref = 0.0
        for i in range(nl):
            for q in range(nf):
                Ya[q, i] = A[r0 + i, F[q]]
            _lsolve_col(L, nf, diag, Ya, i)
            for q in range(nf):
                ref = max(ref, abs(Ya[q, i]))
            for _twice in range(2):  # Gram-Schmidt twice: rows nearly in the span lose digits
                for c in range(nc):
                    if sc[c] > 0.0:
                        acc = 0.0
                        for q in range(nf):
                            acc += Yc[q, c] * Ya[q, i]
                        for q in range(nf):
                            Ya[q, i] -= acc * Yc[q, c]
        if nl > 0:
            _jacobi(Ya, nf, nl, Va, sa, ref)
        # --- step y = -P h + Ua z   (P: projector onto null(Ct) and null(At)),
        #     z_i = (s_i (Va' e)_i - gam^2 (Ua' h)_i) / (s_i^2 + gam^2)
        for q in range(nf):
            y[q] = -h[q]
        for c in range(nc):
            if sc[c] > 0.0:
                acc = 0.0
                for q in range(nf):
                    acc += Yc[q, c] * h[q]
                for q in range(nf):
                    y[q] += acc * Yc[q, c]
        for i in range(nl):
            if sa[i] > 0.0:
                uh = 0.0
                for q in range(nf):
                    uh += Ya[q, i] * h[q]
                ve = 0.0
                for r in range(nl):
                    ve += Va[r, i] * e[r]
                z = (sa[i] * ve - gam2 * uh) / (sa[i] * sa[i] + gam2)
                for q in range(nf):
                    y[q] += (uh + z) * Ya[q, i]
        for c in range(nc):  # y in null(Ct) to round-off: the held moments do not drift
            if sc[c] > 0.0:
                acc = 0.0
                for q in range(nf):
                    acc += Yc[q, c] * y[q]
                for q in range(nf):
                    y[q] -= acc * Yc[q, c]
        _ltsolve(L, nf, diag, y)  # p_F = L^-T y
        # --- ratio test
        alpha = 1.0
        block = -1
        for q in range(nf):
            j = F[q]
            d = y[q]
            if d > 0.0:
                room = hi[j] - u[j]
                if room < alpha * d:
                    alpha = max(room, 0.0) / d
                    block = q
            elif d < 0.0:
                room = lo[j] - u[j]
                if room > alpha * d:
                    alpha = min(room, 0.0) / d
                    block = q
        for q in range(nf):
            u[F[q]] += alpha * y[q]
        if block >= 0:
            j = F[block]
            u[j] = hi[j] if y[block] > 0.0 else lo[j]
            free[j] = False
            if alpha > 0.0:
                tabu[:] = False
            elif j == last:
                tabu[j] = True
            continue
        # --- full step: multipliers of the bounds held, mu = g + A[:r0]' lam
        for j in range(m):
            tmp[j] = u[j] - up[j]
        for j in range(m):
            acc = 0.0
            if gam2 > 0.0:
                if diag:
                    acc = gam2 * Wu[j, j] * tmp[j]
                else:
                    for s in range(m):
                        acc += Wu[j, s] * tmp[s]
                    acc *= gam2
            g[j] = acc
        scale[:] = 0.0  # round-off bound of each g_j (and of A' lam below)
        for i in range(nl):
            acc = -b[r0 + i]
            mag = abs(b[r0 + i])
            for j in range(m):
                t = A[r0 + i, j] * u[j]
                acc += t
                mag += abs(t)
            for j in range(m):
                g[j] += A[r0 + i, j] * acc
                scale[j] += abs(A[r0 + i, j]) * mag
        if gam2 > 0.0:
            for j in range(m):
                if diag:
                    acc = abs(Wu[j, j]) * (abs(u[j]) + abs(up[j]))
                else:
                    acc = 0.0
                    for s in range(m):
                        acc += abs(Wu[j, s]) * (abs(u[s]) + abs(up[s]))
                scale[j] += gam2 * acc
        if nc > 0:
            # lam = -Vc diag(1/sc) Uc' L^-1 g_F
            for q in range(nf):
                h[q] = g[F[q]]
            _lsolve(L, nf, diag, h)
            for c in range(nc):
                lam[c] = 0.0
            for c in range(nc):
                if sc[c] > 0.0:
                    acc = 0.0
                    for q in range(nf):
                        acc += Yc[q, c] * h[q]
                    acc /= sc[c]
                    for r in range(nc):
                        lam[r] -= Vc[r, c] * acc
            for c in range(nc):
                for j in range(m):
                    t = A[c, j] * lam[c]
                    g[j] += t
                    scale[j] += abs(t)
        unique = True
        for c in range(nc):
            if sc[c] == 0.0:
                unique = False
        worst = -1
        wv = 0.0
        for j in range(m):
            if free[j] or lo[j] == hi[j] or pinned[j] or tabu[j]:
                continue
            viol = -g[j] if u[j] <= lo[j] else g[j]
            tol = MU_EPS * scale[j]
            if viol > tol and viol - tol > wv:
                wv = viol - tol
                worst = j
        if worst < 0:
            if unique and nl > 0:
                for j in range(m):
                    if not free[j] and lo[j] < hi[j]:
                        mu = -g[j] if u[j] <= lo[j] else g[j]
                        if mu < -100.0 * MU_EPS * scale[j]:
                            pinned[j] = True
            return it + 1
        free[worst] = True
        last = worst
    return -1


@njit(cache=True, nogil=True)
def _lsolve(L, n, diag, x):  # pragma: no cover - compiled
    """``x[:n] = L^-1 x[:n]`` (forward substitution)."""
    for q in range(n):
        acc = x[q]
        if not diag:
            for s in range(q):
                acc -= L[q, s] * x[s]
        x[q] = acc / L[q, q]


@njit(cache=True, nogil=True)
def _lsolve_col(L, n, diag, X, c):  # pragma: no cover - compiled
    """``X[:n, c] = L^-1 X[:n, c]``."""
    for q in range(n):
        acc = X[q, c]
        if not diag:
            for s in range(q):
                acc -= L[q, s] * X[s, c]
        X[q, c] = acc / L[q, q]


@njit(cache=True, nogil=True)
def _ltsolve(L, n, diag, x):  # pragma: no cover - compiled
    """``x[:n] = L^-T x[:n]`` (back substitution)."""
    for q in range(n - 1, -1, -1):
        acc = x[q]
        if not diag:
            for s in range(q + 1, n):
                acc -= L[s, q] * x[s]
        x[q] = acc / L[q, q]


@njit(cache=True, nogil=True)
def lexico_ls(A, T, perm, starts, gammas, final, Wu, diag, up, B0, P0, v, lo, hi, maxit):  # pragma: no cover - compiled
    """All levels for one demand: ``b = T v[perm]``; returns ``(u, iterations, ok)``.

    ``A`` (n x m) stacks the levels' rows (level ``l`` is ``A[starts[l]:starts[l+1]]``,
    weight ``gammas[l]``); ``final`` adds the preference level ``min (u-up)'Wu(u-up)``
    holding all rows of ``A`` (stage 2 of ``qp``).  The start is the pseudo-inverse
    answer ``up + P0 (v - B0 up)`` clipped into ``[lo, hi]``, the effectors clipped held
    at their bound (a deterministic start: the answer depends on the data alone).
    """
    n, m = A.shape
    b = np.empty(n)
    for i in range(n):
        acc = 0.0
        for r in range(n):
            acc += T[i, r] * v[perm[r]]
        b[i] = acc
    u = np.empty(m)
    free = np.empty(m, dtype=np.bool_)
    pinned = np.zeros(m, dtype=np.bool_)
    # start: the Eq 1.23 pseudo-inverse answer u0 = up + P0 (v - B0 up), clipped
    k0 = B0.shape[0]
    r = np.empty(k0)
    for i in range(k0):
        acc = v[i]
        for j in range(m):
            acc -= B0[i, j] * up[j]
        r[i] = acc
    for j in range(m):
        x = up[j]
        for i in range(k0):
            x += P0[j, i] * r[i]
        x = min(max(x, lo[j]), hi[j])
        u[j] = x
        free[j] = lo[j] < x < hi[j]
    nw = max(n, 1)
    F = np.empty(m, dtype=np.int64)
    tabu = np.zeros(m, dtype=np.bool_)
    work = np.zeros(m * m + 2 * m * nw + 2 * nw * nw + 4 * nw + 5 * m)
    o = 0
    L = work[o:o + m * m].reshape((m, m))
    o += m * m
    Yc = work[o:o + m * nw].reshape((m, nw))
    o += m * nw
    Ya = work[o:o + m * nw].reshape((m, nw))
    o += m * nw
    Vc = work[o:o + nw * nw].reshape((nw, nw))
    o += nw * nw
    Va = work[o:o + nw * nw].reshape((nw, nw))
    o += nw * nw
    sc = work[o:o + nw]
    o += nw
    sa = work[o:o + nw]
    o += nw
    e = work[o:o + nw]
    o += nw
    lam = work[o:o + nw]
    o += nw
    g = work[o:o + m]
    o += m
    h = work[o:o + m]
    o += m
    y = work[o:o + m]
    o += m
    tmp = work[o:o + m]
    o += m
    scale = work[o:o + m]
    total = 0
    for l in range(starts.shape[0] - 1):
        it = _level(A, b, starts[l], starts[l + 1], gammas[l], Wu, diag, up, lo, hi, u, free, pinned, maxit,
                    F, L, Yc, Vc, sc, Ya, Va, sa, e, g, h, y, tmp, lam, tabu, scale)
        if it < 0:
            return u, total + maxit, False
        total += it
    if final:
        it = _level(A, b, n, n, 1.0, Wu, diag, up, lo, hi, u, free, pinned, maxit,
                    F, L, Yc, Vc, sc, Ya, Va, sa, e, g, h, y, tmp, lam, tabu, scale)
        if it < 0:
            return u, total + maxit, False
        total += it
    return u, total, True


@njit(cache=True, nogil=True)
def lexico_ls_batch(A, T, perm, starts, gammas, final, Wu, diag, up, B0, P0, V, lo, hi, maxit):  # pragma: no cover - compiled
    """:func:`lexico_ls` over the rows of ``V``; ``ok[i]`` False where a level hit its cap."""
    N = V.shape[0]
    m = A.shape[1]
    U = np.empty((N, m))
    ok = np.empty(N, dtype=np.bool_)
    for i in range(N):
        u, _it, good = lexico_ls(A, T, perm, starts, gammas, final, Wu, diag, up, B0, P0, V[i], lo, hi, maxit)
        U[i] = u
        ok[i] = good
    return U, ok


# --- packed entry points: one compiled call with few arguments --------------------------
#
# numba unboxes every array argument on each call (~0.1 us each) and every np.empty in a
# call is an allocation; the hot path therefore passes the solver's data packed in one
# float and one int array and carves its work arrays out of one allocation.

#: int header: n, m, k0, levels, final, diag, maxit, then perm (n), then starts (levels + 1)
_HDR = 7


def pack(A, T, perm, starts, gammas, final, Wu, diag, up, B0, P0, maxit):
    """The solver data as ``(fdata, idata)`` for :func:`lexico_packed`."""
    n, m = A.shape
    k0 = B0.shape[0]
    idata = np.concatenate([[n, m, k0, len(starts) - 1, int(final), int(diag), int(maxit)],
                            np.asarray(perm), np.asarray(starts)]).astype(np.int64)
    fdata = np.concatenate([np.ravel(A), np.ravel(T), np.ravel(Wu), np.ravel(up), np.ravel(B0),
                            np.ravel(P0), np.asarray(gammas, dtype=float)]).astype(float)
    return np.ascontiguousarray(fdata), np.ascontiguousarray(idata)


@njit(cache=True, nogil=True)
def lexico_packed(fdata, idata, up, v, lo, hi):  # pragma: no cover - compiled
    """:func:`lexico_ls` on packed data; ``up`` is the preference point of this call."""
    n = idata[0]
    m = idata[1]
    k0 = idata[2]
    nlev = idata[3]
    final = idata[4] != 0
    diag = idata[5] != 0
    maxit = idata[6]
    perm = idata[_HDR:_HDR + n]
    starts = idata[_HDR + n:_HDR + n + nlev + 1]
    o = 0
    A = fdata[o:o + n * m].reshape((n, m))
    o += n * m
    T = fdata[o:o + n * n].reshape((n, n))
    o += n * n
    Wu = fdata[o:o + m * m].reshape((m, m))
    o += m * m
    o += m  # the build-time up (the caller passes the call's up)
    B0 = fdata[o:o + k0 * m].reshape((k0, m))
    o += k0 * m
    P0 = fdata[o:o + m * k0].reshape((m, k0))
    o += m * k0
    gammas = fdata[o:o + nlev]
    return lexico_ls(A, T, perm, starts, gammas, final, Wu, diag, up, B0, P0, v, lo, hi, maxit)


@njit(cache=True, nogil=True)
def lexico_packed_batch(fdata, idata, up, V, lo, hi):  # pragma: no cover - compiled
    """:func:`lexico_packed` over the rows of ``V``; ``ok[i]`` False where a level hit its cap."""
    N = V.shape[0]
    m = idata[1]
    U = np.empty((N, m))
    ok = np.empty(N, dtype=np.bool_)
    for i in range(N):
        u, _it, good = lexico_packed(fdata, idata, up, V[i], lo, hi)
        for j in range(m):
            U[i, j] = u[j]
        ok[i] = good
    return U, ok
