"""Weighted and prioritised pseudo-inverses (seed Eqs 1.23-1.24), rank-safe."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ..exceptions import OptionError, SolverError

FloatArray = NDArray[np.float64]

#: Default relative cut-off: singular values below ``RCOND * s_max`` are treated as zero,
#: so an axis no effector can reach (a failed effector, a nearly singular B) gets no
#: command instead of a huge one; the unreached part of ``v`` is reported as unallocated.
RCOND = 1e-6


def check_real_option(value: object, method: str, field: str, lo: float, hi: float, *,
                      open_lo: bool = False, open_hi: bool = False) -> float:
    """A real-valued option in ``[lo, hi]`` (ends open if asked); OptionError naming it otherwise."""
    lb, rb = "(" if open_lo else "[", ")" if open_hi else "]"
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise OptionError(f"{method}: {field} must be a real number in {lb}{lo:g}, {hi:g}{rb}, got {value!r}",
                          field=field)
    try:
        x = float(value)
    except OverflowError:
        x = math.inf
    ok = (lo < x if open_lo else lo <= x) and (x < hi if open_hi else x <= hi)
    if not ok:
        raise OptionError(f"{method}: {field} must be in {lb}{lo:g}, {hi:g}{rb}, got {value!r}", field=field)
    return x


def check_rcond(rcond: object, method: str) -> float:
    """The ``rcond`` option as a float in ``[0, 1)``; OptionError naming it otherwise."""
    return check_real_option(rcond, method, "rcond", 0.0, 1.0, open_hi=True)


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


def _checked_svd(A: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """``np.linalg.svd(A, full_matrices=False)`` guarded at the LAPACK boundary.

    A non-finite matrix never reaches LAPACK (its SVD can spin forever holding the GIL);
    it and a LAPACK failure raise :class:`~alloc.exceptions.SolverError`, which an
    allocator turns into the safe answer with ``status="fallback"``.
    """
    if not np.isfinite(A).all():
        raise SolverError("SVD: non-finite matrix (magnitudes beyond the float range)")
    try:
        return np.linalg.svd(A, full_matrices=False)
    except np.linalg.LinAlgError as exc:
        raise SolverError(f"SVD: {exc}") from exc


def truncated_pinv(A: FloatArray, atol: float) -> FloatArray:
    """Moore-Penrose pseudo-inverse ignoring singular values ``<= max(atol, ABS_FLOOR)``."""
    return _truncated_pinv(A, max(atol, ABS_FLOOR))


def _truncated_pinv(A: FloatArray, cut: float) -> FloatArray:
    if A.size == 0:
        return np.zeros((A.shape[1], A.shape[0]))
    U, s, Vt = _checked_svd(A)
    keep = s > cut
    return (Vt[keep].T / s[keep]) @ U[:, keep].T


def _pow2(X: FloatArray) -> int:
    """Exponent ``e`` with ``max|X| / 2**e`` in [0.5, 1) (0 for a zero matrix): exact scaling."""
    amax = float(np.abs(X).max()) if X.size else 0.0
    if not (0.0 < amax < np.inf):
        return 0
    return math.frexp(amax)[1]


def priority_groups(priorities: Sequence[float] | None, k: int) -> list[NDArray[np.intp]]:
    """Axis index groups, most important first (a larger priority number is more important).

    Only the order of the levels matters (any real numbers; compared exactly, never cast).
    """
    if priorities is None:
        return [np.arange(k)]
    pr = list(priorities.tolist() if isinstance(priorities, np.ndarray) else priorities)
    levels = sorted(set(pr), reverse=True)
    return [np.array([i for i, x in enumerate(pr) if x == lv], dtype=np.intp) for lv in levels]


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
    # Each factor is scaled by a power of two (exact) so that A = S B R is formed without
    # overflow or underflow whatever the magnitudes of B and the weights (1e300 columns
    # with 1e-20 weights must not reach the SVD as inf): P = R A^+ S = 2**-eb Rs As^+ Ss.
    es, eb, er = _pow2(S), _pow2(B), _pow2(R)
    Ss, Bs, Rs = np.ldexp(S, -es), np.ldexp(B, -eb), np.ldexp(R, -er)
    A = Ss @ Bs @ Rs  # in z = R^-1 (u - up) and weighted-moment coordinates, scaled
    with np.errstate(over="ignore", under="ignore"):
        floor = float(np.ldexp(ABS_FLOOR, -(es + eb + er)))  # ABS_FLOOR in the unscaled A
    if groups is None or len(groups) <= 1:
        if A.size == 0:
            return np.zeros((m, k))
        U, s, Vt = _checked_svd(A)
        keep = s > max(rcond * (s[0] if s.size else 0.0), floor)
        Z = (Vt[keep].T / s[keep]) @ U[:, keep].T
        return _unscale(Rs @ Z @ Ss, eb)
    smax = float(_checked_svd(A)[1][0]) if A.size else 0.0
    cut = max(rcond * smax, floor)
    n = A.shape[1]
    Z = np.zeros((n, k))
    N = np.eye(n)
    for rows in groups:
        Al = A[rows]
        AN = Al @ N
        Pl = _truncated_pinv(AN, cut)
        E = np.zeros((len(rows), k))
        E[np.arange(len(rows)), rows] = 1.0
        Z = Z + Pl @ (E - Al @ Z)
        N = N - Pl @ AN
    return _unscale(Rs @ Z @ Ss, eb)


def _unscale(Ps: FloatArray, eb: int) -> FloatArray:
    """``2**-eb Ps``; a product the float range cannot carry raises SolverError."""
    with np.errstate(over="ignore", under="ignore"):
        P = np.ldexp(Ps, -eb)
    if not np.isfinite(P).all():
        raise SolverError("pseudo-inverse: gains beyond the float range")
    return P


def max_scale(base: FloatArray, du: FloatArray, lo: FloatArray, hi: FloatArray) -> float:
    """Largest ``s`` in [0, 1] with ``lo <= base + s du <= hi`` (``base`` admissible)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        up = np.where(du > 0, (hi - base) / du, np.inf)
        dn = np.where(du < 0, (lo - base) / du, np.inf)
    s = min(1.0, float(up.min(initial=np.inf)), float(dn.min(initial=np.inf)))
    return max(0.0, s)
