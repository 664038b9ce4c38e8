"""ArduPilot frames by FRAME_CLASS / FRAME_TYPE: the factor tables against ArduPilot's numbers worked by hand,
parameter files and CSV tables through every ``--vehicle``.

Source: ArduPilot/ardupilot ``libraries/AP_Motors/AP_MotorsMatrix.cpp`` (setup_octa_matrix,
setup_octaquad_matrix, setup_y6_matrix; ``add_motor``: roll = cos(angle + 90 deg), pitch = cos(angle)),
``normalise_rpy_factors`` (each of roll, pitch, yaw to a largest magnitude of 0.5, throttle to 1).
"""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from typer.testing import CliRunner

from alloc.cli import app
from alloc.exceptions import ProblemError
from alloc.importers.ardupilot import (
    FRAMES, frame_factors, frame_of_params, read_ardupilot_params, read_factor_table, vehicle_from_ardupilot_params,
    vehicle_from_factors,
)
from alloc.vehicle_file import load_vehicle

# octa-quad X: motors at 45 CCW, -45 CW, -135 CCW, 135 CW, -45 CCW, 45 CW, 135 CCW, -135 CW.
# roll = cos(angle + 90) = -sin(angle): 45 -> -0.7071, -45 -> 0.7071, +-135 likewise; pitch = cos(angle);
# all |0.7071| -> 0.5 after normalising; yaw +-1 -> +-0.5; throttle 1.
OCTA_QUAD_X = np.array([
    [-0.5, 0.5, 0.5, 1], [0.5, 0.5, -0.5, 1], [0.5, -0.5, 0.5, 1], [-0.5, -0.5, -0.5, 1],
    [0.5, 0.5, 0.5, 1], [-0.5, 0.5, -0.5, 1], [-0.5, -0.5, 0.5, 1], [0.5, -0.5, -0.5, 1],
])
# Y6B (add_motor_raw): roll -1, -1, 0, 0, 1, 1 -> x 0.5; pitch 0.5, 0.5, -1, -1, 0.5, 0.5 -> x 0.5;
# yaw CW, CCW, CW, CCW, CW, CCW -> -+0.5
Y6B = np.array([
    [-0.5, 0.25, -0.5, 1], [-0.5, 0.25, 0.5, 1], [0.0, -0.5, -0.5, 1], [0.0, -0.5, 0.5, 1],
    [0.5, 0.25, -0.5, 1], [0.5, 0.25, 0.5, 1],
])
# Y6 default (any FRAME_TYPE but 10, 11): pitch 0.666 and -1.333 -> the largest, 1.333, becomes 0.5
Y6_DEFAULT = np.array([
    [-0.5, 0.5 * 0.666 / 1.333, 0.5, 1], [0.5, 0.5 * 0.666 / 1.333, -0.5, 1], [0.5, 0.5 * 0.666 / 1.333, 0.5, 1],
    [0.0, -0.5, -0.5, 1], [-0.5, 0.5 * 0.666 / 1.333, -0.5, 1], [0.0, -0.5, 0.5, 1],
])
S22, C22 = math.sin(math.radians(22.5)), math.cos(math.radians(22.5))  # 0.3827, 0.9239
# octa X: 22.5 CW, -157.5 CW, 67.5 CCW, 157.5 CCW, -22.5 CCW, -112.5 CCW, -67.5 CW, 112.5 CW.
# roll = -sin(angle), pitch = cos(angle); the largest magnitude of each is C22, scaled to 0.5
OCTA_X_RAW = np.array([
    [-S22, C22, -1], [S22, -C22, -1], [-C22, S22, 1], [-S22, -C22, 1],
    [S22, C22, 1], [C22, -S22, 1], [C22, S22, -1], [-C22, -S22, -1],
])


@pytest.mark.parametrize("params, frame, expected", [
    ({"FRAME_CLASS": 4, "FRAME_TYPE": 1}, "octa-quad-x", OCTA_QUAD_X),
    ({"FRAME_CLASS": 5, "FRAME_TYPE": 10}, "y6b", Y6B),
    ({"FRAME_CLASS": 5, "FRAME_TYPE": 1}, "y6", Y6_DEFAULT),
    ({"FRAME_CLASS": 5, "FRAME_TYPE": 0}, "y6", Y6_DEFAULT),
])
def test_tables_are_ardupilots_by_hand(params, frame, expected):
    assert frame_of_params(params) == frame
    np.testing.assert_allclose(frame_factors(frame), expected, atol=1e-15)


def test_octa_x_by_hand():
    expected = np.column_stack([0.5 * OCTA_X_RAW[:, :2] / C22, 0.5 * OCTA_X_RAW[:, 2], np.ones(8)])
    np.testing.assert_allclose(frame_factors(frame_of_params({"FRAME_CLASS": 3, "FRAME_TYPE": 1})), expected,
                               atol=1e-15)
    # FRAME_TYPE defaults to 1 (X), ArduPilot's default
    assert frame_of_params({"FRAME_CLASS": 3}) == "octa-x"


def test_octa_quad_x_effectiveness_inverts_the_mixer():
    v = vehicle_from_ardupilot_params({"FRAME_CLASS": 4, "FRAME_TYPE": 1})
    B = v.problem().B
    # orthogonal factor columns, squared norms 8 * 0.25 = 2 (roll, pitch, yaw) and 8 (throttle)
    np.testing.assert_allclose(B, np.diag([0.5, 0.5, 0.5, 0.125]) @ OCTA_QUAD_X.T, atol=1e-15)
    np.testing.assert_allclose(B @ OCTA_QUAD_X, np.eye(4), atol=1e-14)
    assert v.name == "ardupilot-octa-quad-x" and v.m == 8


def test_every_built_in_frame_is_normalised_and_controllable():
    for frame in FRAMES:
        M = frame_factors(frame)
        assert np.abs(M[:, :3]).max(axis=0).tolist() == pytest.approx([0.5, 0.5, 0.5]), frame
        assert M[:, 3].tolist() == [1.0] * len(M)
        assert np.linalg.matrix_rank(M) == 4, frame


def test_param_file_csv_and_cli(tmp_path):
    (tmp_path / "octaquad.param").write_text("# Mission Planner\nFRAME_CLASS,4\nFRAME_TYPE,1\nMOT_SLEW_UP_TIME,0.25\n"
                                            "MOT_SLEW_DN_TIME,0\n")
    (tmp_path / "octaquad.parm").write_text("FRAME_CLASS 4\nFRAME_TYPE\t1\nMOT_SLEW_UP_TIME 0.25\n")
    a, b = load_vehicle(tmp_path / "octaquad.param"), load_vehicle(tmp_path / "octaquad.parm")
    assert a == b
    # UP 0.25 s: rate 4 per second; DN 0 (ArduPilot: no limit) leaves the vehicle file's default, -rate_max
    assert a.problem().rate_max.tolist() == [4.0] * 8 and a.problem().rate_min.tolist() == [-4.0] * 8
    rows = "\n".join(f"m{i + 1},{','.join(str(x) for x in r)}" for i, r in enumerate(OCTA_QUAD_X))
    (tmp_path / "octaquad_x.csv").write_text("motor,roll,pitch,yaw,throttle\n" + rows + "\n")
    c = load_vehicle(tmp_path / "octaquad_x.csv")
    np.testing.assert_allclose(c.problem().B, a.problem().B, atol=1e-15)  # cos(45 deg) vs 0.5 written out
    assert c.effector_names == tuple(f"m{i}" for i in range(1, 9))
    result = CliRunner().invoke(app, ["allocate", "--vehicle", str(tmp_path / "octaquad_x.csv"), "--v",
                                      "0.1,0,0,0.5", "--json"])
    assert result.exit_code == 0, result.output
    u = np.array(__import__("json").loads(result.stdout)["u"])
    np.testing.assert_allclose(c.problem().B @ u, [0.1, 0, 0, 0.5], atol=1e-9)


@pytest.mark.parametrize("params, message", [
    ({}, "FRAME_CLASS: missing"),
    ({"FRAME_CLASS": 7}, "FRAME_CLASS: 7 is not supported; supported: 1 (quad), 2 (hexa)"),
    ({"FRAME_CLASS": 1.5}, "FRAME_CLASS: expected a whole number, got 1.5"),
    ({"FRAME_CLASS": 2, "FRAME_TYPE": 15}, "FRAME_TYPE: 15 has no table for FRAME_CLASS 2 (hexa); it has: 0 (plus)"),
    ({"FRAME_CLASS": 1, "MOT_SLEW_UP_TIME": -1}, "MOT_SLEW_UP_TIME: must be a number of seconds >= 0"),
])
def test_bad_ardupilot_parameters_are_named(params, message):
    with pytest.raises(ProblemError, match="^" + re.escape(message)):
        vehicle_from_ardupilot_params(params)


@pytest.mark.parametrize("text, message", [
    ("FRAME_CLASS,1\nFRAME_CLASS,2\n", "params: line 2: FRAME_CLASS is set again (first at line 1)"),
    ("FRAME_CLASS,1,2\n", "params: line 1: expected 'NAME,value' or 'NAME value'"),
    ("frame_class,1\n", "params: line 1: 'frame_class' is not an ArduPilot parameter name"),
    ("FRAME_CLASS,nan\n", "params: line 1: FRAME_CLASS: must be finite"),
])
def test_bad_ardupilot_param_lines_are_named(text, message):
    with pytest.raises(ProblemError, match="^" + re.escape(message)) as info:
        read_ardupilot_params(text)
    assert info.value.field == "params"


def test_missing_motor_row_cells_are_named():
    with pytest.raises(ProblemError, match=r"^factors: row 3: yaw: required"):
        read_factor_table("motor,roll,pitch,yaw\nm1,1,0,1\nm2,-1,0\n")
    names, M = read_factor_table("motor,roll,pitch,yaw\nm1,1,0,1\n")
    assert vehicle_from_factors(M, names).m == 1  # one motor is a table; its rank is the user's business


def test_other_commands_take_the_importer_files(tmp_path):
    """`--vehicle` is one option on every command: `alloc ams summary` reads an ArduPilot .param file."""
    (tmp_path / "y6.param").write_text("FRAME_CLASS,5\nFRAME_TYPE,10\n")
    res = CliRunner().invoke(app, ["ams", "summary", "--vehicle", str(tmp_path / "y6.param")])
    assert res.exit_code == 0, res.output
    assert "vertices" in res.stdout
    bad = CliRunner().invoke(app, ["ams", "summary", "--vehicle", str(tmp_path / "none.param")])
    lines = [line for line in bad.stderr.splitlines() if line.strip()]
    assert bad.exit_code == 2 and len(lines) == 1 and "none.param" in lines[0], bad.stderr
