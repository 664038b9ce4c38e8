"""Compiled kernels for the per-call hot path (numba), measured in benchmarks/bench_alloc.py.

Each numpy call on an 11-element array costs about a microsecond of overhead; the
post-processing every allocation needs (clip onto the bounds, ``B u``, the ``exact`` test,
finiteness) is a handful of such calls, so it is done in one compiled function instead.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["all_finite", "owned_demand", "affine", "finish", "finish_owned", "fused_affine", "rate_window",
           "facet_polish"]

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


# --- pseudo-inverse family and cascades (pinv_scale, cgi, daisy) ----------------------
#
# Each replaces a Python loop of small numpy calls (clip, fancy indexing, B u, a dict
# lookup per iteration) with one compiled call.  The arithmetic is the same as the numpy
# code it replaces (tests/alloc/test_kernels_cascade.py compares the two on random problems).


@njit(cache=True, nogil=True)
def clip(x, lo, hi):  # pragma: no cover - compiled
    """``min(max(x, lo), hi)`` elementwise (a NaN stays NaN, as with np.minimum/np.maximum)."""
    m = x.shape[0]
    out = np.empty(m)
    for j in range(m):
        out[j] = clip_scalar(x[j], lo[j], hi[j])
    return out


@njit(cache=True, nogil=True, _nrt=False)
def _residual(B, u, v, r):  # pragma: no cover - compiled
    """``r = v - B u``."""
    k, m = B.shape
    for i in range(k):
        s = 0.0
        for j in range(m):
            s += B[i, j] * u[j]
        r[i] = v[i] - s


@njit(cache=True, nogil=True, _nrt=False)
def _scale_to_box(base, du, lo, hi, idx, n):  # pragma: no cover - compiled
    """Largest ``s`` in [0, 1] with ``lo <= base + s du <= hi`` over ``j = idx[:n]``;
    ``du`` is indexed by position ``q``, the bounds by ``idx[q]`` (``max_scale``)."""
    s = 1.0
    for q in range(n):
        j = idx[q]
        d = du[q]
        if d > 0.0:
            t = (hi[j] - base[j]) / d
            if t < s:
                s = t
        elif d < 0.0:
            t = (lo[j] - base[j]) / d
            if t < s:
                s = t
    return max(0.0, s)


@njit(cache=True, nogil=True)
def scaled_increment(P, B, b, v, lo, hi):  # pragma: no cover - compiled
    """``pinv_scale``: ``base = clip(b)``, ``du = P (v - B base)``, ``u = base + s du``
    with the largest ``s`` in [0, 1] keeping ``u`` in ``[lo, hi]``."""
    k, m = B.shape
    base = clip(b, lo, hi)
    r = np.empty(k)
    _residual(B, base, v, r)
    du = np.empty(m)
    idx = np.empty(m, dtype=np.int64)
    for j in range(m):
        s = 0.0
        for i in range(k):
            s += P[j, i] * r[i]
        du[j] = s
        idx[j] = j
    s = _scale_to_box(base, du, lo, hi, idx, m)
    u = np.empty(m)
    for j in range(m):
        u[j] = base[j] + s * du[j]
    return u


@njit(cache=True)
def fused_scaled(P, B, base, lo, hi, rtol, vmax_domain, v, u_prev, dt):  # pragma: no cover - compiled
    """``pinv_scale`` without rate limits as one call (the allocator's packed fast path;
    ``u_prev`` and ``dt`` unused): :func:`scaled_increment` from the clipped bias ``base``,
    then :func:`finish`, into a :func:`packed_out` array.  Returns ``(out, code, 0)``
    (code 3: ``v`` outside the valid domain)."""
    k, m = B.shape
    out = packed_out(m, k)
    if not copy_demand(v, out, m, vmax_domain):
        return out, 3, 0
    r = out[m + 2 * k:]  # scratch until close_out writes v - B u there
    _residual(B, base, v, r)
    du = out[:m]
    for j in range(m):
        s = 0.0
        for i in range(k):
            s += P[j, i] * r[i]
        du[j] = s
    s = _scale_to_box(base, du, lo, hi, np.arange(m), m)
    for j in range(m):
        du[j] = base[j] + s * du[j]
    code = finish(B, du, lo, hi, v, out[m:m + k], rtol)
    close_out(out, m, k)
    return out, code, 0


@njit(cache=True, nogil=True)
def daisy_chain(B, up, v, lo, hi, idx, start, Pcat):  # pragma: no cover - compiled
    """Daisy chaining (Eqs 1.25-1.27) over groups ``idx[start[g]:start[g+1]]`` whose
    pseudo-inverses are the rows ``Pcat[start[g]:start[g+1]]``.  Returns ``(u, used)``."""
    k, m = B.shape
    u = clip(up, lo, hi)
    r = np.empty(k)
    _residual(B, u, v, r)
    vmax = 1.0
    for i in range(k):
        if abs(v[i]) > vmax:
            vmax = abs(v[i])
    tol = 1e-12 * vmax
    du = np.empty(m)
    step = np.empty(k)
    used = 0
    for g in range(start.shape[0] - 1):
        small = True
        for i in range(k):
            if not abs(r[i]) <= tol:
                small = False
        if small:
            break
        used += 1
        a = start[g]
        n = start[g + 1] - a
        for q in range(n):
            s = 0.0
            for i in range(k):
                s += Pcat[a + q, i] * r[i]
            du[q] = s
        gidx = idx[a:a + n]
        s = _scale_to_box(u, du, lo, hi, gidx, n)
        for i in range(k):
            step[i] = 0.0
        for q in range(n):
            d = s * du[q]
            u[gidx[q]] += d
            for i in range(k):
                step[i] += B[i, gidx[q]] * d
        for i in range(k):
            r[i] = r[i] - step[i]
    return u, used


@njit(cache=True, nogil=True)
def affine_clip_batch(c, P, V, lo, hi):  # pragma: no cover - compiled
    """Rows ``clip(c + P v)`` for the rows ``v`` of ``V``: the arithmetic of
    :func:`fused_affine` (same order of operations), so a batch equals its single calls."""
    n, k = V.shape
    m = c.shape[0]
    U = np.empty((n, m))
    for r in range(n):
        for j in range(m):
            s = c[j]
            for i in range(k):
                s += P[j, i] * V[r, i]
            if s < lo[j]:
                s = lo[j]
            if s > hi[j]:
                s = hi[j]
            U[r, j] = s
    return U


@njit(cache=True, nogil=True)
def scaled_increment_batch(P, B, b, V, lo, hi):  # pragma: no cover - compiled
    """:func:`scaled_increment` for each row of ``V`` (bitwise the single-call answer)."""
    n = V.shape[0]
    U = np.empty((n, B.shape[1]))
    for r in range(n):
        U[r] = scaled_increment(P, B, b, V[r], lo, hi)
    return U


# Free sets of the cascade are keys into an open-addressing hash table held in numpy
# arrays: ``keys[h]`` (the set as bit words, 63 effectors a word), ``slots[h]`` (-1 when
# empty) the index into ``bank``, where ``bank[slot, :|F|]`` is that set's pseudo-inverse.
_FREE_BITS = 63


@njit(cache=True, nogil=True, _nrt=False)
def _free_key(free, key):  # pragma: no cover - compiled
    for w in range(key.shape[0]):
        key[w] = 0
    for j in range(free.shape[0]):
        if free[j]:
            key[j // _FREE_BITS] |= np.int64(1) << np.int64(j % _FREE_BITS)


@njit(cache=True, nogil=True, _nrt=False)
def _probe(keys, slots, key):  # pragma: no cover - compiled
    """Table position of ``key``, or of the empty place where it belongs."""
    h = np.int64(0)
    for w in range(key.shape[0]):
        h = (h ^ key[w]) * np.int64(-7046029254386353131)  # Fibonacci hashing
    mask = slots.shape[0] - 1
    pos = (h >> np.int64(29)) & mask
    while slots[pos] >= 0:
        same = True
        for w in range(key.shape[0]):
            if keys[pos, w] != key[w]:
                same = False
                break
        if same:
            return pos
        pos = (pos + 1) & mask
    return pos


@njit(cache=True, nogil=True)
def free_set_insert(keys, slots, free, slot):  # pragma: no cover - compiled
    """Record that ``bank[slot]`` holds the pseudo-inverse of free set ``free``."""
    key = np.empty(keys.shape[1], dtype=np.int64)
    _free_key(free, key)
    pos = _probe(keys, slots, key)
    keys[pos] = key
    slots[pos] = slot


@njit(cache=True, nogil=True)
def cascade(B, up, v, lo, hi, keys, slots, bank, u, free, it0):  # pragma: no cover - compiled
    """Cascaded generalized inverse (section 1.3.4.6) over cached pseudo-inverses.

    With ``it0 == 1`` starts afresh (writes ``u`` and ``free``); otherwise resumes at
    iteration ``it0`` from the state in ``u`` and ``free``.  Returns ``(iterations, 0)``
    when done, or ``(it, 1)`` when the pseudo-inverse of the current free set is not in the
    table: the caller adds it and resumes with ``it0 = it``.
    """
    k, m = B.shape
    base = clip(up, lo, hi)
    if it0 == 1:
        for j in range(m):
            u[j] = base[j]
            free[j] = lo[j] < hi[j]
    F = np.empty(m, dtype=np.int64)
    r = np.empty(k)
    uF = np.empty(m)
    key = np.empty(keys.shape[1], dtype=np.int64)
    for it in range(it0, m + 2):
        nf = 0
        for j in range(m):
            if free[j]:
                F[nf] = j
                nf += 1
        if nf == 0:
            return it - 1, 0  # (2) all saturated
        for q in range(nf):
            u[F[q]] = base[F[q]]
        _residual(B, u, v, r)
        _free_key(free, key)
        pos = _probe(keys, slots, key)
        if slots[pos] < 0:
            return it, 1
        P = bank[slots[pos]]
        for q in range(nf):
            s = 0.0
            for i in range(k):
                s += P[q, i] * r[i]
            uF[q] = base[F[q]] + s
        if nf < k:  # (3) Eq 1.24, then clip
            for q in range(nf):
                j = F[q]
                u[j] = clip_scalar(uF[q], lo[j], hi[j])
            return it, 0
        hit = False
        for q in range(nf):
            j = F[q]
            if uF[q] > hi[j] or uF[q] < lo[j]:
                hit = True
        if not hit:  # (1) no new saturation
            for q in range(nf):
                u[F[q]] = uF[q]
            return it, 0
        for q in range(nf):
            j = F[q]
            if uF[q] > hi[j]:
                u[j] = hi[j]
                free[j] = False
            elif uF[q] < lo[j]:
                u[j] = lo[j]
                free[j] = False
    return m + 1, 0


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
    (``alloc._linalg.truncated_pinv``).  Returns ``P`` (|F| x k).
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


@njit(cache=True, nogil=True)
def increment(P, B, b, v):  # pragma: no cover - compiled
    """``b + P (v - B b)`` (the incremental pseudo-inverse about ``b``), in a fixed order."""
    k, m = B.shape
    r = np.empty(k)
    for i in range(k):
        s = 0.0
        for j in range(m):
            s += B[i, j] * b[j]
        r[i] = v[i] - s
    u = np.empty(m)
    for j in range(m):
        s = 0.0
        for i in range(k):
            s += P[j, i] * r[i]
        u[j] = b[j] + s
    return u
