"""Scheduled effectiveness (format alloc-vehicle/1.2) and the PX4 tiltrotor VTOL as PX4 ships it.

``13100_generic_vtol_tiltrotor`` (PX4 ROMFS, commit c564d3131a5f; data/px4_airframes/README.md): four
rotors at (+-1, +-1) m, CT 6.5, KM +-0.05; rotor 0 (front right) tilted by tilt servo 2, rotor 2 (front
left) by tilt servo 1, rotors 1 and 3 fixed; two tilt servos at module.yaml's defaults (0..90 deg, towards
the front, used for yaw); four surfaces.  PX4's tiltrotor rules (alloc/importers/px4_tiltrotor.py): yaw row
of the rotors 0 when tilts yaw, thrust rows (0, 0, -CT) whatever the tilt, surfaces x (V / 15)^2 with V in
[7, 20] m/s (FW_AIRSPD_TRIM, _STALL, _MAX defaults).
"""

from __future__ import annotations

import json
import math
import re
import warnings
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import alloc
from alloc.cli import app
from alloc.exceptions import ProblemError, SkippedLinesWarning
from alloc.importers.px4 import read_params, vehicle_from_params
from alloc.importers.px4_tiltrotor import tilted_axis
from alloc.vehicle_file import SCHEMA_PATH, vehicle_from_dict

AIRFRAME = Path(__file__).parent / "data" / "px4_airframes" / "13100_generic_vtol_tiltrotor"
CT, KM = 6.5, 0.05


@pytest.fixture(scope="module")
def params():
    return read_params(AIRFRAME)


def transition(steps: int = 41, cruise: float = 18.0):
    """The brief's path: tilt 90 -> 0 deg while the airspeed goes 0 -> cruise; and PX4's forward one."""
    back = [{"tilt": t, "airspeed": v} for t, v in zip(np.linspace(90, 0, steps), np.linspace(0, cruise, steps))]
    forward = [{"tilt": t, "airspeed": v} for t, v in zip(np.linspace(0, 90, steps), np.linspace(0, cruise, steps))]
    return back + forward


@pytest.mark.parametrize("normalize", ["none", "px4"])
def test_schedule_agrees_with_a_rebuild_at_every_step(params, normalize):
    vehicle = vehicle_from_params(params, normalize=normalize)
    assert vehicle.schedule.names == ("tilt", "airspeed")
    scheduled = vehicle.scheduled()
    for x in transition():
        rebuilt = vehicle_from_params(params, normalize=normalize, at=x)
        assert rebuilt.schedule is None
        np.testing.assert_allclose(scheduled.evaluate(x), rebuilt.problem().B, rtol=0, atol=1e-13, err_msg=str(x))
        np.testing.assert_allclose(vehicle.problem_at(x).B, rebuilt.problem().B, rtol=0, atol=1e-13)


def test_tiltrotor_by_hand_in_hover_and_cruise(params):
    v = vehicle_from_params(params)
    assert v.effector_names == ("motor1", "motor2", "motor3", "motor4", "left_aileron", "right_aileron",
                                "left_v_tail", "right_v_tail", "tilt1", "tilt2")
    assert v.axis_names == ("roll", "pitch", "yaw", "fz")
    a = CT * 1.0
    # hover (tilt 0, the nominal): the quad X; yaw row 0 for the rotors (tilts yaw); the tilt servos yaw
    # +1 (tilt1 turns rotor 2, left: y = -1) and -1 (tilt2 turns rotor 0, right); surfaces at trim speed, x 1
    hover = np.array([
        [-a, a, a, -a, -0.5, 0.5, 0.0, 0.0, 0.0, 0.0],
        [a, -a, a, -a, 0.0, 0.0, 0.5, 0.5, 0.0, 0.0],
        [0.0] * 6 + [0.5, -0.5, 1.0, -1.0],
        [-CT] * 4 + [0.0] * 6,
    ])
    np.testing.assert_allclose(v.problem().B, hover, atol=1e-15)
    # cruise (tilt 90: rotors 0 and 2 point forward, a = (1, 0, 0)); V = 30 m/s held to 20: x (20/15)^2.
    # rotor 0 at (1, 1), KM 0.05: p x a = (0, 0, -1) -> moment (-0.325, 0, -6.5), yaw zeroed;
    # rotor 2 at (1, -1), KM -0.05: p x a = (0, 0, 1) -> (0.325, 0, 6.5), yaw zeroed; thrust rows stay -CT
    k = (20 / 15) ** 2
    cruise = hover.copy()
    cruise[:2, 0] = (-CT * KM, 0.0)
    cruise[:2, 2] = (CT * KM, 0.0)
    cruise[:3, 4:8] *= k
    np.testing.assert_allclose(v.problem_at({"tilt": 90, "airspeed": 30}).B, cruise, atol=1e-14)
    # below stall speed the surfaces keep the stall speed's effect (PX4 holds V to FW_AIRSPD_STALL)
    slow = v.problem_at({"tilt": 0, "airspeed": 0}).B
    np.testing.assert_allclose(slow[:3, 4:8], hover[:3, 4:8] * (7 / 15) ** 2, atol=1e-15)


def test_tilted_axis_is_pxs_euler_rotation():
    # tiltedAxis: Dcm(Euler(0, -angle, direction)) (0, 0, -1); up at 0, forward at 90, right at 90 / 90
    np.testing.assert_allclose(tilted_axis(0, 0), [0, 0, -1], atol=1e-16)
    np.testing.assert_allclose(tilted_axis(90, 0), [1, 0, 0], atol=1e-16)
    np.testing.assert_allclose(tilted_axis(90, 90), [0, 1, 0], atol=1e-16)
    t = math.radians(30)
    np.testing.assert_allclose(tilted_axis(30, 0), [math.sin(t), 0, -math.cos(t)], atol=1e-16)


def test_px4_normalisation_scales_are_the_hovers(params):
    # PX4 computes the scales with the tilts at their minimum and keeps them: at tilt 0 the normalised
    # matrix 0 is the quad's (roll 1/sqrt 8 .. with the yaw of the tilts), and every point is diag(s) B(x)
    vn, v = vehicle_from_params(params, normalize="px4"), vehicle_from_params(params)
    B, Bn = np.array(v.B)[:, :4], np.array(vn.B)[:, :4]
    # each row's scale from its first non-zero entry (the rotors' yaw row is 0: any scale does)
    s = np.array([bn[np.flatnonzero(b)[0]] / b[np.flatnonzero(b)[0]] if b.any() else 1.0 for b, bn in zip(B, Bn)])
    for x in transition(9):
        np.testing.assert_allclose(vn.problem_at(x).B[:, :4], s[:, None] * v.problem_at(x).B[:, :4], atol=1e-14)
    assert s[0] == pytest.approx(1 / (CT * math.sqrt(8)))  # the quad X's roll scale
    assert s[3] == pytest.approx(1 / (4 * CT))  # thrust: each rotor 1/(4 CT)


def test_scheduled_vehicle_file_round_trip_and_schema(params, tmp_path):
    v = vehicle_from_params(params, name="tiltrotor")
    doc = v.to_dict()
    assert doc["format"] == "alloc-vehicle/1.2"
    assert vehicle_from_dict(json.loads(json.dumps(doc))) == v
    for suffix in (".toml", ".json"):
        back = alloc.load_vehicle(v.save(tmp_path / f"t{suffix}"))
        assert back == v
        np.testing.assert_array_equal(back.problem_at({"tilt": 37.5}).B, v.problem_at({"tilt": 37.5}).B)
    jsonschema_rs = pytest.importorskip("jsonschema_rs")
    validator = jsonschema_rs.validator_for(json.loads(SCHEMA_PATH.read_text()))
    assert validator.is_valid(doc)
    assert not validator.is_valid({**doc, "format": "alloc-vehicle/1.1"})


def _small_doc(**schedule):
    return {"format": "alloc-vehicle/1.2", "name": "s", "axes": [{"name": "roll"}, {"name": "pitch"}],
            "effectors": [{"name": "a", "min": -1, "max": 1}, {"name": "b", "min": -1, "max": 1}],
            "effectiveness": {"B": [[1.0, 0.0], [0.0, 1.0]]},
            "schedule": {"variables": [{"name": "q", "unit": "rad", "min": 0, "max": 2, "nominal": 1}],
                         "terms": [{"factor": "linear", "variable": "q", "B": [[1.0, 0.0], [0.0, 0.0]]}],
                         **schedule}}


def test_schedule_semantics_by_hand():
    v = vehicle_from_dict(_small_doc())
    # B(q) = B + (q - 1) * T: at the nominal q = 1 the file's B; at q = 2, B[0][0] = 2; at 0, 0
    assert v.problem_at({"q": 2.0}).B[0].tolist() == [2.0, 0.0]
    assert v.problem_at({"q": 0.0}).B[0].tolist() == [0.0, 0.0]
    assert v.problem_at({}).B.tolist() == [[1.0, 0.0], [0.0, 1.0]]
    sq = vehicle_from_dict(_small_doc(terms=[{"factor": "square", "variable": "q", "scale": 2.0, "clamp": [0.5, 1.5],
                                              "B": [[0.0, 1.0], [0.0, 0.0]]}]))
    # f = (2 clamp(q))^2: nominal 4; q = 2 -> clamp 1.5 -> 9: B[0][1] = 0 + (9 - 4) = 5
    assert sq.problem_at({"q": 2.0}).B[0, 1] == pytest.approx(5.0)
    cos = vehicle_from_dict(_small_doc(terms=[{"factor": "cos", "variable": "q", "B": [[0.0, 0.0], [1.0, 0.0]]}]))
    assert cos.problem_at({"q": 0.0}).B[1, 0] == pytest.approx(1.0 - math.cos(1.0))  # radians: unit is "rad"


@pytest.mark.parametrize("change, message", [
    ({"format": "alloc-vehicle/1.1"}, "schedule: the [schedule] section needs format = 'alloc-vehicle/1.2'"),
    ({"schedule": {"variables": [], "terms": []}}, "schedule.variables: expected at least 1 entries"),
    ({"terms": [{"factor": "exp", "variable": "q", "B": [[0, 0], [0, 0]]}]}, "schedule.terms[0].factor: expected one"),
    ({"terms": [{"factor": "sin", "variable": "z", "B": [[0, 0], [0, 0]]}]}, "schedule.terms[0].variable: unknown 'z'"),
    ({"terms": [{"factor": "sin", "variable": "q", "B": [[0, 0]]}]}, "schedule.terms[0].B: expected 2 entries"),
    ({"variables": [{"name": "q", "min": 0, "max": 2, "nominal": 3}]}, "schedule.variables[0].nominal: must be in"),
    ({"terms": [{"factor": "square", "variable": "q", "scale": 1e30, "B": [[1, 0], [0, 0]]}]},
     "schedule.terms[0]: f * B exceeds"),
    ({"terms": [{"factor": "linear", "variable": "q", "clamp": [2, 1], "B": [[1, 0], [0, 0]]}]},
     "schedule.terms[0].clamp: expected [low, high]"),
])
def test_bad_schedules_are_named(change, message):
    doc = _small_doc()
    if "format" in change or "schedule" in change:
        doc.update(change)
    else:
        doc["schedule"].update(change)
    with pytest.raises(ProblemError, match="^" + re.escape(message)):
        vehicle_from_dict(doc)


def test_bad_values_are_named(params):
    v = vehicle_from_params(params)
    for values, message in [({"tilt": 91}, r"^tilt: must be in \[0, 90\] deg"),
                            ({"tilt": float("nan")}, r"^tilt: must be in"),
                            ({"speed": 3}, r"^schedule: unknown variable 'speed'"),
                            ({"airspeed": "fast"}, r"^airspeed: expected a number")]:
        with pytest.raises(ProblemError, match=message):
            v.problem_at(values)
    with pytest.raises(ProblemError, match=r"^tilt: must be a number in \[0, 90\]"):
        vehicle_from_params(params, at={"tilt": -5})
    with pytest.raises(ProblemError, match="^at: only a tiltrotor"):
        vehicle_from_params({"CA_ROTOR_COUNT": 4}, at={"tilt": 10})
    with pytest.raises(ProblemError, match="^schedule: vehicle 'hexa-x' declares no"):
        alloc.load_vehicle("hexa-x").scheduled()


def test_tilts_with_different_ranges_schedule_the_collective(params):
    p = {**params, "CA_SV_TL1_MINA": -10.0, "CA_SV_TL1_MAXA": 80.0}
    v = vehicle_from_params(p)
    assert v.schedule.names == ("collective_tilt", "airspeed")
    for c in np.linspace(-1, 1, 9):
        x = {"collective_tilt": float(c), "airspeed": 12.0}
        np.testing.assert_allclose(v.problem_at(x).B, vehicle_from_params(p, at=x).problem().B, atol=1e-13)


def test_cli_allocates_at_a_scheduled_point(tmp_path):
    path = tmp_path / "13100_generic_vtol_tiltrotor"
    path.write_bytes(AIRFRAME.read_bytes())
    res = CliRunner().invoke(app, ["allocate", "--vehicle", str(path), "--v", "0,0.5,0,-13", "--at", "tilt=60",
                                   "--at", "airspeed=12", "--json"])
    assert res.exit_code == 0, res.stderr
    u = np.array(json.loads(res.stdout)["u"])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SkippedLinesWarning)
        B = vehicle_from_params(read_params(AIRFRAME), at={"tilt": 60, "airspeed": 12}).problem().B
    np.testing.assert_allclose(B @ u, [0, 0.5, 0, -13], atol=1e-9)
    assert res.stderr.startswith("note: --vehicle ")  # the skipped shell line, after success
    bad = CliRunner().invoke(app, ["allocate", "--vehicle", str(path), "--v", "0,0,0,-13", "--at", "tilt=95"])
    lines = [line for line in bad.stderr.splitlines() if line.strip()]
    assert bad.exit_code == 2 and len(lines) == 1 and "tilt: must be in [0, 90]" in lines[0], bad.stderr


def _mutate_schedule(doc: dict, rng: np.random.Generator) -> dict:
    """One hostile change to the [schedule] of ``doc`` (a copy): a value, a key, a shape or a count."""
    doc = json.loads(json.dumps(doc))
    sched = doc["schedule"]
    bad_values = [float("nan"), float("inf"), 1e400, 1e60, "x", True, None, [], {}, -1e51]
    op = int(rng.integers(7))
    if op == 0:  # a bad number somewhere in a variable
        var = sched["variables"][int(rng.integers(len(sched["variables"])))]
        var[str(rng.choice(["min", "max", "nominal"]))] = bad_values[int(rng.integers(len(bad_values)))]
    elif op == 1:  # a bad entry of a term's matrix
        term = sched["terms"][int(rng.integers(len(sched["terms"])))]
        term["B"][int(rng.integers(len(term["B"])))][0] = bad_values[int(rng.integers(len(bad_values)))]
    elif op == 2:  # a missing or unknown key
        target = sched["terms"][0] if rng.random() < 0.5 else sched["variables"][0]
        if rng.random() < 0.5:
            target.pop(str(rng.choice(sorted(target))))
        else:
            target["surprise"] = 1
    elif op == 3:  # a wrong shape
        term = sched["terms"][int(rng.integers(len(sched["terms"])))]
        term["B"] = term["B"][:-1] if rng.random() < 0.5 else [row[:-1] for row in term["B"]]
    elif op == 4:  # too many terms or variables
        key = str(rng.choice(["terms", "variables"]))
        sched[key] = sched[key] * 20
    elif op == 5:  # a factor, variable or clamp that is not one
        term = sched["terms"][int(rng.integers(len(sched["terms"])))]
        term[str(rng.choice(["factor", "variable", "clamp", "scale"]))] = bad_values[int(rng.integers(len(bad_values)))]
    else:  # a huge scale: the factor leaves 1e50 within the range
        sched["terms"][-1]["scale"] = float(rng.choice([1e20, 1e26, -1e30]))
    return doc


@pytest.mark.parametrize("seed", range(60))
def test_hostile_schedules_are_refused_by_field_or_evaluate_finite(params, seed):
    rng = np.random.default_rng(seed)
    doc = _mutate_schedule(vehicle_from_params(params).to_dict(), rng)
    try:
        v = vehicle_from_dict(doc)
    except ProblemError as exc:
        assert str(exc).startswith(("schedule", "format")) and exc.field.startswith(("schedule", "format")), str(exc)
        return
    for _ in range(5):
        x = {var.name: float(rng.uniform(var.min, var.max)) for var in v.schedule.variables}
        assert np.isfinite(v.scheduled().evaluate(x)).all()


def test_evaluate_into_the_callers_array_leaves_the_buffer_alone(params):
    v = vehicle_from_params(params)
    ev = v.scheduled()
    inside = ev.evaluate({"tilt": 10.0})
    before = inside.copy()
    out = np.empty_like(before)
    got = ev.evaluate({"tilt": 80.0, "airspeed": 19.0}, out=out)
    assert np.shares_memory(got, out) and np.array_equal(inside, before)  # the object's buffer unchanged
    np.testing.assert_allclose(out, vehicle_from_params(params, at={"tilt": 80.0, "airspeed": 19.0}).problem().B,
                               atol=1e-13)
