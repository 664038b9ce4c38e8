"""``da``'s compiled ray solvers (alloc._engine._ray_simplex) against an independent LP (HiGHS).

The dual facet walk answers first, the primal ray simplex behind it, DAQP last; each must give
the boundary the LP formulation of Eqs 1.15-1.17 gives, nominal and rate-limited, at the
effector counts where ``da`` uses them (m up to 192), with the output contract kept.
"""

from __future__ import annotations

import numpy as np
import pytest

import alloc
from alloc._engine import _ray_simplex as rs
from alloc.testing import random_demands, random_problem


@pytest.mark.parametrize(("k", "m"), [(1, 9), (2, 40), (3, 64), (4, 96), (6, 30), (8, 24), (4, 192)])
def test_the_ray_solvers_give_the_lps_boundary(k, m):
    rng = np.random.default_rng(10 * k + m)
    p = random_problem(rng, k, m, "general")
    fast, reference = alloc.make_allocator(p, "da", backend="simplex"), alloc.make_allocator(p, "da", backend="highs")
    V = random_demands(rng, p, 40)
    V[::3] *= 5.0  # unattainable: the boundary itself
    u = p.up.copy()
    for i, v in enumerate(V):
        kw = {"u_prev": u, "dt": 0.01} if i % 2 else {}
        a, b = fast(v, **kw), reference(v, **kw)
        lo = p.umin if not kw else np.maximum(p.umin, u + p.rate_min * 0.01)
        hi = p.umax if not kw else np.minimum(p.umax, u + p.rate_max * 0.01)
        assert np.isfinite(a.u).all() and (a.u >= lo - 1e-9).all() and (a.u <= hi + 1e-9).all()
        assert a.status == b.status, (i, a.status, b.status)
        scale = max(1.0, float(np.abs(v).max()))
        assert np.abs(a.v_achieved - b.v_achieved).max() <= 1e-6 * scale, i
        u = np.asarray(a.u)
    assert fast.impl.simplex_fallbacks == 0  # DAQP never needed on these


def test_the_dual_walk_and_the_primal_simplex_agree_on_t():
    """Both compiled solvers on the same scaled LP: the same optimum ``t`` (the dual from its
    predicted facet in few steps, the primal from u0)."""
    steps = []
    for seed in range(12):
        rng = np.random.default_rng(seed)
        k, m = (2, 3, 4, 6)[seed % 4], (12, 48, 96)[seed % 3]
        impl = alloc.make_allocator(random_problem(rng, k, m, "general"), "da", backend="simplex").impl
        for v in rng.normal(size=(10, k)) * 3.0:
            d = v - impl._Bu0
            q = impl._Q @ (d / np.linalg.norm(d))
            xd, xp = np.empty(m), np.empty(m)
            cd, td, it = rs.dual_ray(impl._Ax, q, impl._x0, impl._xlo, impl._xhi, impl._G, impl._cnorm, 500, xd)
            cp, tp, _ = rs.solve_ray(impl._F, q, impl._x0, impl._xlo, impl._xhi, float(impl._ub[-1]), 500,
                                     impl._work, impl._iwork, xp, impl._G, impl._cnorm)
            assert cd == cp == rs.OPTIMAL
            assert td == pytest.approx(tp, rel=1e-9, abs=1e-12)
            # both are points of the ray: A (x - x0) = t q
            assert np.abs(impl._Ax @ (xd - impl._x0) - td * q).max() <= 1e-9 * (1.0 + td)
            steps.append(it)
    assert np.median(steps) <= 3  # the predicted facet is usually the one (or next to it)


def test_a_failed_walk_falls_back_and_counts_it():
    """An iteration bound of 0 stops both compiled solvers: DAQP answers, counted."""
    rng = np.random.default_rng(3)
    p = random_problem(rng, 4, 60, "general")
    f = alloc.make_allocator(p, "da", backend="simplex")
    f.impl._max_pivots = 0
    ref = alloc.make_allocator(p, "da", backend="highs")
    for v in random_demands(rng, p, 5):
        a, b = f(v), ref(v)
        assert a.status == b.status
        assert np.abs(a.v_achieved - b.v_achieved).max() <= 1e-6 * max(1.0, float(np.abs(v).max()))
    assert f.impl.simplex_fallbacks == 5


def test_a_copy_answers_bit_for_bit_whatever_the_call_history():
    """Every call starts from the same predicted facet: a pickled copy, fed the demands in another
    order, answers each one bit for bit like the original (nominal and rate-limited)."""
    import pickle

    rng = np.random.default_rng(7)
    p = random_problem(rng, 4, 96, "general")
    f = alloc.make_allocator(p, "da")
    assert f.impl._facet is None and f.impl.simplex  # auto: the ray LP at 4 x 96
    V = random_demands(rng, p, 30)
    V[::2] *= 4.0
    u_prev = 0.5 * (p.umin + p.umax)
    first = [(f(v).u.copy(), f(v, u_prev=u_prev, dt=0.01).u.copy()) for v in V]
    g = pickle.loads(pickle.dumps(f))
    for i in rng.permutation(len(V)):
        nominal, rated = first[i]
        assert np.array_equal(g(V[i]).u, nominal) and np.array_equal(g(V[i], u_prev=u_prev, dt=0.01).u, rated)


def test_jammed_effectors_build_and_answer():
    """Every effector jammed (A = 0) or all but two: the LP path builds (the start's ellipsoid is a
    pseudo-inverse) and answers what HiGHS does."""
    B = np.random.default_rng(0).normal(size=(4, 30))
    for lo, hi in [(np.full(30, 0.3), np.full(30, 0.3)),
                   (np.r_[np.full(28, 0.2), -1.0, -1.0], np.r_[np.full(28, 0.2), 1.0, 1.0])]:
        p = alloc.Problem(B, lo, hi)
        f, ref = alloc.make_allocator(p, "da", backend="simplex"), alloc.make_allocator(p, "da", backend="highs")
        assert not f.build_error
        for v in np.random.default_rng(1).normal(size=(5, 4)):
            a, b = f(v), ref(v)
            assert a.status == b.status and np.abs(a.v_achieved - b.v_achieved).max() <= 1e-6 * max(1.0, np.abs(v).max())
