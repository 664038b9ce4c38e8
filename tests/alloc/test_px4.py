"""The ``px4`` method against PX4's own unit-test numbers and an independent restatement.

Sources (PX4/PX4-Autopilot): ``ControlAllocationSequentialDesaturation.cpp`` at commit
1bbd11683f715ebce43c377e0c8628d783ba5b04, ``ControlAllocationPseudoInverse.cpp`` at
089afb0915460c7768ea0e3ee1dad5a93c20ab5e, ``ControlAllocationSequentialDesaturationTest.cpp``
at 5cda32d5565b9047eb792056cb8c2aaf6da5c2a3 (the expected values below are that file's
formulas, written out).  :func:`px4_reference` is a second statement of PX4's steps, written
from the C++ loop by loop (one effector at a time, PX4's function split, in a chosen float
type), sharing no code with :mod:`alloc.methods.px4`; it is the oracle of the cross-checks.
"""

from __future__ import annotations

import numpy as np
import pytest

import alloc
from alloc.importers.px4 import vehicle_from_params

AXES6 = ["roll", "pitch", "yaw", "fx", "fy", "fz"]
ROLL, PITCH, YAW, FX, FY, FZ = range(6)


# ---------------------------------------------------------------- the oracle (PX4's steps, restated)

def px4_reference(B6, v6, umin, umax, airmode: int, dtype=np.float64):
    """PX4's ``ControlAllocationSequentialDesaturation::allocate`` for a 6-axis ``B6`` with zero
    trim, in ``dtype``; returns the clipped command (PX4 clips after ``allocate``)."""
    f = dtype
    mix = np.linalg.pinv(np.asarray(B6, dtype=np.float64)).astype(f)  # geninv
    n = mix.shape[0]
    for i in range(n):  # normalizeControlAllocationMatrix: small entries to zero
        for j in range(6):
            if abs(mix[i, j]) < f(1e-3):
                mix[i, j] = f(0.0)
    c = np.asarray(v6, dtype=f)
    amin = np.asarray(umin, dtype=f).copy()
    amax = np.asarray(umax, dtype=f).copy()

    def gain_of(vec, sp):  # computeDesaturationGain
        k_min, k_max = f(0.0), f(0.0)
        for i in range(n):
            if abs(vec[i]) < f(0.2):
                continue
            if sp[i] < amin[i]:
                k = (amin[i] - sp[i]) / vec[i]
                k_min, k_max = min(k_min, k), max(k_max, k)
            if sp[i] > amax[i]:
                k = (amax[i] - sp[i]) / vec[i]
                k_min, k_max = min(k_min, k), max(k_max, k)
        return f(k_min + k_max)

    def desaturate(sp, vec, increase_only=False):  # desaturateActuators
        g = gain_of(vec, sp)
        if increase_only and g < 0:
            return
        for i in range(n):
            sp[i] = f(sp[i] + g * vec[i])
        g = f(0.5) * gain_of(vec, sp)
        for i in range(n):
            sp[i] = f(sp[i] + g * vec[i])

    def mix_axes(axes):
        sp = np.zeros(n, dtype=f)
        for i in range(n):
            sp[i] = f(sum(mix[i, a] * c[a] for a in axes))
        return sp

    def mix_yaw(sp):  # mixYaw
        nonlocal amax
        for i in range(n):
            sp[i] = f(sp[i] + mix[i, YAW] * c[YAW])
        prev = amax.copy()
        amax = f(amax + (amax - amin) * f(0.15))
        desaturate(sp, mix[:, YAW])
        amax = prev
        desaturate(sp, mix[:, FZ], increase_only=True)

    if airmode == 1:  # mixAirmodeRP
        sp = mix_axes([ROLL, PITCH, FX, FY, FZ])
        desaturate(sp, mix[:, FZ])
        mix_yaw(sp)
    elif airmode == 2:  # mixAirmodeRPY
        sp = mix_axes([ROLL, PITCH, YAW, FX, FY, FZ])
        desaturate(sp, mix[:, FZ])
        desaturate(sp, mix[:, YAW])
    else:  # mixAirmodeDisabled
        sp = mix_axes([ROLL, PITCH, FX, FY, FZ])
        desaturate(sp, mix[:, FZ], increase_only=True)
        desaturate(sp, mix[:, ROLL])
        desaturate(sp, mix[:, PITCH])
        mix_yaw(sp)
    return np.minimum(np.maximum(sp, amin), amax)


# ---------------------------------------------------------------- vehicles

def px4_test_quad() -> np.ndarray:
    """The quad X of PX4's unit test (``make_quad_x_geometry``): rotors at (+-1, +-1), axis -z,
    CT 1, KM +-0.05; ``ActuatorEffectivenessRotors``: moment p x a - km a, force a."""
    rotors = [(1.0, 1.0, 0.05), (-1.0, -1.0, 0.05), (1.0, -1.0, -0.05), (-1.0, 1.0, -0.05)]
    B = np.zeros((6, 4))
    for j, (x, y, km) in enumerate(rotors):
        B[:, j] = [-y, x, km, 0.0, 0.0, -1.0]
    return B


def ring_params(n: int, arm: float, first_deg: float, ct: float = 6.5, km: float = 0.05) -> dict[str, float]:
    """PX4 parameters of an n-rotor X ring (alternating spin), as an airframe file sets them."""
    params: dict[str, float] = {"CA_AIRFRAME": 0, "CA_ROTOR_COUNT": n}
    for i in range(n):
        ang = np.deg2rad(first_deg + 360.0 * i / n)
        params |= {f"CA_ROTOR{i}_PX": arm * np.cos(ang), f"CA_ROTOR{i}_PY": arm * np.sin(ang),
                   f"CA_ROTOR{i}_CT": ct, f"CA_ROTOR{i}_KM": km if i % 2 == 0 else -km}
    return params


def normalised_problem(n: int, first_deg: float) -> alloc.Problem:
    """PX4's normalised 6-axis effectiveness (the importer's ``normalize="px4"``), limits [0, 1]."""
    vehicle = vehicle_from_params(ring_params(n, 0.25, first_deg), normalize="px4", axes="all")
    p = vehicle.problem()
    assert list(p.axes) == AXES6
    return p


VEHICLES = {"quad_x": (4, 45.0), "hexa_x": (6, 30.0), "octa_x": (8, 22.5)}
AIRMODES = {"disabled": 0, "roll_pitch": 1, "roll_pitch_yaw": 2}


# ---------------------------------------------------------------- PX4's unit tests

def _c(roll=0.0, pitch=0.0, yaw=0.0, thrust_z=0.0):
    return np.array([roll, pitch, yaw, 0.0, 0.0, thrust_z])


# (name, control setpoint, expected actuator setpoints) -- ControlAllocationSequentialDesaturationTest.cpp
PX4_UNIT_CASES = [
    ("AirmodeDisabledOnlyYaw", _c(yaw=1.0), [0.0, 0.0, 0.0, 0.0]),
    ("AirmodeDisabledThrustZ", _c(thrust_z=-0.75), [0.75 / 4] * 4),
    ("AirmodeDisabledThrustAndYaw", _c(yaw=0.02, thrust_z=-0.75),
     [0.75 / 4 + 0.02 * 5] * 2 + [0.75 / 4 - 0.02 * 5] * 2),
    ("AirmodeDisabledThrustAndSaturatedYaw", _c(yaw=0.25, thrust_z=-0.75), [0.75 / 2] * 2 + [0.0] * 2),
    ("AirmodeDisabledThrustAndPitch", _c(pitch=0.1, thrust_z=-0.75),
     [0.75 / 4 + 0.1 / 4, 0.75 / 4 - 0.1 / 4, 0.75 / 4 + 0.1 / 4, 0.75 / 4 - 0.1 / 4]),
    # thrust per motor 0.8, yaw 1: yaw difference 1 + 0.15 - 0.8, thrust lowered by the 0.15 margin
    ("AirmodeDisabledReducedThrustAndYaw", _c(yaw=1.0, thrust_z=-3.2),
     [0.8 + 0.35 - 0.15] * 2 + [0.8 - 0.35 - 0.15] * 2),
    # thrust 0.75 per motor, pitch 2: overage 0.75 + 0.5 - 1 taken off every motor
    ("AirmodeDisabledReducedThrustAndPitch", _c(pitch=2.0, thrust_z=-3.0),
     [0.75 + 0.5 - 0.25, 0.75 - 0.5 - 0.25, 0.75 + 0.5 - 0.25, 0.75 - 0.5 - 0.25]),
]


@pytest.mark.parametrize("name,v,expected", PX4_UNIT_CASES, ids=[c[0] for c in PX4_UNIT_CASES])
def test_px4_unit_test_numbers(name, v, expected):
    """PX4's tests assert within 1e-4 in float32; in float64 the same formulas hold to round-off."""
    p = alloc.Problem(px4_test_quad(), np.zeros(4), np.ones(4), axes=AXES6)
    r = alloc.make_allocator(p, "px4")(v)
    np.testing.assert_allclose(r.u, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(px4_reference(p.B, v, p.umin, p.umax, 0), expected, rtol=0, atol=1e-12)


# ---------------------------------------------------------------- the cross-check on normalised B

def _demands(rng: np.random.Generator, n: int) -> np.ndarray:
    """Normalised setpoints: moments in [-1.5, 1.5] (beyond what the rotors reach, often), forces
    fx, fy 0 (a planar multirotor), thrust fz in [-1.6, 0] (hover near -0.5; beyond the range too)."""
    V = np.zeros((n, 6))
    V[:, :3] = rng.uniform(-1.5, 1.5, (n, 3)) * rng.choice([0.05, 0.3, 1.0], (n, 1))
    V[:, FZ] = -rng.uniform(0.0, 1.6, n)
    return V


@pytest.mark.parametrize("vehicle", sorted(VEHICLES))
@pytest.mark.parametrize("airmode", sorted(AIRMODES))
def test_agrees_with_the_restatement_in_double(vehicle, airmode):
    """Same steps in float64, one effector at a time: agreement to round-off (1e-12)."""
    p = normalised_problem(*VEHICLES[vehicle])
    allocate = alloc.make_allocator(p, "px4", airmode=airmode)
    rng = np.random.default_rng(2026)
    worst = 0.0
    saturated = 0
    for v in _demands(rng, 400):
        ref = px4_reference(p.B, v, p.umin, p.umax, AIRMODES[airmode])
        r = allocate(v)
        worst = max(worst, float(np.abs(r.u - ref).max()))
        saturated += r.status is alloc.Status.UNATTAINABLE
    assert worst <= 1e-12, worst
    assert 40 <= saturated <= 360  # both regimes exercised


@pytest.mark.parametrize("vehicle", sorted(VEHICLES))
def test_agrees_with_the_restatement_in_float32(vehicle):
    """PX4 computes in float32: against the float32 restatement the commands agree to float32
    round-off (measured at most 6e-7 on commands in [0, 1], 1,000 demands a case; 2e-6 asserted)."""
    p = normalised_problem(*VEHICLES[vehicle])
    rng = np.random.default_rng(7)
    V = _demands(rng, 300)
    for airmode, code in AIRMODES.items():
        allocate = alloc.make_allocator(p, "px4", airmode=airmode)
        diffs = np.array([np.abs(allocate(v).u - px4_reference(p.B, v, p.umin, p.umax, code, np.float32)).max()
                          for v in V])
        assert diffs.max() <= 2e-6, (airmode, np.sort(diffs)[-5:])


# ---------------------------------------------------------------- what airmode promises

def test_airmode_raises_thrust_to_keep_roll_and_gives_up_yaw_first():
    """At zero thrust a roll demand needs thrust: disabled reduces roll instead (PX4 never raises
    thrust there); roll_pitch and roll_pitch_yaw raise thrust and meet roll and pitch exactly."""
    p = normalised_problem(4, 45.0)
    v = _c(roll=0.3, pitch=-0.2, thrust_z=0.0)
    dis, rp, rpy = (alloc.make_allocator(p, "px4", airmode=a)(v) for a in AIRMODES)
    assert abs(dis.v_achieved[ROLL]) < 0.3 - 1e-3
    for r in (rp, rpy):
        np.testing.assert_allclose(r.v_achieved[[ROLL, PITCH]], [0.3, -0.2], atol=1e-12)
        assert r.v_achieved[FZ] < -1e-3  # thrust raised (fz is down positive)
    # full yaw with a strong roll at hover: yaw is given up, roll and pitch kept
    v = _c(roll=0.3, pitch=0.2, yaw=1.0, thrust_z=-0.5)
    r = alloc.make_allocator(p, "px4", airmode="roll_pitch_yaw")(v)
    np.testing.assert_allclose(r.v_achieved[[ROLL, PITCH]], [0.3, 0.2], atol=1e-12)
    assert r.v_achieved[YAW] < 1.0 - 1e-3 and r.status is alloc.Status.UNATTAINABLE


def test_within_rate_limits_and_desaturated_within_them():
    """Eq 1.28: the call's bounds are the rate-limited window; the answer stays inside it."""
    p = normalised_problem(6, 30.0).replace(rate_min=-np.full(6, 10.0), rate_max=np.full(6, 10.0))
    allocate = alloc.make_allocator(p, "px4", airmode="roll_pitch")
    rng = np.random.default_rng(3)
    u = np.full(6, 0.5)
    for v in _demands(rng, 300):
        r = allocate(v, u_prev=u, dt=0.004)
        lo, hi = p.effective_bounds(u, 0.004)
        assert (r.u >= lo - 1e-12).all() and (r.u <= hi + 1e-12).all()
        assert np.abs(r.u - u).max() <= 10.0 * 0.004 + 1e-12
        u = r.u


def test_without_axis_names_it_is_the_clipped_pseudo_inverse():
    """No roll/pitch/yaw/thrust axis: nothing to desaturate along, so PX4's mixer reduces to its
    ControlAllocationPseudoInverse (clip), the same as ``pinv_clip`` when no entry is zeroed."""
    rng = np.random.default_rng(5)
    p = alloc.Problem(rng.normal(size=(3, 7)), -np.ones(7), np.ones(7))
    a, b = alloc.make_allocator(p, "px4", zero=0.0), alloc.make_allocator(p, "pinv_clip")
    for v in rng.normal(size=(200, 3)) * 2.0:
        np.testing.assert_allclose(a(v).u, b(v).u, rtol=0, atol=1e-14)


def test_thrust_rule_does_not_depend_on_the_axis_sign():
    """'Only reduce thrust' lowers the commands whichever way the thrust axis points: the same
    vehicle with an up-positive ``thrust`` axis gives the same commands."""
    p = normalised_problem(4, 45.0)
    keep = [ROLL, PITCH, YAW, FZ]
    B = p.B[keep].copy()
    down = alloc.Problem(B, p.umin, p.umax, axes=["roll", "pitch", "yaw", "fz"])
    B[3] *= -1.0
    up = alloc.Problem(B, p.umin, p.umax, axes=["roll", "pitch", "yaw", "thrust"])
    rng = np.random.default_rng(9)
    for airmode in AIRMODES:
        a, b = alloc.make_allocator(down, "px4", airmode=airmode), alloc.make_allocator(up, "px4", airmode=airmode)
        for v in _demands(rng, 100)[:, keep]:
            np.testing.assert_allclose(a(v).u, b(v * [1, 1, 1, -1]).u, rtol=0, atol=1e-12)


def test_bad_airmode_names_the_field():
    p = normalised_problem(4, 45.0)
    with pytest.raises(alloc.OptionError) as info:
        alloc.make_allocator(p, "px4", airmode=2)
    assert info.value.field == "airmode" and "disabled, roll_pitch, roll_pitch_yaw" in str(info.value)


@pytest.mark.parametrize("vehicle", sorted(VEHICLES))
def test_physical_units_give_the_normalised_commands(vehicle):
    """PX4's thresholds apply to its normalised mix, which the method forms from any ``B``: the
    physical vehicle (N m, N) with demand ``v`` and the normalised one with ``diag(s) v`` (the
    setpoint PX4 would be given) get the same commands."""
    n, first = VEHICLES[vehicle]
    params = ring_params(n, 0.25, first)
    phys = vehicle_from_params(params, axes="all").problem()
    norm = normalised_problem(n, first)
    s = np.array([np.linalg.norm(norm.B[i]) / np.linalg.norm(phys.B[i]) if phys.B[i].any() else 1.0
                  for i in range(6)])
    np.testing.assert_allclose(norm.B, s[:, None] * phys.B, rtol=1e-12, atol=1e-15)
    rng = np.random.default_rng(4)
    for airmode in AIRMODES:
        a, b = alloc.make_allocator(phys, "px4", airmode=airmode), alloc.make_allocator(norm, "px4", airmode=airmode)
        for vn in _demands(rng, 150):
            np.testing.assert_allclose(a(vn / s).u, b(vn).u, rtol=0, atol=1e-12)
