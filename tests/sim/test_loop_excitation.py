"""``--excitation``: the library's null-space excitation in the loop (seed 1.3.2.5).

The excited loop allocator keeps the moments of the plain one to round-off, stays within the
position limits and the Eq 1.28 box on every call (a seeded generator of hostile demands and
previous commands), keeps the status, and continues its signal across a rebuild (a health
change); the setting is checked, recorded, and refused for the printed static distribution.
"""

from __future__ import annotations

import numpy as np
import pytest

from sim.allocation import build_allocator
from sim.scenarios import get_scenario
from sim.scenarios import harv_latdir, ice
from sim.settings import MAX_EXCITATION, RunSettings, SettingError

T = 0.01


def _hostile_calls(vehicle, rng, n):
    """Demands from zero to 50x past the attainable set and previous commands anywhere, some
    outside the limits (a jammed effector's old command may be)."""
    k, m = len(vehicle.controlled), len(vehicle.actuators)
    lo, hi = vehicle.umin, vehicle.umax
    for _ in range(n):
        v = rng.normal(size=k) * 10.0 ** rng.uniform(-3, 1.7, size=k)
        u_prev = lo + (hi - lo) * rng.uniform(-0.2, 1.2, size=m)
        yield v, u_prev


@pytest.mark.parametrize("module", [ice, harv_latdir], ids=["ice", "harv_latdir"])
@pytest.mark.parametrize("method", ["qp", "wls", "pinv_scale", "cgi"])
def test_the_excitation_keeps_the_moments_and_the_limits_of_every_call(module, method):
    vehicle = module.vehicle()
    plain = build_allocator(vehicle, method, {}, frame_period=T)
    excited = build_allocator(vehicle, method, {}, frame_period=T, excitation=2.0, excitation_seed=7)
    position_only = build_allocator(vehicle, method, {}, rate_aware=False)
    lo, hi = vehicle.umin, vehicle.umax
    B = vehicle.B_alloc
    rng = np.random.default_rng(11)
    moved = 0
    for i, (v, u_prev) in enumerate(_hostile_calls(vehicle, rng, 200)):
        if i % 2:  # a loop's call: the previous command is this demand's own answer
            v = v / (1.0 + np.abs(v).max())
            u_prev = position_only(v, u_prev, T)[0]
        u0, va0, s0 = plain(v, u_prev, T)
        u1, va1, s1 = excited(v, u_prev, T)
        base = np.clip(u_prev, lo, hi)
        assert np.isfinite(u1).all()
        assert np.all(u1 >= lo) and np.all(u1 <= hi)
        # seed Eq 1.28: within the box around u_prev (clipped into the limits, as the loop does)
        rmin, rmax = excited_rates(vehicle)
        assert np.all(u1 >= base + rmin * T - 1e-9) and np.all(u1 <= base + rmax * T + 1e-9)
        scale = np.abs(B).sum() * (1.0 + np.abs(u1).max())
        assert np.abs(B @ u1 - B @ u0).max() <= 1e-12 * scale  # B e = 0 to round-off
        assert np.allclose(va1, B @ u1, rtol=0, atol=1e-12 * scale)
        assert s1 == s0
        moved += bool(i % 2 and np.abs(u1 - u0).max() > 1e-6)
    assert moved >= 50  # of the 100 loop calls, it excites where there is room


def excited_rates(vehicle):
    """The rate limits of the loop's Eq 1.28 box (the actuator horizon, as the loop builds it)."""
    from sim.allocation import allocation_problem, rate_horizon_scale

    problem = allocation_problem(vehicle)
    scale = rate_horizon_scale(vehicle, T, "actuator")
    return scale * problem.rate_min, scale * problem.rate_max


def test_a_rebuilt_allocator_continues_the_signal():
    vehicle = ice.vehicle()
    v, u_prev = np.array([0.1, 0.5, 0.02]), np.zeros(len(vehicle.actuators))
    one = build_allocator(vehicle, "qp", {}, frame_period=T, excitation=2.0, excitation_seed=3)
    calls = [one(v, u_prev, T)[0] for _ in range(12)]
    again = build_allocator(vehicle, "qp", {}, frame_period=T, excitation=2.0, excitation_seed=3, first_call=11)
    assert np.array_equal(again(v, u_prev, T)[0], calls[11])
    assert not np.array_equal(calls[10], calls[11])  # the signal moves from call to call


def test_the_setting_is_checked_recorded_and_refused_for_static():
    with pytest.raises(SettingError, match="excitation"):
        RunSettings(excitation=-1.0)
    with pytest.raises(SettingError, match="excitation"):
        RunSettings(excitation=MAX_EXCITATION * 2)
    with pytest.raises(TypeError, match="excitation"):
        build_allocator(ice.vehicle(), "static", {}, excitation=1.0)
    with pytest.raises(ValueError, match="frame_period"):
        build_allocator(ice.vehicle(), "qp", {}, excitation=1.0)
    r = get_scenario("ice")(method="qp", seed=1, duration=0.5, frame_period=T, excitation=1.5)
    assert r.settings["excitation"] == 1.5 and not r.diverged


def test_no_excitation_is_the_plain_loop_bit_for_bit():
    run = get_scenario("ice")
    a = run(method="qp", seed=2, duration=1.0, frame_period=T)
    b = run(method="qp", seed=2, duration=1.0, frame_period=T, excitation=0.0)
    c = run(method="qp", seed=2, duration=1.0, frame_period=T, excitation=2.0)
    assert np.array_equal(np.asarray(a.effectors), np.asarray(b.effectors))
    assert not np.array_equal(np.asarray(a.effectors), np.asarray(c.effectors))
