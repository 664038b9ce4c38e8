"""Scheduled effectiveness through the service: ``"at"`` on a vehicle allocation or batch answers as
``alloc allocate --vehicle FILE --at NAME=VALUE`` does (PX4's tiltrotor airframe as PX4 ships it, its
``[schedule]`` of tilt and airspeed); hostile ``at`` values get 422 naming ``at.<name>``; concurrent
requests at different ``at`` on one vehicle each get their own answer."""

from __future__ import annotations

import json
import random
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from fastapi.testclient import TestClient
from typer.testing import CliRunner

import alloc
from alloc.cli import app as cli
from alloc.exceptions import SkippedLinesWarning
from alloc.health import apply_health
from alloc.vehicle_file import load_vehicle
from service.config import Settings
from service.main import create_app

TILTROTOR = Path(__file__).parents[1] / "alloc" / "data" / "px4_airframes" / "13100_generic_vtol_tiltrotor"
V = [0.1, -0.05, 0.02, -5.0]
POINTS = [{"tilt": 0.0}, {"tilt": 30.0, "airspeed": 0.0}, {"tilt": 45.0, "airspeed": 12.0}, {"tilt": 90.0},
          {"airspeed": 30.0}, {"tilt": 67.5, "airspeed": 7.0}]


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    app = create_app(Settings(data_dir=tmp_path_factory.mktemp("vehicle-schedule")))
    with TestClient(app) as c:
        yield c


@pytest.fixture(scope="module")
def vehicle():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SkippedLinesWarning)
        return load_vehicle(TILTROTOR)


@pytest.fixture(scope="module")
def tiltrotor(client):
    response = client.post("/v1/vehicles", content=TILTROTOR.read_bytes(), headers={"content-type": "text/plain"},
                           params={"import": "px4-airframe", "name": TILTROTOR.name})
    assert response.status_code == 201, response.text
    return response.json()["id"]


def allocate(client, vehicle_id: str, at: dict | None, method: str = "qp", v=V):
    body = {"v": list(v), "method": method, **({} if at is None else {"at": at})}
    return client.post(f"/v1/vehicles/{vehicle_id}/allocate", json=body)


def cli_answer(at: dict, method: str) -> dict:
    args = ["allocate", "--vehicle", str(TILTROTOR), "--v", ",".join(map(repr, V)), "--method", method, "--json",
            "--repeat", "1"]
    for name, value in at.items():
        args += ["--at", f"{name}={value!r}"]
    run = CliRunner().invoke(cli, args)
    assert run.exit_code == 0, run.output
    return json.loads(run.stdout[run.stdout.index("{"):])


@pytest.mark.parametrize("method", ["qp", "pinv"])
@pytest.mark.parametrize("at", POINTS, ids=[json.dumps(p) for p in POINTS])
def test_at_answers_as_the_cli(client, tiltrotor, vehicle, at, method):
    answer = allocate(client, tiltrotor, at, method)
    assert answer.status_code == 200, answer.text
    cli_out = cli_answer(at, method)
    assert answer.json()["u"] == cli_out["u"] and answer.json()["status"] == cli_out["status"]
    want = alloc.make_allocator(vehicle.problem_at(at), method)(V)  # the library, in this process
    assert answer.json()["u"] == want.u.tolist()


def test_the_schedule_changes_the_answer_and_missing_variables_are_nominal(client, tiltrotor):
    hover = allocate(client, tiltrotor, {"tilt": 0.0}).json()["u"]
    forward = allocate(client, tiltrotor, {"tilt": 90.0}).json()["u"]
    assert not np.allclose(hover, forward)  # B turned with the rotors
    # airspeed's nominal is 15 m/s (PX4's FW_AIRSPD_TRIM default)
    assert allocate(client, tiltrotor, {"tilt": 30.0}).json()["u"] == \
        allocate(client, tiltrotor, {"tilt": 30.0, "airspeed": 15.0}).json()["u"]
    # no `at` (or {}) is the stored nominal B, as the CLI without --at
    assert allocate(client, tiltrotor, None).json()["u"] == allocate(client, tiltrotor, {}).json()["u"]


def test_batch_at_equals_single_calls(client, tiltrotor):
    rows = np.random.default_rng(7).uniform(-0.2, 0.2, (5, 4))
    rows[:, 3] = -5.0
    at = {"tilt": 45.0, "airspeed": 12.0}
    batch = client.post(f"/v1/vehicles/{tiltrotor}/allocate/batch", json={"V": rows.tolist(), "method": "qp",
                                                                          "at": at})
    assert batch.status_code == 200, batch.text
    singles = [allocate(client, tiltrotor, at, v=row).json()["u"] for row in rows.tolist()]
    np.testing.assert_allclose(batch.json()["u"], singles, rtol=0, atol=1e-12)


def test_health_applies_on_top_of_the_schedule(client, vehicle):
    vid = client.post("/v1/vehicles", content=TILTROTOR.read_bytes(), headers={"content-type": "text/plain"},
                      params={"import": "px4-airframe"}).json()["id"]
    name = vehicle.effector_names[0]
    event = client.post(f"/v1/vehicles/{vid}/events", json={"effector": name, "kind": "jam", "position": 0.2})
    assert event.status_code == 201, event.text
    at = {"tilt": 60.0, "airspeed": 10.0}
    response = allocate(client, vid, at)
    assert response.status_code == 200, response.text
    answer = response.json()
    health = client.app.state.store.get(vid).health  # the jam as the service recorded it
    want = alloc.make_allocator(apply_health(vehicle.problem_at(at), health), "qp")(V)
    assert answer["u"] == want.u.tolist() and answer["u"][0] == 0.2 and answer["health_version"] == 1
    nominal = alloc.make_allocator(vehicle.problem_at(at), "qp")(V)
    assert nominal.u[0] != 0.2


@pytest.mark.parametrize("at, loc, text", [
    ({"tilt": 100.0}, ["body", "at", "tilt"], "at.tilt: must be in [0, 90] deg, got 100.0"),
    ({"tilt": -1e-9}, ["body", "at", "tilt"], "at.tilt: must be in [0, 90] deg"),
    ({"airspeed": 1e6}, ["body", "at", "airspeed"], "at.airspeed: must be in [0, 1000] m/s"),
    ({"tilt": 1e300}, ["body", "at", "tilt"], "less than or equal to"),
    ({"rpm": 1.0}, ["body", "at", "rpm"], "at.rpm: unknown scheduling variable; declared: tilt, airspeed"),
    ({"a/b": 1.0}, ["body", "at", "a/b"], "at.a/b: unknown scheduling variable"),
    ({"tilt": "45"}, ["body", "at", "tilt"], "valid number"),
    ({"tilt": True}, ["body", "at", "tilt"], "valid number"),
    ({"tilt": None}, ["body", "at", "tilt"], "valid number"),
    ({"tilt": [45]}, ["body", "at", "tilt"], "valid number"),
    ({"tilt": {"deg": 45}}, ["body", "at", "tilt"], "valid number"),
    ({f"v{i}": 1.0 for i in range(9)}, ["body", "at"], "at most 8"),
    ([45.0], ["body", "at"], "valid dictionary"),
    ("tilt=45", ["body", "at"], "valid dictionary"),
])
def test_hostile_at_is_422_naming_the_variable(client, tiltrotor, at, loc, text):
    response = client.post(f"/v1/vehicles/{tiltrotor}/allocate", json={"v": V, "at": at})
    assert response.status_code == 422, response.text
    problem = response.json()
    assert problem["errors"][0]["loc"] == loc and text in (problem["detail"] + problem["errors"][0]["reason"]), problem


@pytest.mark.parametrize("literal", ["NaN", "Infinity", "-Infinity", "1e400"])
def test_non_finite_at_is_422_naming_the_variable(client, tiltrotor, literal):
    body = '{"v": [0.1, 0, 0, -5], "at": {"tilt": ' + literal + "}}"
    response = client.post(f"/v1/vehicles/{tiltrotor}/allocate", content=body,
                           headers={"content-type": "application/json"})
    assert response.status_code == 422, response.text
    assert response.json()["errors"][0]["loc"] == ["body", "at", "tilt"]


def test_at_on_a_vehicle_without_a_schedule_names_at(client):
    vid = client.post("/v1/vehicles", content=b"FRAME_CLASS,1\n", headers={"content-type": "text/plain"},
                      params={"import": "ardupilot-params"}).json()["id"]
    for path, body in (("allocate", {"v": [0.1, 0, 0, 0.5]}), ("allocate/batch", {"V": [[0.1, 0, 0, 0.5]]})):
        response = client.post(f"/v1/vehicles/{vid}/{path}", json={**body, "at": {"tilt": 10.0}})
        assert response.status_code == 422 and response.json()["errors"][0]["loc"] == ["body", "at"], response.text
        assert "declares no [schedule]" in response.json()["detail"]


def test_concurrent_requests_at_different_at_get_their_own_answers(client, tiltrotor, vehicle):
    rng = random.Random(20261206)
    points = [{"tilt": rng.choice([0.0, 15.0, 45.0, 90.0, rng.uniform(0, 90)]), "airspeed": rng.uniform(0, 30)}
              for _ in range(160)]
    want = {json.dumps(p): alloc.make_allocator(vehicle.problem_at(p), "qp")(V).u.tolist() for p in points}
    with ThreadPoolExecutor(8) as pool:
        answers = list(pool.map(lambda p: (p, allocate(client, tiltrotor, p)), points))
    for p, response in answers:
        assert response.status_code == 200, response.text
        assert response.json()["u"] == want[json.dumps(p)], p
    assert len({json.dumps(u) for u in want.values()}) > 100  # the points do give different answers


def test_one_allocator_is_kept_per_vehicle_method_and_options_not_per_at(client, vehicle):
    vid = client.post("/v1/vehicles", content=TILTROTOR.read_bytes(), headers={"content-type": "text/plain"},
                      params={"import": "px4-airframe"}).json()["id"]
    pool = client.app.state.pool

    def kept() -> list:
        return pool.allocators.keys_where(lambda k: isinstance(k, tuple) and len(k) == 5 and k[0] == vid)

    for tilt in (10.0, 20.0, 30.0, 40.0):
        assert allocate(client, vid, {"tilt": tilt}).status_code == 200
        assert [k[4] for k in kept()] == [(tilt, 15.0)]  # the last at, its values resolved
    builds = pool.allocators.builds
    first = allocate(client, vid, {"tilt": 40.0, "airspeed": 15.0}).json()["u"]  # the same values: reused
    assert pool.allocators.builds == builds
    assert first == alloc.make_allocator(vehicle.problem_at({"tilt": 40.0}), "qp")(V).u.tolist()
    assert allocate(client, vid, {"tilt": 40.0}, method="pinv").status_code == 200
    assert sorted(k[2] for k in kept()) == ["pinv", "qp"]  # one per method
    client.post(f"/v1/vehicles/{vid}/events", json={"effector": vehicle.effector_names[1], "kind": "jam",
                                                     "position": 0.1})
    assert kept() == []  # dropped with the vehicle's stale allocators, not rebuilt for the new health
    after = allocate(client, vid, {"tilt": 40.0})
    assert after.json()["health_version"] == 1 and after.json()["u"][1] == 0.1
    assert [k[1] for k in kept() if k[2] == "qp"] == [1]


def test_evaluators_are_held_apart_from_states_and_bounded(client, tiltrotor):
    from service.schedule import Schedules

    store = client.app.state.store
    other = client.post("/v1/vehicles", content=TILTROTOR.read_bytes(), headers={"content-type": "text/plain"},
                        params={"import": "px4-airframe"}).json()["id"]
    reads: list[str] = []
    schedules = Schedules(lambda vid: reads.append(vid) or store.document(vid), entries=1)
    first, second = store.get(tiltrotor), store.get(other)
    assert first.scheduled and not hasattr(first, "schedule")  # a state holds a flag, not the terms
    assert schedules.of(first) is schedules.of(first) and reads == [tiltrotor]
    schedules.of(second)  # evicts the first: one entry
    schedules.of(first)
    assert reads == [tiltrotor, other, tiltrotor]
