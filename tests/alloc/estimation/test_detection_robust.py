"""The learnt nominal model (alloc.estimation.robust): a plant that is not the model, noise with
heavy tails and slow drift are not failures; jams and losses still are.

Every world here is generated from a seed: a random effectiveness matrix, the plant's columns
scaled by factors drawn in [1 - F, 1 + F] (F = 0.2, the stated uncertainty), Student-t(4)
noise at the stated standard deviation, a smooth multisine command.  The exact detector
(``robust=None``) is the control: it must alarm in the same worlds, or the test shows nothing.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import alloc
from alloc.estimation import FailureDetector, RobustSettings, SampleError, StateError
from alloc.exceptions import OptionError

DT = 0.01
SIGMA = 0.05


def _world(seed: int, k: int = 3, m: int = 6, error: float = 0.2):
    rng = np.random.default_rng(seed)
    B = rng.normal(size=(k, m))
    problem = alloc.Problem(B, -np.ones(m), np.ones(m))
    plant = B * rng.uniform(1.0 - error, 1.0 + error, size=(1, m))
    phases = rng.uniform(0, 2 * np.pi, size=m)
    freqs = rng.uniform(0.2, 1.5, size=m)
    return rng, problem, plant, phases, freqs


def _command(t: float, phases: np.ndarray, freqs: np.ndarray) -> np.ndarray:
    return 0.8 * np.sin(2 * np.pi * freqs * t + phases)


def _t_noise(rng: np.random.Generator, k: int) -> np.ndarray:
    # Student-t with 4 degrees of freedom has variance 2: scaled to the stated level
    return rng.standard_t(4, size=k) * SIGMA / math.sqrt(2.0)


def _fly(det: FailureDetector, rng, plant, phases, freqs, n: int, start: int = 0, fail=None, first=False):
    """Fly ``n`` samples; ``fail(step, u) -> u_true`` applies a failure; returns (step, detection)s
    (``first``: up to the first one)."""
    out = []
    for step in range(start, start + n):
        u = _command(step * DT, phases, freqs)
        u_true = u if fail is None else fail(step, u.copy())
        y = plant @ u_true + _t_noise(rng, plant.shape[0])
        out += [(step, d) for d in det.update(u, y)]
        if first and out:
            break
    return out


SLOW_SEEDS = [pytest.param(s, marks=pytest.mark.slow) for s in range(2, 40)]


@pytest.mark.parametrize("seed", [0, 1, *SLOW_SEEDS])
def test_model_error_and_heavy_tails_are_not_failures(seed):
    rng, problem, plant, phases, freqs = _world(seed)
    exact = FailureDetector(problem, SIGMA, DT, window=0.1, long_window=0.5)
    assert _fly(exact, rng, plant, phases, freqs, 6000, first=True), "the control: the exact detector must alarm in this world"
    rng, problem, plant, phases, freqs = _world(seed)
    learnt = FailureDetector(problem, SIGMA, DT, window=0.1, long_window=0.5, robust=True)
    assert _fly(learnt, rng, plant, phases, freqs, 6000) == []


@pytest.mark.parametrize("seed", [0, 1, *SLOW_SEEDS])
def test_a_jam_is_still_found_at_once_in_that_world(seed):
    rng, problem, plant, phases, freqs = _world(seed)
    det = FailureDetector(problem, SIGMA, DT, window=0.1, long_window=0.5, robust=True)
    assert _fly(det, rng, plant, phases, freqs, 2000) == []
    j = seed % problem.m

    def jam(step, u):
        u[j] = 0.3
        return u

    found = _fly(det, rng, plant, phases, freqs, 300, start=2000, fail=jam)
    assert found, "no detection of a jam within 3 s"
    step, first = found[0]
    assert first.event.effector == problem.names[j]
    assert first.event.kind.value in ("jam", "hardover", "float", "limits")
    assert (step - 2000) * DT < 0.5


@pytest.mark.parametrize("seed", [0, *SLOW_SEEDS])
def test_a_loss_of_a_third_is_found_after_learning(seed):
    rng, problem, plant, phases, freqs = _world(seed)
    det = FailureDetector(problem, SIGMA, DT, window=0.1, long_window=0.5, robust=True)
    assert _fly(det, rng, plant, phases, freqs, 6000) == []
    j = (seed + 1) % problem.m

    def loss(step, u):
        u[j] *= 0.67
        return u

    found = _fly(det, rng, plant, phases, freqs, 200, start=6000, fail=loss)
    assert found, "a loss of a third of an effector's effectiveness not found within 2 s"
    assert found[0][1].event.effector == problem.names[j]


@pytest.mark.slow
def test_slow_drift_is_absorbed_not_declared():
    rng, problem, plant, phases, freqs = _world(7)
    det = FailureDetector(problem, SIGMA, DT, window=0.1, long_window=0.5, robust=True)

    def drift(step, u):  # effector 0 loses 20 % over 200 s: the aircraft ageing, not a failure
        u[0] *= 1.0 - 0.2 * min(1.0, step * DT / 200.0)
        return u

    assert _fly(det, rng, plant, phases, freqs, 25000, fail=drift) == []


def test_state_round_trip_continues_bit_for_bit():
    rng, problem, plant, phases, freqs = _world(3)
    det = FailureDetector(problem, SIGMA, DT, window=0.1, long_window=0.5, robust=True,
                          effector_lag=np.full(problem.m, 0.05))
    _fly(det, rng, plant, phases, freqs, 700)
    state = det.to_dict()
    twin = FailureDetector.from_dict(problem, state)
    assert twin.to_dict() == state
    a = np.random.default_rng(5)
    b = np.random.default_rng(5)
    out_a = _fly(det, a, plant, phases, freqs, 300, start=700)
    out_b = _fly(twin, b, plant, phases, freqs, 300, start=700)
    assert [(s, d.to_dict()) for s, d in out_a] == [(s, d.to_dict()) for s, d in out_b]
    assert det.to_dict() == twin.to_dict()


@pytest.mark.parametrize("robust, field", [
    ({"huber": -1.0}, "robust/huber"), ({"model_memory": 0.0}, "robust/model_memory"),
    ({"lags": 0}, "robust/lags"), ({"colour": 1}, "robust"), ("yes", "robust"),
    ({"model_uncertainty": float("nan")}, "robust/model_uncertainty"),
])
def test_bad_settings_name_their_field(robust, field):
    problem = alloc.Problem(np.eye(2), -np.ones(2), np.ones(2))
    with pytest.raises(OptionError) as info:
        FailureDetector(problem, SIGMA, DT, robust=robust)
    assert str(info.value).startswith(field)


def test_lags_need_a_robust_detector_and_the_cost_is_priced():
    problem = alloc.Problem(np.eye(2), -np.ones(2), np.ones(2))
    with pytest.raises(OptionError, match="^effector_lag"):
        FailureDetector(problem, SIGMA, DT, effector_lag=0.05)
    big = alloc.Problem(np.ones((6, 300)), -np.ones(300), np.ones(300))
    with pytest.raises(OptionError, match="^robust: .*flops"):
        FailureDetector(big, SIGMA, DT, robust=True, effector_lag=0.05)


def test_stored_state_is_checked():
    rng, problem, plant, phases, freqs = _world(1)
    det = FailureDetector(problem, SIGMA, DT, robust=RobustSettings(lags=4))
    _fly(det, rng, plant, phases, freqs, 50)
    state = det.to_dict()
    for key, bad in (("J", "x"), ("sum_abs", [-1.0] * problem.k), ("weight", 1e9), ("sum_cl", [float("nan")] * 4)):
        broken = {**state, "robust": {**state["robust"], key: bad}}
        with pytest.raises(StateError):
            FailureDetector.from_dict(problem, broken)


@pytest.mark.parametrize("seed", range(6))
def test_hostile_samples_never_break_it(seed):
    """Huge, tiny, constant and jumping samples: a SampleError or an answer, and a finite state."""
    rng = np.random.default_rng(1000 + seed)
    k, m = int(rng.integers(1, 5)), int(rng.integers(1, 7))
    B = rng.normal(size=(k, m)) * 10.0 ** rng.uniform(-6, 6)
    problem = alloc.Problem(B, -np.ones(m), np.ones(m))
    det = FailureDetector(problem, 10.0 ** rng.uniform(-4, 2), 0.01, window=0.04, long_window=0.2, robust=True,
                          effector_lag=rng.uniform(0, 0.2, size=m))
    for _ in range(600):
        mode = rng.integers(5)
        u = rng.uniform(-1, 1, size=m) if mode else np.zeros(m)
        scale = 10.0 ** rng.uniform(-300, 60) if mode == 1 else 1.0
        y = rng.standard_cauchy(size=k) * scale
        try:
            det.update(u, y)
        except SampleError as exc:
            assert exc.field in ("y", "u", "position")
    state = det.to_dict()
    assert np.isfinite(np.asarray(state["robust"]["J"])).all()
    assert np.isfinite(np.asarray(state["robust"]["h"])).all()
    assert all(0.0 <= d.confidence <= 1.0 for d in det.detections)
