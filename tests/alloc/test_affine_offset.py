"""Methods on problems whose preferred position is not zero (hover thrust, mid-range surfaces).

Class of defect (issue 22): an affine method that adds ``up`` but not its moment ``B up``
misses every demand, and an exact-region computation that assumes ``B c = 0`` hides it.
Every registered method is checked against the truth ``B u = v`` (not its own status) on
problems with ``up != 0``, and every coverage figure against sampled truth.
"""

from __future__ import annotations

import numpy as np
import pytest

import alloc
from alloc.ams import AttainableSet, coverage, sample_ams
from alloc.result import EXACT_RTOL
from alloc.vehicles import ice_daisy_groups, ice_mid


def hexacopter() -> alloc.Problem:
    """A 4 x 6 hexacopter: rows thrust (N), roll, pitch, yaw (N m) per rotor thrust (N, 0..15).

    Arm 0.25 m, rotors at 60 deg spacing alternating spin, yaw torque 0.016 m x thrust;
    preferred position hover (1.2 kg: 6 x 1.962 N)."""
    angles = np.deg2rad(np.arange(6) * 60.0)
    spin = np.array([1, -1, 1, -1, 1, -1], dtype=float)
    B = np.vstack([np.ones(6), 0.25 * np.sin(angles), -0.25 * np.cos(angles), 0.016 * spin])
    return alloc.Problem(B, np.zeros(6), np.full(6, 15.0), up=np.full(6, 1.2 * 9.81 / 6))


def random_offset_problem(seed: int) -> alloc.Problem:
    rng = np.random.default_rng(seed)
    k, m = int(rng.integers(1, 4)), int(rng.integers(4, 9))
    B = rng.standard_normal((k, m))
    lo = -rng.uniform(0.2, 2.0, m)
    hi = rng.uniform(0.2, 2.0, m)
    up = lo + rng.uniform(0.2, 0.8, m) * (hi - lo)  # strictly inside, away from zero
    return alloc.Problem(B, lo, hi, up=up)


def options_for(method: str, problem: alloc.Problem) -> dict:
    if method == "daisy":
        if problem.m == 11:  # ICE: the catalogue's groups
            return {"groups": ice_daisy_groups()}
        # a first group that spans the axes on its own (daisy is exact only where it does)
        return {"groups": [list(range(problem.m - 1)), [problem.m - 1]]}
    return {}


PROBLEMS = {"hexacopter": hexacopter, "ice-mid": ice_mid,
            **{f"random{s}": (lambda s=s: random_offset_problem(s)) for s in range(4)}}


@pytest.mark.parametrize("name", sorted(PROBLEMS))
@pytest.mark.parametrize("method", alloc.methods())
def test_demands_near_the_preferred_moment_are_met(method, name):
    """``v`` close to ``B up``: ``u = up + pinv increment`` is admissible (the increment is a
    tenth of the smallest room to a limit), so every method must meet ``B u = v`` and say
    ``exact`` (the hexacopter's hover thrust, 11.8 N, is one such ``v``)."""
    p = PROBLEMS[name]()
    allocate = alloc.make_allocator(p, method, **options_for(method, p))
    rng = np.random.default_rng(11)
    P = np.linalg.pinv(p.B)
    for trial in range(20):
        d = rng.standard_normal(p.k)
        # shrink the increment until up + P d sits well inside the limits
        room = np.minimum(p.umax - p.up, p.up - p.umin)
        d *= 0.1 * room.min() / max(np.abs(P @ d).max(), 1e-12)
        v = p.B @ p.up + (d if trial else 0.0)
        r = allocate(v)
        assert np.abs(p.B @ r.u - v).max() <= EXACT_RTOL * max(1.0, np.abs(v).max()), (method, name, trial, r.status)
        assert r.status is alloc.Status.EXACT, (method, name, trial, r.status)


def test_hexacopter_hover_thrust_with_ganging():
    # issue 22: a 39.2 N thrust demand came out as 71.5 N
    p = hexacopter()
    r = alloc.make_allocator(p, "ganging")(np.array([39.2, 0.0, 0.0, 0.0]))
    assert r.status is alloc.Status.EXACT
    np.testing.assert_allclose(p.B @ r.u, [39.2, 0, 0, 0], atol=1e-12)


def test_ice_mid_zero_demand_with_ganging():
    # issue 22: a zero demand on ice-mid came out as 1.63 on the alpha row
    p = ice_mid()
    r = alloc.make_allocator(p, "ganging")(np.zeros(3))
    np.testing.assert_allclose(p.B @ r.u, 0.0, atol=1e-12)


def test_ganging_with_a_user_gang_that_is_not_a_right_inverse_is_exact_nowhere():
    # B G != I: u = c + G v meets B u = v only on a lower-dimensional set; the coverage is
    # then estimated by sampling, and the sample finds none
    p = hexacopter()
    G = np.linalg.pinv(p.B) * 0.9
    cov = coverage(p, "ganging", G=G, samples=2_000, seed=1)
    assert cov.estimator == "monte-carlo" and cov.fraction == 0.0


def sampled_truth(problem: alloc.Problem, method: str, n: int, seed: int) -> float:
    """Fraction of uniform AMS samples where the method's ``u`` is admissible and meets
    ``B u = v`` -- measured on ``u`` itself, not on the method's status."""
    V = sample_ams(AttainableSet(problem), n, np.random.default_rng(seed))
    allocate = alloc.make_allocator(problem, method, **options_for(method, problem))
    met = 0
    for v in V:
        u = allocate(v).u
        admissible = (u >= problem.umin).all() and (u <= problem.umax).all()
        met += bool(admissible and np.abs(problem.B @ u - v).max() <= EXACT_RTOL * max(1.0, np.abs(v).max()))
    return met / n


@pytest.mark.parametrize("name", ["hexacopter", "ice-mid"])
@pytest.mark.parametrize("method", alloc.methods())
def test_coverage_agrees_with_sampled_truth(method, name):
    p = PROBLEMS[name]()
    n = 1_500
    cov = coverage(p, method, samples=n, seed=21, **options_for(method, p))
    truth = sampled_truth(p, method, n, seed=22)
    se = np.sqrt(max(truth * (1 - truth), 1.0 / n) / n)
    # both estimate the same fraction: within 5 standard errors (of the two samples)
    assert abs(cov.fraction - truth) <= 5 * np.hypot(se, cov.stderr), (method, name, cov, truth)
