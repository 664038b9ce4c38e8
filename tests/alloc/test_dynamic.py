"""``dynamic`` (Härkegård 2002): cvxpy cross-check, KKT exactness, frequency shaping."""

from __future__ import annotations

import cvxpy as cp
import numpy as np
import pytest

import alloc
from alloc.testing import KINDS, random_demands, random_problem
from alloc.vehicles import ice

from test_kkt_exact import implied_bounds, kkt_equality_qp, kkt_least_squares

QP_SOLVER = dict(solver=cp.OSQP, eps_abs=1e-11, eps_rel=1e-11, polish=True, max_iter=400000)


def cvx_dynamic(p, v, lo, hi, W1, W2, u_prev, m1):
    """Stage 2 of Härkegård's dynamic allocation at the moment ``m1``, written out in cvxpy."""
    us = alloc.make_allocator(p, "pinv").impl.P @ (v - p.B @ p.up) + p.up
    u = cp.Variable(p.m)
    cost = cp.sum_squares(W1 @ (u - us)) + cp.sum_squares(W2 @ (u - u_prev))
    cp.Problem(cp.Minimize(cost), [u >= lo, u <= hi, p.B @ u == m1]).solve(**QP_SOLVER)
    return u.value


def cases():
    rng = np.random.default_rng(77)
    out = []
    for i in range(14):
        k = int(rng.integers(1, 5))
        p = random_problem(rng, k, int(rng.integers(k + 1, 12)), KINDS[i % len(KINDS)])
        v = random_demands(rng, p, 1)[0]
        u_prev = rng.uniform(p.umin, p.umax)
        W1 = np.diag(rng.uniform(0.5, 2.0, p.m))
        W2 = np.diag(rng.uniform(0.5, 5.0, p.m))
        out.append((p, v, u_prev, W1, W2))
    return out


@pytest.mark.filterwarnings("ignore")
@pytest.mark.parametrize("case", range(14))
def test_dynamic_matches_cvxpy(case):
    p, v, u_prev, W1, W2 = cases()[case]
    f = alloc.make_allocator(p, "dynamic", W1=np.diagonal(W1), W2=W2)
    r = f(v, u_prev=u_prev, dt=0.05)
    lo, hi = p.effective_bounds(u_prev, 0.05)
    assert r.status is not alloc.Status.FALLBACK
    # stage 1 is that of qp (the moment is unique)
    np.testing.assert_allclose(r.v_achieved, alloc.allocate(p, v, "qp", u_prev=u_prev, dt=0.05).v_achieved,
                               atol=1e-9 * max(1.0, np.abs(v).max()), rtol=0)
    u_ref = cvx_dynamic(p, v, lo, hi, W1, W2, u_prev, r.v_achieved)
    np.testing.assert_allclose(r.u, u_ref, atol=1e-6 * max(1.0, np.abs(hi - lo).max()), rtol=0)


def test_dynamic_is_kkt_exact():
    """Both stages at relative KKT residual <= 1e-12 (stage 2 in the Wd metric around c)."""
    for p, v, u_prev, W1, W2 in cases():
        f = alloc.make_allocator(p, "dynamic", W1=W1, W2=W2)
        r = f(v, u_prev=u_prev, dt=0.05)
        lo, hi = p.effective_bounds(u_prev, 0.05)
        assert kkt_least_squares(p.B, p.Wv, v, r.u, lo, hi) <= 1e-12
        Wd = W1.T @ W1 + W2.T @ W2
        c = f.impl.target(v, u_prev)
        pins = implied_bounds(p.B, p.Wv, v, r.u, lo, hi)
        assert kkt_equality_qp(p.B, Wd, c, r.u, lo, hi, pins) <= 1e-12


def test_frequency_shaping_first_order_filter():
    """Unconstrained closed form (Härkegård 2002): with scalar weights the null-space part
    of u is a first-order filter of u_s, u_N(t) = a u_N(t-T) + (1-a) u_s,N(t) with
    a = w2^2/(w1^2+w2^2); the range part meets v exactly.  Constant demands converge to the
    static distribution; a fast demand is filtered (smaller null-space amplitude)."""
    rng = np.random.default_rng(3)
    B = rng.normal(size=(2, 5))
    p = alloc.Problem(B, [-1e3] * 5, [1e3] * 5, Wu=[1.0, 4.0, 1.0, 9.0, 2.0])  # u_s has a null-space part
    w1, w2 = 1.0, 3.0
    a = w2**2 / (w1**2 + w2**2)
    f = alloc.make_allocator(p, "dynamic", W1=w1, W2=w2)
    Bp = np.linalg.pinv(B)
    N = np.eye(5) - Bp @ B
    u = np.zeros(5)
    uN = N @ u
    t = np.arange(400) * 0.01
    V = np.c_[np.sin(2 * np.pi * 0.5 * t), np.cos(2 * np.pi * 8.0 * t)]
    for v in V:
        r = f(v, u_prev=u, dt=0.01)
        us = f.impl.static_command(v)
        uN = a * uN + (1 - a) * (N @ us)
        np.testing.assert_allclose(r.u, Bp @ v + uN, atol=1e-11, rtol=0)
        assert r.status is alloc.Status.EXACT
        u = r.u
    # DC: a held demand converges to u_s
    v = np.array([0.7, -0.2])
    for _ in range(200):
        u = f(v, u_prev=u, dt=0.01).u
    np.testing.assert_allclose(u, f.impl.static_command(v), atol=1e-9)


def test_dynamic_without_u_prev_is_the_two_stage_allocation_nearest_u_s():
    p = ice()
    f = alloc.make_allocator(p, "dynamic", W1=2.0)
    v = np.array([2.0, 30.0, 0.5])
    r = f(v)
    us = f.impl.static_command(v)
    ref = alloc.make_allocator(p.replace(up=np.clip(us, p.umin, p.umax)), "qp")(v)
    if np.all((us >= p.umin) & (us <= p.umax)):
        np.testing.assert_allclose(r.u, ref.u, atol=1e-9)
    assert r.status is alloc.Status.EXACT


@pytest.mark.parametrize("bad", [{"W1": [1, 2]}, {"W2": -1.0}, {"W1": "x"}, {"gamma": 1}])
def test_dynamic_rejects_bad_options(bad):
    with pytest.raises(TypeError):
        alloc.make_allocator(ice(), "dynamic", **bad)
