"""``/v1/allocate``: allocations for an inline problem (single and batch)."""

from __future__ import annotations

from fastapi import APIRouter, Request, Response

from ..bodies import JsonRoute
from ..deps import PoolDep, end_parse_turn
from ..schemas import PROBLEM_RESPONSES, AllocateRequest, AllocationOut, BatchAllocateRequest, BatchOut

router = APIRouter(prefix="/v1/allocate", tags=["allocation"], responses=PROBLEM_RESPONSES, route_class=JsonRoute)


# async: a cached allocator is called on the event loop, so the (not thread-safe) allocators
# are never called concurrently, and a single allocation costs no thread hand-off.  A cache
# miss is built off the loop (service.pool); a batch is priced, run and serialised off the loop.
@router.post("", response_model=AllocationOut, summary="Allocate one demand for an inline problem")
async def allocate(body: AllocateRequest, pool: PoolDep, request: Request) -> Response:
    end_parse_turn(request)
    return await pool.allocate_inline(body)


@router.post("/batch", response_model=BatchOut, summary="Allocate many demands for one inline problem")
async def allocate_batch(body: BatchAllocateRequest, pool: PoolDep, request: Request) -> Response:
    end_parse_turn(request)
    return await pool.allocate_inline_batch(body)
