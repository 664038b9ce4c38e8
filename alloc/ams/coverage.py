"""Coverage of the AMS by an allocation method (seed section 1.3.4.9, Bordignon and Durham).

``coverage(problem, method)`` is the fraction of the AMS volume in which the method returns
an admissible ``u`` with ``B u = v`` (status ``exact``).

* Pseudo-inverse family (``pinv``, ``pinv_clip``, ``pinv_scale``; ``ganging`` when
  ``B G = I``): ``u(v) = u_b + P (v - B u_b)`` is affine, so the reached set
  ``{v : lo <= u(v) <= hi}`` is a polytope; its volume is computed exactly
  (``scipy.spatial.HalfspaceIntersection`` + ``ConvexHull``) and divided by the exact AMS
  volume.  Clipping or scaling an inadmissible ``u`` never gives ``B u = v`` except on a
  set of measure zero.
* Any other method: seeded Monte Carlo.  ``v`` is drawn uniformly in the AMS (uniform in
  its bounding box, rejected outside), allocated, and the fraction with status ``exact``
  is reported with its binomial standard error ``sqrt(p (1 - p) / N)``.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, HalfspaceIntersection

from ..api import make_allocator
from ..problem import Problem
from ..registry import FloatArray
from .geometry import AttainableSet

__all__ = ["CoverageResult", "coverage", "sample_ams", "pinv_reached_polytope"]


@dataclass(frozen=True)
class CoverageResult:
    """Fraction of the AMS volume a method reaches exactly and admissibly.

    ``stderr`` is 0 for the exact polytope estimator and the binomial standard error of
    the Monte Carlo estimator otherwise; ``ci95`` is the Wilson 95 % interval (informative
    also when no sample fails, where the standard error is 0: then it is about ``3/N``).
    """

    method: str
    fraction: float
    stderr: float
    estimator: str  # "polytope" (exact) or "monte-carlo"
    samples: int
    ams_volume: float
    seconds: float
    ci95: tuple[float, float] = (0.0, 1.0)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    def __str__(self) -> str:
        pm = "exact" if self.estimator == "polytope" else (
            f"+/- {100 * self.stderr:.2f}, 95 % CI {100 * self.ci95[0]:.2f}-{100 * self.ci95[1]:.2f}")
        return f"{self.method}: {100 * self.fraction:.2f} % ({pm})"


def sample_ams(ams: AttainableSet, n: int, rng: np.random.Generator) -> FloatArray:
    """``n`` demands uniform in the AMS: uniform in its bounding box, rejected outside."""
    lo, hi = ams.vertices.min(axis=0), ams.vertices.max(axis=0)
    out, have = [], 0
    box = float(np.prod(hi - lo))
    accept = ams.volume / box if box > 0 else 0.0
    if accept <= 0:
        raise ValueError("coverage: the AMS has no volume (rank B < k); nothing to sample")
    while have < n:
        V = rng.uniform(lo, hi, size=(int((n - have) / accept * 1.2) + 16, ams.k))
        V = V[ams.contains(V)]
        out.append(V)
        have += len(V)
    return np.concatenate(out)[:n]


def _affine_map(impl: Any, problem: Problem) -> tuple[FloatArray, FloatArray] | None:
    """``(c, P)`` with ``u(v) = c + P v`` where admissible (:meth:`alloc.registry.Method.affine_map`)."""
    affine = impl.affine_map()
    if affine is None:
        return None
    c, P = affine
    # B (c + P v) = v for every v needs B P = I and B c = 0 (an offset that B does not cancel,
    # e.g. a preferred position added without its moment, is exact nowhere); otherwise the
    # exact set is lower-dimensional or empty -> estimate by sampling instead
    B = problem.B
    if np.abs(B @ P - np.eye(problem.k)).max() > 1e-9:
        return None
    if np.abs(B @ c).max() > 1e-9 * max(1.0, float((np.abs(B) @ np.abs(c)).max())):
        return None
    return c, P


def pinv_reached_polytope(problem: Problem, c: FloatArray, P: FloatArray) -> tuple[float, FloatArray | None]:
    """Volume and vertices of ``{v : lo <= c + P v <= hi}`` (k-dimensional)."""
    A = np.vstack([P, -P])
    b = np.concatenate([problem.umax - c, c - problem.umin])
    keep = np.linalg.norm(A, axis=1) > 0
    if (b[~keep] < 0).any():
        return 0.0, None
    A, b = A[keep], b[keep]
    k = problem.k
    norms = np.linalg.norm(A, axis=1)
    # Chebyshev centre: an interior point, and whether the polytope has volume at all
    res = linprog(np.r_[np.zeros(k), -1.0], A_ub=np.hstack([A, norms[:, None]]), b_ub=b,
                  bounds=[(None, None)] * k + [(0, None)], method="highs")
    if res.status != 0 or res.x[-1] <= 1e-12 * max(1.0, float(np.abs(b).max())):
        return 0.0, None
    centre = res.x[:k]
    if k == 1:
        lo_v = max((b[i] / A[i, 0] for i in range(len(b)) if A[i, 0] < 0), default=-np.inf)
        hi_v = min((b[i] / A[i, 0] for i in range(len(b)) if A[i, 0] > 0), default=np.inf)
        return float(hi_v - lo_v), np.array([[lo_v], [hi_v]])
    hs = HalfspaceIntersection(np.hstack([A, -b[:, None]]), centre)
    hull = ConvexHull(hs.intersections)
    return float(hull.volume), hs.intersections[hull.vertices]


def coverage(problem: Problem, method: str, *, samples: int = 20_000, seed: int = 0,
             exact: bool | None = None, **options: Any) -> CoverageResult:
    """Fraction of the AMS volume where ``method`` returns status ``exact`` (Bordignon-Durham).

    Parameters
    ----------
    problem : Problem
        Position limits only (rate limits are not part of the measure).
    method : str
        Registered method name; ``options`` are passed to it.
    samples : int
        Monte Carlo sample size (ignored by the exact polytope estimator).
    seed : int
        Seed of the Monte Carlo sampler.
    exact : bool, optional
        Force (True) or forbid (False) the exact polytope estimator; default: exact when
        the method is affine (pseudo-inverse family).
    """
    t0 = time.perf_counter()
    ams = AttainableSet(problem)
    allocator = make_allocator(problem, method, **options)
    affine = _affine_map(allocator.impl, problem) if exact is not False else None
    if exact and affine is None:
        raise ValueError(f"coverage: no exact estimator for method {method!r}")
    if affine is not None and ams.volume > 0:
        vol, _ = pinv_reached_polytope(problem, *affine)
        frac = min(1.0, vol / ams.volume)
        return CoverageResult(method, frac, 0.0, "polytope", 0, ams.volume, time.perf_counter() - t0, (frac, frac))
    rng = np.random.default_rng(seed)
    V = sample_ams(ams, samples, rng)
    res = allocator.batch(V)
    p = float(np.mean(res.status == "exact"))
    n = len(V)
    se = float(np.sqrt(p * (1 - p) / n))
    return CoverageResult(method, p, se, "monte-carlo", n, ams.volume, time.perf_counter() - t0, wilson95(p, n))


def wilson95(p: float, n: int) -> tuple[float, float]:
    """Wilson score interval (95 %) of a binomial proportion ``p`` observed in ``n`` trials."""
    z = 1.959963984540054
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return float(max(0.0, centre - half)), float(min(1.0, centre + half))
