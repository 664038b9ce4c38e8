"""Errors of the HTTP layer and their RFC 9457 ``application/problem+json`` form.

Routes raise library exceptions (:class:`alloc.AllocError` subclasses) or the
:class:`ServiceError` subclasses below; :func:`install_handlers` maps every one of
them to a problem document in one place::

    {"type": "urn:alloc:problem:invalid-problem", "title": "Invalid allocation problem",
     "status": 422, "detail": "umin/umax: umin[2] = 3 > umax[2] = 1",
     "errors": [{"loc": ["body", "umin"], "pointer": "/umin", "reason": "..."}]}

``loc`` is the FastAPI-style location, ``pointer`` a JSON Pointer (RFC 6901) into the
request body when the error is in the body.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException
from starlette.routing import Match

import alloc

from .schemas import EVENT_KINDS

__all__ = [
    "ServiceError", "NotFound", "Conflict", "Unauthorized", "PayloadTooLarge", "InvalidRequest", "TooManyRequests",
    "ServiceUnavailable", "Overloaded", "NotReady", "problem_response", "install_handlers", "PROBLEM_JSON",
]

PROBLEM_JSON = "application/problem+json"
_log = logging.getLogger("service")


class ServiceError(Exception):
    """Base of the service's own errors: an HTTP status, a problem type and title.

    A subclass names them as class keywords: ``class NotFound(ServiceError, status=404, ...)``.
    """

    status: int = 400
    slug: str = "bad-request"
    title: str = "Bad request"

    def __init_subclass__(cls, *, status: int, slug: str, title: str, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        cls.status, cls.slug, cls.title = status, slug, title

    def __init__(self, detail: str, errors: Sequence[dict[str, Any]] = ()) -> None:
        super().__init__(detail)
        self.detail = detail
        self.errors = list(errors)


# one line each: the status, the problem type's slug and title, what it means
class NotFound(ServiceError, status=404, slug="not-found", title="Resource not found"): """An unknown vehicle."""
class Conflict(ServiceError, status=409, slug="conflict", title="Concurrent update"): """Retried writes lost."""
class Unauthorized(ServiceError, status=401, slug="unauthorized", title="Missing or wrong API key"): """No key."""
class TooManyRequests(ServiceError, status=429, slug="too-many-requests", title="Too many concurrent builds"):
    """The build lanes and their queues are full (a bounded resource, not an error of the request)."""
class ServiceUnavailable(ServiceError, status=503, slug="service-unavailable", title="Build process unavailable"):
    """A build process stopped (killed, out of memory) during the request's build."""
class Overloaded(ServiceError, status=503, slug="overloaded", title="Service at a capacity limit"):
    """A bounded resource (answer bytes held for clients) is spent; retry shortly."""
class NotReady(ServiceError, status=503, slug="not-ready", title="Not ready"):
    """This worker is starting or shutting down (``/v1/ready``)."""
class PayloadTooLarge(ServiceError, status=413, slug="payload-too-large", title="Request body too large"):
    """A body over ``ALLOC_MAX_BODY_BYTES``."""
class InvalidRequest(ServiceError, status=422, slug="invalid-request", title="Invalid request"):
    """A request that is well-formed JSON but not a valid allocation request."""


def _error(loc: Sequence[str | int], reason: str) -> dict[str, Any]:
    body = list(loc[1:]) if loc and loc[0] == "body" else None
    pointer = "/" + "/".join(str(p).replace("~", "~0").replace("/", "~1") for p in body) if body else None
    return {"loc": list(loc), "pointer": pointer, "reason": reason}


def field_error(field: str, reason: str, *, prefix: Sequence[str | int] = ("body",)) -> dict[str, Any]:
    """One entry of ``errors`` for a body field (``umin``, ``options/G``, ...)."""
    return _error([*prefix, *field.split("/")], reason)


def problem_response(
    status: int, slug: str, title: str, detail: str,
    errors: Sequence[dict[str, Any]] = (), headers: dict[str, str] | None = None, **members: Any,
) -> JSONResponse:
    """A problem document; ``members`` are its extension members (RFC 9457 section 3.2)."""
    content = {"type": f"urn:alloc:problem:{slug}", "title": title, "status": status, "detail": detail,
               "errors": list(errors), **members}
    return JSONResponse(content, status_code=status, media_type=PROBLEM_JSON, headers=headers)


_LIBRARY_ERRORS: tuple[tuple[type[Exception], int, str, str], ...] = (
    (alloc.UnknownMethodError, 422, "unknown-method", "Unknown allocation method"),
    (alloc.OptionError, 422, "invalid-option", "Invalid method option"),
    (alloc.DemandError, 422, "invalid-demand", "Invalid demand"),
    (alloc.ProblemError, 422, "invalid-problem", "Invalid allocation problem"),
    (alloc.AllocError, 422, "allocation-error", "Allocation request rejected"),
)


def library_error_fields(exc: Exception, prefix: Sequence[str | int] = ("body",)) -> list[dict[str, Any]]:
    """The ``errors`` entry of a library exception, against the field it names (``exc.field``)."""
    message = str(exc)
    field = getattr(exc, "field", None)
    if field:
        field = field.split("/", 1)[0]  # "umin/umax": the error concerns both; point at the first
    if isinstance(exc, alloc.UnknownMethodError):
        field = "method"
    elif isinstance(exc, alloc.OptionError):
        field = "options"
    return [field_error(field, message, prefix=prefix)] if field else [_error(list(prefix), message)]


_TYPE_TAGS = frozenset({"str", "int", "float", "bool", "list", "dict", "none"})


def _is_union_tag(step: str | int) -> bool:
    return isinstance(step, str) and ("[" in step or step in _TYPE_TAGS or step in EVENT_KINDS
                                      or step.startswith(("constrained-", "function-")))


def _strip_tags(loc: list[str | int], body: Any) -> list[str | int]:
    """Drop pydantic's union tags (``"list[float]"``, ``"int"``, a discriminator value such
    as ``"jam"``) from a body location, walking the request body alongside."""
    if not loc or loc[0] != "body":
        return loc
    out: list[str | int] = ["body"]
    node = body
    for step in loc[1:]:
        if isinstance(node, dict) and isinstance(step, str) and step in node:
            node = node[step]
        elif isinstance(node, list) and isinstance(step, int) and 0 <= step < len(node):
            node = node[step]
        elif _is_union_tag(step):
            continue
        else:
            node = None  # a missing or extra field: name it, nothing below it to walk
        out.append(step)
    return out


def _validation_errors(exc: RequestValidationError, limit: int) -> tuple[list[dict[str, Any]], int]:
    """The first ``limit`` errors in problem form, and how many there were."""
    body = getattr(exc, "body", None)
    errors = exc.errors()
    out = []
    for err in errors[:limit]:
        loc = [p for p in err.get("loc", ()) if isinstance(p, (str, int))]
        out.append(_error(_strip_tags(loc, body), str(err.get("msg", "invalid value"))))
    return out, len(errors)


#: the methods a 405's ``Allow`` may list (the HTTP methods routes are declared with)
_METHODS = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS")


def allowed_methods(request: Request) -> list[str]:
    """Every method some route serves at the request's path (RFC 9110 section 15.5.6: the
    ``Allow`` of a 405).  Starlette names only the methods of the first route whose path
    matched, and FastAPI makes one route per method: ``PUT .../telemetry`` was answered
    ``Allow: POST`` (issue 39).  Each method is tried against the routing table (included
    routers are matched as the router matches them)."""
    routes = request.app.router.routes
    return [method for method in _METHODS
            if any(route.matches({**request.scope, "method": method})[0] is Match.FULL for route in routes)]


def install_handlers(app: FastAPI) -> None:
    """Register the one mapping from exceptions to problem+json responses."""

    @app.exception_handler(ServiceError)
    async def _service(request: Request, exc: ServiceError) -> JSONResponse:
        headers = ({"WWW-Authenticate": 'ApiKey header="X-API-Key"'} if exc.status == 401
                   else {"Retry-After": "1"} if exc.status in (429, 503) else None)
        return problem_response(exc.status, exc.slug, exc.title, exc.detail, exc.errors, headers)

    @app.exception_handler(alloc.AllocError)
    async def _library(request: Request, exc: alloc.AllocError) -> JSONResponse:
        for cls, status, slug, title in _LIBRARY_ERRORS:
            if isinstance(exc, cls):
                return problem_response(status, slug, title, str(exc), library_error_fields(exc))
        raise AssertionError("unreachable: AllocError is the last entry")

    @app.exception_handler(RequestValidationError)
    async def _validation(request: Request, exc: RequestValidationError) -> JSONResponse:
        # bounded: a body can carry tens of thousands of errors, and listing them all held the
        # event loop for seconds; the first ones and the count say what is wrong
        limit = getattr(getattr(request.app.state, "settings", None), "max_validation_errors", 20)
        errors, total = _validation_errors(exc, limit)
        detail = "; ".join(f"{'/'.join(map(str, e['loc']))}: {e['reason']}" for e in errors[:5])
        if total > len(errors):
            detail += f" (the first {len(errors)} of {total} errors are listed)"
        return problem_response(422, "validation-error", "Request validation failed", detail, errors,
                                error_count=total)

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
        # Routing errors raised by the framework itself (unknown path, wrong verb).
        title = {404: "Not found", 405: "Method not allowed"}.get(exc.status_code, "HTTP error")
        headers = dict(getattr(exc, "headers", None) or {})
        detail = str(exc.detail)
        if exc.status_code == 405:
            allowed = allowed_methods(request)
            headers["Allow"] = ", ".join(allowed)
            detail = f"{request.method} is not allowed on this path; allowed: {', '.join(allowed)}"
        return problem_response(exc.status_code, "http-error", title, detail, headers=headers or None)

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
        # A bug, never a client error: log it with the traceback, leak nothing.
        _log.exception("unhandled error on %s %s", request.method, request.url.path)
        return problem_response(500, "internal-error", "Internal server error",
                                "the service failed to handle this request; it has been logged")
