"""The service over real HTTP: a uvicorn process started by the test, on loopback.

The reconfiguration story end to end: allocate, create a vehicle, record a jam, allocate
again (the jammed effector held, the others compensate, the demand still met), then
SIGKILL the server right after a recorded event and restart it on the same data dir.
"""

from __future__ import annotations

import httpx
import numpy as np
import pytest

import alloc
from alloc.vehicles import ice
from service.process import ServiceProcess

KEY = "test-key"
V = [0.5, 1.0, 0.2]  # (alpha, p, beta) demand, attainable with elevon_l jammed at 10 deg


@pytest.fixture()
def server(tmp_path):
    """A server of the test's own (the test kills it)."""
    proc = ServiceProcess(tmp_path / "data", api_key=KEY).start()
    yield proc
    proc.stop()


@pytest.fixture(scope="module")
def shared_server(tmp_path_factory):
    """One server for the tests that only read it (inline requests and errors: no stored state)."""
    proc = ServiceProcess(tmp_path_factory.mktemp("http") / "data", api_key=KEY).start()
    yield proc
    proc.stop()


def _problem_body(p: alloc.Problem) -> dict:
    return p.to_dict()


def test_inline_allocation_equals_library(shared_server):
    p = ice()
    with httpx.Client(base_url=shared_server.url) as http:
        for method in ("pinv", "qp"):
            r = http.post("/v1/allocate", json={**_problem_body(p), "v": V, "method": method})
            assert r.status_code == 200, r.text
            lib = alloc.make_allocator(p, method)(V)
            body = r.json()
            # exact float equality through the JSON round trip (shortest-repr floats both ways)
            assert body["u"] == lib.u.tolist()
            assert body["v_achieved"] == lib.v_achieved.tolist()
            assert body["status"] == lib.status.value


def test_jam_then_allocate_survives_sigkill(server, tmp_path):
    p = ice()
    jam_at = 10.0
    with httpx.Client(base_url=server.url) as http:
        # writes need the key
        r = http.post("/v1/vehicles", json={**_problem_body(p), "name": "ice"})
        assert r.status_code == 401
        assert r.headers["content-type"].startswith("application/problem+json")
        r = http.post("/v1/vehicles", json={**_problem_body(p), "name": "ice"}, headers={"X-API-Key": KEY})
        assert r.status_code == 201, r.text
        vid = r.json()["id"]
        assert r.headers["location"] == f"/v1/vehicles/{vid}"

        healthy = http.post(f"/v1/vehicles/{vid}/allocate", json={"v": V, "method": "qp"}).json()
        assert healthy["status"] == "exact" and healthy["health_version"] == 0
        assert healthy["u"] != pytest.approx([jam_at] + healthy["u"][1:])

        # a jam outside the limits is refused and recorded nowhere
        r = http.post(f"/v1/vehicles/{vid}/events", headers={"X-API-Key": KEY},
                      json={"effector": "elevon_l", "kind": "jam", "position": 45.0})
        assert r.status_code == 422
        assert r.json()["errors"][0]["pointer"] == "/position"

        r = http.post(f"/v1/vehicles/{vid}/events", headers={"X-API-Key": KEY},
                      json={"effector": "elevon_l", "kind": "jam", "position": jam_at, "note": "hydraulics A"})
        assert r.status_code == 201, r.text
        assert r.json()["health"]["effectors"][0]["status"] == "jammed"

        jammed = http.post(f"/v1/vehicles/{vid}/allocate", json={"v": V, "method": "qp"}).json()
        u = np.array(jammed["u"])
        assert jammed["health_version"] == 1
        assert u[0] == jam_at  # held exactly at the jam position
        assert jammed["status"] == "exact"  # the others compensate ...
        np.testing.assert_allclose(p.B @ u, V, atol=1e-6)  # ... with the nominal B: demand met
        moved = np.abs(u[1:] - np.array(healthy["u"][1:])) > 1e-6
        assert moved.sum() >= 2
        assert np.all(u >= p.umin) and np.all(u <= p.umax)
        # the service's answer is the library's for the jammed problem
        lib = alloc.make_allocator(p.with_jam("elevon_l", jam_at), "qp")(V)
        assert jammed["u"] == lib.u.tolist()

        # one more failure, then SIGKILL right after its response
        r = http.post(f"/v1/vehicles/{vid}/events", headers={"X-API-Key": KEY},
                      json={"effector": "lef_l", "kind": "effectiveness", "fraction": 0.5})
        assert r.status_code == 201
    server.kill()

    restarted = ServiceProcess(tmp_path / "data", api_key=KEY).start()
    try:
        with httpx.Client(base_url=restarted.url) as http:
            health = http.get(f"/v1/vehicles/{vid}/health").json()
            assert health["health_version"] == 2
            by_name = {e["effector"]: e for e in health["effectors"]}
            assert by_name["elevon_l"]["status"] == "jammed"
            assert by_name["elevon_l"]["jam_position"] == jam_at
            assert by_name["lef_l"]["effectiveness"] == 0.5
            events = http.get(f"/v1/vehicles/{vid}/events").json()["items"]
            assert [(e["seq"], e["kind"], e["effector"]) for e in events] == [
                (1, "jam", "elevon_l"), (2, "effectiveness", "lef_l")]
            assert events[0]["note"] == "hydraulics A"
            after = http.post(f"/v1/vehicles/{vid}/allocate", json={"v": V, "method": "qp"}).json()
            assert after["u"][0] == jam_at and after["health_version"] == 2

            # repair: back to the healthy allocation
            r = http.post(f"/v1/vehicles/{vid}/events", headers={"X-API-Key": KEY},
                          json={"effector": "elevon_l", "kind": "repair"})
            assert r.status_code == 201
            r = http.post(f"/v1/vehicles/{vid}/events", headers={"X-API-Key": KEY},
                          json={"effector": "lef_l", "kind": "repair"})
            repaired = http.post(f"/v1/vehicles/{vid}/allocate", json={"v": V, "method": "qp"}).json()
            assert repaired["u"] == healthy["u"]
    finally:
        restarted.stop()


def test_errors_over_http(shared_server):
    with httpx.Client(base_url=shared_server.url) as http:
        raw = b'{"B": [[1, NaN]], "umin": [-1, -1], "umax": [1, 1], "v": [1]}'
        r = http.post("/v1/allocate", content=raw, headers={"content-type": "application/json"})
        assert r.status_code == 422
        assert r.json()["errors"][0]["pointer"] == "/B/0/1"
        r = http.post("/v1/allocate", content=b"[" * 200_000, headers={"content-type": "application/json"})
        assert 400 <= r.status_code < 500
        r = http.post("/v1/allocate", content=b" " * (5 * 1024 * 1024), headers={"content-type": "application/json"})
        assert r.status_code == 413
        assert r.json()["status"] == 413
        r = http.get("/v1/vehicles/does-not-exist/health")
        assert r.status_code == 404 and r.json()["type"] == "urn:alloc:problem:not-found"
