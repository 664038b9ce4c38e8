"""Attainable moment set (AMS) summary: volume and the largest moment along directions.

Convention (the core's ``da`` and :class:`alloc.ams.AttainableSet`): rays start at the
base point ``B u0``, ``u0`` the preferred position clipped into the limits (0 by default);
``scale`` is the largest ``a`` with ``B u0 + a d`` attainable and ``moment`` that point.

:class:`alloc.ams.AttainableSet` answers when it is available and the problem is small
enough for its facet enumeration (``MAX_FACET_SUBSETS`` subsets of ``k - 1`` effectors,
about a second).  Otherwise this module answers with its own small formulation:

* the largest moment along ``d`` is an LP (seed Eqs 1.15-1.17): maximise ``a`` subject
  to ``B (u - u0) = a d``, ``umin <= u <= umax``, ``a >= 0``;
* the AMS is a zonotope with generators ``g_j = (umax_j - umin_j) b_j``, so its volume
  is ``sum over k-subsets S of |det G_S|`` (exact; computed only when there are at most
  ``MAX_SUBSETS`` subsets, else ``null``).
"""

from __future__ import annotations

from itertools import combinations
from math import comb

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linprog

import alloc

from .config import MAX_FACET_SUBSETS
from .errors import InvalidRequest, field_error
from .schemas import AmsOut, DirectionOut

__all__ = ["summarize", "MAX_SUBSETS"]

MAX_SUBSETS = 200_000
_CHUNK = 20_000


def _library_set(problem: alloc.Problem):  # -> alloc.ams.AttainableSet | None
    try:
        from alloc.ams import AttainableSet
    except ImportError:
        return None
    moving = int((problem.umax > problem.umin).sum())
    if comb(moving, problem.k - 1) > MAX_FACET_SUBSETS:
        return None  # facet enumeration would take seconds to minutes: answer with the LP
    return AttainableSet(problem)


def zonotope_volume(problem: alloc.Problem) -> tuple[float | None, str]:
    """``(volume, note)`` of the AMS as a zonotope (Minkowski sum of segments)."""
    G = problem.B * (problem.umax - problem.umin)  # generator j = column j times its range
    G = G[:, np.abs(G).max(axis=0) > 0]
    k, n = G.shape
    if n < k or np.linalg.matrix_rank(G) < k:
        return 0.0, "exact (zonotope): the AMS is flat in some direction"
    count = comb(n, k)
    if count > MAX_SUBSETS:
        return None, f"not computed: {count} generator subsets exceed the cap of {MAX_SUBSETS}"
    total = 0.0
    subsets = combinations(range(n), k)
    while True:
        idx = np.array([s for _, s in zip(range(_CHUNK), subsets)], dtype=np.intp)
        if idx.size == 0:
            break
        total += float(np.abs(np.linalg.det(G[:, idx].transpose(1, 0, 2))).sum())
    if not np.isfinite(total):
        return None, "not computed: the determinants overflow for this problem's scale"
    return total, "exact (zonotope sum of |det| over generator subsets)"


def max_in_direction(problem: alloc.Problem, d: NDArray[np.float64]) -> tuple[float | None, NDArray[np.float64] | None]:
    """Largest ``a`` with ``B u0 + a d`` attainable, and an admissible ``u`` reaching it."""
    k, m = problem.k, problem.m
    u0 = np.minimum(np.maximum(problem.up, problem.umin), problem.umax)
    c = np.zeros(m + 1)
    c[-1] = -1.0
    A_eq = np.hstack([problem.B, -d[:, None]])
    bounds = [*zip(problem.umin, problem.umax), (0.0, None)]
    res = linprog(c, A_eq=A_eq, b_eq=problem.B @ u0, bounds=bounds, method="highs")
    if res.status != 0:  # not expected (a = 0, u = u0 is feasible): report "not found"
        return None, None
    u = np.minimum(np.maximum(res.x[:m], problem.umin), problem.umax)
    return float(res.x[-1]), u


def _directions(problem: alloc.Problem, directions: list[list[float]] | None) -> list[NDArray[np.float64]]:
    if directions is None:
        eye = np.eye(problem.k)
        return [s * eye[i] + 0.0 for i in range(problem.k) for s in (1.0, -1.0)]  # + 0.0: no -0.0
    out = []
    for j, d in enumerate(directions):
        arr = np.asarray(d, dtype=float)
        if arr.shape != (problem.k,):
            reason = f"expected {problem.k} values (one per axis), got {arr.size}"
            raise InvalidRequest(f"directions/{j}: {reason}", [field_error(f"directions/{j}", reason)])
        if not np.abs(arr).max() > 0:
            reason = "a direction must not be zero"
            raise InvalidRequest(f"directions/{j}: {reason}", [field_error(f"directions/{j}", reason)])
        out.append(arr)
    return out


def summarize(problem: alloc.Problem, directions: list[list[float]] | None) -> AmsOut:
    ds = _directions(problem, directions)
    ams = _library_set(problem)
    if ams is not None:
        volume, note = float(ams.volume), "alloc.ams.AttainableSet"
        found = [ams.max_in_direction(d) for d in ds]
    else:
        volume, note = zonotope_volume(problem)
        found = [max_in_direction(problem, d) for d in ds]
    base = problem.B @ np.minimum(np.maximum(problem.up, problem.umin), problem.umax)
    rows = []
    for d, (a, u) in zip(ds, found):
        if a is None or not np.isfinite(a):
            rows.append(DirectionOut(direction=d.tolist(), scale=None, moment=None, u=None))
        else:
            rows.append(DirectionOut(direction=d.tolist(), scale=a, moment=(base + a * d).tolist(),
                                     u=np.asarray(u).tolist()))
    return AmsOut(volume=volume, volume_note=note, directions=rows)
