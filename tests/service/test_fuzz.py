"""Property-based fuzzing of the OpenAPI schema (schemathesis): no request gets a 5xx.

Positive (schema-conforming) and negative (schema-violating) cases for every operation,
a bounded number of examples each, against the ASGI app in-process on a temporary
database.  Every error answer must be RFC 9457 problem+json.
"""

from __future__ import annotations

import tempfile

import itertools

import pytest
import schemathesis
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pydantic import TypeAdapter
from schemathesis import GenerationMode

import alloc
from alloc.vehicles import harv_latdir
from service.config import Settings
from service.main import create_app
from service.schemas import EventIn, VehicleCreate

MAX_EXAMPLES = 25

app = create_app(Settings(data_dir=tempfile.mkdtemp(prefix="alloc-fuzz-")))
# one stored vehicle, so that generated requests can also reach its endpoints
_vehicle = app.state.store.create(VehicleCreate(**harv_latdir().to_dict(), name="harv"))
app.state.store.record_event(
    _vehicle.id, TypeAdapter(EventIn).validate_python({"effector": "rudder", "kind": "jam", "position": 3.0}))
_alternate = itertools.cycle([True, False])
# as the lifespan does (in-process requests without ``with TestClient`` never run it), and waited
# for: a build process warming its kernels on a loaded machine takes longer than a case's 10 s
for _started in app.state.pool.builder.start_processes():
    _started.result(timeout=600)


@pytest.fixture(scope="module", autouse=True)
def _close_store():
    """The lifespan's shutdown, which in-process requests without ``with TestClient`` never reach:
    without it, a build process still warming its kernels (niced, on a loaded machine: minutes)
    kept pytest from exiting until it finished."""
    yield
    app.state.pool.close()
    app.state.store.close()

schema = schemathesis.openapi.from_asgi("/openapi.json", app)
schema.config.generation.update(modes=[GenerationMode.POSITIVE, GenerationMode.NEGATIVE],
                                max_examples=MAX_EXAMPLES)


@schema.hook
def map_path_parameters(ctx, path_parameters):
    # Every other generated vehicle id is the stored vehicle's, so its endpoints get exercised
    # (not for DELETE, which would remove it for the rest of the run).
    if (path_parameters and "vehicle_id" in path_parameters and ctx.operation.method.upper() != "DELETE"
            and next(_alternate)):
        path_parameters["vehicle_id"] = _vehicle.id
    return path_parameters


@schema.parametrize()
@settings(max_examples=MAX_EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck))
def test_no_server_errors(case):
    response = case.call()
    assert response.status_code < 500, (response.status_code, response.text[:2000])
    if response.status_code >= 400:
        content_type = response.headers.get("content-type")
        content_type = content_type[0] if isinstance(content_type, list) else content_type
        assert content_type.startswith("application/problem+json"), response.text[:500]
        body = response.json()
        assert body["status"] == response.status_code
        assert {"type", "title", "detail", "errors"} <= set(body)


def test_methods_listed_match_library():
    from fastapi.testclient import TestClient

    listed = TestClient(app).get("/v1/methods").json()
    assert [m["name"] for m in listed] == alloc.methods()


# Schema-driven cases rarely produce consistent shapes; this one generates well-formed
# problems of every size the API accepts and runs every registered method on them.
_sizes = st.integers(1, 6).flatmap(lambda k: st.tuples(st.just(k), st.integers(1, 12)))
_finite = st.floats(-1e3, 1e3, allow_nan=False, allow_infinity=False)


@st.composite
def _inline_requests(draw):
    k, m = draw(_sizes)
    B = draw(st.lists(st.lists(_finite, min_size=m, max_size=m), min_size=k, max_size=k))
    lo = draw(st.lists(st.floats(-50, 0), min_size=m, max_size=m))
    hi = draw(st.lists(st.floats(0, 50), min_size=m, max_size=m))
    body = {"B": B, "umin": lo, "umax": hi, "v": draw(st.lists(_finite, min_size=k, max_size=k)),
            "method": draw(st.sampled_from(alloc.methods()))}
    if draw(st.booleans()):
        body["u_prev"] = draw(st.lists(st.floats(-60, 60), min_size=m, max_size=m))
        body["dt"] = draw(st.floats(1e-4, 1.0))
        body["rate_min"] = draw(st.lists(st.one_of(st.none(), st.floats(-100, 0)), min_size=m, max_size=m))
        body["rate_max"] = draw(st.lists(st.one_of(st.none(), st.floats(0, 100)), min_size=m, max_size=m))
    return body


@given(body=_inline_requests())
@settings(max_examples=120, deadline=None, suppress_health_check=list(HealthCheck))
def test_wellformed_problems_every_method_no_5xx(body):
    from fastapi.testclient import TestClient

    client = TestClient(app, raise_server_exceptions=False)
    r = client.post("/v1/allocate", json=body)
    assert r.status_code < 500, r.text[:2000]
    if r.status_code == 200:
        out = r.json()
        assert all(lo - 1e-9 <= u <= hi + 1e-9 for u, lo, hi in zip(out["u"], body["umin"], body["umax"]))
    batch = {k: v for k, v in body.items() if k not in ("v", "u_prev", "dt")}
    r = client.post("/v1/allocate/batch", json={**batch, "V": [body["v"]] * 3})
    assert r.status_code < 500, r.text[:2000]
