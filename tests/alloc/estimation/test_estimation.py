"""Estimators of the effectiveness matrix (alloc.estimation.rls, .frequency): they converge
to the true matrix within their stated uncertainty (confidence intervals cover at the
nominal rate), hold unexcited directions without windup, follow a change, round-trip their
state, and refuse bad input naming the field."""

from __future__ import annotations

import json

import numpy as np
import pytest

from alloc.estimation import (
    EffectivenessRLS,
    FrequencyDomainEstimator,
    RecursiveLeastSquares,
    SampleError,
    StateError,
)
from alloc.exceptions import OptionError

Z95 = 1.959963984540054


def random_case(rng: np.random.Generator) -> tuple[np.ndarray, float, np.ndarray]:
    """A random B (k 1-4, m 2-8), a noise level, and a prior off by about prior_std = 0.5."""
    k, m = int(rng.integers(1, 5)), int(rng.integers(2, 9))
    B = rng.normal(size=(k, m))
    return B, float(rng.uniform(0.05, 0.5)), B + rng.normal(size=(k, m)) * 0.5


def test_rls_confidence_intervals_cover_at_the_nominal_rate() -> None:
    """60 seeded random problems, 40-120 samples each, forgetting 0.97-1, penalty 0.01-1:
    the 95 % intervals of every entry cover the truth 95 % of the time (binomial 3.5 sigma)."""
    rng = np.random.default_rng(20261201)
    inside = total = 0
    for _ in range(60):
        B, sigma, B0 = random_case(rng)
        k, m = B.shape
        est = EffectivenessRLS(B0, prior_std=0.5, noise_std=sigma, forgetting=float(rng.uniform(0.97, 1.0)),
                               penalty=float(10 ** rng.uniform(-2, 0)))
        for _ in range(int(rng.integers(40, 120))):
            u = rng.normal(size=m) * rng.uniform(0.5, 3.0)
            est.update(u, B @ u + rng.normal(size=k) * sigma)
        z = (est.B - B) / est.B_std
        inside += int((np.abs(z) < Z95).sum())
        total += z.size
    share = inside / total
    assert abs(share - 0.95) <= 3.5 * np.sqrt(0.95 * 0.05 / total), (share, total)


def test_rls_is_the_minimiser_of_eq_1_4_at_every_sample() -> None:
    """An independent formulation: at each sample, the estimate solves the normal equations of
    seed Eq 1.4 built from the raw data (weights lambda^(n-i), penalty on the previous estimate)."""
    rng = np.random.default_rng(4)
    k, p, lam, alpha = 2, 3, 0.9, 0.5
    theta0 = rng.normal(size=(k, p))
    est = RecursiveLeastSquares(k, p, forgetting=lam, penalty=alpha, theta0=theta0)
    W, Y, prev = [], [], theta0
    for n in range(30):
        w, y = rng.normal(size=p), rng.normal(size=k)
        W.append(w)
        Y.append(y)
        est.update(w, y)
        weights = lam ** np.arange(n, -1, -1)
        Wa, Ya = np.array(W), np.array(Y)
        M = (Wa * weights[:, None]).T @ Wa + alpha * np.eye(p)
        rhs = (Wa * weights[:, None]).T @ Ya + alpha * prev.T
        prev = np.linalg.solve(M, rhs).T
        np.testing.assert_allclose(est.theta, prev, rtol=1e-9, atol=1e-12)


def test_rls_converges_to_the_true_column() -> None:
    """After 800 samples of ICE-sized data (3 x 11) the error of every entry is within 4
    of its standard deviation, and the deviations shrank from the prior's 1 to below 0.02."""
    rng = np.random.default_rng(8)
    B = rng.normal(size=(3, 11))
    est = EffectivenessRLS(np.zeros((3, 11)), prior_std=1.0, noise_std=0.7, forgetting=1.0, penalty=1.0)
    for _ in range(800):
        u = rng.uniform(-10, 10, 11)
        est.update(u, B @ u + rng.normal(size=3) * 0.7)
    assert (np.abs(est.B - B) <= 4 * est.B_std).all()
    assert est.B_std.max() < 0.02


def test_rls_holds_unexcited_directions_without_windup() -> None:
    """Only effector 0 ever moves (then nothing at all for 2,000 samples, forgetting 0.98):
    the other columns stay at the prior exactly, their uncertainty stays the prior's (never
    grows), and the solved matrix's condition number keeps its stated bound."""
    rng = np.random.default_rng(9)
    B = rng.normal(size=(2, 4))
    B0 = B + 0.3
    est = EffectivenessRLS(B0, prior_std=0.3, noise_std=0.1, forgetting=0.98, penalty=0.5)
    wmax = 0.0
    for i in range(3_000):
        u = np.zeros(4)
        if i < 1000:
            u[0] = rng.normal() * 3
        wmax = max(wmax, float(u @ u))
        est.update(u, B @ u + rng.normal(size=2) * 0.1)
        if i == 999:
            assert np.abs(est.B[:, 0] - B[:, 0]).max() < 0.05
    np.testing.assert_array_equal(est.B[:, 1:], B0[:, 1:])
    np.testing.assert_allclose(est.B_std[:, 1:], 0.3, rtol=1e-12)
    assert np.isfinite(est.rls.S_noise).all() and np.abs(est.rls.S_noise).max() < 1e3
    assert est.rls.condition() <= 1 + wmax / (0.5 * (1 - 0.98)) + 1e-9
    assert (est.B_std[:, 0] <= 0.3 + 1e-12).all()  # forgotten information returns to the prior, no further


def test_rls_follows_a_change() -> None:
    """A column halves at sample 1,000 (forgetting 0.98, memory 50 samples): 400 samples later
    the estimate is within 5 % of the new column."""
    rng = np.random.default_rng(10)
    B = rng.normal(size=(3, 5))
    est = EffectivenessRLS(B, prior_std=0.2, noise_std=0.2, forgetting=0.98, penalty=0.1)
    for i in range(1400):
        if i == 1000:
            B = B.copy()
            B[:, 2] *= 0.5
        u = rng.uniform(-5, 5, 5)
        est.update(u, B @ u + rng.normal(size=3) * 0.2)
    assert np.linalg.norm(est.B[:, 2] - B[:, 2]) <= 0.05 * np.linalg.norm(B[:, 2])


def test_rls_state_round_trips() -> None:
    rng = np.random.default_rng(12)
    a = EffectivenessRLS(np.ones((2, 3)), n_states=1, bias=True, noise_std=None)
    for _ in range(50):
        a.update(rng.normal(size=3), rng.normal(size=2), x=rng.normal(size=1))
    b = EffectivenessRLS.from_dict(json.loads(json.dumps(a.to_dict())))
    for _ in range(20):
        u, y, x = rng.normal(size=3), rng.normal(size=2), rng.normal(size=1)
        a.update(u, y, x=x)
        b.update(u, y, x=x)
    np.testing.assert_array_equal(a.B, b.B)
    np.testing.assert_array_equal(a.B_std, b.B_std)


def test_rls_bad_input_names_the_field() -> None:
    est = EffectivenessRLS(np.ones((2, 3)), noise_std=0.1)
    before = est.to_dict()
    for args, field in ((([np.nan, 0, 0], [0, 0]), "u"), (([0, 0, 0], [0, 0, 0]), "y"),
                        (([0, 0, 0], ["x", 0]), "y"), (([1e300, 0, 0], [0, 0]), "u")):
        with pytest.raises(SampleError) as info:
            est.update(*args)
        assert info.value.field == field and isinstance(info.value, ValueError)
    assert est.to_dict() == before
    with pytest.raises(SampleError, match="x"):
        est.update([0, 0, 0], [0, 0], x=[1.0])
    for kwargs, field in (({"forgetting": 1.5}, "forgetting"), ({"forgetting": 0.0}, "forgetting"),
                          ({"penalty": 0.0}, "penalty"), ({"prior_std": -1.0}, "prior_std"),
                          ({"noise_std": [0.1, 0.0]}, "noise_std"), ({"bias": 1}, "bias")):
        with pytest.raises(OptionError) as info:
            EffectivenessRLS(np.ones((2, 3)), **kwargs)
        assert info.value.field == field
    state = est.to_dict()
    state["rls"]["R"] = [[1.0, 2.0]]
    with pytest.raises(StateError, match="R"):
        EffectivenessRLS.from_dict(state)
    with pytest.raises(StateError, match="kind"):
        EffectivenessRLS.from_dict({"kind": "other"})


def multisine(rng: np.random.Generator, m: int, n: int, dt: float, band: tuple[float, float]) -> np.ndarray:
    t = np.arange(n)[:, None, None] * dt
    f = rng.uniform(*band, (m, 5))
    ph = rng.uniform(0, 2 * np.pi, (m, 5))
    return np.sin(2 * np.pi * f * t + ph).sum(axis=2)


def test_frequency_confidence_intervals_cover_with_trim_and_bias() -> None:
    """Eq 1.12 on multisine data with a constant trim on the commands and a bias on the
    responses (the band excludes zero frequency): 95 % intervals cover at the nominal rate
    (binomial 3.5 sigma) over 24 seeded problems."""
    rng = np.random.default_rng(13)
    inside = total = 0
    for _ in range(24):
        k, m = int(rng.integers(1, 4)), int(rng.integers(2, 5))
        B, sigma = rng.normal(size=(k, m)), float(rng.uniform(0.05, 0.3))
        est = FrequencyDomainEstimator(k, m, 0.02, band=(0.2, 2.0), spacing=0.1, window=8.0, noise_std=sigma)
        U = multisine(rng, m, 300, 0.02, (0.2, 2.0)) + rng.normal(size=m) * 3
        bias = rng.normal(size=k)
        for u in U:
            est.update(u, B @ u + bias + rng.normal(size=k) * sigma)
        e = est.estimate()
        assert e.rank == m and e.samples == 300
        z = (e.theta - B) / e.std
        inside += int((np.abs(z) < Z95).sum())
        total += z.size
    share = inside / total
    assert abs(share - 0.95) <= 3.5 * np.sqrt(0.95 * 0.05 / total), (share, total)


def test_frequency_restart_follows_a_change() -> None:
    """A column changes at 10 s; with a 6 s window the estimate at 22 s rests on post-change
    data only and is within 4 standard deviations of the new column; the estimator that never
    restarts (a 1000 s window) is pulled to an average far from it (seed 1.3.2.2)."""
    rng = np.random.default_rng(14)
    dt, n = 0.02, 1100
    B = rng.normal(size=(2, 3))
    B2 = B.copy()
    B2[:, 1] *= -0.5
    U = multisine(rng, 3, n, dt, (0.2, 2.0))
    windowed = FrequencyDomainEstimator(2, 3, dt, band=(0.2, 2.0), spacing=0.1, window=6.0, noise_std=0.1)
    forever = FrequencyDomainEstimator(2, 3, dt, band=(0.2, 2.0), spacing=0.1, window=1000.0, noise_std=0.1)
    for i, u in enumerate(U):
        y = (B if i * dt < 10.0 else B2) @ u + rng.normal(size=2) * 0.1
        windowed.update(u, y)
        forever.update(u, y)
    e, f = windowed.estimate(), forever.estimate()
    assert (np.abs(e.theta - B2) <= 4 * e.std).all()
    assert np.abs(f.theta[:, 1] - B2[:, 1]).max() > 20 * f.std[:, 1].max()


def test_frequency_unexcited_effector_is_undetermined() -> None:
    """Only the first effector moves: its column is estimated, the others' deviations are
    infinite (rank 1; no value is invented for them)."""
    rng = np.random.default_rng(15)
    B = rng.normal(size=(2, 3))
    est = FrequencyDomainEstimator(2, 3, 0.02, band=(0.2, 2.0), spacing=0.1, window=8.0, noise_std=0.1)
    U = np.zeros((300, 3))
    U[:, 0] = multisine(rng, 1, 300, 0.02, (0.2, 2.0))[:, 0]
    for u in U:
        est.update(u, B @ u + rng.normal(size=2) * 0.1)
    e = est.estimate()
    assert e.rank == 1 and np.isinf(e.std[:, 1:]).all() and np.isfinite(e.std[:, 0]).all()
    assert (np.abs(e.theta[:, 0] - B[:, 0]) <= 4 * e.std[:, 0]).all()


def test_frequency_derivative_form_estimates_a_and_b() -> None:
    """Eq 1.5's form: x' = a x + b u sampled finely; [a, b] within 10 % (the finite
    transform's end term, x at the window's end, biases the seed's method by a few percent)."""
    rng = np.random.default_rng(16)
    a, b, dt = -1.5, 2.0, 0.005
    est = FrequencyDomainEstimator(1, 1, dt, band=(0.2, 2.0), spacing=0.05, window=20.0, form="derivative")
    u_all = multisine(rng, 1, 4000, dt, (0.2, 2.0))[:, 0]
    x = 0.0
    for u in u_all:
        est.update([u], [x])
        x = x + dt * (a * x + b * u)  # Euler at 200 Hz: its own error is below 1 %
    e = est.estimate()
    np.testing.assert_allclose(e.theta[0], [a, b], rtol=0.1)


def test_frequency_state_and_bad_input() -> None:
    rng = np.random.default_rng(17)
    est = FrequencyDomainEstimator(2, 2, 0.02, band=(0.2, 2.0), spacing=0.1, window=8.0)
    for _ in range(120):
        u = rng.normal(size=2)
        est.update(u, u + rng.normal(size=2) * 0.1)
    copy = FrequencyDomainEstimator.from_dict(json.loads(json.dumps(est.to_dict())))
    np.testing.assert_array_equal(copy.estimate().theta, est.estimate().theta)
    with pytest.raises(SampleError) as info:
        est.update([0.0, np.inf], [0.0, 0.0])
    assert info.value.field == "u"
    for kwargs, field in (({"band": (0.0, 1.0)}, "band"), ({"band": (0.5, 30.0)}, "band"),
                          ({"window": 1.0}, "window"), ({"form": "other"}, "form"), ({"spacing": -1.0}, "spacing")):
        with pytest.raises(OptionError) as info:
            FrequencyDomainEstimator(2, 2, 0.02, **{"band": (0.2, 2.0), **kwargs})
        assert info.value.field == field
    state = est.to_dict()
    state["banks"][0]["count"] = 10 ** 9
    with pytest.raises(StateError, match="count"):
        FrequencyDomainEstimator.from_dict(state)
