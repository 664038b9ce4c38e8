"""The seed's classic single-input SMC demonstrations, measured (seed chapters 2 and 3).

Each test states what the seed shows, what this simulator measures, and
asserts the measurement.  Where the seed's result is not reproduced the test
says so and an ``xfail(strict=True)`` test records the seed's claim with the
measured numbers, so a future change that does reproduce it is noticed.
"""

from __future__ import annotations

import numpy as np
import pytest

from sim.scenarios import get_scenario
from sim.scenarios.f16 import DELTA_MAX, RATE_MAX, SEED_CASES
from sim.scenarios.pendulum import ACTUATOR_CASES, NOMINAL, linear_model, smc_design

# ------------------------------------------------------------------ pendulum


@pytest.fixture(scope="module")
def pendulum_runs():
    """Seed section 3.1: u = 50 sat(sigma/0.1), x(0) = -1, theta(0) = -10 deg, linear model."""
    run = get_scenario("pendulum")
    return {name: run(actuator_bandwidth=a, duration=10.0) for name, a in ACTUATOR_CASES.items()}


def _window(res, t0, t1):
    return (res.t >= t0) & (res.t < t1)


def _rms(x):
    return float(np.sqrt(np.mean(x**2)))


def _sigma_zero_crossings(res, t0, t1):
    s = res.extra["sigma"][_window(res, t0, t1)]
    return int(np.count_nonzero(np.diff(np.sign(s)) != 0))


def test_pendulum_smc_regulates_without_actuator(pendulum_runs):
    """Seed Fig 3-1: "excellent regulation of the states".

    Measured: RMS of x and theta over 5-10 s about 2e-6; sigma crosses zero
    at most twice in 0.5-1 s (the state slides on the surface).
    """
    res = pendulum_runs["none"]
    assert not res.diverged and res.duration == pytest.approx(10.0)
    late = _window(res, 5.0, 10.0)
    assert _rms(res.output[late, 0]) < 1e-4
    assert _rms(res.output[late, 1]) < 1e-4
    assert _sigma_zero_crossings(res, 0.5, 1.0) <= 2


def test_pendulum_smc_oscillates_with_20_rad_s_actuator(pendulum_runs):
    """Seed Fig 3-2, actuator 20/(s+20): "Already, undesired oscillations appear."

    Measured: after the reaching phase the force swings over 40 N peak to peak
    in 0.5-1 s with sigma crossing zero 13 times (a ~13 Hz oscillation; the
    no-actuator run crosses zero at most twice), so the oscillation is there.
    It is *transient*, not a sustained limit cycle: it dies out by about 2 s
    and x, theta are regulated to ~1e-6 RMS over 5-10 s.  Inside the boundary
    layer the loop is linear, u = 500 sigma through the actuator, and its
    poles are stable (-6.96 +- 93.8j rad/s, damping ratio 0.074, checked
    below), which is why the oscillation decays.  The seed's figure cannot be
    seen in the text, so "sustained" could not be checked against it.
    """
    res = pendulum_runs["actuator_20"]
    assert not res.diverged
    mid = _window(res, 0.5, 1.0)
    assert np.ptp(res.effectors[mid, 0]) > 40.0
    assert _sigma_zero_crossings(res, 0.5, 1.0) >= 10
    late = _window(res, 5.0, 10.0)
    assert _rms(res.output[late, 0]) < 1e-4
    assert _rms(res.output[late, 1]) < 1e-4
    poles = _boundary_layer_loop_poles(20.0)
    fast = poles[np.argmax(np.abs(poles.imag))]
    assert np.all(poles.real < 0)
    assert -fast.real / abs(fast) < 0.1  # lightly damped


def _boundary_layer_loop_poles(a: float) -> np.ndarray:
    """Poles of plant + actuator a/(s+a) + linear law u = (50/0.1) S z (inside the layer)."""
    A, B = linear_model(NOMINAL)
    S = smc_design().S
    Acl = np.zeros((5, 5))
    Acl[:4, :4], Acl[:4, 4] = A, B[:, 0]
    Acl[4, :4], Acl[4, 4] = a * (50.0 / 0.1) * S, -a
    return np.linalg.eigvals(Acl)


def test_pendulum_smc_diverges_with_13_rad_s_actuator(pendulum_runs):
    """Seed Fig 3-3, actuator 13/(s+13): "it drives both states unstable".

    Measured: reproduced.  The pendulum passes 90 deg (the scenario's
    divergence bound) at 1.23 s with the cart 1.9 m off.  The loop inside
    the boundary layer is still linearly stable (poles -3.45 +- 75.8j), so the
    loss of control is a large-signal effect: the slow actuator lets the
    saturated force overshoot the surface and the switching term cannot pull
    the state back.
    """
    res = pendulum_runs["actuator_13"]
    assert res.diverged
    assert res.duration < 2.0
    assert abs(res.output[-1, 1]) > np.pi / 2
    assert np.max(np.abs(res.output[:, 0])) > 1.5  # x(0) = -1: the cart runs away too
    assert np.all(_boundary_layer_loop_poles(13.0).real < 0)


def test_pendulum_matched_disturbance_rejected_by_smc_not_lqr():
    """Seed Figs 2-19/2-20: nonlinear model, white noise plus a bias of 10 on the force at 5 s.

    Seed: LQR shows "a noticeable bias" of the cart after 5 s; SMC
    ``u = U_eq + 50 sat(sigma/0.1)`` keeps regulation "very good".  Measured
    (noise std 1 N, seed 3; the seed does not print its noise level): mean
    cart position over 8-10 s is -0.317 m for LQR (10 N / K_x = 10/31.6) and
    -0.0063 m for SMC (the boundary-layer offset sigma = 10/500 over S_x).
    """
    run = get_scenario("pendulum")
    kw = dict(model="nonlinear", disturbance_bias=10.0, noise_std=1.0, seed=3)
    lqr = run(controller="lqr", **kw)
    smc = run(controller="smc", equivalent_control=True, rho=50.0, epsilon=0.1, **kw)
    late_l, late_s = lqr.t >= 8.0, smc.t >= 8.0
    assert not lqr.diverged and not smc.diverged
    assert lqr.output[late_l, 0].mean() == pytest.approx(-10.0 / 31.62, abs=0.02)
    assert abs(smc.output[late_s, 0].mean()) < 0.02


def test_pendulum_equivalent_control_holds_the_surface_only_on_the_design_model():
    """Seed Fig 2-15: u = U_eq after a 0.15 s reaching phase keeps sliding on the
    linear model; "When this same control is applied to the non-linear
    simulation ... stable control is lost."

    Measured: linear model |sigma| <= 1e-9 after 1 s.  Nonlinear model: the
    state leaves the surface (|sigma| up to 0.37 after 1 s) and |theta| or |x|
    is still 0.11 after 5 s; within 10 s it does not diverge, so "lost" is
    reproduced as "no longer regulated", not as divergence.
    """
    run = get_scenario("pendulum")
    kw = dict(controller="smc", equivalent_control=True, switching_until=0.15, rho=50.0, epsilon=0.1)
    lin = run(model="linear", **kw)
    non = run(model="nonlinear", **kw)
    assert np.max(np.abs(lin.extra["sigma"][lin.t > 1.0])) < 1e-6
    assert np.max(np.abs(non.extra["sigma"][non.t > 1.0])) > 0.1
    assert np.max(np.abs(non.output[non.t > 5.0])) > 0.05
    assert np.max(np.abs(lin.output[lin.t > 5.0])) < 1e-3



def test_pendulum_plant_change_switches_the_plant_at_failure_time():
    """Seed section 2.2 table, "Value after 'Failure'" (masses x10, L x2, friction x4-10).

    The seed shows this failure only for the two-input decoupled SMC (Figs
    2-21..2-25, not implemented here).  Measured for the single-input
    regulator of section 3.1: tracking is unchanged up to 3 s and the
    pendulum falls (passes 90 deg) at 7.6 s; LQR falls too, at 8.3 s.
    """
    run = get_scenario("pendulum")
    healthy, failed = run(duration=10.0), run(failure="plant_change", duration=10.0)
    before = failed.t < 3.0
    np.testing.assert_array_equal(failed.output[before], healthy.output[: np.count_nonzero(before)])
    assert failed.failure_time == 3.0 and failed.diverged and failed.duration > 3.0


def test_pendulum_rejects_unknown_options():
    run = get_scenario("pendulum")
    with pytest.raises(ValueError, match="controller"):
        run(controller="pid", duration=0.01)
    with pytest.raises(ValueError, match="failure"):
        run(failure="engine_out", duration=0.01)
    with pytest.raises(TypeError):
        run(gain=3.0, duration=0.01)


# ------------------------------------------------------------------ F-16


@pytest.fixture(scope="module")
def f16_runs():
    run = get_scenario("f16")
    names = ["fig_3_7", "fig_3_8", "fig_3_9", "fig_3_10", "fig_3_11"]
    return {name: run(**SEED_CASES[name]) for name in names}


@pytest.mark.parametrize("name", ["fig_3_7", "fig_3_8"])
def test_f16_tracks_without_limits(f16_runs, name):
    """Seed Figs 3-7/3-8: no limits, with and without the 5 s tail loss: "excellent tracking".

    Measured: max |q_r - q| 0.0093 rad/s before and 0.0175 after the failure
    (pulses 0.1 rad/s give |q_r| up to 0.25 rad/s).
    """
    res = f16_runs[name]
    assert not res.diverged
    assert np.max(np.abs(res.error)) < 0.02
    assert np.max(np.abs(res.reference)) > 0.2


def test_f16_small_pulses_rate_limit_but_no_position_limit(f16_runs):
    """Seed Fig 3-9: limits on, 0.1 rad/s pulses: "some minor rate limiting occurs,
    but the position limit is never reached".

    Measured: reproduced; 0.11 s at the 10 rad/s rate limit, max |delta|
    0.251 rad < 0.37, max error 0.0175 rad/s.
    """
    res = f16_runs["fig_3_9"]
    assert not res.diverged
    assert res.time_in_rate_saturation > 0.0
    assert res.time_in_position_saturation == 0.0
    assert np.max(np.abs(res.effectors)) < DELTA_MAX
    assert np.max(np.abs(res.error)) < 0.02


def test_f16_static_layer_hits_position_limit_with_large_pulses(f16_runs):
    """Seed Fig 3-10: static boundary layer, 0.2 rad/s pulses, tail loss at 5 s.

    What this simulator measures: the elevator reaches the 0.37 rad position
    limit (0.22 s in position saturation, 0.20 s at the rate limit) and the
    error grows from 0.035 rad/s (max before the failure) to 0.087 rad/s (max
    after), but control is *kept*: no divergence, and the error decays to
    0.0032 rad/s over 11.5-12 s (under a tenth of its peak; run to 30 s it
    stays below 0.0012 after 12 s).  The seed's loss of control is therefore
    not reproduced; see :func:`test_f16_static_layer_loses_control_as_in_seed`.
    Also measured (not asserted): raising the pulses, static and dynamic
    layers both keep control up to 0.4 rad/s and both diverge at 0.5 rad/s;
    saturating the actuator output instead of clamping its integrator, or
    saturating delta_c, does not change the outcome at 0.2 rad/s.
    """
    res = f16_runs["fig_3_10"]
    assert res.time_in_position_saturation > 0.1
    assert np.max(np.abs(res.effectors)) == pytest.approx(DELTA_MAX)
    assert not res.diverged
    summary = res.summary()["channels"]["q"]
    assert summary["max_after"] > 2 * summary["max_before"]
    assert np.max(np.abs(res.error[res.t > 11.5])) < 0.1 * summary["max_after"]


@pytest.mark.xfail(
    strict=True,
    reason="seed Fig 3-10 says the static-layer SMC 'becomes unstable' once the elevator hits "
    "its position limit; measured: limit hit for 0.22 s, max error 0.087 rad/s, no divergence",
)
def test_f16_static_layer_loses_control_as_in_seed(f16_runs):
    """Seed Fig 3-10: "Once the actuator hits the position limits, the system no
    longer tracks the input and it becomes unstable."  Not reproduced."""
    assert f16_runs["fig_3_10"].diverged


def test_f16_dynamic_layer_keeps_control_within_limits(f16_runs):
    """Seed Fig 3-11: the dynamic boundary layer (Eqs 3.6-3.8) "keeps the system
    stable ... Tracking performance is degraded somewhat".

    Measured: reproduced.  The layer widens to eps = 21 (from 0.1); the
    elevator never reaches its position limit (max 0.364 rad) and the rate
    demand stays at or below 7.4 rad/s (Eq 3.7 at delta = 0 binds before
    Eq 3.8's 10 rad/s); |sigma| <= eps throughout (Eq 3.6).  Max error after
    the failure 0.156 rad/s, against 0.087 for the static layer, which here
    keeps control too (see above): the dynamic layer trades tracking for
    never touching a limit.
    """
    dyn, stat = f16_runs["fig_3_11"], f16_runs["fig_3_10"]
    assert not dyn.diverged
    assert dyn.time_in_position_saturation == 0.0
    assert np.max(np.abs(dyn.effectors)) < DELTA_MAX
    assert np.max(np.abs(dyn.pseudo)) <= RATE_MAX + 1e-9
    assert np.all(np.abs(dyn.extra["sigma"]) <= dyn.extra["epsilon"] + 1e-12)
    assert np.max(dyn.extra["epsilon"]) > 10.0
    assert np.max(stat.extra["epsilon"]) == pytest.approx(0.1)
    assert dyn.summary()["channels"]["q"]["max_after"] < 0.2



@pytest.fixture(scope="module")
def f16_slow_actuator_runs():
    run = get_scenario("f16")
    return {name: run(**SEED_CASES[name]) for name in ("fig_3_12", "fig_3_13")}


def test_f16_dynamic_layer_with_known_slow_actuator(f16_slow_actuator_runs, f16_runs):
    """Seed Fig 3-12: actuator and Eq 3.7 design bandwidth both halved to 10 rad/s:
    "Results are comparable to the last case."

    Measured: reproduced; no divergence, no position saturation, max error
    after the failure 0.208 rad/s against 0.156 with the 20 rad/s actuator.
    """
    res = f16_slow_actuator_runs["fig_3_12"]
    assert not res.diverged
    assert res.time_in_position_saturation == 0.0
    ratio = res.summary()["channels"]["q"]["max_after"] / f16_runs["fig_3_11"].summary()["channels"]["q"]["max_after"]
    assert 0.5 < ratio < 2.0


def test_f16_dynamic_layer_with_unknown_slow_actuator_as_measured(f16_slow_actuator_runs):
    """Seed Fig 3-13: true actuator 10 rad/s, Eq 3.7 still designed for 20: "The system fails."

    Measured: not reproduced.  In this model a slower true actuator moves
    ``a_true / a_design = 1/2`` as fast as the postfilter assumes, so it
    stays further inside the limits (max |delta| 0.351 rad, max rate 3.7
    rad/s) and tracking is the same as Fig 3-12 (max error after the failure
    0.207 rad/s).  See the strict xfail below.
    """
    slow, known = f16_slow_actuator_runs["fig_3_13"], f16_slow_actuator_runs["fig_3_12"]
    assert not slow.diverged
    assert np.max(np.abs(slow.effectors)) < DELTA_MAX
    assert slow.summary()["channels"]["q"]["max_after"] == pytest.approx(known.summary()["channels"]["q"]["max_after"], rel=0.05)


@pytest.mark.xfail(
    strict=True,
    reason="seed Fig 3-13 says the dynamic layer fails with an unknown slow (10 rad/s) actuator; "
    "measured: no divergence, max error after failure 0.207 rad/s (same as the known case)",
)
def test_f16_unknown_slow_actuator_fails_as_in_seed(f16_slow_actuator_runs):
    """Seed Fig 3-13: "The system fails."  Not reproduced."""
    assert f16_slow_actuator_runs["fig_3_13"].diverged


def test_f16_rejects_unknown_options():
    run = get_scenario("f16")
    with pytest.raises(ValueError, match="failure"):
        run(failure="wing_loss", duration=0.01)
    with pytest.raises(ValueError, match="boundary_layer"):
        run(boundary_layer="adaptive", duration=0.01)
    with pytest.raises(TypeError):
        run(not_an_option=1, duration=0.01)


# ------------------------------------------------------------------ DC-8


@pytest.fixture(scope="module")
def dc8_runs():
    """Seed section 3.2.2 with the failure moved from 40 s to 10 s to keep the test short."""
    run = get_scenario("dc8")
    kw = dict(duration=30.0, failure_time=10.0)
    return run(**kw), run(failure="aileron_and_stability", **kw)


def test_dc8_tracking_is_invariant_to_the_failure(dc8_runs):
    """Seed Fig 3-18: "there is no difference in the tracking performance between
    this case and the un-failed case" (A rows halved, aileron power and
    aileron actuator bandwidth x0.2).

    Measured (0.2 rad square-wave bank command, period 20 s; the seed's
    command is not printed): reproduced.  After the failure the bank angle
    differs from the healthy run by at most 1.9e-4 rad and the yaw rate by
    4.3e-4 rad/s, while the aileron works 5.5 times harder (max 0.670 rad
    against 0.121).  The bank error 0.1 s before each command step is
    1e-4 to 2e-4 rad in both runs.
    """
    healthy, failed = dc8_runs
    assert not healthy.diverged and not failed.diverged
    after = healthy.t >= 10.0
    assert np.max(np.abs(failed.output[after, 0] - healthy.output[after, 0])) < 1e-3
    assert np.max(np.abs(failed.output[after, 1] - healthy.output[after, 1])) < 1e-3
    assert np.max(np.abs(failed.effectors[after, 0])) > 4 * np.max(np.abs(healthy.effectors[after, 0]))
    for tt in (9.9, 19.9, 29.9):
        k = np.searchsorted(healthy.t, tt)
        assert abs(healthy.error[k, 0]) < 1e-3 and abs(failed.error[k, 0]) < 1e-3


def test_dc8_control_action_is_unrealistic(dc8_runs):
    """Seed section 3.2.2: "the required control action is completely unrealistic".

    Measured: the rudder reaches 0.99 rad (57 deg) and 16 rad/s in the healthy
    run for 0.2 rad bank steps.
    """
    healthy, _ = dc8_runs
    assert np.max(np.abs(healthy.effectors[:, 1])) > 0.5
    assert np.max(np.abs(healthy.effector_rates[:, 1])) > 10.0
