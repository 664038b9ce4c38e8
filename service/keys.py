"""Writes without the API key are refused at the request head, before their body is read.

A write route declares its key check as a dependency (:func:`service.deps.require_api_key`), and
FastAPI reads and parses a request's body before it runs the dependencies: a keyless 3.9 MB body
was read and parsed before its 401 (event p99 152 ms at load 3 under 4 anonymous connections).
:class:`KeyAtHead` answers those requests 401 from their head alone, with ``connection: close``
so that their body is never read.  Which routes need the key is read from the application's
routes (those depending on ``require_api_key``), so the two cannot disagree.  The telemetry
WebSocket checks the key at its handshake (:func:`service.routes.telemetry.stream`).
"""

from __future__ import annotations

import hmac
import re
from collections.abc import Iterable
from typing import Any

from fastapi.dependencies.models import Dependant
from fastapi.routing import APIRoute, iter_route_contexts
from starlette.types import ASGIApp, Receive, Scope, Send

from .deps import require_api_key
from .errors import Unauthorized, problem_response

__all__ = ["KeyAtHead", "keyed_routes", "key_matches", "NO_KEY_WARNING"]

#: logged at start-up when no key is configured (service.main)
NO_KEY_WARNING = ("ALLOC_API_KEY is not set: every write is open to anyone who can reach this port -- creating "
                  "and deleting vehicles, recording failure events, and telemetry, which under policy 'auto' "
                  "turns a faked stream into a faked failure.  Set ALLOC_API_KEY or ALLOC_API_KEY_FILE.")


def key_matches(headers: Iterable[tuple[bytes, bytes]], key: str | None) -> bool:
    """Whether a request's first ``X-API-Key`` header is ``key`` (any request when ``key`` is None)."""
    if key is None:
        return True
    for name, value in headers:
        if name == b"x-api-key":
            return hmac.compare_digest(value, key.encode())
    return False


def _needs_key(dependant: Dependant) -> bool:
    return any(d.call is require_api_key or _needs_key(d) for d in dependant.dependencies)


def keyed_routes(app: Any) -> list[tuple[frozenset[str], re.Pattern[str]]]:
    """The application's routes that require the key: their methods and path pattern."""
    return [(frozenset(route.methods or ()), route.path_regex) for route in iter_route_contexts(app.routes)
            if isinstance(route.original_route, APIRoute) and _needs_key(route.dependant)]


class KeyAtHead:
    """ASGI middleware: a request to a keyed route without the right ``X-API-Key`` gets 401 at once
    (module docstring).  Inert when no key is configured."""

    def __init__(self, app: ASGIApp, api_key: str | None, routes_of: Any) -> None:
        self.app, self.api_key, self._routes_of = app, api_key, routes_of
        self._routes: list[tuple[frozenset[str], re.Pattern[str]]] | None = None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and self.api_key is not None and self._keyed(scope["method"], scope["path"]):
            headers = scope.get("headers", ())
            if not key_matches(headers, self.api_key):
                missing = all(name != b"x-api-key" for name, _ in headers)
                detail, reason = (("this endpoint requires the X-API-Key header", "missing") if missing
                                  else ("wrong API key", "wrong key"))  # require_api_key's words
                response = problem_response(401, Unauthorized.slug, Unauthorized.title, detail,
                                            [{"loc": ["header", "X-API-Key"], "pointer": None, "reason": reason}],
                                            {"WWW-Authenticate": 'ApiKey header="X-API-Key"',
                                             "Connection": "close"})  # its body is never read
                await response(scope, receive, send)
                return
        await self.app(scope, receive, send)

    def _keyed(self, method: str, path: str) -> bool:
        if self._routes is None:  # the routes are complete by the first request
            self._routes = keyed_routes(self._routes_of())
        return any(method in methods and pattern.match(path) for methods, pattern in self._routes)
