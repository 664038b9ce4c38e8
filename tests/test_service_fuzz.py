"""Property-based fuzzing of the OpenAPI schema (schemathesis): no request gets a 5xx.

Positive (schema-conforming) and negative (schema-violating) cases for every operation,
a bounded number of examples each, against the ASGI app in-process on a temporary
database.  Every error answer must be RFC 9457 problem+json.
"""

from __future__ import annotations

import tempfile

import itertools

import schemathesis
from hypothesis import HealthCheck, settings
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

schema = schemathesis.openapi.from_asgi("/openapi.json", app)
schema.config.generation.update(modes=[GenerationMode.POSITIVE, GenerationMode.NEGATIVE],
                                max_examples=MAX_EXAMPLES)


@schema.hook
def map_path_parameters(ctx, path_parameters):  # noqa: ANN001 - schemathesis hook signature
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
