"""``/v1/health``: liveness and database check; ``/v1/ready``: readiness, for a load balancer.

Liveness says the process answers (and its database does); readiness says it should be
sent traffic: its start-up (database, application) is done and it is not shutting down.
The numba kernels load on a thread after the start-up (``ALLOC_WARMUP``, :mod:`service.warm`);
``warmed`` says whether they all have (a request before that loads its method's kernels).  uvicorn accepts connections only after start-up, so a worker
that answers at all is normally ready; ``/v1/ready`` turns 503 as soon as shutdown begins.
"""

from __future__ import annotations

from fastapi import APIRouter, Request

import alloc

from ..deps import StoreDep
from ..errors import NotReady
from ..schemas import NOT_READY, PROBLEM_RESPONSES, ServiceHealth, ServiceReady
from ..warm import is_warm

router = APIRouter(prefix="/v1", tags=["system"], responses=PROBLEM_RESPONSES)


@router.get("/health", response_model=ServiceHealth, summary="Service health check")
async def health(store: StoreDep) -> ServiceHealth:
    # async, one committed read through the version probe: answers even when the thread
    # pool is busy with sync routes
    store.ping()
    return ServiceHealth(status="ok", version=alloc.__version__, database="ok", methods=len(alloc.methods()))


@router.get("/ready", response_model=ServiceReady, summary="Readiness check (503 while starting or stopping)",
            responses=NOT_READY)
async def ready(request: Request, store: StoreDep) -> ServiceReady:
    state = request.app.state
    if not getattr(state, "ready", False):
        raise NotReady("this worker is starting or shutting down; send traffic elsewhere")
    store.ping()
    return ServiceReady(status="ready", startup_seconds=round(state.startup_seconds, 3),
                        warmed=state.settings.warmup and is_warm())
