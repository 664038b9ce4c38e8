"""The cvxpy reference of every optimisation method, as one table.

Each method that solves an optimisation problem has an independent formulation of that problem
written out in cvxpy (Clarabel or OSQP at tight tolerances) and a check comparing the library's
answer with it: ``u`` where the optimum is unique, the optimal values where it is not (the L1
stage 2, direct allocation on edges).  :data:`REFERENCES` maps a method to its row
(:class:`Reference`: the formulation, the check, its tolerance, the cases and the option sets it is
run with); ``tests/alloc/test_crosscheck_cvxpy.py`` runs every row, and a new method adds one row
(``tests/walkthroughs/test_add_a_method.py`` does).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import cvxpy as cp
import numpy as np
import pytest

import alloc
from alloc.testing import KINDS, random_demands, random_problem
from alloc.vehicles import harv_latdir, ice

SOLVER = dict(solver=cp.CLARABEL, tol_gap_abs=1e-11, tol_gap_rel=1e-11, tol_feas=1e-11)
# Interior-point solvers do not resolve tiny quadratic terms in u (SOLVER-NOTES); the QP
# references use OSQP at tight tolerances with solution polishing instead.
QP_SOLVER = dict(solver=cp.OSQP, eps_abs=1e-11, eps_rel=1e-11, polishing=True, max_iter=400000)


def cvx_qp(p, v, lo, hi, m1=None):
    """Eq 1.20 then Eq 1.21 (stage 2 at the stage-1 moment ``m1``), written out in cvxpy."""
    u = cp.Variable(p.m)
    Lv = np.linalg.cholesky(p.Wv)
    e = Lv.T @ (p.B @ u - v)
    cp.Problem(cp.Minimize(cp.sum_squares(e)), [u >= lo, u <= hi]).solve(**SOLVER)
    J1 = float(np.sum((Lv.T @ (p.B @ u.value - v)) ** 2))
    if m1 is None:
        m1 = p.B @ np.clip(u.value, lo, hi)  # the stage-1 moment is unique, u is not
    Lu = np.linalg.cholesky(p.Wu)
    u2 = cp.Variable(p.m)
    stage2 = cp.Problem(cp.Minimize(cp.sum_squares(Lu.T @ (u2 - p.up))), [u2 >= lo, u2 <= hi, p.B @ u2 == m1])
    stage2.solve(**QP_SOLVER)
    return u2.value, J1


def cvx_wls(p, v, lo, hi, gamma):
    u = cp.Variable(p.m)
    Lv, Lu = np.linalg.cholesky(p.Wv), np.linalg.cholesky(p.Wu)
    obj = cp.sum_squares(Lv.T @ (p.B @ u - v)) + gamma**2 * cp.sum_squares(Lu.T @ (u - p.up))
    prob = cp.Problem(cp.Minimize(obj), [u >= lo, u <= hi])
    prob.solve(**QP_SOLVER)
    return u.value, prob.value


def cvx_lp(p, v, lo, hi, m1=None):
    """Eqs 1.18-1.19: optimal values of both stages (stage 2 at the stage-1 moment ``m1``)."""
    wv, wu = np.diagonal(p.Wv), np.diagonal(p.Wu)
    u = cp.Variable(p.m)
    s1 = cp.Problem(cp.Minimize(wv @ cp.abs(p.B @ u - v)), [u >= lo, u <= hi])
    s1.solve(**SOLVER)
    if m1 is None:
        m1 = p.B @ np.clip(u.value, lo, hi)
    u2 = cp.Variable(p.m)
    s2 = cp.Problem(cp.Minimize(wu @ cp.abs(u2 - p.up)), [u2 >= lo, u2 <= hi, p.B @ u2 == m1])
    s2.solve(**SOLVER)
    return s1.value, s2.value


def cvx_da(p, v, lo, hi):
    """Eqs 1.15-1.17: the largest a with B(u - u0) = a (v - B u0) admissible."""
    u0 = np.clip(p.up, lo, hi)
    d = v - p.B @ u0
    u, a = cp.Variable(p.m), cp.Variable()
    prob = cp.Problem(cp.Maximize(a), [p.B @ (u - u0) == a * d, u >= lo, u <= hi, a >= 0])
    prob.solve(**SOLVER)
    return float(a.value)


def cases():
    """ICE, HARV and seeded random suites (all kinds), with and without rate limits."""
    rng = np.random.default_rng(2024)
    out = []
    for name, p in (("ice", ice()), ("harv", harv_latdir())):
        for j, v in enumerate(random_demands(rng, p, 12)):
            out.append((f"{name}-{j}", p, v, j % 3 == 0))
    for i in range(36):
        k = int(rng.integers(1, 7))
        m = int(rng.integers(k + 1, 21))
        p = random_problem(rng, k, m, KINDS[i % len(KINDS)])
        p = p.replace(Wv=np.diagonal(p.Wv)) if np.count_nonzero(p.Wv - np.diag(np.diagonal(p.Wv))) and i % 2 else p
        v = random_demands(rng, p, 1)[0]
        out.append((f"rand{i}-{KINDS[i % len(KINDS)]}-k{k}m{m}", p, v, i % 3 == 0))
    return out


CASES = cases()


def bounds(p, rated, seed=0):
    if not rated:
        return p.umin, p.umax, {}
    rng = np.random.default_rng(seed)
    u_prev = rng.uniform(p.umin, p.umax)
    lo, hi = p.effective_bounds(u_prev, 0.05)
    return lo, hi, dict(u_prev=u_prev, dt=0.05)


def polish_stage1(p, v, lo, hi, u_ref):
    """The reference stage-1 moment made exact on the active set cvxpy found.

    Effectors within 1e-7 (relative) of a bound are held there; the rest solve the
    equality-free least squares ``min |Lv'(B_F u_F - (v - B_X u_X))|`` by ``lstsq``.  Only
    the active set comes from cvxpy; the arithmetic is numpy's.  The polished point is
    used only if it is admissible and at least as good as the unpolished one.
    """
    span = np.maximum(hi - lo, 1e-12)
    u = np.clip(u_ref, lo, hi)
    X = (u - lo <= 1e-7 * span) | (hi - u <= 1e-7 * span)
    u[X & (u - lo <= 1e-7 * span)] = lo[X & (u - lo <= 1e-7 * span)]
    u[X & (hi - u <= 1e-7 * span)] = hi[X & (hi - u <= 1e-7 * span)]
    S = np.linalg.cholesky(p.Wv).T
    F = ~X
    cand = u.copy()
    if F.any():
        cand[F] = np.linalg.lstsq(S @ p.B[:, F], S @ (v - p.B[:, X] @ u[X]), rcond=1e-13)[0]

    def J(x: np.ndarray) -> float:
        return float(np.sum((S @ (p.B @ x - v)) ** 2))

    ok = (cand >= lo - 1e-12 * span).all() and (cand <= hi + 1e-12 * span).all() and J(cand) <= J(u) + 1e-14
    return p.B @ (cand if ok else u)


def polish_stage2(p, m1, lo, hi, u_ref):
    """The reference stage-2 answer made exact on its active set: with the effectors near
    a bound held there, ``min (u-up)'Wu(u-up)`` s.t. ``B u = m1`` is one KKT system."""
    span = np.maximum(hi - lo, 1e-12)
    u = np.clip(u_ref, lo, hi)
    atlo, athi = u - lo <= 1e-7 * span, hi - u <= 1e-7 * span
    u[atlo], u[athi] = lo[atlo], hi[athi]
    F = ~(atlo | athi)
    nf = int(F.sum())
    if nf == 0:
        return u
    H = p.Wu[np.ix_(F, F)]
    rhs1 = H @ p.up[F] - p.Wu[np.ix_(F, ~F)] @ (u[~F] - p.up[~F])
    K = np.block([[H, p.B[:, F].T], [p.B[:, F], np.zeros((p.k, p.k))]])
    sol = np.linalg.lstsq(K, np.r_[rhs1, m1 - p.B[:, ~F] @ u[~F]], rcond=1e-14)[0]
    cand = u.copy()
    cand[F] = sol[:nf]
    ok = (cand >= lo - 1e-12 * span).all() and (cand <= hi + 1e-12 * span).all()
    return cand if ok else u


def cases_3x8():
    """3 x 8 problems with collinear or coplanar columns, unattainable demands, rate limits."""
    rng = np.random.default_rng(38)
    out = []
    for i in range(16):
        kind = ("collinear", "coplanar")[i % 2]
        p = random_problem(rng, 3, 8, kind)
        v = random_demands(rng, p, 1, attainable_fraction=0.0)[0]
        out.append((f"3x8-{kind}-{i}", p, v, True))
    return out


CASES_QP = CASES + cases_3x8()


def check_qp(name, p, v, rated, options):
    """Stage 1's moment (unique) to 1e-9 and stage 2's u (unique) to 1e-9 against cvxpy's
    answers polished on their own active sets (:func:`polish_stage1`, :func:`polish_stage2`);
    stage 2's reference is solved at our moment (the same feasible set)."""
    lo, hi, kw = bounds(p, rated, seed=len(name))
    r = alloc.allocate(p, v, "qp", **options, **kw)
    u = cp.Variable(p.m)
    S = np.linalg.cholesky(p.Wv).T
    cp.Problem(cp.Minimize(cp.sum_squares(S @ (p.B @ u - v))), [u >= lo, u <= hi]).solve(**SOLVER)
    m_ref = polish_stage1(p, v, lo, hi, u.value)
    scale = max(1.0, float(np.abs(v).max()))
    np.testing.assert_allclose(r.v_achieved, m_ref, atol=1e-9 * scale, rtol=0)
    u_ref, _ = cvx_qp(p, v, lo, hi, m1=r.v_achieved)
    u_ref = polish_stage2(p, r.v_achieved, lo, hi, u_ref)
    np.testing.assert_allclose(r.u, u_ref, atol=1e-9 * max(1.0, np.abs(hi - lo).max()), rtol=0)


def check_wls(name, p, v, rated, options):
    gamma = options["gamma"]
    lo, hi, kw = bounds(p, rated)
    r = alloc.allocate(p, v, "wls", **options, **kw)
    u_ref, J_ref = cvx_wls(p, v, lo, hi, gamma)
    np.testing.assert_allclose(r.u, u_ref, atol=1e-6 * max(1.0, np.abs(hi - lo).max()), rtol=0)


def check_lp(name, p, v, rated, options):
    if np.count_nonzero(p.Wv - np.diag(np.diagonal(p.Wv))):
        p = p.replace(Wv=np.diagonal(p.Wv))
    lo, hi, kw = bounds(p, rated)
    r = alloc.allocate(p, v, "lp", **options, **kw)
    wv, wu = np.diagonal(p.Wv), np.diagonal(p.Wu)
    J1 = float(wv @ np.abs(p.B @ r.u - v))
    J2 = float(wu @ np.abs(r.u - p.up))
    # Stage 1 against the reference optimum; stage 2 against the reference at our stage-1
    # moment (the L1 stage-1 optimum may be a whole face of moments; Eq 1.19 fixes one).
    J1_ref, J2_ref = cvx_lp(p, v, lo, hi, m1=r.v_achieved)
    scale = max(1.0, float(np.abs(v).max()))
    assert J1 == pytest.approx(J1_ref, abs=1e-6 * scale)
    assert J2 == pytest.approx(J2_ref, abs=1e-6 * max(1.0, J2_ref))


def check_da(name, p, v, rated, options):
    """Both the facet search (``auto`` on these sizes) and the LP backends."""
    lo, hi, kw = bounds(p, rated)
    alloc_da = alloc.make_allocator(p, "da", **options)
    r = alloc_da(v, **kw)
    a_ref = cvx_da(p, v, lo, hi)
    u0 = np.clip(p.up, lo, hi)
    d = v - p.B @ u0
    if np.linalg.matrix_rank(p.B) < p.k and np.abs(d - p.B @ np.linalg.lstsq(p.B, d, rcond=None)[0]).max() > 1e-9:
        pytest.skip("demand leaves the range of a rank-deficient B: the LP reference has only a = 0")
    # achieved moment = u0-moment + min(a*, 1) d
    expected = p.B @ u0 + min(a_ref, 1.0) * d
    np.testing.assert_allclose(r.v_achieved, expected, atol=1e-6 * max(1.0, np.abs(v).max()), rtol=0)
    assert (r.status is alloc.Status.EXACT) == (a_ref >= 1 - 1e-7) or abs(a_ref - 1) < 1e-6


Case = tuple[str, alloc.Problem, np.ndarray, bool]


@dataclass(frozen=True)
class Reference:
    """One method's row: what cvxpy solves, how the answers are compared, on which cases."""

    formulation: str
    check: Callable[[str, alloc.Problem, np.ndarray, bool, Mapping[str, Any]], None]
    tolerance: str
    cases: Sequence[Case] = field(default_factory=lambda: CASES)
    options: Sequence[Mapping[str, Any]] = ({},)


REFERENCES: dict[str, Reference] = {
    "qp": Reference("Eq 1.20 then Eq 1.21 at the stage-1 moment (OSQP, polished on its active set)", check_qp,
                    "stage-1 moment 1e-9 max(1, |v|); stage-2 u 1e-9 max(1, span)", CASES_QP),
    "wls": Reference("Eq 1.22, gamma 1e-2 (unique optimum)", check_wls, "u 1e-6 max(1, span)",
                     options=({"gamma": 1e-2},)),
    "lp": Reference("Eqs 1.18-1.19, optimal values of both stages", check_lp,
                    "stage 1 1e-6 max(1, |v|); stage 2 1e-6 max(1, J2)"),
    "da": Reference("Eqs 1.15-1.17, the largest admissible scale a", check_da, "moment 1e-6 max(1, |v|)",
                    options=({"backend": "auto"}, {"backend": "daqp"}, {"backend": "highs"})),
}


def params(references: Mapping[str, Reference] | None = None) -> list[Any]:
    """``pytest.param(method, options, name, p, v, rated)`` for every row, option set and case."""
    rows = REFERENCES if references is None else references
    out = []
    for method, ref in rows.items():
        for options in ref.options:
            tag = ",".join(f"{k}={v}" for k, v in options.items())
            for name, p, v, rated in ref.cases:
                out.append(pytest.param(method, dict(options), name, p, v, rated,
                                        id=f"{method}[{tag}]-{name}" if tag else f"{method}-{name}"))
    return out
