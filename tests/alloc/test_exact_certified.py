"""``exact`` is a certificate: the residual in exact arithmetic is within the tolerance.

Class of defect (issue 22): where ``|B| |u|`` is 1e25-1e49 times the demand the float64
product ``B u`` cancels, and a residual computed as zero was reported ``exact`` although the
true residual was 1e14-1e38 times the tolerance.  The truth here is rational arithmetic
(:class:`fractions.Fraction`, exact for every float64), not the code's own check.
"""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

import alloc
from alloc import vehicles
from alloc._engine._kernels import finish
from alloc.result import EXACT_RTOL


def true_residual(B: np.ndarray, u: np.ndarray, v: np.ndarray) -> Fraction:
    """``max_i |sum_j B_ij u_j - v_i|`` in exact rational arithmetic."""
    worst = Fraction(0)
    for i in range(B.shape[0]):
        s = sum((Fraction(float(b)) * Fraction(float(x)) for b, x in zip(B[i], u)), Fraction(0))
        worst = max(worst, abs(s - Fraction(float(v[i]))))
    return worst


def tolerance(v: np.ndarray) -> Fraction:
    return Fraction(EXACT_RTOL) * max(Fraction(1), max(Fraction(abs(float(x))) for x in v))


def sequential_product(B: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``B u`` summed left to right, as the kernels do: its residual computes as zero."""
    out = np.zeros(B.shape[0])
    for i in range(B.shape[0]):
        s = 0.0
        for j in range(B.shape[1]):
            s += B[i, j] * u[j]
        out[i] = s
    return out


def cancelling_case(rng: np.random.Generator):
    """``u`` in the null space of ``B`` (|B| |u| 1e20-1e45, ``B u`` cancels), and ``v`` the
    float64 ``B u`` itself or next to it: the computed residual is about zero, the true one
    the product's rounding error, about eps |B| |u| -- many times the tolerance."""
    k, m = int(rng.integers(1, 4)), int(rng.integers(4, 9))
    B = rng.standard_normal((k, m)) * 10.0 ** rng.uniform(5, 20)
    null = np.linalg.svd(B)[2][k:]
    u = null.T @ rng.standard_normal(m - k) * 10.0 ** rng.uniform(10, 25)
    v = sequential_product(B, u) + rng.standard_normal(k) * 1e-9 * (rng.random() < 0.5)
    return B, u, v


@pytest.mark.parametrize("seed", range(300))
def test_finish_never_certifies_a_false_exact(seed):
    rng = np.random.default_rng(seed)
    B, u, v = cancelling_case(rng)
    lo, hi = -np.full(len(u), 1e49), np.full(len(u), 1e49)
    ach = np.empty(B.shape[0])
    code = finish(np.ascontiguousarray(B), u.copy(), lo, hi, v, ach, EXACT_RTOL)
    if code == 0:
        assert true_residual(B, u, v) <= tolerance(v), seed


def test_plain_cases_stay_exact():
    # the certificate costs nothing where float64 can tell: ICE demands inside the AMS
    p = vehicles.problem("ice")
    allocate = alloc.make_allocator(p, "qp")
    rng = np.random.default_rng(0)
    exact = 0
    for _ in range(200):
        v = rng.uniform(-1, 1, 3) * [2.0, 30.0, 0.5]
        r = allocate(v)
        exact += r.status is alloc.Status.EXACT
        if r.status is alloc.Status.EXACT:
            assert true_residual(p.B, r.u, v) <= tolerance(v)
    assert exact > 100  # measured 200 of 200 before and after the certificate


def huge_problem(seed: int) -> tuple[alloc.Problem, np.ndarray]:
    """A valid problem (magnitudes inside the documented domain) whose |B| |u| dwarfs v."""
    rng = np.random.default_rng(seed)
    k, m = int(rng.integers(1, 4)), int(rng.integers(3, 8))
    B = rng.standard_normal((k, m)) * 10.0 ** rng.uniform(0, 25, m)
    hi = 10.0 ** rng.uniform(0, 24, m)
    p = alloc.Problem(B, -hi, hi)
    v = rng.standard_normal(k) * 10.0 ** rng.uniform(-3, 2)
    return p, v


@pytest.mark.parametrize("method", ["pinv", "pinv_scale", "ganging", "qp", "wls", "dynamic", "lp", "da",
                                    "da_facet", "da_table", "cgi"])
def test_methods_never_report_a_false_exact_on_cancelling_problems(method):
    false_exact = []
    for seed in range(40):
        p, v = huge_problem(seed)
        r = alloc.make_allocator(p, method)(v)
        if r.status is alloc.Status.EXACT and true_residual(p.B, r.u, v) > tolerance(v):
            false_exact.append(seed)
    assert not false_exact, (method, false_exact)
