"""Connection hygiene for uvicorn: request timeouts and framing errors as problem+json.

uvicorn bounds idle keep-alive connections (``timeout_keep_alive``) and concurrent
connections (``limit_concurrency``, 503 beyond) but not a request that is sent slowly or
never finished: 2,000 half-sent requests stay open and exhaust file descriptors.  The
protocol below closes a connection whose request (headers and body) has not fully
arrived ``request_timeout`` seconds after its first byte (or after the connection opened),
answering ``408`` as problem+json, and answers malformed framing (bad
``Content-Length``, garbage request line) with ``400`` problem+json instead of text.
"""

from __future__ import annotations

import asyncio
import json
import os
import time
from typing import Any

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

from .errors import PROBLEM_JSON
from .priority import GATE_STATE_KEY, SCOPE_KEY

__all__ = ["GuardedHttpToolsProtocol", "REQUEST_TIMEOUT_S", "problem_bytes"]

#: seconds for a whole request (headers and body) to arrive (``ALLOC_REQUEST_TIMEOUT_S``)
REQUEST_TIMEOUT_S = float(os.environ.get("ALLOC_REQUEST_TIMEOUT_S", "10"))

_REASONS = {400: "Bad Request", 408: "Request Timeout"}


def problem_bytes(status: int, slug: str, title: str, detail: str) -> bytes:
    """A complete HTTP/1.1 response (connection: close) carrying a problem document."""
    body = json.dumps({"type": f"urn:alloc:problem:{slug}", "title": title, "status": status, "detail": detail,
                       "errors": []}).encode()
    head = (f"HTTP/1.1 {status} {_REASONS[status]}\r\ncontent-type: {PROBLEM_JSON}\r\n"
            f"content-length: {len(body)}\r\nconnection: close\r\n\r\n").encode()
    return head + body


class GuardedHttpToolsProtocol(HttpToolsProtocol):
    """uvicorn's httptools protocol with a whole-request timeout and problem+json framing errors."""

    request_timeout = REQUEST_TIMEOUT_S

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._request_timer: asyncio.TimerHandle | None = None
        self._receiving = True

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
            self.transport.write(problem_bytes(408, "request-timeout", "Request timeout",
                                               f"the request did not arrive within {self.request_timeout:g} s"))
            self.transport.close()

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        self._arm()

    def connection_lost(self, exc: Exception | None) -> None:
        self._disarm()
        super().connection_lost(exc)

    def on_message_begin(self) -> None:
        super().on_message_begin()
        # when the request's first bytes were parsed: ServerTiming reports the wait from
        # here to the application starting (a busy event loop shows as "dispatch")
        self.scope["alloc.received"] = time.perf_counter()  # type: ignore[typeddict-unknown-key]

    def on_headers_complete(self) -> None:
        # A priority request (service.priority) closes the gate now, before the loop runs
        # any request task queued ahead of it; not when uvicorn answers 503 itself.
        gate = self.app_state.get(GATE_STATE_KEY)
        limit = self.limit_concurrency
        over = limit is not None and (len(self.connections) >= limit or len(self.tasks) >= limit)
        super().on_headers_complete()
        if gate is not None and not over and "path" in self.scope:
            priority = gate.claims(self.scope["method"], self.scope["path"], self.headers)
            self.scope[SCOPE_KEY] = priority  # type: ignore[literal-required]
            if priority:
                gate.enter()

    def data_received(self, data: bytes) -> None:
        if not self._receiving:
            self._receiving = True
        self._arm()
        super().data_received(data)

    def on_message_complete(self) -> None:
        self._receiving = False
        self._disarm()
        super().on_message_complete()

    def send_400_response(self, msg: str) -> None:
        self._disarm()
        self.transport.write(problem_bytes(400, "bad-framing", "Malformed HTTP request", msg))
        self.transport.close()
