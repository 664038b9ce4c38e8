"""Controllability report: PX4 hexa X and quad X after a rotor loss, worked by hand."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import alloc
from alloc import vehicles
from alloc.ams import zonotope_volume
from alloc.controllability import RANK_RTOL, report
from alloc.exceptions import ProblemError
from alloc.health import EffectorHealth, FailureEvent
from alloc.importers.px4 import read_params, vehicle_from_params
from test_import_px4 import HEXA_X, QUAD_X

CT, KM_CT = 6.5, 0.325  # PX4 defaults: CT 6.5, |KM| 0.05 -> yaw moment 0.325 per rotor
LOST = {"motor1": EffectorHealth(floating=True)}  # a stopped rotor: no thrust, held at 0


@pytest.fixture(scope="module")
def hexa():
    return vehicle_from_params(read_params(HEXA_X))


@pytest.fixture(scope="module")
def quad():
    return vehicle_from_params(read_params(QUAD_X))


def test_hexa_nominal_by_hand(hexa):
    r = report(hexa, at=[0.0, 0.0, 0.0, -3 * CT])  # hover at half thrust
    # rows of B are orthogonal: singular values are the row norms (roll 6.5 sqrt .75, pitch 6.5 * 2 * .43,
    # yaw .325 sqrt 6, thrust 6.5 sqrt 6); condition = 6.5 sqrt 6 / (.325 sqrt 6) = 20
    expected = sorted([CT * math.sqrt(6), CT * math.sqrt(0.75), CT * 0.86, KM_CT * math.sqrt(6)], reverse=True)
    assert r.nominal_singular_values == pytest.approx(expected, rel=1e-12)
    assert r.rank == r.nominal_rank == 4 and r.condition == pytest.approx(20.0, rel=1e-12)
    assert r.independent_axes == ("roll", "pitch", "yaw", "fz") and r.uncontrollable_directions == ()
    # yaw at hover, roll = pitch = 0: the three CCW rotors (1, 3, 4) full and the CW ones off keep sum u = 3,
    # roll 3.25 - 1.625 - 1.625 = 0, pitch -2.795 + 2.795 = 0: yaw = 3 * 0.325 = 0.975; symmetric below
    yaw = r.range("yaw")
    assert (yaw.low, yaw.high) == pytest.approx((-0.975, 0.975), abs=1e-7) and yaw.two_sided
    p = hexa.problem()
    assert r.volume == pytest.approx(zonotope_volume(p.B, p.umin, p.umax), rel=1e-10)  # independent formula
    assert r.volume_fraction == pytest.approx(1.0) and r.margin > 0 and r.failed == ()


def test_hexa_after_a_rotor_loss_stays_full_rank_but_loses_yaw_one_way(hexa):
    r = report(hexa, LOST, at=[0.0, 0.0, 0.0, -3 * CT])
    assert r.failed == ("motor1",) and "motor1" not in r.active
    assert r.rank == 4 and r.full_rank and r.independent_axes == ("roll", "pitch", "yaw", "fz")
    assert 20.0 < r.condition < math.inf
    # yaw at hover with rotor 1 (index 0, CW) stopped: with S = sum u = 3, roll 2u1 + u2 - u3 - u4 + u5 = 0
    # (over 1.625) and pitch u2 - u3 + u4 - u5 = 0, the yaw sum u1 - u2 + u3 + u4 - u5 equals 3 u1 (u1 = the
    # CCW rotor opposite the lost one): yaw in [0, 3 * 0.325] -- the hover point is on the boundary.
    yaw = r.range("yaw")
    assert (yaw.low, yaw.high) == pytest.approx((0.0, 0.975), abs=1e-7)
    assert not yaw.two_sided and yaw.fraction == pytest.approx(0.5, abs=1e-7)
    assert r.margin == pytest.approx(0.0, abs=1e-9)  # Du et al.'s hover authority index: zero
    # every non-degenerate 4-subset of rotors has the same |det| here; rotor 1 is in 8 of the 12 non-degenerate
    # ones (numbers from zonotope_volume below): a third of the volume is left
    p = hexa.problem().with_health(LOST)
    assert r.volume == pytest.approx(zonotope_volume(p.B, p.umin, p.umax), rel=1e-10)
    assert r.volume_fraction == pytest.approx(1 / 3, rel=1e-12)
    json.dumps(r.to_dict(), allow_nan=False)


def test_quad_after_a_rotor_loss_has_rank_three(quad):
    r = report(quad, LOST, at=[0.0, 0.0, 0.0, -2 * CT])
    # nominal volume = |det B| = product of the orthogonal row norms (2 * 0.975)^2 * (2 * 0.325) * (4 * 6.5)... / 2:
    # rows: roll and pitch norm 2 * 0.975, yaw 2 * 0.325, thrust 2 * 6.5
    assert r.nominal_volume == pytest.approx(1.95 * 1.95 * 0.65 * 13.0, rel=1e-12)
    assert r.rank == 3 and r.nominal_rank == 4 and not r.full_rank and r.condition == math.inf
    assert r.volume == 0.0 and r.volume_fraction == 0.0
    assert r.independent_axes == ()  # every axis is coupled to the others
    # the lost direction n is orthogonal to the three remaining columns
    # c1 = (.975, -.975, .325, -6.5), c2 = (.975, .975, -.325, -6.5), c3 = (-.975, -.975, -.325, -6.5):
    # (c1 + c2) . n = 0 -> n_roll = 13 n_z / 1.95; (c2 + c3) . n = 0 -> n_yaw = -20 n_z; c2 . n = 0 -> n_pitch = -n_roll
    n = np.array([20 / 3, -20 / 3, -20.0, 1.0])
    n = -n / np.linalg.norm(n)  # sign: largest component positive
    assert len(r.uncontrollable_directions) == 1
    np.testing.assert_allclose(r.uncontrollable_directions[0], n, atol=1e-12)
    # hover (0, 0, 0, -13) has n . v != 0: not attainable any more
    assert not r.reference_attainable and all(math.isnan(x.low) for x in r.ranges)
    d = r.to_dict()
    assert d["condition"] is None and d["rank"] == 3
    json.dumps(d, allow_nan=False)


def test_problem_input_events_and_reference_checks():
    p = vehicles.problem("ice")
    events = [FailureEvent("elevon_l", "jam", position=10.0), FailureEvent("ssd_r", "float")]
    r = report(p, events)
    assert r.reference == (0.0, 0.0, 0.0) and r.failed == ("elevon_l", "ssd_r")
    assert r.rank == 3 and r.independent_axes == ("alpha", "p", "beta")
    healthy = p.with_health({"elevon_l": EffectorHealth(jam_position=10.0), "ssd_r": EffectorHealth(floating=True)})
    assert r.volume == pytest.approx(zonotope_volume(healthy.B, healthy.umin, healthy.umax), rel=1e-9)
    assert 0 < r.volume_fraction < 1
    for axis in r.ranges:  # a failure never widens an axis's range
        assert axis.nominal_low - 1e-9 <= axis.low <= 0.0 <= axis.high <= axis.nominal_high + 1e-9
    with pytest.raises(ProblemError, match="^at: expected shape"):
        report(p, at=[0.0, 1.0])
    with pytest.raises(ProblemError, match="^at: "):
        report(p, at=[0.0, math.nan, 0.0])
    with pytest.raises(ProblemError, match="^problem: expected"):
        report("ice")
    with pytest.raises(ProblemError, match="^health: expected"):
        report(p, 3)
    assert RANK_RTOL == 1e-9


def test_seeded_random_failures_never_widen_and_never_crash():
    rng = np.random.default_rng(2026)
    for trial in range(25):
        k, m = int(rng.integers(1, 5)), int(rng.integers(1, 8))
        B = rng.normal(size=(k, m)) * rng.choice([1.0, 0.0, 1e-6], size=(k, m), p=[0.8, 0.15, 0.05])
        lo = -rng.uniform(0.0, 2.0, m)
        hi = rng.uniform(0.0, 2.0, m)
        p = alloc.Problem(B, lo, hi)
        health = {}
        for j in rng.choice(m, size=int(rng.integers(0, m + 1)), replace=False):
            kind = rng.integers(3)
            if kind == 0:
                health[int(j)] = EffectorHealth(jam_position=float(rng.uniform(lo[j], hi[j])))
            elif kind == 1:
                health[int(j)] = EffectorHealth(floating=True)
            else:
                health[int(j)] = EffectorHealth(effectiveness=float(rng.uniform(0, 1)))
        r = report(p, health)
        assert 0 <= r.rank <= r.nominal_rank <= k, trial
        if r.volume is not None and r.nominal_volume is not None:
            assert 0.0 <= r.volume <= r.nominal_volume * (1 + 1e-9) + 1e-12, trial
        jammed = any(h.jam_position not in (None, 0.0) for h in health.values())
        assert r.reference_attainable or jammed, trial  # u = 0 is in every box unless a jam holds it elsewhere
        if not r.reference_attainable:
            assert all(math.isnan(a.low) and math.isnan(a.high) for a in r.ranges)
            continue
        for axis in r.ranges:
            assert axis.nominal_low - 1e-7 <= axis.low <= 0.0 <= axis.high <= axis.nominal_high + 1e-7, trial
        json.dumps(r.to_dict(), allow_nan=False)


def test_vehicle_trim_is_the_default_reference():
    v = vehicle_from_params({**read_params(HEXA_X), "MPC_THR_HOVER": 0.5})
    r = report(v, LOST)
    assert r.reference == (0.0, 0.0, 0.0, -3 * CT) and r.name == "px4"
    assert (r.range("yaw").low, r.range("yaw").high) == pytest.approx((0.0, 0.975), abs=1e-7)


def test_bundled_hexa_example_after_a_rotor_loss():
    # as above with sum u = S = 19.62 / 6.5: C = u2 + u5 = (S - 3 u1) / 2 and A = u3 + u4 = 2 u1 + C, yaw sum = 3 u1;
    # A <= 2 caps u1 at 4 - S = 0.9815: yaw in [0, 3 * 0.325 * (4 - S)]
    r = report(alloc.load_vehicle("hexa-x"), LOST)
    assert r.rank == 4 and r.reference == (0.0, 0.0, 0.0, -19.62)
    S = 19.62 / CT
    assert (r.range("yaw").low, r.range("yaw").high) == pytest.approx((0.0, 3 * KM_CT * (4 - S)), abs=1e-7)
