"""ArduPilot importer: the factors of AP_MotorsMatrix.cpp (setup_quad_matrix / setup_hexa_matrix,
MOTOR_FRAME_TYPE_X, then normalise_rpy_factors) worked by hand, and user tables."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

from alloc.exceptions import ProblemError
from alloc.importers.ardupilot import (
    frame_factors, normalise_rpy_factors, read_factor_table, vehicle_from_factors, vehicle_from_frame,
)
from alloc.vehicle_file import load_vehicle, vehicle_from_dict

# quad X: motors at 45 (CCW), -135 (CCW), -45 (CW), 135 (CW) degrees.
# roll = cos(angle + 90): -0.7071, 0.7071, 0.7071, -0.7071; pitch = cos(angle): 0.7071, -0.7071, 0.7071, -0.7071;
# normalised to magnitude 0.5; yaw CCW +1 / CW -1 -> +-0.5; throttle 1.
QUAD_X = np.array([
    [-0.5, 0.5, 0.5, 1.0],
    [0.5, -0.5, 0.5, 1.0],
    [0.5, 0.5, -0.5, 1.0],
    [-0.5, -0.5, -0.5, 1.0],
])
# hexa X: 90 CW, -90 CCW, -30 CW, 150 CCW, 30 CCW, -150 CW.
# roll = -sin(angle): -1, 1, 0.5, -0.5, -0.5, 0.5 -> x 0.5; pitch = cos(angle): 0, 0, 0.866, -0.866, 0.866, -0.866 -> 0.5
HEXA_X = np.array([
    [-0.5, 0.0, -0.5, 1.0],
    [0.5, 0.0, 0.5, 1.0],
    [0.25, 0.5, -0.5, 1.0],
    [-0.25, -0.5, 0.5, 1.0],
    [-0.25, 0.5, 0.5, 1.0],
    [0.25, -0.5, -0.5, 1.0],
])


@pytest.mark.parametrize("frame, expected", [("quad-x", QUAD_X), ("hexa-x", HEXA_X)])
def test_builtin_factors_are_ardupilots(frame, expected):
    np.testing.assert_allclose(frame_factors(frame), expected, atol=1e-15)


def test_quad_x_effectiveness_is_the_mixers_inverse():
    v = vehicle_from_frame("quad-x")
    B = v.problem().B
    # factor columns orthogonal, squared norms 1, 1, 1, 4: pinv(M) = diag(1, 1, 1, 1/4) M'
    np.testing.assert_allclose(B, np.diag([1, 1, 1, 0.25]) @ QUAD_X.T, atol=1e-15)
    np.testing.assert_allclose(B @ QUAD_X, np.eye(4), atol=1e-14)  # mixing then applying gives the demand back
    assert v.axis_names == ("roll", "pitch", "yaw", "throttle") and v.problem().umax.tolist() == [1.0] * 4


def test_hexa_x_effectiveness_by_hand():
    B = vehicle_from_frame("hexa-x").problem().B
    # squared column norms: roll 2 * 0.25 + 4 * 0.0625 = 0.75, pitch 4 * 0.25 = 1, yaw 6 * 0.25 = 1.5, throttle 6
    np.testing.assert_allclose(B, np.diag([1 / 0.75, 1.0, 1 / 1.5, 1 / 6]) @ HEXA_X.T, atol=1e-14)
    Bt = vehicle_from_frame("hexa-x", effectiveness="transpose").problem().B
    np.testing.assert_allclose(Bt, HEXA_X.T, atol=1e-15)


def test_quad_plus_and_hexa_plus_are_built_in():
    for frame in ("quad-plus", "hexa-plus"):
        M = frame_factors(frame)
        assert np.abs(M[:, :3]).max(axis=0).tolist() == pytest.approx([0.5, 0.5, 0.5])
        assert np.linalg.matrix_rank(M) == 4


def test_csv_and_toml_tables(tmp_path):
    csv_text = "motor,roll,pitch,yaw,throttle\n" + "\n".join(
        f"m{i + 1},{r},{p},{y}" + ("" if i == 0 else f",{t}") for i, (r, p, y, t) in enumerate(QUAD_X))
    names, M = read_factor_table(csv_text)
    assert names == ["m1", "m2", "m3", "m4"] and np.array_equal(M, QUAD_X)  # a missing throttle is 1
    toml_text = "\n".join(f'[[motors]]\nname = "m{i + 1}"\nroll = {r}\npitch = {p}\nyaw = {y}\nthrottle = {t}\n'
                          for i, (r, p, y, t) in enumerate(QUAD_X))
    (tmp_path / "f.toml").write_text(toml_text)
    names2, M2 = read_factor_table(tmp_path / "f.toml")
    assert names2 == names and np.array_equal(M2, QUAD_X)
    # un-normalised factors (ArduPilot normalises every table)
    v = vehicle_from_factors(2 * M, names, slew_up_time=0.5, slew_down_time=0.25)
    assert v == vehicle_from_factors(M, names, slew_up_time=0.5, slew_down_time=0.25)
    p = v.problem()
    assert p.rate_max.tolist() == [2.0] * 4 and p.rate_min.tolist() == [-4.0] * 4
    assert load_vehicle(v.save(tmp_path / "q.toml")) == v


@pytest.mark.parametrize("text, message", [
    ("motor,roll,pitch\nm1,1,2\n", "factors: the CSV header needs columns"),
    ("motor,roll,pitch,yaw\nm1,1,x,0\n", "factors: row 2: pitch: 'x' is not a number"),
    ("motor,roll,pitch,yaw\n,1,0,0\n", "factors: row 2: a motor name is required"),
    ("motor,roll,pitch,yaw\nm1,1,nan,0\n", "factors: row 2: pitch: must be finite"),
    ('[[motors]]\nname = "a"\nroll = 1\npitch = 0\n', "factors: motors[0]: yaw: required"),
])
def test_bad_tables_are_named(text, message):
    with pytest.raises(ProblemError, match="^" + re.escape(message)):
        read_factor_table(text)


def test_bad_arguments_are_named():
    with pytest.raises(ProblemError, match="^frame: unknown 'octo-x'"):
        vehicle_from_frame("octo-x")
    with pytest.raises(ProblemError, match="^factors: expected a table"):
        vehicle_from_factors(np.ones((4, 3)))
    with pytest.raises(ProblemError, match="^slew_up_time: must be a positive"):
        vehicle_from_factors(QUAD_X, slew_up_time=-1)
    with pytest.raises(ProblemError, match="^effectiveness: expected"):
        vehicle_from_factors(QUAD_X, effectiveness="inverse")


def test_seeded_random_tables_give_valid_vehicles():
    rng = np.random.default_rng(4)
    for _ in range(50):
        m = int(rng.integers(1, 13))
        M = rng.normal(size=(m, 4)) * rng.choice([0.0, 1.0, 1e-8, 1e6], size=(m, 4))
        v = vehicle_from_factors(M)
        B = v.problem().B
        assert np.isfinite(B).all()
        Mn = normalise_rpy_factors(M)
        if np.linalg.matrix_rank(Mn) == 4:
            np.testing.assert_allclose(B @ Mn, np.eye(4), atol=1e-6 * max(1.0, np.abs(B).max()))
        assert vehicle_from_dict(v.to_dict()) == v
        assert not math.isnan(B.sum())
