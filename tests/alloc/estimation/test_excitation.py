"""Identifiable allocation (alloc.estimation.excitation): with every registry method, on
seeded hostile problems, the excited command keeps B u to round-off, stays within position
and rate limits exactly, is finite and its status tells the truth; the excitation makes the
regressor well conditioned where allocation alone makes it singular (seed 1.3.2.5)."""

from __future__ import annotations

import numpy as np
import pytest

import alloc
from alloc import vehicles
from alloc.estimation import NullSpaceExcitation, RandomWeightAllocator, regressor_condition
from alloc.exceptions import OptionError
from alloc.result import EXACT_RTOL, Status

DT = 0.01


def hostile_problem(rng: np.random.Generator) -> alloc.Problem:
    """Random k 1-3, m k+1..7; limits asymmetric, some one-sided, one sometimes jammed;
    rate limits finite or infinite; entries of B spanning four decades."""
    k = int(rng.integers(1, 4))
    m = int(rng.integers(k + 1, 8))
    B = rng.normal(size=(k, m)) * 10 ** rng.uniform(-2, 2, (1, m))
    lo = -rng.uniform(0, 30, m)
    hi = rng.uniform(0.5, 30, m)
    lo[rng.random(m) < 0.2] = 0.0
    if rng.random() < 0.3:
        j = int(rng.integers(m))
        lo[j] = hi[j] = 0.0
    rate = np.where(rng.random(m) < 0.5, rng.uniform(5, 200, m), np.inf)
    return alloc.Problem(B, lo, hi, rate_min=-rate, rate_max=rate)


def certified_status(p: alloc.Problem, u: np.ndarray, v: np.ndarray) -> Status:
    """The exact test recomputed independently (the residual against EXACT_RTOL)."""
    res = np.abs(p.B @ u - v).max()
    return Status.EXACT if res <= EXACT_RTOL * max(1.0, np.abs(v).max()) else Status.UNATTAINABLE


def near_the_tolerance(p: alloc.Problem, u: np.ndarray, v: np.ndarray) -> bool:
    """Within a factor 10 of the tolerance, where the library's certified test (which adds a
    rounding bound) and the plain residual may disagree."""
    res = np.abs(p.B @ u - v).max()
    tol = EXACT_RTOL * max(1.0, np.abs(v).max())
    return tol / 10 < res < 10 * tol


@pytest.mark.parametrize("method", alloc.methods())
def test_excitation_keeps_moments_and_limits_with_every_method(method: str) -> None:
    """3 hostile problems x 10 calls, with and without rate limits, PRBS and multisine: B u
    moves by round-off only (<= 1e-12 relative to |B| |u|), every command lies within that
    call's bounds exactly, and the status is the excited command's own."""
    rng = np.random.default_rng(sum(map(ord, method)))
    excited_calls = 0
    for case in range(3):
        p = hostile_problem(rng)
        a = alloc.make_allocator(p, method)
        ex = NullSpaceExcitation(a, DT, amplitude=rng.uniform(0.1, 3.0, p.m), signal=("prbs", "multisine")[case % 2],
                                 seed=case)
        u_prev = np.clip(rng.normal(size=p.m) * 5, p.umin, p.umax)
        for call in range(10):
            v = rng.normal(size=p.k) * np.abs(p.B).sum(axis=1) * rng.uniform(0.05, 2.0)
            rated = call % 3 != 0
            kw = {"u_prev": u_prev, "dt": DT} if rated else {}
            r0 = a(v, **kw)
            r = ex(v, **kw)
            lo, hi = p.effective_bounds(**kw) if rated else (p.umin, p.umax)
            assert np.isfinite(r.u).all()
            assert (r.u >= lo).all() and (r.u <= hi).all()
            scale = float((np.abs(p.B) @ (np.abs(r.u) + np.abs(r0.u))).max()) + 1e-300
            assert np.abs(p.B @ r.u - p.B @ r0.u).max() <= 1e-12 * scale
            assert np.abs(r.v_achieved - p.B @ r.u).max() <= 1e-12 * scale
            if r0.status is Status.FALLBACK:
                assert r.status is Status.FALLBACK
            elif not near_the_tolerance(p, r.u, v):
                assert r.status is certified_status(p, r.u, v)
            excited_calls += bool(np.abs(r.u - r0.u).max() > 0)
            u_prev = r.u
    assert excited_calls > 0


def ice_demands(n: int) -> np.ndarray:
    """Moderate demands (the linear regime of most methods): three incommensurate sines."""
    t = np.arange(n) * DT
    return np.column_stack([2 * np.sin(0.3 * t), 4 * np.sin(0.5 * t + 1), np.cos(0.7 * t)])


@pytest.mark.parametrize("method", ["pinv", "qp", "wls"])
def test_excitation_makes_the_regressor_well_conditioned(method: str) -> None:
    """ICE (mid-range preferences), 10 s at 100 Hz: allocation alone gives a singular regressor
    (condition > 1e12: three demands drive eleven effectors), 2-degree multisine excitation
    brings it below 300, and the moments are unchanged to round-off."""
    p = vehicles.problem("ice-mid")
    a = alloc.make_allocator(p, method)
    ex = NullSpaceExcitation(a, DT, amplitude=2.0, seed=1)
    U0, U1, u_prev = [], [], p.up.copy()
    for v in ice_demands(1000):
        U0.append(a(v).u)
        r = ex(v, u_prev=u_prev, dt=DT)
        U1.append(r.u)
        u_prev = r.u
    scale = (p.umax - p.umin) / 2
    assert regressor_condition(U0, scale) > 1e12
    assert regressor_condition(U1, scale) < 300


def test_random_weights_decorrelate_a_weighted_method() -> None:
    """The seed's variant (random Wu) on pinv for ICE: the regressor's condition number falls
    from > 1e12 to below 1e4; each call is an ordinary pinv allocation of its own weights."""
    p = vehicles.problem("ice-mid")
    rw = RandomWeightAllocator(p, "pinv", spread=4.0, n_weights=8, dwell=25, seed=3)
    U = []
    for v in ice_demands(1000):
        r = rw(v)
        np.testing.assert_array_equal(r.u, rw.bank[rw.current](v).u)
        U.append(r.u)
    assert regressor_condition(U, (p.umax - p.umin) / 2) < 1e4
    assert len({tuple(np.round(f, 12)) for f in rw.factors}) == 8


def test_bad_input_names_the_field() -> None:
    p = vehicles.problem("ice")
    a = alloc.make_allocator(p, "pinv")
    for kwargs, field in (({"signal": "chirp"}, "signal"), ({"amplitude": -1.0}, "amplitude"),
                          ({"amplitude": [1.0, 2.0]}, "amplitude"), ({"band": (0.0, 1.0)}, "band"),
                          ({"seed": -1}, "seed")):
        with pytest.raises(OptionError) as info:
            NullSpaceExcitation(a, DT, **kwargs)
        assert info.value.field == field and isinstance(info.value, TypeError)
    with pytest.raises(OptionError, match="allocator"):
        NullSpaceExcitation("pinv", DT)
    with pytest.raises(OptionError, match="spread"):
        RandomWeightAllocator(p, "pinv", spread=1.0)
    with pytest.raises(alloc.UnknownMethodError):
        RandomWeightAllocator(p, "nope")
    ex = NullSpaceExcitation(a, DT)
    with pytest.raises(alloc.DemandError):
        ex([np.nan, 0.0, 0.0])
