"""Attainable moment set geometry (alloc.ams.geometry), checked against independent formulas.

References: the zonotope volume formula (sum over k-subsets of |det B_S| prod ranges),
scipy's ConvexHull of the vertices (Qhull), seeded Monte Carlo, and a HiGHS linear
program for the ray exit (``scipy.optimize.linprog``).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog
from scipy.spatial import ConvexHull

import alloc
from alloc.ams import AttainableSet, zonotope_volume
from alloc.vehicles import harv_latdir, ice


def random_problem(k: int, m: int, seed: int) -> alloc.Problem:
    rng = np.random.default_rng(seed)
    return alloc.Problem(rng.standard_normal((k, m)), -rng.uniform(0.5, 2, m), rng.uniform(0.5, 2, m))


def degenerate_problem(seed: int) -> alloc.Problem:
    """Collinear (same and opposite sign), duplicated, zero, coplanar and jammed columns."""
    rng = np.random.default_rng(seed)
    B = rng.standard_normal((3, 5))
    B = np.hstack([
        B, 2 * B[:, [0]], -B[:, [1]], B[:, [1]], np.zeros((3, 1)),
        B[:, [0]] + B[:, [1]], B[:, [2]] - 0.5 * B[:, [3]], B[:, [4]],
    ])
    m = B.shape[1]
    lo, hi = -rng.uniform(0.5, 2, m), rng.uniform(0.5, 2, m)
    lo[4] = hi[4] = 0.2  # jammed
    return alloc.Problem(B, lo, hi)


CASES = {
    "ice": ice(),
    "harv": harv_latdir(),
    "random_11": random_problem(3, 11, 0),
    "degenerate_a": degenerate_problem(1),
    "degenerate_b": degenerate_problem(2),
    "k4_degenerate": alloc.Problem(
        np.hstack([(B4 := np.random.default_rng(5).standard_normal((4, 6))),
                   B4[:, [0]] + B4[:, [1]] + B4[:, [2]], B4[:, [0]] - B4[:, [1]], -3 * B4[:, [4]]]),
        -np.ones(9), np.ones(9)),
}


def lp_ray_exit(p: alloc.Problem, d: np.ndarray, u0: np.ndarray) -> float:
    """Independent reference: max a s.t. B u - a d = B u0, umin <= u <= umax (HiGHS, rows scaled)."""
    scale = 1.0 / np.abs(p.B).max(axis=1)
    A = np.hstack([p.B, -d[:, None]]) * scale[:, None]
    c = np.zeros(p.m + 1)
    c[-1] = -1.0
    bounds = list(zip(p.umin, p.umax)) + [(0, None)]
    res = linprog(c, A_eq=A, b_eq=(p.B @ u0) * scale, bounds=bounds, method="highs",
                  options={"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10})
    assert res.status == 0
    return float(res.x[-1])


# ------------------------------------------------------------------ volume
@pytest.mark.parametrize("name", sorted(CASES))
def test_volume_matches_zonotope_formula_and_hull(name):
    p = CASES[name]
    ams = AttainableSet(p)
    formula = zonotope_volume(p.B, p.umin, p.umax)
    assert ams.volume == pytest.approx(formula, rel=1e-10)
    hull = ConvexHull(ams.vertices)
    assert ams.volume == pytest.approx(hull.volume, rel=1e-9)
    # every vertex we report is a hull vertex, and the hull has no others
    assert len(hull.vertices) == len(ams.vertices)


@pytest.mark.parametrize("k", [1, 2, 3, 4, 5, 6])
def test_volume_any_dimension(k):
    p = random_problem(k, k + 4, seed=10 + k)
    ams = AttainableSet(p)
    assert ams.volume == pytest.approx(zonotope_volume(p.B, p.umin, p.umax), rel=1e-10)
    if k >= 2:
        assert ams.volume == pytest.approx(ConvexHull(ams.vertices).volume, rel=1e-9)


def test_volume_of_ice_against_monte_carlo():
    p = ice()
    ams = AttainableSet(p)
    rng = np.random.default_rng(42)
    lo, hi = ams.vertices.min(axis=0), ams.vertices.max(axis=0)
    n = 200_000
    inside = ams.contains(rng.uniform(lo, hi, size=(n, 3)))
    frac = inside.mean()
    box = float(np.prod(hi - lo))
    se = box * np.sqrt(frac * (1 - frac) / n)
    assert abs(box * frac - ams.volume) < 4 * se  # binomial standard error


def test_one_dimensional_and_flat_sets():
    p = alloc.Problem([[1.0, -2.0, 0.5]], [-1, -1, 0], [1, 2, 1])
    ams = AttainableSet(p)
    assert ams.volume == pytest.approx(2 + 6 + 0.5)
    assert sorted(ams.vertices[:, 0]) == pytest.approx([-5.0, 3.5])
    # all columns in the (v0, v1) plane: a flat set of volume 0 with relative facets
    flat = alloc.Problem([[1.0, 0.0, 1.0], [0.0, 1.0, 1.0], [0.0, 0.0, 0.0]], [-1] * 3, [1] * 3)
    fa = AttainableSet(flat)
    assert fa.rank == 2 and fa.volume == 0.0 and fa.volume_in_hull == pytest.approx(12.0)
    assert fa.max_in_direction([0.0, 0.0, 1.0])[0] == 0.0
    assert fa.max_in_direction([1.0, 0.0, 0.0])[0] == pytest.approx(2.0)
    assert fa.contains([0.5, 0.5, 0.0]) and not fa.contains([0.5, 0.5, 1e-3])


# ------------------------------------------------------------------ facets and vertices
@pytest.mark.parametrize("m", [4, 5, 11, 20])
def test_facet_and_vertex_counts_in_general_position(m):
    ams = AttainableSet(random_problem(3, m, seed=m))
    assert ams.n_facets == m * (m - 1)  # seed section 1.3.4.2
    assert len(ams.vertices) == m * (m - 1) + 2
    assert all(f.n_corners == 4 and len(f.free) == 2 for f in ams.facets)


def test_ice_facets_merge_collinear_and_coplanar_columns():
    p = ice()
    ams = AttainableSet(p)
    s = ams.summary()
    assert s["merged_collinear"] == [["pitch_flap", "pitch_tv"]]  # both act only on pitch
    hull = ConvexHull(ams.vertices)
    planes = np.unique(np.round(hull.equations / np.abs(hull.equations[:, :3]).max(axis=1, keepdims=True), 9), axis=0)
    assert ams.n_facets == len(planes) == 78  # not m(m-1) = 110: merged polygons
    assert len(ams.vertices) == len(hull.vertices) == 86
    polygons = [f for f in ams.facets if f.n_corners > 4]
    assert len(polygons) == 6 and all(f.n_corners == 6 for f in polygons)
    # the elevon pair with the pitch class: left + right elevon is a pure pitch moment
    names = {tuple(p.names[j] for j in f.free) for f in polygons}
    assert ("elevon_l", "elevon_r", "pitch_flap", "pitch_tv") in names


def test_facets_are_supporting_and_corners_lie_on_them():
    for p in (ice(), degenerate_problem(3)):
        ams = AttainableSet(p)
        scale = np.abs(ams.vertices).max()
        assert (ams.vertices @ ams.normals.T - ams.offsets <= 1e-9 * scale).all()
        for f in ams.facets:
            assert np.allclose(f.vertices @ f.normal, f.offset, atol=1e-9 * scale)
            assert f.offset == pytest.approx(ams.support(f.normal), abs=1e-9 * scale)
            fixed = ~np.isnan(f.fixed)
            on_limit = np.isclose(f.fixed[fixed], p.umin[fixed]) | np.isclose(f.fixed[fixed], p.umax[fixed])
            assert on_limit[ams.active[fixed]].all()


# ------------------------------------------------------------------ ray exit
@pytest.mark.parametrize("name", ["ice", "harv", "degenerate_a", "degenerate_b", "k4_degenerate"])
def test_max_in_direction_matches_lp_and_is_certified(name):
    p = CASES[name]
    ams = AttainableSet(p)
    rng = np.random.default_rng(7)
    span = np.abs(ams.vertices - ams.base_v).max(axis=0)
    scale = float(np.abs(ams.vertices).max())
    n = 1000 if name in ("ice", "harv") else 200
    for _ in range(n):
        d = rng.standard_normal(p.k) * span
        a, u = ams.max_in_direction(d)
        x = ams.base_v + a * d
        assert (u >= p.umin - 1e-12).all() and (u <= p.umax + 1e-12).all()
        assert np.abs(p.B @ u - x).max() <= 1e-10 * scale  # a d is attained ...
        f = ams.facet_hit(d)
        n_f = ams.normals[f]
        assert n_f @ d > 0 and abs(n_f @ x - ams.support(n_f)) <= 1e-10 * scale  # ... and maximal
        assert a == pytest.approx(lp_ray_exit(p, d, ams.base_u), rel=1e-7, abs=1e-12)


def test_contains_along_rays():
    p = ice()
    ams = AttainableSet(p)
    rng = np.random.default_rng(8)
    for d in rng.standard_normal((100, 3)) * [10, 100, 10]:
        a, _ = ams.max_in_direction(d)
        assert ams.contains(ams.base_v + 0.999 * a * d)
        assert not ams.contains(ams.base_v + 1.001 * a * d)


# ------------------------------------------------------------------ reconfiguration
def test_changed_suites_give_updated_sets():
    p = ice()
    for q in (p.with_jam("elevon_l", 10.0), p.with_effectiveness("pitch_tv", 0.0),
              p.with_limits("lef_r", -5.0, 5.0), p.with_effectiveness("yaw_tv", 0.5)):
        ams = AttainableSet(q)
        assert ams.volume == pytest.approx(zonotope_volume(q.B, q.umin, q.umax), rel=1e-10)
        assert ams.volume == pytest.approx(ConvexHull(ams.vertices).volume, rel=1e-9)


def test_rate_limited_box_reuses_structure():
    p = ice()
    ams = AttainableSet(p)
    rng = np.random.default_rng(9)
    u_prev = rng.uniform(p.umin, p.umax)
    lo, hi = p.effective_bounds(u_prev, 0.05)
    step = AttainableSet(p, lo, hi)
    assert step.volume == pytest.approx(zonotope_volume(p.B, lo, hi), rel=1e-10)
    u0 = np.minimum(np.maximum(p.up, lo), hi)
    for d in rng.standard_normal((50, 3)):
        a1, u1 = ams.max_in_direction(d, lo=lo, hi=hi)
        a2, u2 = step.max_in_direction(d)
        assert a1 == pytest.approx(a2, rel=1e-12, abs=1e-14)
        assert np.allclose(p.B @ u1, p.B @ u0 + a1 * d, atol=1e-9)
        assert (u1 >= lo - 1e-12).all() and (u1 <= hi + 1e-12).all()


def test_tiling_is_the_public_facet_table():
    """``AttainableSet.tiling`` (what the facet searches read): read-only, and each tile is a
    parallelepiped on its facet's supporting plane, reached by the stated controls (Eq 1.16)."""
    for p in (ice(), harv_latdir()):
        ams = AttainableSet(p)
        t = ams.tiling
        assert not t.tile_u.flags.writeable and not t.normals.flags.writeable
        np.testing.assert_allclose(t.tile_u @ t.B.T, t.tile_corner, atol=1e-12)
        offsets = t.gaps + t.normals @ (t.B @ ams.base_u)  # facet planes: n . v = offset
        scale = np.abs(ams.vertices).max()
        for i, f in enumerate(t.tile_facet):
            n = t.normals[f]
            assert abs(n @ t.tile_corner[i] - offsets[f]) <= 1e-12 * scale
            edges = t.generators[:, t.tile_span[i]]
            np.testing.assert_allclose(n @ edges, 0.0, atol=1e-12 * scale)  # the tile lies in the plane
            np.testing.assert_allclose(t.B @ t.class_steps[t.tile_span[i]].T, edges, atol=1e-12 * scale)
        assert len(np.unique(t.tile_facet)) == ams.n_facets
    flat = AttainableSet(alloc.Problem([[1.0, 2.0], [2.0, 4.0]], [-1, -1], [1, 1]))
    assert flat.rank == 1 and flat.tiling.B.shape == (1, 2)
    empty = AttainableSet(alloc.Problem([[0.0, 0.0]], [-1, -1], [1, 1]))
    assert empty.rank == 0 and empty.tiling.tile_u.shape == (0, 2)
