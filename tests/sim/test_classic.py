"""The seed's classic single-input SMC demonstrations, measured (seed chapters 2 and 3),
and the one runner that flies them (:mod:`sim.scenarios.classic`).

Each test states what the seed shows, what this simulator measures, and
asserts the measurement.  Where the seed's result is not reproduced the test
says so and an ``xfail(strict=True)`` test records the seed's claim with the
measured numbers, so a future change that does reproduce it is noticed.
"""

from __future__ import annotations

import inspect
import math

import numpy as np
import pytest

import sim.scenarios
from sim.blocks import DEFAULT_DT
from sim.result import SimResult
from sim.scenarios import get_scenario
from sim.scenarios.classic import DEFAULT_DT as CLASSIC_DT
from sim.scenarios.classic import classic_scenario, run_classic
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


# ------------------------------------------------------------------ the classic runner and registration


@pytest.mark.parametrize(
    ("scenario", "options", "error", "match"),
    [
        ("pendulum", {"controller": "pid"}, ValueError, "controller"),
        ("pendulum", {"model": "quadratic"}, ValueError, "model"),
        ("pendulum", {"epsilon": 0.0}, ValueError, "epsilon"),
        ("pendulum", {"actuator_bandwidth": -1.0}, ValueError, "actuator_bandwidth"),
        ("pendulum", {"failure": "engine_out"}, ValueError, "engine_out"),
        ("pendulum", {"gain": 3.0}, TypeError, "gain"),
        ("f16", {"failure": "wing_loss"}, ValueError, "wing_loss"),
        ("f16", {"boundary_layer": "adaptive"}, ValueError, "boundary_layer"),
        ("f16", {"design_bandwidth": 0.0}, ValueError, "bandwidth"),
        ("f16", {"not_an_option": 1}, TypeError, "not_an_option"),
        ("dc8", {"failure": "engine_out"}, ValueError, "aileron_and_stability"),  # the message lists the known
        ("dc8", {"gain": 3.0}, TypeError, "gain"),
        ("dc8", {"dt": 0.0}, ValueError, "dt"),
        ("f16", {"dt": float("nan")}, ValueError, "dt"),
        ("pendulum", {"duration": -1.0}, ValueError, "duration"),
        ("pendulum", {"duration": float("inf")}, ValueError, "duration"),
    ],
)
def test_classic_scenarios_reject_bad_options(scenario, options, error, match):
    with pytest.raises(error, match=match):
        get_scenario(scenario)(**{"duration": 0.01, **options})


@pytest.mark.parametrize("scenario", ["pendulum", "f16", "dc8"])
def test_classic_scenarios_take_and_ignore_the_registry_arguments(scenario):
    """method, allocator_knows_failure and progress change nothing; the default duration is the registry's."""
    run = get_scenario(scenario)
    plain = run(duration=0.05)
    other = run(duration=0.05, method="qp", allocator_knows_failure=True, progress=True)
    assert plain.method is None and other.method is None
    np.testing.assert_array_equal(plain.output, other.output)
    np.testing.assert_array_equal(plain.effectors, other.effectors)
    assert plain.t.size == round(0.05 / DEFAULT_DT) + 1
    params = list(inspect.signature(run).parameters)
    assert params[:7] == ["method", "failure", "duration", "seed", "dt", "allocator_knows_failure", "progress"]
    assert inspect.signature(run).parameters["dt"].default == DEFAULT_DT
    assert run.default_method is None and run.default_duration == {"pendulum": 10.0, "f16": 12.0, "dc8": 80.0}[scenario]


def test_classic_default_step_is_the_engines():
    """classic.DEFAULT_DT is a copy (sim.blocks loads numba); they must not drift apart."""
    assert CLASSIC_DT == DEFAULT_DT == 0.0005


def test_run_classic_is_heun_with_held_inputs_and_records_every_step():
    """x' = -a x + w with w held per step: Heun's step multiplies x by 1 - h a + (h a)^2 / 2 and adds
    h w (1 - h a / 2), exactly the trapezoid of the Euler-predicted slopes."""
    a, dt = 3.0, 0.01
    held_at: list[float] = []

    def hold(t):
        held_at.append(float(t))
        return 0.5 if t >= 0.1 else 0.0

    def derivative(t, x, w):
        return -a * x + w, (w, 2.0 * x[0])

    run = run_classic(derivative, np.array([1.0]), duration=0.2, dt=dt, n_signals=2, outputs=[0], output_bound=10.0,
                      hold=hold)
    assert not run.diverged and run.t.size == 21
    np.testing.assert_array_equal(run.t, np.arange(21) * dt)
    assert held_at == pytest.approx(list(run.t))  # once per step, never at the corrector's t + dt
    x = [1.0]
    for k in range(20):
        w = 0.5 if k * dt >= 0.1 else 0.0
        x.append(x[-1] * (1 - dt * a + (dt * a) ** 2 / 2) + dt * w * (1 - dt * a / 2))
    np.testing.assert_allclose(run.states[:, 0], x, rtol=1e-13)
    np.testing.assert_allclose(run.rates[:, 0], -a * run.states[:, 0] + run.signals[:, 0], rtol=1e-13)
    np.testing.assert_array_equal(run.signals[:, 1], 2.0 * run.states[:, 0])


def test_run_classic_stops_at_the_first_sample_outside_the_bound_and_applies_after_step():
    """x' = x from 1 leaves |x| <= 2 at t = ln 2 (Heun's error is O(dt^2)); a clamp on x[1] holds it."""

    def clamp(x):
        x[1] = min(x[1], 0.25)

    run = run_classic(lambda t, x, held: (np.array([x[0], 1.0]), ()), np.array([1.0, 0.0]), duration=5.0, dt=0.001,
                      n_signals=0, outputs=slice(0, 1), output_bound=2.0, after_step=clamp)
    assert run.diverged
    assert run.states[-1, 0] > 2.0 and np.all(run.states[:-1, 0] <= 2.0)
    assert run.t[-1] == pytest.approx(math.log(2.0), abs=2e-3)
    assert np.max(run.states[:, 1]) == 0.25 and run.states[-1, 1] == 0.25
    assert run.signals.shape == (run.t.size, 0)


def test_add_a_classic_scenario_walkthrough(monkeypatch):
    """docs/ARCHITECTURE.md "Add a scenario", classic branch: a PD-regulated double integrator
    x'' = g u, u = -2 x - 3 x' (poles -1, -2, so x = 2 e^-t - e^-2t from x = 1), registered by name."""
    monkeypatch.setattr(sim.scenarios.registry, "_REGISTRY", dict(sim.scenarios.registry._REGISTRY))  # undone after

    @classic_scenario("_double_integrator", failures={"half_gain": "g = 1/2 from 1 s"}, default_duration=3.0,
                      description="double integrator, PD regulator")
    def run(*, failure: str | None, duration: float, dt: float, seed: int, gain: float = 1.0) -> SimResult:
        def derivative(t, x, g):
            u = -2.0 * x[0] - 3.0 * x[1]
            return np.array([x[1], g * u]), (u,)

        flown = run_classic(derivative, np.array([1.0, 0.0]), duration=duration, dt=dt, n_signals=1, outputs=[0],
                            output_bound=10.0, hold=lambda t: gain / 2 if failure and t >= 1.0 else gain)
        return flown.result("_double_integrator", failure, 1.0, channels=["x"], reference=np.zeros((flown.t.size, 1)),
                            output=flown.states[:, :1], command=np.zeros((flown.t.size, 1)), pseudo=flown.signals)

    res = get_scenario("_double_integrator")(method="ignored")
    assert res.method is None and res.failure_time is None and not res.diverged
    assert res.t[-1] == pytest.approx(3.0)
    np.testing.assert_allclose(res.output[:, 0], 2 * np.exp(-res.t) - np.exp(-2 * res.t), atol=1e-6)
    failed = get_scenario("_double_integrator")(failure="half_gain")
    assert failed.failure_time == 1.0
    before, after = failed.t < 1.0, failed.t >= 1.0
    np.testing.assert_array_equal(failed.output[before], res.output[before])
    # from t = 1: x'' + 1.5 x' + x = 0 (poles -0.75 +- 0.661j) from the nominal state at 1 s
    x1, v1, w = 2 * math.exp(-1) - math.exp(-2), -2 * math.exp(-1) + 2 * math.exp(-2), math.sqrt(1 - 0.75**2)
    tau = failed.t[after] - 1.0
    expected = np.exp(-0.75 * tau) * (x1 * np.cos(w * tau) + (v1 + 0.75 * x1) / w * np.sin(w * tau))
    np.testing.assert_allclose(failed.output[after, 0], expected, atol=1e-6)
    with pytest.raises(ValueError, match="half_gain"):
        get_scenario("_double_integrator")(failure="stuck")


@pytest.mark.parametrize("module", ["ice", "harv_lon", "harv_latdir"])
def test_mimo_scenarios_register_their_own_defaults(module):
    """sim.scenarios.mimo.mimo_scenario takes the registry's defaults from the MimoScenario (one place)."""
    mod = __import__(f"sim.scenarios.{module}", fromlist=["SCENARIO"])
    run = get_scenario(module)
    assert run is mod.run and run.accepts_failure_objects
    assert (run.default_duration, run.default_method) == (mod.SCENARIO.default_duration, mod.SCENARIO.default_method)
