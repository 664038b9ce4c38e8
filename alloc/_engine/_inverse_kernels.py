"""Compiled kernels of the pseudo-inverse family and its cascades (``pinv``, ``pinv_clip``,
``ganging``, ``pinv_scale``, ``cgi``, ``daisy``), measured in benchmarks/bench_alloc.py.

Each replaces a Python loop of small numpy calls (clip, fancy indexing, ``B u``, a dict
lookup per iteration) with one compiled call.  The arithmetic is the same as the numpy
code it replaces (tests/alloc/test_kernels_cascade.py compares the two on random problems).
What every method's call shares (the clip onto the bounds, ``B u`` and the status, the
packed output, the rate window) is in :mod:`alloc._engine._kernels`.
"""

from __future__ import annotations

import numpy as np
import alloc._engine._kernel_cache  # noqa: F401 - kernel caches placed before any kernel is decorated
from numba import njit

from ._kernels import _FREE_BITS, clip_scalar, close_out, copy_demand, finish, packed_out

__all__ = ["affine", "affine_clip_batch", "cascade", "daisy_chain", "free_set_insert", "fused_scaled", "increment",
           "scaled_increment", "scaled_increment_batch"]


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
