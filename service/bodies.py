"""Request bodies: a size limit per request, a budget of body bytes held at once, and large
bodies parsed one at a time, never while an authenticated write or a light request is in flight.

* **Size.** A body over ``ALLOC_MAX_BODY_BYTES`` gets 413 (``Content-Length`` checked before
  a byte of the body is read; a chunked body counted as it arrives).
* **Budget.** The bodies this process holds at once (buffered here until the route has
  parsed and validated them) total at most ``ALLOC_BODY_BYTES_IN_FLIGHT``;
  ``ALLOC_WRITER_BODY_BYTES`` of it is kept for priority writes (:mod:`service.priority`), so
  clients without the key cannot spend what an event needs.  A request over the budget gets
  503 problem+json with ``Retry-After`` before its body is read; its bytes stay in the
  kernel's socket buffer, not in this process.
* **Parse turns.** A body over :data:`HEAVY_BODY_BYTES` costs the event loop milliseconds to
  parse (a 1.3 MB batch body: 21-35 ms with pydantic-core's JSON parser, 85-137 ms with the
  ``json.loads`` Starlette would use, measured at load 7-10 on 2 cores).  Such bodies
  of requests other than priority writes are parsed one at a time, each once it has fully
  arrived (a slow sender holds no turn), and each only when no priority write is in flight
  and no light request (a small body or none: an allocation, ``/v1/health``) is open, from
  its head's arrival to its answer's start (:meth:`service.priority.PriorityGate.wait`
  ``heavy``; a light flood delays a parse by at most ``MAX_WAIT_S``).  An event, and the
  allocation after it, therefore wait for at most the one parse already running when they
  arrived, once, whatever the number and size of the other bodies.  Without the light rule
  the next parse started as soon as the previous one ended, ahead of an allocation whose
  bytes had arrived meanwhile (its wake-up was queued before the loop read the socket), and
  again while the allocation awaited its rebuild on a build thread (a parse holds the GIL
  for its whole document).  Measured under the validation-error flood of
  ``tests/service/test_attacks.py`` at load 15, niceness -20: the allocation's
  ``Server-Timing`` ``dispatch`` was 60-334 ms in 4 of 6 rounds before, 0.2-0.6 ms in 11 of
  11 after; its p50 at the client 324 ms before, 160 ms after.

**Duplicate keys.** pydantic-core, like ``json.loads``, keeps the last of a repeated key, so
``{"t": [...], "t": [...]}`` would be taken silently; a JSON body with a repeated key is refused
with 422 naming it (:func:`duplicate_key`, issue 39), before its fields are validated.

Parsing in a thread would not help: the parser holds the GIL for the whole document (a
1 ms sleep on the loop thread woke up to 1.5 s late beside a thread running ``json.loads``).
"""

from __future__ import annotations

import asyncio
import email.message
import json
import re
from collections.abc import Callable, Coroutine
from typing import Any

import pydantic_core
from fastapi import Request, Response
from fastapi.routing import APIRoute
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from .deps import PARSE_TURN_KEY
from .errors import InvalidRequest, Overloaded, PayloadTooLarge, field_error, problem_response
from .priority import HEAVY_BODY_BYTES, SCOPE_KEY, PriorityGate

__all__ = ["BodySizeLimit", "BodyBudget", "JsonRoute", "HEAVY_BODY_BYTES", "GC_THRESHOLDS", "duplicate_key",
           "refuse_duplicate_keys"]

#: the garbage collector's thresholds in the service (CPython's default: 700, 10, 10).  A parsed
#: batch body is thousands of lists (one per row of ``V``, twice: JSON and validated), and with
#: the default a burst of them triggers full collections over everything alive: 40 bodies of
#: 8,000 rows, parsed and held, took 3.5-4.8 s with pauses of 180-300 ms (full collections);
#: with 5,000 for the young generation, 2.0 s and the longest pause 22 ms (measured at load 10)
GC_THRESHOLDS = (5000, 10, 10)


class BodyBudget:
    """Bytes of request bodies held at once: ``total``, of which ``reserved`` only for priority writes."""

    def __init__(self, total: int, reserved: int) -> None:
        self.total, self.reserved = total, reserved
        self.held = 0
        self.refused = 0  # requests refused for the budget (tests, benchmarks)

    def take(self, nbytes: int, priority: bool) -> bool:
        """Reserve ``nbytes`` (called on the event loop); ``False`` when they do not fit."""
        limit = self.total if priority else self.total - self.reserved
        if self.held + nbytes > limit:
            self.refused += 1
            return False
        self.held += nbytes
        return True

    def give(self, nbytes: int) -> None:
        self.held -= nbytes


class BodySizeLimit:
    """ASGI middleware: the size limit, the budget and the parse turns of the module docstring.

    Bodies are buffered here (at most the limit) and replayed to the application.
    (FastAPI's own ``max_body_size`` answers ``text/plain`` when it rejects on ``Content-Length``.)
    """

    def __init__(self, app: ASGIApp, limit: int, budget: BodyBudget | None = None,
                 gate: PriorityGate | None = None) -> None:
        self.app, self.limit, self.gate = app, limit, gate
        self.budget = budget or BodyBudget(64 * limit, 0)
        self._parse_turn: asyncio.Semaphore | None = None

    async def _too_large(self, scope: Scope, receive: Receive, send: Send, detail: str) -> None:
        err = PayloadTooLarge
        response = problem_response(err.status, err.slug, err.title, detail,
                                    [{"loc": ["body"], "pointer": "", "reason": detail}])
        await response(scope, receive, send)

    async def _over_budget(self, scope: Scope, receive: Receive, send: Send) -> None:
        err = Overloaded
        detail = (f"request bodies held by the service are at their limit (ALLOC_BODY_BYTES_IN_FLIGHT = "
                  f"{self.budget.total:,} bytes, {self.budget.reserved:,} of them kept for authenticated "
                  f"writes); retry shortly")
        response = problem_response(err.status, err.slug, err.title, detail, headers={"Retry-After": "1"},
                                    limit="ALLOC_BODY_BYTES_IN_FLIGHT")
        await response(scope, receive, send)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        limit, budget = self.limit, self.budget
        priority = bool(scope.get(SCOPE_KEY))
        declared = 0
        for name, value in scope.get("headers", ()):
            if name == b"content-length":
                if not value.isdigit() or int(value) > limit:
                    await self._too_large(scope, receive, send, f"body of {value.decode(errors='replace')} "
                                                                f"bytes exceeds the limit of {limit} bytes")
                    return
                declared = int(value)
        held = 0
        try:
            if declared and not budget.take(declared, priority):
                await self._over_budget(scope, receive, send)
                return
            held = declared
            chunks, size = [], 0
            while True:
                message = await receive()
                if message["type"] != "http.request":
                    break
                chunk = message.get("body", b"")
                size += len(chunk)
                if size > limit:
                    await self._too_large(scope, receive, send, f"body exceeds the limit of {limit} bytes")
                    return
                if size > held:  # chunked, or more than declared: reserve what arrived
                    if not budget.take(size - held, priority):
                        await self._over_budget(scope, receive, send)
                        return
                    held = size
                chunks.append(chunk)
                if not message.get("more_body", False):
                    break
            body = b"".join(chunks)
            del chunks
            await self._run(scope, receive, send, body, priority)
        finally:
            budget.give(held)

    async def _run(self, scope: Scope, receive: Receive, send: Send, body: bytes, priority: bool) -> None:
        replayed = False

        async def replay() -> Message:
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()

        if len(body) <= HEAVY_BODY_BYTES or priority:
            await self.app(scope, replay, send)
            return
        # The route ends the turn when it starts (validation done: service.deps.end_parse_turn),
        # the error handler by returning.
        if self._parse_turn is None:
            self._parse_turn = asyncio.Semaphore(1)
        turn = self._parse_turn
        await turn.acquire()
        released = False

        def end_turn() -> None:
            nonlocal released
            if not released:
                released = True
                turn.release()
        scope[PARSE_TURN_KEY] = end_turn
        try:
            if self.gate is not None:
                await self.gate.wait(heavy=True)  # writes and light requests go first
            await self.app(scope, replay, send)
        finally:
            end_turn()


_POSITION = re.compile(r" at line (\d+) column (\d+)$")


def parse_json(body: bytes) -> Any:
    """``body`` parsed by pydantic-core (floats bit-identical to ``json.loads``'), its
    errors raised as :class:`json.JSONDecodeError` with the position, as FastAPI expects."""
    try:
        return pydantic_core.from_json(body)
    except ValueError as exc:
        message = str(exc)
        match = _POSITION.search(message)
        pos = 0
        if match:
            line, column = int(match[1]), int(match[2])
            for _ in range(line - 1):
                pos = body.find(b"\n", pos) + 1
            pos += column - 1
        doc = body.decode("utf-8", errors="replace")
        raise json.JSONDecodeError(message[:match.start()] if match else message, doc, min(pos, len(doc))) from None


#: a JSON string token (escapes included), to count the colons inside strings
_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"')


def _members(node: Any, *, every_list: bool) -> int:
    """Members of the objects in a parsed document: all of them, or (``every_list`` false) those
    reached without entering a list whose first element is not an object (rows of numbers)."""
    count, stack = 0, [node]
    while stack:
        item = stack.pop()
        if isinstance(item, dict):
            count += len(item)
            stack.extend(v for v in item.values() if isinstance(v, (dict, list)))
        elif isinstance(item, list) and item and (every_list or isinstance(item[0], dict)):
            stack.extend(v for v in item if isinstance(v, (dict, list)))
    return count


class _Repeated(dict):
    """An object in which ``key`` was given more than once (found by :func:`duplicate_key`)."""

    key: str


def _pairs(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out = _Repeated(pairs)
    if len(out) == len(pairs):
        return dict(pairs)
    seen: set[str] = set()
    out.key = next(k for k, _ in pairs if k in seen or seen.add(k))  # type: ignore[func-returns-value]
    return out


def _pointer_of_repeat(node: Any) -> str | None:
    stack: list[tuple[Any, tuple[str, ...]]] = [(node, ())]
    while stack:
        item, path = stack.pop()
        if isinstance(item, _Repeated):
            return "/" + "/".join(p.replace("~", "~0").replace("/", "~1") for p in (*path, item.key))
        if isinstance(item, dict):
            stack.extend((v, (*path, k)) for k, v in item.items() if isinstance(v, (dict, list)))
        else:
            stack.extend((v, (*path, str(i))) for i, v in enumerate(item) if isinstance(v, (dict, list)))
    return None


def duplicate_key(raw: bytes, parsed: Any) -> str | None:
    """The JSON pointer of a key given twice in one object of the document ``raw`` (``parsed``
    is its value, which keeps the last), or ``None``.

    Cheap when there is none: the members counted in ``parsed`` are at most those written, which
    are at most the colons of ``raw``; when the count reaches the colons (outside strings) no key
    was repeated.  Only when it does not is the whole document walked, and only when a key was
    repeated is it parsed again (``json.loads`` keeping every pair) to name it.
    """
    colons = raw.count(b":")
    reached = _members(parsed, every_list=False) if colons else 0
    if reached == colons:
        return None
    written = colons - sum(m.group().count(b":") for m in _STRING.finditer(raw) if b":" in m.group())
    if reached == written or _members(parsed, every_list=True) == written:
        return None
    return _pointer_of_repeat(json.loads(raw, object_pairs_hook=_pairs))


def refuse_duplicate_keys(raw: bytes, parsed: Any, *, prefix: tuple[str, ...] = ("body",)) -> None:
    """422 naming a key given twice in one object of ``raw`` (:func:`duplicate_key`)."""
    pointer = duplicate_key(raw, parsed)
    if pointer is not None:
        field = pointer[1:]
        reason = "this key appears more than once in its object (a JSON parser would keep only the last)"
        raise InvalidRequest(f"{field}: {reason}", [field_error(field, reason, prefix=prefix)])


def _is_json(content_type: str | None) -> bool:
    """FastAPI's rule for a body it parses as JSON: ``application/json`` or ``application/*+json``."""
    if not content_type:
        return False  # FastAPI's strict content type: no header, no JSON
    message = email.message.Message()
    message["content-type"] = content_type
    subtype = message.get_content_subtype()
    return message.get_content_maintype() == "application" and (subtype == "json" or subtype.endswith("+json"))


class _JsonRequest(Request):
    async def json(self) -> Any:
        if not hasattr(self, "_json"):
            self._json = parse_json(await self.body())
        return self._json

    async def refuse_duplicate_keys(self) -> None:
        """422 for a JSON body with a key given twice (a body that is not JSON is left to FastAPI)."""
        body = await self.body()
        if not body or not _is_json(self.headers.get("content-type")):
            return
        try:
            parsed = await self.json()
        except json.JSONDecodeError:
            return
        refuse_duplicate_keys(body, parsed)


class JsonRoute(APIRoute):
    """A route whose JSON body is parsed by :func:`parse_json`: 4-5x faster than Starlette's
    ``json.loads`` on a batch body (rows of numbers), about as fast on an object of 40,000
    members (building the dict dominates), so the event loop is held that much less; a body
    with a key given twice is refused (:func:`duplicate_key`)."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        handler = super().get_route_handler()
        has_body = self.body_field is not None

        async def route(request: Request) -> Response:
            json_request = _JsonRequest(request.scope, request.receive)
            if has_body:
                await json_request.refuse_duplicate_keys()
            return await handler(json_request)
        return route
