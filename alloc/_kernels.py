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
