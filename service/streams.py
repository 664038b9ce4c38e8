"""Telemetry WebSockets: a capacity of their own, and a budget per API key over all its sockets.

A telemetry WebSocket is a connection held for as long as its vehicle streams.  uvicorn counted
it, and its task, against ``limit_concurrency`` like an HTTP request in flight, and accepted
upgrades past it: 512 open streams (a fleet, or one client leaking sockets) made every HTTP
request a 503, events and health probes included.  And its limits were per connection, checked
behind the priority gate: 100 key-holding sockets sending flat out delayed an event to 1.7 s
(p99), every refused message still costing the event loop a turn through the gate.  Here:

* **Capacity** (:class:`GuardedWebSocketProtocol`).  At most ``ALLOC_MAX_WEBSOCKETS`` WebSockets
  are open per worker process; an upgrade beyond gets HTTP 503 problem+json on the upgrade
  request only (:meth:`service.server.GuardedHttpToolsProtocol.handle_websocket_upgrade`).
  Open WebSockets and their tasks are not counted against the HTTP requests' limit.
* **Budget per key** (:class:`KeyBudget`, :class:`StreamLimits`).  All the telemetry sockets
  opened with one API key share ``ALLOC_WS_KEY_MESSAGES_PER_S`` messages and
  ``ALLOC_WS_KEY_BYTES_PER_S`` bytes per second per worker process (one second's worth as burst),
  on top of each connection's own rate (:data:`service.routes.telemetry.WS_MESSAGES_PER_S`).
  The checks run before the priority gate and before the message is parsed: a message over a
  limit is answered with a problem document (413 over the size cap, 429 over a rate) and never
  reaches the route.  Refusals are paced too: they draw on a schedule of their own, the key's
  message rate (:meth:`KeyBudget.refusal_delay`), and a connection whose refusal has to wait is
  not read meanwhile (uvicorn reads a WebSocket's next frames only once its message is taken),
  so the senders are held back by TCP, at no cost here.  One key's sockets thus cost the event
  loop at most about twice its message rate, whatever their number and speed.
* **Size.**  A message is at most :data:`service.routes.telemetry.WS_MAX_MESSAGE_BYTES` (64 KiB,
  the light-body size of :mod:`service.priority`: its parse on the loop takes about 0.3 ms);
  uvicorn refuses a frame larger than that plus 64 KiB before reading it
  (``ws_max_size``, close code 1009).  Larger batches go through ``POST .../telemetry``,
  whose large bodies wait their parse turn (:mod:`service.bodies`).
"""

from __future__ import annotations

import asyncio
import json
import time
from typing import Any, ClassVar

from starlette.types import ASGIApp, Message, Receive, Scope, Send
from uvicorn.protocols.websockets.websockets_sansio_impl import WebSocketsSansIOProtocol

from .keys import key_matches

__all__ = ["GuardedWebSocketProtocol", "KeyBudget", "StreamLimits", "TokenBucket"]


class TokenBucket:
    """``rate`` units per second sustained, ``burst`` at once (``clock``: seconds, monotonic)."""

    __slots__ = ("rate", "burst", "tokens", "at", "_clock")

    def __init__(self, rate: float, burst: float, clock: Any = time.monotonic) -> None:
        self.rate, self.burst, self._clock = float(rate), float(burst), clock
        self.tokens, self.at = self.burst, clock()

    def take(self, amount: float = 1.0) -> bool:
        """Take ``amount`` if there is that much; ``False`` (nothing taken) otherwise."""
        now = self._clock()
        self.tokens = min(self.burst, self.tokens + (now - self.at) * self.rate)
        self.at = now
        if self.tokens < amount:
            return False
        self.tokens -= amount
        return True


class KeyBudget:
    """What the telemetry sockets of one API key may cost this process, together, per second:
    ``messages`` processed and their ``nbytes``, each with one second's worth as burst; and a
    schedule for refusals at the same message rate (:meth:`refusal_delay`)."""

    def __init__(self, messages_per_s: float, bytes_per_s: float, clock: Any = time.monotonic) -> None:
        self.messages = TokenBucket(messages_per_s, max(1.0, messages_per_s), clock)
        self.nbytes = TokenBucket(bytes_per_s, bytes_per_s, clock)
        self._interval = 1.0 / messages_per_s
        self._window = max(1.0, messages_per_s) * self._interval  # the refusals' burst: one second's worth
        self._due = 0.0  # when the refusal schedule is next free (GCRA's theoretical arrival time)
        self._clock = clock

    def take(self, size: int) -> bool:
        """One message of ``size`` bytes may be processed: both rates allow it (then both spent)."""
        if not self.messages.take():
            return False
        if not self.nbytes.take(size):
            self.messages.tokens += 1.0  # not processed: give the message back
            return False
        return True

    def refusal_delay(self) -> float:
        """Seconds before the next refusal may be sent (0 within the burst).  Each call books a slot,
        so waiting connections are served in turn, none woken for nothing."""
        now = self._clock()
        self._due = max(self._due, now) + self._interval
        return max(0.0, self._due - now - self._window)


class GuardedWebSocketProtocol(WebSocketsSansIOProtocol):
    """uvicorn's WebSocket protocol, counted apart from HTTP: :attr:`open` connections and
    :attr:`running` application tasks of this process (``service.server`` subtracts them from
    the HTTP limit and caps :attr:`open` at ``ALLOC_MAX_WEBSOCKETS``)."""

    open: ClassVar[int] = 0
    running: ClassVar[int] = 0

    def connection_made(self, transport: Any) -> None:
        self._counted_task = False
        super().connection_made(transport)
        GuardedWebSocketProtocol.open += 1

    def connection_lost(self, exc: Exception | None) -> None:
        GuardedWebSocketProtocol.open -= 1
        super().connection_lost(exc)

    def handle_connect(self, event: Any) -> None:
        tasks = len(self.tasks)
        super().handle_connect(event)
        if len(self.tasks) > tasks:  # the handshake went on: the application's task started
            self._counted_task = True
            GuardedWebSocketProtocol.running += 1

    def on_task_complete(self, task: asyncio.Task[None]) -> None:
        if self._counted_task:
            self._counted_task = False
            GuardedWebSocketProtocol.running -= 1
        super().on_task_complete(task)


def _refusal(status: int, slug: str, title: str, detail: str) -> str:
    # the shape of service.errors.problem_response, written here without a response object: a
    # refusal must cost less than the message it refuses
    return json.dumps({"type": f"urn:alloc:problem:{slug}", "title": title, "status": status, "detail": detail,
                       "errors": [{"loc": ["body"], "pointer": "", "reason": detail}]})


class StreamLimits:
    """ASGI middleware, outside :class:`service.priority.PriorityMiddleware`: a WebSocket's
    messages within their size and rates reach the application; the others are answered here,
    in order, unparsed (module docstring).  The budgets are per API key, kept for the process."""

    def __init__(self, app: ASGIApp, api_key: str | None, messages_per_s: float, bytes_per_s: float) -> None:
        self.app, self.api_key = app, api_key
        self.messages_per_s, self.bytes_per_s = messages_per_s, bytes_per_s
        # one budget per key; the service has one key (or none: then every socket shares one)
        self.budget = KeyBudget(messages_per_s, bytes_per_s)
        self.refused = {"size": 0, "connection": 0, "key": 0}  # this process's, for tests and benchmarks

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "websocket" or not key_matches(scope.get("headers", ()), self.api_key):
            await self.app(scope, receive, send)  # a wrong key: the route refuses the handshake
            return
        # the per-connection limits are the route's (its API contract): read when the socket opens
        from .routes import telemetry as route

        max_bytes = route.WS_MAX_MESSAGE_BYTES
        connection = TokenBucket(route.WS_MESSAGES_PER_S, route.WS_BURST)
        budget, refused = self.budget, self.refused
        too_fast = _refusal(429, "too-many-requests", "Too many messages",
                            f"more than {route.WS_MESSAGES_PER_S:g} messages per second (burst {route.WS_BURST}) "
                            f"on this connection; this message was not processed")
        over_budget = _refusal(429, "too-many-requests", "Too many messages",
                               f"this API key's telemetry sockets are over their budget of "
                               f"{self.messages_per_s:g} messages and {self.bytes_per_s:,.0f} bytes per second "
                               f"(per worker process); this message was not processed")

        async def receive_within_limits() -> Message:
            while True:
                message = await receive()
                if message["type"] != "websocket.receive":
                    return message
                text = message.get("text")
                size = len(message.get("bytes") or b"") if text is None else \
                    len(text) if text.isascii() else len(text.encode())
                if size > max_bytes:
                    refusal, reason = _refusal(413, "payload-too-large", "Request body too large",
                                               f"message of {size:,} bytes exceeds the limit of {max_bytes:,}"), "size"
                elif not connection.take():
                    refusal, reason = too_fast, "connection"
                elif not budget.take(size):
                    refusal, reason = over_budget, "key"
                else:
                    return message
                refused[reason] += 1
                delay = budget.refusal_delay()
                if delay > 0:
                    await asyncio.sleep(delay)  # not read meanwhile: TCP holds the sender back
                await send({"type": "websocket.send", "text": refusal})

        await self.app(scope, receive_within_limits, send)
