"""Compiled per-call kernels for the facet searches of :mod:`alloc.methods.facet_search` (numba).

A Durham search round is a dozen numpy calls on arrays of a few dozen floats, each paying
about a microsecond of dispatch; here a whole call (Eqs 1.15-1.17) is one compiled
function fed with the tables :class:`~alloc.methods.facet_search.FacetSearch` stores at build time.
Every kernel follows its numpy reference (``_solve_reference``) operation for operation, so
the answers agree to round-off (``tests/alloc/ams/test_kernels.py``).
"""

from __future__ import annotations

import math

import numpy as np
import alloc._engine._kernel_cache  # noqa: F401 - kernel caches placed before any kernel is decorated
from numba import njit

__all__ = ["facet_solve", "bisect_solve", "ray_exit_solve", "flat_ray_exit_solve"]

_TOL = 1e-10  # Eq 1.17 slack, as in facet_search.py
_EPS = np.finfo(np.float64).eps


@njit(cache=True, nogil=True)
def _matvec_tile(Minv, t, d, x):  # pragma: no cover - compiled
    k = d.shape[0]
    for i in range(k):
        s = 0.0
        for j in range(k):
            s += Minv[t, i, j] * d[j]
        x[i] = s


@njit(cache=True, nogil=True)
def _tile_score(x):  # pragma: no cover - compiled
    """Eq 1.17 margin of ``x = [1/a, b/a, ...]``: ``min(b, 1 - b)`` scaled by ``a``; -inf if ``a <= 0``."""
    x0 = x[0]
    if not x0 > 0:
        return -np.inf
    s = np.inf
    for i in range(1, x.shape[0]):
        p = x[i]
        q = x0 - p
        if q < p:
            p = q
        if p < s:
            s = p
    return s / x0


@njit(cache=True, nogil=True)
def _best_tile(Minv, tiles, n, d, x, xbest):  # pragma: no cover - compiled
    """``np.argmax`` of the Eq 1.17 score over ``tiles[:n]`` (first maximum, NaN wins)."""
    best, score = -1, -np.inf
    for q in range(n):
        t = tiles[q]
        _matvec_tile(Minv, t, d, x)
        s = _tile_score(x)
        if s != s:
            best, score = q, s
            xbest[:] = x
            break
        if best < 0 or s > score:
            best, score = q, s
            xbest[:] = x
    return best, score


@njit(cache=True, nogil=True)
def _from_tile(U, S, t, x):  # pragma: no cover - compiled
    """``(a*, u*)`` on tile ``t``: ``a = 1 / x0``, ``u = U_t + clip(b, 0, 1) S_t`` (Eq 1.16)."""
    a = 1.0 / x[0]
    m = U.shape[1]
    u = np.zeros(m)
    for i in range(S.shape[1]):
        b = x[i + 1] * a
        b = min(max(b, 0.0), 1.0)
        for j in range(m):
            u[j] += b * S[t, i, j]
    for j in range(m):
        u[j] = U[t, j] + u[j]
    return a, u


@njit(cache=True, nogil=True)
def _sequential(Minv, U, S, d):  # pragma: no cover - compiled
    """Sequential facet search over every stored tile (1.3.4.2.1)."""
    T, k = Minv.shape[0], d.shape[0]
    x = np.empty(k)
    xb = np.empty(k)
    tiles = np.arange(T)
    t, _ = _best_tile(Minv, tiles, T, d, x, xb)
    t = max(t, 0)
    _matvec_tile(Minv, t, d, x)
    return _from_tile(U, S, t, x)


@njit(cache=True, nogil=True)
def _demand(v, p0, d):  # pragma: no cover - compiled
    """``d = v - p0``; False when ``d`` is negligible (the base point answers)."""
    dmax, vmax = 0.0, 1.0
    for i in range(v.shape[0]):
        d[i] = v[i] - p0[i]
        if abs(d[i]) > dmax or d[i] != d[i]:
            dmax = abs(d[i])
        if abs(v[i]) > vmax:
            vmax = abs(v[i])
    return dmax > 1e-14 * vmax


@njit(cache=True, nogil=True)
def _blocked(Nz, d):  # pragma: no cover - compiled
    """Whether the ray leaves at once through a facet holding the base point."""
    k = d.shape[0]
    nd = 0.0
    for i in range(k):
        nd += d[i] * d[i]
    tol = 1e-12 * math.sqrt(nd)
    for f in range(Nz.shape[0]):
        s = 0.0
        for i in range(k):
            s += Nz[f, i] * d[i]
        if s > tol:
            return True
    return False


@njit(cache=True, nogil=True)
def _eq_1_15(u0, a, ustar):  # pragma: no cover - compiled
    if a >= 1.0:
        u = np.empty(u0.shape[0])
        for j in range(u0.shape[0]):
            u[j] = u0[j] + (ustar[j] - u0[j]) / a
        return u
    return ustar


@njit(cache=True, nogil=True)
def facet_solve(v, p0, u0, Nz, Minv, U, S):  # pragma: no cover - compiled
    """``da_facet`` for the nominal box: returns ``(u, iterations)``."""
    d = np.empty(v.shape[0])
    if not _demand(v, p0, d) or _blocked(Nz, d):
        return u0.copy(), 0
    a, ustar = _sequential(Minv, U, S, d)
    return _eq_1_15(u0, a, ustar), 1


@njit(cache=True, nogil=True)
def facet_solve_batch(V, p0, u0, Nz, Minv, U, S):  # pragma: no cover - compiled
    """:func:`facet_solve` for each row of ``V``: a batch row is bitwise its single call."""
    n = V.shape[0]
    out = np.empty((n, u0.shape[0]))
    for r in range(n):
        u, _ = facet_solve(V[r], p0, u0, Nz, Minv, U, S)
        out[r] = u
    return out


# ---------------------------------------------------------------- Durham's edge bisection
@njit(cache=True, nogil=True)
def _sign(x):  # pragma: no cover - compiled
    if x > 0:
        return 1.0
    if x < 0:
        return -1.0
    if x == 0:
        return 0.0
    return np.nan


@njit(cache=True, nogil=True)
def _edge(th, gx, gy0, gz0, cx, cy0, cz0, gy, gz, tb, agy, order, sig):  # pragma: no cover - compiled
    """Silhouette edge over the positive x-axis at rotation angle ``th`` (``EdgeBisect._edge``).

    Writes the generator signs into ``sig``; returns the edge class and the edge point's z.
    """
    C = gx.shape[0]
    co, si = math.cos(th), math.sin(th)
    for c in range(C):
        gy[c] = co * gy0[c] + si * gz0[c]
        gz[c] = -si * gy0[c] + co * gz0[c]
    cy = co * cy0 + si * cz0
    cz = -si * cy0 + co * cz0
    total = 0.0
    for c in range(C):
        tb[c] = -gx[c] / gy[c] if gy[c] != 0 else np.inf
        agy[c] = abs(gy[c])
        total += agy[c]
    if C <= 32:  # argsort by insertion: no allocation, ties keep index order
        for q in range(C):
            i = q
            while i > 0 and tb[order[i - 1]] > tb[q]:
                order[i] = order[i - 1]
                i -= 1
            order[i] = q
    else:
        order[:] = np.argsort(tb)
    # weighted median of the breakpoints: first one where the slope turns non-negative
    base = cy - total
    run = 0.0
    n_neg = 0
    for q in range(C):
        run += agy[order[q]]
        if 2.0 * run + base < 0:
            n_neg += 1
    c = order[min(n_neg, C - 1)]
    t = tb[c]
    sy, sz = 0.0, 0.0
    for q in range(C):
        s = _sign(gx[q] + t * gy[q])
        if q == c:
            s = 0.0
        sig[q] = s
        sy += s * gy[q]
        sz += s * gz[q]
    step = -(cy + sy) / gy[c]
    return c, cz + sz + step * gz[c]


@njit(cache=True, nogil=True)
def _try_facet(cl, sl, ch, sh, d, pair_cross, lut, tile_ptr, tile_pos, Minv, U, S, x, xb):  # pragma: no cover
    """``EdgeBisect._try_facet``: Eq 1.17 on the facet the two bracketing edges span.

    Returns ``(found, a*, u*)``.
    """
    C = sl.shape[0]
    i = j = -1
    for q in range(C):
        if sl[q] != sh[q] or q == cl or q == ch:
            if i < 0:
                i = q
            else:
                j = q
                break
    empty = np.empty(0)
    if j < 0:
        return False, 0.0, empty
    s = d[0] * pair_cross[i, j, 0] + d[1] * pair_cross[i, j, 1] + d[2] * pair_cross[i, j, 2]
    f = lut[i, j, 1 if s > 0 else 0]
    if f < 0:
        return False, 0.0, empty
    lo, hi = tile_ptr[f], tile_ptr[f + 1]
    if hi == lo:
        return False, 0.0, empty
    if hi - lo == 1:  # a parallelogram: Eq 1.17 on three floats
        t = tile_pos[lo]
        _matvec_tile(Minv, t, d, x)
        x0 = x[0]
        slack = _TOL * abs(x0)
        if not x0 > 0:
            return False, 0.0, empty
        for q in range(1, x.shape[0]):
            if not (-slack <= x[q] <= x0 + slack):
                return False, 0.0, empty
        a, u = _from_tile(U, S, t, x)
        return True, a, u
    q, score = _best_tile(Minv, tile_pos[lo:hi], hi - lo, d, x, xb)
    if score < -_TOL:
        return False, 0.0, empty
    a, u = _from_tile(U, S, tile_pos[lo + q], xb)
    return True, a, u


@njit(cache=True, nogil=True)
def bisect_solve(v, p0, u0, Nz, Minv, U, S, W, G, c0, lut, pair_cross, tile_ptr, tile_pos,
                 fractions, first_angles, max_rounds):  # pragma: no cover - compiled
    """``da_bisect`` for the nominal box (k = 3): returns ``(u, iterations, rounds, fell_back)``.

    ``rounds`` is 0 when the search did not run (negligible or blocked demand) and
    ``fell_back`` is True when ``max_rounds`` passed without a facet (then the sequential
    search answers), as in ``EdgeBisect._boundary``.
    """
    d = np.empty(3)
    if not _demand(v, p0, d) or _blocked(Nz, d):
        return u0.copy(), 0, 0, False
    # orthonormal frame, x along the scaled demand
    x0, x1, x2 = d[0] * W[0], d[1] * W[1], d[2] * W[2]
    nx = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    x0, x1, x2 = x0 / nx, x1 / nx, x2 / nx
    if abs(x0) <= abs(x1) and abs(x0) <= abs(x2):
        y0, y1, y2 = 0.0, x2, -x1
    elif abs(x1) <= abs(x2):
        y0, y1, y2 = -x2, 0.0, x0
    else:
        y0, y1, y2 = x1, -x0, 0.0
    ny = math.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
    y0, y1, y2 = y0 / ny, y1 / ny, y2 / ny
    z0, z1, z2 = x1 * y2 - x2 * y1, x2 * y0 - x0 * y2, x0 * y1 - x1 * y0
    C = G.shape[1]
    gx, gy0, gz0 = np.empty(C), np.empty(C), np.empty(C)
    for c in range(C):
        gx[c] = x0 * G[0, c] + x1 * G[1, c] + x2 * G[2, c]
        gy0[c] = y0 * G[0, c] + y1 * G[1, c] + y2 * G[2, c]
        gz0[c] = z0 * G[0, c] + z1 * G[1, c] + z2 * G[2, c]
    cx = x0 * c0[0] + x1 * c0[1] + x2 * c0[2]
    cy0 = y0 * c0[0] + y1 * c0[1] + y2 * c0[2]
    cz0 = z0 * c0[0] + z1 * c0[1] + z2 * c0[2]
    K = fractions.shape[0]
    gy, gz, tb, agy = np.empty(C), np.empty(C), np.empty(C), np.empty(C)
    order = np.empty(C, dtype=np.int64)
    cc = np.empty(K, dtype=np.int64)
    zz = np.empty(K)
    ss = np.empty((K, C))
    sl, sh = np.empty(C), np.empty(C)
    x, xb = np.empty(3), np.empty(3)
    cl, zl = _edge(first_angles[0], gx, gy0, gz0, cx, cy0, cz0, gy, gz, tb, agy, order, sl)
    ch = cl
    sh[:] = sl
    zh = -zl  # the half-turn sees the same edge, z mirrored
    lo_t, hi_t = 0.0, math.pi
    for r in range(1, max_rounds + 1):
        for q in range(K):
            th = first_angles[q + 1] if r == 1 else lo_t + (hi_t - lo_t) * fractions[q]
            c, z = _edge(th, gx, gy0, gz0, cx, cy0, cz0, gy, gz, tb, agy, order, ss[q])
            cc[q] = c
            zz[q] = z
        # bracket: first angle whose z has the sign of the upper end
        j = K
        for q in range(K):
            if (zz[q] > 0) if zh > 0 else (zz[q] <= 0):
                j = q
                break
        lo_new, hi_new = lo_t, hi_t
        if j > 0:
            lo_new = first_angles[j] if r == 1 else lo_t + (hi_t - lo_t) * fractions[j - 1]
        if j < K:
            hi_new = first_angles[j + 1] if r == 1 else lo_t + (hi_t - lo_t) * fractions[j]
        if j > 0:
            lo_t = lo_new
            cl = cc[j - 1]
            sl[:] = ss[j - 1]
        if j < K:
            hi_t = hi_new
            ch = cc[j]
            sh[:] = ss[j]
        found, a, ustar = _try_facet(cl, sl, ch, sh, d, pair_cross, lut, tile_ptr, tile_pos, Minv, U, S, x, xb)
        if found:
            return _eq_1_15(u0, a, ustar), 1, r, False
    a, ustar = _sequential(Minv, U, S, d)
    return _eq_1_15(u0, a, ustar), 1, 0, True


# ---------------------------------------------------------------- spherical table
@njit(cache=True, nogil=True)
def table_solve(v, p0, u0, Nz, Minv, U, S, W, table, na, ne):  # pragma: no cover - compiled
    """``da_table`` for the nominal box (k = 3): returns ``(u, iterations, hit)``."""
    d = np.empty(3)
    if not _demand(v, p0, d) or _blocked(Nz, d):
        return u0.copy(), 0, False
    x, y, z = d[0] * W[0], d[1] * W[1], d[2] * W[2]
    az = math.atan2(y, x)
    el = math.atan2(z, math.hypot(x, y))
    i = min(int((az + math.pi) / (2 * math.pi) * na), na - 1)
    j = min(int((el + math.pi / 2) / math.pi * ne), ne - 1)
    cand = table[i * ne + j]
    xt, xb = np.empty(3), np.empty(3)
    q, score = _best_tile(Minv, cand, cand.shape[0], d, xt, xb)
    if score >= -_TOL:
        a, ustar = _from_tile(U, S, cand[q], xb)
        return _eq_1_15(u0, a, ustar), 1, True
    a, ustar = _sequential(Minv, U, S, d)
    return _eq_1_15(u0, a, ustar), 1, False


# ---------------------------------------------------------------- rate-limited box
@njit(cache=True, nogil=True)
def _solve_columns(E, rhs, Q, R, rcond):  # pragma: no cover - compiled
    """Least-squares ``p`` with ``E p = rhs`` (``E`` (k, n), n < k, ``rhs`` in its range).

    Modified Gram-Schmidt QR (accurate to ``cond(E) eps``, as ``lstsq``; a few us cheaper).
    When a column is nearly dependent on the others (``cond(E) >~ 1e6``: a class whose
    rate window is empty, or nearly parallel classes) the system goes to
    ``np.linalg.lstsq`` as in the numpy reference, for the same minimum-norm answer.
    """
    k, n = E.shape
    for e in range(n):
        for i in range(k):
            Q[e, i] = E[i, e]
    scale = 0.0
    for e in range(n):
        s = 0.0
        for i in range(k):
            s += Q[e, i] * Q[e, i]
        scale = max(scale, math.sqrt(s))
    for e in range(n):
        for f in range(e):
            s = 0.0
            for i in range(k):
                s += Q[f, i] * Q[e, i]
            R[f, e] = s
            for i in range(k):
                Q[e, i] -= s * Q[f, i]
        s = 0.0
        for i in range(k):
            s += Q[e, i] * Q[e, i]
        s = math.sqrt(s)
        if not s > 1e-6 * scale:  # ill-conditioned or dependent: as the reference
            return np.linalg.lstsq(E, rhs, rcond)[0]
        R[e, e] = s
        for i in range(k):
            Q[e, i] /= s
    p = _qr_back(Q, R, rhs, np.zeros(n))
    # one step of refinement on the residual: as close to lstsq as round-off allows
    res = np.empty(k)
    for i in range(k):
        s = rhs[i]
        for e in range(n):
            s -= E[i, e] * p[e]
        res[i] = s
    return _qr_back(Q, R, res, p)


@njit(cache=True, nogil=True)
def _qr_back(Q, R, rhs, p0):  # pragma: no cover - compiled
    """``p0 + R^-1 Q^T rhs`` for the thin QR of :func:`_solve_columns`."""
    n, k = Q.shape
    p = np.empty(n)
    for e in range(n - 1, -1, -1):
        s = 0.0
        for i in range(k):
            s += Q[e, i] * rhs[i]
        for f in range(e + 1, n):
            s -= R[e, f] * p[f]
        p[e] = s / R[e, e]
    for e in range(n):
        p[e] += p0[e]
    return p


@njit(cache=True, nogil=True)
def _exit_in_box(y, dn, u0, lo, hi, Br, Nr, NB, member, sign, active, tile_hi, tile_span,
                 facet_ptr):  # pragma: no cover - compiled
    """``(u*, a*)`` of the ray ``Br u0 + a y`` (``y`` in the set's coordinates, ``|d| = dn``)
    in the box ``[lo, hi]``: ``a* = min gap_f / (n_f . y)`` over facets with ``n_f . y > 0``,
    gaps from this box; ``u*`` from Eq 1.16 on the hit facet's tiles (least squares, as
    ``point_on_facet``).  ``a* = inf`` when no facet lies ahead (a degenerate structure)."""
    r, m = Br.shape
    F = Nr.shape[0]
    best_f, best_ratio = 0, np.inf
    for f in range(F):
        nd = 0.0
        for i in range(r):
            nd += Nr[f, i] * y[i]
        ratio = np.inf
        if nd > 1e-12 * dn:
            gap = 0.0
            for j in range(m):
                g = max(NB[f, j] * (lo[j] - u0[j]), NB[f, j] * (hi[j] - u0[j]))
                gap += g
            ratio = gap / nd
        if ratio < best_ratio or (ratio != ratio and best_ratio == best_ratio):
            best_f, best_ratio = f, ratio
            if ratio != ratio:
                break
    a = max(0.0, best_ratio)
    ustar = u0.copy()
    if a == 0.0 or a == np.inf:
        return ustar, a
    f = best_f
    # point on facet f: Eq 1.16 on each of its tiles in this box
    q = np.empty(r)
    for i in range(r):
        s = 0.0
        for j in range(m):
            s += Br[i, j] * u0[j]
        q[i] = s + a * y[i]
    n_free = tile_span.shape[1]
    Ut = np.empty(m)
    St = np.zeros((n_free, m))
    E = np.zeros((r, n_free))
    rhs = np.empty(r)
    best = -np.inf
    rcond = _EPS * max(r, n_free)
    Qw = np.empty((n_free, r))
    Rw = np.empty((n_free, n_free))
    for t in range(facet_ptr[f], facet_ptr[f + 1]):
        for j in range(m):
            Ut[j] = (hi[j] if tile_hi[t, j] else lo[j]) if active[j] else u0[j]
        for e in range(n_free):
            c = tile_span[t, e]
            for j in range(m):
                St[e, j] = member[c, j] * (sign[j] * (hi[j] - lo[j]))
        for i in range(r):
            s = 0.0
            for j in range(m):
                s += Br[i, j] * Ut[j]
            rhs[i] = q[i] - s
            for e in range(n_free):
                s = 0.0
                for j in range(m):
                    s += Br[i, j] * St[e, j]
                E[i, e] = s
        margin = 0.0
        if n_free > 0:
            p = _solve_columns(E, rhs, Qw, Rw, rcond)
            margin = np.inf
            for e in range(n_free):
                margin = min(margin, min(p[e], 1.0 - p[e]))
        else:
            p = np.empty(0)
        if margin > best:
            best = margin
            for j in range(m):
                s = 0.0
                for e in range(n_free):
                    s += min(max(p[e], 0.0), 1.0) * St[e, j]
                ustar[j] = Ut[j] + s
        if margin >= -1e-12:
            break
    return ustar, a


@njit(cache=True, nogil=True)
def _base_and_demand(v, up, lo, hi, B, u0, d):  # pragma: no cover - compiled
    """``u0 = clip(up, lo, hi)``, ``d = v - B u0``; False when ``d`` is negligible."""
    k, m = B.shape
    for j in range(m):
        u0[j] = min(max(up[j], lo[j]), hi[j])
    dmax, vmax = 0.0, 1.0
    for i in range(k):
        s = 0.0
        for j in range(m):
            s += B[i, j] * u0[j]
        d[i] = v[i] - s
        if abs(d[i]) > dmax or d[i] != d[i]:
            dmax = abs(d[i])
        if abs(v[i]) > vmax:
            vmax = abs(v[i])
    return dmax > 1e-14 * vmax


@njit(cache=True, nogil=True)
def ray_exit_solve(v, up, lo, hi, B, Br, Nr, NB, member, sign, active, tile_hi, tile_span,
                   facet_ptr):  # pragma: no cover - compiled
    """Direct allocation in a box ``[lo, hi]`` inside the position limits (full-rank set).

    Support-function form (``AttainableSet.ray_exit``, :func:`_exit_in_box`).  Returns
    ``(u, iterations)``; iterations ``-1`` when no facet lies ahead of the ray (a
    degenerate structure: the caller's safe answer).
    """
    k, m = B.shape
    u0 = np.empty(m)
    d = np.empty(k)
    if not _base_and_demand(v, up, lo, hi, B, u0, d):
        return u0, 0
    dn2 = 0.0
    for i in range(k):
        dn2 += d[i] * d[i]
    ustar, a = _exit_in_box(d, math.sqrt(dn2), u0, lo, hi, Br, Nr, NB, member, sign, active, tile_hi, tile_span,
                            facet_ptr)
    if a == np.inf:
        return u0, -1
    return _eq_1_15(u0, a, ustar), 1


@njit(cache=True, nogil=True)
def flat_ray_exit_solve(v, up, lo, hi, B, range_proj, Q, Br, Nr, NB, member, sign, active, tile_hi, tile_span,
                        facet_ptr):  # pragma: no cover - compiled
    """Direct allocation on a flat set (rank ``r < k``) in a box ``[lo, hi]``.

    As the core's ``da``: the ray follows the part of ``d = v - B u0`` in the range of
    ``B`` (``range_proj``); a ray off the set's own hull (orthonormal basis ``Q`` (k, r))
    leaves at once (``u0``); otherwise :func:`_exit_in_box` in the set's coordinates
    ``y = Q' d``.  Returns ``(u, iterations)`` as :func:`ray_exit_solve`.
    """
    k, m = B.shape
    r = Q.shape[1]
    u0 = np.empty(m)
    d0 = np.empty(k)
    if not _base_and_demand(v, up, lo, hi, B, u0, d0):
        return u0, 0
    d = np.empty(k)
    dmax, vmax = 0.0, 1.0
    for i in range(k):
        s = 0.0
        for j in range(k):
            s += range_proj[i, j] * d0[j]
        d[i] = s
        if abs(s) > dmax or s != s:
            dmax = abs(s)
        if abs(v[i]) > vmax:
            vmax = abs(v[i])
    if not dmax > 1e-14 * vmax:
        return u0, 0
    dn2 = 0.0
    for i in range(k):
        dn2 += d[i] * d[i]
    dn = math.sqrt(dn2)
    y = np.empty(r)
    for e in range(r):
        s = 0.0
        for i in range(k):
            s += Q[i, e] * d[i]
        y[e] = s
    off2 = 0.0
    for i in range(k):
        s = d[i]
        for e in range(r):
            s -= Q[i, e] * y[e]
        off2 += s * s
    if r == 0 or not math.sqrt(off2) <= 1e-12 * dn:
        return u0, 1  # leaves the set's hull at once
    ustar, a = _exit_in_box(y, dn, u0, lo, hi, Br, Nr, NB, member, sign, active, tile_hi, tile_span, facet_ptr)
    if a == np.inf:
        return u0, -1
    return _eq_1_15(u0, a, ustar), 1
