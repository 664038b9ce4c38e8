"""The stage-1 test under correlated noise (alloc.estimation.detection, ``noise_correlation``).

A rate differenced from a filtered sensor signal is correlated over a few samples; a
chi-square threshold that assumed it white alarms above its design rate, the whitened
(generalised least-squares) test at it.  The setting is validated naming the field, and it
survives the stored state."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import alloc
from alloc.estimation import FailureDetector, SampleError, StateError
from alloc.exceptions import OptionError

DT = 0.01
#: moving-average filter of the test noise: strongly correlated over four samples, like the
#: simulator's differenced sensor noise (lags +, -, -, -), stronger so a short run shows it
MA = np.array([1.0, 0.5, -0.3, -0.6, -0.3])


def ma_correlation(h: np.ndarray) -> np.ndarray:
    """Exact autocorrelation at lags 1.. of white noise filtered by ``h``."""
    full = np.correlate(h, h, mode="full")[len(h) - 1:]
    return full[1:] / full[0]


def correlated_noise(rng: np.random.Generator, n: int, k: int) -> np.ndarray:
    """``(n, k)`` unit-variance Gaussian noise with autocorrelation :func:`ma_correlation` per column."""
    w = rng.normal(size=(n + len(MA) - 1, k))
    e = np.stack([np.convolve(w[:, i], MA, mode="valid") for i in range(k)], axis=1)
    return e / math.sqrt(float(MA @ MA))


def alarm_counts(seed: int, n: int, rate: float) -> tuple[int, int, float]:
    """Stage-1 alarms of the white-noise test and of the whitened one on the same correlated
    no-failure data (smooth commands, independent windows of four samples), and the design count.
    Orthonormal columns: the four effectors' statistics are independent, so the Bonferroni bound
    over them is the rate itself (to 0.1 %), not only an upper bound."""
    rng = np.random.default_rng(seed)
    B = np.linalg.qr(rng.normal(size=(4, 4)))[0]
    p = alloc.Problem(B, -20 * np.ones(4), 20 * np.ones(4))
    t = np.arange(n)[:, None] * DT
    U = 8.0 * np.sin(2 * np.pi * rng.uniform(0.3, 1.5, 4) * t + rng.uniform(0, 6, 4))
    sigma = 0.3
    Y = U @ p.B.T + sigma * correlated_noise(rng, n, 4)
    # an isolation nearly impossible to pass: no false isolation changes the model during the count
    common = {"false_alarm_rate": rate, "window": 4 * DT, "hop": 4, "min_confidence": 1 - 1e-9}
    white = FailureDetector(p, sigma, DT, **common)
    whitened = FailureDetector(p, sigma, DT, noise_correlation=ma_correlation(MA), **common)
    for i in range(n):
        white.update(U[i], Y[i])
        whitened.update(U[i], Y[i])
    assert white.detections == [] and whitened.detections == []
    return white.alarm_count, whitened.alarm_count, rate * n * DT / 3600.0


def test_whitening_restores_the_design_false_alarm_rate() -> None:
    """30 design alarms in 4,000 samples: the whitened test within 3.5 Poisson sigma of it
    (less, by the tests skipped while an alarm is pending: at most two per alarm, so 3 % of
    them); the white-noise test on the same data 4 sigma above it (its tail is heavier)."""
    white, whitened, expected = alarm_counts(11, 4_000, 30 * 3600.0 / (4_000 * DT))
    assert abs(whitened - expected) <= 3.5 * math.sqrt(expected), (whitened, expected)
    assert white >= expected + 4.0 * math.sqrt(expected), (white, expected)


def test_white_noise_needs_no_correlation_and_changes_nothing() -> None:
    """Told zero correlation, the detector is the white-noise one exactly (same statistics)."""
    rng = np.random.default_rng(4)
    B = rng.normal(size=(3, 4))
    p = alloc.Problem(B, -20 * np.ones(4), 20 * np.ones(4))
    U = rng.uniform(-10, 10, (400, 4))
    Y = U @ B.T + 0.5 * rng.normal(size=(400, 3))
    a = FailureDetector(p, 0.5, DT, false_alarm_rate=3600.0)
    b = FailureDetector(p, 0.5, DT, false_alarm_rate=3600.0, noise_correlation=[0.0, 0.0])
    for i in range(400):
        a.update(U[i], Y[i])
        b.update(U[i], Y[i])
    assert a.alarm_count == b.alarm_count > 0
    assert np.allclose(a._stage1(a.N)[1], b._stage1(b.N)[1], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("seed", range(6))
def test_hostile_correlations_are_refused_naming_the_field(seed: int) -> None:
    """Seeded hostile ``noise_correlation``: not finite, outside (-1, 1), not a sequence, or no
    noise's autocorrelation (its window matrix not positive definite)."""
    rng = np.random.default_rng(seed)
    p = alloc.Problem(rng.normal(size=(2, 3)), -np.ones(3), np.ones(3))
    lag = float(rng.uniform(0.1, 0.9))
    hostile = [[np.nan], [np.inf, 0.0], [1.0], [-1.0 - lag], [[lag]], [], "ab", [0.95, -0.95 + lag / 100]]
    for value in hostile:
        with pytest.raises(OptionError) as info:
            FailureDetector(p, 0.5, DT, window=0.1, noise_correlation=value)
        assert info.value.field == "noise_correlation", value


def test_the_correlation_is_stored_and_old_states_load() -> None:
    rng = np.random.default_rng(5)
    p = alloc.Problem(rng.normal(size=(2, 3)), -np.ones(3), np.ones(3))
    det = FailureDetector(p, 0.5, DT, noise_correlation=[0.2, -0.1])
    for _ in range(6):
        det.update(rng.uniform(-1, 1, 3), rng.normal(size=2))
    state = json.loads(json.dumps(det.to_dict()))
    back = FailureDetector.from_dict(p, state)
    assert back.noise_correlation.tolist() == [0.2, -0.1]
    assert np.allclose(back._whiten, det._whiten)
    del state["noise_correlation"]  # a state stored before the setting: white, as it was
    assert FailureDetector.from_dict(p, state).noise_correlation is None
    state["noise_correlation"] = [2.0]
    with pytest.raises(StateError, match="noise_correlation"):
        FailureDetector.from_dict(p, state)


@pytest.mark.parametrize("corr", [None, [0.13, -0.24, -0.19]])
def test_window_statistics_are_the_streaming_ones(corr) -> None:
    """Every window's stage-1 statistics at once equal those the streaming detector computes
    sample by sample (to round-off), white or whitened; bad arrays are refused naming ``u``."""
    rng = np.random.default_rng(1)
    B = rng.normal(size=(3, 4))
    p = alloc.Problem(B, -20 * np.ones(4), 20 * np.ones(4))
    U = rng.uniform(-10, 10, (60, 4))
    Y = U @ B.T + 0.5 * rng.normal(size=(60, 3))
    det = FailureDetector(p, 0.5, 0.1, window=0.4, hop=1, noise_correlation=corr, false_alarm_rate=1e-9)
    batch = det.window_statistics(U, Y)
    streamed = []
    for i in range(60):
        det.update(U[i], Y[i])
        if i >= det.N - 1:
            streamed.append(det._stage1(det.N)[1])
    assert batch.shape == (57, 4) and np.allclose(batch, np.array(streamed), rtol=1e-12, atol=1e-12)
    with pytest.raises(SampleError) as info:
        det.window_statistics(U[:, :3], Y)
    assert info.value.field == "u"
