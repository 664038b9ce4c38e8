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

from typing import Any

import numpy as np
from fastapi import Response
from pydantic import BaseModel

import alloc

from .errors import InvalidRequest, field_error
from .schemas import AllocationOut, BatchOut

__all__ = ["model_response", "allocation_response", "batch_response"]


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


def batch_response(result: alloc.BatchResult, **extra: Any) -> Response:
    _require_finite(result.method, result.u, result.v_achieved)
    return model_response(BatchOut.of(result, **extra))
