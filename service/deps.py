"""Dependencies shared by the routers: the store (the repository), the allocator pool, the
settings, the API-key check.

All are ``async``: FastAPI runs a sync dependency in the thread pool, a thread hand-off
that costs more than the allocation itself.
"""

from __future__ import annotations

import hashlib
import hmac
from typing import Annotated

from fastapi import Depends, Header, Request, Security
from fastapi.security import APIKeyHeader
from pydantic import BaseModel

from .config import Settings
from .errors import Unauthorized
from .pool import AllocatorPool
from .store import Idempotency, VehicleStore

__all__ = ["StoreDep", "PoolDep", "SettingsDep", "IdempotencyKey", "require_api_key", "idempotency", "end_parse_turn"]

#: the scope key service.main.BodySizeLimit stores a request's parse-turn release under
PARSE_TURN_KEY = "alloc.parse_turn"

#: the ``Idempotency-Key`` request header of the write endpoints (printable ASCII, no spaces)
IdempotencyKey = Annotated[str | None, Header(
    alias="Idempotency-Key", min_length=1, max_length=255, pattern=r"^[\x21-\x7e]+$",
    description="a retry with the same key and body gets the first answer (the write happens once); "
                "the same key with another body gets 409. Kept ALLOC_IDEMPOTENCY_TTL_S (24 h)")]

_api_key_header = APIKeyHeader(name="X-API-Key", auto_error=False,
                               description="required on write endpoints when ALLOC_API_KEY is set")


async def get_store(request: Request) -> VehicleStore:
    return request.app.state.store


async def get_pool(request: Request) -> AllocatorPool:
    return request.app.state.pool


async def get_settings(request: Request) -> Settings:
    return request.app.state.settings


StoreDep = Annotated[VehicleStore, Depends(get_store)]
PoolDep = Annotated[AllocatorPool, Depends(get_pool)]
SettingsDep = Annotated[Settings, Depends(get_settings)]


async def require_api_key(settings: SettingsDep, key: Annotated[str | None, Security(_api_key_header)] = None) -> None:
    """Write endpoints: when ``ALLOC_API_KEY`` is set, header ``X-API-Key`` must equal it."""
    expected = settings.api_key
    if not expected:
        return
    if key is None:
        raise Unauthorized("this endpoint requires the X-API-Key header",
                           [{"loc": ["header", "X-API-Key"], "pointer": None, "reason": "missing"}])
    if not hmac.compare_digest(key.encode(), expected.encode()):
        raise Unauthorized("wrong API key", [{"loc": ["header", "X-API-Key"], "pointer": None, "reason": "wrong key"}])


def idempotency(request: Request, key: str | None, body: BaseModel) -> Idempotency | None:
    """The write's key, scoped to its method and path, with the fingerprint of its validated body."""
    if key is None:
        return None
    scope = f"{request.method} {request.url.path.rstrip('/')}"
    digest = hashlib.sha256(f"{scope}\n".encode() + body.model_dump_json().encode()).hexdigest()
    return Idempotency(scope, key, digest)


def end_parse_turn(request: Request) -> None:
    """The request's body is parsed and validated: let the next large body be parsed
    (:class:`service.main.BodySizeLimit`).  Routes taking large bodies call it first."""
    end = request.scope.get(PARSE_TURN_KEY)
    if end is not None:
        end()
