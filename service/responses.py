"""Responses of the allocation routes, checked and serialised once.

Routes declare ``response_model`` for the OpenAPI document, but a route that returns a
model lets FastAPI validate and serialise it a second time.  The allocation routes build
their output from an :class:`alloc.Result` themselves and return its JSON directly:
pydantic-core writes floats in shortest round-trip form, so ``u`` parses back to the very
same float64 values the library computed.

The library promises finite commands (a subnormal ``B``, which once overflowed to NaN, is
now answered finitely).  This module still guards the promise: should a non-finite value
ever appear, the caller gets a 422 naming the problem, never a ``null`` in ``u`` (JSON
cannot carry NaN) and never a 500.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import numpy as np
from fastapi import Response
from pydantic import BaseModel
from pydantic_core import to_json
from starlette.types import Receive, Scope, Send

import alloc

from .errors import InvalidRequest, Overloaded, field_error
from .schemas import AllocationOut, BatchOut

__all__ = ["model_response", "allocation_response", "batch_json", "AnswerBudget",
           "StreamedAnswer", "CHUNK_BYTES"]


def model_response(model: BaseModel, status_code: int = 200) -> Response:
    return Response(model.model_dump_json(), status_code=status_code, media_type="application/json")


def _require_finite(method: str, *arrays: np.ndarray) -> None:
    if not all(np.isfinite(a).all() for a in arrays):
        reason = (f"{method} produced non-finite values for this problem (numerically degenerate); "
                  f"rescale the problem or use another method")
        raise InvalidRequest(f"B: {reason}", [field_error("B", reason)])


def allocation_response(result: alloc.Result, **extra: Any) -> Response:
    _require_finite(result.method, result.u, result.v_achieved)
    return model_response(AllocationOut.of(result, **extra))


#: numbers serialised per call of the JSON encoder while a batch answer is written.  Each call
#: holds the GIL (neither json's C encoder nor pydantic-core releases it), and the answer is
#: built on a build thread: one call over a whole 8,000 x 64 answer held the event loop for
#: 130-170 ms (pydantic's validation and dump), so an event arriving then waited as long.
NUMBERS_PER_CALL = 8192


def _rows(name: str, a: np.ndarray) -> list[bytes]:
    rows = max(1, NUMBERS_PER_CALL // max(1, a.shape[1] if a.ndim == 2 else 1))
    parts = [f'"{name}":['.encode()]
    for start in range(0, len(a), rows):
        if start:
            parts.append(b",")
        parts.append(to_json(a[start:start + rows].tolist())[1:-1])
    parts.append(b"]")
    return parts


def batch_json(result: alloc.BatchResult, **extra: Any) -> bytes:
    """A batch's answer as JSON bytes (built where the batch ran, off the event loop).

    The same document as ``BatchOut.of(result, **extra).model_dump_json()`` (the tests compare
    them), written in pieces of :data:`NUMBERS_PER_CALL` numbers so that the thread building it
    lets the event loop run in between; the arrays are the library's own finite float64 values,
    so only the small fields go through the model's validation.
    """
    _require_finite(result.method, result.u, result.v_achieved)
    tail = BatchOut(u=[], v_achieved=[], unallocated=[], status=[], counts=result.counts(), method=result.method,
                    solve_time=float(result.solve_time), **extra).model_dump(mode="json")
    parts: list[bytes] = [b"{"]
    for name in ("u", "v_achieved", "unallocated", "status"):
        del tail[name]
        parts += _rows(name, getattr(result, name) if name != "status" else np.asarray(result.status, dtype=str))
        parts.append(b",")
    parts.append(to_json(tail)[1:])
    return b"".join(parts)


#: bytes handed to the server per write of a streamed answer: the server's write buffer
#: then holds at most its high-water mark plus one chunk per connection
CHUNK_BYTES = 64 * 1024


class AnswerBudget:
    """Bytes of large answers held for clients at once (``ALLOC_ANSWER_BYTES_IN_FLIGHT``).

    A batch reserves its predicted answer size before it runs (503 with ``Retry-After``
    when the budget is spent) and frees it when its answer has been written out or the
    connection dropped (a client that does not read is dropped after
    ``ALLOC_WRITE_TIMEOUT_S``: :mod:`service.server`).
    """

    def __init__(self, limit: int) -> None:
        self.limit, self.held = limit, 0
        self._lock = threading.Lock()

    def reserve(self, nbytes: int) -> Callable[[], None]:
        """Hold ``nbytes``; returns the function that frees them (idempotent)."""
        with self._lock:
            if self.held + nbytes > self.limit:
                raise Overloaded(f"the service holds {self.held:,} bytes of answers for clients, and "
                                         f"this answer's {nbytes:,} would exceed ALLOC_ANSWER_BYTES_IN_FLIGHT = "
                                         f"{self.limit:,}; retry shortly")
            self.held += nbytes
        freed = False

        def free() -> None:
            nonlocal freed
            with self._lock:
                if not freed:
                    freed = True
                    self.held -= nbytes
        return free


class StreamedAnswer(Response):
    """A JSON answer written in :data:`CHUNK_BYTES` pieces, each after the client took the
    previous ones (the server's flow control), and its reservation freed when done or
    when the client went away."""

    media_type = "application/json"

    def __init__(self, body: bytes, free: Callable[[], None]) -> None:
        super().__init__(status_code=200, headers={"content-length": str(len(body))})
        self._payload, self._free = body, free

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        try:
            await send({"type": "http.response.start", "status": self.status_code, "headers": self.raw_headers})
            view = memoryview(self._payload)
            for start in range(0, max(len(view), 1), CHUNK_BYTES):
                end = start + CHUNK_BYTES
                await send({"type": "http.response.body", "body": bytes(view[start:end]),
                            "more_body": end < len(view)})
        finally:
            self._payload = b""
            self._free()
