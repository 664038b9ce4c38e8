"""``/v1/vehicles``: effector suites, their failure/repair events, health and allocations.

Writes (create, delete, record an event) require the API key when one is configured;
reads and allocations are open.
"""

from __future__ import annotations

from typing import Annotated

import json

from fastapi import APIRouter, Depends, Path, Query, Request, Response, status
from pydantic import BaseModel

from ..bodies import JsonRoute
from ..db import EventRow
from ..deps import IdempotencyKey, PoolDep, StoreDep, end_parse_turn, idempotency, require_api_key
from ..health import failure_text, health_out
from ..schemas import (
    NOT_FOUND, PROBLEM_RESPONSES, UNAUTHORIZED,
    AllocationOut, AmsOut, AmsVehicleRequest, BatchOut, EventIn, EventList, EventOut, EventRecorded,
    HealthOut, ProblemOut, VehicleAllocateRequest, VehicleBatchRequest, VehicleList,
    VehicleOut, VehicleSummary,
)
from ..vehicle_document import (TOML_MEDIA_TYPE, VehicleBody, VehicleDocumentIn, document_of,
                                require_vehicle_media_type, toml_text, vehicle_create)
from ..store import Answer, VehicleState
from ..vehicle_import import ImportFormat, check_import_query, imported_vehicle, media_type

router = APIRouter(prefix="/v1/vehicles", tags=["vehicles"], responses={**PROBLEM_RESPONSES, **NOT_FOUND},
                   route_class=JsonRoute)
VehicleId = Annotated[str, Path(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_-]+$",
                                description="vehicle id from POST /v1/vehicles")]
WriteAccess = [Depends(require_api_key)]


def _vehicle_out(s: VehicleState) -> VehicleOut:
    return VehicleOut(id=s.id, name=s.name, created_at=s.created_at, health_version=s.version,
                      problem=ProblemOut.of(s.nominal), health=health_out(s.nominal, s.health))


def _health_out(s: VehicleState) -> HealthOut:
    return HealthOut(vehicle_id=s.id, health_version=s.version, effectors=health_out(s.nominal, s.health),
                     effective=ProblemOut.of(s.problem))


def _event_out(e: EventRow) -> EventOut:
    return EventOut(seq=e.seq, effector=e.effector, kind=e.kind, params=e.params, note=e.note,
                    recorded_at=e.recorded_at, failure=failure_text(e.effector, e.kind, e.params))


@router.post("", response_model=VehicleOut, status_code=status.HTTP_201_CREATED,
             dependencies=[*WriteAccess, Depends(require_vehicle_media_type)],
             responses={**UNAUTHORIZED, 415: {"description": "not JSON, a TOML vehicle file or a flight stack's file"}},
             summary="Create a vehicle (an effector suite, a vehicle document: JSON or TOML, or a flight stack's file)",
             description="The body is an effector suite or a vehicle document (JSON), a vehicle file "
                         f"({TOML_MEDIA_TYPE}), or a flight stack's file read by the library's importers: an "
                         "ArduPilot motor factor table (text/csv), or as text/plain an ArduPilot parameter file "
                         "(?import=ardupilot-params: FRAME_CLASS, FRAME_TYPE), a QGroundControl .params file "
                         "(?import=px4-params) or a PX4 airframe file as PX4 ships it (?import=px4-airframe); "
                         "?name= names an imported vehicle.",
             openapi_extra={"requestBody": {"content": {
                 TOML_MEDIA_TYPE: {"schema": {"type": "string", "description": "a vehicle file (alloc-vehicle/1), "
                                              "as alloc.load_vehicle reads it"}},
                 "text/csv": {"schema": {"type": "string", "description": "an ArduPilot motor factor table: header "
                                         "motor,roll,pitch,yaw[,throttle], one motor a row"}},
                 "text/plain": {"schema": {"type": "string", "description": "an ArduPilot .param/.parm file, a "
                                           "QGroundControl .params file or a PX4 airframe file, named by ?import="}},
             }}})
def create_vehicle(body: VehicleBody, store: StoreDep, request: Request,
                   idempotency_key: IdempotencyKey = None,
                   import_format: Annotated[ImportFormat | None, Query(
                       alias="import", description="how to read a text/plain (or text/csv) body: a flight stack's "
                       "file")] = None,
                   name: Annotated[str | None, Query(min_length=1, max_length=64, pattern=r"^[^\x00-\x1f\x7f]*$",
                                                     description="the name of an imported vehicle (default the "
                                                     "importer's)")] = None) -> Response:
    media, charset = media_type(request.headers.get("content-type"))
    form = check_import_query(media, None if import_format is None else import_format.value, name)
    fingerprinted: BaseModel = body
    if form is not None and isinstance(body, VehicleDocumentIn) and isinstance(body.root, bytes):
        suite, _, fingerprinted = imported_vehicle(body.root, form, name, charset)
    elif isinstance(body, VehicleDocumentIn):
        suite = vehicle_create(body)[0]
    else:
        suite = body
    # the fingerprint is the body as sent (suite, document or file), once it is known to be valid
    once = idempotency(request, idempotency_key, fingerprinted)
    answer = store.create_once(suite, once, lambda state: _vehicle_out(state).model_dump_json().encode())
    location = f"/v1/vehicles/{json.loads(answer.body)['id']}"
    return _answer(answer, Location=location)


def _answer(answer: Answer, **headers: str) -> Response:
    """A write's answer, as first sent; a replay for a retried key says so."""
    if answer.replayed:
        headers["Idempotent-Replayed"] = "true"
    return Response(answer.body, status_code=answer.status, media_type="application/json", headers=headers)


@router.get("", response_model=VehicleList, summary="List vehicles")
def list_vehicles(store: StoreDep, limit: Annotated[int, Query(ge=1, le=1000)] = 100,
                  offset: Annotated[int, Query(ge=0, le=2**31)] = 0) -> VehicleList:
    rows, total = store.list(limit, offset)
    items = [VehicleSummary(id=r.id, name=r.name, created_at=r.created_at, health_version=r.health_version,
                            m=len(r.problem["umin"]), k=len(r.problem["B"])) for r in rows]
    return VehicleList(items=items, total=total)


@router.get("/{vehicle_id}", response_model=VehicleOut, summary="Read a vehicle")
def get_vehicle(vehicle_id: VehicleId, store: StoreDep) -> VehicleOut:
    return _vehicle_out(store.get(vehicle_id))


@router.get("/{vehicle_id}/document", summary="The vehicle document (JSON, or TOML for Accept: application/toml)",
            responses={200: {"content": {"application/json": {"schema": {"type": "object"}},
                                         TOML_MEDIA_TYPE: {"schema": {"type": "string"}}},
                             "description": "the document the vehicle was created from (format alloc-vehicle/1); "
                                            "for a vehicle created from an effector suite, the suite's document"}})
def get_document(vehicle_id: VehicleId, store: StoreDep, request: Request) -> Response:
    state = store.get(vehicle_id)
    document = document_of(store.document(vehicle_id), state.nominal, state.name)
    if TOML_MEDIA_TYPE in request.headers.get("accept", ""):
        return Response(toml_text(document), media_type=TOML_MEDIA_TYPE)
    return Response(json.dumps(document, allow_nan=False), media_type="application/json")


@router.delete("/{vehicle_id}", status_code=status.HTTP_204_NO_CONTENT, dependencies=WriteAccess,
               responses=UNAUTHORIZED, summary="Delete a vehicle and its history")
async def delete_vehicle(vehicle_id: VehicleId, store: StoreDep) -> Response:
    await store.write(store.delete, vehicle_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)


@router.post("/{vehicle_id}/events", response_model=EventRecorded, status_code=status.HTTP_201_CREATED,
             dependencies=WriteAccess, responses=UNAUTHORIZED, summary="Record a failure or repair of one effector",
             description="The body is the kind's fields (below), or the same failure as text in the library's "
                         "failure grammar: {\"failure\": \"jam:elevon_l@5\", \"note\": ...} (kind:effector@values, "
                         "one effector, a told kind; alloc/failure_grammar.py).")
async def record_event(vehicle_id: VehicleId, body: EventIn, store: StoreDep, request: Request,
                       idempotency_key: IdempotencyKey = None) -> Response:
    # Committed (fsync'd) on the writer threads and visible to every process before the
    # response; the store publishes the new state to the allocator pool, which starts the
    # rebuilds before the response (service.pool), so the next allocation finds its rebuild
    # in flight rather than queueing a build of its own behind other requests'.
    answer = await store.write(store.record_event_once, vehicle_id, body,
                               idempotency(request, idempotency_key, body), _render_event)
    return _answer(answer)


def _render_event(event: EventRow, state: VehicleState, old_version: int) -> bytes:
    return EventRecorded(event=_event_out(event), health=_health_out(state)).model_dump_json().encode()


@router.get("/{vehicle_id}/events", response_model=EventList, summary="Event history, oldest first")
def list_events(vehicle_id: VehicleId, store: StoreDep) -> EventList:
    return EventList(vehicle_id=vehicle_id, items=[_event_out(e) for e in store.events(vehicle_id)])


@router.get("/{vehicle_id}/health", response_model=HealthOut, summary="Current health and effective problem")
def get_health(vehicle_id: VehicleId, store: StoreDep) -> HealthOut:
    return _health_out(store.get(vehicle_id))


@router.post("/{vehicle_id}/allocate", response_model=AllocationOut,
             summary="Allocate one demand at the vehicle's current health")
async def allocate(vehicle_id: VehicleId, body: VehicleAllocateRequest, pool: PoolDep, request: Request) -> Response:
    end_parse_turn(request)
    return await pool.allocate(vehicle_id, body)


@router.post("/{vehicle_id}/allocate/batch", response_model=BatchOut,
             summary="Allocate many demands at the vehicle's current health")
async def allocate_batch(vehicle_id: VehicleId, body: VehicleBatchRequest, pool: PoolDep, request: Request) -> Response:
    end_parse_turn(request)
    return await pool.allocate_batch(vehicle_id, body)


@router.post("/{vehicle_id}/ams", response_model=AmsOut, summary="AMS summary at the vehicle's current health")
async def ams_summary(vehicle_id: VehicleId, body: AmsVehicleRequest, pool: PoolDep, request: Request) -> AmsOut:
    end_parse_turn(request)
    return await pool.vehicle_ams_summary(vehicle_id, body)
