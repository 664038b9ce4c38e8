"""Dependencies shared by the routers: the store, the settings, the API-key check.

All are ``async``: FastAPI runs a sync dependency in the thread pool, a thread hand-off
that costs more than the allocation itself.
"""

from __future__ import annotations

import hmac
from typing import Annotated

from fastapi import Depends, Request, Security
from fastapi.security import APIKeyHeader

from .config import Settings
from .errors import Unauthorized
from .store import VehicleStore

__all__ = ["StoreDep", "SettingsDep", "require_api_key"]

_api_key_header = APIKeyHeader(name="X-API-Key", auto_error=False,
                               description="required on write endpoints when ALLOC_API_KEY is set")


async def get_store(request: Request) -> VehicleStore:
    return request.app.state.store


async def get_settings(request: Request) -> Settings:
    return request.app.state.settings


StoreDep = Annotated[VehicleStore, Depends(get_store)]
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
