"""Facet-search direct allocation (da_facet, da_bisect, da_table) against the core's LP ``da``
and against the exact ray exit of :class:`alloc.ams.AttainableSet`.

The LP reference (core ``da``, DAQP) carries its own round-off: on HARV (rows scaled
0.005 .. 3) its achieved moment is off by up to ~3e-8 relative, so agreement with it is
asserted at 1e-7 relative; agreement with the exact geometric reference at 1e-9.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import alloc
from alloc.ams import AttainableSet
from alloc.vehicles import harv_latdir, ice

FACET_METHODS = ["da_facet", "da_bisect", "da_table"]


def random_problem(k: int, m: int, seed: int) -> alloc.Problem:
    rng = np.random.default_rng(seed)
    return alloc.Problem(rng.standard_normal((k, m)), -rng.uniform(0.5, 2, m), rng.uniform(0.5, 2, m))


def degenerate_problem() -> alloc.Problem:
    rng = np.random.default_rng(4)
    B = rng.standard_normal((3, 5))
    B = np.hstack([B, -2 * B[:, [0]], B[:, [1]], np.zeros((3, 1)), B[:, [2]] + B[:, [3]]])
    m = B.shape[1]
    lo, hi = -np.ones(m), np.ones(m)
    lo[1] = hi[1] = 0.5  # jammed
    return alloc.Problem(B, lo, hi, up=np.clip(rng.uniform(-0.5, 0.5, m), lo, hi))


PROBLEMS = {
    "ice": ice(),
    "harv": harv_latdir(),
    "random20": random_problem(3, 20, 1),
    "degenerate": degenerate_problem(),
    "k2": random_problem(2, 6, 2),
    "k4": random_problem(4, 8, 3),
}


def demands(p: alloc.Problem, n: int, seed: int) -> np.ndarray:
    """Demands inside and outside the AMS (up to 1.5x its extent)."""
    ams = AttainableSet(p)
    span = np.abs(ams.vertices).max(axis=0)
    return np.random.default_rng(seed).uniform(-1.5, 1.5, size=(n, p.k)) * span


def exact_reference(ams: AttainableSet, v: np.ndarray) -> np.ndarray:
    """Achieved moment of Eq 1.15 from the exact ray exit (d projected on the range of B, as ``da``)."""
    U, sv, _ = np.linalg.svd(ams.problem.B, full_matrices=False)
    Q = U[:, sv > 1e-10 * sv[0]]
    d = Q @ (Q.T @ (v - ams.base_v))
    a, _ = ams.max_in_direction(d)
    return ams.base_v + min(a, 1.0) * d


@pytest.mark.parametrize("method", FACET_METHODS)
@pytest.mark.parametrize("name", sorted(PROBLEMS))
def test_agrees_with_lp_direct_allocation(method, name):
    p = PROBLEMS[name]
    ref = alloc.make_allocator(p, "da")
    alloc_ = alloc.make_allocator(p, method)
    ams = AttainableSet(p)
    scale = float(np.abs(ams.vertices).max())
    for v in demands(p, 150, seed=11):
        r = alloc_(v)
        assert (r.u >= p.umin).all() and (r.u <= p.umax).all()
        assert np.abs(r.v_achieved - exact_reference(ams, v)).max() <= 1e-9 * scale
        rl = ref(v)
        assert np.abs(r.v_achieved - rl.v_achieved).max() <= 1e-7 * scale
        a_star = ams.max_in_direction(v - ams.base_v)[0]
        if abs(a_star - 1.0) > 1e-6:  # clear of the boundary both agree on attainability
            assert r.status == rl.status == ("exact" if a_star > 1 else "unattainable")


@pytest.mark.parametrize("method", FACET_METHODS)
def test_batch_matches_single_calls(method):
    p = ice()
    a = alloc.make_allocator(p, method)
    V = demands(p, 300, seed=12)
    batch = a.batch(V)
    single = np.array([a(v).v_achieved for v in V])
    assert np.abs(batch.v_achieved - single).max() <= 1e-9 * np.abs(V).max()


def lp_step_reference(p: alloc.Problem, v: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Independent reference for one rate-limited step: HiGHS LP of max a, B(u - u0) = a d."""
    from scipy.optimize import linprog

    u0 = np.clip(p.up, lo, hi)
    d = v - p.B @ u0
    scale = 1.0 / np.abs(p.B).max(axis=1)
    res = linprog(np.r_[np.zeros(p.m), -1.0], A_eq=np.hstack([p.B, -d[:, None]]) * scale[:, None],
                  b_eq=(p.B @ u0) * scale, bounds=list(zip(lo, hi)) + [(0, None)], method="highs",
                  options={"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10})
    assert res.status == 0
    return p.B @ u0 + min(1.0, res.x[-1]) * d


@pytest.mark.parametrize("method", FACET_METHODS)
def test_rate_limited_calls_are_exact_and_admissible(method):
    p = ice()
    a = alloc.make_allocator(p, method)
    rng = np.random.default_rng(13)
    u_prev = np.zeros(p.m)
    for v in demands(p, 60, seed=14):
        lo, hi = p.effective_bounds(u_prev, 0.02)
        r = a(v, u_prev=u_prev, dt=0.02)
        assert (r.u >= lo).all() and (r.u <= hi).all()
        step = AttainableSet(p, lo, hi)  # the set reachable in this step, built from scratch
        assert np.allclose(r.v_achieved, exact_reference(step, v), atol=1e-9 * max(1.0, np.abs(v).max()))
        assert np.allclose(r.v_achieved, lp_step_reference(p, v, lo, hi), atol=1e-7 * max(1.0, np.abs(v).max()))
        u_prev = np.clip(r.u + rng.normal(0, 0.5, p.m), p.umin, p.umax)


def test_failed_effector_suites():
    p = ice()
    for q in (p.with_jam("elevon_r", -12.0), p.with_effectiveness("yaw_tv", 0.0), p.with_limits("pitch_flap", -3, 3)):
        ams = AttainableSet(q)
        for method in FACET_METHODS:
            a = alloc.make_allocator(q, method)
            for v in demands(q, 40, seed=15):
                assert np.abs(a(v).v_achieved - exact_reference(ams, v)).max() <= 1e-9 * np.abs(ams.vertices).max()


def test_base_point_on_the_boundary():
    # up at a limit puts B u0 on facets: rays leaving through them give a* = 0 (u = u0)
    p = alloc.Problem([[1.0, 0.0, 1.0], [0.0, 1.0, 1.0], [1.0, 1.0, -1.0]], [0, 0, 0], [1, 1, 1])
    for method in FACET_METHODS:
        a = alloc.make_allocator(p, method)
        r = a([-1.0, 0.2, 0.1])
        assert np.allclose(r.u, 0.0) and r.status.value == "unattainable"
        r = a([0.3, 0.2, 0.4])
        assert r.status.value == "exact"


def test_options_are_validated():
    p = ice()
    with pytest.raises(TypeError):
        alloc.make_allocator(p, "da_facet", resolution=3)
    with pytest.raises(TypeError):
        alloc.make_allocator(p, "da_table", resolution=1)
    with pytest.raises(TypeError):
        alloc.make_allocator(p, "da_bisect", angles=0)
    assert alloc.make_allocator(p, "da_table", resolution=16)([1.0, 2.0, 0.5]).status.value == "exact"


def test_bisect_and_table_search_mostly_without_fallback():
    p = ice()
    bis = alloc.make_allocator(p, "da_bisect")
    tab = alloc.make_allocator(p, "da_table")
    V = demands(p, 400, seed=16)
    for v in V:
        bis(v)
        tab(v)
    assert bis.impl.fallbacks == 0
    assert tab.impl.fallbacks <= 0.02 * len(V)


def test_flat_and_one_dimensional_sets_match_lp():
    # rank B < k: the ray follows the part of d in the range of B (the core's convention)
    flat = alloc.Problem([[1.0, 0, 1], [0, 1, 1], [0, 0, 0]], [-1] * 3, [1] * 3)
    line = alloc.Problem([[1.0, -2.0, 0.5]], [-1, -1, 0], [1, 2, 1])
    for p, V in ((flat, [[0.5, 0.5, 0], [0.5, 0.5, 1], [5, 0, 0], [3, -3, 2]]), (line, [[-6.0], [-1.0], [0.3], [4.0]])):
        ref = alloc.make_allocator(p, "da")
        for method in FACET_METHODS:
            a = alloc.make_allocator(p, method)
            for v in V:
                assert np.allclose(a(v).v_achieved, ref(v).v_achieved, atol=1e-9)
                assert a(v).status == ref(v).status


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.integers(3, 9))
def test_property_admissible_and_exact_iff_attained(seed, m):
    """Random suites with duplicated, opposite, zero and jammed columns."""
    rng = np.random.default_rng(seed)
    B = rng.standard_normal((3, m))
    B[:, rng.integers(0, m)] = 0.0
    i, j = rng.choice(m, 2, replace=False)
    B[:, j] = -rng.uniform(0.2, 3) * B[:, i]
    lo, hi = -rng.uniform(0.1, 2, m), rng.uniform(0.1, 2, m)
    jam = rng.integers(0, m)
    lo[jam] = hi[jam] = 0.0
    p = alloc.Problem(B, lo, hi)
    ams = AttainableSet(p)
    a = alloc.make_allocator(p, "da_facet")
    for v in rng.standard_normal((20, 3)) * 2:
        r = a(v)
        assert np.isfinite(r.u).all() and (r.u >= lo).all() and (r.u <= hi).all()
        assert (r.status.value == "exact") == bool(np.abs(p.B @ r.u - v).max() <= 1e-6 * max(1, np.abs(v).max()))
        assert np.abs(r.v_achieved - exact_reference(ams, v)).max() <= 1e-9 * max(1.0, np.abs(ams.vertices).max())


def test_directions_coplanar_within_tolerance_use_the_lp():
    """Issue 9 regression (hostile seed 10,048,334, shrunk): four unit directions in 4-D whose
    thinnest dimension (5e-10) is above the rank threshold (1e-10) but below the coplanarity
    tolerance (DIRECTION_TOL = 1e-9).  Every hyperplane held all four, the facet structure was an
    open slab, no facet lay ahead of the ray and ``point_on_facet`` returned ``None``
    (``TypeError: ... 'NoneType' and 'float'`` in the flat case k = 5, a ZeroDivisionError and
    wrong boundary points at k = 4).  The structure is now refused and da* use the LP."""
    B4 = np.array([[1, 0, 0, 1], [0, 1, 0, 1], [0, 0, 1, 1], [0, 0, 0, 5e-10]])
    with pytest.raises(alloc.ProblemError, match="not closed"):
        AttainableSet(alloc.Problem(B4, [-1] * 4, [1] * 4))
    for B in (B4, np.vstack([B4, np.zeros((1, 4))])):  # full rank, and flat in k = 5
        p = alloc.Problem(B, [-1] * 4, [1] * 4)
        k = p.k
        for method in FACET_METHODS:
            f = alloc.make_allocator(p, method)
            # routed before any enumeration: the singular value ratio 1.4e-10 lies in the
            # near-flat band [1e-10, NEAR_FLAT_RTOL) (alloc.facet_cost)
            assert "nearly rank-deficient" in f.impl.lp_reason
            r = f(np.eye(k)[0] * 0.5)  # attainable (u = [0.5, 0, 0, 0])
            assert r.status.value == "exact"
            np.testing.assert_allclose(r.v_achieved, np.eye(k)[0] * 0.5, atol=1e-9)
            r = f(np.eye(k)[0] * 3.0)  # beyond the set along its first axis: boundary at 2
            assert r.status.value == "unattainable"
            assert r.v_achieved[0] == pytest.approx(2.0, rel=1e-9)
