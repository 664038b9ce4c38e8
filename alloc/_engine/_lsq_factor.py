"""Factorisations of the active-set solver's free sets (:mod:`alloc._engine._active_set`).

The least-squares step on the free effectors is the minimum-norm solution from a one-sided
Jacobi SVD of the small ``rows x free`` matrix in the ``Wu`` metric (:func:`_jacobi`,
:func:`_factor`) and its triangular solves (:func:`_lsolve`, :func:`_ltsolve`).  A free
set's factors depend on the level and the set alone, so :func:`_factors` keeps them per
(level, free set) in the allocator's cache bank (a slot's layout: :func:`_slot_offsets`);
the cache changes the cost, never the answer.
"""

from __future__ import annotations

import numpy as np
import alloc._engine._kernel_cache  # noqa: F401 - kernel caches placed before any kernel is decorated
from numba import njit

from ._kernels import _FREE_BITS
from ._active_set_layout import (_A, _FACTORED, _FIDX, _FREE, _HEAD, _KEY, _MISC, _NCW, _NEXT_SLOT, _NLW, _OVER,
                                 _TABLE, _WORDS, _WU, OVERFLOW_SLOTS)

__all__ = ["SIGMA_RTOL", "JACOBI_EPS"]

#: Singular values below this fraction of the largest are round-off (dropped).
SIGMA_RTOL = 1e-12


#: Unit round-off of the Jacobi SVD's orthogonality test (see :func:`_jacobi`).
JACOBI_EPS = float(np.finfo(float).eps)


@njit(cache=True, nogil=True, _nrt=False)
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
    # a pair is orthogonal when |c| <= tol sqrt(a b): the computed c of an n-row dot product
    # carries a relative error up to about n eps, so a smaller tol cannot be met on
    # (near-)dependent columns and the sweeps ran to their cap (40 sweeps, 4-14 us a
    # factorisation at ICE size, the slow tail of first-seen free sets; LAPACK's xGESVJ uses
    # sqrt(n) eps for the same reason)
    tol = max(1e-15, n * JACOBI_EPS)
    # a column below 1e-15 of ||X||_F is round-off (dropped below, SIGMA_RTOL = 1e-12): it
    # is not rotated.  With more columns than rows (p > n) one column must become such noise,
    # and no rotation can make it orthogonal to the others, which already span the rows: the
    # sweeps ran to their cap on every such matrix (2 x 3 at the second stage of ICE qp).
    small = 0.0
    for j in range(p):
        for r in range(n):
            small += X[r, j] * X[r, j]
    small *= 1e-30
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
                if c == 0.0 or a <= small or b <= small or abs(c) <= tol * np.sqrt(a * b):
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


@njit(cache=True, nogil=True, inline="always")
def _lsolve(bankL, s, n, diag, vecs, row):  # pragma: no cover - compiled
    """``x[:n] = L^-1 x[:n]`` (forward substitution), ``L = bankL[s]``, ``x = vecs[row]``."""
    for q in range(n):
        acc = vecs[row, q]
        if not diag:
            for t in range(q):
                acc -= bankL[s, q, t] * vecs[row, t]
        vecs[row, q] = acc / bankL[s, q, 0 if diag else q]


@njit(cache=True, nogil=True, inline="always")
def _lsolve_col(L, n, diag, X, c):  # pragma: no cover - compiled
    """``X[:n, c] = L^-1 X[:n, c]``."""
    for q in range(n):
        acc = X[q, c]
        if not diag:
            for s in range(q):
                acc -= L[q, s] * X[s, c]
        X[q, c] = acc / L[q, 0 if diag else q]


@njit(cache=True, nogil=True, inline="always")
def _ltsolve(bankL, s, n, diag, vecs, row):  # pragma: no cover - compiled
    """``x[:n] = L^-T x[:n]`` (back substitution), ``L = bankL[s]``, ``x = vecs[row]``."""
    for q in range(n - 1, -1, -1):
        acc = vecs[row, q]
        if not diag:
            for t in range(q + 1, n):
                acc -= bankL[s, t, q] * vecs[row, t]
        vecs[row, q] = acc / bankL[s, q, 0 if diag else q]


@njit(cache=True, nogil=True, _nrt=False)
def _factor(A, r0, r1, Wu, diag, F, nf, L, Yc, Vc, sc, Ya, Va, sa):  # pragma: no cover - compiled
    """Factorise the free set ``F[:nf]`` of the level with rows ``A[r0:r1]`` (equalities ``A[:r0]``).

    ``L L' = Wu[F, F]``; ``Yc`` (with ``Vc``, ``sc``) the SVD of the equality rows in the ``L``
    metric, ``L^-1 A[:r0, F]'``; ``Ya`` (with ``Va``, ``sa``) that of this level's rows projected
    onto their null space.  A pure function of the level and ``F``: cached per free set.
    """
    nl = r1 - r0
    nc = r0
    if diag:
        for q in range(nf):
            L[q, 0] = np.sqrt(Wu[F[q], F[q]])  # a diagonal L is stored as a column
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
    for c in range(nc):
        for q in range(nf):
            Yc[q, c] = A[c, F[q]]
        _lsolve_col(L, nf, diag, Yc, c)
    if nc > 0:
        _jacobi(Yc, nf, nc, Vc, sc, 0.0)
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


@njit(cache=True, nogil=True, inline="always")
def _factors(mats, ivecs, bankL, bank, r0, r1, lev, diag, nf, m):  # pragma: no cover - compiled
    """The cache slot holding the factorisation of the current free set (``_factor``'s
    ``L = bankL[s]``, the rest :func:`_slot` of ``bank[s]``): looked up, else computed (and
    kept in the hash table while it has room; past that, in the overflow slot of its hash).  Cached and
    recomputed factors are bitwise equal, so the cache never changes an answer, only its cost.  The hash table (rows ``_TABLE:`` of ``ivecs``)
    is open addressing as in :func:`alloc._engine._inverse_kernels._probe`.
    """
    words = ivecs[_HEAD, _WORDS]
    for w in range(words):
        ivecs[_KEY, w] = 0
    for j in range(m):
        if ivecs[_FREE, j]:
            ivecs[_KEY, j // _FREE_BITS] |= np.int64(1) << np.int64(j % _FREE_BITS)
    ivecs[_KEY, words - 1] = lev + 1
    h = np.int64(0)
    for w in range(words):
        h = (h ^ ivecs[_KEY, w]) * np.int64(-7046029254386353131)  # Fibonacci hashing
    mask = ivecs.shape[0] - _TABLE - 1
    pos = (h >> np.int64(29)) & mask
    while ivecs[_TABLE + pos, 0] >= 0:
        same = True
        for w in range(words):
            if ivecs[_TABLE + pos, 1 + w] != ivecs[_KEY, w]:
                same = False
                break
        if same:
            return ivecs[_TABLE + pos, 0]
        pos = (pos + 1) & mask
    s = ivecs[_MISC, _NEXT_SLOT]
    if s < bankL.shape[0]:
        ivecs[_MISC, _NEXT_SLOT] = s + 1
        for w in range(words):
            ivecs[_TABLE + pos, 1 + w] = ivecs[_KEY, w]
        ivecs[_TABLE + pos, 0] = s
    else:  # the table is full: the overflow slot of this hash, looked up, else overwritten
        s = (h >> np.int64(40)) & np.int64(OVERFLOW_SLOTS - 1)
        same = ivecs[_OVER + s, 0] != 0
        for w in range(words):
            if ivecs[_OVER + s, 1 + w] != ivecs[_KEY, w]:
                same = False
        if same:
            return s
        ivecs[_OVER + s, 0] = 1
        for w in range(words):
            ivecs[_OVER + s, 1 + w] = ivecs[_KEY, w]
    ivecs[_MISC, _FACTORED] += 1  # counted for benchmarks/bench_alloc.py
    Yc, Vc, sc, Ya, Va, sa = _slot(bank, s, m, ivecs[_HEAD, _NCW], ivecs[_HEAD, _NLW])
    _factor(mats[_A], r0, r1, mats[_WU], diag, ivecs[_FIDX], nf, bankL[s], Yc, Vc, sc, Ya, Va, sa)
    return s


@njit(cache=True, nogil=True, inline="always")
def _slot_offsets(m, ncw, nlw):  # pragma: no cover - compiled
    """Where a cache slot's blocks start, packed end to end: ``Yc`` (m x ncw) at 0, then
    ``Vc`` (ncw x ncw), ``sc`` (ncw), ``Ya`` (m x nlw), ``Va`` (nlw x nlw), ``sa`` (nlw), each
    row-major; ``ncw`` and ``nlw`` are the most equality rows and level rows a level
    factorises on its own (:func:`pack`).  Returns the starts of ``Vc, sc, Ya, Va, sa`` and
    the slot's length."""
    oVc = m * ncw
    osc = oVc + ncw * ncw
    oYa = osc + ncw
    oVa = oYa + m * nlw
    osa = oVa + nlw * nlw
    return oVc, osc, oYa, oVa, osa, osa + nlw


@njit(cache=True, nogil=True, inline="always")
def _slot(bank, s, m, ncw, nlw):  # pragma: no cover - compiled
    """The blocks of cache slot ``s`` (:func:`_slot_offsets`) as views, for :func:`_factor`."""
    E = bank[s]
    oVc, osc, oYa, oVa, osa, end = _slot_offsets(m, ncw, nlw)
    return (E[:oVc].reshape((m, ncw)), E[oVc:osc].reshape((ncw, ncw)), E[osc:oYa],
            E[oYa:oVa].reshape((m, nlw)), E[oVa:osa].reshape((nlw, nlw)), E[osa:end])
