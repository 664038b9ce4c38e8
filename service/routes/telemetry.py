"""``/v1/vehicles/{id}/telemetry`` and ``.../proposals``: the service learns from telemetry.

A vehicle's telemetry is configured once (``PUT``: its policy and detector settings), then fed
with batches of samples (``POST``, or one batch per WebSocket message); each batch updates the
vehicle's detector state in the database and turns its detections into health events
(policy ``auto``) or proposals (``confirm``), in one transaction (:mod:`service.telemetry_store`).
Writes need the API key; reads are open.  The WebSocket is authenticated when it connects
(``X-API-Key`` header), bounded in message size (:data:`WS_MAX_MESSAGE_BYTES`) and rate
(:data:`WS_MESSAGES_PER_S`, burst :data:`WS_BURST`, and a budget per API key over all its sockets:
both enforced before the message is parsed, by :class:`service.streams.StreamLimits`), and answers
each message in order with the ``POST`` answer or a problem document (``status`` 4xx, nothing
changed).
"""

from __future__ import annotations

import json
from typing import Annotated, Any, Literal

import pydantic_core
from fastapi import APIRouter, Depends, Path, Query, Request, WebSocket
from fastapi.exceptions import RequestValidationError
from pydantic import ValidationError
from starlette.websockets import WebSocketDisconnect

import alloc

from ..bodies import JsonRoute, refuse_duplicate_keys
from ..deps import SettingsDep, StoreDep, end_parse_turn, require_api_key
from ..errors import (
    _LIBRARY_ERRORS, InvalidRequest, ServiceError, Unauthorized,
    _validation_errors, field_error, library_error_fields, problem_response,
)
from ..health import failure_text, health_out
from ..keys import key_matches
from ..schemas import NOT_FOUND, PROBLEM_RESPONSES, UNAUTHORIZED, EventOut, HealthOut, ProblemOut
from ..store import VehicleState
from ..telemetry import DetectorSettings, Policy, Samples, samples_from
from ..telemetry_schemas import (
    ProposalDecided, ProposalList, ProposalOut, TelemetryBatchIn, TelemetryConfigIn, TelemetryOut, TelemetryResult,
)
from ..telemetry_store import TelemetryStore

__all__ = ["router", "WS_MAX_MESSAGE_BYTES", "WS_MESSAGES_PER_S", "WS_BURST"]

#: bytes of one WebSocket message, at most: the light-body size (service.priority.HEAVY_BODY_BYTES),
#: so that a message's parse on the event loop is bounded (0.3 ms for 64 KiB, about 180 samples at
#: m = 11, k = 6; 2.2 ms for a 1,000-sample batch of 356 KB, which goes through POST instead)
WS_MAX_MESSAGE_BYTES = 64 * 1024
#: messages per second one WebSocket connection may send (sustained), and its burst
WS_MESSAGES_PER_S = 50.0
WS_BURST = 20

#: paths relative to the vehicles' prefix: :mod:`service.routes` includes this router in
#: :data:`service.routes.vehicles.router` (``/v1/vehicles``)
router = APIRouter(tags=["telemetry"], responses={**PROBLEM_RESPONSES, **NOT_FOUND}, route_class=JsonRoute)
VehicleId = Annotated[str, Path(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_-]+$",
                                description="vehicle id from POST /v1/vehicles")]
ProposalId = Annotated[int, Path(ge=1, le=2**62, description="proposal id from GET .../proposals")]
WriteAccess = [Depends(require_api_key)]


def telemetry_of(app: Any) -> TelemetryStore:
    """The application's :class:`TelemetryStore` (made on first use, beside the vehicle store)."""
    found = getattr(app.state, "telemetry", None)
    if found is None:
        store = app.state.store
        found = app.state.telemetry = TelemetryStore(store, store._sessions)
    return found


async def _telemetry(request: Request) -> TelemetryStore:
    return telemetry_of(request.app)


Telemetry = Annotated[TelemetryStore, Depends(_telemetry)]


def _sample_maker(body: TelemetryBatchIn) -> Any:
    def make(vehicle: VehicleState, settings: DetectorSettings) -> Samples:
        return samples_from(vehicle.nominal, settings, body.t, body.u, body.y, body.position)
    return make


async def _ingest(telemetry: TelemetryStore, vehicle_id: str, body: TelemetryBatchIn, budget: float) -> dict[str, Any]:
    try:
        return await telemetry.runner.run(telemetry.ingest, vehicle_id, _sample_maker(body), budget)
    except alloc.AllocError as exc:  # a sample the detector refuses: the field and the sample
        field = exc.field or "t"
        raise InvalidRequest(str(exc), [field_error(field, str(exc))]) from exc


def _health(s: VehicleState) -> HealthOut:
    return HealthOut(vehicle_id=s.id, health_version=s.version, effectors=health_out(s.nominal, s.health),
                     effective=ProblemOut.of(s.problem))


# ------------------------------------------------------------------ settings
@router.put("/{vehicle_id}/telemetry", response_model=TelemetryOut, dependencies=WriteAccess,
            responses=UNAUTHORIZED, summary="Set the vehicle's telemetry policy and detector settings")
async def configure(vehicle_id: VehicleId, body: TelemetryConfigIn, store: StoreDep,
                    telemetry: Telemetry) -> TelemetryOut:
    settings = body.to_settings(store.get(vehicle_id).nominal)
    out = await telemetry.runner.run(telemetry.configure, vehicle_id, Policy(body.policy), settings, body.reset)
    return TelemetryOut(**out)


@router.get("/{vehicle_id}/telemetry", response_model=TelemetryOut,
            responses={409: PROBLEM_RESPONSES[422] | {"description": "telemetry not configured"}},
            summary="The vehicle's telemetry policy, settings and detector summary")
def read(vehicle_id: VehicleId, telemetry: Telemetry) -> TelemetryOut:
    return TelemetryOut(**telemetry.read(vehicle_id))


# ------------------------------------------------------------------- batches
@router.post("/{vehicle_id}/telemetry", response_model=TelemetryResult, dependencies=WriteAccess,
             responses=UNAUTHORIZED, summary="A batch of samples: update the detector, apply or propose detections")
async def ingest(vehicle_id: VehicleId, body: TelemetryBatchIn, request: Request, settings: SettingsDep,
                 telemetry: Telemetry) -> TelemetryResult:
    end_parse_turn(request)
    return TelemetryResult(**await _ingest(telemetry, vehicle_id, body, settings.batch_budget_s))


# ----------------------------------------------------------------- proposals
@router.get("/{vehicle_id}/proposals", response_model=ProposalList, summary="Detections proposed as events")
def list_proposals(vehicle_id: VehicleId, telemetry: Telemetry,
                   status: Literal["pending", "accepted", "rejected", "withdrawn"] | None = Query(default=None)
                   ) -> ProposalList:
    return ProposalList(vehicle_id=vehicle_id, items=[ProposalOut(**p) for p in telemetry.proposals(vehicle_id, status)])


async def _decide(telemetry: TelemetryStore, vehicle_id: str, pid: int, accept: bool) -> ProposalDecided:
    proposal, new_state, event = await telemetry.runner.run(telemetry.decide, vehicle_id, pid, accept)
    state = new_state or telemetry.store.get(vehicle_id)
    out = None if event is None else EventOut(
        **{**event, "failure": failure_text(event["effector"], event["kind"], event["params"])})
    return ProposalDecided(proposal=ProposalOut(**proposal), event=out, health=_health(state))


@router.post("/{vehicle_id}/proposals/{pid}/accept", response_model=ProposalDecided, dependencies=WriteAccess,
             responses=UNAUTHORIZED, summary="Accept a proposal: it becomes a health event")
async def accept(vehicle_id: VehicleId, pid: ProposalId, telemetry: Telemetry) -> ProposalDecided:
    return await _decide(telemetry, vehicle_id, pid, True)


@router.post("/{vehicle_id}/proposals/{pid}/reject", response_model=ProposalDecided, dependencies=WriteAccess,
             responses=UNAUTHORIZED, summary="Reject a proposal (the detector's belief drops it)")
async def reject(vehicle_id: VehicleId, pid: ProposalId, telemetry: Telemetry) -> ProposalDecided:
    return await _decide(telemetry, vehicle_id, pid, False)


# ----------------------------------------------------------------- streaming
def _problem(exc: Exception, limit: int) -> dict[str, Any]:
    """``exc`` as the problem document the HTTP handlers of :mod:`service.errors` would send."""
    if isinstance(exc, ServiceError):
        response = problem_response(exc.status, exc.slug, exc.title, exc.detail, exc.errors)
    elif isinstance(exc, RequestValidationError):
        errors, total = _validation_errors(exc, limit)
        detail = "; ".join(f"{'/'.join(map(str, e['loc']))}: {e['reason']}" for e in errors[:5])
        response = problem_response(422, "validation-error", "Request validation failed", detail, errors,
                                    error_count=total)
    else:
        status, slug, title = next((s, g, t) for cls, s, g, t in _LIBRARY_ERRORS if isinstance(exc, cls))
        response = problem_response(status, slug, title, str(exc), library_error_fields(exc))
    return json.loads(response.body)


def _key_ok(websocket: WebSocket) -> bool:
    return key_matches(websocket.scope.get("headers", ()), websocket.app.state.settings.api_key)


@router.websocket("/{vehicle_id}/telemetry/ws")
async def stream(websocket: WebSocket, vehicle_id: str) -> None:
    """One batch per text message, answered in order (module docstring).  A message reaching
    the route is within its size and rates: :class:`service.streams.StreamLimits` answered the others."""
    app = websocket.app
    settings = app.state.settings
    refusal: ServiceError | None = None
    if not _key_ok(websocket):
        refusal = Unauthorized("this endpoint requires the X-API-Key header",
                               [{"loc": ["header", "X-API-Key"], "pointer": None, "reason": "missing or wrong"}])
    else:
        try:
            telemetry_of(app).store.get(vehicle_id)
        except ServiceError as exc:  # unknown vehicle (or a malformed id: the same 404)
            refusal = exc
    if refusal is not None:
        await websocket.send_denial_response(problem_response(refusal.status, refusal.slug, refusal.title,
                                                              refusal.detail, refusal.errors))
        return
    await websocket.accept()
    telemetry = telemetry_of(app)
    limit = settings.max_validation_errors
    try:
        while True:
            message = await websocket.receive()
            if message["type"] == "websocket.disconnect":
                return
            data = message.get("text")
            if data is None:
                data = (message.get("bytes") or b"").decode("utf-8", errors="replace")
            answer: dict[str, Any]
            try:
                body = _parse(data)
                answer = TelemetryResult(**await _ingest(telemetry, vehicle_id, body,
                                                         settings.batch_budget_s)).model_dump(mode="json")
            except (ServiceError, alloc.AllocError, RequestValidationError) as exc:
                answer = _problem(exc, limit)
            await websocket.send_text(json.dumps(answer))
    except WebSocketDisconnect:
        return


def _parse(data: str) -> TelemetryBatchIn:
    """One WebSocket message as a batch: JSON (a key given twice refused naming it, as on HTTP),
    then the schema."""
    raw = data.encode()
    try:
        parsed = pydantic_core.from_json(raw)
    except ValueError as exc:
        raise InvalidRequest(f"body: not JSON ({exc})", [{"loc": ["body"], "pointer": "", "reason": "not JSON"}]) \
            from None
    refuse_duplicate_keys(raw, parsed)
    try:
        return TelemetryBatchIn.model_validate(parsed)
    except ValidationError as exc:
        errors = [{**e, "loc": ("body", *e["loc"])} for e in exc.errors(include_url=False)]
        raise RequestValidationError(errors, body=parsed) from None

