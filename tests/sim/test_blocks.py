"""Unit tests of the simulator building blocks (sim.blocks, sim.result, registry) and the compiled loop."""

from __future__ import annotations

import dataclasses
import importlib
import json

import numpy as np
import pytest
from scipy import signal

from sim.allocation import build_allocator
from sim.blocks import ActuatorBank, ActuatorFailure, ActuatorSpec, DelayLine, DiscreteLTI, HedgeTerm, ScheduledPlant
from sim.blocks import actuator_heun_step, band_limited_noise, hedge_system, observer_gain, smc_control, sum_of_sines
from sim.engine import _controller_system
from sim.packed import _matvec
from sim.result import SimResult, divergence_check
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


def test_every_table_effect_is_executed_and_repair_restores_the_nominal_actuator():
    specs = [ActuatorSpec.second_order(f"e{i}", 30.0, 0.7, -30.0, 30.0, 100.0) for i in range(3)]
    bank = ActuatorBank(specs, DT)
    bank.pos[:] = [4.0, 3.0, 2.0]
    done = [bank.apply_failure(f) for f in (
        ActuatorFailure(0, "jam"), ActuatorFailure(1, "hardover"), ActuatorFailure(2, "float"),
        ActuatorFailure(1, "effectiveness", fraction=0.4), ActuatorFailure(2, "limits", lo=-5.0, hi=6.0),
        ActuatorFailure(2, "rate_limits", rate_min=-7.0, rate_max=7.0))]
    # defaults filled in: the jam where the surface was, the hard-over at the nominal upper stop
    assert done[0] == ActuatorFailure(0, "jam", position=4.0) and done[1].position == 30.0
    assert (bank.jam_pos[0], bank.hard_pos[1], bank.jammed[0], bank.hardover[1]) == (4.0, 30.0, True, True)
    np.testing.assert_array_equal(bank.effectiveness, [1.0, 0.4, 0.0])
    assert (bank.lo[2], bank.hi[2], bank.rmax[2]) == (-5.0, 6.0, 7.0)
    for i in range(3):
        bank.apply_failure(ActuatorFailure(i, "repair"))
    assert bank.specs == specs and not bank.jammed.any() and not bank.hardover.any()
    np.testing.assert_array_equal(bank.effectiveness, 1.0)
    assert ActuatorFailure.KINDS == ("jam", "hardover", "float", "effectiveness", "limits", "rate_limits", "repair",
                                     "bandwidth")


def test_hostile_actuator_failures_are_refused_naming_the_field_or_executed_within_limits():
    """Seeded generator: kinds (table, simulator-only, unknown) with parameters of every sort."""
    from alloc import ProblemError
    from alloc.health import FAILURE_KINDS, SIMULATOR_ONLY

    rng = np.random.default_rng(4242)
    kinds = [*FAILURE_KINDS, "bandwidth", "delay", "drift", "loe", "", 3]
    values = [0.5, -0.5, 2.0, -40.0, 0.0, 1e12, float("nan"), float("inf"), True, "1", None, 7]
    names = ["position", "fraction", "lo", "hi", "rate_min", "rate_max", "wn", "rate", "delay"]
    refused = executed = 0
    for _ in range(2000):
        kind = kinds[rng.integers(len(kinds))]
        own = list(getattr(FAILURE_KINDS.get(kind, SIMULATOR_ONLY.get(kind)), "params", ()))
        pool = own if own and rng.random() < 0.6 else names  # mostly the kind's own parameters
        params = {pool[j]: values[rng.integers(len(values))]
                  for j in rng.choice(len(pool), rng.integers(0, min(4, len(pool) + 1)), replace=False)}
        index = int(rng.choice([0, 1, 2, 2, 1, -1]))
        try:
            f = ActuatorFailure(index, kind, **params)
            bank = ActuatorBank([ActuatorSpec.second_order(f"e{i}", 30.0, 0.7, -30.0, 30.0, 100.0)
                                 for i in range(3)], DT)
            done = bank.apply_failure(f)
        except ProblemError as exc:
            refused += 1
            assert exc.field in {"kind", "index", *names}, exc
            assert isinstance(exc, ValueError)
            continue
        assert kind in FAILURE_KINDS or SIMULATOR_ONLY[kind].per_actuator
        executed += 1
        assert set(done.params) == {n for n, d in done.spec.params.items() if d is not None or n in f.params}
        for _ in range(50):
            pos = bank.step(np.array([50.0, -50.0, 10.0]))
        assert np.isfinite(pos).all() and (pos >= bank.lo - 1e-12).all() and (pos <= bank.hi + 1e-12).all()
        assert ((bank.effectiveness >= 0.0) & (bank.effectiveness <= 1.0)).all()
    assert refused > 500 and executed > 150  # both branches reached (1,766 and 234 with this seed)


def test_a_jam_without_a_position_holds_and_tells_the_position_at_the_failure(monkeypatch):
    """Told and untold runs: the surface stays where it was at the instant of failure, and a
    told allocator is told exactly that number."""
    import sim.engine
    from alloc import ProblemError
    from sim.allocation import allocation_problem
    from sim.model import Failure
    from sim.scenarios import ice

    failure = Failure("jam_here", 0.5, "elevon_l jams where it is", actuators=(ActuatorFailure(0, "jam"),))
    with pytest.raises(ProblemError, match="^position: required for a 'jam' failure"):
        allocation_problem(ice.vehicle(), failure)  # before injection nobody knows the position
    told = []
    build = sim.engine.build_allocator

    def spy(vehicle, method, options, *, failure=None, **kw):
        if failure is not None:
            told.append(allocation_problem(vehicle, failure))
        return build(vehicle, method, options, failure=failure, **kw)

    monkeypatch.setattr(sim.engine, "build_allocator", spy)
    held = {}
    for knows in (True, False):
        run = get_scenario("ice")(failure=failure, method="qp", duration=0.8, seed=1, allocator_knows_failure=knows,
                                  failure_time=0.5)
        after = run.t >= 0.5
        assert not run.diverged
        held[knows] = run.effectors[after, 0]
        assert np.all(held[knows] == held[knows][0]) and held[knows][0] != 0.0
    assert held[True][0] == held[False][0]  # the same flight until the failure: the same jam position
    (problem,) = told
    assert problem.umin[0] == problem.umax[0] == held[True][0]


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


# ----------------------------------------------------------- compiled kernels
def _numpy_heun(bank_arrays, u, dt):
    """The actuator step as first written: vectorised numpy (reference formulation)."""
    pos, rate, first, wn2, c1, lo, hi, rmax, jammed, jam_pos, hardover, hard_pos = bank_arrays

    def velocity(p, r, u):
        vel = np.clip(np.where(first, c1 * (u - p), r), -rmax, rmax)
        acc = np.where(first, 0.0, wn2 * (u - p) - c1 * r)
        return vel, acc

    u = np.where(hardover, hard_pos, u)
    v1, a1 = velocity(pos, rate, u)
    p1 = pos + dt * v1
    r1 = np.clip(rate + dt * a1, -rmax, rmax)
    v2, a2 = velocity(p1, r1, u)
    new_pos = pos + 0.5 * dt * (v1 + v2)
    new_rate = np.clip(rate + 0.5 * dt * (a1 + a2), -rmax, rmax)
    at_lo, at_hi = new_pos <= lo, new_pos >= hi
    new_pos = np.clip(new_pos, lo, hi)
    new_rate = np.where((at_lo & (new_rate < 0)) | (at_hi & (new_rate > 0)), 0.0, new_rate)
    new_pos = np.where(jammed, jam_pos, new_pos)
    new_rate = np.where(jammed, 0.0, new_rate)
    rate_out = np.where(first, (new_pos - pos) / dt, new_rate)
    return new_pos, new_rate, rate_out


def test_actuator_heun_kernel_matches_numpy_formulation_bit_for_bit():
    rng = np.random.default_rng(3)
    m = 8
    first = np.arange(m) % 3 == 0
    wn2, c1 = rng.uniform(100.0, 5000.0, m), rng.uniform(10.0, 140.0, m)
    lo, hi = -rng.uniform(5.0, 30.0, m), rng.uniform(5.0, 30.0, m)
    rmax = rng.uniform(10.0, 150.0, m)
    jammed, jam_pos = np.arange(m) == 1, np.full(m, 5.0)
    hardover, hard_pos = np.arange(m) == 2, np.full(m, -30.0)
    pos, rate = np.zeros(m), np.zeros(m)
    kpos, krate, krate_out = np.zeros(m), np.zeros(m), np.zeros(m)
    rate_limited = position_limited = 0
    for _ in range(3000):
        u = rng.uniform(-40.0, 40.0, m)  # beyond the position limits too
        pos, rate, rate_out = _numpy_heun((pos, rate, first, wn2, c1, lo, hi, rmax, jammed, jam_pos,
                                           hardover, hard_pos), u, DT)
        actuator_heun_step(kpos, krate, krate_out, u, first, wn2, c1, lo, hi, rmax, jammed, jam_pos,
                           hardover, hard_pos, DT)
        assert np.array_equal(kpos, pos) and np.array_equal(krate, rate) and np.array_equal(krate_out, rate_out)
        rate_limited += np.any(np.abs(krate_out) >= rmax)
        position_limited += np.any((kpos == hi) | (kpos == lo))
    assert rate_limited > 100 and position_limited > 100  # both limits were exercised


@pytest.mark.parametrize("shape", [(1, 1), (1, 5), (1, 30), (3, 3), (9, 48), (48, 28), (11, 11)])
def test_compiled_matvec_is_numpy_matmul_bit_for_bit(shape):
    rng = np.random.default_rng(sum(shape))
    for _ in range(50):
        A, x, out = rng.standard_normal(shape), rng.standard_normal(shape[1]), np.empty(shape[0])
        _matvec(A, x, out)
        assert np.array_equal(out, A @ x)


def _reference_loop(*, vehicle, references, controller, commands, pilots, failure, method, duration, dt, seed,
                    noise, output_bound, record_every, **_):
    """The engine as first written: block objects stepped with numpy (SMC designs, static allocator)."""
    k, m = len(vehicle.controlled), len(vehicle.actuators)
    n_steps = int(round(duration / dt))
    meas, ctrl = np.asarray(vehicle.measured), np.asarray(vehicle.controlled)
    noise_all = np.zeros((n_steps + 1, vehicle.C.shape[0]))
    if noise:
        noise_all[:, meas] = band_limited_noise(n_steps + 1, dt, vehicle.noise_gains, np.random.default_rng(seed))
    plant = ScheduledPlant(vehicle.A, vehicle.B, vehicle.C, vehicle.D, dt, A_fail=failure.A, B_fail=failure.B,
                           D_fail=failure.D)
    bank, delay = ActuatorBank(vehicle.actuators, dt), DelayLine(m, dt, 0.0)
    allocator = build_allocator(vehicle, method, {})
    ctl, n_in = _controller_system(vehicle, controller, references, dt)
    w, integ = np.zeros(n_in), np.zeros(k)
    t_grid = np.arange(n_steps + 1) * dt
    pilot_delays = [DelayLine(1, dt, p.delay) for p in pilots]
    pilot_cmds = [p.attitude_command(t_grid) for p in pilots]
    pilot_att = np.zeros(len(pilots))
    rec = {name: [] for name in ("reference", "output", "command", "pseudo", "unallocated", "effectors",
                                 "effector_rates")}
    u_act, u_cmd, cmd, rate_out = bank.pos.copy(), np.zeros(m), np.zeros(k), np.zeros(m)
    failed = False
    for step in range(n_steps + 1):
        if not failed and step * dt >= failure.time - 0.5 * dt:
            failed = True
            for f in failure.actuators:
                bank.apply_failure(f)
            plant.fail(effectiveness=bank.effectiveness)
            if failure.delay is not None:
                delay.set_delay(failure.delay)
            u_act = bank.pos.copy()
        y_all = plant.output(u_act)
        z_all = y_all + noise_all[step]
        if divergence_check(y_all[ctrl], output_bound, plant.x):
            break
        cmd[:] = commands[step]
        for j, p in enumerate(pilots):
            att = p.row @ z_all
            if p.integrate:
                pilot_att[j] += dt * att
                att = pilot_att[j]
            else:
                pilot_att[j] = att
            cmd[p.channel] = p.gain * pilot_delays[j].push(np.array([pilot_cmds[j][step] - att]))[0]
        o = ctl.C @ ctl.x
        r = o[:k]
        e = r - (o[k : 2 * k] + o[2 * k :])
        uc = smc_control(controller.K0 * e + controller.Km1 * integ, controller.rho, controller.eps)
        v = vehicle.demand_map @ uc
        u_cmd, v_achieved, _ = allocator(v, u_cmd, dt)
        unalloc = v - v_achieved
        if step % record_every == 0:
            for name, value in zip(rec, (r, y_all[ctrl], cmd, uc, unalloc, u_act, rate_out if step else 0 * u_act)):
                rec[name].append(np.array(value))
        w[:] = np.concatenate([cmd, u_cmd, z_all[meas], uc])
        ctl.x = ctl.Ad @ ctl.x + ctl.Bd @ w
        integ += dt * e
        plant.step(u_act)
        u_act = bank.step(delay.push(u_cmd))
        rate_out = bank.rate_out
    return {name: np.array(values) for name, values in rec.items()}


@pytest.mark.parametrize("name, options", [
    # pilot with 0.2 s delay, noise, plant failure, 50 ms actuator delay, jam, limits, bandwidth
    ("ice", dict(failure="seed", failure_time=0.1, duration=0.4)),
    # single-channel rows (numpy's dot path), integrating pilot, hard-over, failure at 0.05 s
    ("harv_lon", dict(failure="failure1", failure_time=0.05, duration=0.4)),
    ("harv_latdir", dict(failure="failure1", failure_time=0.05, duration=0.4)),
])
def test_compiled_loop_matches_reference_loop_bit_for_bit(monkeypatch, name, options):
    import sim.engine

    module = importlib.import_module("sim.scenarios.mimo")  # the one MIMO runner calls simulate
    captured = {}

    def capture(spec, **kwargs):
        captured.update({f.name: getattr(spec, f.name) for f in dataclasses.fields(spec)})
        return sim.engine.simulate(spec, **kwargs)

    monkeypatch.setattr(module, "simulate", capture)
    result = get_scenario(name)(method="static", record_every=1, **options)
    expected = _reference_loop(**captured)
    assert not result.diverged
    for field_name, values in expected.items():
        assert np.array_equal(getattr(result, field_name), values), field_name


def test_resting_at_a_zero_limit_is_not_saturation():
    """A one-sided effector (limits [0, 60], like the ICE tips) resting at 0 is not saturated;
    the same effector at 60 is."""
    t = np.arange(0.0, 4.0, 1.0)
    z = np.zeros((4, 1))
    res = SimResult(
        "x", "pinv", None, t, ["q"], z, z, z,
        effectors=np.array([[0.0], [0.0], [60.0], [30.0]]), effector_limits=(np.array([0.0]), np.array([60.0])),
    )
    assert res.time_in_position_saturation == pytest.approx(1.0)
