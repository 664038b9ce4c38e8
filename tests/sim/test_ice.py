"""ICE 6-DOF scenario (seed section 4.7): transcription checks and the seed's qualitative results.

Measured (seed 0, dt = 0.5 ms; see the report table in README):

* no observer, actuators in the loop: alpha leaves +-45 deg within ~2 s -> diverged (Fig 4-95 reproduced);
* Table 4-6 observers and hedges, noise-free, pilot gain 1: bounded through the failure (Fig 4-110
  reproduced in that setting);
* with the default pilot stand-in (gain 2, 0.2 s) and the seed's noise, the SMC loop also diverges
  about 10 s after the t = 20 s failure: NOT reproduced (xfail below);
* Eq 4.28 loop-shaped baseline: diverges after the failure (Fig 4-119 reproduced, ~14 s after it).
"""

from __future__ import annotations

import numpy as np
import pytest

import alloc
from sim.scenarios import get_scenario
from sim.scenarios import ice

run = get_scenario("ice")


def test_eq_4_24_reproduced_from_design_rows():
    # seed Eq 4.23 with Wu = diag(2, 2, 1, ...) on the w, pb, v rows of B (spoilers out of pitch)
    Wi = np.diag(1.0 / ice.WU)
    B = ice.B_DESIGN
    Bk = Wi @ B.T @ np.linalg.inv(B @ Wi @ B.T)
    assert np.allclose(Bk, ice.SEED_BK, atol=0.01 + 0.01 * np.abs(ice.SEED_BK))


def test_actuator_frequencies_quoted_in_failure_list():
    wn = {a.name: a.wn for a in ice.vehicle().actuators}
    assert wn["pitch_flap"] == pytest.approx(63.2, abs=0.1)  # seed de4: "reduced from 63 rad/s"
    assert wn["pitch_tv"] == pytest.approx(39.2, abs=0.1)  # seed de10: "reduced from 39 rad/s"


def test_allocation_problem_matches_table_4_5():
    p = ice.allocation_problem()
    assert p.k == 3 and p.m == 11
    assert p.umin[3] == 0.0 and p.umax[3] == 60.0  # all-moving tip
    assert p.rate_max[2] == 50.0  # symmetric pitch flap


def test_no_observer_diverges_fig_4_95():
    r = run(method="static", observer=False, hedge=False, noise=False, duration=5.0)
    assert r.diverged
    assert r.duration < 4.0


def test_observers_and_hedges_bounded_through_failure_fig_4_110():
    """Noise-free, pilot stand-in gain 1, failure at 5 s instead of 20 s to keep the test short."""
    r = run(method="static", failure="seed", failure_time=5.0, duration=15.0, noise=False, pilot_gain=1.0)
    s = r.summary()["channels"]
    assert not r.diverged
    assert s["alphaw"]["max_after"] < 10.0
    assert s["betaw"]["max_after"] < 5.0
    assert s["alphaw"]["rms_before"] < 0.6


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="measured: with the seed's noise and our pilot stand-in (gain 2, "
                   "0.2 s) ps reaches 200 deg/s about 12 s after the t = 20 s failure; seed Fig 4-110 "
                   "shows the loop stable")
def test_full_seed_run_with_noise_stays_bounded():
    r = run(method="static", failure="seed", duration=40.0)
    assert not r.diverged


def test_loop_shaped_baseline_diverges_after_failure_fig_4_119():
    r = run(method="static", controller="loopshape", failure="seed", failure_time=5.0, duration=20.0, noise=False)
    assert r.diverged
    assert r.duration > 5.0  # tracked before the failure
    assert r.summary()["channels"]["alphaw"]["rms_before"] < 1.0


#: Every registry method, ICE, seed failure at 1.5 s told, rate-aware (Eq 1.28 default), noise off,
#: pilot gain 1, 3 s: tracking RMS per channel, before and after the failure, must stay within
#: IN_LOOP_FACTOR x the seed design (static Eq 4.24) + IN_LOOP_FLOOR.  Measured spread (this
#: machine): worst before-failure ratio 6.3 (pinv_scale/daisy alpha), after 6.3 (cgi alpha).
IN_LOOP_FACTOR = 8.0
IN_LOOP_FLOOR = 0.05
IN_LOOP = dict(failure="seed", failure_time=1.5, duration=3.0, noise=False, allocator_knows_failure=True,
               pilot_gain=1.0)
SLOW_IN_LOOP = {"cgi", "da"}  # LP-backed, ~20 s each on a shared machine


@pytest.fixture(scope="module")
def seed_design_rms():
    s = run(method="static", **IN_LOOP).summary()["channels"]
    return {ch: (v["rms_before"], v["rms_after"]) for ch, v in s.items()}


@pytest.mark.parametrize("method", [
    pytest.param(m, marks=pytest.mark.slow) if m in SLOW_IN_LOOP else m for m in alloc.methods()
])
def test_every_registry_method_flies_and_tracks_in_the_loop(method, seed_design_rms):
    r = run(method=method, **IN_LOOP)
    assert not r.diverged
    assert r.t[-1] == pytest.approx(3.0)
    # It flies: the surfaces move (u = 0 was daisy's and pinv_scale's answer with up = 0 on ICE).
    assert np.max(np.abs(r.effectors - r.effectors[0])) > 1.0
    for ch, v in r.summary()["channels"].items():
        before, after = seed_design_rms[ch]
        assert v["rms_before"] <= IN_LOOP_FACTOR * before + IN_LOOP_FLOOR, ch
        assert v["rms_after"] <= IN_LOOP_FACTOR * after + IN_LOOP_FLOOR, ch
    s = r.summary()
    assert s["allocator_calls"] == 6001 and s["fallback_fraction"] == 0.0
    assert 0.0 <= s["unattainable_fraction"] <= 1.0


def test_one_sided_effectors_prefer_mid_range_by_default():
    from sim.allocation import allocation_problem

    p = allocation_problem(ice.vehicle())
    one_sided = p.umin == 0.0
    assert one_sided.sum() == 4  # AMT and SSD pairs, 0..60 deg (seed Table 4-5)
    assert np.all(p.up[one_sided] == 30.0) and np.all(p.up[~one_sided] == 0.0)
    assert np.all(allocation_problem(ice.vehicle(), preferred="zero").up == 0.0)


def test_pinv_scale_flies_zero_with_the_seed_up_and_not_with_mid_range():
    """The cause of u = 0: with up = 0 at the lower limit of one-sided effectors the scale is 0."""
    zero = run(method="pinv_scale", preferred="zero", duration=0.5, noise=False)
    mid = run(method="pinv_scale", duration=0.5, noise=False)
    assert np.max(np.abs(zero.effectors[:, [3, 4, 5, 6]])) == 0.0
    assert np.max(np.abs(mid.effectors[:, [3, 4, 5, 6]])) > 1.0


def test_told_problem_uses_the_one_health_model():
    from sim.allocation import allocation_problem

    p = allocation_problem(ice.vehicle(), ice.failure())
    i = ice.EFFECTORS.index
    assert p.umin[i("de2")] == p.umax[i("de2")] == 5.0  # jam
    assert (p.umin[i("de3")], p.umax[i("de3")], p.rate_max[i("de3")]) == (-15.0, 15.0, 10.0)  # limits + rate
    assert p.rate_max[i("de4")] == 50.0  # bandwidth failures are never told
    assert p.names[0] == "elevon_l"  # the library's effector names


def test_rate_horizon_spans_the_actuator_lag():
    from sim.allocation import actuator_lag, rate_horizon_scale

    v = ice.vehicle()
    assert actuator_lag(v)[0] == pytest.approx(1 / 40 + 1 / 100)  # (40)(100)/((s+40)(s+100))
    assert rate_horizon_scale(v, 0.0005, "actuator")[0] == pytest.approx(70.0)
    assert np.all(rate_horizon_scale(v, 0.1, "actuator") == 1.0)  # T >= every lag (LEF: 66 ms): Eq 1.28, dt = T
    assert np.all(rate_horizon_scale(v, 0.0005, "frame") == 1.0)


@pytest.mark.slow
@pytest.mark.parametrize("method", ["pinv", "qp"])
def test_rate_aware_told_allocation_survives_the_seed_failure(method):
    """Was: diverged at 25.7 s (pinv) / 24.6 s (qp) with an Eq 1.28 box of rate x 0.5 ms."""
    kw = dict(method=method, failure="seed", allocator_knows_failure=True, noise=False, pilot_gain=1.0,
              preferred="zero")
    literal = run(rate_horizon="frame", **kw)
    fixed = run(**kw)
    assert literal.diverged and 24.0 < literal.duration < 28.0
    assert not fixed.diverged
    assert fixed.summary()["channels"]["ps"]["rms_after"] < 5.0


def test_frame_period_holds_the_computer_outputs_between_frames():
    base = dict(method="pinv", failure="seed", failure_time=0.2, duration=0.5, noise=False, record_every=1)
    fast = run(**base)
    same = run(frame_period=0.0005, **base)
    slow = run(frame_period=0.002, **base)
    assert np.array_equal(fast.output, same.output)  # T = dt is the seed's single-rate loop
    assert slow.allocator_status.size == 251 and fast.allocator_status.size == 1001
    # pseudo-commands change only at frames (every 4th integration step)
    changes = np.nonzero(np.any(np.diff(slow.pseudo, axis=0) != 0.0, axis=1))[0] + 1
    assert changes.size > 10 and np.all(changes % 4 == 0)
    assert slow.settings["frame_period"] == pytest.approx(0.002)


def test_seed_design_reports_exact_allocation_and_csv(tmp_path):
    r = run(method="static", duration=0.2, noise=False)
    s = r.summary()
    assert s["unattainable_fraction"] == 0.0 and s["fallback_fraction"] == 0.0
    path = r.to_csv(tmp_path / "ice.csv")
    lines = path.read_text().splitlines()
    header = lines[0].split(",")
    assert header[0] == "t" and "pos_elevon_l" in header and header[-1] == "alloc_status"
    assert len(lines) == r.t.size + 1 and lines[1].endswith(",exact")


# ---------------------------------------------------------------- frame rate (flight-control computer at T)
def _quasi_sliding_radius(frame_period: float, rule: str) -> float:
    """Spectral radius of the SMC's linear-region loop sampled at ``T`` (plant outputs frozen).

    State: the controller (reference models, observers, hedges, ZOH-discretised at ``T``) and the
    integral of ``e``; ``u_c = rho / eps_T (K0 e + K_-1 int e)``, allocated by the seed's ``B_k``.
    """
    from sim.engine import _controller_system
    from sim.settings import boundary_layer_at

    v, d = ice.vehicle(), ice.smc_design()
    k, m, nz = 3, 11, 11
    ctl, n_in = _controller_system(v, d, ice.REFERENCES, frame_period)
    n = ctl.Ad.shape[0]
    E = ctl.C[:k] - ctl.C[k : 2 * k] - ctl.C[2 * k :]  # e = r - (y_hat + y_f)
    uc = np.diag(d.rho / boundary_layer_at(d.eps, frame_period, rule)) @ np.hstack([np.diag(d.K0) @ E, np.diag(d.Km1)])
    W = np.zeros((n_in, n + k))
    W[k : k + m] = v.Bk_seed @ uc
    W[k + m + nz :] = uc
    M = np.zeros((n + k, n + k))
    M[:n, :n] = ctl.Ad
    M[:n] += ctl.Bd @ W
    M[n:, :n] = frame_period * E
    M[n:, n:] = np.eye(k)
    return float(np.max(np.abs(np.linalg.eigvals(M))))


def test_seed_boundary_layer_sampled_at_100_hz_is_an_unstable_discrete_loop():
    """The cause of the 100 Hz divergence: per-frame gain T g rho / eps = 9-10 (stable below 2)."""
    assert _quasi_sliding_radius(0.0005, "fixed") <= 1.0 + 1e-6  # seed rate (measured 1.000)
    assert _quasi_sliding_radius(0.0025, "fixed") > 1.4  # 400 Hz (measured 1.52): chatters
    assert _quasi_sliding_radius(0.01, "fixed") > 10.0  # 100 Hz (measured 11.8): diverges
    assert _quasi_sliding_radius(0.01, "frame") <= 1.0 + 1e-6  # eps x 20 keeps the seed's per-frame gain


def test_boundary_layer_and_anti_windup_rules_are_the_seed_at_the_seed_rate():
    from sim.settings import anti_windup_on, boundary_layer_at

    eps = np.ones(3)
    assert boundary_layer_at(eps, 0.0005) is eps and boundary_layer_at(eps, 0.01, "fixed") is eps
    assert np.all(boundary_layer_at(eps, 0.01) == 20.0) and np.all(boundary_layer_at(eps, 0.0025) == 5.0)
    assert not anti_windup_on("auto", 0.0005) and anti_windup_on("auto", 0.001) and not anti_windup_on("off", 0.01)
    base = dict(method="qp", failure="seed", failure_time=0.2, duration=0.5, noise=False, allocator_knows_failure=True)
    seed = run(boundary_layer="fixed", anti_windup="off", **base)
    assert np.array_equal(run(**base).output, seed.output)


def test_ice_flies_at_100_hz_with_the_frame_boundary_layer():
    base = dict(method="pinv", duration=8.0, noise=False, pilot_gain=1.0, rate_aware=False)
    seed_rate = run(**base).summary()["channels"]
    r = run(frame_period=0.01, **base)
    fixed = run(frame_period=0.01, boundary_layer="fixed", anti_windup="off", **base)  # the seed's law
    assert fixed.diverged and fixed.duration < 5.0  # measured 4.05 s
    assert not r.diverged
    for ch, s in r.summary()["channels"].items():  # measured 0.18/0.21/0.13 vs 0.19/0.26/0.13 at 2 kHz
        assert s["rms_before"] <= 1.2 * seed_rate[ch]["rms_before"] + 0.02, ch


@pytest.mark.parametrize("method", ["cgi", "pinv_scale", "daisy"])
def test_rate_box_is_given_only_where_the_answer_breaks_a_rate_limit(method):
    from sim.allocation import build_allocator

    v, T = ice.vehicle(), 0.01
    blind = build_allocator(v, method, {}, rate_aware=False)
    binding = build_allocator(v, method, {}, frame_period=T, rate_horizon="frame")
    always = build_allocator(v, method, {}, frame_period=T, rate_horizon="frame", rate_window="always")
    rng = np.random.default_rng(3)
    moved = 0.0
    for _ in range(40):
        d = rng.normal(size=3) * np.array([2.0, 5.0, 0.2])
        u0 = blind(d, np.zeros(11), T)[0]
        assert np.array_equal(binding(d, u0, T)[0], u0)  # inside its own box: the position-limited answer
        moved = max(moved, float(np.abs(always(d, u0, T)[0] - u0).max()))
        u1 = binding(d + rng.normal(size=3) * 20.0, u0, T)[0]  # a large step breaks a rate limit
        assert np.all(np.abs(u1 - u0) <= v.rate_max * T + 1e-9)
    assert moved > 1e-3  # the heuristic's answer moves with the box where it does not bind ("always")


def test_anti_windup_holds_the_integral_while_the_allocator_falls_short():
    kw = dict(method="qp", failure="seed", allocator_knows_failure=True, noise=False, pilot_gain=1.0,
              frame_period=0.01, duration=32.0)
    on, off = run(**kw), run(anti_windup="off", **kw)
    assert off.diverged and 21.0 < off.duration < 32.0
    assert not on.diverged
    assert on.summary()["channels"]["ps"]["rms_after"] < 3.0  # measured 2.31 (rate-blind 2.38)
