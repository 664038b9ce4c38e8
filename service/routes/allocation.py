"""``/v1/allocate``: allocations for an inline problem (single and batch)."""

from __future__ import annotations

from anyio import to_thread
from fastapi import APIRouter, Response

from ..deps import StoreDep
from ..responses import allocation_response, batch_response
from ..schemas import PROBLEM_RESPONSES, AllocateRequest, AllocationOut, BatchAllocateRequest, BatchOut, ProblemIn

router = APIRouter(prefix="/v1/allocate", tags=["allocation"], responses=PROBLEM_RESPONSES)

_PROBLEM_FIELDS = set(ProblemIn.model_fields)


# async: runs on the event loop, so the cached (not thread-safe) allocators are never
# called concurrently, and a single allocation costs no thread hand-off.  Only a cache
# miss goes to a worker thread, for the build.
@router.post("", response_model=AllocationOut, summary="Allocate one demand for an inline problem")
async def allocate(body: AllocateRequest, store: StoreDep) -> Response:
    key = body.model_dump_json(include=_PROBLEM_FIELDS)
    allocator = await store.inline_allocator(key, body.to_problem, body.method, body.options)
    return allocation_response(allocator(body.v, u_prev=body.u_prev, dt=body.dt))


# A 10,000-demand batch must not block the event loop: it builds its own allocator on the
# build pool (cached ones are only ever called from the event loop) and runs in a thread.
@router.post("/batch", response_model=BatchOut, summary="Allocate many demands for one inline problem")
async def allocate_batch(body: BatchAllocateRequest, store: StoreDep) -> Response:
    allocator = await store.fresh_allocator(body.to_problem(), body.method, body.options)
    return batch_response(await to_thread.run_sync(allocator.batch, body.V))
