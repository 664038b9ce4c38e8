"""The compiled facet searches (alloc/methods/_facet_kernels.py) against their numpy reference.

Every case calls the method's ``solve`` (compiled) and ``_solve_reference`` (the numpy
implementation the kernels replaced) on the same demand and box and asserts equal
iteration counts, ``B u`` to 1e-12 relative and ``u`` to 1e-9 (the searches pick the same
tile, so the boundary point agrees too).  Suites: ICE, HARV and seeded random problems of
every kind in :data:`alloc.testing.KINDS`; demands inside and outside the set; nominal box
and rate-limited boxes (``u_prev`` inside and outside the position limits).
"""

from __future__ import annotations

import numpy as np
import pytest

import alloc
from alloc import vehicles
from alloc.testing import KINDS, random_demands, random_problem

BV_RTOL = 1e-12  # achieved moment, relative to max(1, |B u|)
U_TOL = 1e-9  # controls, relative to max(1, effector range)
METHODS = ("da_facet", "da_bisect", "da_table")


def boxes(rng: np.random.Generator, p: alloc.Problem, n: int):
    """``n`` (lo, hi, u_prev): the nominal box every other time, else an Eq 1.28 window."""
    for i in range(n):
        if i % 2 == 0 or p.rate_max is None:
            yield p.umin, p.umax, None
            continue
        span = p.umax - p.umin
        u_prev = rng.uniform(p.umin - 0.1 * span, p.umax + 0.1 * span)  # sometimes outside
        dt = rng.choice([1e-3, 1e-2, 0.05, 1.0])
        lo, hi = p.effective_bounds(u_prev, dt)
        yield lo, hi, u_prev


def check_same(p: alloc.Problem, method: str, V: np.ndarray, rng: np.random.Generator) -> int:
    impl = alloc.make_allocator(p, method).impl
    scale_u = max(1.0, float(np.abs(p.umax - p.umin).max()))
    for v, (lo, hi, u_prev) in zip(V, boxes(rng, p, len(V))):
        u, it = impl.solve(v, lo, hi, u_prev)
        u_ref, it_ref = impl._solve_reference(v, lo, hi, u_prev)
        where = f"{method} k={p.k} m={p.m} v={v.tolist()} rated={u_prev is not None}"
        assert it == it_ref, where
        assert np.all(np.isfinite(u)), where
        bv, bv_ref = p.B @ u, p.B @ u_ref
        assert np.abs(bv - bv_ref).max() <= BV_RTOL * max(1.0, float(np.abs(bv_ref).max())), where
        assert np.abs(u - u_ref).max() <= U_TOL * scale_u, where
    return len(V)


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("vehicle", ["ice", "harv_latdir"])
def test_vehicles_match_reference(method, vehicle):
    p = getattr(vehicles, vehicle)()
    rng = np.random.default_rng(11)
    V = random_demands(rng, p, 1200)
    assert check_same(p, method, V, rng) == 1200


@pytest.mark.parametrize("kind", KINDS)
def test_random_k3_match_reference(kind):
    rng = np.random.default_rng(20 + KINDS.index(kind))
    cases = 0
    for _ in range(4):
        p = random_problem(rng, 3, int(rng.integers(4, 12)), kind)
        V = random_demands(rng, p, 60)
        for method in METHODS:
            cases += check_same(p, method, V, rng)
    assert cases == 4 * 60 * len(METHODS)


@pytest.mark.parametrize("k", [1, 2, 4])
@pytest.mark.parametrize("kind", KINDS)
def test_random_facet_any_k_match_reference(kind, k):
    rng = np.random.default_rng(100 * k + KINDS.index(kind))
    cases = 0
    for _ in range(3):
        p = random_problem(rng, k, int(rng.integers(k + 1, k + 7)), kind)
        cases += check_same(p, "da_facet", random_demands(rng, p, 50), rng)
    assert cases == 150


@pytest.mark.parametrize("method", ["da_facet", "da_bisect"])
def test_allocator_result_matches_reference(method):
    """Through ``make_allocator``: the clipped result equals the reference's, clipped."""
    p = vehicles.ice()
    allocate = alloc.make_allocator(p, method)
    rng = np.random.default_rng(5)
    u_prev = np.zeros(p.m)
    for v in random_demands(rng, p, 200):
        r = allocate(v)
        u_ref = np.clip(allocate.impl._solve_reference(v, p.umin, p.umax, None)[0], p.umin, p.umax)
        assert np.abs(r.u - u_ref).max() <= U_TOL
        lo, hi = p.effective_bounds(u_prev, 0.0005)
        r = allocate(v, u_prev=u_prev, dt=0.0005)
        u_ref = np.clip(allocate.impl._solve_reference(v, lo, hi, u_prev)[0], lo, hi)
        assert np.abs(r.u - u_ref).max() <= U_TOL


def test_bisect_counters_follow_the_search():
    """``rounds``/``fallbacks`` are kept as the numpy search kept them (bench_ams reports them)."""
    p = vehicles.ice()
    impl = alloc.make_allocator(p, "da_bisect").impl
    rng = np.random.default_rng(6)
    for v in random_demands(rng, p, 300):
        impl.solve(v, p.umin, p.umax, None)
        assert 1 <= impl.rounds <= impl.max_rounds
    assert impl.fallbacks == 0


@pytest.mark.parametrize("m", [40, 60])
def test_random_many_effectors_match_reference(m):
    """Past 32 generator classes the bisect kernel sorts breakpoints with np.argsort."""
    rng = np.random.default_rng(m)
    p = random_problem(rng, 3, m)
    V = random_demands(rng, p, 100)
    assert p.m > 32
    for method in METHODS:
        assert check_same(p, method, V, rng) == 100
