"""The vehicle file's [body] table (alloc.vehicle_file.body) and the hover model derived from it.

Reference numbers are hexa-x's, by hand from its file: roll row ``-CT y / Ixx`` (motor1 at y = 0.5 m:
-6.5 x 0.5 / 0.08 = -40.625 rad/s^2), pitch ``CT x / Iyy`` (motor3 at x = 0.43: 34.9375), yaw
``CT KM / Izz`` (6.5 x 0.05 / 0.15), heave ``-CT / m`` (-3.25 m/s^2).
"""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

from alloc.cli import app
from alloc.exceptions import AllocError
from alloc.vehicle_file import load_vehicle, to_toml, vehicle_from_dict
from multirotor_files import hexa_document

runner = CliRunner()


def test_hexa_x_body_gives_its_model_exactly():
    v = load_vehicle("hexa-x")
    derived = vehicle_from_dict(hexa_document(mass=2.0, inertia=[0.08, 0.08, 0.15]))
    assert derived.model_derived and not v.model_derived
    B = np.array(derived.model.B)
    assert B[3, 0] == -40.625 and B[4, 2] == 34.9375
    assert B[5, 1] == pytest.approx(6.5 * 0.05 / 0.15, rel=1e-15) and B[6, 0] == -3.25
    for name in ("A", "B", "C", "D"):
        np.testing.assert_array_equal(np.array(getattr(derived.model, name)), np.array(getattr(v.model, name)))
    assert derived.model.controlled == ("p", "q", "r", "w")


def test_full_inertia_matrix_couples_roll_and_yaw():
    J = [[0.08, 0.0, -0.01], [0.0, 0.08, 0.0], [-0.01, 0.0, 0.15]]
    v = vehicle_from_dict(hexa_document(mass=2.0, inertia=J))
    B = np.array(v.model.B)
    moments = np.array(v.B)[:3]
    np.testing.assert_allclose(np.array(J) @ B[3:6], moments, rtol=0, atol=1e-12)
    assert B[5, 0] != 0.0 and not v.body.diagonal  # a product of inertia: roll moments accelerate yaw


def test_body_round_trips_without_writing_the_derived_model(tmp_path):
    v = vehicle_from_dict(hexa_document())
    doc = v.to_dict()
    assert "model" not in doc and doc["body"]["rotor_speed_max"] == 900.0
    assert vehicle_from_dict(doc) == v
    path = tmp_path / "hexa.toml"
    v.save(path)
    assert load_vehicle(path) == v
    kept = load_vehicle("hexa-x")  # a file with both keeps its own [model] and writes it back
    assert "model" in kept.to_dict() and vehicle_from_dict(kept.to_dict()) == kept


@pytest.mark.parametrize("field, body", [
    ("body.mass", {"mass": -2.0, "inertia": [0.1, 0.1, 0.2]}),
    ("body.mass", {"inertia": [0.1, 0.1, 0.2]}),
    ("body.inertia", {"mass": 2.0, "inertia": [0.1, 0.1]}),
    ("body.inertia[1]", {"mass": 2.0, "inertia": [0.1, 0.0, 0.2]}),
    ("body.inertia", {"mass": 2.0, "inertia": [[0.1, 0.2, 0], [0, 0.1, 0], [0, 0, 0.2]]}),
    ("body.inertia", {"mass": 2.0, "inertia": [[0.1, 0.2, 0], [0.2, 0.1, 0], [0, 0, 0.2]]}),
    ("body.inertia", {"mass": 2.0, "inertia": [0.01, 0.01, 0.2]}),
    ("body.inertia[0]", {"mass": 2.0, "inertia": ["a", 0.1, 0.2]}),
    ("body.thrust_coefficient", {"mass": 2.0, "inertia": [0.1, 0.1, 0.2], "rotor_speed_max": 900.0,
                                 "thrust_coefficient": 1e-5}),
    ("body.torque_coefficient", {"mass": 2.0, "inertia": [0.1, 0.1, 0.2], "torque_coefficient": 1e-7}),
    ("body.torque_coefficient", {"mass": 2.0, "inertia": [0.1, 0.1, 0.2], "thrust_coefficient": 6.5 / 900**2,
                                 "torque_coefficient": 1e-7}),
    ("body.motor_time_constant", {"mass": 2.0, "inertia": [0.1, 0.1, 0.2], "motor_time_constant": 0.0}),
    ("body.colour", {"mass": 2.0, "inertia": [0.1, 0.1, 0.2], "colour": "red"}),
])
def test_bad_body_names_its_field(field, body):
    with pytest.raises(AllocError) as info:
        vehicle_from_dict(hexa_document(**body))
    assert isinstance(info.value, ValueError)
    assert info.value.field == field, str(info.value)
    assert str(info.value).startswith(field)


def test_consistent_coefficients_are_accepted():
    k_eta = 6.5 / 900.0**2
    v = vehicle_from_dict(hexa_document(mass=2.0, inertia=[0.08, 0.08, 0.15], thrust_coefficient=k_eta,
                                        torque_coefficient=0.05 * k_eta, motor_time_constant=0.03))
    assert v.body.rotor_speed_max_for(6.5) == pytest.approx(900.0, rel=1e-12)


def test_hover_model_needs_the_four_hover_axes():
    doc = hexa_document()
    doc["axes"][2] = {"name": "side", "unit": "N", "wrench": "fy"}
    with pytest.raises(AllocError) as info:
        vehicle_from_dict(doc)
    assert info.value.field == "axes[2].wrench"


def _bar_file(tmp_path):
    doc = hexa_document(mass=2.0, inertia=[0.02, 0.02, 0.04])
    doc.pop("methods", None)
    path = tmp_path / "my-hexa.toml"
    path.write_text(to_toml(doc))
    return path


def test_a_body_only_hexacopter_flies_alloc_sim(tmp_path):
    # the bar, shortened: a [body] with mass and inertia, no [model], no [simulation]
    res = runner.invoke(app, ["sim", "--vehicle", str(_bar_file(tmp_path)), "--failure", "float:motor1", "--health",
                              "told", "--duration", "2", "--failure-time", "1"])
    assert res.exit_code == 0, res.output


@pytest.mark.slow
def test_a_body_only_hexacopter_flies_alloc_sim_20_s(tmp_path):
    res = runner.invoke(app, ["sim", "--vehicle", str(_bar_file(tmp_path)), "--failure", "float:motor1", "--health",
                              "told"])
    assert res.exit_code == 0, res.output
