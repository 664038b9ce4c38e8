"""Weighted and prioritised pseudo-inverses (seed Eqs 1.23-1.24), rank-safe."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: Default relative cut-off: singular values below ``RCOND * s_max`` are treated as zero,
#: so an axis no effector can reach (a failed effector, a nearly singular B) gets no
#: command instead of a huge one; the unreached part of ``v`` is reported as unallocated.
RCOND = 1e-6


def inv_sqrt_factor(W: FloatArray) -> FloatArray:
    """``R`` with ``R R' = W^-1`` (``R = L^-T`` for ``W = L L'``); diagonal fast path."""
    if np.count_nonzero(W - np.diag(np.diagonal(W))) == 0:
        return np.diag(1.0 / np.sqrt(np.diagonal(W)))
    L = np.linalg.cholesky(W)
    return np.linalg.inv(L).T


def sqrt_factor(W: FloatArray) -> FloatArray:
    """``S`` with ``S' S = W`` (``S = L'`` for ``W = L L'``)."""
    if np.count_nonzero(W - np.diag(np.diagonal(W))) == 0:
        return np.diag(np.sqrt(np.diagonal(W)))
    return np.linalg.cholesky(W).T


#: Singular values below this are zero whatever the scale of B: inverting them (a
#: subnormal effectiveness such as 5e-324) would overflow to inf and then NaN.
ABS_FLOOR = 1e-150


def truncated_pinv(A: FloatArray, atol: float) -> FloatArray:
    """Moore-Penrose pseudo-inverse ignoring singular values ``<= max(atol, ABS_FLOOR)``."""
    if A.size == 0:
        return np.zeros((A.shape[1], A.shape[0]))
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    keep = s > max(atol, ABS_FLOOR)
    return (Vt[keep].T / s[keep]) @ U[:, keep].T


def priority_groups(priorities: Sequence[int] | None, k: int) -> list[NDArray[np.intp]]:
    """Axis index groups, most important first (a larger priority number is more important)."""
    if priorities is None:
        return [np.arange(k)]
    pr = np.asarray(priorities)
    levels = sorted(set(pr.tolist()), reverse=True)
    return [np.flatnonzero(pr == lv) for lv in levels]


def weighted_pinv(
    B: FloatArray,
    Wu: FloatArray,
    Wv: FloatArray | None = None,
    *,
    groups: Sequence[NDArray[np.intp]] | None = None,
    rcond: float = RCOND,
) -> FloatArray:
    """Distribution matrix ``P`` (m x k) of the biased weighted pseudo-inverse.

    ``u = up + P (v - B up)`` minimises ``(u - up)' Wu (u - up)`` subject to ``B u = v``
    (seed Eqs 1.22-1.23: ``P = Wu^-1 B' (B Wu^-1 B')^-1`` when ``B`` has full row rank).
    When it has not, ``P`` gives the minimum-``Wu``-norm least-squares solution in the
    ``Wv`` metric (with fewer effectors than axes this is the left pseudo-inverse of
    Eq 1.24).  With ``groups`` (axis index sets, most important first) the axes are met
    lexicographically: each group is solved in the null space of the groups before it.
    """
    k, m = B.shape
    if m == 0:
        return np.zeros((0, k))
    R = inv_sqrt_factor(Wu)
    S = sqrt_factor(Wv) if Wv is not None else np.eye(k)
    A = S @ B @ R  # in z = R^-1 (u - up) and weighted-moment coordinates
    smax = np.linalg.norm(A, 2) if A.size else 0.0
    atol = rcond * smax
    if groups is None or len(groups) <= 1:
        return R @ truncated_pinv(A, atol) @ S
    n = A.shape[1]
    Z = np.zeros((n, k))
    N = np.eye(n)
    for rows in groups:
        Al = A[rows]
        AN = Al @ N
        Pl = truncated_pinv(AN, atol)
        E = np.zeros((len(rows), k))
        E[np.arange(len(rows)), rows] = 1.0
        Z = Z + Pl @ (E - Al @ Z)
        N = N - Pl @ AN
    return R @ Z @ S


def max_scale(base: FloatArray, du: FloatArray, lo: FloatArray, hi: FloatArray) -> float:
    """Largest ``s`` in [0, 1] with ``lo <= base + s du <= hi`` (``base`` admissible)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        up = np.where(du > 0, (hi - base) / du, np.inf)
        dn = np.where(du < 0, (lo - base) / du, np.inf)
    s = min(1.0, float(up.min(initial=np.inf)), float(dn.min(initial=np.inf)))
    return max(0.0, s)
