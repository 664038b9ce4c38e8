"""The linearised closed loop (sim.linearise): it matches the simulator, pinv's local map is the
analytic one, margins are finite and reproducible, and a stable and a divergent configuration
are told apart as the simulator shows."""

from __future__ import annotations

from dataclasses import replace

import control
import numpy as np
import pytest

from sim.allocation import allocation_problem, build_allocator
from sim.engine import simulate
from sim.linearise import (
    FrameLoop,
    LinearisationError,
    gain_phase_margins,
    linearise,
    local_map,
    margins,
    operating_point,
)
from sim.scenarios import ice
from sim.scenarios.mimo import mimo_spec


def _ice_spec(frame_period: float, method: str = "pinv", duration: float = 3.0, **options):
    spec, _ = mimo_spec(ice.SCENARIO, method=method, frame_period=frame_period, noise=False,
                        duration=duration, **options)
    quiet = tuple(replace(p, attitude_command=lambda t: np.zeros_like(t)) for p in spec.pilots)
    n = int(round(duration / spec.dt)) + 1
    return replace(spec, pilots=quiet, commands=np.zeros((n, 3)), record_every=spec.frame_steps(), failure=None)


@pytest.fixture(scope="module")
def ice_10ms():
    spec = _ice_spec(0.01)
    loop = FrameLoop(spec)
    lin = linearise(loop, operating_point(loop))
    return spec, loop, lin


def test_frame_loop_is_the_simulator(ice_10ms):
    """The numpy frame map flies the engine's loop to the last bit (noise off, an alpha step)."""
    spec, loop, _ = ice_10ms
    cmd = np.array(spec.commands)
    cmd[int(round(1.0 / spec.dt)):, 0] = 0.1
    spec = replace(spec, commands=cmd, duration=2.0)
    r = simulate(spec)
    n = r.output.shape[0] - 1
    _, ys = loop.run(loop.initial_state(), n, cmd=cmd[:: loop.N][:n])
    assert np.max(np.abs(ys - r.output[:n])) == 0.0


def test_linear_model_matches_simulator_small_step(ice_10ms):
    """A 0.1 deg alpha step flown by the simulator (less the same flight without it) against the
    linear model at trim over 1.5 s: relative error below 1e-5 (measured 1.6e-7)."""
    spec, loop, lin = ice_10ms
    step_at = 1.5
    cmd = np.array(spec.commands)
    cmd[int(round(step_at / spec.dt)):, 0] = 0.1
    with_step, without = simulate(replace(spec, commands=cmd)), simulate(spec)
    i0 = int(round(step_at / loop.T))
    flown = with_step.output[i0:] - without.output[i0:]
    model = lin.step_response(0, 0.1, flown.shape[0])
    assert np.max(np.abs(flown[:, 0])) > 0.05  # the step moved alpha
    assert np.max(np.abs(model - flown)) / np.max(np.abs(flown)) < 1e-5


def test_pinv_local_map_is_the_analytic_pseudo_inverse(ice_10ms):
    """du/dv of pinv inside its limits is Eq 1.23's P = Wu^-1 B' (B Wu^-1 B')^-1 (seed Eq 1.23)."""
    _, loop, lin = ice_10ms
    problem = allocation_problem(ice.vehicle())
    B, Wi = problem.B, np.linalg.inv(problem.Wu)
    P = Wi @ B.T @ np.linalg.inv(B @ Wi @ B.T)
    assert np.allclose(lin.J_v, P, atol=1e-7)
    assert np.allclose(lin.J_prev, 0.0, atol=1e-9)  # inside the rate box u_prev does not matter


def test_saturated_effectors_have_zero_rows_in_the_local_map():
    """Seeded demands that put pinv_clip effectors on their limits: those rows of du/dv are 0,
    the others are P's rows (the active set frozen)."""
    vehicle = ice.vehicle()
    problem = allocation_problem(vehicle)
    allocator = build_allocator(vehicle, "pinv_clip", {}, rate_aware=False)
    B, Wi = problem.B, np.linalg.inv(problem.Wu)
    P = Wi @ B.T @ np.linalg.inv(B @ Wi @ B.T)
    rng = np.random.default_rng(27)
    checked = 0
    for _ in range(20):
        v = rng.normal(size=3) * rng.choice([0.5, 5.0, 50.0])
        u = allocator(v, problem.up, 0.01)[0]
        on_limit = (np.abs(u - problem.umin) < 1e-9) | (np.abs(u - problem.umax) < 1e-9)
        J, _ = local_map(allocator, v, problem.up, 0.01)
        assert np.allclose(J[on_limit], 0.0, atol=1e-9)
        assert np.allclose(J[~on_limit], P[~on_limit], atol=1e-6)
        checked += int(on_limit.any())
    assert checked >= 5  # the generator reached saturation


def test_margins_are_finite_and_reproducible(ice_10ms):
    _, loop, lin = ice_10ms
    a, b = margins(lin), margins(linearise(loop, lin.X0))
    assert np.isfinite(a.spectral_radius) and np.isfinite(a.sigma_min) and np.isfinite(a.pilot_phase_margin_deg)
    assert np.all(np.isfinite(a.disk_margin))
    assert a.spectral_radius == b.spectral_radius and a.sigma_min == b.sigma_min
    assert np.array_equal(a.gain_margin_db, b.gain_margin_db, equal_nan=True)
    # measured: rho 0.99984, sigma_min(I + L) 0.096, pilot PM 40.3 deg at 10 ms, pinv, nominal
    assert 0.999 < a.spectral_radius < 1.0
    assert 0.05 < a.sigma_min < 0.2
    assert 30.0 < a.pilot_phase_margin_deg < 50.0


def test_stable_and_unstable_frame_rates_are_told_apart(ice_10ms):
    """ICE pinv, nominal, noise off, no input: at 10 ms the trim is locally stable (positive
    margins) and the simulator sits still at it; at 20 ms the trim is unstable (spectral radius
    > 1, zero disk margins) and the simulator leaves it for a rate-limited limit cycle
    (measured effector-rate RMS over 5-8 s: 0.008 deg/s at 10 ms, 33 deg/s at 20 ms)."""
    _, _, lin10 = ice_10ms
    m10 = margins(lin10)
    assert m10.stable and m10.mimo_disk_margin > 0.0 and m10.pilot_disk_margin > 0.0
    loop20 = FrameLoop(_ice_spec(0.02))
    m20 = margins(linearise(loop20, operating_point(loop20)))
    assert m20.spectral_radius > 1.05  # measured 1.091
    assert m20.mimo_disk_margin == 0.0 and not m20.stable

    def rate_rms(frame_period: float) -> float:
        flown = simulate(_ice_spec(frame_period, duration=8.0))
        tail = flown.t > 5.0
        return float(np.sqrt(np.mean(flown.effector_rates[tail] ** 2)))

    assert rate_rms(0.01) < 0.1
    assert rate_rms(0.02) > 10.0


def test_gain_phase_margins_agree_with_python_control():
    """Seeded discrete SISO loops: the sampled-response margins equal control.stability_margins'."""
    rng = np.random.default_rng(4)
    T = 0.01
    w = np.logspace(-2, np.log10(np.pi / T * 0.999), 4000)
    compared = 0
    for _ in range(12):
        k = rng.uniform(0.5, 8.0)
        a = rng.uniform(0.5, 5.0)
        delay = int(rng.integers(1, 6))
        G = control.c2d(control.tf([k * a], [1.0, a, 0.0]), T) * control.tf([1.0], [1.0] + [0.0] * delay, T)
        gm, pm = control.stability_margins(G)[:2]
        L = G(np.exp(1j * w * T))
        gm_db, pm_ours = gain_phase_margins(L, w)
        if np.isfinite(gm) and gm > 0:
            assert gm_db == pytest.approx(20 * np.log10(gm), abs=0.05)
            compared += 1
        if np.isfinite(pm):
            assert pm_ours == pytest.approx(abs(pm), abs=0.2)
    assert compared >= 8


def test_bad_operating_point_is_refused(ice_10ms):
    _, loop, _ = ice_10ms
    with pytest.raises(LinearisationError, match="X0"):
        linearise(loop, np.zeros(3))
    bad = np.zeros(loop.n_states)
    bad[0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        linearise(loop, bad)
    with pytest.raises(LinearisationError, match="failure"):
        FrameLoop(_ice_spec(0.01), failed=True)
