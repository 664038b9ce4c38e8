"""``/v1/allocate``: allocations for an inline problem (single and batch)."""

from __future__ import annotations

from fastapi import APIRouter, Request, Response

from ..builds import Call
from ..bodies import JsonRoute
from ..deps import StoreDep, end_parse_turn
from ..responses import allocation_response
from ..schemas import PROBLEM_RESPONSES, AllocateRequest, AllocationOut, BatchAllocateRequest, BatchOut, ProblemIn

router = APIRouter(prefix="/v1/allocate", tags=["allocation"], responses=PROBLEM_RESPONSES, route_class=JsonRoute)

_PROBLEM_FIELDS = set(ProblemIn.model_fields)


# async: a cached allocator is called on the event loop, so the (not thread-safe) allocators
# are never called concurrently, and a single allocation costs no thread hand-off.  A cache
# miss is built off the loop (service.builds); a batch is priced, run and serialised off the loop.
@router.post("", response_model=AllocationOut, summary="Allocate one demand for an inline problem")
async def allocate(body: AllocateRequest, store: StoreDep, request: Request) -> Response:
    end_parse_turn(request)
    key = body.model_dump_json(include=_PROBLEM_FIELDS)
    call = Call(body.v, body.u_prev, body.dt)
    return allocation_response(await store.inline_allocate(key, body.to_problem, body.method, body.options, call))


@router.post("/batch", response_model=BatchOut, summary="Allocate many demands for one inline problem")
async def allocate_batch(body: BatchAllocateRequest, store: StoreDep, request: Request) -> Response:
    end_parse_turn(request)
    return await store.inline_batch(body.to_problem(), body.method, body.options, body.V)
