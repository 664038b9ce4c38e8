"""``POST /v1/vehicles`` with a vehicle document (JSON or TOML) and ``GET /v1/vehicles/{id}/document``:
the library's reader decides, floats come back bit for bit, malformed documents are 4xx naming the field."""

from __future__ import annotations

import json
import random
import tomllib

import pytest
from fastapi.testclient import TestClient

from alloc.exceptions import ProblemError
from alloc.vehicle_file import DATA_DIR, load_vehicle, to_toml, vehicle_from_dict
from service.config import Settings
from service.main import create_app
from service.vehicle_document import document_pointer
from vehicle_documents import mutate

FILES = sorted(DATA_DIR.glob("*.toml"))
TOML = {"content-type": "application/toml"}


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    app = create_app(Settings(data_dir=tmp_path_factory.mktemp("vehicle-document")))
    with TestClient(app) as c:
        yield c


def exact(x) -> str:
    """A JSON text whose equality is bit-for-bit equality of every float (repr, -0.0 kept)."""
    return json.dumps(x, sort_keys=True, allow_nan=False)


def created(response) -> dict:
    assert response.status_code == 201, response.text[:500]
    return response.json()


@pytest.mark.parametrize("path", FILES, ids=[p.stem for p in FILES])
def test_vehicle_file_round_trips_through_the_service_bit_for_bit(client, path):
    vehicle = load_vehicle(path)
    problem = vehicle.problem()
    by_toml = created(client.post("/v1/vehicles", content=path.read_bytes(), headers=TOML))
    by_suite = created(client.post("/v1/vehicles", json={**problem.to_dict(), "name": vehicle.name}))
    for out in (by_toml, by_suite):
        assert out["name"] == vehicle.name
        assert exact(out["problem"]) == exact(problem.to_dict())  # file -> Problem -> to_dict() -> service
    for out in (by_toml,):  # the JSON form of the document: test_document_keeps_names_units_...
        document = client.get(f"/v1/vehicles/{out['id']}/document")
        assert document.status_code == 200 and document.headers["content-type"].startswith("application/json")
        assert exact(document.json()) == exact(vehicle.to_dict())
        assert vehicle_from_dict(document.json()) == vehicle  # names, units, limits, dynamics, methods, model
        text = client.get(f"/v1/vehicles/{out['id']}/document", headers={"accept": "application/toml"})
        assert text.headers["content-type"].startswith("application/toml")
        committed = path.read_text(encoding="utf-8")
        # the committed file's data exactly (the seed's files also carry their citations as TOML
        # comments, which a document does not keep); byte for byte where it has none
        assert tomllib.loads(text.text) == tomllib.loads(committed)
        if not any(line.lstrip().startswith("#") or " # " in line for line in committed.splitlines()):
            assert text.text == committed
    # a suite's document: the problem's own (vehicle_from_problem), which yields the same problem
    suite_doc = client.get(f"/v1/vehicles/{by_suite['id']}/document").json()
    assert exact(vehicle_from_dict(suite_doc).problem().to_dict()) == exact(problem.to_dict())


def test_document_keeps_names_units_preferred_and_method_defaults(client):
    vehicle = load_vehicle("hexa-x")
    out = created(client.post("/v1/vehicles", json=vehicle.to_dict()))
    doc = client.get(f"/v1/vehicles/{out['id']}/document").json()
    assert [e["name"] for e in doc["effectors"]] == list(vehicle.effector_names) == out["problem"]["names"]
    assert [a["unit"] for a in doc["axes"]] == ["N m", "N m", "N m", "N"]
    assert doc["methods"]["qp"] == {"priorities": [2, 2, 1, 3]}
    assert doc["axes"][3]["trim"] == -2.0 * 9.81
    ice = load_vehicle("ice")
    out = created(client.post("/v1/vehicles", json=ice.to_dict()))
    assert out["problem"]["up"] == ice.problem().up.tolist()
    assert client.get(f"/v1/vehicles/{out['id']}/document").json()["methods"]["daisy"]["groups"] == \
        ice.methods["daisy"]["groups"]


@pytest.mark.parametrize("edit, pointer, detail", [
    (lambda d: d["effectors"][3].__setitem__("rate_max", -1.0), "/effectors/3/rate_max",
     "effectors[3].rate_max: must be > 0, got -1"),
    (lambda d: d.__setitem__("format", "alloc-vehicle/9"), "/format", "format: unsupported format"),
    (lambda d: d["axes"][0].pop("name"), "/axes/0/name", "axes[0].name: required"),
    (lambda d: d["methods"]["daisy"].__setitem__("groups", [["nope"]]), "/methods/daisy/groups/0/0",
     "methods.daisy.groups[0][0]: unknown effector"),
])
def test_malformed_document_is_422_naming_the_field(client, edit, pointer, detail):
    doc = load_vehicle("ice").to_dict()
    edit(doc)
    for response in (client.post("/v1/vehicles", json=doc),
                     client.post("/v1/vehicles", content=to_toml(doc).encode(), headers=TOML)):
        assert response.status_code == 422, response.text
        assert response.headers["content-type"].startswith("application/problem+json")
        body = response.json()
        assert body["type"] == "urn:alloc:problem:invalid-vehicle-document"
        assert body["detail"].startswith(detail) and body["errors"][0]["pointer"] == pointer


@pytest.mark.parametrize("content, headers, status", [
    (b"format = [", TOML, 422),                                  # not TOML
    (b"\xff\xfe = 1", TOML, 422),                                # not UTF-8
    (b'format = "alloc-vehicle/1"', TOML, 422),                 # TOML, but no name, axes, effectors
    (b"{}", {"content-type": "text/html"}, 415),                  # text/plain is a flight stack's file: test_vehicle_import.py
    (b'{"format": "alloc-vehicle/1"}', {"content-type": "application/xml"}, 415),
    (json.dumps({f"k{i}": 1 for i in range(65)} | {"format": "alloc-vehicle/1"}).encode(),
     {"content-type": "application/json"}, 422),                # members bounded before the reader runs
])
def test_bodies_that_are_not_vehicle_documents(client, content, headers, status):
    response = client.post("/v1/vehicles", content=content, headers=headers)
    assert response.status_code == status, response.text
    assert response.headers["content-type"].startswith("application/problem+json")


def test_seeded_malformed_documents_get_the_library_verdict_never_5xx(client):
    """Each mutated document: the service answers what ``vehicle_from_dict`` says (201, or 422 at its path)."""
    rng = random.Random(20261202)
    bases = [load_vehicle(name).to_dict() for name in ("hexa-x", "tailless")]
    outcomes = {"rejected": 0, "accepted": 0, "not JSON": 0}
    for trial in range(40):
        doc = mutate(bases[trial % 2], rng)
        try:
            body = json.dumps(doc, allow_nan=False).encode()
        except (ValueError, TypeError):  # nan/inf or a lone surrogate: not JSON, the parser's 422
            body = json.dumps(doc).encode("utf-8", "surrogatepass")
            response = client.post("/v1/vehicles", content=body, headers={"content-type": "application/json"})
            assert response.status_code == 422, (trial, response.text[:300])
            outcomes["not JSON"] += 1
            continue
        response = client.post("/v1/vehicles", content=body, headers={"content-type": "application/json"})
        assert response.status_code < 500, (trial, response.text[:300])
        try:
            expected = vehicle_from_dict(json.loads(body))
        except ProblemError as exc:
            outcomes["rejected"] += 1
            assert response.status_code == 422, (trial, response.text[:300])
            problem = response.json()
            if problem["type"] == "urn:alloc:problem:invalid-vehicle-document":
                assert problem["detail"] == str(exc)
                assert problem["errors"][0]["pointer"] in (f"/{document_pointer(exc.field)}", None)
            continue
        outcomes["accepted"] += 1
        assert response.status_code == 201, (trial, response.text[:300])
        doc_back = client.get(f"/v1/vehicles/{response.json()['id']}/document").json()
        assert vehicle_from_dict(doc_back) == expected
    assert outcomes["rejected"] > 20 and outcomes["accepted"] > 0, outcomes


def test_idempotent_document_create_replays_and_refuses_another_body(client):
    path = DATA_DIR / "hexa-x.toml"
    key = {"Idempotency-Key": "doc-1", **TOML}
    first = client.post("/v1/vehicles", content=path.read_bytes(), headers=key)
    again = client.post("/v1/vehicles", content=path.read_bytes(), headers=key)
    assert first.status_code == again.status_code == 201 and again.headers.get("Idempotent-Replayed") == "true"
    assert again.json()["id"] == first.json()["id"]
    other = client.post("/v1/vehicles", content=(DATA_DIR / "tailless.toml").read_bytes(), headers=key)
    assert other.status_code == 409


def test_document_of_unknown_vehicle_is_404(client):
    response = client.get("/v1/vehicles/nope/document")
    assert response.status_code == 404 and response.json()["errors"][0]["loc"] == ["path", "vehicle_id"]


@pytest.mark.slow  # the schema's generation: seconds
def test_openapi_lists_both_forms_and_toml(client):
    op = client.get("/openapi.json").json()["paths"]["/v1/vehicles"]["post"]
    content = op["requestBody"]["content"]
    assert "application/toml" in content and "application/json" in content
    assert "415" in op["responses"]
    assert "/v1/vehicles/{vehicle_id}/document" in client.get("/openapi.json").json()["paths"]


@pytest.mark.parametrize("name,method,v", [
    ("hexa-x", "qp", [3.0, -3.0, 1.0, -19.62]),        # [methods.qp] priorities; unattainable
    ("hexa-x", "cgi", [3.0, -3.0, 1.0, -19.62]),       # [methods.cgi] priorities
    ("tailless", "daisy", [2.0, 5.0, 0.5]),            # [methods.daisy] groups
])
def test_a_documents_method_defaults_reach_its_allocations(client, name, method, v):
    """An allocation for a vehicle created from a document uses the document's [methods.<m>]
    defaults under the request's own options, bit for bit as the library with the same options;
    a vehicle created from the bare suite has none."""
    import numpy as np

    import alloc

    vehicle = load_vehicle(name)
    vid = created(client.post("/v1/vehicles", content=(DATA_DIR / f"{name}.toml").read_bytes(), headers=TOML))["id"]
    defaults = vehicle.method_options(method)
    assert defaults, f"{name} declares [methods.{method}]"
    got = client.post(f"/v1/vehicles/{vid}/allocate", json={"v": v, "method": method})
    assert got.status_code == 200, got.text[:300]
    want = alloc.allocate(vehicle.problem(), v, method, **defaults)
    assert got.json()["u"] == want.u.tolist() and got.json()["status"] == want.status.value
    batch = client.post(f"/v1/vehicles/{vid}/allocate/batch", json={"V": [v, v], "method": method})
    assert batch.status_code == 200 and batch.json()["u"][1] == want.u.tolist()

    # the request's own option wins over the document's, key by key
    key, value = next(iter(defaults.items()))
    if key == "priorities":
        mine = {"priorities": [1] * vehicle.k}
        got = client.post(f"/v1/vehicles/{vid}/allocate", json={"v": v, "method": method, "options": mine})
        assert got.json()["u"] == alloc.allocate(vehicle.problem(), v, method, **{**defaults, **mine}).u.tolist()

    suite = created(client.post("/v1/vehicles", json={**vehicle.problem().to_dict(), "name": name}))["id"]
    bare = client.post(f"/v1/vehicles/{suite}/allocate", json={"v": v, "method": method})
    plain = alloc.allocate(vehicle.problem(), v, method)  # the library without the document's options
    assert bare.status_code == 200 and bare.json()["u"] == plain.u.tolist()
    assert not np.array_equal(plain.u, want.u), "the case must tell the defaults apart"


def _hostile_toml(rng: random.Random) -> bytes:
    """Seeded TOML bodies that cost tomllib super-linear time or escape it as a raw error."""
    n = rng.choice([17, 200, 2_000, 8_000])
    kind = rng.choice(["dotted", "header", "arrays", "tables", "digits", "big"])
    if kind == "dotted":
        text = "format = 'alloc-vehicle/1'\n" + ".".join(f"k{i}" for i in range(n)) + " = 1\n"
    elif kind == "header":
        text = "[" + ".".join("a" for _ in range(n)) + "]\nx = 1\n"
    elif kind == "arrays":
        text = "x = " + "[" * n + "]" * n + "\n"
    elif kind == "tables":
        text = "x = " + "{a = " * n + "1" + "}" * n + "\n"
    elif kind == "digits":
        text = "x = " + "9" * (4_301 + n) + "\n"
    else:
        text = "# " + "x" * (200_000 + n) + "\n"
    return text.encode()


def test_hostile_toml_bodies_are_422_quickly_never_5xx(client):
    """Issue 39: the service's TOML reader is the library's bounded one (a 16 KB dotted key took 1.5 s)."""
    import time

    rng = random.Random(39)
    for _ in range(40):
        body = _hostile_toml(rng)
        start = time.perf_counter()
        r = client.post("/v1/vehicles", content=body, headers=TOML)
        assert r.status_code in (413, 422), (r.status_code, r.text[:200])
        assert r.headers["content-type"].startswith("application/problem+json")
        assert time.perf_counter() - start < 2.0, body[:60]
