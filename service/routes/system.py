"""``/v1/health``: liveness and database check."""

from __future__ import annotations

from fastapi import APIRouter

import alloc

from ..deps import StoreDep
from ..schemas import PROBLEM_RESPONSES, ServiceHealth

router = APIRouter(prefix="/v1", tags=["system"], responses=PROBLEM_RESPONSES)


@router.get("/health", response_model=ServiceHealth, summary="Service health check")
async def health(store: StoreDep) -> ServiceHealth:
    # async, one committed read through the version probe: answers even when the thread
    # pool is busy with sync routes
    store.ping()
    return ServiceHealth(status="ok", version=alloc.__version__, database="ok", methods=len(alloc.methods()))
