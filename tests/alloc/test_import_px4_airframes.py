"""PX4 airframe files as PX4 ships them: the same B as their bare parameters, by hand, and normalised
as PX4's ControlAllocationPseudoInverse does (an oracle written from its C++ below).

The files in ``data/px4_airframes`` are PX4/PX4-Autopilot's ROMFS airframes byte for byte (paths and
commits in that folder's README).  Every parameter they do not set takes its module.yaml default
(CT 6.5, KM 0.05, axis (0, 0, -1), surface type 1).
"""

from __future__ import annotations

import math
import re
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

import alloc
from alloc.exceptions import ProblemError, SkippedLinesWarning
from alloc.importers.px4 import NO_TORQUE_TYPES, read_params, read_params_report, vehicle_from_params

DATA = Path(__file__).parent / "data" / "px4_airframes"
AIRFRAMES = ["6001_hexa_x", "1103_standard_vtol_sih.hil", "2100_standard_plane"]
CT = 6.5


def bare_parameters(path: Path) -> dict[str, float]:
    """The airframe's parameters written out by hand from its text: every ``param set[-default]`` line,
    ``param set`` over ``param set-default`` (PX4's rule), nothing else."""
    defaults, values = {}, {}
    for line in path.read_text().splitlines():
        m = re.match(r"param (set|set-default) (\w+) (\S+)", line)
        if m:
            (values if m.group(1) == "set" else defaults)[m.group(2)] = float(m.group(3))
    return {**defaults, **values}


def load_quietly(path: Path) -> alloc.vehicle_file.Vehicle:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SkippedLinesWarning)
        return alloc.load_vehicle(path)


@pytest.mark.parametrize("name", AIRFRAMES)
@pytest.mark.parametrize("normalize", ["none", "px4"])
def test_airframe_file_gives_the_B_of_its_bare_parameters(name, normalize):
    path = DATA / name
    read = read_params_report(path)
    assert read.airframe
    from_file = vehicle_from_params(read.params, normalize=normalize)
    from_bare = vehicle_from_params(bare_parameters(path), normalize=normalize)
    np.testing.assert_array_equal(from_file.problem().B, from_bare.problem().B)
    assert from_file.effector_names == from_bare.effector_names
    if normalize == "none":
        np.testing.assert_array_equal(load_quietly(path).problem().B, from_bare.problem().B)


def test_shell_lines_are_skipped_listed_and_warned(tmp_path):
    path = DATA / "1103_standard_vtol_sih.hil"
    read = read_params_report(path)
    assert read.skipped == ((20, ". ${R}etc/init.d/rc.vtol_defaults"),)  # comments and blanks are not listed
    assert read.params["UAVCAN_ENABLE"] == 0 and read.params["CA_ROTOR4_AX"] == 1
    copy = tmp_path / "13000_my_quadplane"  # a name as PX4 names airframes: no extension
    shutil.copy(path, copy)
    with pytest.warns(SkippedLinesWarning, match=r"^13000_my_quadplane: 1 shell line\(s\) skipped \(line 20: "):
        v = alloc.load_vehicle(copy)
    assert "1 shell line(s) skipped" in v.source and v.name == "13000_my_quadplane"
    text = "#!/bin/sh\nset MAV_TYPE 22\nif [ $AUTOCNF = yes ]\nthen\n\tparam set CA_ROTOR_COUNT 1\nfi\n" \
           "param select x.bson\nparam set-default CA_ROTOR_COUNT 4\n"
    read = read_params_report(text)
    assert [n for n, _ in read.skipped] == [2, 3, 4, 6, 7]
    assert read.params["CA_ROTOR_COUNT"] == 1  # 'param set' is the value, 'param set-default' only the default


def test_hexa_x_airframe_by_hand():
    # ActuatorEffectivenessRotors: moment CT (p x a) - CT KM a, thrust CT a, a = (0, 0, -1)
    v = load_quietly(DATA / "6001_hexa_x")
    expected = np.array([
        [-3.25, 3.25, 1.625, -1.625, -1.625, 1.625],
        [0.0, 0.0, 2.795, -2.795, 2.795, -2.795],
        [-0.325, 0.325, -0.325, 0.325, 0.325, -0.325],
        [-CT] * 6,
    ])
    np.testing.assert_allclose(v.problem().B, expected, rtol=1e-14, atol=1e-15)


def test_standard_vtol_sih_airframe_by_hand():
    v = load_quietly(DATA / "1103_standard_vtol_sih.hil")
    # CS0 type 2 (right aileron) TRQ_R 0.5, CS1 type 3 elevator TRQ_P 1, CS2 no type: module.yaml's 1 (left
    # aileron) with TRQ_Y 1 -- as the file ships it
    assert v.effector_names[5:] == ("right_aileron", "elevator", "left_aileron")
    a, y = CT * 0.2, CT * 0.05
    expected = np.array([
        [-a, a, a, -a, 0.0, 0.5, 0.0, 0.0],
        [a, -a, a, -a, 0.0, 0.0, 1.0, 0.0],
        [y, y, -y, -y, 0.0, 0.0, 0.0, 1.0],
        [0.0, 0.0, 0.0, 0.0, CT, 0.0, 0.0, 0.0],  # the pusher: axis (1, 0, 0), not upwards, so KM 0
        [-CT] * 4 + [0.0] * 4,
    ])
    np.testing.assert_allclose(v.problem().B, expected, rtol=1e-15, atol=1e-15)
    vn = vehicle_from_params(read_params(DATA / "1103_standard_vtol_sih.hil"), normalize="px4")
    r = 1 / math.sqrt(8)  # roll, pitch: s = sqrt(|M_col|^2 / (4 / 2)) with M_col = row / |row|^2
    np.testing.assert_allclose(vn.problem().B[:, :5], np.array([
        [-r, r, r, -r, 0.0], [r, -r, r, -r, 0.0], [0.25, 0.25, -0.25, -0.25, 0.0],
        [0.0, 0.0, 0.0, 0.0, 1.0], [-0.25] * 4 + [0.0]]), rtol=1e-12, atol=1e-15)


# ---------------------------------------------------------------------------------------------- oracle
def px4_normalised_mix(B6: np.ndarray, normalize_rpy: bool) -> tuple[np.ndarray, np.ndarray]:
    """PX4's updateControlAllocationMatrixScale + normalizeControlAllocationMatrix, loop by loop in
    float32 as written in src/lib/control_allocation/control_allocation/ControlAllocationPseudoInverse.cpp
    (commit 1316f1cea719): ``(scale, normalised mix before the 1e-3 zeroing)``."""
    f32 = np.float32
    mix = np.linalg.pinv(B6.astype(f32)).astype(f32)
    n = mix.shape[0]
    scale = np.ones(6, dtype=f32)
    eps = np.finfo(f32).eps
    if normalize_rpy:
        nz_roll = sum(1 for i in range(n) if abs(mix[i, 0]) > f32(1e-3))
        nz_pitch = sum(1 for i in range(n) if abs(mix[i, 1]) > f32(1e-3))
        roll_s = math.sqrt(float(np.sum(mix[:, 0] ** 2)) / (nz_roll / 2.0)) if nz_roll else 1.0
        pitch_s = math.sqrt(float(np.sum(mix[:, 1] ** 2)) / (nz_pitch / 2.0)) if nz_pitch else 1.0
        scale[0] = scale[1] = max(roll_s, pitch_s)
        scale[2] = mix[:, 2].max()
    scale[5] = 1.0
    for axis_idx in (2, 1, 0):
        norm_sum, count = f32(0), 0
        for i in range(n):
            norm = abs(mix[i, 3 + axis_idx])
            norm_sum += norm
            count += norm > eps
        scale[3 + axis_idx] = norm_sum / count if count else scale[5]
    out = mix.copy()
    if scale[0] > eps:
        out[:, 0] /= scale[0]
        out[:, 1] /= scale[1]
    if scale[2] > eps:
        out[:, 2] /= scale[2]
    if scale[3] > eps:
        out[:, 3:6] /= scale[3:6]
    return scale, out


@pytest.mark.parametrize("name", AIRFRAMES)
def test_px4_normalisation_matches_the_oracle(name):
    params = read_params(DATA / name)
    six = vehicle_from_params(params, axes="all")  # physical, PX4's six rows
    ours = vehicle_from_params(params, normalize="px4", axes="all").problem().B
    airframe = int(params.get("CA_AIRFRAME", 0))
    rotors = [j for j, e in enumerate(six.effectors) if e.kind == "rotor"]
    surfaces = [j for j, e in enumerate(six.effectors) if e.kind == "surface"]
    # PX4's matrices: a fixed-wing has one (not RPY-normalised); a multirotor one, a standard VTOL two
    matrices = [(rotors + surfaces, False)] if airframe == 1 else [(rotors, True)] + ([(surfaces, False)] if
                                                                                     surfaces else [])
    B = six.problem().B
    for cols, rpy in matrices:
        scale, mix = px4_normalised_mix(B[:, cols], rpy)
        # the normalised B is diag(s) B: PX4's normalised mix is its pseudo-inverse wherever B has full row rank
        np.testing.assert_allclose(ours[:, cols], scale.astype(float)[:, None] * B[:, cols], rtol=2e-6, atol=1e-7)
        rows = np.flatnonzero(np.abs(B[:, cols]).sum(axis=1))
        np.testing.assert_allclose(ours[np.ix_(rows, cols)] @ mix[:, rows], np.eye(len(rows)), atol=5e-6)


def test_surface_types_px4_zeroes_get_no_torque():
    params = {"CA_AIRFRAME": 1, "CA_SV_CS_COUNT": 8}
    types = [9, 10, 11, 13, 14, 16, 17, 18]  # flaps, airbrake, A-tails, steering wheel, spoilers
    for i, t in enumerate(types):
        params |= {f"CA_SV_CS{i}_TYPE": t, f"CA_SV_CS{i}_TRQ_R": 0.25, f"CA_SV_CS{i}_TRQ_P": 0.5,
                   f"CA_SV_CS{i}_TRQ_Y": -0.5}
    v = vehicle_from_params(params, axes="all")
    assert v.effector_names == ("left_flap", "right_flap", "airbrake", "left_a_tail", "right_a_tail",
                                "steering_wheel", "left_spoiler", "right_spoiler")
    B = v.problem().B
    for j, t in enumerate(types):
        expected = [0.0] * 6 if t in NO_TORQUE_TYPES else [0.25, 0.5, -0.5, 0.0, 0.0, 0.0]
        assert B[:, j].tolist() == expected, t
    assert set(NO_TORQUE_TYPES) == {9, 10, 11, 16, 17, 18}


def test_a_parameter_the_importer_does_not_read_may_be_set_twice():
    # as an old 13014_vtol_babyshark does (MPC_JERK_AUTO 8, then 15): PX4's shell keeps the last
    text = "#!/bin/sh\nparam set MPC_JERK_AUTO 8\nparam set MPC_JERK_AUTO 15\nparam set-default CA_ROTOR_COUNT 4\n"
    read = read_params_report(text)
    assert read.params["MPC_JERK_AUTO"] == 15 and read.overridden == ((3, "MPC_JERK_AUTO"),)
    assert "MPC_JERK_AUTO at line 3" in read.skipped_summary()
    with pytest.raises(ProblemError, match=r"^params: line 3: CA_ROTOR_COUNT is set again \(first at line 2\)"):
        read_params("#!/bin/sh\nparam set-default CA_ROTOR_COUNT 4\nparam set-default CA_ROTOR_COUNT 6\n")


@pytest.mark.parametrize("text, message", [
    ("param set-default CA_ROTOR_COUNT 4\nparam set-default CA_ROTOR_COUNT 6\n",
     "params: line 2: CA_ROTOR_COUNT is set again (first at line 1)"),
    ("#!/bin/sh\nparam set-default CA_ROTOR0_PX\n", "params: line 2: expected 'param set-default NAME value'"),
    ("#!/bin/sh\nparam set-default CA_ROTOR0_PX ${X}\n", "params: line 2: CA_ROTOR0_PX: '${X}' is not a number"),
    ("param set-default CA_ROTOR0_PX 1e400\n", "params: line 1: CA_ROTOR0_PX: must be finite"),
    ("param set-default CA_ROTOR0_PX_WITH_A_LONG_NAME 1\n", "params: line 1: 'CA_ROTOR0_PX_WITH_A_LONG_NAME' is not"),
])
def test_bad_airframe_lines_are_named(text, message):
    with pytest.raises(ProblemError, match="^" + re.escape(message)):
        read_params(text)


def test_a_file_that_is_no_airframe_is_refused_naming_the_path(tmp_path):
    path = tmp_path / "13000_not_an_airframe"
    path.write_text("set MAV_TYPE 22\n")
    with pytest.raises(ProblemError, match="^path: 13000_not_an_airframe has no extension and is not a PX4 airframe"):
        alloc.load_vehicle(path)
