"""Pictures of the AMS with the region a method reaches drawn inside (matplotlib).

k = 3: the AMS facets (merged polygons) as translucent faces; the reached region of an
affine (pseudo-inverse family) method as its exact polytope, of any other method as the
Monte Carlo demands it allocates exactly.  k = 2: the AMS polygon with the same overlay.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..api import make_allocator
from ..problem import Problem
from .coverage import _affine_map, coverage, pinv_reached_polytope, sample_ams
from .geometry import AttainableSet

__all__ = ["plot_ams"]


def _ordered_polygon(P: np.ndarray) -> np.ndarray:
    c = P.mean(axis=0)
    return P[np.argsort(np.arctan2(P[:, 1] - c[1], P[:, 0] - c[0]))]


def plot_ams(problem: Problem, method: str | None = None, out: str | Path | None = None, *,
             samples: int = 4000, seed: int = 0, title: str | None = None, name: str = "",
             **options: Any):
    """Draw the AMS of ``problem`` (k = 2 or 3) and what ``method`` reaches; save a PNG to ``out``.

    Returns the matplotlib figure.
    """
    # A bare Figure (no pyplot): the library never chooses the caller's matplotlib backend.
    from matplotlib.figure import Figure
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection
    from scipy.spatial import ConvexHull

    k = problem.k
    if k not in (2, 3):
        raise ValueError(f"plot: only k = 2 or 3 can be drawn, got k = {k}")
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
    axes = problem.axes
    if k == 3:
        fig = Figure(figsize=(8, 7))
        ax = fig.add_subplot(projection="3d")
        faces = [f.vertices for f in ams.facets]
        ax.add_collection3d(Poly3DCollection(faces, facecolor="tab:blue", edgecolor="navy", linewidths=0.4,
                                             alpha=0.12))
        if reached_poly is not None and len(reached_poly) >= 4:
            hull = ConvexHull(reached_poly)
            ax.add_collection3d(Poly3DCollection(reached_poly[hull.simplices], facecolor="tab:orange",
                                                 edgecolor="none", alpha=0.55))
        if reached_pts is not None and len(reached_pts):
            ax.scatter(*reached_pts.T, s=1.5, c="tab:orange", alpha=0.5, depthshade=False)
        lo, hi = ams.vertices.min(axis=0), ams.vertices.max(axis=0)
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
        poly = _ordered_polygon(ams.vertices)
        ax.fill(*poly.T, facecolor="tab:blue", alpha=0.15, edgecolor="navy", label="AMS")
        if reached_poly is not None and len(reached_poly) >= 3:
            rp = _ordered_polygon(reached_poly)
            ax.fill(*rp.T, facecolor="tab:orange", alpha=0.6, label="reached")
        if reached_pts is not None and len(reached_pts):
            ax.scatter(*reached_pts.T, s=2, c="tab:orange", alpha=0.5, label="reached")
        ax.set_xlabel(axes[0])
        ax.set_ylabel(axes[1])
        ax.legend(loc="upper right")
        ax.set_aspect("auto")
    ax.set_title(title or (f"{name + ': ' if name else ''}attainable moment set ({ams.n_facets} facets, volume {ams.volume:.4g})"
                           + (f"\n{label}" if label else "")))
    if out is not None:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        fig.savefig(out, dpi=120, bbox_inches="tight")
    return fig
