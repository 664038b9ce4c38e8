"""Priority for reconfiguration: while an authenticated write is in flight, other requests wait.

The event loop runs ready work first come, first served.  Under a flood of unauthenticated
requests (each a few hundred microseconds of validation, a version read, a cost check and
a refusal), an event's request would wait behind every flood request ahead of it, at each
of its steps: before it starts, and again when its commit returns from the writer thread.
Measured under the 16-client option flood of ``benchmarks/bench_service.py`` on the shared
2-core machine: event p99 221-414 ms, of which up to 140 ms before the application saw
the request and up to 205 ms between the commit returning and the coroutine resuming.

So a *priority* request (a write to ``/v1/vehicles`` carrying the right API key, or any
such write when no key is configured) closes a gate for the time it is in flight; every
other request waits at the gate before it reads its body or costs anything (at most
:data:`MAX_WAIT_S`, a safety net), and passes at once when no write is in flight.
The gate is closed as soon as the request's headers are parsed
(:class:`service.server.GuardedHttpToolsProtocol`), before the loop runs any request task
queued ahead of it; without that protocol (an in-process test client) the middleware closes
it when the request reaches the application.
"""

from __future__ import annotations

import asyncio
import hmac
from collections.abc import Iterable

from starlette.types import ASGIApp, Receive, Scope, Send

from . import timing

__all__ = ["PriorityGate", "PriorityMiddleware", "MAX_WAIT_S", "SCOPE_KEY", "GATE_STATE_KEY"]

#: the longest a request waits for writes in flight (a bound, not a schedule: writes take ms)
MAX_WAIT_S = 0.5
#: scope key set by the protocol: ``True`` when the gate was closed for this request
SCOPE_KEY = "alloc.priority"
#: key of the gate in the lifespan state (where the protocol finds it)
GATE_STATE_KEY = "alloc.gate"
_WRITE_METHODS = {"POST", "DELETE", "PUT", "PATCH"}
_PREFIX = "/v1/vehicles"


class PriorityGate:
    """Counts priority requests in flight; others wait while any is."""

    def __init__(self, api_key: str | None) -> None:
        self._key = api_key.encode() if api_key else None
        self.active = 0
        self.waited = 0  # requests that found the gate closed (tests, benchmarks)
        self._open = asyncio.Event()  # set exactly when active == 0 (binds no loop until awaited)
        self._open.set()

    def claims(self, method: str, path: str, headers: Iterable[tuple[bytes, bytes]]) -> bool:
        """``True`` for a write to a vehicle resource with the right API key (or no key configured)."""
        if method not in _WRITE_METHODS or not path.startswith(_PREFIX):
            return False
        if self._key is None:
            return True
        for name, value in headers:
            if name == b"x-api-key":
                return hmac.compare_digest(value, self._key)
        return False

    def enter(self) -> None:
        self.active += 1
        self._open.clear()

    def leave(self) -> None:
        self.active = max(0, self.active - 1)
        if self.active == 0:
            self._open.set()

    async def wait(self) -> None:
        """Return when no priority request is in flight (or after :data:`MAX_WAIT_S`)."""
        if self.active == 0:
            return
        self.waited += 1
        try:
            await asyncio.wait_for(self._open.wait(), MAX_WAIT_S)
        except TimeoutError:
            pass  # a write that long is no longer worth holding everyone else for


class PriorityMiddleware:
    """ASGI middleware: priority requests hold the gate while in flight, others wait for it."""

    def __init__(self, app: ASGIApp, gate: PriorityGate) -> None:
        self.app, self.gate = app, gate

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        gate = self.gate
        priority = scope.get(SCOPE_KEY)
        if priority is None:  # not marked by the protocol: classify here
            priority = gate.claims(scope["method"], scope["path"], scope.get("headers", ()))
            if priority:
                gate.enter()
        if not priority:
            await gate.wait()
            timing.mark("gate")
            await self.app(scope, receive, send)
            return
        try:
            await self.app(scope, receive, send)
        finally:
            gate.leave()
