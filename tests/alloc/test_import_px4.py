"""PX4 importer: stock airframes' effectiveness against PX4's formulas worked by hand.

Parameters are PX4's own airframe files (PX4/PX4-Autopilot, ROMFS/px4fmu_common/init.d/airframes):
4001_quad_x (commit 37091fe9ca9a), 6001_hexa_x (commit 517f6f0051fc), 2100_standard_plane (commit
c564d3131a5f) and 1103_standard_vtol_sih.hil (commit 00381e0dc572); every other parameter at its
module.yaml default (CT 6.5, KM 0.05, axis (0, 0, -1)).  Expected columns are written out from
ActuatorEffectivenessRotors::computeEffectivenessMatrix: moment = CT (p x a) - CT KM a, thrust = CT a,
with p x a = (py az - pz ay, pz ax - px az, px ay - py ax).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import alloc
from alloc.exceptions import ProblemError
from alloc.importers.px4 import px4_scales, read_params, vehicle_from_params

QUAD_X = """
param set-default CA_ROTOR_COUNT 4
param set-default CA_ROTOR0_PX 0.15
param set-default CA_ROTOR0_PY 0.15
param set-default CA_ROTOR1_PX -0.15
param set-default CA_ROTOR1_PY -0.15
param set-default CA_ROTOR2_PX 0.15
param set-default CA_ROTOR2_PY -0.15
param set-default CA_ROTOR2_KM -0.05
param set-default CA_ROTOR3_PX -0.15
param set-default CA_ROTOR3_PY 0.15
param set-default CA_ROTOR3_KM -0.05
"""

HEXA_X = """
param set-default MAV_TYPE 13
param set-default CA_ROTOR_COUNT 6
param set-default CA_ROTOR0_PX 0.0
param set-default CA_ROTOR0_PY 0.5
param set-default CA_ROTOR0_KM -0.05
param set-default CA_ROTOR1_PX 0.0
param set-default CA_ROTOR1_PY -0.5
param set-default CA_ROTOR2_PX 0.43
param set-default CA_ROTOR2_PY -0.25
param set-default CA_ROTOR2_KM -0.05
param set-default CA_ROTOR3_PX -0.43
param set-default CA_ROTOR3_PY 0.25
param set-default CA_ROTOR4_PX 0.43
param set-default CA_ROTOR4_PY 0.25
param set-default CA_ROTOR5_PX -0.43
param set-default CA_ROTOR5_PY -0.25
param set-default CA_ROTOR5_KM -0.05
"""

PLANE = """
param set-default CA_AIRFRAME 1
param set-default CA_ROTOR_COUNT 1
param set-default CA_ROTOR0_PX 0.3
param set-default CA_SV_CS_COUNT 4
param set-default CA_SV_CS0_TYPE 1
param set-default CA_SV_CS0_TRQ_R -0.5
param set-default CA_SV_CS1_TRQ_R 0.5
param set-default CA_SV_CS1_TYPE 2
param set-default CA_SV_CS2_TRQ_P 1
param set-default CA_SV_CS2_TYPE 3
param set-default CA_SV_CS3_TRQ_Y 1
param set-default CA_SV_CS3_TYPE 4
"""

VTOL = """
param set-default CA_AIRFRAME 2
param set-default CA_ROTOR_COUNT 5
param set-default CA_ROTOR0_KM 0.05
param set-default CA_ROTOR0_PX 0.2
param set-default CA_ROTOR0_PY 0.2
param set-default CA_ROTOR1_KM 0.05
param set-default CA_ROTOR1_PX -0.2
param set-default CA_ROTOR1_PY -0.2
param set-default CA_ROTOR2_PX 0.2
param set-default CA_ROTOR2_PY -0.2
param set-default CA_ROTOR2_KM -0.05
param set-default CA_ROTOR3_PX -0.2
param set-default CA_ROTOR3_PY 0.2
param set-default CA_ROTOR3_KM -0.05
param set-default CA_ROTOR4_PX -0.3
param set-default CA_ROTOR4_KM 0.05
param set-default CA_ROTOR4_AX 1
param set-default CA_ROTOR4_AZ 0
param set-default CA_SV_CS_COUNT 3
param set-default CA_SV_CS0_TRQ_R 1
param set-default CA_SV_CS0_TYPE 15 # single channel aileron
param set-default CA_SV_CS1_TRQ_P 1
param set-default CA_SV_CS1_TYPE 3 # elevator
param set-default CA_SV_CS2_TRQ_Y 1
param set-default CA_SV_CS2_TYPE 4 # rudder
"""

CT = 6.5


def test_quad_x_effectiveness_by_hand():
    v = vehicle_from_params(read_params(QUAD_X))
    assert v.axis_names == ("roll", "pitch", "yaw", "fz")  # fx, fy: no rotor acts on them
    # rotor 0 (0.15, 0.15): p x a = (0.15 * -1, -(0.15 * -1), 0) = (-0.15, 0.15, 0); KM 0.05: yaw +0.325
    # rotor 1 (-0.15, -0.15): (0.15, -0.15, 0); rotor 2 (0.15, -0.15), KM -0.05: (0.15, 0.15, 0), yaw -0.325
    # rotor 3 (-0.15, 0.15), KM -0.05: (-0.15, -0.15, 0), yaw -0.325
    arm = CT * 0.15  # 0.975
    yaw = CT * 0.05  # 0.325
    expected = np.array([
        [-arm, arm, arm, -arm],
        [arm, -arm, arm, -arm],
        [yaw, yaw, -yaw, -yaw],
        [-CT, -CT, -CT, -CT],
    ])
    np.testing.assert_allclose(v.problem().B, expected, rtol=1e-15, atol=1e-15)
    p = v.problem()
    assert p.umin.tolist() == [0.0] * 4 and p.umax.tolist() == [1.0] * 4
    assert v.effectors[0].rotor is not None  # the geometry is kept in the vehicle file


def test_quad_x_px4_normalisation_by_hand():
    v = vehicle_from_params(read_params(QUAD_X), normalize="px4")
    # B's rows are orthogonal, so pinv's column for a row r is r / |r|^2.
    # roll: |r|^2 = 4 arm^2, all 4 entries non-zero: s = sqrt((1 / (4 arm^2)) / (4 / 2)) = 1 / (arm sqrt 8);
    # pitch the same; normalised roll row = arm / (arm sqrt 8) = 1 / sqrt 8 (PX4's familiar mix entry sqrt(2)/2).
    # yaw: max entry of r / |r|^2 = 1 / (4 * 0.325): normalised row 0.325 * 4 * 0.325 / (4 * 0.325)... = 1 / 4.
    # thrust: |M_i,force| = 1 / (4 CT) for every rotor: s = 1 / (4 CT), row -CT / (4 CT) = -1 / 4.
    r = 1 / math.sqrt(8)
    expected = np.array([
        [-r, r, r, -r],
        [r, -r, r, -r],
        [0.25, 0.25, -0.25, -0.25],
        [-0.25, -0.25, -0.25, -0.25],
    ])
    np.testing.assert_allclose(v.problem().B, expected, rtol=1e-12)
    assert v.axes[0].unit == "1"


def test_hexa_x_effectiveness_and_normalisation_by_hand():
    v = vehicle_from_params(read_params(HEXA_X))
    B = v.problem().B
    # rotor0 (0, 0.5) KM -0.05: p x a = (-0.5, 0, 0) -> (-3.25, 0, -0.325); rotor1 (0, -0.5) KM 0.05: (3.25, 0, 0.325)
    # rotor2 (0.43, -0.25) KM -0.05: (0.25, 0.43, 0) -> (1.625, 2.795, -0.325); rotor3 (-0.43, 0.25): (-1.625, -2.795, 0.325)
    # rotor4 (0.43, 0.25) KM 0.05: (-0.25, 0.43, 0) -> (-1.625, 2.795, 0.325); rotor5 (-0.43, -0.25) KM -0.05
    expected = np.array([
        [-3.25, 3.25, 1.625, -1.625, -1.625, 1.625],
        [0.0, 0.0, 2.795, -2.795, 2.795, -2.795],
        [-0.325, 0.325, -0.325, 0.325, 0.325, -0.325],
        [-CT] * 6,
    ])
    np.testing.assert_allclose(B, expected, rtol=1e-14, atol=1e-15)
    # normalisation: rows orthogonal again.  roll: |r|^2 = CT^2 (2 * 0.25 + 4 * 0.0625) = 0.75 CT^2, 6 non-zero:
    # s_roll = sqrt(1 / (0.75 CT^2) / 3) = 1 / (1.5 CT).  pitch: |q|^2 = 4 (0.43 CT)^2, 4 non-zero:
    # s_pitch = sqrt(1 / (4 * 0.1849 CT^2) / 2) = 1 / (CT sqrt(1.4792)); roll and pitch share the larger, s_pitch.
    # yaw: s = 1 / (6 * 0.325), normalised row +-1/6; thrust: s = 1 / (6 CT), row -1/6.
    s_rp = 1.0 / (CT * math.sqrt(1.4792))
    vn = vehicle_from_params(read_params(HEXA_X), normalize="px4")
    expected_n = np.vstack([s_rp * expected[0], s_rp * expected[1], expected[2] / (6 * 0.325), [-1 / 6] * 6])
    np.testing.assert_allclose(vn.problem().B, expected_n, rtol=1e-12)
    assert vn.problem().B[1, 2] == pytest.approx(0.5 / math.sqrt(2), rel=1e-12)  # 2.795 / (6.5 sqrt 1.4792)


def test_standard_plane_surfaces_by_hand():
    v = vehicle_from_params(read_params(PLANE))
    assert v.effector_names == ("motor1", "left_aileron", "right_aileron", "elevator", "rudder")
    assert v.axis_names == ("roll", "pitch", "yaw", "fx")
    # motor: fixed-wing axis (1, 0, 0), propeller torque off; p x a = (0.3, 0, 0) x (1, 0, 0) = 0; thrust 6.5 x
    expected = np.array([
        [0.0, -0.5, 0.5, 0.0, 0.0],
        [0.0, 0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 0.0, 1.0],
        [CT, 0.0, 0.0, 0.0, 0.0],
    ])
    np.testing.assert_array_equal(v.problem().B, expected)
    p = v.problem()
    assert p.umin.tolist() == [0.0, -1.0, -1.0, -1.0, -1.0]


def test_standard_vtol_by_hand_and_px4_two_matrices():
    v = vehicle_from_params(read_params(VTOL))
    assert v.effector_names == ("motor1", "motor2", "motor3", "motor4", "motor5", "single_channel_aileron",
                                "elevator", "rudder")
    assert v.axis_names == ("roll", "pitch", "yaw", "fx", "fz")
    a, y = CT * 0.2, CT * 0.05  # 1.3, 0.325
    # pusher (-0.3, 0, 0), axis (1, 0, 0): not upwards, so KM -> 0; p x a = 0; thrust (6.5, 0, 0)
    expected = np.array([
        [-a, a, a, -a, 0.0, 1.0, 0.0, 0.0],
        [a, -a, a, -a, 0.0, 0.0, 1.0, 0.0],
        [y, y, -y, -y, 0.0, 0.0, 0.0, 1.0],
        [0.0, 0.0, 0.0, 0.0, CT, 0.0, 0.0, 0.0],
        [-CT, -CT, -CT, -CT, 0.0, 0.0, 0.0, 0.0],
    ])
    np.testing.assert_allclose(v.problem().B, expected, rtol=1e-15, atol=1e-15)
    assert v.effectors[4].rotor.km == 0.0
    vn = vehicle_from_params(read_params(VTOL), normalize="px4")
    Bn = vn.problem().B
    # matrix 0 (rotors, RPY normalised): roll/pitch/yaw rows as the quad's (1/sqrt 8, 1/4).  Forces, each axis
    # apart (ControlAllocationPseudoInverse.cpp, commit 1316f1cea719): fx only the pusher, |M_fx| = 1 / 6.5, s_x =
    # 1 / 6.5 and its row 6.5 * s_x = 1; fz the four lift rotors, |M_fz| = 1 / (4 * 6.5) each: s_z = 1 / 26, row -1/4.
    # (PX4 commit 089afb091546 shared s = (1/6.5 + 4/(4 * 6.5)) / 5 = 2 / 32.5 for both: rows 0.4 and -0.4.)
    r = 1 / math.sqrt(8)
    np.testing.assert_allclose(Bn[:, :5], np.array([
        [-r, r, r, -r, 0.0], [r, -r, r, -r, 0.0], [0.25, 0.25, -0.25, -0.25, 0.0],
        [0.0, 0.0, 0.0, 0.0, 1.0], [-0.25] * 4 + [0.0]]), rtol=1e-12, atol=1e-15)
    # matrix 1 (surfaces, not RPY normalised, no forces): unchanged
    np.testing.assert_array_equal(Bn[:, 5:], expected[:, 5:])


def test_qgc_params_file_and_load_vehicle(tmp_path):
    lines = ["# Onboard parameters for Vehicle 1", "#", "# Vehicle-Id Component-Id Name Value Type",
             "1\t1\tCA_AIRFRAME\t0\t6", "1\t1\tCA_ROTOR_COUNT\t4\t6", "1\t1\tCA_R2_SLEW\t0.5\t9"]
    for i, (x, y, km) in enumerate([(0.15, 0.15, 0.05), (-0.15, -0.15, 0.05), (0.15, -0.15, -0.05),
                                    (-0.15, 0.15, -0.05)]):
        lines += [f"1\t1\tCA_ROTOR{i}_PX\t{x}\t9", f"1\t1\tCA_ROTOR{i}_PY\t{y}\t9", f"1\t1\tCA_ROTOR{i}_KM\t{km}\t9"]
    path = tmp_path / "quad.params"
    path.write_text("\n".join(lines) + "\n")
    v = alloc.load_vehicle(path)
    assert v.name == "quad"
    np.testing.assert_array_equal(v.problem().B, vehicle_from_params(read_params(QUAD_X)).problem().B)
    assert v.problem().rate_max[2] == 2.0 and math.isinf(v.problem().rate_max[0])  # 1 / 0.5 s
    back = alloc.load_vehicle(v.save(tmp_path / "quad.toml"))
    assert back == v


def test_px4_scales_unit_cases():
    # one rotor straight up: M = pinv = column / |column|^2; force scale |M| = 1/CT
    B6 = np.array([[0.0], [0.0], [0.0], [0.0], [0.0], [-2.0]])
    s = px4_scales(B6, normalize_rpy=True)
    assert s[3:].tolist() == [0.5, 0.5, 0.5] and s[:3].tolist() == [1.0, 1.0, 1.0]


@pytest.mark.parametrize("text, message", [
    ("1\t1\tCA_ROTOR_COUNT\tfour\t6", "params: line 1: CA_ROTOR_COUNT: 'four' is not a number"),
    ("garbage line", "params: line 1: expected"),
    ("1\t1\tCA_ROTOR0_PX\tnan\t9", "params: line 1: CA_ROTOR0_PX: must be finite"),
])
def test_bad_params_lines_are_named(text, message):
    with pytest.raises(ProblemError, match="^" + message.replace("(", r"\(")):
        read_params(text)


@pytest.mark.parametrize("params, message", [
    ({"CA_AIRFRAME": 4, "CA_ROTOR_COUNT": 4}, "CA_AIRFRAME: 4 is not supported"),  # tailsitter
    ({"CA_ROTOR_COUNT": 13}, "CA_ROTOR_COUNT: expected an integer 0..12"),
    ({"CA_ROTOR_COUNT": 0}, "CA_ROTOR_COUNT: the parameters define no rotor"),
    ({"CA_ROTOR_COUNT": 1, "CA_R0_SLEW": -1.0}, "CA_R0_SLEW: must be >= 0"),
    ({"CA_AIRFRAME": 1, "CA_SV_CS_COUNT": 1, "CA_SV_CS0_TRIM": 2.0}, "CA_SV_CS0_TRIM: must be in"),
])
def test_bad_parameters_are_named(params, message):
    with pytest.raises(ProblemError, match="^" + message):
        vehicle_from_params(params)


def test_seeded_random_multirotors_match_the_formula_and_load_back():
    """Hostile geometry: random positions, tilted and zero axes, zero CT, any rotor count."""
    rng = np.random.default_rng(25)
    for _ in range(60):
        n = int(rng.integers(1, 13))
        params: dict = {"CA_ROTOR_COUNT": n}
        for i in range(n):
            for s in ("PX", "PY", "PZ"):
                params[f"CA_ROTOR{i}_{s}"] = float(rng.normal(0, 1))
            if rng.random() < 0.5:
                params[f"CA_ROTOR{i}_AX"], params[f"CA_ROTOR{i}_AY"] = float(rng.normal()), float(rng.normal())
            if rng.random() < 0.05:
                params[f"CA_ROTOR{i}_AX"] = params[f"CA_ROTOR{i}_AY"] = params[f"CA_ROTOR{i}_AZ"] = 0.0
            params[f"CA_ROTOR{i}_CT"] = 0.0 if rng.random() < 0.05 else float(rng.uniform(0.1, 20))
            params[f"CA_ROTOR{i}_KM"] = float(rng.uniform(-0.1, 0.1))
        try:
            v = vehicle_from_params(params, axes="all")
        except ProblemError as exc:  # every rotor skipped: PX4 would have no effectiveness either
            assert "no effector acts" in str(exc)
            continue
        B = v.problem().B
        for i in range(n):
            a = np.array([params.get(f"CA_ROTOR{i}_A{c}", d) for c, d in zip("XYZ", (0.0, 0.0, -1.0))])
            p = np.array([params[f"CA_ROTOR{i}_P{c}"] for c in "XYZ"])
            ct, km = params[f"CA_ROTOR{i}_CT"], params[f"CA_ROTOR{i}_KM"]
            if np.linalg.norm(a) <= np.finfo(np.float32).eps or ct < np.finfo(np.float32).eps:
                assert not B[:, i].any()
                continue
            a = a / np.linalg.norm(a)
            np.testing.assert_allclose(B[:3, i], ct * np.cross(p, a) - ct * km * a, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(B[3:, i], ct * a, rtol=1e-12, atol=1e-12)
        assert alloc.vehicle_file.vehicle_from_dict(v.to_dict()) == v
        vn = vehicle_from_params(params, normalize="px4", axes="all")
        assert np.isfinite(vn.problem().B).all()


def test_hover_thrust_sets_the_fz_trim():
    v = vehicle_from_params({**read_params(HEXA_X), "MPC_THR_HOVER": 0.5})
    assert v.trim.tolist() == [0.0, 0.0, 0.0, -0.5 * 6 * CT]  # six rotors at half command
    vn = vehicle_from_params({**read_params(HEXA_X), "MPC_THR_HOVER": 0.5}, normalize="px4")
    assert vn.trim[-1] == pytest.approx(-0.5)  # normalised: each rotor -1/6
    with pytest.raises(ProblemError, match="^MPC_THR_HOVER: must be in"):
        vehicle_from_params({**read_params(HEXA_X), "MPC_THR_HOVER": 1.5})
