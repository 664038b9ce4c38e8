"""The combinatorics of a zonotope from its generators (seed section 1.3.4.2).

What :class:`alloc.ams.geometry.AttainableSet` is built from, with no problem or box of
its own: the generator classes of collinear columns, the facet hyperplanes spanned by
``k - 1`` classes, the signs that place each facet's vertex, the zonotopal tiling of a
facet with more than ``k - 1`` classes, and the zonotope volume that checks them.
"""

from __future__ import annotations

from itertools import combinations, product
from math import comb

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..exceptions import ProblemError

__all__ = ["generator_classes", "zonotope_volume", "DIRECTION_TOL"]

FloatArray = NDArray[np.float64]

#: Two unit column directions closer than this (sine of the angle) are collinear; a unit
#: column whose component along a unit hyperplane normal is below it lies in the hyperplane.
DIRECTION_TOL = 1e-9
_LIFT_SEED = 20240229  # generic heights for tiling degenerate facets (any generic values work)


def _active(B: FloatArray, lo: FloatArray, hi: FloatArray) -> NDArray[np.bool_]:
    """Effectors that move the moment: a range and a non-zero column."""
    norms = np.linalg.norm(B, axis=0)
    scale = float(norms.max()) if norms.size else 0.0
    return (hi > lo) & (norms > 1e-12 * scale) & (scale > 0)


def generator_classes(B: FloatArray, active: NDArray[np.bool_], tol: float = DIRECTION_TOL):
    """Group active columns by direction (collinear columns, either sign, share a class).

    Returns
    -------
    cls : ndarray (m,) of int
        Class of each effector, ``-1`` for inactive ones.
    sign : ndarray (m,)
        ``+1`` when the column points along its class direction, ``-1`` against, 0 inactive.
    R : ndarray (k, C)
        Unit class directions (the first member's column, normalised).
    """
    k, m = B.shape
    idx = np.flatnonzero(active)
    cls = np.full(m, -1, dtype=np.intp)
    sign = np.zeros(m)
    if idx.size == 0:
        return cls, sign, np.zeros((k, 0))
    U = B[:, idx] / np.linalg.norm(B[:, idx], axis=0)
    dots = U.T @ U  # (n, n)
    # sine of the angle between each pair: |u_i - (u_i . u_j) u_j|
    resid = np.linalg.norm(U.T[:, None, :] - dots[:, :, None] * U.T[None, :, :], axis=2)
    reps: list[int] = []
    for a, j in enumerate(idx):
        for c, r in enumerate(reps):
            if resid[a, r] <= tol:
                cls[j], sign[j] = c, np.sign(dots[a, r])
                break
        else:
            reps.append(a)
            cls[j], sign[j] = len(reps) - 1, 1.0
    return cls, sign, U[:, reps]


#: up to this order the generalised cross product is the cofactor expansion, as it always was, so
#: the catalogue's facet structures (k <= 6) keep their bits; beyond it a QR (see :func:`_cross`)
_COFACTOR_MAX_D = 6


def _cross(M: FloatArray) -> FloatArray:
    """Generalised cross product of the ``d-1`` columns of each ``M[s]`` (S, d, d-1) -> (S, d)."""
    S, d, _ = M.shape
    if d == 2:
        return np.stack([M[:, 1, 0], -M[:, 0, 0]], axis=1)
    if d == 3:
        return np.cross(M[:, :, 0], M[:, :, 1])
    if d > _COFACTOR_MAX_D:
        # the cofactor expansion below costs d determinants of order d-1 per subset (d^4): at
        # k = 24 it was half of a facet build.  The last column of a complete QR spans the
        # orthogonal complement, and |prod diag R| is the volume the cross product's norm
        # measures (equal to the expansion within 6e-15 relative at d = 24; the sign is
        # immaterial, every hyperplane bounds the set on both sides)
        Q, Rm = np.linalg.qr(M, mode="complete")
        volume = np.abs(np.prod(np.diagonal(Rm, axis1=1, axis2=2), axis=1))
        return Q[:, :, -1] * volume[:, None]
    out = np.empty((S, d))
    rows = np.arange(d)
    for i in range(d):
        out[:, i] = (-1) ** i * np.linalg.det(M[:, rows != i, :])
    return out


def _hyperplanes(R: FloatArray, tol: float = DIRECTION_TOL) -> tuple[FloatArray, NDArray[np.bool_]]:
    """Distinct hyperplanes spanned by ``d-1`` of the unit directions ``R`` (d, C), rank d.

    Returns unit normals (H, d) and the mask (H, C) of directions lying in each hyperplane.
    Subsets spanning the same hyperplane (coplanar directions) are merged: a hyperplane is
    identified by the set of directions it contains, not by a rounded normal.
    """
    d, C = R.shape
    if d == 1:
        return np.ones((1, 1)), np.zeros((1, C), dtype=bool)
    subsets = np.array(list(combinations(range(C), d - 1)), dtype=np.intp)
    n = _cross(np.moveaxis(R[:, subsets], 1, 0))
    norms = np.linalg.norm(n, axis=1)
    keep = norms > tol
    n = n[keep] / norms[keep, None]
    free = np.abs(n @ R) <= tol
    key = np.packbits(free, axis=1)
    _, first = np.unique(key.view(np.dtype((np.void, key.shape[1]))).ravel(), return_index=True)
    first.sort()
    n, free = n[first], free[first]
    for h in np.flatnonzero(free.sum(axis=1) > d - 1):
        # coplanar directions: the least-squares normal of all of them, not of the first pair
        n[h] = np.linalg.svd(R[:, free[h]])[0][:, -1]
    return n, free


def _check_closed(normals: FloatArray, r: int) -> None:
    """Raise when the hyperplanes cannot bound a rank-``r`` set (their normals span fewer dimensions).

    The set's rank counts singular values of the unit directions above ``1e-10``, the
    hyperplane search merges directions within ``DIRECTION_TOL`` of a hyperplane: directions
    whose thinnest dimension lies between the two are "full rank" for the one and coplanar
    for the other, and every hyperplane then holds all of them -- a slab open along the
    hyperplane, with no facet ahead of most rays (the issue-9 ``None`` reaching arithmetic
    in ``point_on_facet``).  Such a structure is refused here; the facet-search methods
    then use the LP formulation of the same problem.
    """
    s = np.linalg.svd(normals, compute_uv=False) if normals.size else np.zeros(0)
    if len(s) < r or not s[r - 1] > DIRECTION_TOL * s[0]:
        raise ProblemError(f"B: AMS facet structure not closed (facet normals span fewer than rank {r} "
                           "dimensions: directions coplanar within DIRECTION_TOL but not flat)")


def _plane_basis(n: FloatArray) -> FloatArray:
    """Orthonormal basis (d, d-1) of the hyperplane with unit normal ``n``."""
    return np.linalg.svd(n[:, None])[0][:, 1:]


def _unit_columns(X: FloatArray) -> FloatArray:
    return X / np.linalg.norm(X, axis=0)


def _vertex_signs(R: FloatArray) -> NDArray[np.int8]:
    """Sign vectors (V, C) of the vertices of the zonotope with generator directions ``R`` (d, C).

    Vertex ``sigma`` is ``c + sum_c sigma_c g_c``.  Recursion on facets: a facet fixes the
    directions outside its hyperplane at ``sign(n . r_c)`` and its own vertices are those of
    the (d-1)-zonotope of its free directions.
    """
    d, C = R.shape
    if C == 0:
        return np.zeros((1, 0), dtype=np.int8)
    if d == 1:
        s = np.sign(R[0]).astype(np.int8)
        return np.stack([s, -s])
    normals, free = _hyperplanes(R)
    out = []
    simple = free.sum(axis=1) == d - 1
    if simple.any():
        sig = np.sign(normals[simple] @ R).astype(np.int8)
        sig[free[simple]] = 0
        fidx = np.nonzero(free[simple])[1].reshape(int(simple.sum()), d - 1)
        combos = np.array(list(product((-1, 1), repeat=d - 1)), dtype=np.int8)
        for sgn in (1, -1):
            rows = np.repeat(sgn * sig, len(combos), axis=0)
            rr = np.arange(len(rows))
            rows[rr[:, None], np.repeat(fidx, len(combos), axis=0)] = np.tile(combos, (len(sig), 1))
            out.append(rows)
    for h in np.flatnonzero(~simple):
        F = np.flatnonzero(free[h])
        sub = _vertex_signs(_unit_columns(_plane_basis(normals[h]).T @ R[:, F]))
        base = np.sign(normals[h] @ R).astype(np.int8)
        base[F] = 0
        for sgn in (1, -1):
            rows = np.repeat((sgn * base)[None], len(sub), axis=0)
            rows[:, F] = sub
            out.append(rows)
    rows = np.concatenate(out)
    key = np.packbits(rows > 0, axis=1)
    _, first = np.unique(key.view(np.dtype((np.void, key.shape[1]))).ravel(), return_index=True)
    return rows[np.sort(first)]


def _upper_tiles(Rp: FloatArray) -> tuple[NDArray[np.intp], NDArray[np.int8]]:
    """Tile the zonotope of directions ``Rp`` (d, F), rank d, into parallelepipeds.

    Lifts the directions to ``d+1`` dimensions with generic heights and keeps the upper
    facets (regular fine zonotopal tiling).  Returns the spanning direction indices (T, d)
    and, per tile, the end (0 = low, 1 = high, -1 = spanning) of every direction.
    """
    d, F = Rp.shape
    rng = np.random.default_rng(_LIFT_SEED)
    for _ in range(8):
        L = np.vstack([Rp, rng.standard_normal(F)])
        L = _unit_columns(L)
        normals, free = _hyperplanes(L)
        up = np.abs(normals[:, -1]) > DIRECTION_TOL
        normals, free = normals[up] * np.sign(normals[up, -1:]), free[up]
        if (free.sum(axis=1) == d).all():
            span = np.nonzero(free)[1].reshape(-1, d)
            ends = (normals @ L > 0).astype(np.int8)
            ends[free] = -1
            return span, ends
    raise ProblemError("AMS: could not tile a degenerate facet (generic lift failed)")  # pragma: no cover


def zonotope_volume(B: ArrayLike, lo: ArrayLike, hi: ArrayLike) -> float:
    """Volume of ``{B u : lo <= u <= hi}`` by the zonotope formula.

    ``vol = sum over k-subsets S of the effectors of |det B_S| prod_{j in S} (hi_j - lo_j)``
    (Shephard/McMullen).  Independent of the facet enumeration of :class:`AttainableSet`,
    it serves as its check.  Vectorised over subsets in chunks.
    """
    B = np.atleast_2d(np.asarray(B, dtype=float))
    rng = np.asarray(hi, dtype=float) - np.asarray(lo, dtype=float)
    k, m = B.shape
    idx = np.flatnonzero(rng > 0)
    if idx.size < k:
        return 0.0
    G = B[:, idx] * rng[idx]
    total = 0.0
    it = combinations(range(idx.size), k)
    n_sub = comb(idx.size, k)
    chunk = 200_000
    for _ in range(0, n_sub, chunk):
        S = np.array([s for _, s in zip(range(chunk), it)], dtype=np.intp)
        total += float(np.abs(np.linalg.det(np.moveaxis(G[:, S], 1, 0))).sum())
    return total
