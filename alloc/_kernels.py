"""Compiled kernels for the per-call hot path (numba), measured in benchmarks/bench_alloc.py.

Each numpy call on an 11-element array costs about a microsecond of overhead; the
post-processing every allocation needs (clip onto the bounds, ``B u``, the ``exact`` test,
finiteness) is a handful of such calls, so it is done in one compiled function instead.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["all_finite", "affine", "finish"]

FINISH_EXACT, FINISH_UNATTAINABLE, FINISH_NONFINITE = 0, 1, 2


@njit(cache=True, nogil=True)
def all_finite(x):  # pragma: no cover - compiled
    for i in range(x.shape[0]):
        if not np.isfinite(x[i]):
            return False
    return True


@njit(cache=True, nogil=True)
def affine(c, P, v):  # pragma: no cover - compiled
    """``c + P v`` for a small dense ``P``."""
    m, k = P.shape
    out = np.empty(m)
    for j in range(m):
        s = c[j]
        for i in range(k):
            s += P[j, i] * v[i]
        out[j] = s
    return out


@njit(cache=True, nogil=True)
def finish(B, u, lo, hi, v, v_ach, rtol):  # pragma: no cover - compiled
    """Clip ``u`` onto ``[lo, hi]`` in place, write ``B u`` into ``v_ach``, and classify.

    Returns 0 when ``max|B u - v| <= rtol * max(1, max|v|)`` (exact), 1 otherwise, and 2
    when ``u`` holds a non-finite value (then nothing is written).
    """
    k, m = B.shape
    for j in range(m):
        if not np.isfinite(u[j]):
            return 2
    for j in range(m):
        x = u[j]
        if x < lo[j]:
            x = lo[j]
        if x > hi[j]:
            x = hi[j]
        u[j] = x
    err = 0.0
    vmax = 1.0
    for i in range(k):
        s = 0.0
        for j in range(m):
            s += B[i, j] * u[j]
        v_ach[i] = s
        e = abs(s - v[i])
        if e > err:
            err = e
        a = abs(v[i])
        if a > vmax:
            vmax = a
    return 0 if err <= rtol * vmax else 1


@njit(cache=True, nogil=True)
def affine_finish(c, P, B, v, lo, hi, rtol):  # pragma: no cover - compiled
    """Fused pseudo-inverse/ganging step: ``u = clip(c + P v)``, ``B u`` and the status code."""
    u = affine(c, P, v)
    v_ach = np.empty(B.shape[0])
    code = finish(B, u, lo, hi, v, v_ach, rtol)
    return u, v_ach, code


@njit(cache=True, nogil=True)
def rate_window(umin, umax, rate_min, rate_max, u_prev, dt):  # pragma: no cover - compiled
    """Eq 1.28 bounds; where the rate window misses the position box, the nearest limit."""
    m = umin.shape[0]
    lo = np.empty(m)
    hi = np.empty(m)
    for j in range(m):
        a = max(umin[j], u_prev[j] + rate_min[j] * dt)
        b = min(umax[j], u_prev[j] + rate_max[j] * dt)
        if a > b:
            a = min(max(u_prev[j], umin[j]), umax[j])
            b = a
        lo[j] = a
        hi[j] = b
    return lo, hi


@njit(cache=True, nogil=True)
def facet_polish(B, ustar, d, u0, lo, hi, a):  # pragma: no cover - compiled
    """Exact boundary point on the facet an LP found (used by ``da``).

    With ``k - 1`` effectors strictly inside their limits, solve the ``k x k`` system
    ``B_F u_F - a d = B u0 - B_S u_S`` by Gaussian elimination with partial pivoting.
    Returns ``(a, u, ok)``; ``ok`` is False (and the inputs are returned) when the point
    is not a plain facet hit or the exact solution is not admissible.
    """
    k, m = B.shape
    nf = 0
    F = np.empty(m, dtype=np.int64)
    for j in range(m):
        span = max(hi[j] - lo[j], 1e-300)
        if ustar[j] - lo[j] > 1e-7 * span and hi[j] - ustar[j] > 1e-7 * span:
            if nf < m:
                F[nf] = j
            nf += 1
    if nf != k - 1:
        return a, ustar, False
    M = np.empty((k, k))
    rhs = np.empty(k)
    for i in range(k):
        s = 0.0
        for j in range(m):
            s += B[i, j] * u0[j]
        for j in range(m):
            inside = False
            for q in range(nf):
                if F[q] == j:
                    inside = True
            if not inside:
                s -= B[i, j] * ustar[j]
        rhs[i] = s
        for q in range(nf):
            M[i, q] = B[i, F[q]]
        M[i, k - 1] = -d[i]
    for c in range(k):  # elimination with partial pivoting
        piv = c
        for r in range(c + 1, k):
            if abs(M[r, c]) > abs(M[piv, c]):
                piv = r
        if abs(M[piv, c]) < 1e-300:
            return a, ustar, False
        if piv != c:
            for q in range(k):
                M[c, q], M[piv, q] = M[piv, q], M[c, q]
            rhs[c], rhs[piv] = rhs[piv], rhs[c]
        for r in range(c + 1, k):
            f = M[r, c] / M[c, c]
            for q in range(c, k):
                M[r, q] -= f * M[c, q]
            rhs[r] -= f * rhs[c]
    x = np.empty(k)
    for c in range(k - 1, -1, -1):
        s = rhs[c]
        for q in range(c + 1, k):
            s -= M[c, q] * x[q]
        x[c] = s / M[c, c]
    a_new = x[k - 1]
    if not (a_new >= 0.0 and abs(a_new - a) <= 1e-6 * max(1.0, a)):
        return a, ustar, False
    u = ustar.copy()
    for q in range(nf):
        j = F[q]
        if x[q] < lo[j] or x[q] > hi[j]:
            return a, ustar, False
        u[j] = x[q]
    return a_new, u, True
