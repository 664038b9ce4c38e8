"""Unit tests of the simulator building blocks (sim.blocks, sim.result, registry)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy import signal

from sim.blocks import (
    ActuatorBank,
    ActuatorFailure,
    ActuatorSpec,
    DelayLine,
    DiscreteLTI,
    HedgeTerm,
    band_limited_noise,
    hedge_system,
    observer_gain,
    smc_control,
    sum_of_sines,
)
from sim.result import SimResult
from sim.scenarios import get_scenario, scenarios

DT = 0.0005


def test_discrete_lti_step_response_matches_scipy():
    lti = DiscreteLTI.from_tf([100.0], [1.0, 20.0, 100.0], DT)
    y = np.array([lti.step(np.array([1.0]))[0] for _ in range(2001)])
    t = np.arange(2001) * DT
    _, y_ref = signal.step(([100.0], [1.0, 20.0, 100.0]), T=t)
    assert np.max(np.abs(y - y_ref)) < 1e-3


def test_actuator_two_real_poles_matches_linear_response_when_unlimited():
    spec = ActuatorSpec.two_real_poles("e", 40.0, 100.0, -1e9, 1e9, 1e9)  # seed Table 4-5 form
    bank = ActuatorBank([spec], DT)
    y = np.array([bank.step(np.array([1.0]))[0] for _ in range(400)])
    _, y_ref = signal.step(([4000.0], [1.0, 140.0, 4000.0]), T=np.arange(0, 401) * DT)
    assert np.max(np.abs(y - y_ref[1:])) < 1e-4  # Heun (ODE2) at dt = 0.5 ms
    assert spec.wn == pytest.approx(np.sqrt(4000.0))  # 63 rad/s, seed section 4.7


def test_actuator_rate_and_position_limits():
    bank = ActuatorBank([ActuatorSpec.second_order("e", 30.0, 0.707, -5.0, 5.0, 10.0)], DT)
    pos, rates = [], []
    for _ in range(4000):
        pos.append(bank.step(np.array([20.0]))[0])
        rates.append(bank.rate_out[0])
    assert max(np.abs(rates)) <= 10.0 + 1e-9
    assert max(pos) == pytest.approx(5.0)
    # Rate-limited ramp: 1 s after start it cannot exceed 10 deg.
    assert pos[1999] <= 5.0


def test_actuator_failures_jam_hardover_bandwidth():
    specs = [ActuatorSpec.two_real_poles(f"e{i}", 40.0, 100.0, -30.0, 30.0, 150.0) for i in range(3)]
    bank = ActuatorBank(specs, DT)
    bank.apply_failure(ActuatorFailure(0, "jam", position=5.0))
    bank.apply_failure(ActuatorFailure(1, "hardover", position=-30.0))
    bank.apply_failure(ActuatorFailure(2, "bandwidth", wn=10.0))
    for _ in range(4000):
        u = bank.step(np.array([1.0, 1.0, 1.0]))
    assert u[0] == 5.0
    assert u[1] == pytest.approx(-30.0, abs=1e-6)
    assert bank.specs[2].wn == pytest.approx(10.0)
    assert bank.specs[2].c1 / (2 * bank.specs[2].wn) == pytest.approx(140.0 / (2 * np.sqrt(4000.0)))


def test_delay_line_per_component():
    d = DelayLine(2, DT, np.array([0.0, 0.002]))  # 0 and 4 steps
    outs = [d.push(np.array([k, k], dtype=float)) for k in range(10)]
    assert [o[0] for o in outs] == list(range(10))
    assert [o[1] for o in outs][4:] == [0, 1, 2, 3, 4, 5]


def test_smc_control_boundary_layer_and_sign():
    s = np.array([-2.0, 0.05, 3.0])
    assert np.allclose(smc_control(s, np.array([10.0, 10.0, 10.0]), np.array([0.1, 0.1, 0.1])), [-10, 5, 10])
    assert np.allclose(smc_control(s, np.ones(3) * 2, None), [-2, 2, 2])


def test_observer_gain_places_poles():
    A = np.array([[-0.5088, 0.9940], [-1.1310, -0.2804]])  # seed Eq 4.9
    C = np.eye(2)
    G = observer_gain(A, C, (-40.0, -41.0))
    assert np.allclose(np.sort(np.linalg.eigvals(A - G @ C).real), [-41.0, -40.0])


def test_hedge_system_is_filter_times_plant_times_gain():
    # seed section 4.5 "fast" hedge: -5 (s/(s+100)) (100/(s^2+20s+100))
    A, B, C, D = hedge_system([HedgeTerm(0, 0, a_f=100.0, a_h=20.0, b_h=100.0)], 1, [-5.0])
    w = np.array([1.0, 10.0, 100.0])
    _, h = signal.freqresp((A, B, C, D), w)
    s = 1j * w
    expected = -5.0 * s / (s + 100) * 100 / (s**2 + 20 * s + 100)
    assert np.allclose(h, expected)


def test_noise_rms_matches_seed():
    # seed section 4.6: gain 0.1414 -> RMS about 0.07; gain 0.0707 -> about 0.035
    rng = np.random.default_rng(1)
    n = band_limited_noise(400_000, DT, np.array([0.1414, 0.0707]), rng)
    rms = np.sqrt(np.mean(n[20_000:] ** 2, axis=0))
    assert rms == pytest.approx([0.07, 0.035], rel=0.1)


def test_sum_of_sines_starts_at_zero_and_is_reproducible():
    t = np.arange(0, 10, DT)
    c = sum_of_sines(t, 5.0)
    assert c[0] == 0.0
    # seed Table 4-2 amplitude sum bounds |c| <= xi * 3.98
    assert np.max(np.abs(c)) <= 5.0 * 3.98


def _result(failure_time):
    t = np.arange(0.0, 4.0, 1.0)
    ref = np.zeros((4, 1))
    out = np.array([[1.0], [1.0], [3.0], [3.0]])
    return SimResult(
        "x", "pinv", "f" if failure_time else None, t, ["q"], ref, out, ref,
        effectors=np.array([[1.0], [0.0], [1.0], [0.5]]), effector_limits=(np.array([-1.0]), np.array([1.0])),
        failure_time=failure_time,
    )


def test_summary_splits_at_failure_and_writes_json(tmp_path):
    s = _result(2.0).summary()
    assert s["channels"]["q"]["rms_before"] == pytest.approx(1.0)
    assert s["channels"]["q"]["rms_after"] == pytest.approx(3.0)
    assert s["time_in_position_saturation"] == pytest.approx(2.0)
    path = tmp_path / "s.json"
    _result(None).to_json(path)
    data = json.loads(path.read_text())
    assert data["channels"]["q"]["rms_after"] is None
    assert data["diverged"] is False


def test_registry_lists_all_scenarios_and_rejects_unknown():
    assert {"ice", "harv_lon", "harv_latdir"} <= set(scenarios())
    assert get_scenario("ice").default_duration == 40.0
    with pytest.raises(KeyError, match="known scenarios"):
        get_scenario("nope")
