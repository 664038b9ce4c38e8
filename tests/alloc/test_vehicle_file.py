"""Vehicle files (alloc.vehicle_file): the seed's aircraft bit for bit, round trips, errors naming paths."""

from __future__ import annotations

import json
import math
import random
import tomllib

import numpy as np
import pytest

import alloc
from alloc import vehicles
from alloc.exceptions import ProblemError
from alloc.vehicle_file import (
    FORMAT, SCHEMA_PATH, Dynamics, LinearModel, load_vehicle, rotor_wrench, to_toml, vehicle_from_dict,
    vehicle_names,
)

from vehicle_documents import mutate

PROBLEM_FIELDS = ("B", "umin", "umax", "up", "Wu", "Wv", "rate_min", "rate_max")


def assert_same_problem(p: alloc.Problem, q: alloc.Problem) -> None:
    for f in PROBLEM_FIELDS:
        a, b = getattr(p, f), getattr(q, f)
        assert a.dtype == b.dtype and a.shape == b.shape, f
        assert np.array_equal(a, b), f  # bit for bit: equal floats, inf where inf
        assert a.tobytes() == b.tobytes(), f
    assert p.names == q.names and p.axes == q.axes


def hexa_doc() -> dict:
    """A hexacopter described by rotor geometry (PX4 6001_hexa_x positions, CT 6.5, KM +-0.05)."""
    xy = [(0.0, 0.5, -0.05), (0.0, -0.5, 0.05), (0.43, -0.25, -0.05), (-0.43, 0.25, 0.05),
          (0.43, 0.25, 0.05), (-0.43, -0.25, -0.05)]
    return {
        "format": FORMAT, "name": "hexa",
        "axes": [{"name": "roll", "unit": "N m"}, {"name": "pitch", "unit": "N m"}, {"name": "yaw", "unit": "N m"},
                 {"name": "thrust", "unit": "N", "wrench": "fz", "trim": -19.5}],
        "effectors": [{"name": f"m{i + 1}", "kind": "rotor", "min": 0.0, "max": 1.0, "rate_max": 10.0,
                       "dynamics": {"bandwidth": 40.0, "delay": 0.005},
                       "rotor": {"position": [x, y, 0.0], "ct": 6.5, "km": km}} for i, (x, y, km) in enumerate(xy)],
        "methods": {"daisy": {"groups": [["m1", "m2", "m3"], ["m4", "m5", "m6"]]}},
    }


# --------------------------------------------------------------------------- the seed's aircraft
@pytest.mark.parametrize("name", vehicles.SEED_NAMES)
def test_seed_vehicle_file_is_the_catalogue_problem_bit_for_bit(name):
    v = load_vehicle(name)
    assert_same_problem(v.problem(), vehicles.problem(name))
    assert_same_problem(v.problem(), vehicles.bundled(name).problem())
    assert v.method_options("daisy") == {"groups": vehicles.daisy_groups(name)}


EXAMPLES = ("hexa-x", "tailless", "x57-dep")


def test_every_catalogue_entry_has_a_file_and_back():
    assert vehicle_names() == sorted([*vehicles.SEED_NAMES, *EXAMPLES])


def test_tailless_example_is_ice_on_its_eight_surfaces():
    ice, v = vehicles.problem("ice"), load_vehicle("tailless")
    cols = [ice.names.index(n) for n in v.effector_names]
    assert v.effector_names == ("elevon_l", "elevon_r", "amt_l", "amt_r", "ssd_l", "ssd_r", "lef_l", "lef_r")
    expected = alloc.Problem(ice.B[:, cols], ice.umin[cols], ice.umax[cols], rate_min=ice.rate_min[cols],
                             rate_max=ice.rate_max[cols], names=v.effector_names, axes=ice.axes)
    assert_same_problem(v.problem(), expected)
    A, B, C, D = v.model.arrays()
    full = load_vehicle("ice").model.arrays()
    assert np.array_equal(A, full[0]) and np.array_equal(B, full[1][:, cols]) and np.array_equal(D, full[3][:, cols])


def test_hexa_example_hover_model_and_priorities():
    v = load_vehicle("hexa-x")
    p = v.problem()
    A, B, C, D = v.model.arrays()
    # p' = roll / Ixx, w' = thrust / m (hover, small angles)
    np.testing.assert_array_equal(B[3], p.B[0] / 0.08)
    np.testing.assert_array_equal(B[6], p.B[3] / 2.0)
    assert v.trim.tolist() == [0.0, 0.0, 0.0, -19.62]
    assert v.method_options("qp") == {"priorities": [2, 2, 1, 3]}  # yaw gives way first, thrust last
    assert v.effectors[0].dynamics.transfer_function() == ((30.0,), (1.0, 30.0))


def test_seed_ice_model_is_the_simulator_model():
    ice = pytest.importorskip("sim.scenarios.ice")
    A, B, C, D = load_vehicle("ice").model.arrays()
    for mine, theirs in ((A, ice.A), (B, ice.B), (C, ice.C), (D, ice.D)):
        assert np.array_equal(mine, theirs)
    # the allocation rows of the ICE problem are rows of the model's B (seed section 4.7)
    assert np.array_equal(load_vehicle("ice").problem().B, B[[1, 5, 4]])


# --------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("name", [*vehicles.SEED_NAMES, *EXAMPLES, "hexa"])
def test_round_trips_toml_json_dict(name, tmp_path):
    v = vehicle_from_dict(hexa_doc()) if name == "hexa" else load_vehicle(name)
    assert vehicle_from_dict(v.to_dict()) == v
    assert vehicle_from_dict(json.loads(json.dumps(v.to_dict()))) == v
    for suffix in (".toml", ".json"):
        back = load_vehicle(v.save(tmp_path / f"v{suffix}"))
        assert back == v
        assert_same_problem(back.problem(), v.problem())
    p = v.problem()
    assert_same_problem(alloc.Problem(**{k: val for k, val in p.to_dict().items()}), p)


def test_rotor_columns_are_px4_formula_by_hand():
    v = vehicle_from_dict(hexa_doc())
    B = np.array(v.B)
    # rotor 1 at (0, 0.5, 0), axis (0, 0, -1), ct 6.5, km -0.05 (PX4 6001_hexa_x):
    # p x a = (0.5 * -1 - 0, 0 - 0 * -1, 0) = (-0.5, 0, 0); moment = 6.5 * (-0.5, 0, 0) + 6.5 * 0.05 * (0, 0, -1)
    assert B[:, 0].tolist() == pytest.approx([-3.25, 0.0, -0.325, -6.5], abs=1e-15)
    # rotor 3 at (0.43, -0.25): p x a = (0.25, 0.43, 0); km -0.05 -> yaw -0.325
    assert B[:, 2].tolist() == pytest.approx([1.625, 2.795, -0.325, -6.5], abs=1e-15)
    assert v.trim.tolist() == [0.0, 0.0, 0.0, -19.5]
    assert rotor_wrench([1, 2, 3], [0, 0, 0], 1.0, 0.0).tolist() == [0.0] * 6  # PX4 skips a zero axis


def test_per_effector_columns_and_dynamics():
    doc = {"format": FORMAT, "name": "t", "axes": [{"name": "a"}, {"name": "b"}],
           "effectors": [{"name": "u", "min": -1, "max": 1, "effectiveness": [1.0, 2.0],
                          "dynamics": {"wn": 10.0, "zeta": 0.5}},
                         {"name": "w", "min": -2, "max": 2, "rate_max": 3.0, "rate_min": -1.0,
                          "effectiveness": [0.0, -1.0], "dynamics": {"poles": [2.0, 5.0]}}]}
    v = vehicle_from_dict(doc)
    p = v.problem()
    assert p.B.tolist() == [[1.0, 0.0], [2.0, -1.0]]
    assert p.rate_min.tolist() == [-math.inf, -1.0] and p.rate_max.tolist() == [math.inf, 3.0]
    assert v.effectors[0].dynamics.transfer_function() == ((100.0,), (1.0, 10.0, 100.0))
    assert v.effectors[1].dynamics.transfer_function() == ((10.0,), (1.0, 7.0, 10.0))
    assert Dynamics(time_constant=0.1).transfer_function() == ((1.0,), (0.1, 1.0))
    assert Dynamics(bandwidth=40.0).transfer_function() == ((40.0,), (1.0, 40.0))
    assert "effectiveness" not in v.to_dict()  # written back per effector, as given


def test_toml_writer_strings_and_keys_round_trip():
    doc = {"s": 'a "quoted" \\ back\nslash\t\x01\x7f é ✈', "weird key": 1.5e-300, "n": -0.0, "big": 1e300,
           "t": {"x y": [1.0, 2.0], "m": [[1.0, 2.0], [3.0, 4.0]]}, "arr": [{"a": 1, "b": {"c": "d"}}]}
    back = tomllib.loads(to_toml(doc))
    assert back == doc and math.copysign(1.0, back["n"]) == -1.0


def test_python_control_interop():
    control = pytest.importorskip("control")
    model = load_vehicle("harv").model
    sys = model.to_statespace(inputs=load_vehicle("harv").effector_names)
    assert list(sys.output_labels) == list(model.outputs)
    back = LinearModel.from_statespace(sys, controlled=model.controlled, units=model.units)
    assert back == model
    assert LinearModel.from_statespace(sys, controlled=model.controlled).units == ()
    assert control is not None


def test_linear_model_without_python_control_says_how_to_install(monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_control(name, *args, **kwargs):
        if name == "control":
            raise ImportError("no control")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_control)
    with pytest.raises(ImportError, match="pip install control"):
        load_vehicle("harv").model.to_statespace()


def test_published_schema_accepts_every_valid_document():
    jsonschema_rs = pytest.importorskip("jsonschema_rs")
    validator = jsonschema_rs.validator_for(json.loads(SCHEMA_PATH.read_text()))
    for name in vehicle_names():
        assert validator.is_valid(load_vehicle(name).to_dict())
    assert validator.is_valid(vehicle_from_dict(hexa_doc()).to_dict())
    bad = hexa_doc()
    bad["effectors"][3]["rate_max"] = -1
    assert not validator.is_valid(bad)


# --------------------------------------------------------------------------- errors name the path
def _mutated(edit) -> dict:
    doc = hexa_doc()
    edit(doc)
    return doc


@pytest.mark.parametrize("edit, message", [
    (lambda d: d["effectors"][3].__setitem__("rate_max", -1), "effectors[3].rate_max: must be > 0, got -1"),
    (lambda d: d.__setitem__("format", "alloc-vehicle/2"), "format: unsupported format"),
    (lambda d: d.pop("format"), "format: required"),
    (lambda d: d["effectors"][1].__setitem__("max", -1.0), "effectors[1].max: max = -1 is below min = 0"),
    (lambda d: d["effectors"][2].__setitem__("preferred", 2.0), "effectors[2].preferred: 2 is outside"),
    (lambda d: d["effectors"][0].__setitem__("kind", "wing"), "effectors[0].kind: unknown kind 'wing'"),
    (lambda d: d["effectors"][0].__setitem__("rate_mx", 1.0), "effectors[0].rate_mx: unknown field"),
    (lambda d: d["effectors"][5]["rotor"].__setitem__("position", [0, 1]), "effectors[5].rotor.position: expected 3"),
    (lambda d: d["effectors"][4]["rotor"].__setitem__("axis", [0, 0, 0]), "effectors[4].rotor.axis: the thrust axis"),
    (lambda d: d["effectors"][0]["dynamics"].__setitem__("wn", 3.0), "effectors[0].dynamics.wn: give one of"),
    (lambda d: d["effectors"][0]["dynamics"].__setitem__("delay", -1), "effectors[0].dynamics.delay: must be >= 0"),
    (lambda d: d["axes"][3].pop("wrench"), "axes[3].wrench: required to compute rotor columns"),
    (lambda d: d["axes"][1].__setitem__("name", "roll"), "axes[1]: duplicate name 'roll'"),
    (lambda d: d["effectors"][4].__setitem__("name", "m1"), "effectors[4]: duplicate name 'm1'"),
    (lambda d: d["effectors"][2].__setitem__("min", "0"), "effectors[2].min: expected a number, got text"),
    (lambda d: d["effectors"][2].__setitem__("min", True), "effectors[2].min: expected a number, got boolean"),
    (lambda d: d["effectors"][2].__setitem__("max", math.inf), "effectors[2].max: must be finite"),
    (lambda d: d["methods"]["daisy"].__setitem__("groups", [["m1", "m9"]]), "methods.daisy.groups[0][1]: unknown"),
    (lambda d: d["methods"].__setitem__("nope", {}), "methods.nope: "),
    (lambda d: d["methods"]["daisy"].__setitem__("gain", 1.0), "methods.daisy.gain: "),
    (lambda d: d.__setitem__("effectiveness", {"B": [[0.0] * 6] * 4}), "effectors[0].rotor: the matrix is given"),
    (lambda d: d.__setitem__("axes", []), "axes: expected at least 1"),
    (lambda d: d.__setitem__("model", {"states": ["x"], "outputs": ["y"], "A": [[0.0]], "B": [[1.0]], "C": [[1.0]]}),
     "model.B[0]: expected 6 entries"),
])
def test_errors_name_the_field_path(edit, message):
    with pytest.raises(ProblemError) as info:
        vehicle_from_dict(_mutated(edit))
    assert str(info.value).startswith(message), str(info.value)
    assert str(info.value).startswith(info.value.field + ":")


def test_missing_effectiveness_is_named():
    doc = {"format": FORMAT, "name": "t", "axes": [{"name": "a"}],
           "effectors": [{"name": "u", "min": 0, "max": 1, "effectiveness": [1.0]}, {"name": "w", "min": 0, "max": 1}]}
    with pytest.raises(ProblemError, match=r"^effectors\[1\]\.effectiveness: required"):
        vehicle_from_dict(doc)


def test_load_vehicle_file_errors(tmp_path):
    with pytest.raises(ProblemError, match="^path: no file 'no-such-plane'.*bundled: harv, hexa-x, ice"):
        load_vehicle("no-such-plane")
    (tmp_path / "bad.toml").write_text("format = \n")
    with pytest.raises(ProblemError, match="^path: bad.toml is not valid TOML"):
        load_vehicle(tmp_path / "bad.toml")
    (tmp_path / "bad.json").write_bytes(b"\xff\xfe")
    with pytest.raises(ProblemError, match="^path: bad.json is not UTF-8"):
        load_vehicle(tmp_path / "bad.json")
    (tmp_path / "v.yaml").write_text("x")
    with pytest.raises(ProblemError, match="^path: unknown extension"):
        load_vehicle(tmp_path / "v.yaml")
    with pytest.raises(ProblemError, match="^source: "):
        load_vehicle(42)


# --------------------------------------------------------------------------- hostile documents
def test_seeded_malformed_documents_raise_problem_error_naming_a_path():
    jsonschema_rs = pytest.importorskip("jsonschema_rs")
    validator = jsonschema_rs.validator_for(json.loads(SCHEMA_PATH.read_text()))
    rng = random.Random(20261201)
    bases = [hexa_doc(), load_vehicle("harv").to_dict()]
    outcomes = {"rejected": 0, "accepted": 0}
    for trial in range(400):
        doc = mutate(bases[trial % 2], rng)
        try:
            v = vehicle_from_dict(doc)
        except ProblemError as exc:
            outcomes["rejected"] += 1
            assert exc.field and str(exc).startswith(exc.field + ":"), (trial, str(exc))
            continue
        outcomes["accepted"] += 1
        assert vehicle_from_dict(v.to_dict()) == v  # what loads, writes and reads back
        assert validator.is_valid(v.to_dict()), trial
    assert outcomes["rejected"] > 300 and outcomes["accepted"] > 0, outcomes


@pytest.mark.parametrize("name", vehicles.SEED_NAMES)
def test_vehicle_from_problem_round_trips_bit_for_bit(name):
    from alloc.vehicle_file import vehicle_from_problem

    p = vehicles.problem(name)
    v = vehicle_from_problem(p, name, methods={"daisy": {"groups": vehicles.daisy_groups(name)}})
    assert_same_problem(v.problem(), p)
    assert_same_problem(load_vehicle(v.to_dict()).problem(), p)


def test_vehicle_from_problem_refuses_what_the_format_cannot_carry():
    from alloc.vehicle_file import vehicle_from_problem

    p = alloc.Problem([[1.0, 2.0]], [-1, -1], [1, 1], Wu=[[2.0, 0.5], [0.5, 2.0]])
    with pytest.raises(ProblemError, match="^Wu: a vehicle file carries diagonal weights only"):
        vehicle_from_problem(p, "x")
    q = alloc.Problem([[1.0, 2.0]], [-1, -1], [1, 1], rate_max=[1.0, 2.0])
    with pytest.raises(ProblemError, match="^rate_min: "):
        vehicle_from_problem(q, "x")
    r = alloc.Problem([[1.0, 2.0]], [-1, -1], [1, 1], rate_min=[-3.0, -1.0], rate_max=[1.0, 2.0], Wv=[4.0])
    assert_same_problem(vehicle_from_problem(r, "x").problem(), r)


def test_method_defaults_are_checked_against_the_problem():
    doc = hexa_doc()
    doc["methods"] = {"ganging": {"G": np.zeros((6, 4)).tolist()}, "cgi": {"priorities": [2, 2, 1, 3]}}
    v = vehicle_from_dict(doc)
    assert v.method_options("cgi") == {"priorities": [2, 2, 1, 3]} and v.method_options("qp") == {}
    doc["methods"] = {"ganging": {"G": np.zeros((4, 6)).tolist()}}
    with pytest.raises(ProblemError, match=r"^methods\.ganging\.G: "):
        vehicle_from_dict(doc)
    doc["methods"] = {"cgi": {"priorities": [1, 2]}}
    with pytest.raises(ProblemError, match=r"^methods\.cgi\.priorities: expected 4 entries"):
        vehicle_from_dict(doc)


@pytest.mark.parametrize("name", vehicles.SEED_NAMES)
def test_seed_file_allocates_as_the_catalogue_does(name):
    v = load_vehicle(name)
    a = alloc.make_allocator(v.problem(), "daisy", **v.method_options("daisy"))
    b = alloc.make_allocator(vehicles.problem(name), "daisy", groups=vehicles.daisy_groups(name))
    rng = np.random.default_rng(7)
    for d in rng.normal(size=(20, v.k)):
        ra, rb = a(d), b(d)
        assert ra.u.tobytes() == rb.u.tobytes() and ra.status == rb.status


def test_hexa_example_allocates_with_its_priorities():
    v = load_vehicle("hexa-x")
    p = v.problem()
    qp = alloc.make_allocator(p, "qp", **v.method_options("qp"))
    r = qp(v.trim + np.array([0.0, 0.0, 2.0, 0.0]))  # more yaw than a hover can give with roll and pitch held
    assert np.all(r.u >= p.umin) and np.all(r.u <= p.umax)
    achieved = p.B @ r.u
    assert achieved[3] == pytest.approx(-19.62, abs=1e-6)  # thrust (highest priority) met; yaw gave way
    assert achieved[2] < 2.0


# --------------------------------------------------------------------------- the [simulation] section (format 1.1)
def test_simulation_section_round_trips_and_needs_its_format():
    for name in ("ice", "harv"):
        v = load_vehicle(name)
        assert v.simulation is not None and v.to_dict()["format"] == "alloc-vehicle/1.1"
        assert vehicle_from_dict(json.loads(json.dumps(v.to_dict()))) == v
        assert vehicle_from_dict(tomllib.loads(to_toml(v.to_dict()))) == v
    assert load_vehicle("hexa-x").to_dict()["format"] == FORMAT  # the oldest format that carries it
    doc = load_vehicle("ice").to_dict()
    with pytest.raises(ProblemError, match=r"^simulation: the \[simulation\] section needs format"):
        vehicle_from_dict({**doc, "format": FORMAT})
    with pytest.raises(ProblemError, match=r"^simulation: the \[simulation\] section flies the \[model\]"):
        vehicle_from_dict({k: v for k, v in doc.items() if k != "model"})


@pytest.mark.parametrize("edit, message", [
    (lambda s: s["smc"].__setitem__("rho", [1.0, 2.0]), "simulation.smc.rho: expected 3 entries, got 2"),
    (lambda s: s["smc"]["hedge"][1].__setitem__("inp", "q"), "simulation.smc.hedge[1].inp: unknown channel 'q'"),
    (lambda s: s["pilot"]["attitude"].__setitem__("psi", 1.0), "simulation.pilot.attitude.psi: unknown output"),
    (lambda s: s["failures"]["seed"]["actuators"][0].__setitem__("effector", "x"),
     "simulation.failures.seed.actuators[0].effector: unknown effector 'x'"),
    (lambda s: s["failures"]["seed"]["actuators"][2].__setitem__("wn", -1.0),
     "simulation.failures.seed.actuators[2].wn:"),
    (lambda s: s["failures"]["seed"]["actuators"][3].__setitem__("position", 99.0),
     "simulation.failures.seed.actuators[3].position:"),
    (lambda s: s["failures"]["seed"]["actuators"][0].__setitem__("position", 1.0),
     "simulation.failures.seed.actuators[0].position: a 'limits' failure takes"),
    (lambda s: s["references"][0].__setitem__("den", [0.0, 1.0]), "simulation.references[0].den: the leading"),
    (lambda s: s["allocation"].__setitem__("static", [[1.0]]), "simulation.allocation.static: expected 11 entries"),
    (lambda s: s.__setitem__("method", "nope"), "simulation.method: unknown"),
])
def test_simulation_errors_name_the_field_path(edit, message):
    doc = load_vehicle("ice").to_dict()
    edit(doc["simulation"])
    with pytest.raises(ProblemError) as info:
        vehicle_from_dict(doc)
    assert str(info.value).startswith(message), str(info.value)


def test_seeded_malformed_simulation_sections_raise_problem_error_naming_a_path():
    rng = random.Random(20261203)
    base = load_vehicle("harv").to_dict()
    rejected = 0
    for trial in range(150):
        doc = {**base, "simulation": mutate(base["simulation"], rng)}
        try:
            v = vehicle_from_dict(doc)
        except ProblemError as exc:
            rejected += 1
            assert exc.field and str(exc).startswith(exc.field + ":"), (trial, str(exc))
            assert exc.field.startswith(("simulation", "model.controlled")), (trial, str(exc))
            continue
        assert vehicle_from_dict(v.to_dict()) == v, trial
    assert rejected > 100, rejected


def test_x57_example_columns_are_its_geometry():
    """The distributed-propulsion example: a forward-thrusting propeller at (x, y, z) gives
    fx = ct, yaw = -ct y, pitch = ct z, roll = -ct km (alloc.vehicle_file.rotor_wrench, PX4's
    convention); the surfaces carry their stated derivatives; 18 effectors on 4 axes."""
    v = load_vehicle("x57-dep")
    p = v.problem()
    assert (p.k, p.m) == (4, 18) and v.effector_names[:6] == tuple(f"hl{i}_l" for i in range(1, 7))
    hl1_r, cruise_l = v.effector_names.index("hl1_r"), v.effector_names.index("cruise_l")
    np.testing.assert_allclose(p.B[:, hl1_r], [-250.0 * 0.05, 250.0 * 0.15, -250.0 * 0.9, 250.0], atol=1e-12)
    np.testing.assert_allclose(p.B[:, cruise_l], [1500.0 * 0.08, 0.0, 1500.0 * 4.8, 1500.0], atol=1e-12)
    np.testing.assert_allclose(p.B[:, v.effector_names.index("stabilator")], [0.0, -5924.0, 0.0, 0.0])
    # every effector moves the set: full rank, no zero column
    assert np.linalg.matrix_rank(p.B) == 4 and (np.abs(p.B).sum(axis=0) > 0).all()
