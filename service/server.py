"""Connection hygiene for uvicorn: every resource a connection holds has a bound and a deadline.

uvicorn bounds idle keep-alive connections (``timeout_keep_alive``) and concurrent
connections (``limit_concurrency``, 503 beyond) but not a request that is sent slowly or
never finished, nor the size of its head under httptools (h11's
``max_incomplete_event_size`` does not apply: a 40 MB header stalled the loop 1.4 s), nor
an answer a client never reads (held in the write buffer for as long as the connection
lives).  The protocol below adds, with the limits of :class:`service.config.Settings`:

* a whole-request deadline (``ALLOC_REQUEST_TIMEOUT_S``): a request whose head and body
  have not arrived in time is answered ``408`` and closed;
* head limits: the request line and headers at most ``ALLOC_MAX_HEADER_BYTES``, at most
  ``ALLOC_MAX_HEADERS`` fields, checked on the raw bytes before the parser buffers them
  (``431``, closed);
* a write deadline (``ALLOC_WRITE_TIMEOUT_S``): when the client has not taken the answer's
  bytes (the write buffer stays above its high-water mark) for that long, the connection
  is dropped and the buffer freed;
* an accept policy: at most ``ALLOC_MAX_CONNECTIONS_PER_CLIENT`` connections per client
  address (``503``, closed; a deployment risk behind a reverse proxy or NAT, where every client
  has the proxy's address: docs/service.md), and room kept for newcomers: beyond
  ``ALLOC_MAX_CONNECTIONS - ALLOC_RESERVED_CONNECTIONS`` open connections, one connection is
  closed for each new one: the oldest that has never had a request answered (a half-sent
  request), else the oldest idle one.  Stalled connections then cannot take the capacity an
  event's connection needs: a new one finishes its request within a millisecond and is never
  the oldest, and one that keeps its connection open between events is closed only when no
  half-sent request is left to close;
* capacity apart for what must always answer: uvicorn's ``limit_concurrency`` (connections and
  tasks in flight, ``ALLOC_MAX_CONNECTIONS``; ``503`` beyond) counts HTTP only, not the open
  WebSockets and their tasks (:class:`service.streams.GuardedWebSocketProtocol`, capped on their
  own at ``ALLOC_MAX_WEBSOCKETS``: an upgrade beyond gets ``503``), and the requests that must
  always answer (:func:`always_room`: events and the other priority writes with the key,
  ``/v1/health``, ``/v1/ready``) have ``ALLOC_RESERVED_REQUESTS`` more.

Framing errors (bad ``Content-Length``, garbage request line) are answered ``400``
problem+json instead of text.
"""

from __future__ import annotations

import asyncio
import json
import time
from collections import Counter, OrderedDict
from functools import lru_cache
from typing import Any

import httptools
from starlette.types import Receive, Scope, Send
from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

from .config import Settings
from .errors import PROBLEM_JSON
from .priority import GATE_STATE_KEY, LIGHT_KEY, SCOPE_KEY, LightTicket, PriorityGate, is_light
from .streams import GuardedWebSocketProtocol

__all__ = ["GuardedHttpToolsProtocol", "GuardedWebSocketProtocol", "problem_bytes", "limits", "always_room",
           "ALWAYS_ROOM_READS"]

#: the reads that must answer whatever else is in flight (a load balancer's probes)
ALWAYS_ROOM_READS: frozenset[tuple[str, str]] = frozenset({("GET", "/v1/health"), ("GET", "/v1/ready")})

_REASONS = {400: "Bad Request", 408: "Request Timeout", 431: "Request Header Fields Too Large",
            503: "Service Unavailable"}


@lru_cache(maxsize=1)
def limits() -> Settings:
    """This process's settings (a worker reads them from the ``ALLOC_*`` environment)."""
    return Settings()


def always_room(gate: PriorityGate | None, method: str, path: str, headers: list[tuple[bytes, bytes]]) -> bool:
    """Whether a request may use ``ALLOC_RESERVED_REQUESTS``: a probe of :data:`ALWAYS_ROOM_READS`,
    or a priority write (an event, with the key: :meth:`service.priority.PriorityGate.claims`)."""
    return (method, path) in ALWAYS_ROOM_READS or (gate is not None and gate.claims(method, path, headers))


def _over_capacity(limit: int) -> Any:
    body = json.dumps({"type": "urn:alloc:problem:over-capacity", "title": "Service at a capacity limit",
                       "status": 503, "errors": [],
                       "detail": f"{limit} HTTP requests are in flight in this worker (ALLOC_MAX_CONNECTIONS); "
                                 f"retry shortly"}).encode()
    headers = [(b"content-type", PROBLEM_JSON.encode()), (b"content-length", str(len(body)).encode()),
               (b"retry-after", b"1"), (b"connection", b"close")]

    async def refuse(scope: Scope, receive: Receive, send: Send) -> None:
        await send({"type": "http.response.start", "status": 503, "headers": headers})
        await send({"type": "http.response.body", "body": body})
    return refuse


def problem_bytes(status: int, slug: str, title: str, detail: str) -> bytes:
    """A complete HTTP/1.1 response (connection: close) carrying a problem document."""
    body = json.dumps({"type": f"urn:alloc:problem:{slug}", "title": title, "status": status, "detail": detail,
                       "errors": []}).encode()
    head = (f"HTTP/1.1 {status} {_REASONS[status]}\r\ncontent-type: {PROBLEM_JSON}\r\n"
            f"content-length: {len(body)}\r\nconnection: close\r\n\r\n").encode()
    return head + body


class _HeadTooLarge(Exception):
    """Raised from a parser callback: the request's head is over a limit."""


class GuardedHttpToolsProtocol(HttpToolsProtocol):
    """uvicorn's httptools protocol with the deadlines and limits of the module docstring."""

    #: this process's connections that have not had a request answered yet and are not running
    #: one, oldest first: evicted first (a half-sent request is here for as long as it lives)
    _evictable: OrderedDict[GuardedHttpToolsProtocol, None] = OrderedDict()
    #: connections that have had requests answered, idle or sending the next one: evicted only
    #: when no connection of the first kind is left (a writer keeping its connection is here)
    _idle: OrderedDict[GuardedHttpToolsProtocol, None] = OrderedDict()
    #: this process's open connections per client address
    _per_client: Counter[str] = Counter()

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        settings = limits()
        self.request_timeout = settings.request_timeout_s
        self.write_timeout = settings.write_timeout_s
        self.max_head, self.max_headers = settings.max_header_bytes, settings.max_headers
        self.open_limit = settings.max_connections - settings.reserved_connections
        self.per_client_limit = settings.max_connections_per_client
        # uvicorn's own check would count the open WebSockets and their tasks: this protocol's
        # replaces it (on_headers_complete), with room kept for what must always answer
        self.http_limit, self.limit_concurrency = self.limit_concurrency, None
        self.reserved_requests = settings.reserved_requests
        self.max_websockets = settings.max_websockets
        self._request_timer: asyncio.TimerHandle | None = None
        self._write_timer: asyncio.TimerHandle | None = None
        self._receiving = True
        self._in_head, self._head_bytes, self._head_tail, self._header_count = True, 0, b"", 0
        self._refusal: bytes | None = None
        self._address: str | None = None
        self._running = False  # between a request's last byte and its answer's
        self._served = False  # a request of this connection has been answered
        self._ticket: LightTicket | None = None  # the current request's, when it is light

    # ----------------------------------------------------------- deadlines
    def _arm(self) -> None:
        if self._request_timer is None:
            self._request_timer = self.loop.call_later(self.request_timeout, self._request_timed_out)

    def _disarm(self) -> None:
        if self._request_timer is not None:
            self._request_timer.cancel()
            self._request_timer = None

    def _request_timed_out(self) -> None:
        self._request_timer = None
        if self._receiving and not self.transport.is_closing():
            self._close_with(problem_bytes(408, "request-timeout", "Request timeout",
                                           f"the request did not arrive within {self.request_timeout:g} s"))

    def pause_writing(self) -> None:
        super().pause_writing()
        if self._write_timer is None:
            self._write_timer = self.loop.call_later(self.write_timeout, self._write_timed_out)

    def resume_writing(self) -> None:
        if self._write_timer is not None:
            self._write_timer.cancel()
            self._write_timer = None
        super().resume_writing()

    def _write_timed_out(self) -> None:
        # the client took none of the answer for write_timeout seconds: drop it, free its buffer
        self._write_timer = None
        if not self.transport.is_closing():
            self.logger.warning("dropped %s: it read none of its answer for %g s", self._address, self.write_timeout)
            self.transport.abort()

    def _close_with(self, response: bytes) -> None:
        self._disarm()
        self.transport.write(response)
        self.transport.close()

    # ------------------------------------------------------ accept policy
    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._address = self.client[0] if self.client else "?"
        self._per_client[self._address] += 1
        if self._per_client[self._address] > self.per_client_limit:
            self._close_with(problem_bytes(503, "too-many-connections", "Too many connections",
                                           f"at most {self.per_client_limit} open connections per client address"))
            return
        self._evictable[self] = None
        self._make_room()
        self._arm()

    def _make_room(self) -> None:
        """Beyond the open limit, close the oldest connections not running a request."""
        excess = len(self.connections) - GuardedWebSocketProtocol.open - self.open_limit  # HTTP's only
        while excess > 0 and (self._evictable or self._idle):
            tier = self._evictable if self._evictable else self._idle
            oldest = next(iter(tier))
            if oldest is self:
                break
            del tier[oldest]
            if not oldest.transport.is_closing():
                oldest._close_with(problem_bytes(503, "connection-evicted", "Connection closed to make room",
                                                 "the service closed this connection, which was not running a "
                                                 "request, to accept a newer one; retry"))
            excess -= 1

    def connection_lost(self, exc: Exception | None) -> None:
        self._release()
        super().connection_lost(exc)

    def handle_websocket_upgrade(self) -> None:
        if GuardedWebSocketProtocol.open >= self.max_websockets:  # refused on the upgrade request only
            self._close_with(problem_bytes(503, "too-many-websockets", "Too many WebSockets",
                                           f"at most {self.max_websockets} WebSockets are open per worker "
                                           f"process (ALLOC_MAX_WEBSOCKETS); retry later"))
            return
        # The connection passes to uvicorn's WebSocket protocol, whose close this protocol never
        # hears of: release what it holds now (a WebSocket is then counted by uvicorn's
        # connection limit, not per client), or every WebSocket ever opened would keep one of
        # its client's ALLOC_MAX_CONNECTIONS_PER_CLIENT slots.  Its own count is
        # GuardedWebSocketProtocol's.
        self._release()
        super().handle_websocket_upgrade()

    def _release(self) -> None:
        self._disarm()
        self._close_ticket()  # a request dropped before its answer started
        if self._write_timer is not None:
            self._write_timer.cancel()
            self._write_timer = None
        self._evictable.pop(self, None)
        self._idle.pop(self, None)
        if self._address is not None:
            self._per_client[self._address] -= 1
            if self._per_client[self._address] <= 0:
                del self._per_client[self._address]
            self._address = None

    # --------------------------------------------------------- the request
    def data_received(self, data: bytes) -> None:
        if not self._receiving:
            self._receiving = True
        if not self._running:  # a request arriving: evictable until it has arrived
            (self._idle if self._served else self._evictable).setdefault(self)
        self._arm()
        if self._in_head and not self._head_fits(data):
            self._close_with(problem_bytes(431, "header-too-large", "Request header fields too large",
                                           f"the request line and headers exceed {self.max_head:,} bytes"))
            return
        super().data_received(data)

    def _head_fits(self, data: bytes) -> bool:
        """Whether the head still fits its byte limit, judged on the raw bytes: the head ends
        within the budget left, or this chunk is within it (a chunk may carry the body too)."""
        budget = self.max_head - self._head_bytes
        if len(data) <= budget:
            self._head_bytes += len(data)
            self._head_tail = data[-3:]
            return True
        return (self._head_tail + data[:budget]).find(b"\r\n\r\n") >= 0

    def on_message_begin(self) -> None:
        super().on_message_begin()
        self._header_count = 0
        # when the request's first bytes were parsed: ServerTiming reports the wait from
        # here to the application starting (a busy event loop shows as "dispatch")
        self.scope["alloc.received"] = time.perf_counter()  # type: ignore[typeddict-unknown-key]

    def on_header(self, name: bytes, value: bytes) -> None:
        self._header_count += 1
        if self._header_count > self.max_headers:
            self._refusal = problem_bytes(431, "too-many-headers", "Request header fields too large",
                                          f"more than {self.max_headers} header fields")
            raise _HeadTooLarge  # the parser stops; send_400_response answers with the refusal
        super().on_header(name, value)

    def on_headers_complete(self) -> None:
        self._in_head, self._head_bytes, self._head_tail = False, 0, b""
        # A priority request (service.priority) closes the gate now, before the loop runs
        # any request task queued ahead of it; not when uvicorn answers 503 itself.
        gate = self.app_state.get(GATE_STATE_KEY)
        over = self._over_limit(gate)
        app = self.app
        if over:
            self.app = _over_capacity(self.http_limit)  # this request's application only
        try:
            super().on_headers_complete()
        finally:
            self.app = app
        if gate is not None and not over and "path" in self.scope:
            priority = gate.claims(self.scope["method"], self.scope["path"], self.headers)
            self.scope[SCOPE_KEY] = priority  # type: ignore[literal-required]
            if priority:
                gate.enter()
            elif is_light(self.headers):
                # open from now, before its task runs: a large body's parse about to start
                # yields to it (service.priority.LightTicket)
                self._close_ticket()
                self._ticket = self.scope[LIGHT_KEY] = LightTicket(gate)  # type: ignore[literal-required]

    def _over_limit(self, gate: PriorityGate | None) -> bool:
        """Whether this request is over the HTTP limit: connections or tasks in flight, the
        WebSockets' not counted, at ``ALLOC_MAX_CONNECTIONS``, or that plus
        ``ALLOC_RESERVED_REQUESTS`` for a request of :func:`always_room`."""
        limit = self.http_limit
        if limit is None or self.parser.should_upgrade():  # an upgrade is the WebSocket cap's to judge
            return False
        busy = max(len(self.connections) - GuardedWebSocketProtocol.open,
                   len(self.tasks) - GuardedWebSocketProtocol.running)
        if busy < limit:
            return False
        path = httptools.parse_url(self.url).path.decode("ascii", errors="replace")
        method = self.parser.get_method().decode("ascii", errors="replace")
        room = self.reserved_requests if always_room(gate, method, path, self.headers) else 0
        return busy >= limit + room

    def _close_ticket(self) -> None:
        if self._ticket is not None:
            self._ticket.done()
            self._ticket = None

    def on_message_complete(self) -> None:
        self._receiving = False
        self._in_head = True  # what follows on this connection is the next request's head
        self._evictable.pop(self, None)  # running a request: not evicted for a newcomer
        self._idle.pop(self, None)
        self._running = True
        self._disarm()
        super().on_message_complete()

    def on_response_complete(self) -> None:
        self._running, self._served = False, True
        self._close_ticket()
        super().on_response_complete()
        if not self.transport.is_closing():
            self._idle[self] = None  # idle between requests

    def send_400_response(self, msg: str) -> None:
        refusal, self._refusal = self._refusal, None
        self._close_with(refusal or problem_bytes(400, "bad-framing", "Malformed HTTP request", msg))
