"""``/v1/allocate``: allocations for an inline problem (single and batch)."""

from __future__ import annotations

from fastapi import APIRouter, Response

from ..builds import Call
from ..deps import StoreDep
from ..responses import allocation_response, batch_response
from ..schemas import PROBLEM_RESPONSES, AllocateRequest, AllocationOut, BatchAllocateRequest, BatchOut, ProblemIn

router = APIRouter(prefix="/v1/allocate", tags=["allocation"], responses=PROBLEM_RESPONSES)

_PROBLEM_FIELDS = set(ProblemIn.model_fields)


# async: a cached allocator is called on the event loop, so the (not thread-safe) allocators
# are never called concurrently, and a single allocation costs no thread hand-off.  A cache
# miss is built off the loop (service.builds); a batch is answered off the loop too.
@router.post("", response_model=AllocationOut, summary="Allocate one demand for an inline problem")
async def allocate(body: AllocateRequest, store: StoreDep) -> Response:
    key = body.model_dump_json(include=_PROBLEM_FIELDS)
    call = Call(body.v, body.u_prev, body.dt)
    return allocation_response(await store.inline_allocate(key, body.to_problem, body.method, body.options, call))


@router.post("/batch", response_model=BatchOut, summary="Allocate many demands for one inline problem")
async def allocate_batch(body: BatchAllocateRequest, store: StoreDep) -> Response:
    return batch_response(await store.inline_allocate("", body.to_problem, body.method, body.options, Call(V=body.V)))
