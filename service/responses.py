"""Responses of the hot paths, serialised once.

Routes declare ``response_model`` for the OpenAPI document, but a route that returns a
model lets FastAPI validate and serialise it a second time.  The allocation routes build
their output model themselves (from a :class:`alloc.Result`), so they return its JSON
directly: pydantic-core writes floats in shortest round-trip form, so ``u`` parses back
to the very same float64 values.
"""

from __future__ import annotations

from fastapi import Response
from pydantic import BaseModel

__all__ = ["model_response"]


def model_response(model: BaseModel, status_code: int = 200) -> Response:
    return Response(model.model_dump_json(), status_code=status_code, media_type="application/json")
