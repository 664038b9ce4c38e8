"""Pictures of the AMS with the region a method reaches drawn inside (matplotlib).

k = 3: the AMS facets (merged polygons) as translucent faces; the reached region of an
affine (pseudo-inverse family) method as its exact polytope, of any other method as the
Monte Carlo demands it allocates exactly.  k = 2: the AMS polygon with the same overlay.

More than three axes (a multirotor's thrust and three moments, a VTOL's six) cannot be drawn
whole; ``axes`` names the two or three to draw, and the picture is one of two exact views,
named in its title:

* a **slice** (``at`` fixes every other axis, e.g. thrust at hover): the demands with those
  components that are attainable, ``{x : n_s . x <= h - n_o . v_o}`` from the AMS's facets
  (``normals . v <= offsets``), and what the method allocates exactly among them;
* a **projection** (no ``at``): the AMS of the drawn rows of ``B`` (the projection of a
  zonotope is the zonotope of the projected generators), and the projection of the demands
  the method allocates exactly, sampled over the whole AMS.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..api import make_allocator
from ..exceptions import DemandError, ProblemError
from ..problem import Problem
from .coverage import _affine_map, coverage, pinv_reached_polytope, sample_ams
from .geometry import AttainableSet

__all__ = ["plot_ams"]


def _ordered_polygon(P: np.ndarray) -> np.ndarray:
    c = P.mean(axis=0)
    return P[np.argsort(np.arctan2(P[:, 1] - c[1], P[:, 0] - c[0]))]


@dataclass
class _View:
    """What one picture draws, in the drawn axes' coordinates."""

    axes: tuple[str, ...]
    vertices: np.ndarray                 # corners of the drawn set (N, 2 or 3)
    faces: list[np.ndarray] | None       # k = 3 whole AMS: its facets; else None (hull of vertices)
    reached_poly: np.ndarray | None      # an affine method's exact reached polytope
    reached_pts: np.ndarray | None       # sampled demands allocated exactly
    label: str                           # the method's line in the title
    what: str                            # "attainable moment set", "slice at ...", "projection ..."
    n_facets: int
    volume: float


def _pick_axes(problem: Problem, axes: Sequence[str] | None) -> list[int]:
    if axes is None:
        if problem.k in (2, 3):
            return list(range(problem.k))
        raise ProblemError(f"axes: {problem.k} axes cannot be drawn at once; name 2 or 3 of "
                           f"{', '.join(problem.axes)} (fixing the others gives a slice, else a projection)", field="axes")
    names = list(axes)
    unknown = [a for a in names if a not in problem.axes]
    if unknown:
        raise ProblemError(f"axes: unknown axis {unknown[0]!r}; the vehicle has {', '.join(problem.axes)}",
                           field="axes")
    if len(set(names)) != len(names) or len(names) not in (2, 3):
        raise ProblemError(f"axes: name 2 or 3 different axes, got {', '.join(names)}", field="axes")
    return [problem.axes.index(a) for a in names]


def _whole_view(problem: Problem, method: str | None, samples: int, seed: int, options: dict[str, Any]) -> _View:
    ams = AttainableSet(problem)
    reached_poly = reached_pts = None
    label = ""
    if method is not None:
        cov = coverage(problem, method, samples=samples, seed=seed, **options)
        label = f"{method}: {100 * cov.fraction:.1f} % of AMS volume" + (
            "" if cov.estimator == "polytope" else f" (+/- {100 * cov.stderr:.1f}, N={cov.samples})")
        impl = make_allocator(problem, method, **options)
        affine = _affine_map(impl.impl, problem)
        if affine is not None:
            _, reached_poly = pinv_reached_polytope(problem, *affine)
        else:
            V = sample_ams(ams, samples, np.random.default_rng(seed))
            reached_pts = V[impl.batch(V).status == "exact"]
    faces = [f.vertices for f in ams.facets] if problem.k == 3 else None
    return _View(tuple(problem.axes), ams.vertices, faces, reached_poly, reached_pts, label,
                 "attainable moment set", ams.n_facets, ams.volume)


def _sampled_label(method: str, exact: np.ndarray, of: str) -> str:
    n = len(exact)
    frac = float(exact.mean()) if n else 0.0
    err = float(np.sqrt(frac * (1 - frac) / n)) if n else 0.0
    return f"{method}: {100 * frac:.1f} % of the {of} (+/- {100 * err:.1f}, N={n}, sampled)"


def _projection_view(problem: Problem, rows: list[int], method: str | None, samples: int, seed: int,
                     options: dict[str, Any]) -> _View:
    names = tuple(problem.axes[i] for i in rows)
    sub = AttainableSet(Problem(problem.B[rows], problem.umin, problem.umax, axes=names))
    reached_pts, label = None, ""
    if method is not None:
        # the reached set of the whole problem, projected: demands drawn over the full AMS
        V = sample_ams(AttainableSet(problem), samples, np.random.default_rng(seed))
        exact = make_allocator(problem, method, **options).batch(V).status == "exact"
        reached_pts = V[exact][:, rows]
        label = _sampled_label(method, exact, "AMS (full demands)")
    free = ", ".join(a for a in problem.axes if a not in names)
    return _View(names, sub.vertices, None, None, reached_pts, label,
                 f"projection onto {', '.join(names)} ({free} free)", sub.n_facets, sub.volume)


def _slice_vertices(A: np.ndarray, b: np.ndarray, field: str) -> np.ndarray:
    """Corners of ``{x : A x <= b}`` (bounded), or a refusal when it has no interior."""
    from scipy.optimize import linprog
    from scipy.spatial import HalfspaceIntersection

    d = A.shape[1]
    norms = np.linalg.norm(A, axis=1)
    # Chebyshev centre: the deepest interior point, needed by the halfspace intersection
    res = linprog(np.r_[np.zeros(d), -1.0], A_ub=np.c_[A, norms], b_ub=b,
                  bounds=[(None, None)] * d + [(0, None)], method="highs")
    scale = max(1.0, float(np.abs(b).max()))
    if res.status != 0 or res.x[-1] <= 1e-9 * scale:
        raise DemandError(f"{field}: the slice is empty or flat (the fixed components are not attainable "
                          "with room to spare)", field=field)
    hs = HalfspaceIntersection(np.c_[A, -b], res.x[:d])
    return np.asarray(hs.intersections)


def _slice_view(problem: Problem, rows: list[int], at: Mapping[str, float], method: str | None, samples: int,
                seed: int, options: dict[str, Any]) -> _View:
    names = tuple(problem.axes[i] for i in rows)
    others = [i for i in range(problem.k) if i not in rows]
    missing = [problem.axes[i] for i in others if problem.axes[i] not in at]
    extra = [a for a in at if a not in problem.axes or a in names]
    if missing or extra:
        raise ProblemError(f"at: fix exactly the axes not drawn ({', '.join(problem.axes[i] for i in others)}); "
                           + (f"missing {', '.join(missing)}" if missing else f"not allowed: {', '.join(extra)}"),
                           field="at")
    v_fixed = np.array([float(at[problem.axes[i]]) for i in others])
    if not np.isfinite(v_fixed).all():
        raise DemandError("at: values must be finite", field="at")
    ams = AttainableSet(problem)
    if ams.rank < problem.k:
        raise ProblemError(f"B: rank {ams.rank} < {problem.k} axes; the AMS is flat and has no slice",
                           field="B")
    N, h = ams.normals, ams.offsets
    A, b = N[:, rows], h - N[:, others] @ v_fixed
    verts = _slice_vertices(A, b, "at")
    reached_pts, label = None, ""
    if method is not None:
        rng = np.random.default_rng(seed)
        lo, hi = verts.min(axis=0), verts.max(axis=0)
        X = rng.uniform(lo, hi, size=(4 * samples + 64, len(rows)))
        X = X[(X @ A.T <= b + 1e-12 * max(1.0, float(np.abs(b).max()))).all(axis=1)][:samples]
        V = np.empty((len(X), problem.k))
        V[:, rows], V[:, others] = X, v_fixed
        exact = make_allocator(problem, method, **options).batch(V).status == "exact"
        reached_pts = X[exact]
        label = _sampled_label(method, exact, "slice")
    fixed = ", ".join(f"{problem.axes[i]} = {at[problem.axes[i]]:g}" for i in others)
    from scipy.spatial import ConvexHull

    hull = ConvexHull(verts)
    planes = len(np.unique(np.round(hull.equations / np.abs(hull.equations).max(), 9), axis=0))  # merged triangles
    return _View(names, verts, None, None, reached_pts, label, f"slice at {fixed}", planes, float(hull.volume))


def plot_ams(problem: Problem, method: str | None = None, out: str | Path | None = None, *,
             samples: int = 4000, seed: int = 0, title: str | None = None, name: str = "",
             axes: Sequence[str] | None = None, at: Mapping[str, float] | None = None,
             units: Mapping[str, str] | None = None, **options: Any):
    """Draw the AMS of ``problem`` and what ``method`` reaches; save a PNG to ``out``.

    ``axes`` (2 or 3 names) picks the drawn axes; required for more than three axes.  With
    ``at`` (a value for every other axis) the picture is the exact slice there, else the exact
    projection; the title says which.  ``units`` (axis name -> unit) label the plot's axes.
    Returns the matplotlib figure.
    """
    rows = _pick_axes(problem, axes)
    if at is not None and len(rows) == problem.k and at:
        raise ProblemError("at: every axis is drawn; nothing to fix", field="at")
    if len(rows) == problem.k and rows == list(range(problem.k)):
        view = _whole_view(problem, method, samples, seed, options)
    elif at:
        view = _slice_view(problem, rows, at, method, samples, seed, options)
    else:
        view = _projection_view(problem, rows, method, samples, seed, options)
    fig = _draw(view, units or {})
    fig.axes[0].set_title(title or (f"{name + ': ' if name else ''}{view.what} ({view.n_facets} facets, "
                                    f"volume {view.volume:.4g})" + (f"\n{view.label}" if view.label else "")))
    if out is not None:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=120, bbox_inches="tight")
    return fig


def _draw(view: _View, units: Mapping[str, str]) -> Any:
    # A bare Figure (no pyplot): the library never chooses the caller's matplotlib backend.
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    from scipy.spatial import ConvexHull

    axes = [f"{a} ({units[a]})" if units.get(a) else a for a in view.axes]
    if len(axes) == 3:
        fig = Figure(figsize=(8, 7))
        ax = fig.add_subplot(projection="3d")
        if view.faces is not None:
            faces = view.faces
        else:
            hull = ConvexHull(view.vertices)
            faces = list(view.vertices[hull.simplices])
        ax.add_collection3d(Poly3DCollection(faces, facecolor="tab:blue",
                                             edgecolor="navy" if view.faces is not None else "none",
                                             linewidths=0.4, alpha=0.12))
        if view.reached_poly is not None and len(view.reached_poly) >= 4:
            hull = ConvexHull(view.reached_poly)
            ax.add_collection3d(Poly3DCollection(view.reached_poly[hull.simplices], facecolor="tab:orange",
                                                 edgecolor="none", alpha=0.55))
        if view.reached_pts is not None and len(view.reached_pts):
            ax.scatter(*view.reached_pts.T, s=1.5, c="tab:orange", alpha=0.5, depthshade=False)
        lo, hi = view.vertices.min(axis=0), view.vertices.max(axis=0)
        ax.set_xlim(lo[0], hi[0])
        ax.set_ylim(lo[1], hi[1])
        ax.set_zlim(lo[2], hi[2])
        ax.set_box_aspect((1.0, 1.0, 0.9))  # axes have different units: show each to full extent
        ax.view_init(elev=22, azim=-58)
        ax.set_xlabel(axes[0])
        ax.set_ylabel(axes[1])
        ax.set_zlabel(axes[2])
    else:
        fig = Figure(figsize=(7, 6))
        ax = fig.add_subplot()
        poly = _ordered_polygon(view.vertices)
        ax.fill(*poly.T, facecolor="tab:blue", alpha=0.15, edgecolor="navy", label="AMS")
        if view.reached_poly is not None and len(view.reached_poly) >= 3:
            rp = _ordered_polygon(view.reached_poly)
            ax.fill(*rp.T, facecolor="tab:orange", alpha=0.6, label="reached")
        if view.reached_pts is not None and len(view.reached_pts):
            ax.scatter(*view.reached_pts.T, s=2, c="tab:orange", alpha=0.5, label="reached")
        ax.set_xlabel(axes[0])
        ax.set_ylabel(axes[1])
        ax.legend(loc="upper right")
        ax.set_aspect("auto")
    return fig
