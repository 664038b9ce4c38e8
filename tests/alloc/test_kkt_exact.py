"""KKT optimality of ``qp`` (both stages), ``wls`` and ``dynamic`` on seeded generators.

The checker is independent of the solver: it takes only the answer ``u`` and the data.
Relative KKT residual = the largest violation of stationarity / sign conditions of the
bound multipliers, divided by the magnitude of the terms that form the gradient.  The
stage-2 equality multipliers ``lam`` are not unique at a stage-1 vertex, so they are found
by a small LP (min max violation, HiGHS) refined exactly on its tight rows.

Suites: random problems of every degenerate kind (k = 1..6, m up to 30), 3 x 8 problems
with collinear or coplanar columns and near-singular ``B'WvB`` (columns collinear to
1e-9), rate-limited windows from 0.5 ms to 100 ms, and demands mostly unattainable.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog

import alloc
from alloc.testing import KINDS, random_demands, random_problem
from alloc.vehicles import harv_latdir, ice

KKT_RTOL = 1e-12


def _violations(g, u, lo, hi):
    """|g_j| on free effectors, the wrong-sign part at a bound, 0 for jammed ones."""
    tol = 1e-12 * np.maximum(1.0, hi - lo)
    atlo = (u <= lo + tol) & (lo < hi)
    athi = (u >= hi - tol) & (lo < hi)
    viol = np.abs(g)
    viol[atlo] = np.maximum(0.0, -g[atlo])
    viol[athi] = np.maximum(0.0, g[athi])
    viol[lo == hi] = 0.0
    return viol


def kkt_least_squares(B, Wv, v, u, lo, hi, gamma=0.0, Wu=None, up=None):
    """min (Bu-v)'Wv(Bu-v) + gamma^2 (u-up)'Wu(u-up) over the box (stage 1 when gamma = 0)."""
    G = B.T @ Wv
    g = G @ (B @ u - v)
    den = np.abs(G).sum(axis=1).max() * (np.abs(B @ u).max() + np.abs(v).max())
    if gamma:
        g = g + gamma**2 * Wu @ (u - up)
        den += gamma**2 * np.abs(Wu).sum(axis=1).max() * (np.abs(u).max() + np.abs(up).max())
    return float(_violations(g, u, lo, hi).max() / (den + 1e-300))


def implied_bounds(B, Wv, v, u, lo, hi, rtol=1e-10, held=None):
    """Effectors held at a bound on the whole stage-1 optimal set.

    For a convex problem a strictly positive multiplier at one optimum makes its
    constraint active at every optimum; the stage-1 gradient is unique (a function of the
    moment), so ``|g1_j| > 0`` pins ``u_j``.  Stage 2's constraints imply these bounds;
    stating them keeps its equality multipliers bounded (with columns collinear to 1e-6
    they otherwise reach ~1e6, beyond what an LP checker resolves).
    ``held`` (rows of B) are equalities of this level (a lower priority level): their
    multipliers are the least-squares ones on the free effectors.
    """
    G = B.T @ Wv
    g = G @ (B @ u - v)
    den = np.abs(G).sum(axis=1).max() * (np.abs(B @ u).max() + np.abs(v).max()) + 1e-300
    if held is not None and len(held):
        tol = 1e-12 * np.maximum(1.0, hi - lo)
        free = (u > lo + tol) & (u < hi - tol)
        lam = np.linalg.lstsq(held[:, free].T, -g[free], rcond=None)[0] if free.any() else np.zeros(len(held))
        g = g + held.T @ lam
    return np.abs(g) > rtol * den


def kkt_equality_qp(B, Wu, up, u, lo, hi, pinned=None):
    """min (u-up)'Wu(u-up) s.t. B u = B u (held), box: exists lam making the signs right.

    ``pinned`` effectors are held by an implied equality (their multiplier is free)."""
    gw = Wu @ (u - up)
    tol = 1e-12 * np.maximum(1.0, hi - lo)
    free = (u > lo + tol) & (u < hi - tol)
    atlo = ~free & (u <= lo + tol) & (lo < hi)
    athi = ~free & (u >= hi - tol) & (lo < hi)
    if pinned is not None:
        atlo &= ~pinned
        athi &= ~pinned
    k = B.shape[0]
    rows, rhs = [], []
    for j in range(B.shape[1]):
        if free[j] or athi[j]:
            rows.append(np.r_[B[:, j], -1.0])
            rhs.append(-gw[j])
        if free[j] or atlo[j]:
            rows.append(np.r_[-B[:, j], -1.0])
            rhs.append(gw[j])
    if not rows:
        return 0.0
    res = linprog(np.r_[np.zeros(k), 1.0], A_ub=np.array(rows), b_ub=np.array(rhs),
                  bounds=[(None, None)] * k + [(0, None)], method="highs")
    assert res.status == 0
    lam = res.x[:k]
    def _viol(g):
        out = _violations(g, u, lo, hi)
        if pinned is not None:
            out[pinned & ~free] = 0.0
        return out.max()

    best = _viol(gw + B.T @ lam)
    tight = np.abs(gw + B.T @ lam) <= 1e-6 * (np.abs(gw).max() + 1e-300)
    if tight.any():  # the LP's lam is accurate to its tolerances; re-solve its tight rows exactly
        lam2 = np.linalg.lstsq(B[:, tight].T, -gw[tight], rcond=None)[0]
        v2 = _viol(gw + B.T @ lam2)
        if v2 <= best:
            best, lam = v2, lam2
    den = np.abs(Wu).sum(axis=1).max() * np.abs(u - up).max() + np.abs(B).sum(axis=0).max() * np.abs(lam).max()
    return float(best / (den + 1e-300))


def near_singular_problem(rng, kind):
    """3 x 8 with collinear/coplanar columns, exact or to 1e-9 (near-singular B'WvB)."""
    p = random_problem(rng, 3, 8, "general")
    B = p.B.copy()
    eps = 1e-6 if kind.startswith("near") else 0.0
    if kind.endswith("collinear"):
        B[:, 1] = -0.7 * B[:, 0] + eps * rng.normal(size=3)
        B[:, 4] = 1.3 * B[:, 3] + eps * rng.normal(size=3)
    else:
        B[:, 2] = 0.4 * B[:, 0] - 1.3 * B[:, 1] + eps * rng.normal(size=3)
        B[:, 5] = B[:, 3] + B[:, 4] + eps * rng.normal(size=3)
    return p.replace(B=B)


def suite(seed, n_problems, n_demands):
    """(problem, demand, lo, hi, call kwargs): 3 x 8 degenerate ones first, then random ones."""
    rng = np.random.default_rng(seed)
    out = []
    kinds38 = ("collinear", "coplanar", "near_collinear", "near_coplanar")
    for i in range(n_problems):
        if i % 2 == 0:
            p = near_singular_problem(rng, kinds38[(i // 2) % 4])
        else:
            k = int(rng.integers(1, 7))
            p = random_problem(rng, k, int(rng.integers(k + 1, 31)), KINDS[i % len(KINDS)])
        for j, v in enumerate(random_demands(rng, p, n_demands, attainable_fraction=0.25)):
            if j % 4 == 0:
                out.append((p, v, p.umin, p.umax, {}))
                continue
            u_prev = rng.uniform(p.umin, p.umax)
            dt = float(rng.choice([0.0005, 0.01, 0.1]))
            lo, hi = p.effective_bounds(u_prev, dt)
            out.append((p, v, lo, hi, dict(u_prev=u_prev, dt=dt)))
    return out


SUITE = suite(2026, 120, 12)


def test_suite_has_unattainable_rate_limited_degenerate_cases():
    n = sum(1 for p, v, lo, hi, kw in SUITE if kw and p.m == 8 and p.k == 3)
    assert n >= 500


@pytest.mark.parametrize("priorities", [None, "two", "three"])
def test_qp_stages_are_kkt_exact(priorities):
    """Stage 1 (Eq 1.20, or each priority level's own stage 1 for the top level) and stage 2
    (Eq 1.21) at relative KKT residual <= 1e-12, no fallback."""
    worst1 = worst2 = 0.0
    built = {}
    bad = []
    for p, v, lo, hi, kw in SUITE:
        if priorities == "two":
            pr = [2] + [1] * (p.k - 1)
        elif priorities == "three":
            pr = [3] + [2] * ((p.k - 1) // 2) + [1] * (p.k - 1 - (p.k - 1) // 2)
        else:
            pr = None
        key = (id(p), priorities)
        if key not in built:
            built[key] = alloc.make_allocator(p, "qp", priorities=pr)
        r = built[key](v, **kw)
        assert r.status is not alloc.Status.FALLBACK, r.message
        if pr is None:
            worst1 = max(worst1, kkt_least_squares(p.B, p.Wv, v, r.u, lo, hi))
        else:  # the top level alone is a plain stage 1 on its rows
            top = np.flatnonzero(np.asarray(pr) == max(pr))
            worst1 = max(worst1, kkt_least_squares(p.B[top], p.Wv[np.ix_(top, top)], v[top], r.u, lo, hi))
        if pr is None:
            pins = implied_bounds(p.B, p.Wv, v, r.u, lo, hi)
        else:  # every level's implied bounds, the levels above it held
            pins = np.zeros(p.m, dtype=bool)
            levels = sorted(set(pr), reverse=True)
            for lv in levels:
                rows = np.flatnonzero(np.asarray(pr) == lv)
                above = np.flatnonzero(np.asarray(pr) > lv)
                pins |= implied_bounds(p.B[rows], p.Wv[np.ix_(rows, rows)], v[rows], r.u, lo, hi,
                                       held=p.B[above])
        k2 = kkt_equality_qp(p.B, p.Wu, p.up, r.u, lo, hi, pins)
        if k2 > KKT_RTOL:
            bad.append((p.k, p.m, bool(kw), k2))
        worst2 = max(worst2, k2)
    assert worst1 <= KKT_RTOL and worst2 <= KKT_RTOL, (worst1, worst2, bad)


@pytest.mark.parametrize("gamma", [1e-2, 1e-4, 1e-6])
def test_wls_is_kkt_exact(gamma):
    worst = 0.0
    built = {}
    for p, v, lo, hi, kw in SUITE[::2]:
        if id(p) not in built:
            built[id(p)] = alloc.make_allocator(p, "wls", gamma=gamma)
        r = built[id(p)](v, **kw)
        assert r.status is not alloc.Status.FALLBACK, r.message
        worst = max(worst, kkt_least_squares(p.B, p.Wv, v, r.u, lo, hi, gamma, p.Wu, p.up))
    assert worst <= KKT_RTOL, worst


@pytest.mark.parametrize("vehicle", [ice, harv_latdir], ids=["ice", "harv"])
def test_qp_kkt_exact_on_a_rate_limited_trajectory(vehicle):
    """A sampled trajectory through saturation (the issue's case): every step exact."""
    p = vehicle()
    f = alloc.make_allocator(p, "qp")
    t = np.arange(300) * 0.01
    scale = np.abs(p.B).sum(axis=1) * np.abs(p.umax).max() * 0.6
    V = np.sin(np.outer(t, [1.3, 2.1, 0.7]) + [0.0, 1.0, 2.0])[:, : p.k] * scale
    u = np.array(p.up)
    for v in V:
        r = f(v, u_prev=u, dt=0.01)
        lo, hi = p.effective_bounds(u, 0.01)
        assert kkt_least_squares(p.B, p.Wv, v, r.u, lo, hi) <= KKT_RTOL
        pins = implied_bounds(p.B, p.Wv, v, r.u, lo, hi)
        assert kkt_equality_qp(p.B, p.Wu, p.up, r.u, lo, hi, pins) <= KKT_RTOL
        u = r.u
