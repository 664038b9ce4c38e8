"""Priority for reconfiguration: while an authenticated write is in flight, other requests wait.

The event loop runs ready work first come, first served.  Under a flood of unauthenticated
requests (each a few hundred microseconds of validation, a version read, a cost check and
a refusal), an event's request would wait behind every flood request ahead of it, at each
of its steps: before it starts, and again when its commit returns from the writer thread.
Measured under the 16-client option flood of ``benchmarks/bench_service.py`` on the shared
2-core machine (``Server-Timing`` phases): event p99 221-414 ms, of which up to 140 ms
before the application saw the request (``dispatch``) and up to 205 ms between the commit
returning and the coroutine resuming (``resume``); with the gate, p50 of both 0.1-2.8 ms.

So a *priority* request (a write of :data:`PRIORITY_ROUTES` with a light body: create or
delete a vehicle, record an event, post a telemetry batch, accept or reject a proposal;
carrying the right API key, or any such write when no key is configured; and each light
message of an authenticated telemetry WebSocket) closes a gate for the time it is in
flight; every other request waits at the gate before it reads its body or costs anything.
When no write is in flight the others enter :data:`TURNS` per loop iteration, so the loop
reads its sockets (and a write's headers) between every few of them.

What is bounded, and by how much: the gate stays closed for at most :data:`MAX_WAIT_S` at
a time (writes overlapping for longer no longer hold the others back), and for at most
:data:`CLOSED_SHARE` of any period beyond that: closing spends a budget that refills at that
rate, up to ``MAX_WAIT_S`` (a sparse writer always finds it full; key holders posting writes
back to back, telemetry batches of hundreds of ms each, cannot keep the others out for longer
than half the time).  A request's whole wait is that plus its place in the line that formed
behind the gate: ``TURNS`` of the waiting requests enter per loop iteration, each costing
``c`` (about 0.6 ms on a quiet machine, more on a loaded one), so with ``Q`` requests ahead
of it a request waits up to ``MAX_WAIT_S + Q c``; at most ``ALLOC_MAX_CONNECTIONS`` (512)
requests can be in line, so up to about 0.8 s at 0.6 ms each (measured 0.65-0.92 s under the
flood of ``benchmarks/bench_service.py`` on the shared machine: ``c`` up to about 0.8 ms
there).  Writes do not queue here at all.  The gate is closed as soon as the request's
headers are parsed (:class:`service.server.GuardedHttpToolsProtocol`), before the loop runs
any request task queued ahead of it; without that protocol (an in-process test client) the
middleware closes it when the request reaches the application.

Large bodies (:mod:`service.bodies`) wait, besides, for the light requests: a parse holds
the loop and the GIL for its whole document, so one that starts while an allocation awaits
its build on a thread delays both the build and the allocation's resumption, and parses
starting one after another added up (the validation-error flood's allocations).  A light
request (:func:`is_light`) holds a :class:`LightTicket` from its head's arrival (the
protocol opens it) to its answer's start; a parse's turn comes only when none is open, at
the second refill after it asked at the earliest (the loop reads its sockets in between),
or after :data:`MAX_WAIT_S` however many there are.
"""

from __future__ import annotations

import asyncio
import hmac
import re
import time
from collections import deque
from collections.abc import Callable, Iterable
from typing import Any

from starlette.types import ASGIApp, Message, Receive, Scope, Send

from . import timing

__all__ = ["PriorityGate", "PriorityMiddleware", "LightTicket", "MAX_WAIT_S", "CLOSED_SHARE", "SCOPE_KEY",
           "LIGHT_KEY", "GATE_STATE_KEY", "PRIORITY_ROUTES", "PRIORITY_STREAMS"]

#: requests other than writes let into the application per event-loop iteration: between
#: two reads of the sockets the loop runs at most this many of them (a flood request costs
#: ~0.6 ms), so a write's bytes are read, and the gate closed, within about a millisecond
TURNS = 2
#: the longest the gate stays closed at a time (a bound, not a schedule: writes take ms); a
#: request's whole wait adds its place in the line behind the gate (module docstring)
MAX_WAIT_S = 0.5
#: the largest share of time the gate can be closed over a long period, whatever the writers
#: do (a design choice, not a measurement: the others keep at least half the loop's time)
CLOSED_SHARE = 0.5
#: scope key set by the protocol: ``True`` when the gate was closed for this request
SCOPE_KEY = "alloc.priority"
#: scope key of a light request's :class:`LightTicket` (set by the protocol, else the middleware)
LIGHT_KEY = "alloc.light"
#: key of the gate in the lifespan state (where the protocol finds it)
GATE_STATE_KEY = "alloc.gate"
#: a body larger than this is parsed in a turn of its own (service.bodies): a "heavy" request
HEAVY_BODY_BYTES = 64 * 1024
#: The priority routes (FastAPI path formats; a ``{...}`` is one path segment): the writes that
#: publish or decide a failure, or add or remove a vehicle.  A telemetry batch that turns
#: into a detection is how a *silent* failure is published (policy ``auto``), and accepting
#: a proposal how a detection becomes an event (``confirm``), so they are priority like an
#: event; rejecting one is the same bodyless transaction.  Setting a vehicle's telemetry
#: (``PUT .../telemetry``) publishes nothing and waits like a read.
PRIORITY_ROUTES: frozenset[tuple[str, str]] = frozenset({
    ("POST", "/v1/vehicles"),
    ("DELETE", "/v1/vehicles/{vehicle_id}"),
    ("POST", "/v1/vehicles/{vehicle_id}/events"),
    ("POST", "/v1/vehicles/{vehicle_id}/telemetry"),
    ("POST", "/v1/vehicles/{vehicle_id}/proposals/{pid}/accept"),
    ("POST", "/v1/vehicles/{vehicle_id}/proposals/{pid}/reject"),
})
#: the WebSocket whose messages are priority, each from its receipt to its answer
#: (:class:`PriorityMiddleware`): one telemetry batch per message
PRIORITY_STREAMS: frozenset[str] = frozenset({"/v1/vehicles/{vehicle_id}/telemetry/ws"})


def _route_pattern(path_format: str) -> re.Pattern[str]:
    return re.compile(re.sub(r"\\\{\w+\\\}", "[^/]+", re.escape(path_format)))


_ROUTES: dict[str, list[re.Pattern[str]]] = {
    method: [_route_pattern(f) for m, f in sorted(PRIORITY_ROUTES) if m == method] for method, _ in PRIORITY_ROUTES}
_STREAMS = [_route_pattern(f) for f in sorted(PRIORITY_STREAMS)]


def is_light(headers: Iterable[tuple[bytes, bytes]]) -> bool:
    """Whether a request's head declares a body of at most :data:`HEAVY_BODY_BYTES` (or none);
    a chunked body's size is unknown until it has arrived: not light."""
    for name, value in headers:
        if name == b"content-length":
            return value.isdigit() and int(value) <= HEAVY_BODY_BYTES
        if name == b"transfer-encoding":
            return False
    return True


def _is_write(method: str, path: str, headers: Iterable[tuple[bytes, bytes]]) -> bool:
    """A request to one of :data:`PRIORITY_ROUTES` declaring a light body (:func:`is_light`).

    Why light only: a priority request skips the line at the gate, skips the parse turn of
    :mod:`service.bodies` and draws on ``ALLOC_WRITER_BODY_BYTES``, and while it is in flight
    nobody else starts.  Its parse holds the loop for the whole body (a 1.3 MB batch body:
    21-35 ms), so with bodies up to ``ALLOC_MAX_BODY_BYTES`` (4 MiB) a key holder posting
    them back to back would hold the loop, not just the gate.  A light body costs at most
    about 1-2 ms to parse, and bounds the work behind it: a telemetry batch of at most
    64 KiB is about 180 samples at m = 11, k = 6 (18 s of a 10 Hz stream), its detector
    work priced before it runs (``ALLOC_BATCH_BUDGET_S``) and done on the telemetry threads.
    Every other priority route's body is far smaller (an event: about 100 bytes; the largest
    catalogue vehicle: 1.7 kB).  A heavier or chunked batch (a backfill) is still accepted,
    as an ordinary large body: in its parse turn, from the shared budget."""
    patterns = _ROUTES.get(method)
    return patterns is not None and any(p.fullmatch(path) for p in patterns) and is_light(headers)


def _is_stream(path: str) -> bool:
    return any(p.fullmatch(path) for p in _STREAMS)


def _light_message(message: Message) -> bool:
    """A WebSocket message of at most :data:`HEAVY_BODY_BYTES` (a text's length is its size in
    bytes when it is ASCII, which CPython knows without a scan; JSON numbers are ASCII)."""
    text = message.get("text")
    if text is not None:
        return len(text) <= HEAVY_BODY_BYTES and text.isascii()
    return len(message.get("bytes") or b"") <= HEAVY_BODY_BYTES


class LightTicket:
    """A light request (no large body to parse) from its head's arrival to its answer's start:
    while any is open, no large body's parse starts (:meth:`PriorityGate.wait` ``heavy``)."""

    __slots__ = ("_gate",)

    def __init__(self, gate: PriorityGate) -> None:
        self._gate: PriorityGate | None = gate
        gate.light += 1

    def done(self) -> None:
        """The request started its answer, failed or was dropped (idempotent)."""
        gate, self._gate = self._gate, None
        if gate is not None:
            gate.light -= 1
            if gate.light == 0 and gate._heavy:
                gate._schedule_refill()


class PriorityGate:
    """Counts priority requests in flight; lets the others in a few per loop iteration, and
    none while a priority request is in flight (for at most :data:`MAX_WAIT_S` at a time and
    :data:`CLOSED_SHARE` of the time; ``clock``: seconds, monotonic).  A large
    body's parse (``heavy``) waits, besides, until no light request is open
    (:class:`LightTicket`), for at most :data:`MAX_WAIT_S`."""

    def __init__(self, api_key: str | None, clock: Callable[[], float] = time.monotonic) -> None:
        self._key = api_key.encode() if api_key else None
        self.active = 0
        self.light = 0  # open light requests (LightTicket)
        self.waited = 0  # requests that found the gate closed (tests, benchmarks)
        self._clock = clock
        self._closed_at = 0.0
        self._closes_for = 0.0  # how long the current closure may last
        self._budget, self._budget_at = MAX_WAIT_S, clock()  # seconds of closure available (CLOSED_SHARE)
        self._turns = TURNS
        self._queue: deque[asyncio.Future[None]] = deque()
        #: large bodies waiting to be parsed: [since, turn, seen by a refill]
        self._heavy: deque[list[Any]] = deque()
        self._refill_pending = False

    def claims(self, method: str, path: str, headers: Iterable[tuple[bytes, bytes]]) -> bool:
        """``True`` for a priority write (:data:`PRIORITY_ROUTES`, a light body: :func:`_is_write`)
        with the right API key, or with none when no key is configured (allocations and AMS
        queries are reads)."""
        return _is_write(method, path, headers) and self._key_matches(headers)

    def claims_stream(self, path: str, headers: Iterable[tuple[bytes, bytes]]) -> bool:
        """``True`` for a WebSocket of :data:`PRIORITY_STREAMS` opened with the right API key (or
        any when no key is configured): its light messages are priority (:class:`PriorityMiddleware`)."""
        return _is_stream(path) and self._key_matches(headers)

    def _key_matches(self, headers: Iterable[tuple[bytes, bytes]]) -> bool:
        if self._key is None:
            return True
        for name, value in headers:
            if name == b"x-api-key":  # the first one, as the routes' key check reads it
                return hmac.compare_digest(value, self._key)
        return False

    def enter(self) -> None:
        """A priority request arrived (called on the event loop)."""
        if self.active == 0:
            now = self._clock()
            self._refill_budget(now)
            self._closed_at, self._closes_for = now, min(MAX_WAIT_S, self._budget)
            asyncio.get_running_loop().call_later(self._closes_for, self._schedule_refill)
        self.active += 1

    def leave(self) -> None:
        self.active = max(0, self.active - 1)
        if self.active == 0:
            now = self._clock()
            self._refill_budget(now)
            self._budget = max(0.0, self._budget - min(now - self._closed_at, self._closes_for))
            if self._queue or self._heavy:
                self._schedule_refill()

    def _refill_budget(self, now: float) -> None:
        self._budget = min(MAX_WAIT_S, self._budget + (now - self._budget_at) * CLOSED_SHARE)
        self._budget_at = now

    def _closed(self) -> bool:
        return self.active > 0 and self._clock() - self._closed_at < self._closes_for

    async def wait(self, heavy: bool = False) -> None:
        """Return when it is this request's turn: no priority request in flight (or it has
        been for :data:`MAX_WAIT_S`), and fewer than :data:`TURNS` let in this iteration.

        ``heavy`` (a large body about to be parsed: :mod:`service.bodies`) waits, besides,
        for a loop iteration with no light request open nor waiting, or :data:`MAX_WAIT_S`.
        Always at least one iteration: a light request whose bytes arrived while the previous
        parse held the loop has its head read then, and goes first."""
        loop = asyncio.get_running_loop()
        turn = loop.create_future()
        if heavy:
            self._heavy.append([self._clock(), turn, False])
            loop.call_later(MAX_WAIT_S + 0.001, self._schedule_refill)
            self._schedule_refill()
            await turn
            return
        if not self._closed() and self._turns > 0 and not self._queue:
            self._turns -= 1
            self._schedule_refill()
            return
        self.waited += self.active > 0
        self._queue.append(turn)
        self._schedule_refill()
        await turn

    def _schedule_refill(self) -> None:
        if not self._refill_pending:
            self._refill_pending = True
            asyncio.get_running_loop().call_soon(self._refill)

    def _refill(self) -> None:
        """Next loop iteration (after the loop has read its sockets): :data:`TURNS` more, unless
        a priority request is in flight (its ``leave`` or its deadline refills then); a heavy
        turn when no light request is open, or the oldest has waited :data:`MAX_WAIT_S`."""
        self._refill_pending = False
        if self._closed():
            return
        self._turns = TURNS
        while self._turns and self._queue:
            turn = self._queue.popleft()
            if not turn.done():  # a request cancelled while waiting gives its turn away
                turn.set_result(None)
                self._turns -= 1
        while self._heavy and self._heavy[0][1].done():
            self._heavy.popleft()
        if self._heavy and self._turns and not self._queue:
            since, turn, seen = self._heavy[0]
            if seen and (self.light == 0 or self._clock() - since >= MAX_WAIT_S):
                self._heavy.popleft()
                turn.set_result(None)
                self._turns -= 1
        for entry in self._heavy:
            entry[2] = True  # released at the next refill at the earliest: the loop reads its sockets first
        if self._queue or self._turns < TURNS or (self._heavy and self.light == 0):
            self._schedule_refill()


#: the longest a liveness or readiness probe waits at the gate.  Behind a fleet's telemetry the gate
#: is closed most of the time (each message is a priority request): probes waited up to 4.3 s in
#: ``benchmarks/bench_fleet.py`` (2,000 sockets), and an orchestrator would restart a healthy
#: service.  A probe is one small read; past this wait it goes in, at most one per probe request
PROBE_WAIT_S = 0.02
_PROBES = frozenset({"/v1/health", "/v1/ready"})


async def _wait_turn(gate: PriorityGate, scope: Scope) -> None:
    """The request's turn at the gate; a probe (GET of :data:`_PROBES`) waits at most :data:`PROBE_WAIT_S`."""
    if scope.get("method") == "GET" and scope.get("path") in _PROBES:
        try:
            await asyncio.wait_for(gate.wait(), PROBE_WAIT_S)  # a cancelled turn is given away
        except TimeoutError:
            pass
        return
    await gate.wait()


class PriorityMiddleware:
    """ASGI middleware: priority requests hold the gate while in flight, others wait for it."""

    def __init__(self, app: ASGIApp, gate: PriorityGate) -> None:
        self.app, self.gate = app, gate

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "websocket" and self.gate.claims_stream(scope["path"], scope.get("headers", ())):
            await self._stream(scope, receive, send)
            return
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        gate = self.gate
        priority = scope.get(SCOPE_KEY)
        if priority is None:  # not marked by the protocol: classify here
            priority = gate.claims(scope["method"], scope["path"], scope.get("headers", ()))
            scope[SCOPE_KEY] = priority
            if priority:
                gate.enter()
        if not priority:
            ticket = scope.get(LIGHT_KEY)
            if ticket is None and is_light(scope.get("headers", ())):
                ticket = scope[LIGHT_KEY] = LightTicket(gate)
            if ticket is None:
                await _wait_turn(gate, scope)
                timing.mark("gate")
                await self.app(scope, receive, send)
                return

            async def send_then_close(message: Message) -> None:
                if message["type"] == "http.response.start":
                    ticket.done()  # its answer is computed: large bodies may be parsed again
                await send(message)
            try:
                await _wait_turn(gate, scope)
                timing.mark("gate")
                await self.app(scope, receive, send_then_close)
            finally:
                ticket.done()
            return
        left = False

        def leave() -> None:
            nonlocal left
            if not left:
                left = True
                gate.leave()

        async def send_then_leave(message: Message) -> None:
            await send(message)
            if message["type"] == "http.response.body" and not message.get("more_body", False):
                leave()  # answered: background work after the response holds nobody back
        try:
            await self.app(scope, receive, send_then_leave)
        finally:
            leave()

    async def _stream(self, scope: Scope, receive: Receive, send: Send) -> None:
        """A priority WebSocket: each light message (at most :data:`HEAVY_BODY_BYTES`) holds the
        gate from the route's receipt of it to the route's next send of its answer (the route
        answers every message, in order).  Its frames were read by the protocol already; what
        the gate spares it is the line behind other requests at each of its steps (its parse,
        and its resumption when its batch returns from a telemetry thread).  A heavier
        message (up to the route's 1 MiB) does not hold the gate."""
        gate = self.gate
        holding = False

        def leave() -> None:
            nonlocal holding
            if holding:
                holding = False
                gate.leave()

        async def receive_then_enter() -> Message:
            nonlocal holding
            leave()
            message = await receive()
            if message["type"] == "websocket.receive" and _light_message(message):
                holding = True
                gate.enter()
            return message

        async def leave_then_send(message: Message) -> None:
            # answered once the route sends: a client that does not read its answers (the send
            # waits for the socket) holds nobody back, however long the transport keeps it
            leave()
            await send(message)
        try:
            await self.app(scope, receive_then_enter, leave_then_send)
        finally:
            leave()
