"""Attainable moment set (AMS) summary: volume and the largest moment along directions.

All numerics are the library's (:mod:`alloc.ams`, :mod:`alloc.methods.direct`); this
module only picks the formulation a shared service can afford and shapes the answer.

Convention (the core's ``da`` and :class:`alloc.ams.AttainableSet`): rays start at the
base point ``B u0``, ``u0`` the preferred position clipped into the limits (0 by default);
``scale`` is the largest ``a`` with ``B u0 + a d`` attainable and ``moment`` that point.

* Small enough to enumerate the facets within the build budget (``service.cost``):
  :class:`alloc.ams.AttainableSet` answers both (exact volume, facet ray exit, Eq 1.15).
* Larger: the volume from :func:`alloc.ams.zonotope_volume` while its ``C(n, k)``
  determinants stay under ``MAX_SUBSETS`` (else ``null``), and each direction from the
  direct-allocation LP of :class:`alloc.methods.direct.DirectAllocation` (seed Eqs 1.15-1.17).
"""

from __future__ import annotations

from math import comb

import numpy as np
from numpy.typing import NDArray

import alloc
from alloc.ams import AttainableSet, zonotope_volume

from .cost import build_seconds
from .errors import InvalidRequest, field_error
from .schemas import AmsOut, DirectionOut

__all__ = ["summarize", "MAX_SUBSETS"]

#: generator k-subsets the zonotope volume may sum (200,000 determinants: ~0.3 s measured)
MAX_SUBSETS = 200_000


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


def summarize(problem: alloc.Problem, directions: list[list[float]] | None, budget: float = 3.0) -> AmsOut:
    """Volume and ray exits of the AMS of ``problem``; ``budget`` seconds of facet enumeration at most."""
    ds = _directions(problem, directions)
    u0 = np.minimum(np.maximum(problem.up, problem.umin), problem.umax)
    if build_seconds(problem, "da_facet", {}) <= budget:  # the facet search's declared enumeration cost
        ams = AttainableSet(problem)
        volume, note = float(ams.volume), "alloc.ams.AttainableSet"
        found = [ams.max_in_direction(d) for d in ds]
    else:
        G = problem.B * (problem.umax - problem.umin)
        n = int((np.abs(G).max(axis=0) > 0).sum())
        if comb(n, problem.k) > MAX_SUBSETS:
            volume, note = None, (f"not computed: {comb(n, problem.k)} generator subsets exceed the cap of "
                                  f"{MAX_SUBSETS}")
        else:
            volume, note = zonotope_volume(problem.B, problem.umin, problem.umax), "alloc.ams.zonotope_volume"
            if not np.isfinite(volume):
                volume, note = None, "not computed: the determinants overflow for this problem's scale"
        from alloc.methods.direct import DirectAllocation  # here: the methods load numba (0.3 s of start-up)

        lp = DirectAllocation(problem, backend="highs")
        found = []
        for d in ds:
            a, u, _ = lp.boundary(d, u0, problem.umin, problem.umax)
            found.append((a, u))
    base = problem.B @ u0
    rows = []
    for d, (a, u) in zip(ds, found):
        if a is None or not np.isfinite(a):
            rows.append(DirectionOut(direction=d.tolist(), scale=None, moment=None, u=None))
        else:
            rows.append(DirectionOut(direction=d.tolist(), scale=float(a), moment=(base + a * d).tolist(),
                                     u=np.asarray(u).tolist()))
    return AmsOut(volume=volume, volume_note=note, directions=rows)
