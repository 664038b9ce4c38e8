"""The OpenAPI document and the validation agree (issue 39: schemathesis found schema-valid
requests refused, e.g. ``hop: 22.0`` on an integer field and weights such as 1e-288).

Schema-valid requests are generated from the app's own OpenAPI document (schemathesis, positive
mode only).  None may be refused by the *schema-level* validation (``validation-error``): what
the schema cannot state (a vector's length is the vehicle's ``m`` or ``k``, a window's samples
depend on ``sample_time``) is refused by the service's own checks (``invalid-request``,
``invalid-problem``, ...) with 422, which every operation's schema lists.  An integer written
``22.0`` is the integer 22 in JSON Schema: wherever the request schema has an integer, the
same request with its integers written as floats gets the same status.

Known gap, left to its owner: the vehicle *document* branch of ``POST /v1/vehicles``
(``service/vehicle_document.py``) is stated as any object or string (JSON or TOML), so generated
documents get ``validation-error``; those cases are set aside (counted) here.
"""

from __future__ import annotations

import tempfile
from collections import Counter
from typing import Any

import pytest
import schemathesis
from hypothesis import HealthCheck, settings
from schemathesis import GenerationMode

from alloc.vehicles import harv_latdir
from service.config import Settings
from service.main import create_app
from service.schemas import VehicleCreate

#: examples per operation: the default run, and the slow one
MAX_EXAMPLES = 8
SLOW_EXAMPLES = 150

app = create_app(Settings(data_dir=tempfile.mkdtemp(prefix="alloc-schema-"), warmup=False))
_vehicle = app.state.store.create(VehicleCreate(**harv_latdir().to_dict(), name="harv"))
schema = schemathesis.openapi.from_asgi("/openapi.json", app)
schema.config.generation.update(modes=[GenerationMode.POSITIVE], max_examples=MAX_EXAMPLES)
set_aside: Counter[str] = Counter()


@pytest.fixture(scope="module", autouse=True)
def _close_store():
    yield
    app.state.pool.close()
    app.state.store.close()
    print(f"\nset aside (vehicle documents, service/vehicle_document.py): {dict(set_aside)}")


@schema.hook
def map_path_parameters(ctx, path_parameters):
    # the stored vehicle's endpoints are reached (never deleted: DELETE keeps its generated id)
    if path_parameters and "vehicle_id" in path_parameters and ctx.operation.method.upper() != "DELETE":
        path_parameters["vehicle_id"] = _vehicle.id
    return path_parameters


def _is_document(case: Any) -> bool:
    if case.method.upper() != "POST" or case.path != "/v1/vehicles":
        return False
    fields = VehicleCreate.model_fields
    required = {name for name, f in fields.items() if f.is_required()}
    return not (isinstance(case.body, dict) and required <= set(case.body) <= set(fields))


def _as_floats(value: Any) -> Any:
    """``value`` with every integer (not a bool) written as a float: ``22`` -> ``22.0``."""
    if isinstance(value, bool):
        return value
    if isinstance(value, int):
        return float(value)
    if isinstance(value, list):
        return [_as_floats(v) for v in value]
    if isinstance(value, dict):
        return {k: _as_floats(v) for k, v in value.items()}
    return value


def _check_schema_level_validation(case: Any) -> None:
    if _is_document(case):
        set_aside[case.path] += 1
        return
    response = case.call()
    assert response.status_code < 500, (response.status_code, response.text[:500])
    if response.status_code == 422:
        problem = response.json()
        assert problem["type"] != "urn:alloc:problem:validation-error", (case.method, case.path, case.body,
                                                                         problem["detail"])
        # a 422 the schema does not rule out: the operation documents it
        assert "422" in case.operation.definition.raw["responses"], (case.method, case.path)


@schema.parametrize()
@settings(max_examples=MAX_EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck), database=None)
def test_schema_valid_requests_pass_the_schema_level_validation(case):
    _check_schema_level_validation(case)


@pytest.mark.slow
@schema.parametrize()
@settings(max_examples=SLOW_EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck), database=None)
def test_schema_valid_requests_pass_the_schema_level_validation_many(case):
    _check_schema_level_validation(case)


_WITH_INTEGERS = {("POST", "/v1/vehicles/{vehicle_id}/events"), ("PUT", "/v1/vehicles/{vehicle_id}/telemetry")}


def test_the_operations_with_integer_fields_are_the_ones_checked():
    """The float-integer test below covers every operation whose request schema has an integer."""
    document = app.openapi()
    components = document["components"]["schemas"]

    def has_integer(node: Any, seen: frozenset[str] = frozenset()) -> bool:
        if isinstance(node, dict):
            if node.get("type") == "integer":
                return True
            ref = node.get("$ref", "").rsplit("/", 1)[-1]
            if ref:
                return ref not in seen and has_integer(components[ref], seen | {ref})
            return any(has_integer(v, seen) for v in node.values())
        return isinstance(node, list) and any(has_integer(v, seen) for v in node)
    found = {(method.upper(), path) for path, ops in document["paths"].items() for method, op in ops.items()
             if has_integer(op.get("requestBody"))}
    assert found == _WITH_INTEGERS


@schema.include(path_regex=r"/events$|/telemetry$", method=["POST", "PUT"]).parametrize()
@settings(max_examples=MAX_EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck), database=None)
def test_integers_written_as_floats_are_the_same_integers(case):
    if (case.method.upper(), case.path) not in _WITH_INTEGERS or not isinstance(case.body, dict):
        return
    first = case.call()
    case.body = _as_floats(case.body)
    second = case.call()
    assert second.status_code == first.status_code, (case.body, first.text[:300], second.text[:300])
