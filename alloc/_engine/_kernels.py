"""Compiled kernels for the per-call hot path (numba), measured in benchmarks/bench_alloc.py.

Each numpy call on an 11-element array costs about a microsecond of overhead; the
post-processing every allocation needs (clip onto the bounds, ``B u``, the ``exact`` test,
finiteness) is a handful of such calls, so it is done in one compiled function instead.
The pseudo-inverse family's own kernels (``pinv_scale``, ``cgi``, ``daisy``, ...) are in
:mod:`alloc._engine._inverse_kernels`.
"""

from __future__ import annotations

import numpy as np
import alloc._engine._kernel_cache  # noqa: F401 - kernel caches placed before any kernel is decorated
from numba import njit

__all__ = ["all_finite", "owned_demand", "finish", "finish_owned", "fused_affine", "rate_window", "facet_polish"]

FINISH_EXACT, FINISH_UNATTAINABLE, FINISH_NONFINITE = 0, 1, 2


@njit(cache=True, nogil=True, _nrt=False)
def all_finite(x):  # pragma: no cover - compiled
    for i in range(x.shape[0]):
        if not np.isfinite(x[i]):
            return False
    return True


@njit(cache=True, nogil=True, inline="always")
def clip_scalar(y, lo, hi):  # pragma: no cover - compiled
    """``min(max(y, lo), hi)`` for one value (a NaN stays NaN); inlined where it is called."""
    if y < lo:
        y = lo
    if y > hi:
        y = hi
    return y


@njit(cache=True, nogil=True)
def owned_demand(v, bound):  # pragma: no cover - compiled
    """A copy of ``v`` and whether every ``|v[i]| <= bound`` (False for NaN and inf)."""
    out = np.empty(v.shape[0])
    ok = True
    for i in range(v.shape[0]):
        out[i] = v[i]
        if not abs(v[i]) <= bound:
            ok = False
    return out, ok


@njit(cache=True, nogil=True, inline="always")
def rounding_gamma(m):  # pragma: no cover - compiled
    """Factor of the rounding bound of a computed residual ``fl(sum_j B_ij u_j - v_i)``.

    Summed in order, ``|fl(r_i) - r_i| <= gamma_{m+1} (sum_j |B_ij u_j| + |v_i|)`` with
    ``gamma_n = n u / (1 - n u)``, ``u = 2**-53`` (Higham, *Accuracy and Stability of
    Numerical Algorithms*, 2nd ed., Eq 3.5).  ``(m + 2) * 2**-52`` exceeds ``gamma_{m+1}``
    with room for the rounding of the bound itself, so ``|fl(r_i)| + gamma (...)`` bounds the
    residual in exact arithmetic: ``exact`` is a certificate even where ``|B| |u|`` dwarfs
    ``v`` and the float64 product cancels (there it is withheld, never guessed).
    """
    return (m + 2) * 2.220446049250313e-16


@njit(cache=True, nogil=True, _nrt=False)
def finish(B, u, lo, hi, v, v_ach, rtol):  # pragma: no cover - compiled
    """Clip ``u`` onto ``[lo, hi]`` in place, write ``B u`` into ``v_ach``, and classify.

    Returns 0 when the residual in exact arithmetic is certified within the tolerance,
    ``max_i (|fl(B u - v)_i| + rounding_bound_i) <= rtol * max(1, max|v|)`` (exact; see
    :func:`rounding_gamma`), 1 otherwise, and 2 when ``u`` or ``B u`` holds a non-finite
    value.  Every comparison is written so that a NaN fails it: a NaN can never be
    classified exact.
    """
    k, m = B.shape
    for j in range(m):
        if not np.isfinite(u[j]):
            return 2
    for j in range(m):
        u[j] = clip_scalar(u[j], lo[j], hi[j])
    gamma = rounding_gamma(m)
    err = 0.0
    vmax = 1.0
    for i in range(k):
        s = 0.0
        a = 0.0
        for j in range(m):
            t = B[i, j] * u[j]
            s += t
            a += abs(t)
        v_ach[i] = s
        e = abs(s - v[i]) + gamma * (a + abs(v[i]))
        if not e <= err:  # NaN-safe: a NaN error becomes the error
            err = e
        a = abs(v[i])
        if not a <= vmax:
            vmax = a
    if not (np.isfinite(err) and np.isfinite(vmax)):
        return 2
    return 0 if err <= rtol * vmax else 1


@njit(cache=True, nogil=True)
def finish_owned(B, u_m, lo, hi, v, rtol):  # pragma: no cover - compiled
    """:func:`finish` into one new buffer ``[u | B u | v | v - B u]`` (the result's own arrays,
    ``u_m`` and ``v`` left untouched), and the status code."""
    k, m = B.shape
    out = np.empty(m + 3 * k)
    u = out[:m]
    for j in range(m):
        u[j] = u_m[j]
    code = finish(B, u, lo, hi, v, out[m:m + k], rtol)
    for i in range(k):
        out[m + k + i] = v[i]
        out[m + 2 * k + i] = v[i] - out[m + i]
    return out, code


@njit(cache=True, nogil=True)
def finish_batch(B, U, lo, hi, V, Vach, rtol):  # pragma: no cover - compiled
    """:func:`finish` on each row (``U`` clipped in place): a batch row's ``B u`` and status
    are bitwise those of its single call.  Returns the codes (N,)."""
    n = U.shape[0]
    codes = np.empty(n, dtype=np.int64)
    for r in range(n):
        codes[r] = finish(B, U[r], lo, hi, V[r], Vach[r], rtol)
    return codes


@njit(cache=True, nogil=True, _nrt=False)
def rate_window_into(umin, umax, rate_min, rate_max, u_prev, dt, lo, hi):  # pragma: no cover - compiled
    """Eq 1.28 bounds into ``lo``, ``hi``; where the rate window misses the position box,
    the nearest limit."""
    for j in range(umin.shape[0]):
        a = max(umin[j], u_prev[j] + rate_min[j] * dt)
        b = min(umax[j], u_prev[j] + rate_max[j] * dt)
        if a > b:
            a = min(max(u_prev[j], umin[j]), umax[j])
            b = a
        lo[j] = a
        hi[j] = b


@njit(cache=True, nogil=True)
def rate_window(umin, umax, rate_min, rate_max, u_prev, dt):  # pragma: no cover - compiled
    """Eq 1.28 bounds ``(lo, hi)`` (:func:`rate_window_into` on new arrays)."""
    lo = np.empty(umin.shape[0])
    hi = np.empty(umin.shape[0])
    rate_window_into(umin, umax, rate_min, rate_max, u_prev, dt, lo, hi)
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



# Bits of one word of a free-set key (63 effectors a word): the keys of the cascade's table
# (alloc._engine._inverse_kernels) and of the active set's factor cache (alloc._engine._lsq_factor).
_FREE_BITS = 63


@njit(cache=True, nogil=True)
def packed_out(m, k):  # pragma: no cover - compiled
    """The one array a fast-path call returns, ``m + 3 k`` long: ``u`` (m), ``B u`` (k), a
    copy of ``v`` (k), ``v - B u`` (k) (the allocator wraps read-only views of it into the
    Result: one allocation per call)."""
    return np.empty(m + 3 * k)


@njit(cache=True, nogil=True, _nrt=False)
def copy_demand(v, out, m, vmax_domain):  # pragma: no cover - compiled
    """Copy ``v`` into ``out``; False when ``v`` is outside the valid domain (non-finite
    or ``|v| > vmax_domain``)."""
    k = v.shape[0]
    for i in range(k):
        if not abs(v[i]) <= vmax_domain:  # also NaN
            return False
        out[m + k + i] = v[i]
    return True


@njit(cache=True, nogil=True, _nrt=False)
def close_out(out, m, k):  # pragma: no cover - compiled
    """Write ``v - B u`` into a packed output."""
    for i in range(k):
        out[m + 2 * k + i] = out[m + k + i] - out[m + i]


@njit(cache=True, nogil=True)
def fused_affine(W, v, rtol, vmax_domain):  # pragma: no cover - compiled
    """One call for ``u = clip(c + P v)``, ``B u`` and the status, without rate limits.

    ``W`` packs everything constant, one row per effector: ``[c | P (k) | B' (k) | umin | umax]``
    (numba charges per argument, so one packed array is measurably cheaper than five).
    Returns ``(out, code, 0)``: the :func:`packed_out` array, the code (0 exact,
    1 unattainable, 2 non-finite ``u`` or ``B u``, 3 ``v`` outside the valid domain) and
    the iteration count.
    """
    m = W.shape[0]
    k = v.shape[0]
    out = packed_out(m, k)
    if not copy_demand(v, out, m, vmax_domain):
        return out, 3, 0
    vmax = 1.0
    for i in range(k):
        vmax = max(vmax, abs(v[i]))
    for j in range(m):
        s = W[j, 0]
        for i in range(k):
            s += W[j, 1 + i] * v[i]
        if not np.isfinite(s):
            return out, 2, 0
        out[j] = clip_scalar(s, W[j, 1 + 2 * k], W[j, 2 + 2 * k])
    gamma = rounding_gamma(m)
    err = 0.0
    for i in range(k):
        s = 0.0
        a = 0.0
        for j in range(m):
            t = W[j, 1 + k + i] * out[j]
            s += t
            a += abs(t)
        out[m + i] = s
        e = abs(s - v[i]) + gamma * (a + abs(v[i]))  # certified, as in :func:`finish`
        if not e <= err:  # NaN-safe
            err = e
    close_out(out, m, k)
    return out, (2 if not np.isfinite(err) else (0 if err <= rtol * vmax else 1)), 0


@njit(cache=True, nogil=True)
def free_set_pinv(SB, rdiag, S, free, rcond, floor):  # pragma: no cover - compiled
    """``weighted_pinv(B[:, F], Wu[F, F], Wv)`` for a diagonal ``Wu``, ``F`` = ``free``.

    ``SB = S B`` with ``S' S = Wv`` and ``rdiag = Wu^-1/2``: ``A = S B_F R_F``, and
    ``P = R_F A^+ S`` with singular values ``<= max(rcond * s_max(A), floor)`` dropped
    (``alloc._engine._linalg.truncated_pinv``).  Returns ``P`` (|F| x k).
    """
    k, m = SB.shape
    nf = 0
    for j in range(m):
        if free[j]:
            nf += 1
    A = np.empty((k, nf))
    F = np.empty(nf, dtype=np.int64)
    q = 0
    for j in range(m):
        if free[j]:
            F[q] = j
            for i in range(k):
                A[i, q] = SB[i, j] * rdiag[j]
            q += 1
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    cut = max(rcond * s[0], floor)
    Z = np.zeros((nf, k))
    for l in range(s.shape[0]):
        if s[l] > cut:
            for q in range(nf):
                a = Vt[l, q] / s[l]
                for i in range(k):
                    Z[q, i] += a * U[i, l]
    P = np.zeros((nf, k))
    for q in range(nf):
        for i in range(k):
            t = 0.0
            for l in range(k):
                t += Z[q, l] * S[l, i]
            P[q, i] = rdiag[F[q]] * t
    return P


# Fixed-order products for the methods' per-call paths: numpy's ``@`` takes BLAS or its own
# loops by the operands' layout (contiguous or strided, their alignment), which round
# differently, so an allocator and its copy could answer a few ulps apart.
@njit(cache=True, nogil=True)
def matvec(A, x):  # pragma: no cover - compiled
    """``A @ x`` summed left to right in each row."""
    n, p = A.shape
    y = np.empty(n)
    for i in range(n):
        s = 0.0
        for j in range(p):
            s += A[i, j] * x[j]
        y[i] = s
    return y


@njit(cache=True, nogil=True)
def rmatvec(A, x):  # pragma: no cover - compiled
    """``A.T @ x`` summed in row order of ``A``."""
    n, p = A.shape
    y = np.zeros(p)
    for i in range(n):
        for j in range(p):
            y[j] += A[i, j] * x[i]
    return y
